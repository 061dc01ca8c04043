"""Dense scans: memory linear in the beams with a small constant (issue 9, item 6).

A normal scan has about a thousand beams; these have 30 000 and 100 000.
Reading holds no Python object per beam and segmentation no (returns x
longest piece) table; a whole ``locate`` of 100 000 beams, in its own
process, peaks within twice the memory of a normal scan's.
"""

from __future__ import annotations

import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest

from mast.bench.dense import measure, write_dense_scan
from mast.io import read_scan_csv
from mast.io.scan_csv import _read_whole
from mast.pipeline.segmentation import segment_scan

DENSE = 100_000


@pytest.fixture(scope="module")
def scans(tmp_path_factory: pytest.TempPathFactory) -> dict[int, tuple[Path, Path]]:
    folder = tmp_path_factory.mktemp("dense")
    return {n: write_dense_scan(folder, n) for n in (1081, 30_000, DENSE)}


T = TypeVar("T")


def _peak_bytes(fn: Callable[[], T]) -> tuple[int, T]:
    """Peak bytes Python allocated (numpy's arrays included) while ``fn`` ran, and its result."""
    tracemalloc.start()
    try:
        out = fn()
        return tracemalloc.get_traced_memory()[1], out
    finally:
        tracemalloc.stop()


def test_reading_a_dense_scan_streams_into_arrays(scans: dict[int, tuple[Path, Path]]) -> None:
    path, _ = scans[DENSE]
    peak, scan = _peak_bytes(lambda: read_scan_csv(path))
    # The file is 37 bytes a beam; whole-file reading with a float object per value
    # peaked at 260 bytes a beam. Arrays and the scan's own copies need about 50.
    assert peak < 1_000_000 + 80 * DENSE
    _, angles, ranges, _ = _read_whole(path)
    assert scan.angles_rad.tobytes() == angles.tobytes()
    assert np.array_equal(scan.ranges_m, ranges, equal_nan=True)


def test_segmenting_a_dense_scan_is_linear_in_memory(scans: dict[int, tuple[Path, Path]]) -> None:
    normal = segment_scan(read_scan_csv(scans[1081][0]))
    scan = read_scan_csv(scans[30_000][0])
    peak, seg = _peak_bytes(lambda: segment_scan(scan))
    # Partitioning one 30 000-return wall run held 30 000 x 128 candidate pieces
    # (4.7 kB a beam, 140 MB); now a fixed block of them and ~100 bytes a beam.
    assert peak < 8_000_000 + 200 * 30_000
    # The same walls and panels as at normal density: long runs are put back together.
    assert len(seg.segments) == len(normal.segments)


def test_a_dense_scan_locates_within_twice_a_normal_scans_memory(
    scans: dict[int, tuple[Path, Path]],
) -> None:
    normal = measure(*scans[1081], timeout_s=120)
    dense = measure(*scans[DENSE], timeout_s=120)
    assert normal.status == dense.status == "fix"
    assert dense.peak_rss_mb <= 2 * normal.peak_rss_mb
