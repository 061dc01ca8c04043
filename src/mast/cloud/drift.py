"""SLAM drift corrected between beacons: a pose graph over the cloud's own trajectory.

The trajectory (TUM, or the ``mast track`` CSV) gives the scanner's pose in
the cloud's frame over time. Keyframes are taken every ``step_m`` of travel;
consecutive keyframes are joined by the SLAM's own relative pose as a GTSAM
between factor whose standard deviation is the stated drift model (see
:data:`HEADING_PER_ROOT_M`): ``drift`` of each step in position, and a
heading random walk of a tenth of ``drift`` per square root of a metre. Every
control beacon pins the keyframe at the time it was seen: its edges, in that
keyframe's body frame, must land on the surveyed edges (a custom factor, the
edges' covariance rotated into the grid plus the survey's). Heights are a
separate 1D chain of offsets with the same drift per metre, pinned by the
beacons' tops.

Every point is then moved by the correction of the trajectory at its time,
``C(t) = X(t) X_slam(t)^-1``, interpolated between keyframes; the rigid
transformation is where the graph starts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.cloud.adjust import BeaconObs, Transformation
from mast.errors import InputError

__all__ = ["DriftCorrection", "Trajectory", "correct_drift", "read_trajectory"]

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


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Scanner poses in the cloud's frame: times (s), x, y, z and yaw (radians, from x)."""

    time: NDArray[np.float64]
    xyz: NDArray[np.float64]
    yaw: NDArray[np.float64]
    path: Path


def read_trajectory(path: str | Path) -> Trajectory:
    """Read a TUM file (``t x y z qx qy qz qw``) or a ``mast track`` trajectory CSV."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read: {err}", path=p) from None
    lines = text.splitlines()
    first = next((ln for ln in lines if ln.strip() and not ln.startswith("#")), "")
    if first.startswith("stamp_ns"):
        return _read_track_csv(p, lines)
    rows = []
    for no, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 8:
            raise InputError(
                f"a TUM pose has 8 numbers (t x y z qx qy qz qw), this line {len(parts)}",
                path=p,
                line=no,
            )
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            raise InputError("not a number in a TUM pose", path=p, line=no) from None
        if not all(math.isfinite(v) for v in vals):
            raise InputError("a TUM pose with a value that is not finite", path=p, line=no)
        rows.append(vals)
    return _trajectory(p, np.array(rows).reshape(-1, 8))


def _trajectory(p: Path, a: NDArray[np.float64]) -> Trajectory:
    if a.shape[0] < 2:
        raise InputError("a trajectory needs at least two poses", path=p)
    t = a[:, 0]
    if np.any(np.diff(t) <= 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 2
        raise InputError(f"times must increase (pose {bad} does not)", path=p)
    qx, qy, qz, qw = a[:, 4], a[:, 5], a[:, 6], a[:, 7]
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2))
    return Trajectory(t, a[:, 1:4].copy(), np.unwrap(yaw), p)


def _read_track_csv(p: Path, lines: list[str]) -> Trajectory:
    import csv

    reader = csv.DictReader(lines)
    rows = []
    for no, row in enumerate(reader, 2):
        try:
            t = int(row["stamp_ns"]) * 1e-9
            e, n, az = float(row["easting"]), float(row["northing"]), float(row["azimuth_deg"])
        except (KeyError, TypeError, ValueError):
            raise InputError(
                "a track trajectory row needs stamp_ns, easting, northing, azimuth_deg",
                path=p,
                line=no,
            ) from None
        yaw = math.pi / 2 - math.radians(az)
        rows.append([t, e, n, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])
    return _trajectory(p, np.array(rows).reshape(-1, 8))


@dataclass(frozen=True, eq=False)
class DriftCorrection:
    """The correction ``C(t)`` at the keyframes: rotation, translation (grid = R p + t) and
    height offset; with the residuals at the beacons after it."""

    time: NDArray[np.float64]
    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    dz: NDArray[np.float64]
    drift: float
    step_m: float
    residuals: dict[str, NDArray[np.float64]]
    heights: bool

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

    def at_beacon(self, obs: BeaconObs) -> NDArray[np.float64]:
        """The beacon's edges (E, N, Z of its top) after the correction at its time."""
        k = len(obs.edges)
        t = np.full(k, obs.time if obs.time is not None else self.time[0])
        xyz = np.column_stack([obs.cloud_xy, np.full(k, obs.top)])
        return self.apply(xyz, t)


def _pose_at(traj: Trajectory, t: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.column_stack(
        [
            np.interp(t, traj.time, traj.xyz[:, 0]),
            np.interp(t, traj.time, traj.xyz[:, 1]),
            np.interp(t, traj.time, traj.yaw),
        ]
    )


def correct_drift(
    traj: Trajectory,
    controls: Sequence[BeaconObs],
    rigid: Transformation,
    *,
    drift: float,
    survey_sigma_m: float,
    heights: bool,
    step_m: float = 1.0,
) -> DriftCorrection:
    """Solve the pose graph (module docstring) and the correction at every keyframe."""
    import gtsam

    timed = [o for o in controls if o.time is not None]
    if len(timed) < 2:
        raise InputError(
            "the drift correction needs two control beacons seen at known times "
            "(the cloud's points need a time)",
            path=traj.path,
        )
    # keyframes every step_m of travel, plus each beacon's time
    d = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(traj.xyz[:, :2], axis=0).T))])
    marks = np.arange(0.0, d[-1] + step_m, step_m)
    t_key = np.interp(marks, d, traj.time)
    t_beacons = np.array([o.time for o in timed], dtype=float)
    if t_beacons.min() < traj.time[0] - 1.0 or t_beacons.max() > traj.time[-1] + 1.0:
        raise InputError(
            f"the trajectory's times ({traj.time[0]:.3f} to {traj.time[-1]:.3f} s) do not "
            f"cover the beacons' ({t_beacons.min():.3f} to {t_beacons.max():.3f} s): "
            "is it the trajectory of this cloud, in the same time base?",
            path=traj.path,
        )
    t_key = np.unique(np.concatenate([t_key, np.clip(t_beacons, traj.time[0], traj.time[-1])]))
    slam = _pose_at(traj, t_key)
    dist = np.interp(t_key, traj.time, d)
    rot0 = math.radians(rigid.rotation_deg)
    c0, s0 = math.cos(rot0), math.sin(rot0)
    r0 = np.array([[c0, -s0], [s0, c0]])
    t0 = rigid.translation[:2] - r0 @ rigid.centre[:2]

    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    poses = [gtsam.Pose2(*p) for p in slam]
    for k, p in enumerate(slam):
        xy = r0 @ p[:2] + t0
        values.insert(k, gtsam.Pose2(float(xy[0]), float(xy[1]), float(p[2] + rot0)))
    for k in range(len(poses) - 1):
        step = max(float(dist[k + 1] - dist[k]), 1e-3)
        sig = np.array(
            [
                SCALE_SHARE * drift * step + 1e-4,
                SCALE_SHARE * drift * step + 1e-4,
                HEADING_PER_ROOT_M * drift * math.sqrt(step) + 1e-6,
            ]
        )
        graph.add(
            gtsam.BetweenFactorPose2(
                k,
                k + 1,
                poses[k].between(poses[k + 1]),
                gtsam.noiseModel.Diagonal.Sigmas(sig),
            )
        )
    key_of = {float(t): k for k, t in enumerate(t_key)}
    s2 = survey_sigma_m**2
    for o in timed:
        tb = float(np.clip(o.time, traj.time[0], traj.time[-1]))  # type: ignore[arg-type]
        k = key_of[tb]
        body = poses[k]
        for i in range(len(o.edges)):
            q = body.transformTo(np.asarray(o.cloud_xy[i], dtype=float))
            cov = o.cloud_cov[i]
            rb = np.array(
                [
                    [math.cos(body.theta()), -math.sin(body.theta())],
                    [math.sin(body.theta()), math.cos(body.theta())],
                ]
            )
            cov_body = rb.T @ cov @ rb
            graph.add(_edge_factor(k, np.asarray(q, dtype=float), o.grid_xy[i], cov_body, s2))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    params.setMaxIterations(100)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    rot = np.empty(len(poses))
    trans = np.empty((len(poses), 2))
    for k, p in enumerate(poses):
        x = result.atPose2(k)
        corr = x.compose(p.inverse())
        rot[k] = corr.theta()
        trans[k] = [corr.x(), corr.y()]
    rot = np.unwrap(rot)
    dz = _height_chain(t_key, dist, timed, drift, s2, rigid) if heights else np.zeros(len(t_key))
    corr_ = DriftCorrection(t_key, rot, trans, dz, drift, step_m, {}, heights)
    res = {}
    for o in controls:
        g = corr_.at_beacon(o)
        res[o.beacon] = g - np.column_stack(
            [o.grid_xy, np.full(len(o.edges), o.grid_top if heights else g[0, 2])]
        )
    return DriftCorrection(t_key, rot, trans, dz, drift, step_m, res, heights)


def _edge_factor(
    key: int, q: NDArray[np.float64], g: NDArray[np.float64], cov: NDArray[np.float64], s2: float
) -> Any:
    """``X(key) * q = g``: an edge seen at ``q`` in the keyframe's body frame is surveyed
    at ``g``."""
    import gtsam

    noise = gtsam.noiseModel.Gaussian.Covariance(cov + s2 * np.eye(2))

    def error(
        this: object, v: object, jac: list[NDArray[np.float64]] | None
    ) -> NDArray[np.float64]:
        x = v.atPose2(this.keys()[0])  # type: ignore[attr-defined]
        c, s = math.cos(x.theta()), math.sin(x.theta())
        r = np.array([[c, -s], [s, c]])
        e: NDArray[np.float64] = r @ q + np.array([x.x(), x.y()]) - g
        if jac is not None:
            jac[0] = np.column_stack([r, r @ np.array([-q[1], q[0]])])
        return e

    return gtsam.CustomFactor(noise, [key], error)


def _height_chain(
    t_key: NDArray[np.float64],
    dist: NDArray[np.float64],
    timed: Sequence[BeaconObs],
    drift: float,
    s2: float,
    rigid: Transformation,
) -> NDArray[np.float64]:
    """Height offsets at the keyframes: a random walk of ``drift`` per metre pinned by
    the beacons' tops (sparse least squares)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

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
        w.append(1.0 / math.sqrt(o.sigma_top**2 + s2))
    wv = np.array(w)
    a = coo_matrix((np.array(vals) * wv[rows], (rows, cols)), shape=(len(rhs), n)).tocsr()
    b = np.array(rhs) * wv
    out: NDArray[np.float64] = np.asarray(spsolve((a.T @ a).tocsc(), a.T @ b), dtype=float)
    return out
