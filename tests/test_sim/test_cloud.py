"""The simulated SLAM point cloud: files, truth, drift and determinism."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import laspy
import numpy as np
import pytest

from mast.errors import InputError
from mast.io import read_survey
from mast.sim.cloud import CloudOptions, CloudScenario, simulate_cloud

SMALL = CloudOptions(length_m=80.0, beacons=3, density=150.0)
EXACT = CloudOptions(length_m=80.0, beacons=3, density=150.0, noise_m=0.0, survey_sigma_m=0.0)


@pytest.fixture(scope="module")
def exact(tmp_path_factory: pytest.TempPathFactory) -> CloudScenario:
    return simulate_cloud(tmp_path_factory.mktemp("exact"), seed=3, options=EXACT)


@pytest.fixture(scope="module")
def drifted(tmp_path_factory: pytest.TempPathFactory) -> CloudScenario:
    options = CloudOptions(length_m=80.0, beacons=3, density=150.0, noise_m=0.0, drift=0.01)
    return simulate_cloud(tmp_path_factory.mktemp("drifted"), seed=3, options=options)


def _truth(scenario: CloudScenario) -> dict[str, Any]:
    truth: dict[str, Any] = json.loads(scenario.truth.read_text(encoding="utf-8"))
    return truth


def _to_grid(truth: dict[str, Any], xyz: np.ndarray) -> np.ndarray:
    a = math.radians(truth["rotation_deg"])
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    en = xyz[:, :2] @ rot.T + [truth["easting_m"], truth["northing_m"]]
    return np.column_stack([en, xyz[:, 2] + truth["elevation_m"]])


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.asarray(np.hypot(*(p - a - t[:, None] * ab).T))


def _panel_distance(p: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Plan distance of points ``p`` to the nearest of a beacon's three panels."""
    return np.asarray(np.min([_segment_distance(p, edges[k], edges[k + 1]) for k in range(3)], 0))


def _bright(scenario: CloudScenario) -> np.ndarray:
    las = laspy.read(scenario.cloud)
    keep = np.asarray(las.intensity) > 20_000
    return np.column_stack([las.x, las.y, las.z])[keep]


def test_files_and_fields(exact: CloudScenario) -> None:
    for path in (exact.cloud, exact.survey, exact.trajectory, exact.truth):
        assert path.is_file()
    las = laspy.read(exact.cloud)
    assert las.header.version.minor == 4
    assert las.header.point_format.id == 6
    assert "range" in list(las.point_format.extra_dimension_names)
    assert len(las.points) == exact.points == las.header.point_count
    assert np.allclose(las.header.scales, 1e-4)
    t = np.asarray(las.gps_time)
    assert t.min() >= 345_600.0
    assert t.max() <= 345_600.0 + 80.0 / 1.2 + 0.2
    rng_m = np.asarray(las["range"])
    assert rng_m.dtype == np.float32
    assert 0 <= rng_m.min() < rng_m.max() < 30
    assert np.all(np.asarray(las.classification) == 0)
    # local frame: small coordinates, the scanner starting at the origin
    assert np.abs(np.column_stack([las.x, las.y])).max() < 100
    tum = np.loadtxt(exact.trajectory)
    assert tum.shape[1] == 8
    assert np.allclose(np.diff(tum[:, 0]), 0.1)
    assert np.allclose(tum[0, 1:4], 0.0)
    assert np.allclose(np.hypot(tum[:, 6], tum[:, 7]), 1.0)


def test_survey_reads_back_with_elevations(exact: CloudScenario) -> None:
    survey = read_survey(exact.survey)
    truth = _truth(exact)
    assert survey.ids == ["B01", "B02", "B03"] == [b["id"] for b in truth["beacons"]]
    for b in truth["beacons"]:
        edges = np.array(b["edges_grid"])
        assert edges[0, 0] > 400_000
        assert edges[0, 1] > 7_000_000
        assert edges[0, 2] < -700
        assert np.allclose(survey[b["id"]].edges, edges[:, :2], atol=1e-9)
        elevations = survey[b["id"]].elevations
        assert elevations is not None
        assert np.allclose(elevations, b["top_elevation_m"], atol=1e-9)


def test_survey_noise(tmp_path: Path) -> None:
    scenario = simulate_cloud(tmp_path, seed=3, options=SMALL)
    survey, truth = read_survey(scenario.survey), _truth(scenario)
    err = [survey[b["id"]].edges - np.array(b["edges_grid"])[:, :2] for b in truth["beacons"]]
    assert 0 < np.abs(err).max() < 5 * SMALL.survey_sigma_m


def test_truth_maps_panel_points_onto_the_survey(exact: CloudScenario) -> None:
    truth = _truth(exact)
    grid = _to_grid(truth, _bright(exact))
    assert len(grid) == sum(sum(b["panel_points"]) for b in truth["beacons"])
    tops = []
    for b in truth["beacons"]:
        edges = np.array(b["edges_grid"])
        near = np.hypot(*(grid[:, :2] - edges[:, :2].mean(axis=0)).T) < 1.0
        assert near.sum() == sum(b["panel_points"]) > 20
        assert _panel_distance(grid[near, :2], edges[:, :2]).max() < 1e-3
        z = grid[near, 2]
        assert z.max() <= b["top_elevation_m"] + 1e-3
        assert z.max() > b["top_elevation_m"] - 0.05
        assert z.min() > b["top_elevation_m"] - EXACT.panel_height_m - 1e-3
        tops.append(b["top_elevation_m"])
        # without drift, the edges seen in the cloud are T0^-1 of the true edges
        assert np.allclose(_to_grid(truth, np.array(b["edges_local"])), edges, atol=1e-6)
    assert np.ptp(tops) > EXACT.panel_height_m  # the floor is on a grade


def test_drift_moves_the_end_by_drift_times_length(
    exact: CloudScenario, drifted: CloudScenario
) -> None:
    truth = _truth(drifted)
    assert truth["rotation_deg"] == _truth(exact)["rotation_deg"]  # same geometry
    true_path = _to_grid(truth, np.loadtxt(exact.trajectory)[:, 1:4])
    slam_path = _to_grid(truth, np.loadtxt(drifted.trajectory)[:, 1:4])
    assert np.allclose(slam_path[0], true_path[0], atol=1e-9)
    end_error = float(np.linalg.norm(slam_path[-1] - true_path[-1]))
    expected = 0.01 * EXACT.length_m
    assert expected / 2 < end_error < 2 * expected
    assert truth["final_error_m"] == pytest.approx(expected, rel=1e-3)


def test_drifted_beacons_where_truth_says(drifted: CloudScenario) -> None:
    """The drifted cloud is locally consistent: panel points lie on ``edges_local``."""
    truth, bright = _truth(drifted), _bright(drifted)
    for b in truth["beacons"]:
        edges = np.array(b["edges_local"])
        near = np.hypot(*(bright[:, :2] - edges[:, :2].mean(axis=0)).T) < 1.0
        assert near.sum() == sum(b["panel_points"])
        assert _panel_distance(bright[near, :2], edges[:, :2]).max() < 0.01
        assert abs(bright[near, 2].max() - edges[0, 2]) < 0.03


def test_point_count_follows_density(exact: CloudScenario) -> None:
    # walls, floor and arched roof of 80 m of drift (~18.5 m2/m) plus a side drift and clutter
    per_metre = exact.points / (EXACT.density * EXACT.length_m)
    assert 17 < per_metre < 26


def test_max_points_caps_the_cloud(tmp_path: Path) -> None:
    options = CloudOptions(length_m=80.0, beacons=3, density=150.0, max_points=100_000)
    scenario = simulate_cloud(tmp_path, seed=3, options=options)
    assert 90_000 < scenario.points <= 100_000


def test_same_seed_same_files(tmp_path: Path) -> None:
    options = CloudOptions(length_m=50.0, beacons=2, density=50.0, chunk_points=5_000)
    a = simulate_cloud(tmp_path / "a", seed=7, options=options)
    b = simulate_cloud(tmp_path / "b", seed=7, options=options)
    for x, y in ((a.cloud, b.cloud), (a.survey, b.survey), (a.trajectory, b.trajectory)):
        assert x.read_bytes() == y.read_bytes()
    c = simulate_cloud(tmp_path / "c", seed=8, options=options)
    assert c.cloud.read_bytes() != a.cloud.read_bytes()


def test_hard_clouds_thin_with_range_and_mount_several_designs(tmp_path: Path) -> None:
    """``falloff_m``: the points per square metre fall as the square of the range beyond
    it (and the truth counts the beacons' points kept); ``designs``: the paper's hat and
    shallow random hats in turn, each identifiable."""
    base = CloudOptions(length_m=80.0, beacons=3, density=150.0)
    plain = simulate_cloud(tmp_path / "plain", seed=3, options=base)
    hard = CloudOptions(
        length_m=80.0,
        beacons=3,
        density=150.0,
        falloff_m=3.0,
        rock_behind_beacons=True,
        designs=3,
    )
    thin = simulate_cloud(tmp_path / "thin", seed=3, options=hard)
    r_plain = np.asarray(laspy.read(plain.cloud)["range"])
    r_thin = np.asarray(laspy.read(thin.cloud)["range"])
    near = np.mean(r_thin < 3.0) * thin.points / (np.mean(r_plain < 3.0) * plain.points)
    far = np.mean(r_thin > 6.0) * thin.points / (np.mean(r_plain > 6.0) * plain.points)
    assert 0.8 < near < 1.25  # as dense where the scanner is close
    assert far < 0.25  # a quarter or less at twice the fall-off and beyond
    survey = read_survey(thin.survey)
    lengths = {tuple(np.round(b.template.panel_lengths, 3)) for b in survey}
    assert len(lengths) == 3
    assert all(not b.identifiability_problems() for b in survey)
    counts = [b["panel_points"] for b in _truth(thin)["beacons"]]
    assert all(sum(c) > 0 for c in counts)
    with pytest.raises(InputError, match="falloff_m"):
        simulate_cloud(tmp_path / "bad", seed=3, options=CloudOptions(falloff_m=-1.0))
