"""The speed benchmark on a tiny configuration: every figure present and sane."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from mast.bench.speed import (
    PEER_MISSING,
    Stats,
    kept_scans,
    measure_locate,
    measure_peer,
    peer,
    run_speed,
    stages,
)
from mast.bench.speed.model import OTHER_STAGE, STAGES
from mast.core.pose import Pose2D
from mast.pipeline.locator import STAGES as LOCATOR_STAGES


def _positive(s: Stats) -> None:
    assert s.count > 0
    assert 0.0 < s.median <= s.p95 <= s.max
    assert math.isfinite(s.mean)


def test_tiny_run_has_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "speed.txt"
    lines: list[str] = []
    figs = run_speed(
        scans=5,
        scans_360=2,
        bag_scans=(20,),
        track_scans=(20,),
        minewide_poses=2,
        survey_beacons=50,
        startup_runs=1,
        tracked_scans=12,
        out=out,
        echo=lines.append,
    )
    # 1. locate per scan, at 1081 and 1800 beams, every kept scan fixed or owed one
    assert [f.beams for f in figs.locate] == [1081, 1800]
    for f in figs.locate:
        assert f.scans == (5 if f.beams == 1081 else 2)
        assert 0 < f.fixed <= f.scans
        _positive(f.time_ms)
        assert f.time_ms.max < 10_000  # seconds per scan would mean a wrong unit
        # fixes of simulated scans are good to centimetres and arc-minutes
        assert f.position_err_mm.max < 50.0
        assert f.azimuth_err_arcsec.max < 600.0
        stages = dict(f.stages_ms)
        assert list(stages) == [s for s, _ in STAGES] + [OTHER_STAGE]
        _positive(stages["segmentation"])
        _positive(stages["verification (ICP)"])
        # the stages add up to the wrapped total, scan by scan, so their means do too
        assert sum(s.mean for s in stages.values()) == pytest.approx(f.wrapped_total_ms.mean)
        assert stages[OTHER_STAGE].mean >= 0.0
        assert f.hot
        assert all(0.0 < share <= 1.0 for _, share in f.hot)
    # 2. whole runs: read, locate and track of the 20-scan bag, ratios finite
    assert [(r.step, r.scans) for r in figs.runs] == [("read", 20), ("locate", 20), ("track", 20)]
    read = figs.runs[0]
    for r in figs.runs:
        assert r.seconds > 0.0
        assert math.isfinite(r.scans_per_s)
        assert r.scans_per_s > 0.0
        assert 10.0 < r.peak_mb < 10_000.0
        assert math.isfinite(read.scans_per_s / r.scans_per_s)
    # 3. mine-wide: the copies change no fix, the ratio is finite
    mw = figs.minewide
    assert mw is not None
    assert mw.survey_beacons[0] >= 50
    assert mw.status_differ == 0
    assert mw.pose_differ == 0
    assert math.isfinite(mw.median_ratio)
    assert mw.median_ratio > 0.0
    # 4. start-up
    assert figs.startup is not None
    assert 0.0 < figs.startup.python_median_s < figs.startup.help_median_s < 60.0
    # 5. the peer: measured with a sane error, or reported missing
    if figs.peer is None:
        assert figs.peer_note == PEER_MISSING
        assert any(PEER_MISSING in line for line in lines)
    else:
        p = figs.peer
        assert p.scans > 0
        _positive(p.time_ms)
        _positive(p.mast_time_ms)
        assert p.position_err_mm.max < 1000.0
        assert p.azimuth_err_arcsec.max < 3600.0 * 5
    # the printed table holds each section, and --out holds the same text
    text = "\n".join(lines)
    # 6. tracked scans: the drive's first scan has no prior, the rest are fixed near it
    t = figs.tracked
    assert t is not None
    assert t.scans == 12
    assert t.global_ms.count == 1
    assert t.tracked_ms.count >= 8
    assert t.narrow <= t.tracked_ms.count
    assert t.position_err_mm.max < 50.0
    stages = dict(t.stages_ms)
    assert list(stages) == [*LOCATOR_STAGES, OTHER_STAGE]
    assert all(s.count == t.tracked_ms.count for s in stages.values())
    _positive(stages["window"])  # the window's bound and grid search
    _positive(stages["verification"])
    # most tracked fixes need no segmentation (nor, then, identification)
    assert stages["segmentation"].median == 0.0
    assert stages["identification"].median == 0.0
    for section in (
        "1. locate",
        "2. whole runs",
        "3. mine-wide",
        "4. start-up",
        "5. peer",
        "6. tracked scans",
    ):
        assert section in text
    assert "mast locate BAG" in text
    assert "mast track BAG" in text
    assert "nan" not in text
    assert out.read_text(encoding="utf-8") == text + "\n"


def test_missing_peer_is_reported_not_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "small_gicp", None)  # import raises ImportError
    _, kept = measure_locate(2, profile=False)
    assert measure_peer(kept) is None
    lines: list[str] = []
    figs = run_speed(
        scans=2,
        scans_360=0,
        bag_scans=(),
        track_scans=(),
        minewide_poses=0,
        startup_runs=0,
        tracked_scans=0,
        echo=lines.append,
    )
    assert figs.peer is None
    assert lines[-1] == f"  {PEER_MISSING}"
    assert "pip install 'mast-survey[bench]'" in PEER_MISSING


def test_peer_recovers_the_pose_from_its_offset_start() -> None:
    pytest.importorskip("small_gicp")
    kept = kept_scans(0, 4)
    peer = measure_peer(kept)
    assert peer is not None
    assert peer.scans == sum(f.ok for f in kept.fixes) > 0
    # from 200 mm and 2 degrees off, it ends within centimetres and arc-minutes
    assert peer.position_err_mm.max < 30.0
    assert peer.azimuth_err_arcsec.max < 300.0


def test_stage_clocks_cover_the_locator_and_are_removed() -> None:
    from mast.pipeline import locator

    before = {name: getattr(locator, name) for _, names in STAGES for name in names}
    assert all(callable(fn) for fn in before.values())  # no stage renamed unnoticed
    clock: dict[str, float] = {}
    kept = kept_scans(0, 1)
    with stages._stage_clocks(clock):
        locator.locate(kept.sims[0].scan, kept.survey)
    assert clock["segmentation"] > 0.0
    assert clock["verification (ICP)"] > 0.0
    after = {name: getattr(locator, name) for name in before}
    assert after == before


def test_pose_matrix_round_trip() -> None:
    pose = Pose2D(1234.5, 6789.25, 2.5)
    m = peer._matrix(pose)
    back = peer._pose_of(m)
    assert back.easting == pytest.approx(pose.easting)
    assert back.northing == pytest.approx(pose.northing)
    assert math.remainder(back.azimuth - pose.azimuth, math.tau) == pytest.approx(0.0, abs=1e-12)
    # the matrix maps scanner points as the pose does
    pts = np.array([[1.0, 0.0], [0.0, 2.0], [-3.0, 4.0]])
    lifted = np.column_stack([pts, np.zeros(3), np.ones(3)])
    np.testing.assert_allclose((lifted @ m.T)[:, :2], pose.scanner_to_mine(pts))


def test_stats_of_nothing_is_nan() -> None:
    s = Stats.of([])
    assert s.count == 0
    assert math.isnan(s.median)
    t = Stats.of([3.0, 1.0, 2.0])
    assert (t.median, t.max, t.mean, t.count) == (2.0, 3.0, 2.0, 3)
