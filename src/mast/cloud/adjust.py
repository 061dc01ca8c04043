"""The cloud-to-grid transformation, adjusted by least squares over the beacon edges.

Observations, per control beacon: its inner edges e2 and e3 found in the
cloud's plan (from the beacon-level fit of :mod:`mast.cloud.beacon_fit`, with
their joint covariance; or two fitted lines meeting, each edge's own) and, where
the survey has elevations, the height of its top (the mean of its panels' top
edges). The survey's coordinates carry its own ``sigma_m`` per edge where it gives
one (:attr:`BeaconObs.grid_var`), else ``survey_sigma_m``, in each coordinate and
in the tops' elevations (the survey contract has no vertical sigma).

Models:

* ``4`` (default): easting, northing and elevation offsets and a rotation about
  the vertical (SLAM clouds are levelled); without surveyed elevations the
  elevation offset is not estimated and heights are reported as not controlled.
* ``helmert7``: a 3D similarity (three translations, three rotations, scale)
  over the edges' tops as 3D points; it needs elevations and three beacons.

The solution is Gauss-Newton with the residual covariance re-rotated at every
step. Reported: the a-posteriori reference variance and its two-sided
chi-square test, Baarda's w-test of every coordinate, and a leave-one-out test
of every beacon; a beacon whose removal alone makes the rest consistent is
named and left out, as ``mast locate`` does with a beacon that moved. Check
beacons stay out of the solution and are compared with the survey after it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.stats import W_TEST_ALPHA, BeaconTest, beacon_critical, variance_bounds, w_critical

__all__ = [
    "BeaconObs",
    "CheckResult",
    "Solution",
    "Transformation",
    "adjust_transformation",
    "check_beacons",
    "rigid_solution",
]


@dataclass(frozen=True, eq=False)
class BeaconObs:
    """One found beacon's observations.

    Attributes
    ----------
    beacon : str
    edges : tuple of int
        Edge numbers observed (2 and/or 3).
    cloud_xy : ndarray, shape (k, 2)
        The edges in the cloud's plan.
    cloud_cov : ndarray, shape (2k, 2k)
        The edges' joint covariance in the cloud's plan, ``(x, y)`` of each edge in
        turn: edges fitted with their beacon are correlated through its panels.
    top : float
        Height of the beacon's top in the cloud (nan if unknown).
    sigma_top : float
    grid_xy : ndarray, shape (k, 2)
        Surveyed edges.
    grid_top : float
        Surveyed elevation of those edges' tops (mean), nan without elevations.
    time : float or None
        When the scanner saw it (median time of its points).
    points : int
        Points on its panels.
    grid_var : ndarray, shape (k,), optional
        The survey's variance of each observed edge's coordinates (its ``sigma_m``
        squared); None: the adjustment's one ``survey_sigma_m`` for every edge.
    """

    beacon: str
    edges: tuple[int, ...]
    cloud_xy: NDArray[np.float64]
    cloud_cov: NDArray[np.float64]
    top: float
    sigma_top: float
    grid_xy: NDArray[np.float64]
    grid_top: float
    time: float | None = None
    points: int = 0
    grid_var: NDArray[np.float64] | None = None

    def survey_var(self, s2: float) -> NDArray[np.float64]:
        """Each observed edge's surveyed variance: :attr:`grid_var`, or ``s2`` for all."""
        return np.full(len(self.edges), s2) if self.grid_var is None else self.grid_var

    def moved(self, cloud_xy: NDArray[np.float64], top: float) -> BeaconObs:
        return replace(self, cloud_xy=cloud_xy, top=top)


@dataclass(frozen=True, eq=False)
class Transformation:
    """``grid = scale * R @ (cloud - centre) + translation`` with its covariance.

    ``params`` are named in :attr:`names`; ``rotation`` is the 3x3 matrix.
    """

    model: str
    names: tuple[str, ...]
    params: NDArray[np.float64]
    covariance: NDArray[np.float64]
    centre: NDArray[np.float64]
    heights: bool

    @property
    def rotation(self) -> NDArray[np.float64]:
        return _rotation(self.model, self.params)

    @property
    def scale(self) -> float:
        return float(self.params[6]) if self.model == "helmert7" else 1.0

    @property
    def translation(self) -> NDArray[np.float64]:
        """The grid point of :attr:`centre` (without heights z is kept: centre and
        elevation offset are 0)."""
        return np.array(self.params[:3], dtype=float)

    def apply(self, xyz: NDArray[np.float64]) -> NDArray[np.float64]:
        out: NDArray[np.float64] = (
            self.scale * (xyz - self.centre) @ self.rotation.T + self.translation
        )
        return out

    def to_cloud(self, xyz: NDArray[np.float64]) -> NDArray[np.float64]:
        """Grid points in the cloud's frame (the inverse of :meth:`apply`)."""
        out: NDArray[np.float64] = (xyz - self.translation) @ self.rotation / self.scale + (
            self.centre
        )
        return out

    def matrix(self) -> NDArray[np.float64]:
        """The 4x4 homogeneous matrix, cloud to grid."""
        m = np.eye(4)
        sr = self.scale * self.rotation
        m[:3, :3] = sr
        m[:3, 3] = self.translation - sr @ self.centre
        return m

    @property
    def rotation_deg(self) -> float:
        """Rotation about the vertical, counter-clockwise from cloud x to easting."""
        r = self.rotation
        return math.degrees(math.atan2(r[1, 0], r[0, 0]))


def _rotation(model: str, p: NDArray[np.float64]) -> NDArray[np.float64]:
    if model == "4":
        c, s = math.cos(p[3]), math.sin(p[3])
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    # helmert7: rotation vector (omega, phi, kappa) about x, y, z (Rodrigues)
    w = np.asarray(p[3:6], dtype=float)
    th = float(np.linalg.norm(w))
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-12:
        return np.asarray(np.eye(3) + k, dtype=float)
    k /= th
    return np.asarray(np.eye(3) + math.sin(th) * k + (1 - math.cos(th)) * (k @ k), dtype=float)


@dataclass(frozen=True, eq=False)
class Solution:
    """An adjusted transformation and its statistics.

    Attributes
    ----------
    transformation : Transformation
    used : list of BeaconObs
        The control beacons it rests on.
    excluded : list of str
        Control beacons named as outliers and left out.
    residuals : dict[str, ndarray]
        Per beacon: ``(k, 3)`` residuals (E, N, Z; Z nan without heights), grid
        minus transformed cloud... written as transformed minus surveyed.
    w : dict[str, ndarray]
        Per beacon, the w-test statistic of each residual coordinate.
    tests : list of BeaconTest
    reference_variance : float
    dof : int
    chi2_test : str
        ``pass``, ``too_small`` or ``too_large``.
    chi2_bounds : tuple of float
        The test's acceptance interval for the reference variance.
    w_critical : float
        Critical value of the w-tests.
    scaled : bool
        The global test failed (too large) with no beacon to blame: the
        transformation's covariance is scaled by the reference variance.
    """

    transformation: Transformation
    used: list[BeaconObs]
    excluded: list[str]
    residuals: dict[str, NDArray[np.float64]]
    w: dict[str, NDArray[np.float64]]
    tests: list[BeaconTest[str]]
    reference_variance: float
    dof: int
    chi2_test: str
    chi2_bounds: tuple[float, float]
    w_critical: float = field(default=0.0)
    scaled: bool = False


class AdjustmentError(Exception):
    """The beacons cannot give a trustworthy transformation; ``reason`` and ``detail``."""

    def __init__(self, reason: str, detail: str, suspects: Sequence[str] = ()):
        self.reason = reason
        self.detail = detail
        self.suspects = list(suspects)
        super().__init__(f"{reason}: {detail}")


def _names(model: str) -> tuple[str, ...]:
    if model == "helmert7":
        return (
            "easting_m",
            "northing_m",
            "elevation_m",
            "omega_rad",
            "phi_rad",
            "kappa_rad",
            "scale",
        )
    return ("easting_m", "northing_m", "elevation_m", "rotation_rad")


def _free(model: str, heights: bool) -> NDArray[np.bool_]:
    """The parameters estimated: without heights the elevation offset stays 0."""
    free = np.ones(7 if model == "helmert7" else 4, bool)
    if model == "4" and not heights:
        free[2] = False
    return free


def _stack(
    obs: Sequence[BeaconObs], model: str, heights: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64], list[tuple[int, int, str]]]:
    """Cloud points (n, 3), surveyed points (n, 3) and, per beacon, its rows."""
    cloud, grid, rows = [], [], []
    r = 0
    for b in obs:
        k = len(b.edges)
        z = b.top if heights else 0.0
        gz = b.grid_top if heights else 0.0
        cloud.append(np.column_stack([b.cloud_xy, np.full(k, z)]))
        grid.append(np.column_stack([b.grid_xy, np.full(k, gz)]))
        rows.append((r, r + k, b.beacon))
        r += k
    return np.concatenate(cloud), np.concatenate(grid), rows


def _residual_vector(
    obs: Sequence[BeaconObs],
    model: str,
    heights: bool,
    p: NDArray[np.float64],
    centre: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Transformed cloud minus surveyed, stacked per beacon: E, N of each edge, then the
    height once (4-parameter) or E, N, Z of each edge (helmert7)."""
    scale = float(p[6]) if model == "helmert7" else 1.0
    rot = _rotation(model, p)
    out = []
    for b in obs:
        k = len(b.edges)
        z = b.top if heights else centre[2]
        x = np.column_stack([b.cloud_xy, np.full(k, z)])
        g = scale * (x - centre) @ rot.T + p[:3]
        d = g - np.column_stack([b.grid_xy, np.full(k, b.grid_top if heights else g[0, 2])])
        if model == "helmert7":
            out.append(d.reshape(-1))
        else:
            out.append(d[:, :2].reshape(-1))
            if heights:
                out.append(d[:1, 2])
    return np.concatenate(out)


def _covariance(
    obs: Sequence[BeaconObs],
    model: str,
    heights: bool,
    p: NDArray[np.float64],
    survey_sigma_m: float,
) -> tuple[NDArray[np.float64], list[tuple[int, int]]]:
    """Covariance of the residual vector (cloud rotated into the grid, plus the survey)
    and each beacon's block of rows."""
    scale = float(p[6]) if model == "helmert7" else 1.0
    rot = _rotation(model, p)
    blocks, spans = [], []
    r = 0
    s2 = survey_sigma_m**2
    for b in obs:
        k = len(b.edges)
        if model == "helmert7":
            c = np.zeros((3 * k, 3 * k))
            xy = np.flatnonzero(np.arange(3 * k) % 3 != 2)
            c[np.ix_(xy, xy)] = b.cloud_cov
            zi = np.arange(k) * 3 + 2
            c[np.ix_(zi, zi)] = b.sigma_top**2  # one top for all its edges
            big = np.kron(np.eye(k), rot * scale)
            c = big @ c @ big.T + np.diag(np.repeat(b.survey_var(s2), 3))
            # the surveyed tops of one beacon: one level each, independent
        else:
            m = 2 * k + (1 if heights else 0)
            c = np.zeros((m, m))
            r2 = rot[:2, :2]
            sv = b.survey_var(s2)
            turn = np.kron(np.eye(k), r2)
            c[: 2 * k, : 2 * k] = turn @ b.cloud_cov @ turn.T + np.diag(np.repeat(sv, 2))
            if heights:
                # the mean of the observed edges' surveyed tops
                c[-1, -1] = b.sigma_top**2 + float(np.sum(sv)) / k**2
        blocks.append(c)
        spans.append((r, r + c.shape[0]))
        r += c.shape[0]
    size = r
    full = np.zeros((size, size))
    for (a, e), c in zip(spans, blocks, strict=True):
        full[a:e, a:e] = c
    return full, spans


def _solve(
    obs: Sequence[BeaconObs],
    model: str,
    heights: bool,
    survey_sigma_m: float,
    start: NDArray[np.float64] | None = None,
) -> Solution:
    cloud, grid, _ = _stack(obs, model, heights)
    centre = cloud.mean(axis=0)
    if not heights:
        centre[2] = 0.0
    names = _names(model)
    # start: the plan's rigid fit, heights from the mean offset
    a = cloud[:, :2] - centre[:2]
    g = grid[:, :2] - grid[:, :2].mean(axis=0)
    rot0 = math.atan2(float(np.sum(a[:, 0] * g[:, 1] - a[:, 1] * g[:, 0])), float(np.sum(a * g)))
    t0 = grid.mean(axis=0)
    if start is not None:
        p = start.copy()
    elif model == "helmert7":
        p = np.array([t0[0], t0[1], t0[2], 0.0, 0.0, rot0, 1.0])
    else:
        p = np.array([t0[0], t0[1], t0[2] if heights else 0.0, rot0])
    free = _free(model, heights)
    for _ in range(20):
        v = _residual_vector(obs, model, heights, p, centre)
        cov, _ = _covariance(obs, model, heights, p, survey_sigma_m)
        jac = _jacobian(lambda q: _residual_vector(obs, model, heights, q, centre), p)[:, free]
        chol = np.linalg.cholesky(cov)
        aw = np.linalg.solve(chol, jac)
        vw = np.linalg.solve(chol, v)
        step, *_ = np.linalg.lstsq(aw, -vw, rcond=None)
        p[free] += step
        if np.max(np.abs(step)) < 1e-12 * max(1.0, float(np.max(np.abs(p)))):
            break
    v = _residual_vector(obs, model, heights, p, centre)
    cov, spans = _covariance(obs, model, heights, p, survey_sigma_m)
    jac = _jacobian(lambda q: _residual_vector(obs, model, heights, q, centre), p)[:, free]
    pinv = np.linalg.inv(cov)
    n_mat = jac.T @ pinv @ jac
    qxx = np.linalg.inv(n_mat)
    omega = float(v @ pinv @ v)
    dof = v.size - int(free.sum())
    s0 = omega / dof if dof > 0 else math.nan
    lo, hi = variance_bounds(dof)
    test = "pass" if lo <= s0 <= hi or dof == 0 else ("too_small" if s0 < lo else "too_large")
    qvv = cov - jac @ qxx @ jac.T
    pv = pinv @ v
    pqp = pinv @ qvv @ pinv
    w = pv / np.sqrt(np.maximum(np.diag(pqp), 1e-30))
    residuals: dict[str, NDArray[np.float64]] = {}
    ws: dict[str, NDArray[np.float64]] = {}
    tests: list[BeaconTest[str]] = []
    for b, (r0, r1) in zip(obs, spans, strict=True):
        residuals[b.beacon] = _per_edge(v[r0:r1], model, heights, len(b.edges))
        ws[b.beacon] = w[r0:r1]
        block = pqp[r0:r1, r0:r1]
        try:
            stat = float(pv[r0:r1] @ np.linalg.solve(block, pv[r0:r1]))
        except np.linalg.LinAlgError:
            stat = math.inf
        k = r1 - r0
        # a beacon left out of a solution of dof = k or less is not testable
        if dof - k > 0:
            tests.append(BeaconTest(b.beacon, stat, k, beacon_critical(W_TEST_ALPHA / len(obs), k)))
    qfull = np.zeros((p.size, p.size))
    qfull[np.ix_(free, free)] = qxx
    trans = Transformation(model, names, p, qfull, centre, heights)
    return Solution(
        trans,
        list(obs),
        [],
        residuals,
        ws,
        tests,
        s0,
        dof,
        test,
        (lo, hi),
        w_critical(v.size),
    )


def _per_edge(v: NDArray[np.float64], model: str, heights: bool, k: int) -> NDArray[np.float64]:
    """Residuals of one beacon as (k, 3): E, N, Z per edge."""
    if model == "helmert7":
        return v.reshape(k, 3)
    out = np.full((k, 3), math.nan)
    out[:, :2] = v[: 2 * k].reshape(k, 2)
    if heights:
        out[:, 2] = v[-1]
    return out


def _jacobian(
    f: Callable[[NDArray[np.float64]], NDArray[np.float64]], p: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Central differences (the models are smooth and small)."""
    base = f(p)
    jac = np.empty((base.size, p.size))
    for i in range(p.size):
        h = 1e-6 * max(1.0, abs(float(p[i]))) if i < 3 else 1e-7
        up, dn = p.copy(), p.copy()
        up[i] += h
        dn[i] -= h
        jac[:, i] = (f(up) - f(dn)) / (2 * h)
    return jac


def adjust_transformation(
    obs: Sequence[BeaconObs],
    *,
    model: str = "4",
    survey_sigma_m: float,
    heights: bool,
) -> Solution:
    """Adjust, test, and leave out one beacon at a time that alone spoils the rest.

    Raises
    ------
    AdjustmentError
        ``too_few`` below two beacons (three for ``helmert7``); ``inconsistent``
        when the beacons disagree and no single one is to blame.
    """
    need = 3 if model == "helmert7" else 2
    obs = list(obs)
    if model == "helmert7" and not heights:
        raise AdjustmentError(
            "no_heights", "helmert7 needs surveyed elevations (no elevation column)"
        )
    if len(obs) < need:
        raise AdjustmentError(
            "too_few", f"{len(obs)} control beacon(s) found; the {_label(model)} needs {need}"
        )
    try:
        sol = _solve(obs, model, heights, survey_sigma_m)
    except np.linalg.LinAlgError:
        raise AdjustmentError(
            "weak_geometry",
            f"the {len(obs)} beacons do not fix the {_label(model)} (all in a line?)",
        ) from None
    free = _free(model, heights)
    if not np.all(np.isfinite(sol.transformation.covariance)) or (
        np.linalg.cond(sol.transformation.covariance[np.ix_(free, free)]) > 1e14
    ):
        raise AdjustmentError(
            "weak_geometry",
            f"the {len(obs)} beacons barely fix the {_label(model)} (all in a line?)",
        )
    excluded: list[str] = []
    while any(t.failed for t in sol.tests):
        culprits = []
        for b in sol.used:
            rest = [o for o in sol.used if o.beacon != b.beacon]
            if len(rest) < need:
                continue
            alt = _solve(rest, model, heights, survey_sigma_m)
            if not any(t.failed for t in alt.tests):
                culprits.append(b.beacon)
        if len(culprits) != 1:
            suspects = culprits or [t.beacon for t in sol.tests if t.failed]
            raise AdjustmentError(
                "inconsistent",
                "the beacons do not fit one transformation and no single beacon is to blame "
                f"(reference variance {sol.reference_variance:.3g}); suspects: "
                f"{', '.join(suspects) or 'all'}. A cloud that drifts needs --trajectory",
                suspects,
            )
        excluded.append(culprits[0])
        sol = _solve(
            [o for o in sol.used if o.beacon != culprits[0]], model, heights, survey_sigma_m
        )
    if sol.chi2_test == "too_large":
        # No beacon stands out, yet together they scatter more than their precisions
        # say: the precisions were optimistic. As mast locate does, the covariance is
        # scaled by the reference variance, and the report says so.
        t = sol.transformation
        sol = replace(
            sol,
            transformation=replace(t, covariance=t.covariance * sol.reference_variance),
            scaled=True,
        )
    return replace(sol, excluded=excluded)


def rigid_solution(
    obs: Sequence[BeaconObs], model: str, survey_sigma_m: float, heights: bool
) -> Solution:
    """The least-squares solution over every beacon, tests as they come (no exclusion)."""
    return _solve(list(obs), model, heights, survey_sigma_m)


def _label(model: str) -> str:
    return "3D similarity (helmert7)" if model == "helmert7" else "4-parameter transformation"


@dataclass(frozen=True, eq=False)
class CheckResult:
    """A check beacon compared with the survey: residuals (transformed minus surveyed,
    per edge, E N Z), their standard deviations and the worst w."""

    beacon: str
    residuals: NDArray[np.float64]
    sigmas: NDArray[np.float64]
    max_abs_w: float
    critical: float

    @property
    def horizontal_m(self) -> float:
        return float(np.max(np.hypot(self.residuals[:, 0], self.residuals[:, 1])))

    @property
    def failed(self) -> bool:
        return self.max_abs_w > self.critical


def check_beacons(
    sol: Solution, checks: Sequence[BeaconObs], *, survey_sigma_m: float
) -> list[CheckResult]:
    """Compare check beacons, kept out of the solution, with the survey."""
    trans = sol.transformation
    model, heights = trans.model, trans.heights
    p = trans.params
    free = _free(model, heights)
    out = []
    n_all = sum(len(c.edges) * (3 if heights else 2) for c in checks)
    crit = w_critical(n_all)
    for c in checks:
        v = _residual_vector([c], model, heights, p, trans.centre)
        cov, _ = _covariance([c], model, heights, p, survey_sigma_m)

        def of(q: NDArray[np.float64], c: BeaconObs = c) -> NDArray[np.float64]:
            return _residual_vector([c], model, heights, q, trans.centre)

        jac = _jacobian(of, p)[:, free]
        qxx = trans.covariance[np.ix_(free, free)]
        total = cov + jac @ qxx @ jac.T
        sig = np.sqrt(np.diag(total))
        w = v / sig
        out.append(
            CheckResult(
                c.beacon,
                _per_edge(v, model, heights, len(c.edges)),
                _per_edge(sig, model, heights, len(c.edges)),
                float(np.max(np.abs(w))),
                crit,
            )
        )
    return out
