"""A 3D frame seen from above is the 2D scan of the plan view: the paper's layout
ray-cast by a 16-ring lidar (vertical walls, vertical panels with their top edges),
projected by :func:`plan_scan`, is fixed by the 2D pipeline where the sensor stands."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.core.pose3d import Pose3D, rotation_rpy
from mast.pipeline.locator import LocatorConfig, locate
from mast.pipeline.plan_view import level_rotation, plan_scan
from tests._raycast3d import cast, paper_walls


@pytest.mark.parametrize(
    ("variant", "pitch_deg", "roll_deg"),
    [("parallel", 0.0, 0.0), ("convergent", 6.0, -4.0), ("divergent", -8.0, 10.0)],
)
def test_a_frame_seen_from_above_is_fixed_by_the_2d_pipeline(
    variant: str, pitch_deg: float, roll_deg: float
) -> None:
    walls, scene = paper_walls(variant)
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, pitch_deg, roll_deg)
    frame = cast(truth, walls, noise_m=0.01, seed=3)
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


@pytest.mark.parametrize(
    ("band", "surface", "n"),
    [((-1.0, 1.5), 0.05, 1440), ((-0.2, 0.3), 0.5, 1440), ((-1.0, 1.5), 0.05, 40_000)],
)
def test_the_compiled_plan_ranges_agree_with_their_numpy_reference(
    band: tuple[float, float], surface: float, n: int
) -> None:
    # Each bearing's mean range of its nearest surface, compiled and in numpy: the same
    # bins seen, the same ranges to rounding.
    from mast.core._kernels import plan_ranges
    from mast.pipeline.plan_view import _plan_ranges_reference

    walls, _ = paper_walls("convergent")
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 30.0, 6.0, -4.0)
    frame = cast(truth, walls, noise_m=0.02, seed=4)
    L = level_rotation(truth.rotation.T @ np.array([0.0, 0.0, 1.0]) + [0.02, -0.01, 0.0])
    step = 2.0 * math.pi / n  # 40 000 bins: more than 16-bit keys hold
    got = plan_ranges(frame.points, L, band[0], band[1], n, step, surface)
    want = _plan_ranges_reference(frame.points, L, band[0], band[1], n, step, surface)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert np.count_nonzero(np.isfinite(want)) > 300
    np.testing.assert_allclose(got, want, rtol=1e-12, equal_nan=True)
