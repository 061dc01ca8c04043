"""The real-clutter benchmark on a handful of scans of a real CARMEN log."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from mast.bench.clutter import (
    CARMEN_LOGS,
    ClutterSummary,
    WallSite,
    beacon_designs,
    chord_range_for,
    run_clutter_log,
)
from mast.core.beacon import Survey
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.io.carmen_log import read_carmen_log
from mast.pipeline.locator import NO_FIX_REASONS
from tests._paths import SHARED_DATA

LOG = SHARED_DATA / CARMEN_LOGS["freiburg-101"]
pytestmark = pytest.mark.skipif(not LOG.is_file(), reason="shared data not present")


@pytest.fixture(scope="module")
def handful() -> list[tuple[Scan, Pose2D]]:
    return list(read_carmen_log(LOG))[40:48]


@pytest.fixture(scope="module")
def run(handful: list[tuple[Scan, Pose2D]]) -> tuple[ClutterSummary, Survey, list[WallSite]]:
    return run_clutter_log("freiburg-101", handful, beacons=4, seed=3, echo=lambda _s: None)


def test_beacons_stand_on_real_walls(
    handful: list[tuple[Scan, Pose2D]], run: tuple[ClutterSummary, Survey, list[WallSite]]
) -> None:
    _, survey, sites = run
    assert len(survey) == len(sites) == 4
    returns = cKDTree(np.vstack([pose.scanner_to_mine(s.points()[1]) for s, pose in handful]))
    for beacon, site in zip(survey, sites, strict=True):
        beacon.check_identifiable()
        e = beacon.edges
        # both free ends and the chord's middle lie on returns of the real wall
        distance, _ = returns.query(np.vstack([e[0], e[3], site.point]))
        assert np.all(distance < 0.05), (beacon.id, distance)
        assert np.hypot(*(0.5 * (e[0] + e[3]) - site.point)) < 1e-9
        # the inner edges stand out towards the side the scanner saw the wall from
        assert np.all((e[1:3] - site.point) @ site.free_side > 0.03)
        for i in site.seen_by:
            assert (handful[i][1].position - site.point) @ site.free_side > 0.5
    middles = np.array([s.point for s in sites])
    gaps = np.hypot(*(middles[:, None] - middles[None, :]).transpose(2, 0, 1))
    assert np.all(gaps[~np.eye(len(sites), dtype=bool)] >= 2.0)


def test_counts_are_sane(run: tuple[ClutterSummary, Survey, list[WallSite]]) -> None:
    summary, _, _ = run
    assert summary.scans == len(summary.outcomes) == 8
    assert 0 < summary.owed <= summary.scans
    assert summary.owed_fixed <= summary.owed
    assert summary.fixes == summary.owed_fixed + summary.fixes_not_owed
    assert summary.fixes + sum(summary.reasons.values()) == summary.scans
    assert set(summary.reasons) <= set(NO_FIX_REASONS)
    assert summary.wrong == 0
    assert summary.owed_fixed >= summary.owed - 1
    assert len(summary.errors_mm) == summary.fixes
    assert max(summary.errors_mm) < 50.0
    for o in summary.outcomes:
        assert (o.status == "fix") == math.isfinite(o.error_m)
        if o.owed:
            assert len(o.beacons_hit) >= 2
    line = summary.line()
    assert line.startswith("freiburg-101")
    assert f"owed {summary.owed:4d}" in line


def test_designs_are_identifiable_distinct_or_repeated_and_seeded() -> None:
    lo, hi = chord_range_for(math.radians(1.0))
    assert (lo, hi) == pytest.approx((0.9, 1.8))
    a = beacon_designs(12, np.random.default_rng(5), chord_range_m=(lo, hi))
    b = beacon_designs(12, np.random.default_rng(5), chord_range_m=(lo, hi))
    assert [d.edges_local.tolist() for d in a] == [d.edges_local.tolist() for d in b]
    assert len({id(d) for d in a}) == 10  # two of twelve repeat an earlier design
    for d in a:
        assert lo - 1e-9 <= d.chord_m <= hi + 1e-9
        assert d.depth_m <= 0.4
