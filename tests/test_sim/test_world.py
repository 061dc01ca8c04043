import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from mast import Pose2D
from mast.sim import ScannerModel, Surface, WorldBuilder, random_scene, simulate_scan
from mast.sim.world import World


def _distance_to_surface(world: World, surface: int, p: np.ndarray) -> float:
    best = math.inf
    sel = world.seg_surface == surface
    a, b = world.seg_a[sel], world.seg_b[sel]
    if len(a):
        ab = b - a
        t = np.clip(np.sum((p - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0, 1)
        best = float(np.min(np.hypot(*(a + t[:, None] * ab - p).T)))
    sel = world.circ_surface == surface
    if np.any(sel):
        d = np.abs(np.hypot(*(world.circ_c[sel] - p).T) - world.circ_r[sel])
        best = min(best, float(d.min()))
    return best


@pytest.mark.parametrize("azimuth_deg", [0.0, 37.0, 90.0, 143.0, 180.0, 251.0, 300.0])
def test_beam_perpendicular_to_a_wall_returns_its_distance(azimuth_deg: float) -> None:
    pose = Pose2D.from_degrees(1234.5, -678.9, azimuth_deg)
    d = 7.25
    fwd = np.array([math.sin(pose.azimuth), math.cos(pose.azimuth)])
    side = np.array([fwd[1], -fwd[0]])
    wb = WorldBuilder()
    foot = pose.position + d * fwd
    wb.polyline([foot - 20 * side, foot + 20 * side], Surface("wall"))
    sim = simulate_scan(wb.build(), pose, ScannerModel("t", 180.0, 0.5))
    centre = int(np.argmin(np.abs(sim.scan.angles_rad)))
    assert sim.scan.angles_rad[centre] == pytest.approx(0.0, abs=1e-15)
    assert sim.scan.ranges_m[centre] == pytest.approx(d, rel=1e-14)
    # beams off the normal see d / cos(phi)
    ok = sim.scan.valid
    assert_allclose(sim.scan.ranges_m[ok] * np.cos(sim.scan.angles_rad[ok]), d, rtol=1e-12)


def test_left_beams_hit_what_is_on_the_left() -> None:
    # Facing north, a wall to the west (left) is seen at phi = +90 deg, to the east at -90 deg.
    wb = WorldBuilder()
    wb.polyline([[-3.0, -50.0], [-3.0, 50.0]], Surface("wall", "west"))
    wb.polyline([[5.0, -50.0], [5.0, 50.0]], Surface("wall", "east"))
    sim = simulate_scan(wb.build(), Pose2D(0.0, 0.0, 0.0), ScannerModel("t", 270.0, 0.5))
    a = sim.scan.angles_rad
    left = int(np.argmin(np.abs(a - math.pi / 2)))
    right = int(np.argmin(np.abs(a + math.pi / 2)))
    assert sim.scan.ranges_m[left] == pytest.approx(3.0)
    assert sim.surfaces[sim.surface_index[left]].beacon == "west"
    assert sim.scan.ranges_m[right] == pytest.approx(5.0)


def test_circle_hit_distance() -> None:
    wb = WorldBuilder()
    wb.circle([0.0, 10.0], 0.5, Surface("person"))
    sim = simulate_scan(wb.build(), Pose2D(0.0, 0.0, 0.0), ScannerModel("t", 90.0, 0.25))
    centre = int(np.argmin(np.abs(sim.scan.angles_rad)))
    assert sim.scan.ranges_m[centre] == pytest.approx(9.5, abs=1e-12)
    assert sim.surfaces[sim.surface_index[centre]].kind == "person"


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_every_return_lies_on_the_surface_it_hit(seed: int) -> None:
    scene = random_scene(seed, 0)
    for shot in scene.shots:
        sim = simulate_scan(scene.world, shot.pose, shot.scanner)
        ok = sim.scan.valid
        assert np.all(sim.surface_index[ok] >= 0)
        pts = shot.pose.beam_to_mine(sim.scan.angles_rad[ok], sim.scan.ranges_m[ok])
        for p, s in zip(pts, sim.surface_index[ok], strict=True):
            assert _distance_to_surface(scene.world, int(s), p) < 1e-9 * (
                1 + float(np.abs(p).max()) / 1e6
            )


def test_nothing_hit_is_no_return() -> None:
    sim = simulate_scan(WorldBuilder().build(), Pose2D(0, 0, 0), ScannerModel("t", 270.0, 1.0))
    assert not sim.scan.valid.any()
    assert np.all(sim.surface_index == -1)
