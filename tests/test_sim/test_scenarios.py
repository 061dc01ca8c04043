import csv
import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from mast import Beacon, InputError
from mast.io import read_laserscans, read_scan_csv, read_survey
from mast.sim import (
    Roughness,
    build_scenario,
    paper_design,
    paper_scene,
    polyline_design,
    random_scene,
    roughen,
    write_scenario,
)

# Table 2 of the paper: position number -> (E, N, azimuth deg)
TABLE2 = {
    "P1": (7.000, 7.000, 0.0),
    "P2": (10.932, 6.219, 5.0),
    "P3": (10.932, 7.781, 355.0),
    "P4": (11.000, 7.000, 0.0),
    "P5": (14.863, 5.437, 10.0),
    "P6": (14.863, 8.563, 350.0),
    "P7": (15.000, 7.000, 0.0),
}


def test_paper_scenario_reproduces_table2_positions() -> None:
    seen = set()
    for scene in build_scenario("paper"):
        assert scene.survey.ids == ["B1", "B2"]
        for shot in scene.shots:
            label = shot.label.split("@")[0]
            e, n, az = TABLE2[label]
            assert shot.pose.easting == pytest.approx(e, abs=6e-4)
            assert shot.pose.northing == pytest.approx(n, abs=6e-4)
            assert shot.pose.azimuth_deg == pytest.approx(az, abs=1e-9)
            seen.add(label)
            assert shot.scanner.resolution_deg in (0.25, 0.5)
    assert seen == set(TABLE2)


def test_paper_beacon1_is_yawed_about_p1() -> None:
    for variant, yaw in (("convergent", -10.0), ("parallel", 0.0), ("divergent", 10.0)):
        b1 = paper_scene(variant).survey["B1"]
        d = b1.edges[3] - b1.edges[0]  # chord along the wall
        wall_az = math.degrees(math.atan2(d[0], d[1])) % 180.0
        assert wall_az == pytest.approx(yaw % 180.0, abs=1e-9)
        # its mid-panel normal points back at P1's neighbourhood (west-ish)
        assert b1.centroid[0] > 14.0


def test_paper_design_geometry() -> None:
    d = paper_design(1.0, 0.2)
    assert d.chord_m == pytest.approx(1.0, abs=1e-12)
    assert d.depth_m == pytest.approx(0.2, abs=1e-12)
    t = Beacon("x", d.edges_local).template
    assert_allclose(t.panel_lengths / t.panel_lengths[2], [2.0, 3.0, 1.0], rtol=1e-9)
    assert t.deflections[0] == pytest.approx(-math.asin(0.2 / t.panel_lengths[0]))
    assert t.deflections[1] == pytest.approx(-math.asin(0.2 / t.panel_lengths[2]))
    for chord, depth in ((0.499, 0.1), (1.996, 0.4)):  # the paper's extremes
        assert paper_design(chord, depth).chord_m == pytest.approx(chord)
    with pytest.raises(InputError, match=r"chord 0\.3 m is too short for depth 0\.2 m"):
        paper_design(0.3, 0.2)


@pytest.mark.parametrize("side", [1, -1])
def test_mounted_beacon_stands_out_into_the_tunnel(side: int) -> None:
    d = polyline_design((0.4, 0.6, 0.25), (-0.5, -0.9))
    edges = d.mounted([100.0, 50.0], [0.0, 1.0], tunnel_side=side)
    # wall along north through E=100; tunnel on the left (west) for +1
    out = (edges[1:3, 0] - 100.0) * -side
    assert np.all(out > 0.05)
    assert_allclose(edges[[0, 3], 0], 100.0, atol=1e-12)


def test_random_scenes_are_seeded_and_identifiable() -> None:
    a, b, c = random_scene(5, 0), random_scene(5, 0), random_scene(6, 0)
    assert_array_equal(a.world.seg_a, b.world.seg_a)
    assert [s.pose for s in a.shots] == [s.pose for s in b.shots]
    assert [s.pose for s in a.shots] != [s.pose for s in c.shots]
    for seed in range(10):
        for beacon in random_scene(seed, 1).survey:
            assert beacon.identifiability_problems() == []


def test_roughness_is_bounded_and_smooth_at_beacons() -> None:
    wall = np.array([[0.0, 0.0], [20.0, 0.0]])
    rough = roughen(
        wall, Roughness(amplitude_m=0.08), np.random.default_rng(0), smooth_intervals=[(5.0, 6.0)]
    )
    assert np.abs(rough[:, 1]).max() == pytest.approx(0.08, rel=1e-9)
    patch = (rough[:, 0] >= 5.0) & (rough[:, 0] <= 6.0)
    assert_allclose(rough[patch, 1], 0.0, atol=1e-12)


def _truth(folder: Path) -> list[dict[str, str]]:
    with (folder / "truth.csv").open(encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_write_scenario_csv_round_trip(tmp_path: Path) -> None:
    scenes = [paper_scene("divergent")]
    written = write_scenario(scenes, tmp_path, fmt="csv", scenario="paper")
    (w,) = written
    assert (tmp_path / "scenario.json").is_file()
    survey = read_survey(w.survey)
    assert_array_equal(survey["B1"].edges, scenes[0].survey["B1"].edges)
    rows = _truth(w.folder)
    assert len(rows) == len(scenes[0].shots) == len(w.scans)
    sims = scenes[0].simulate_all()
    for row, sim, path in zip(rows, sims, w.scans, strict=True):
        scan = read_scan_csv(path)
        assert_array_equal(scan.ranges_m[scan.valid], sim.scan.ranges_m[sim.scan.valid])
        assert float(row["easting"]) == sim.pose.easting
        assert float(row["azimuth_deg"]) == pytest.approx(sim.pose.azimuth_deg)
        assert "B1:" in row["panels_seen"]


@pytest.mark.parametrize("fmt", ["bag", "ros2", "mcap"])
def test_write_scenario_bags(tmp_path: Path, fmt: str) -> None:
    (w,) = write_scenario([paper_scene("parallel")], tmp_path, fmt=fmt)
    scans = list(read_laserscans(w.scans[0]))
    rows = _truth(w.folder)
    assert len(scans) == len(rows) == 6
    assert [s.stamp_ns for s in scans] == [int(r["stamp_ns"]) for r in rows]


def test_unknown_names() -> None:
    with pytest.raises(InputError, match="unknown scenario 'mars'; known: paper, random"):
        build_scenario("mars")
    with pytest.raises(InputError, match="unknown paper variant"):
        paper_scene("sideways")
