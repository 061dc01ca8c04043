"""Scenes drawn as widely as the field (issue 31, item 4)."""

import math

import numpy as np
import pytest

from mast.bench.field import PRIOR_OFF_DEG, PRIOR_OFF_M, good_prior
from mast.core.pose import Pose2D
from mast.sim import simulate_scan
from mast.sim.design import BeaconDesign
from mast.sim.hard import FIELD_SCANNERS, field_scene
from mast.sim.owed import OWED_FIELD


def test_field_scenes_are_seeded_and_as_wide_as_the_field() -> None:
    a, b = field_scene(3, 1), field_scene(3, 1)
    assert a.description == b.description
    np.testing.assert_array_equal(a.survey["B1"].edges, b.survey["B1"].edges)
    chords, scanners, widths = [], set(), []
    for seed in range(12):
        scene = field_scene(seed, seed % 4)
        assert [x.id for x in scene.survey] == ["B1", "B2"]
        widths.append(scene.params["width_m"])
        for beacon in scene.survey:
            chords.append(float(np.hypot(*(beacon.edges[3] - beacon.edges[0]))))
        scanners |= {s.scanner.name for s in scene.shots}
    assert min(chords) >= 0.45
    assert max(chords) <= 2.0 + 1e-9
    assert max(chords) - min(chords) > 0.8
    assert min(widths) >= 4.0
    assert max(widths) <= 10.0
    assert scanners == {m.name for m in FIELD_SCANNERS}
    assert {m.range_sigma_m for m in FIELD_SCANNERS} == {0.008, 0.012, 0.015, 0.020}


def test_field_beacons_are_bolted_askew_up_to_ten_degrees() -> None:
    tilts = [t for seed in range(10) for t in field_scene(seed, 0).params["tilts_deg"].values()]
    assert max(abs(t) for t in tilts) <= 10.0
    assert min(tilts) < -4.0
    assert max(tilts) > 4.0


@pytest.mark.parametrize("hostile", [False, True])
def test_field_scans_owe_fixes_and_hostile_ones_hold_mixed_pixels(hostile: bool) -> None:
    owed = mixed = 0
    for i in range(8):
        scene = field_scene(i // 4, i % 4, hostile=hostile)
        for sim in scene.simulate_all():
            owed += sim.owes_fix(OWED_FIELD)
            mixed += int(np.sum((sim.surface_index < 0) & sim.scan.valid))
    assert owed >= 6
    assert (mixed > 0) == hostile


def test_a_lookalike_chord_runs_from_its_first_vertex_to_its_last() -> None:
    bracket = BeaconDesign("bracket", np.array([[0.0, 0.0], [0.4, 0.0], [0.4, 0.3]]))
    assert bracket.chord_m == pytest.approx(0.5)
    hat = BeaconDesign(
        "hat", np.array([[0.0, 0.0], [0.2, 0.2], [0.8, 0.2], [1.0, 0.0], [1.5, 0.1]])
    )
    assert hat.chord_m == pytest.approx(math.hypot(1.5, 0.1))


def test_field_shots_see_the_beacons_from_between_them() -> None:
    scene = field_scene(0, 0)
    centre = np.mean([b.edges.mean(axis=0) for b in scene.survey], axis=0)
    for shot in scene.shots:
        sim = simulate_scan(scene.world, shot.pose, shot.scanner.noise_free())
        assert sim.beacon_mask().any()
        assert math.dist(shot.pose.position, centre) < 15.0


def test_the_field_benchmarks_good_prior_holds_the_truth_within_half_its_window() -> None:
    truth = Pose2D.from_degrees(1000.0, 2000.0, 359.0)
    rng = np.random.default_rng(5)
    offs = []
    for _ in range(500):
        prior = good_prior(truth, rng)
        off = math.hypot(prior.pose.easting - truth.easting, prior.pose.northing - truth.northing)
        turn = abs(math.remainder(prior.pose.azimuth - truth.azimuth, 2 * math.pi))
        assert off <= PRIOR_OFF_M + 1e-12
        assert turn <= math.radians(PRIOR_OFF_DEG) + 1e-12
        assert prior.radius_m == 2 * PRIOR_OFF_M
        assert prior.admits(truth)
        offs.append(off)
    # Uniform over the disc: half the draws beyond 1/sqrt(2) of the radius.
    assert 0.4 < np.mean(np.asarray(offs) > PRIOR_OFF_M / math.sqrt(2)) < 0.6
