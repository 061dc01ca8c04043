"""Benchmarks run on tiny subsets: the detection-limit evidence and the mine-wide survey."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose

from mast.bench.accuracy import ACCURACY_CONFIGS, owed_poses, run_accuracy
from mast.bench.detection import detection_bins, detection_evidence, detection_table
from mast.bench.minewide import MinewideSummary, minewide_survey, run_minewide
from mast.pipeline.locator import LocatorConfig, locate
from mast.sim import random_scene, simulate_scan
from mast.sim.owed import OWED

MODEL = ACCURACY_CONFIGS[0]  # 270deg-0.5deg-12mm


def test_accuracy_rows_carry_detection_evidence_and_table(tmp_path: Path) -> None:
    lines: list[str] = []
    run_accuracy(configs=[MODEL], poses=3, draws=2, out_dir=tmp_path, echo=lines.append)
    with (tmp_path / f"accuracy_{MODEL.name}.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    for r in rows:
        # every pose is owed a fix, so both beacons show >= 3 returns on two panels
        assert int(r["evidence_returns"]) >= OWED.min_points
        assert 0.0 < float(r["evidence_range_m"]) <= MODEL.range_max_m
        assert 0.0 < float(r["evidence_direction_sigma_deg"]) < 90.0
    table = lines[-1]
    for label in ("3-4", "5-7", "8-11", "12-19", "20-39", ">=40", "<0.5", "0.5-1", ">=10"):
        assert f" {label} " in table
    assert "evidence_returns" in table
    assert "evidence_direction_sigma_deg" in table
    with (tmp_path / "detection.csv").open() as fh:
        det = list(csv.DictReader(fh))
    assert {d["measure"] for d in det} == {"evidence_returns", "evidence_direction_sigma_deg"}
    for measure in ("evidence_returns", "evidence_direction_sigma_deg"):
        assert sum(int(d["draws"]) for d in det if d["measure"] == measure) == 6


def test_evidence_returns_is_what_the_owed_rule_thresholds() -> None:
    exact = MODEL.noise_free()
    owed = 0
    for idx in range(3):
        scene = random_scene(1, idx)
        for shot in scene.shots:
            truth = simulate_scan(scene.world, shot.pose, exact)
            ev = detection_evidence(truth, scene.survey, range_sigma_m=MODEL.range_sigma_m)
            is_owed = truth.owes_fix(OWED)
            owed += is_owed
            assert (ev.returns >= OWED.min_points) == is_owed
            if ev.returns:
                assert len(ev.beacons) == 2
                assert math.isfinite(ev.range_m)
            else:
                assert math.isnan(ev.direction_sigma_deg)
    assert owed > 0


def test_detection_table_bins_draws_and_shares_misses_by_reason() -> None:
    def row(returns: int, sigma: float, reason: str = "") -> dict[str, object]:
        return {
            "fixed": int(not reason),
            "reason": reason,
            "evidence_returns": returns,
            "evidence_direction_sigma_deg": sigma,
        }

    rows = {
        "cfg": [
            row(3, 0.3),
            row(4, 0.7, "one_beacon"),
            row(4, 0.7, "one_beacon"),
            row(4, 0.7, "no_beacon"),
            row(45, 12.0),
            row(2, 1.5, "no_beacon"),
        ]
    }
    bins = {(b.measure, b.label): b for b in detection_bins(rows)}
    low = bins[("evidence_returns", "3-4")]
    assert (low.draws, low.fixed) == (4, 1)
    assert low.misses["one_beacon"] == 2
    assert low.misses["no_beacon"] == 1
    assert bins[("evidence_returns", ">=40")].draws == 1
    assert bins[("evidence_returns", "<3")].draws == 1  # listed only when not empty
    assert bins[("evidence_returns", "5-7")].draws == 0
    assert bins[("evidence_direction_sigma_deg", "0.5-1")].draws == 3
    assert bins[("evidence_direction_sigma_deg", ">=10")].draws == 1
    table = detection_table(rows)
    line = next(x for x in table.splitlines() if " 3-4 " in x)
    assert line.split() == ["cfg", "3-4", "4", "25.0", "33", "67"]  # no_beacon, one_beacon
    assert "inconsistent" not in table  # reasons that never occur get no column


def test_minewide_survey_hides_exact_copies_out_of_reach() -> None:
    scene = random_scene(0, 1)
    poses = [s.pose for s in scene.shots]
    big = minewide_survey(
        scene.survey, poses, copies=40, clearance_m=40.0, rng=np.random.default_rng(0)
    )
    assert len(big) == len(scene.survey) + 40
    assert big.ids[: len(scene.survey)] == scene.survey.ids
    assert big.ids[len(scene.survey)] == "X0001"
    assert big.ids[-1] == "X0040"
    xy = np.array([p.position for p in poses])
    originals = list(scene.survey)
    for k, copy in enumerate(list(big)[len(originals) :]):
        src = originals[k % len(originals)]
        assert_allclose(copy.template.panel_lengths, src.template.panel_lengths, atol=1e-9)
        assert_allclose(copy.template.deflections, src.template.deflections, atol=1e-9)
        d = np.hypot(*(copy.edges[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        assert d.min() >= 40.0


def test_minewide_run_matches_local_run() -> None:
    lines: list[str] = []
    s = run_minewide(poses=3, copies=40, echo=lines.append)
    assert isinstance(s, MinewideSummary)
    assert s.poses == len(s.scans) == 3
    assert s.min_copy_distance_m >= MODEL.range_max_m + 10.0
    assert [x.local_status for x in s.scans] == [x.minewide_status for x in s.scans]
    assert s.local_fixes == s.minewide_fixes > 0
    assert s.status_differ == s.pose_differ == s.copy_fixes == 0
    for x in s.scans:
        assert not x.differs
        if x.local_status == "fix":
            assert x.position_diff_m <= 1e-3
            assert x.azimuth_diff_arcsec <= 1.0
            assert not any(b.startswith("X") for b in x.minewide_beacons)
    assert lines == [lines[0]]
    assert f"fixes {s.local_fixes} vs {s.minewide_fixes}," in lines[0]


def test_minewide_copies_do_not_crowd_out_the_true_single_hypothesis() -> None:
    # Pose 4 of the benchmark: fixed on a single-node hypothesis of its second node (B2).
    scene, shot = owed_poses(MODEL, 5, 0)[4]
    big = minewide_survey(
        scene.survey,
        [s.pose for s in scene.shots],
        copies=184,
        clearance_m=MODEL.range_max_m + 10.0,
        rng=np.random.default_rng([0, 1, 11]),
    )
    sim = simulate_scan(scene.world, shot.pose, MODEL, rng=np.random.default_rng([0, 4, 7]))
    cfg = LocatorConfig(range_sigma_m=MODEL.range_sigma_m, survey_sigma_m=0.0)
    assert locate(sim.scan, scene.survey, config=cfg).ok
    assert locate(sim.scan, big, config=cfg).ok


def test_minewide_run_does_not_depend_on_survey_order() -> None:
    s = run_minewide(poses=3, copies=40, copies_first=True, echo=lambda _: None)
    assert [x.local_status for x in s.scans] == [x.minewide_status for x in s.scans]


def test_tracking_bench_good_prior_fixes_wrong_prior_refuses() -> None:
    from mast.bench.tracking import run_tracking

    lines: list[str] = []
    (s,) = run_tracking(configs=(MODEL,), poses=4, draws=1, echo=lines.append)
    assert s.scans == s.wrong_prior_scans == 4
    assert s.fixed == 4
    assert s.wrong == 0
    assert s.wrong_prior_fixes == 0
    assert "good prior: fixed 4/4" in lines[0]


def test_longdrive_sends_each_scan_through_its_protocol() -> None:
    from mast.bench.longdrive import as_sent
    from mast.sim.drive import drive_scene

    sim = next(drive_scene(3, scans=2, rate_hz=40.0).iter_simulated())
    scan = sim.scan
    for kind in ("sick", "hokuyo"):
        sent = as_sent(kind, scan, counter=7)
        assert sent.stamp_ns == scan.stamp_ns
        assert_allclose(sent.angles_rad, scan.angles_rad, atol=1e-9)
        both = sent.valid & scan.valid
        assert both.sum() == scan.valid.sum()
        # whole millimetres, as both protocols send ranges
        assert_allclose(sent.ranges_m[both] * 1000.0, np.rint(scan.ranges_m[both] * 1000.0))
        assert np.any(sent.ranges_m[both] != scan.ranges_m[both])


def test_longdrive_counts_owed_fixes_and_flags_none_wrong_on_a_short_drive(
    tmp_path: Path,
) -> None:
    import csv

    from mast.bench.longdrive import run_longdrive

    lines: list[str] = []
    figures = run_longdrive(
        scans=150, seeds=1, workers=1, out_dir=tmp_path / "rows", echo=lines.append
    )
    assert [(f.kind, f.rate_hz) for f in figures] == [("sick", 50.0), ("hokuyo", 40.0)]
    for f in figures:
        assert f.scans == 150
        assert 0 < f.owed <= f.scans
        assert f.owed_fixed == f.owed
        assert not f.wrong
        assert f.owed_fixed <= f.fixes
        assert f.tracked_fixes < f.fixes
        with (tmp_path / "rows" / f"longdrive_{f.kind}_0.csv").open() as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == 150
        assert sum(r["status"] == "fix" for r in rows) == f.fixes
        assert sum(r["owed"] == "1" for r in rows) == f.owed
        assert all(r["error_mm"] == "" for r in rows if r["status"] != "fix")
        assert max(float(r["error_mm"]) for r in rows if r["status"] == "fix") < 50.0
    assert lines[-1].startswith("all: 300 scans")
