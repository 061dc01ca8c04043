"""SLAM drift corrected between beacons: a pose graph over the cloud's own trajectory.

The trajectory (TUM, or the ``mast track`` CSV) gives the scanner's pose in
the cloud's frame over time. Keyframes are taken every ``step_m`` of travel;
consecutive keyframes are joined by the SLAM's own relative pose as a GTSAM
between factor whose standard deviation is the stated drift model (see
:data:`HEADING_PER_ROOT_M`): ``drift`` of each step in position, and a
heading random walk of a tenth of ``drift`` per square root of a metre. Every
control beacon pins the keyframe at the time it was seen: the mean of its edges, in
that keyframe's body frame, must land on the mean of the surveyed edges (a custom
factor, that mean's covariance from the edges' rotated into the grid plus the
survey's; a beacon's own heading is left to the SLAM, see ``_Seen``). Heights are a
separate 1D chain of offsets with the same drift per metre, pinned by the
beacons' tops.

Every point is then moved by the correction of the trajectory at its time,
``C(t) = X(t) X_slam(t)^-1``, interpolated between keyframes; the rigid
transformation is where the graph starts.

The graph bends the cloud onto its control beacons, so a beacon that moved
after its survey would bend the cloud locally and leave no residual to show
it. Each control beacon is therefore tested against the graph solved without
it: where the rest of the beacons and the drift model put its edges (with
the covariance of that prediction from the graph's marginals, plus its own
edges' and the survey's) against where it was surveyed, a chi-square test of
its plan coordinates at the w-tests' significance (Bonferroni over the
beacons). While some fail, the worst is left out and the rest tested again
(iterated data snooping); when more than a third would have to go, the drift
model or the beacons are wrong and the correction is refused. Check beacons
are never in the graph: each is tested the same way against the final one.
With heights, the beacon's top against the height chain solved without it
adds one degree of freedom to the same test.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.cloud.adjust import AdjustmentError, BeaconObs, Transformation
from mast.core import posegraph
from mast.core.stats import W_TEST_ALPHA, BeaconTest, beacon_critical
from mast.core.trajectory import ScannerPath
from mast.errors import InputError

__all__ = ["DriftCorrection", "correct_drift"]

#: The drift model of the between factors, per step of ``s`` metres: position
#: ``SCALE_SHARE * drift * s`` in each axis, heading ``HEADING_PER_ROOT_M * drift *
#: sqrt(s)`` radians. Chosen on simulated 1 % drifts (mast bench georef; a 160 m
#: and a 627 m cloud, checks every fourth beacon): with the heading three times
#: looser (a random walk that alone makes 1 % after 100 m) the checks were 50-350 mm
#: off, with the position ten times tighter 40-150 mm; these gave 3-23 mm. The SLAM's
#: along-track (scale) error, common in featureless drifts, is what a tight position
#: model cannot absorb.
HEADING_PER_ROOT_M = 0.1
SCALE_SHARE = 1.0
#: At most this share of the control beacons may be left out as outliers.
MAX_EXCLUDED_SHARE = 1.0 / 3.0
#: The beacons' tests in the order they are reported.
ROLES = ("control", "excluded", "check")


@dataclass(frozen=True, eq=False)
class DriftCorrection:
    """The correction ``C(t)`` at the keyframes: rotation, translation (grid = R p + t) and
    height offset; with the residuals at the beacons after it, each beacon's test, and the
    control beacons left out by them."""

    time: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    dz: NDArray[np.float64]
    drift: float
    step_m: float
    residuals: dict[str, NDArray[np.float64]]
    heights: bool
    #: each control beacon against the graph solved without it, each check against the
    #: final graph (module docstring); the squared Mahalanobis distance of its surveyed
    #: plan edges (and top, with heights), on two degrees of freedom per edge (one more
    #: for the top)
    tests: tuple[BeaconTest[str], ...] = ()
    excluded: tuple[str, ...] = ()

    @property
    def statistic_per_dof(self) -> float:
        """The control beacons' test statistics over their degrees of freedom (nan when
        none was tested): about 1 when the drift model fits the SLAM (the report judges
        it against the chi-square's 5 % bounds on :attr:`control_dof`); well below, the
        SLAM drifts less than the model says and only moves well beyond its misclosures
        are caught; above, it drifts more. Beacons left out are not counted."""
        tests = [t for t in self.tests if t.role == "control"]
        dof = self.control_dof
        return sum(t.statistic for t in tests) / dof if dof else math.nan

    @property
    def control_dof(self) -> int:
        """Degrees of freedom of the control beacons' tests, together."""
        return sum(t.dof for t in self.tests if t.role == "control")

    def apply(self, xyz: NDArray[np.float64], time: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points moved by the correction at their times (held at the ends outside)."""
        rot = np.interp(time, self.time, self.rotation)
        tx = np.interp(time, self.time, self.translation[:, 0])
        ty = np.interp(time, self.time, self.translation[:, 1])
        dz = np.interp(time, self.time, self.dz)
        c, s = np.cos(rot), np.sin(rot)
        out = np.empty_like(xyz)
        out[:, 0] = c * xyz[:, 0] - s * xyz[:, 1] + tx
        out[:, 1] = s * xyz[:, 0] + c * xyz[:, 1] + ty
        out[:, 2] = xyz[:, 2] + dz
        return out

    def to_cloud(self, grid_xy: NDArray[np.float64], path: ScannerPath) -> NDArray[np.float64]:
        """Where the grid points ``grid_xy`` (one beacon's edges, E and N) are in the
        cloud's plan: taken back by the correction at the keyframe from which they are
        nearest the scanner (when it passed them, and its points of them were taken)."""

        def back(rel: NDArray[np.float64], rot: NDArray[np.float64]) -> NDArray[np.float64]:
            c, s = np.cos(rot), np.sin(rot)  # grid = R p + t, so p = R^T (grid - t)
            return np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])

        middle = back(grid_xy.mean(axis=0) - self.translation, self.rotation)
        k = int(np.argmin(np.hypot(*(middle - _pose_at(path, self.time)[:, :2]).T)))
        return back(grid_xy - self.translation[k], np.full(len(grid_xy), self.rotation[k]))

    def at_beacon(self, obs: BeaconObs) -> NDArray[np.float64]:
        """The beacon's edges (E, N, Z of its top) after the correction at its time."""
        k = len(obs.edges)
        t = np.full(k, obs.time if obs.time is not None else self.time[0])
        xyz = np.column_stack([obs.cloud_xy, np.full(k, obs.top)])
        return self.apply(xyz, t)


def _pose_at(traj: ScannerPath, t: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.column_stack(
        [
            np.interp(t, traj.time, traj.xyz[:, 0]),
            np.interp(t, traj.time, traj.xyz[:, 1]),
            np.interp(t, traj.time, traj.yaw),
        ]
    )


def correct_drift(
    traj: ScannerPath,
    controls: Sequence[BeaconObs],
    rigid: Transformation,
    *,
    drift: float,
    survey_sigma_m: float,
    heights: bool,
    step_m: float = 1.0,
    checks: Sequence[BeaconObs] = (),
) -> DriftCorrection:
    """Solve the pose graph (module docstring), test its beacons, and the correction at
    every keyframe.

    Raises
    ------
    AdjustmentError
        ``inconsistent`` when more than :data:`MAX_EXCLUDED_SHARE` of the control
        beacons would have to be left out (two always remain).
    """
    import gtsam

    timed = [o for o in controls if o.time is not None]
    if len(timed) < 2:
        raise InputError(
            "the drift correction needs two control beacons seen at known times "
            "(the cloud's points need a time)",
            path=traj.path,
        )
    timed_checks = [o for o in checks if o.time is not None]
    # keyframes every step_m of travel, plus each beacon's time
    d = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(traj.xyz[:, :2], axis=0).T))])
    marks = np.arange(0.0, d[-1] + step_m, step_m)
    t_key = np.interp(marks, d, traj.time)
    t_beacons = np.array([o.time for o in [*timed, *timed_checks]], dtype=float)
    if t_beacons.min() < traj.time[0] - 1.0 or t_beacons.max() > traj.time[-1] + 1.0:
        raise InputError(
            f"the trajectory's times ({traj.time[0]:.3f} to {traj.time[-1]:.3f} s) do not "
            f"cover the beacons' ({t_beacons.min():.3f} to {t_beacons.max():.3f} s): "
            "is it the trajectory of this cloud, in the same time base?",
            path=traj.path,
        )
    # a keyframe at each control's time (a check is placed from its nearest keyframe, so
    # the graph is the same whichever beacons are checks)
    t_control = np.array([o.time for o in timed], dtype=float)
    t_key = np.unique(np.concatenate([t_key, np.clip(t_control, traj.time[0], traj.time[-1])]))
    slam = _pose_at(traj, t_key)
    dist = np.interp(t_key, traj.time, d)
    rot0 = math.radians(rigid.rotation_deg)
    c0, s0 = math.cos(rot0), math.sin(rot0)
    r0 = np.array([[c0, -s0], [s0, c0]])
    t0 = rigid.translation[:2] - r0 @ rigid.centre[:2]

    chain = gtsam.NonlinearFactorGraph()
    start = gtsam.Values()
    poses = [gtsam.Pose2(*p) for p in slam]
    for k, p in enumerate(slam):
        xy = r0 @ p[:2] + t0
        start.insert(k, gtsam.Pose2(float(xy[0]), float(xy[1]), float(p[2] + rot0)))
    for k in range(len(poses) - 1):
        step = max(float(dist[k + 1] - dist[k]), 1e-3)
        sig = np.array(
            [
                SCALE_SHARE * drift * step + 1e-4,
                SCALE_SHARE * drift * step + 1e-4,
                HEADING_PER_ROOT_M * drift * math.sqrt(step) + 1e-6,
            ]
        )
        chain.add(
            gtsam.BetweenFactorPose2(
                k,
                k + 1,
                poses[k].between(poses[k + 1]),
                gtsam.noiseModel.Diagonal.Sigmas(sig),
            )
        )
    s2 = survey_sigma_m**2
    seen = {o.beacon: _Seen(o, poses, t_key, r0) for o in [*timed, *timed_checks]}

    def solve(active: Sequence[BeaconObs], init: Any) -> tuple[Any, Any]:
        graph = gtsam.NonlinearFactorGraph()
        graph.push_back(chain)
        for o in active:
            for f in seen[o.beacon].factors(s2):
                graph.add(f)
        values = posegraph.solve(graph, init)
        return graph, values

    def test(
        o: BeaconObs, role: str, others: Sequence[BeaconObs], n: int
    ) -> BeaconTest[str] | None:
        """``o`` against the graph of ``others`` (a control's is solved without it); None
        when they cannot place the graph (fewer than two points: a rotation left free)."""
        if len(others) < 2:
            return None
        try:
            if role == "control":
                graph, values = solve(others, result)
                marginals = gtsam.Marginals(graph, values)
            else:  # a check, or a control left out: against the final graph
                values, marginals = result, final_marginals()
            stat, dof = seen[o.beacon].statistic(values, marginals, s2)
        except RuntimeError:  # GTSAM: an indeterminant system (too weak to place)
            return None
        if heights and math.isfinite(o.top) and math.isfinite(o.grid_top):
            k = seen[o.beacon].key
            dz, var = _height_chain(t_key, dist, others, drift, s2, at=k)
            r = o.top + float(dz[k]) - o.grid_top
            stat += r * r / (var + o.sigma_top**2 + _top_var(o, s2))
            dof += 1
        return BeaconTest(o.beacon, stat, dof, beacon_critical(W_TEST_ALPHA / max(n, 1), dof), role)

    def final_marginals() -> Any:
        if not cache or cache[0] is not result:
            cache[:] = [result, gtsam.Marginals(final, result)]
        return cache[1]

    cache: list[Any] = []
    active = list(timed)
    final, result = solve(active, start)
    excluded: list[BeaconTest[str]] = []
    while True:
        tried = [test(o, "control", [a for a in active if a is not o], len(active)) for o in active]
        tests = [t for t in tried if t is not None]
        failing = [t for t in tests if t.failed]
        if not failing:
            break
        worst = max(failing, key=lambda t: t.statistic / t.critical)
        # (the share alone keeps two: at most one of three, and one of two never)
        if len(excluded) + 1 > MAX_EXCLUDED_SHARE * len(timed) or len(active) <= 2:
            names = ", ".join(t.beacon for t in failing)
            raise AdjustmentError(
                "inconsistent",
                f"with the drift correction, beacon(s) {names} do not fit where the rest "
                f"and the drift model ({100 * drift:g} % of distance) put them, and too many "
                "to leave out: a beacon moved, or the SLAM drifts more than the model "
                "(--drift)",
                [t.beacon for t in failing],
            )
        excluded.append(worst)
        active = [o for o in active if o.beacon != worst.beacon]
        final, result = solve(active, result)
    # the left out and the checks, each against the final graph
    out = [o for o in timed if o.beacon in {t.beacon for t in excluded}]
    tests += [t for o in out if (t := test(o, "excluded", active, len(out)))]
    tests += [t for o in timed_checks if (t := test(o, "check", active, len(timed_checks)))]

    rot = np.empty(len(poses))
    trans = np.empty((len(poses), 2))
    for k, p in enumerate(poses):
        x = result.atPose2(k)
        corr = x.compose(p.inverse())
        rot[k] = corr.theta()
        trans[k] = [corr.x(), corr.y()]
    rot = np.unwrap(rot)
    dz = _height_chain(t_key, dist, active, drift, s2)[0] if heights else np.zeros(len(t_key))
    corr_ = DriftCorrection(t_key, rot, trans, dz, drift, step_m, {}, heights)
    res = {}
    for o in [*controls, *checks]:
        g = corr_.at_beacon(o)
        res[o.beacon] = g - np.column_stack(
            [o.grid_xy, np.full(len(o.edges), o.grid_top if heights else g[0, 2])]
        )
    return DriftCorrection(
        t_key,
        rot,
        trans,
        dz,
        drift,
        step_m,
        res,
        heights,
        tuple(sorted(tests, key=lambda t: (ROLES.index(t.role), t.beacon))),
        tuple(t.beacon for t in excluded),
    )


class _Seen:
    """A beacon as the pose graph sees it: its edges in the body frame of the keyframe
    nearest the time it was seen (a control's own), their covariance in the grid (the
    cloud's, turned by the rigid rotation ``r0``: the factors' errors are in the grid).

    In the graph (:meth:`factors`) the beacon is one point, the mean of its edges,
    with that mean's covariance: its own heading (two edges 0.6 m apart, each surveyed
    to a few millimetres: about 10 mrad) is worse than the SLAM's over the tens of
    metres between beacons, and a drift model looser than the SLAM (as the benchmark's
    is, see docs/georef.md) let it turn the graph at every control. Its test
    (:meth:`statistic`) takes every edge: a beacon knocked round about its middle
    keeps its mean and moves its edges."""

    def __init__(
        self,
        o: BeaconObs,
        poses: Sequence[Any],
        t_key: NDArray[np.float64],
        r0: NDArray[np.float64],
    ) -> None:
        self.obs = o
        self.key = int(np.argmin(np.abs(t_key - float(o.time))))  # type: ignore[arg-type]
        body = poses[self.key]
        self.q = [np.asarray(body.transformTo(np.asarray(p, dtype=float))) for p in o.cloud_xy]
        turn = np.kron(np.eye(len(self.q)), r0)
        self.cov = turn @ o.cloud_cov @ turn.T
        k = len(self.q)
        self.mean = np.kron(np.full((1, k), 1.0 / k), np.eye(2))  # (2, 2k): the edges' mean

    def _covariance(self, s2: float) -> NDArray[np.float64]:
        """The edges' joint covariance in the grid, the survey's added."""
        out: NDArray[np.float64] = self.cov + np.diag(np.repeat(self.obs.survey_var(s2), 2))
        return out

    def factors(self, s2: float) -> list[Any]:
        m = self.mean
        q = [m @ np.concatenate(self.q)]
        g = (m @ self.obs.grid_xy.reshape(-1)).reshape(1, 2)
        return [_edges_factor(self.key, q, g, m @ self._covariance(s2) @ m.T)]

    def statistic(self, values: Any, marginals: Any, s2: float) -> tuple[float, int]:
        """Squared Mahalanobis distance of the surveyed edges from where a graph solved
        without this beacon (``values``, ``marginals``) puts them, and its degrees of
        freedom (2 per edge)."""
        x = values.atPose2(self.key)
        pose_cov = marginals.marginalCovariance(self.key)
        v, jac = _edges_error(x, self.q, self.obs.grid_xy)
        total = self._covariance(s2) + jac @ pose_cov @ jac.T
        return float(v @ np.linalg.solve(total, v)), v.size


def _edges_factor(
    key: int, qs: Sequence[NDArray[np.float64]], gs: NDArray[np.float64], cov: NDArray[np.float64]
) -> Any:
    """``X(key) * q_i = g_i`` for a beacon's edges together: seen at ``qs`` in the
    keyframe's body frame, surveyed at ``gs``; ``cov`` is their joint covariance in the
    grid, where the error is (edges fitted with their beacon are correlated)."""
    import gtsam

    noise = gtsam.noiseModel.Gaussian.Covariance(cov)

    def error(
        this: object, v: object, jac: list[NDArray[np.float64]] | None
    ) -> NDArray[np.float64]:
        e, d = _edges_error(v.atPose2(this.keys()[0]), qs, gs)  # type: ignore[attr-defined]
        if jac is not None:
            jac[0] = d
        return e

    return gtsam.CustomFactor(noise, [key], error)


def _edges_error(
    x: Any, qs: Sequence[NDArray[np.float64]], gs: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`_edge_error` of each edge, stacked: the errors (2k,) and Jacobian (2k, 3)."""
    parts = [_edge_error(x, q, g) for q, g in zip(qs, gs, strict=True)]
    return np.concatenate([p[0] for p in parts]), np.vstack([p[1] for p in parts])


def _edge_error(
    x: Any, q: NDArray[np.float64], g: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``X * q - g`` for a pose ``X`` (a ``gtsam.Pose2``), and its 2x3 Jacobian for a
    perturbation of the pose in its own frame (GTSAM's retraction)."""
    c, s = math.cos(x.theta()), math.sin(x.theta())
    r = np.array([[c, -s], [s, c]])
    e: NDArray[np.float64] = r @ q + np.array([x.x(), x.y()]) - g
    return e, np.column_stack([r, r @ np.array([-q[1], q[0]])])


def _top_var(o: BeaconObs, s2: float) -> float:
    """The surveyed variance of a beacon's top: its observed edges' mean (``s2`` each
    when the survey gives none of its own)."""
    return s2 if o.grid_var is None else float(np.mean(o.grid_var))


def _height_chain(
    t_key: NDArray[np.float64],
    dist: NDArray[np.float64],
    timed: Sequence[BeaconObs],
    drift: float,
    s2: float,
    *,
    at: int | None = None,
) -> tuple[NDArray[np.float64], float]:
    """Height offsets at the keyframes: a random walk of ``drift`` per metre pinned by
    the beacons' tops (sparse least squares); and the variance of the offset at
    keyframe ``at`` (nan without one)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import splu

    n = t_key.size
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    rhs: list[float] = []
    w: list[float] = []
    for k in range(n - 1):
        step = max(float(dist[k + 1] - dist[k]), 1e-3)
        sig = drift * step + 1e-4
        r = len(rhs)
        rows += [r, r]
        cols += [k, k + 1]
        vals += [-1.0, 1.0]
        rhs.append(0.0)
        w.append(1.0 / sig)
    for o in timed:
        k = int(np.argmin(np.abs(t_key - float(o.time))))  # type: ignore[arg-type]
        r = len(rhs)
        rows.append(r)
        cols.append(k)
        vals.append(1.0)
        rhs.append(o.grid_top - o.top)
        w.append(1.0 / math.sqrt(o.sigma_top**2 + _top_var(o, s2)))
    wv = np.array(w)
    a = coo_matrix((np.array(vals) * wv[rows], (rows, cols)), shape=(len(rhs), n)).tocsr()
    b = np.array(rhs) * wv
    normal = splu((a.T @ a).tocsc())
    out: NDArray[np.float64] = np.asarray(normal.solve(a.T @ b), dtype=float)
    if at is None:
        return out, math.nan
    unit = np.zeros(n)
    unit[at] = 1.0
    return out, float(normal.solve(unit)[at])
