"""Whole-mine survey benchmark: a survey file of thousands of beacons read, checked and
indexed, timed (the time ``mast locate`` spends before it reads a scan)."""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mast.core.beacon import Beacon, Survey

__all__ = ["mine_survey", "run_survey_load"]

#: Beacons every this many metres along a drift, each drift this far from the next.
SPACING_M = 25.0
DRIFT_GAP_M = 50.0
#: Beacons along one drift.
PER_DRIFT = 100


def mine_survey(beacons: int, designs: int, seed: int = 0) -> Survey:
    """A mine's survey: ``beacons`` on alternate walls of parallel drifts, built to
    ``designs`` random designs, in UTM-sized coordinates."""
    from mast.sim.design import random_design

    rng = np.random.default_rng(seed)
    kinds = [random_design(rng) for _ in range(designs)]
    out = []
    for k in range(beacons):
        drift, station = divmod(k, PER_DRIFT)
        side = 1.0 if k % 2 else -1.0
        e = kinds[k % designs].edges_local * np.array([1.0, side])
        at = np.array(
            [500_000.0 + station * SPACING_M, 7_000_000.0 + drift * DRIFT_GAP_M + 2.5 * side]
        )
        out.append(Beacon(f"B{k:05d}", e + at))
    return Survey(out)


def run_survey_load(
    *,
    beacons: int = 10_000,
    designs: tuple[int, ...] = (8, 10_000),
    repeats: int = 3,
    range_max_m: float = 80.0,
    echo: Callable[[str], object] = print,
) -> dict[int, float]:
    """Median seconds to read, check and index a ``beacons`` survey, per number of designs,
    for a scanner of ``range_max_m`` (the index keeps edge pairs within twice the range)."""
    from mast.io import read_survey, write_survey
    from mast.pipeline.locator import survey_index

    out: dict[int, float] = {}
    with tempfile.TemporaryDirectory(prefix="mast-survey-") as tmp:
        for n_designs in designs:
            path = Path(tmp) / f"mine_{n_designs}.csv"
            write_survey(path, mine_survey(beacons, min(n_designs, beacons)))
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                survey = read_survey(path)
                survey_index(survey, range_max_m)
                times.append(time.perf_counter() - t0)
            out[n_designs] = statistics.median(times)
            size = path.stat().st_size / 2**20
            echo(
                f"{beacons} beacons of {min(n_designs, beacons)} design(s) ({size:.1f} MiB): read, "
                f"checked and indexed for a {range_max_m:g} m scanner in {out[n_designs]:.2f} s "
                f"(median of {repeats})"
            )
    return out
