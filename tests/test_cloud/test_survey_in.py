"""mast survey-in on simulated terrestrial scans: each beacon of its design, its edges and
top within their sigmas, ids kept from a previous survey, a moved beacon named."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from subprocess import CompletedProcess

import numpy as np
import pytest

from mast.core.beacon import Beacon, Survey
from mast.io import read_survey, write_survey
from mast.sim.tls import TlsOptions, TlsScenario, simulate_tls
from tests._cli import run_mast_text

OPTIONS = TlsOptions(length_m=24.0, beacons=3, designs=2, stations=2, step_rad=0.0006)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> TlsScenario:
    return simulate_tls(tmp_path_factory.mktemp("tls"), 1, OPTIONS)


@pytest.fixture(scope="module")
def surveyed(scene: TlsScenario, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("survey")
    done = _survey_in(scene, out, "--crs", "local:Mine Grid A")
    assert done.returncode == 0, done.stderr
    return out


def _survey_in(scene: TlsScenario, out: Path, *args: str) -> CompletedProcess[str]:
    return run_mast_text(
        "survey-in", str(scene.e57), "--designs", str(scene.designs), "--out", str(out),
        "--noise", "0.0015", "--station-sigma", "0", *args,
    )  # fmt: skip


def _nearest(survey: Survey, b: Beacon) -> Beacon:
    return min(survey, key=lambda t: math.dist(t.edges.mean(axis=0), b.edges.mean(axis=0)))


def test_beacons_are_surveyed_in_with_their_designs_within_their_sigmas(
    scene: TlsScenario, surveyed: Path
) -> None:
    found = read_survey(surveyed / "beacons.csv")
    truth = read_survey(scene.survey)
    assert len(found) >= 2
    for b in found:
        t = _nearest(truth, b)
        assert b.design == t.design
        assert b.id.startswith(f"{b.design}-")
        assert b.edge_sigmas_m is not None
        assert b.elevations is not None
        assert t.elevations is not None
        err = np.hypot(*(b.edges - t.edges).T)
        assert np.all(err < 0.002), (b.id, err)
        # each coordinate within 4.5 sigma (two coordinates, four edges, a few beacons)
        assert np.all(np.abs(b.edges - t.edges) <= 4.5 * b.edge_sigmas_m[:, None] + 1e-5)
        assert abs(float(b.elevations[0] - t.elevations[0])) < 0.003


def test_the_report_names_each_panel_and_edge(surveyed: Path) -> None:
    text = (surveyed / "report.txt").read_text()
    assert "beacon(s) surveyed in" in text
    for word in ("P1", "P2", "P3", "plane RMS", "tilt", "length seen", "e4", "sigma"):
        assert word in text
    assert (surveyed / "report.html").read_text().startswith("<!DOCTYPE html>")
    assert "grid CRS         Mine Grid A (local grid)" in text


def test_a_previous_survey_keeps_its_ids_and_names_the_beacon_that_moved(
    scene: TlsScenario, surveyed: Path, tmp_path: Path
) -> None:
    found = read_survey(surveyed / "beacons.csv")
    truth = read_survey(scene.survey)
    # the previous survey: the truth, with one beacon 8 mm away from where it is now
    moved = _nearest(truth, next(iter(found))).id
    before = [
        Beacon(b.id, b.edges + ([0.008, 0.0] if b.id == moved else 0.0), b.elevations,
               np.full(4, 0.001), b.design)
        for b in truth
    ]  # fmt: skip
    previous = tmp_path / "previous.csv"
    write_survey(previous, Survey(before))
    done = _survey_in(scene, tmp_path / "again", "--previous", str(previous))
    assert done.returncode == 0, done.stderr
    again = read_survey(tmp_path / "again" / "beacons.csv")
    assert set(again.ids) <= set(truth.ids)
    stdout = done.stdout
    assert f"{moved} (" in stdout
    moved_lines = [line for line in stdout.splitlines() if "MOVED" in line]
    assert len(moved_lines) == 1
    assert moved_lines[0].strip().startswith(moved)


def test_scans_without_beacons_exit_3(tmp_path: Path) -> None:
    empty = simulate_tls(tmp_path / "sim", 2, TlsOptions(length_m=12.0, beacons=0, stations=1,
                                                         step_rad=0.001))  # fmt: skip
    done = _survey_in(empty, tmp_path / "out")
    assert done.returncode == 3
    assert "no beacon found" in done.stderr


@pytest.mark.parametrize(("option", "value"), [("--noise", "0"), ("--station-sigma", "-1")])
def test_bad_options_are_bad_input(
    scene: TlsScenario, tmp_path: Path, option: str, value: str
) -> None:
    done = run_mast_text("survey-in", str(scene.e57), "--designs", str(scene.designs),
                         "--out", str(tmp_path / "o"), option, value)  # fmt: skip
    assert done.returncode == 2
    assert option in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_a_panel_lines_covariance_matches_its_scatter() -> None:
    """The line's angle and offset (about an origin 0.35 m away, as the fit takes them)
    vary over many noisy fits as the covariance says, their correlation's sign too."""
    from mast.cloud.beacon_fit import panel_line

    rng = np.random.default_rng(5)
    t = np.linspace(0.0, 0.6, 300)
    base = np.column_stack([0.2 + t * math.cos(0.4), 0.3 + t * math.sin(0.4)])
    normal = np.array([-math.sin(0.4), math.cos(0.4)])
    draws = []
    for _ in range(3000):
        pts = base + rng.normal(0.0, 0.0015, t.size)[:, None] * normal
        draws.append(panel_line(pts, 0.0015)[0])
    got = np.cov(np.array(draws).T)
    _, want, _ = panel_line(base + rng.normal(0.0, 0.0015, t.size)[:, None] * normal, 0.0015)
    assert np.allclose(np.diag(got), np.diag(want), rtol=0.15)
    assert np.sign(got[0, 1]) == np.sign(want[0, 1])
    assert got[0, 1] == pytest.approx(want[0, 1], rel=0.2)


def test_a_design_longer_at_a_free_end_is_not_taken_for_the_true_one(
    scene: TlsScenario, surveyed: Path, tmp_path: Path
) -> None:
    """A design with P1 30 mm longer, listed first: the free end's points stop at the
    true design's length, so the beacons are surveyed as the designs they are."""
    designs = read_survey(scene.designs, apart=False)
    first = designs.ids[0]
    d = designs[first]
    e = d.edges.copy()
    e[0] = e[1] + (e[0] - e[1]) * (math.dist(e[0], e[1]) + 0.03) / math.dist(e[0], e[1])
    longer = Beacon("longer", e + [20.0, 0.0], design="longer")
    path = tmp_path / "designs.csv"
    write_survey(path, Survey([longer, *designs]))
    done = run_mast_text("survey-in", str(scene.e57), "--designs", str(path), "--out",
                         str(tmp_path / "o"), "--noise", "0.0015")  # fmt: skip
    assert done.returncode == 0, done.stderr
    found = read_survey(tmp_path / "o" / "beacons.csv")
    assert "longer" not in {b.design for b in found}
    assert {b.design for b in found} == {b.design for b in read_survey(surveyed / "beacons.csv")}


def test_two_designs_of_one_shape_are_refused(scene: TlsScenario, tmp_path: Path) -> None:
    designs = read_survey(scene.designs, apart=False)
    first = designs[designs.ids[0]]
    twin = Beacon("twin", first.edges + [0.0005, 0.0], design="twin")
    path = tmp_path / "designs.csv"
    write_survey(path, Survey([*designs, twin]))
    done = run_mast_text("survey-in", str(scene.e57), "--designs", str(path), "--out",
                         str(tmp_path / "o"))  # fmt: skip
    assert done.returncode == 2
    assert "are the same shape" in done.stderr
    assert "twin" in done.stderr


def test_a_previous_survey_without_sigmas_leaves_movement_untested(
    scene: TlsScenario, tmp_path: Path
) -> None:
    truth = read_survey(scene.survey)
    plain = Survey([Beacon(b.id, b.edges, b.elevations, None, b.design) for b in truth])
    previous = tmp_path / "previous.csv"
    write_survey(previous, plain)
    done = _survey_in(scene, tmp_path / "o", "--previous", str(previous))
    assert done.returncode == 0, done.stderr
    assert "movement untested" in done.stdout
    assert "MOVED" not in done.stdout
    assert (
        "untested (the previous survey gives no sigma_m)"
        in (tmp_path / "o" / "report.txt").read_text()
    )


def test_the_scans_spacing_on_a_panel_is_its_columns_not_its_one_shadow() -> None:
    """A panel's points run on across gaps of the scan's own spacing: a far, oblique
    panel's columns are centimetres apart, a near one's points millimetres; one gap
    where something shadows a near panel is not its spacing."""
    from mast.cloud.detect import Panel, _segment
    from mast.cloud.survey_in import column_spacing

    rng = np.random.default_rng(4)

    def spacing(x: np.ndarray) -> float:
        xy = np.column_stack([np.sort(x), rng.normal(0.0, 0.0015, x.size)])
        seg = _segment(0, 0, np.arange(x.size), xy, 0.0015, 0.1)
        return column_spacing(Panel(seg, 0.0, 0.0015, 0.5, 2.0, 0.001, 1.5, None))

    columns = np.repeat(np.arange(0.0, 0.6, 0.028), 40) + rng.normal(0.0, 0.001, 22 * 40)
    assert 0.02 < spacing(columns) < 0.03
    dense = rng.uniform(0.0, 0.6, 3000)
    assert spacing(dense) < 0.002
    shadowed = dense[(dense < 0.2) | (dense > 0.3)]
    assert spacing(shadowed) < 0.002


def test_beacons_16_m_from_the_nearer_station_are_surveyed_in(tmp_path: Path) -> None:
    """Two stations 47 m apart: beacons 16-17 m from the nearer one are seen in scan
    columns centimetres apart (their cells alone, their floor and roof in the next
    cells), and are surveyed in with their designs (docs/survey-in.md, "Far scenes")."""
    import json

    from mast.cloud.survey_in import SurveyInConfig, survey_in

    options = TlsOptions(length_m=95.0, beacons=6, designs=2, stations=2, step_rad=0.0006)
    scene = simulate_tls(tmp_path, 1, options)
    truth = read_survey(scene.survey)
    points = {
        b["id"]: b["points_per_panel"] for b in json.loads(scene.truth.read_text())["beacons"]
    }
    stations = np.array([s[:2] for s in scene.stations])
    far = [
        b
        for b in truth
        if np.min(np.hypot(*(stations - b.edges.mean(axis=0)).T)) > 15.0 and min(points[b.id]) >= 50
    ]
    assert len(far) == 2
    config = SurveyInConfig(noise_m=options.range_noise_m, station_sigma_m=0.0)
    found = survey_in([scene.e57], read_survey(scene.designs, apart=False), config).beacons
    for b in far:
        fb = min(found, key=lambda f: math.dist(f.beacon.edges.mean(axis=0), b.edges.mean(axis=0)))
        assert fb.beacon.design == b.design
        assert np.max(np.hypot(*(fb.beacon.edges - b.edges).T)) < 0.005


@pytest.fixture(scope="module")
def edge_on(tmp_path_factory: pytest.TempPathFactory) -> tuple[TlsScenario, list[Beacon]]:
    """A far scene in which a station 17 m away sees a beacon's middle panel edge-on: a
    couple of columns of points on it, their mixed returns at its edges (a beam 3.5 mm
    wide at the exit) leave no piece of its own (the survey-in benchmark's far scene 2)."""
    import json

    options = TlsOptions(length_m=95.5, beacons=6, designs=3, stations=2, range_noise_m=0.0018,
                         step_rad=0.0006, roughness_m=0.0275, station_sigma_m=0.001,
                         panel_bow_m=0.001, beam_exit_m=0.0035)  # fmt: skip
    scene = simulate_tls(tmp_path_factory.mktemp("edge-on"), 14, options)
    points = {
        b["id"]: b["points_per_panel"] for b in json.loads(scene.truth.read_text())["beacons"]
    }
    thin = [b for b in read_survey(scene.survey) if 50 <= points[b.id][1] < 300
            and min(points[b.id]) >= 50]  # fmt: skip
    assert thin
    return scene, thin


def _surveyed_in(scene: TlsScenario) -> list[Beacon]:
    from mast.cloud.survey_in import SurveyInConfig, survey_in

    config = SurveyInConfig(noise_m=0.0018, station_sigma_m=0.001)
    found = survey_in([scene.e57], read_survey(scene.designs, apart=False), config).beacons
    return [f.beacon for f in found]


def test_a_beacon_whose_middle_panel_is_seen_edge_on_is_surveyed_in(
    edge_on: tuple[TlsScenario, list[Beacon]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Its outer panels and its design place the middle panel; its columns there fit it
    (docs/survey-in.md, "A middle panel seen edge-on"). Without that search it is missed,
    and nothing found is not a beacon of the scene."""
    from mast.cloud import survey_in as module

    scene, thin = edge_on
    truth = read_survey(scene.survey)
    found = _surveyed_in(scene)
    for b in found:
        t = _nearest(truth, b)
        assert b.design == t.design
        assert np.max(np.hypot(*(b.edges - t.edges).T)) < 0.005
    for b in thin:
        fb = _nearest(Survey(found), b)
        assert np.max(np.hypot(*(fb.edges - b.edges).T)) < 0.005, b.id
    monkeypatch.setattr(module, "_middle_edge_on", lambda *args: ([], []))
    without = Survey(_surveyed_in(scene))
    assert any(
        math.dist(_nearest(without, b).edges.mean(axis=0), b.edges.mean(axis=0)) > 0.25
        for b in thin
    )


def test_outer_panels_without_a_middle_one_between_them_are_no_beacon(
    edge_on: tuple[TlsScenario, list[Beacon]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same scene with the thin middle panels' points taken out of the candidates: the
    outer panels alone at their design's angle are not surveyed as a beacon."""
    from mast.cloud import survey_in as module
    from mast.cloud.detect import Candidates

    scene, thin = edge_on
    real = module.find_candidates

    def without_middles(*args: object, **kwargs: object) -> Candidates:
        cand = real(*args, **kwargs)  # type: ignore[arg-type]
        keep = np.ones(cand.xyz.shape[0], dtype=bool)
        for b in thin:
            a, d = b.edges[1], b.edges[2] - b.edges[1]
            t = np.clip((cand.xyz[:, :2] - a) @ d / float(d @ d), 0.0, 1.0)
            keep &= np.hypot(*(cand.xyz[:, :2] - a - t[:, None] * d).T) > 0.05
        return replace(cand, xyz=cand.xyz[keep], core=cand.core[keep],
                       time=None if cand.time is None else cand.time[keep])  # fmt: skip

    monkeypatch.setattr(module, "find_candidates", without_middles)
    found = Survey(_surveyed_in(scene))
    for b in thin:
        assert math.dist(_nearest(found, b).edges.mean(axis=0), b.edges.mean(axis=0)) > 0.25


def test_a_middle_panel_seen_edge_on_whose_beacon_is_refused_is_reported_where_it_is(
    edge_on: tuple[TlsScenario, list[Beacon]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A beacon whose middle panel's columns do not meet its outer panels at the design's
    angles is not surveyed; the report says where it stands, to scan it again."""
    from mast.cloud import survey_in as module
    from mast.cloud.survey_in_outputs import report_text

    scene, thin = edge_on
    monkeypatch.setattr(module, "_angles_hold", lambda *args: False)
    config = module.SurveyInConfig(noise_m=0.0018, station_sigma_m=0.001)
    designs = read_survey(scene.designs, apart=False)
    result = module.survey_in([scene.e57], designs, config)
    assert not result.beacons
    for b in thin:
        assert any(math.dist(c, b.edges.mean(axis=0)) < 0.25 for c in result.edge_on), b.id
    text = report_text(result, clouds=[scene.e57], designs_file=scene.designs)
    c = result.edge_on[0]
    assert f"a middle panel seen edge-on at E {c[0]:.3f} N {c[1]:.3f}" in text


def _face(a: np.ndarray, b: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Points on the vertical face from ``a`` to ``b`` (plan), 1.5-2.0 m high."""
    t = rng.uniform(0.0, 1.0, 600)
    xy = a + t[:, None] * (b - a) + rng.normal(0.0, 0.0005, (600, 2))
    return np.column_stack([xy, rng.uniform(1.5, 2.0, 600)])


@pytest.mark.parametrize("turn_deg", [0.0, 100.0, 179.0, -120.0])
def test_outer_panels_place_their_designs_middle_panel_and_no_mirror_of_it(
    turn_deg: float,
) -> None:
    """P1 and P3 seen, their design turned onto them places e1-e4 where they are, whichever
    way P1's piece runs; P3 taken for P1 (the beacon read backwards, a mirror image) is
    not placed where the beacon is."""
    from mast.cloud.detect import panel_from_points
    from mast.cloud.survey_in import _placed

    rng = np.random.default_rng(3)
    design = np.array([[0.0, 0.0], [0.3, 0.16], [0.9, 0.16], [1.08, 0.06]])
    c, s = math.cos(math.radians(turn_deg)), math.sin(math.radians(turn_deg))
    edges = design @ np.array([[c, s], [-s, c]]) + [100.0, -40.0]
    units = np.diff(design, axis=0) / np.hypot(*np.diff(design, axis=0).T)[:, None]
    shapes = [(units, np.hypot(*np.diff(design, axis=0).T))]
    p1 = panel_from_points(_face(edges[0], edges[1], rng), 0.0005)
    p3 = panel_from_points(_face(edges[2], edges[3], rng), 0.0005)
    assert not isinstance(p1, str)
    assert not isinstance(p3, str)
    placed = [e for sign in (1.0, -1.0) for _, e in _placed(p1, p3, sign, shapes)]
    assert len(placed) == 1
    assert np.max(np.hypot(*(placed[0] - edges).T)) < 0.003
    backwards = [e for sign in (1.0, -1.0) for _, e in _placed(p3, p1, sign, shapes)]
    assert all(np.max(np.hypot(*(e - edges).T)) > 0.05 for e in backwards)


def test_a_fitted_beacon_holds_its_designs_angles_to_half_a_degree_across_north() -> None:
    """Table 1's corner test on the fitted lines: a beacon turned to any heading (its
    panels' directions wrapping through +-180 deg) holds; one corner off by 1 deg does not,
    unless its lines are that uncertain."""
    from mast.cloud.survey_in import _angles_hold

    design = Beacon("d", np.array([[0.0, 0.0], [0.3, 0.16], [0.9, 0.16], [1.08, 0.06]]))
    sharp = [np.diag([1e-8, 1e-8])] * 3
    for turn in (0.0, 2.9, math.pi, -3.1):
        c, s = math.cos(turn), math.sin(turn)
        edges = design.edges @ np.array([[c, s], [-s, c]])
        assert _angles_hold(edges, design, sharp)
        bent = edges.copy()
        d = bent[3] - bent[2]
        k, m = math.cos(math.radians(1.0)), math.sin(math.radians(1.0))
        bent[3] = bent[2] + np.array([[k, -m], [m, k]]) @ d
        assert not _angles_hold(bent, design, sharp)
        assert _angles_hold(bent, design, [np.diag([1e-4, 1e-8])] * 3)
