"""The simulated terrestrial laser scans: in the grid through their E57 poses, on the
true panels within the range noise, panels hiding the rock behind them, repeatable."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mast.cloud.io import open_cloud
from mast.io import read_survey
from mast.sim.tls import TlsOptions, TlsScenario, simulate_tls

SMALL = TlsOptions(length_m=20.0, beacons=2, designs=2, stations=1, step_rad=0.001)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> TlsScenario:
    return simulate_tls(tmp_path_factory.mktemp("tls"), 3, SMALL)


def _turn(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _grid_points(scene: TlsScenario) -> np.ndarray:
    return np.concatenate([c.xyz for c in open_cloud(scene.e57).chunks()])


def test_the_files_and_the_truth_agree(scene: TlsScenario) -> None:
    truth = json.loads(scene.truth.read_text())
    survey = read_survey(scene.survey)
    designs = read_survey(scene.designs)
    assert survey.ids == list(scene.beacons) == ["T01", "T02"]
    assert {b.design for b in survey} == set(designs.ids) == {"hat-1.0", "hat-2"}
    assert truth["points"] == scene.points == len(_grid_points(scene))
    for b in survey:
        assert b.elevations is not None
        assert np.allclose(b.elevations, SMALL.origin[2] + SMALL.beacon_top_m)
        # the same shape as its design: a rigid body, never mirrored
        own = designs[b.design or ""].edges
        assert np.allclose(np.hypot(*np.diff(b.edges, axis=0).T), np.hypot(*np.diff(own, axis=0).T))
        turn = _turn(b.edges[1] - b.edges[0], b.edges[2] - b.edges[1])
        assert np.sign(turn) == np.sign(_turn(own[1] - own[0], own[2] - own[1]))


def test_panel_points_lie_on_the_true_panels_within_the_range_noise(scene: TlsScenario) -> None:
    xyz = _grid_points(scene)
    survey = read_survey(scene.survey)
    seen = 0
    for b in survey:
        assert b.elevations is not None
        top = float(b.elevations[0])
        for i in range(3):
            a, c = b.edges[i], b.edges[i + 1]
            length = math.dist(a, c)
            d = (c - a) / length
            rel = xyz[:, :2] - a
            along, off = rel @ d, rel @ np.array([-d[1], d[0]])
            on = (
                (np.abs(off) < 0.01)
                & (along > 0.02)
                & (along < length - 0.02)
                & (xyz[:, 2] > top - SMALL.panel_height_m + 0.02)
                & (xyz[:, 2] < top - 0.02)
            )
            if on.sum() < 50:
                continue
            seen += 1
            assert float(np.sqrt(np.mean(off[on] ** 2))) < 2 * SMALL.range_noise_m
    assert seen >= 4


def test_a_panel_hides_the_rock_behind_it(scene: TlsScenario) -> None:
    """No return lies behind a panel on its ray from the station: a ray that meets a
    panel stops there."""
    xyz = _grid_points(scene)
    truth = json.loads(scene.truth.read_text())
    st = truth["stations"][0]
    station = np.array([st["easting"], st["northing"], st["elevation"]])
    survey = read_survey(scene.survey)
    for b in survey:
        assert b.elevations is not None
        top = float(b.elevations[0])
        for i in range(3):
            a, c = b.edges[i], b.edges[i + 1]
            n = np.array([-(c - a)[1], (c - a)[0]])
            ray = xyz - station
            denom = ray[:, :2] @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((a - station[:2]) @ n) / denom  # where the ray crosses the panel's plane
            cross = station + t[:, None] * ray
            s = (cross[:, :2] - a) @ (c - a) / float((c - a) @ (c - a))
            inside = (
                (t > 0)
                & (t < 1 - 0.01 / np.linalg.norm(ray, axis=1))  # well before the return
                & (s > 0.01)
                & (s < 0.99)
                & (cross[:, 2] > top - SMALL.panel_height_m + 0.01)
                & (cross[:, 2] < top - 0.01)
            )
            assert not np.any(inside), (b.id, i, int(inside.sum()))


def test_the_same_seed_writes_the_same_scene(tmp_path: Path, scene: TlsScenario) -> None:
    again = simulate_tls(tmp_path / "again", 3, SMALL)
    assert again.survey.read_bytes() == scene.survey.read_bytes()
    assert again.points == scene.points
    assert np.array_equal(_grid_points(again), _grid_points(scene))


def test_options_out_of_range_are_refused(tmp_path: Path) -> None:
    from mast.errors import InputError

    with pytest.raises(InputError, match="beacon_top_m"):
        simulate_tls(tmp_path, 0, TlsOptions(beacon_top_m=9.0))


def test_a_wide_beam_mixes_a_panels_boundary_with_what_lies_behind(tmp_path: Path) -> None:
    """Mixed pixels: only returns near a beacon change when the beam gets a width, and
    some of them move off the panels by more than the noise (into the gap behind)."""
    thin = simulate_tls(tmp_path / "thin", 3, SMALL)
    wide = simulate_tls(tmp_path / "wide", 3, replace(SMALL, beam_exit_m=0.01))
    a, b = _grid_points(thin), _grid_points(wide)
    assert a.shape == b.shape
    moved = np.linalg.norm(a - b, axis=1) > 1e-4
    assert 0 < moved.sum() < 0.05 * len(a)
    survey = read_survey(thin.survey)
    near = np.min(
        [np.min(np.hypot(*(a[moved, None, :2] - bb.edges[None]).transpose(2, 0, 1)), axis=1)
         for bb in survey],
        axis=0,
    )  # fmt: skip
    assert np.all(near < 1.0)
    assert np.max(np.linalg.norm(a[moved] - b[moved], axis=1)) > 0.01


def test_a_stations_setup_error_moves_its_whole_scan(tmp_path: Path) -> None:
    import pye57

    off = simulate_tls(
        tmp_path / "off",
        3,
        replace(SMALL, station_sigma_m=0.01),
    )
    truth = json.loads(off.truth.read_text())["stations"][0]
    e57 = pye57.E57(str(off.e57))
    written = np.asarray(e57.get_header(0).translation)
    e57.close()
    shift = written[:2] - [truth["easting"], truth["northing"]]
    assert 1e-4 < float(np.hypot(*shift)) < 0.05
    assert written[2] == pytest.approx(truth["elevation"])
