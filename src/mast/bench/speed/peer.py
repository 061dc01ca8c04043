"""The peer: small_gicp's point-to-plane ICP on the same scans' beacon returns."""

from __future__ import annotations

import importlib
import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.bench.speed.model import (
    PEER_EPSILON,
    PEER_HEIGHTS_M,
    PEER_MAX_CORRESPONDENCE_M,
    PEER_MAX_ITERATIONS,
    PEER_NEIGHBOURS,
    PEER_OFFSET_M,
    PEER_STEP_M,
    PEER_TURN_DEG,
    PeerSpeed,
    Stats,
)
from mast.bench.speed.scans import KeptScans, pose_errors
from mast.core.beacon import Survey
from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D

__all__ = ["measure_peer", "peer_align", "peer_module", "peer_target"]


def peer_module() -> Any:
    """small_gicp, or ``None`` when it is not installed."""
    try:
        return importlib.import_module("small_gicp")
    except ImportError:
        return None


def _panel_model(survey: Survey) -> NDArray[np.float64]:
    """The surveyed panels as 3D points: every ``PEER_STEP_M`` along, at ``PEER_HEIGHTS_M``."""
    panels = PanelSet.from_survey(survey)
    rows = []
    for a, b, length in zip(panels.a, panels.b, panels.length, strict=True):
        t = np.linspace(0.0, 1.0, max(2, math.ceil(length / PEER_STEP_M) + 1))
        rows.append(a + t[:, None] * (b - a))
    xy = np.vstack(rows)
    z = np.asarray(PEER_HEIGHTS_M)
    return np.column_stack([np.repeat(xy, z.size, axis=0), np.tile(z, len(xy))])


def _matrix(pose: Pose2D) -> NDArray[np.float64]:
    """4x4 transform taking scanner-frame points (z = 0) to the mine frame."""
    m = np.eye(4)
    m[:2, :2] = pose.rotation()
    m[:2, 3] = pose.position
    return m


def _pose_of(m: NDArray[np.float64]) -> Pose2D:
    # Pose2D.rotation: [[sin A, -cos A], [cos A, sin A]]
    return Pose2D(float(m[0, 3]), float(m[1, 3]), math.atan2(m[0, 0], m[1, 0]))


def peer_align(
    sg: Any, target: Any, tree: Any, source: NDArray[np.float64], start: Pose2D
) -> tuple[float, Pose2D, bool]:
    """The peer aligning scanner-frame ``source`` points to the panel model from
    ``start``: its milliseconds, the pose it ends at, and whether it converged."""
    lifted = np.column_stack([source, np.zeros(len(source))])
    t1 = time.perf_counter()
    cloud = sg.PointCloud(lifted)
    result = sg.align(
        target,
        cloud,
        tree,
        init_T_target_source=_matrix(start),
        registration_type="PLANE_ICP",
        max_correspondence_distance=PEER_MAX_CORRESPONDENCE_M,
        num_threads=1,
        max_iterations=PEER_MAX_ITERATIONS,
        rotation_epsilon=PEER_EPSILON,
        translation_epsilon=PEER_EPSILON,
    )
    ms = 1e3 * (time.perf_counter() - t1)
    return ms, _pose_of(np.asarray(result.T_target_source)), bool(result.converged)


def peer_target(survey: Survey, sg: Any) -> tuple[Any, Any, float]:
    """The peer's model of the surveyed panels, its tree, and milliseconds to build."""
    t0 = time.perf_counter()
    target = sg.PointCloud(_panel_model(survey))
    tree = sg.KdTree(target, 1)
    sg.estimate_normals(target, tree, PEER_NEIGHBOURS, 1)
    return target, tree, 1e3 * (time.perf_counter() - t0)


def measure_peer(kept: KeptScans, *, seed: int = 0) -> PeerSpeed | None:
    """The peer on the scans ``locate`` fixed, beside ``locate``'s own figures on them;
    ``None`` when small_gicp is not installed."""
    sg = peer_module()
    if sg is None:
        return None
    rng = np.random.default_rng([seed, 23])
    target, tree, build_ms = peer_target(kept.survey, sg)
    times, pos, az, mast_t, mast_pos, mast_az = [], [], [], [], [], []
    converged = 0
    for sim, fix, dt in zip(kept.sims, kept.fixes, kept.seconds, strict=True):
        if not (fix.ok and fix.pose is not None):
            continue
        beams, points = sim.scan.points()
        source = points[sim.beacon_mask()[beams]]
        if len(source) < 3:
            continue
        truth = sim.pose
        heading = float(rng.uniform(0.0, math.tau))
        turn = math.radians(PEER_TURN_DEG) * float(rng.choice([-1.0, 1.0]))
        start = Pose2D(
            truth.easting + PEER_OFFSET_M * math.cos(heading),
            truth.northing + PEER_OFFSET_M * math.sin(heading),
            truth.azimuth + turn,
        )
        ms, got, ok = peer_align(sg, target, tree, source, start)
        times.append(ms)
        converged += ok
        p, a = pose_errors(truth, got)
        pos.append(p)
        az.append(a)
        mp, ma = pose_errors(truth, fix.pose)
        mast_t.append(1e3 * dt)
        mast_pos.append(mp)
        mast_az.append(ma)
    version = getattr(sg, "__version__", None) or _dist_version("small_gicp")
    return PeerSpeed(
        library=f"small_gicp {version}",
        scans=len(times),
        model_points=int(target.size()),
        model_build_ms=build_ms,
        time_ms=Stats.of(times),
        position_err_mm=Stats.of(pos),
        azimuth_err_arcsec=Stats.of(az),
        converged=converged / len(times) if times else math.nan,
        mast_time_ms=Stats.of(mast_t),
        mast_position_err_mm=Stats.of(mast_pos),
        mast_azimuth_err_arcsec=Stats.of(mast_az),
    )


def _dist_version(name: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "(version unknown)"
