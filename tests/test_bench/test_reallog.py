"""The real-log run benchmark: a stretch of a real CARMEN log (a scan every metre or so)
tracked as ``mast track --max-gap 3`` does, with beacons cast on its real walls."""

from __future__ import annotations

import math

import pytest

from mast.bench.clutter import CARMEN_LOGS
from mast.bench.reallog import run_real_log
from mast.io.carmen_log import read_carmen_log
from tests._paths import SHARED_DATA

LOG = SHARED_DATA / CARMEN_LOGS["freiburg-101"]
pytestmark = pytest.mark.skipif(not LOG.is_file(), reason="shared data not present")


def test_a_real_log_is_chained_between_fixes_and_its_scans_judged() -> None:
    data = list(read_carmen_log(LOG))[:30]
    lines: list[str] = []
    chained = run_real_log("freiburg-101", data, seed=1, max_gap_s=3.0, echo=lines.append)
    assert chained.scans == 30
    assert 0 < chained.fixes < chained.placed <= 30
    assert chained.odometry == chained.placed - chained.fixes
    assert len(chained.inside_95) == chained.odometry
    assert all(math.isfinite(e) for e in chained.errors_m)
    assert "odometry-placed" in lines[0]
    # At mast track's default gap these scans, 1.6-2.6 s apart, are never chained.
    alone = run_real_log("freiburg-101", data, seed=1, max_gap_s=0.5, echo=lines.append)
    assert alone.odometry == 0
    assert alone.placed == alone.fixes
