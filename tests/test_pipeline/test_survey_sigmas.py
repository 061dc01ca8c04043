"""A survey's own ``sigma_m`` per edge, where it gives one, instead of one
``--survey-sigma`` for every edge."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from mast.core.beacon import Beacon, Survey
from mast.core.geometry import PanelSet
from mast.io.beacons_csv import write_survey
from mast.io.scan_csv import write_scan_csv
from mast.pipeline.locator import LocatorConfig, locate
from mast.report.record import ReportInputs, fix_record, fix_text, survey_weighing
from mast.sim import paper_scene, simulate_scan
from tests._cli import run_mast_text


def _with_sigmas(survey: Survey, sigmas: list[float]) -> Survey:
    return Survey(Beacon(b.id, b.edges, b.elevations, sigmas) for b in survey)


def test_a_panel_takes_the_mean_variance_of_its_edges_and_the_default_where_blank() -> None:
    survey = paper_scene().survey
    own = _with_sigmas(survey, [0.001, 0.003, math.nan, 0.005])
    var = PanelSet.from_survey(own).survey_variance(0.002)
    per_beacon = np.array([(1 + 9) / 2, (9 + 4) / 2, (4 + 25) / 2]) * 1e-6
    np.testing.assert_allclose(var, np.tile(per_beacon, len(survey)), rtol=1e-12)
    assert PanelSet.from_survey(own).worst_survey_sigma(0.002) == 0.005
    assert PanelSet.from_survey(own).worst_survey_sigma(0.009) == 0.009
    plain = PanelSet.from_survey(survey)
    assert plain.edge_sigma_m is None
    assert np.all(plain.survey_variance(0.002) == 0.002**2)


def _fixes(survey: Survey, sigma: float) -> list[tuple[float, ...]]:
    scene = paper_scene()
    rng = np.random.default_rng(7)
    cfg = LocatorConfig(survey_sigma_m=sigma)
    out = []
    for shot in scene.shots[:4]:
        scan = simulate_scan(scene.world, shot.pose, shot.scanner, rng=rng).scan
        fix = locate(scan, survey, config=cfg)
        assert fix.status == "fix", fix.detail
        assert fix.adjustment is not None
        p = fix.pose
        assert p is not None
        out.append((p.easting, p.northing, p.azimuth, *fix.adjustment.covariance.reshape(-1)))
    return out


def test_a_sigma_for_every_edge_equal_to_the_default_changes_nothing() -> None:
    survey = paper_scene().survey
    assert _fixes(_with_sigmas(survey, [0.004] * 4), 0.004) == _fixes(survey, 0.004)


def test_the_survey_sigma_widens_the_fix_edge_by_edge() -> None:
    survey = paper_scene().survey
    base = _fixes(survey, 0.003)
    loose = _fixes(_with_sigmas(survey, [0.003, 0.02, 0.02, 0.003]), 0.003)
    blank = _fixes(_with_sigmas(survey, [math.nan] * 4), 0.003)
    assert blank == base  # a blank sigma_m is the default's
    for a, b in zip(base, loose, strict=True):
        var_a = np.array(a[3:]).reshape(3, 3)
        var_b = np.array(b[3:]).reshape(3, 3)
        # the poses agree (the weights of the fit are the scanner's), the spread does not
        assert a[:2] == pytest.approx(b[:2], abs=1e-9)
        assert np.all(np.diag(var_b) > 1.5 * np.diag(var_a))


def test_the_report_says_how_the_survey_weighs_its_edges() -> None:
    scene = paper_scene()
    own = _with_sigmas(scene.survey, [0.001, 0.002, math.nan, 0.002])
    text = survey_weighing(own, 0.003)
    assert text is not None
    n = 4 * len(own)
    assert text == (
        f"the survey's sigma_m on {n - len(own)} of {n} edges (1.0 to 2.0 mm), 3.0 mm on the rest"
    )
    assert survey_weighing(scene.survey, 0.003) is None
    shot = scene.shots[0]
    scan = simulate_scan(scene.world, shot.pose, shot.scanner, rng=np.random.default_rng(1)).scan
    fix = locate(scan, own)
    report = fix_text(fix, scan=scan, inputs=ReportInputs(survey_sigmas=text))
    assert f"Survey σ      {text}" in report
    record = fix_record(fix, scan=scan, inputs=ReportInputs(survey_sigmas=text))
    assert record["inputs"]["survey_sigmas"] == text
    schema = json.loads((Path(__file__).parents[2] / "docs" / "fix.schema.json").read_text())
    jsonschema.validate(record, schema)


def test_one_loose_edge_is_named_and_warned_of(tmp_path: Path) -> None:
    """An edge's sigma_m far above the rest widens every beacon's identification: the
    commands say which."""
    scene = paper_scene()
    sig = {b.id: [0.002, 0.002, 0.002, 0.002] for b in scene.survey}
    first = scene.survey.ids[0]
    sig[first][2] = 0.3
    loose = Survey(Beacon(b.id, b.edges, b.elevations, sig[b.id]) for b in scene.survey)
    assert loose.loose_edges(0.003) == [f"{first} e3 (0.300 m)"]
    assert _with_sigmas(scene.survey, [0.002] * 4).loose_edges(0.003) == []
    survey = tmp_path / "beacons.csv"
    write_survey(survey, loose)
    shot = scene.shots[0]
    scan = simulate_scan(scene.world, shot.pose, shot.scanner, rng=np.random.default_rng(2)).scan
    path = tmp_path / "scan.csv"
    write_scan_csv(path, scan)
    done = run_mast_text("locate", str(path), "-b", str(survey))
    assert f"far above the rest: {first} e3 (0.300 m)" in done.stderr
    assert done.returncode in (0, 3), done.stderr
