"""A 3D frame seen from above is the 2D scan of the plan view: the paper's layout
ray-cast by a 16-ring lidar (vertical walls, vertical panels with their top edges),
projected by :func:`plan_scan`, is fixed by the 2D pipeline where the sensor stands."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from mast.core.pose3d import Frame3D, Pose3D, rotation_rpy
from mast.pipeline.locator import LocatorConfig, locate
from mast.pipeline.plan_view import level_rotation, plan_scan
from mast.sim.scenarios import paper_scene

RINGS_DEG = np.arange(-15.0, 16.0, 2.0)  # a VLP-16's


def _segments(scene_variant: str) -> tuple[list[tuple[NDArray[np.float64], ...]], object]:
    scene = paper_scene(scene_variant)
    walls = []
    for b in scene.survey:
        top = float(b.elevations[0]) if b.elevations is not None else 1.5
        for k in range(3):  # each panel: a vertical rectangle 0.8 m tall below its top
            walls.append((b.edges[k], b.edges[k + 1], top - 0.8, top))
    for b in scene.survey:  # each beacon's wall runs through its free ends e1 and e4
        e1, e4 = b.edges[0], b.edges[3]
        t = (e4 - e1) / np.linalg.norm(e4 - e1)
        walls.append((e1 - 40 * t, e1 + 40 * t, -10.0, 10.0))
    return walls, scene


def _cast(pose: Pose3D, walls: list, noise_m: float, seed: int) -> Frame3D:
    """Every ring's rays from the sensor at ``pose``, the nearest vertical rectangle hit."""
    rng = np.random.default_rng(seed)
    az = np.radians(np.arange(-180.0, 180.0, 0.2))
    el = np.radians(RINGS_DEG)
    A, E = np.meshgrid(az, el)
    d_sensor = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(
        -1, 3
    )
    d = d_sensor @ pose.rotation.T
    o = pose.position
    best = np.full(len(d), np.inf)
    for a, b, zlo, zhi in walls:
        u = b - a
        den = d[:, 0] * (-u[1]) - d[:, 1] * (-u[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            rx, ry = a[0] - o[0], a[1] - o[1]
            t = (rx * (-u[1]) - ry * (-u[0])) / den
            s = (d[:, 0] * ry - d[:, 1] * rx) / den
        z = o[2] + t * d[:, 2]
        hit = (t > 0.05) & (s >= 0) & (s <= 1) & (z >= zlo) & (z <= zhi) & (t < best)
        best[hit] = t[hit]
    ok = np.isfinite(best) & (best < 30.0)
    r = best[ok] + rng.normal(0.0, noise_m, int(ok.sum()))
    return Frame3D(d_sensor[ok] * r[:, None])


@pytest.mark.parametrize(
    ("variant", "pitch_deg", "roll_deg"),
    [("parallel", 0.0, 0.0), ("convergent", 6.0, -4.0), ("divergent", -8.0, 10.0)],
)
def test_a_frame_seen_from_above_is_fixed_by_the_2d_pipeline(
    variant: str, pitch_deg: float, roll_deg: float
) -> None:
    walls, scene = _segments(variant)
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, pitch_deg, roll_deg)
    frame = _cast(truth, walls, noise_m=0.01, seed=3)
    # levelled by the true vertical (the tilt estimate is the 3D locator's own step)
    up = truth.rotation.T @ np.array([0.0, 0.0, 1.0])
    scan = plan_scan(frame, up=up)
    fix = locate(scan, scene.survey, config=LocatorConfig(range_sigma_m=0.01))
    assert fix.ok, fix.detail
    assert fix.pose is not None
    assert math.hypot(fix.pose.easting - 7.0, fix.pose.northing - 7.0) < 0.01
    turn = (fix.pose.azimuth_deg + 180.0) % 360.0 - 180.0
    assert abs(turn) < 0.1


@pytest.mark.parametrize(("roll", "pitch", "yaw"), [(0.1, -0.07, 0.0), (-0.17, 0.17, 2.0)])
def test_levelling_is_ry_rx_turning_up_onto_z_and_keeping_the_heading(
    roll: float, pitch: float, yaw: float
) -> None:
    R = rotation_rpy(roll, pitch, yaw)
    up = R.T @ np.array([0.0, 0.0, 1.0])
    L = level_rotation(up)
    assert L @ up == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert np.allclose(L @ L.T, np.eye(3), atol=1e-12)
    assert np.allclose(L, rotation_rpy(roll, pitch, 0.0), atol=1e-12)
    assert level_rotation([0.0, 0.0, 2.0]) == pytest.approx(np.eye(3))
