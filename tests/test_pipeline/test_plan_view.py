"""A 3D frame seen from above is the 2D scan of the plan view: the paper's layout
ray-cast by a 16-ring lidar (vertical walls, vertical panels with their top edges),
projected by :func:`plan_scan`, is fixed by the 2D pipeline where the sensor stands."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

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
    scan = plan_scan(frame, up=up, range_sigma_m=0.01)
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
    [((-1.0, 1.5), 0.05, 1440), ((-0.2, 0.3), 0.5, 1440), ((-1.0, 1.5), 0.09, 40_000)],
)
def test_the_compiled_plan_ranges_agree_with_their_numpy_reference(
    band: tuple[float, float], surface: float, n: int
) -> None:
    # Each bearing's nearest surface, compiled and in numpy: the same bins seen, the
    # same bearings and ranges to rounding.
    from mast.core._kernels import plan_ranges
    from mast.pipeline.plan_view import _plan_ranges_reference

    walls, _ = paper_walls("convergent")
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 30.0, 6.0, -4.0)
    frame = cast(truth, walls, noise_m=0.02, seed=4)
    L = level_rotation(truth.rotation.T @ np.array([0.0, 0.0, 1.0]) + [0.02, -0.01, 0.0])
    step = 2.0 * math.pi / n  # 40 000 bins: more than 16-bit keys hold
    low, high = np.full(n, band[0]), np.full(n, band[1])
    low[: n // 4], high[: n // 4] = 0.5, 2.0  # a quarter of the bearings their own band
    got = plan_ranges(frame.points, L, low, high, n, step, surface)
    want = _plan_ranges_reference(frame.points, L, low, high, n, step, surface)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    assert np.count_nonzero(np.isfinite(want[1])) > 300
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, equal_nan=True)
    assert np.all(np.diff(got[0]) > 0)  # a scan's bearings, strictly increasing


def test_the_compiled_floor_lows_agree_with_their_numpy_reference() -> None:
    # Each floor column's lowest return, compiled and in numpy: the same returns in the
    # same order, ties to the first; a simulated drift's frame (its floor), a grid with
    # ties in every column, and nothing low enough.
    from mast.core._kernels import floor_lows
    from mast.pipeline.plan_view import _floor_lows_reference
    from mast.sim.lidar3d import random_drift_scene

    sim = random_drift_scene(7, frames=1, lidar="vlp16").simulate(0)
    q = sim.frame.points @ level_rotation(sim.pose.rotation[2]).T
    tied = np.array([[x, y, -1.0 - (x % 1.0 > 0.5)] for x in np.arange(-3, 3, 0.25)
                     for y in np.arange(-2, 2, 0.25) for _ in range(2)])  # fmt: skip
    for pts in (q, tied, tied + [0.0, 0.0, 5.0]):
        got, near = floor_lows(pts, -0.3, 12.0, 0.5)
        want, near_want = _floor_lows_reference(pts, -0.3, 12.0, 0.5)
        np.testing.assert_array_equal(got, want)
        assert near == near_want
    assert len(_floor_lows_reference(q, -0.3, 12.0, 0.5)[0]) > 100
    assert floor_lows(tied + [0.0, 0.0, 5.0], -0.3, 12.0, 0.5)[1] == 0


def test_a_panel_seen_by_many_noisy_returns_is_not_pulled_in_front_of_its_plane() -> None:
    # Cut at the nearest return plus 5 cm, a bin's returns on a panel at 3 cm range
    # noise are the nearer part of their noise: the panel comes out about 2.5 cm in
    # front of its plane. A window of three sigmas takes in most of the rest.
    from mast.core.frames import yaw_of_azimuth
    from mast.pipeline.adjust3d import PanelPlanes

    walls, scene = paper_walls("parallel")
    planes = PanelPlanes.of(scene.survey)
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 30.0, 0.0, 0.0)

    def offsets(**how: float) -> NDArray[np.float64]:
        out = []
        for seed in range(3):
            scan = plan_scan(cast(truth, walls, noise_m=0.03, seed=seed), **how)
            seen = np.isfinite(scan.ranges_m)
            bearing = yaw_of_azimuth(math.radians(30.0)) + scan.angles_rad[seen]
            r = scan.ranges_m[seen, None]
            xy = truth.position[:2] + r * np.c_[np.cos(bearing), np.sin(bearing)]
            d = xy @ planes.normal.T - planes.offset
            t = np.einsum("mkj,kj->mk", xy[:, None, :] - planes.start[None], planes.along)
            on = (t > 0.1) & (t < planes.length - 0.1) & (np.abs(d) < 0.1)
            k = np.argmax(on, axis=1)[on.any(axis=1)]
            out.append(d[on.any(axis=1), k] * planes.front[k])  # > 0: in front
        return np.concatenate(out)

    wide = offsets(range_sigma_m=0.03)
    assert wide.size > 400
    assert abs(float(np.mean(wide))) < 0.01
    assert float(np.mean(offsets(surface_m=0.05))) > 0.015  # 5 cm whatever the noise


def test_bearings_given_their_own_band_see_a_beacon_the_band_passes_over() -> None:
    # A band above the beacons sees the wall behind them; the bearings of one beacon
    # given the band of its panels see its panels there, and every other bearing is the
    # same as before.
    walls, scene = paper_walls("parallel")
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, 0.0, 0.0)
    frame = cast(truth, walls, noise_m=0.01, seed=5)
    beacon = next(iter(scene.survey))
    d = beacon.edges - truth.position[:2]
    bearing = -np.arctan2(d[:, 0], d[:, 1])  # counter-clockwise from the heading (north)
    top = float(beacon.elevations[0]) - truth.elevation
    over = plan_scan(frame, band=(top + 0.2, top + 1.0), range_sigma_m=0.01)
    own = (float(bearing.min()), float(bearing.max()), top - 0.4, top - 0.05)
    seen = plan_scan(frame, band=(top + 0.2, top + 1.0), range_sigma_m=0.01, bands=[own])
    inside = (over.angles_rad > own[0] + 0.01) & (over.angles_rad < own[1] - 0.01)
    assert np.count_nonzero(inside) > 10
    behind = over.ranges_m[inside] - seen.ranges_m[inside]
    assert np.all(behind > 0.02)  # the wall behind, then the panels in front of it
    assert float(np.median(behind)) > 0.1
    outside = (over.angles_rad < own[0] - 0.01) | (over.angles_rad > own[1] + 0.01)
    np.testing.assert_array_equal(over.ranges_m[outside], seen.ranges_m[outside])
