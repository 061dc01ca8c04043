"""The scans timed: a simulated drive's scans that give a fix or show two beacons."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

from mast.bench.speed.model import IN_VIEW_RETURNS
from mast.core.beacon import Survey
from mast.core.heap import QuietCollector
from mast.core.pose import Pose2D
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.sim import DriveScene, ScannerModel, SimulatedScan, drive_scene

__all__ = ["KeptScans", "kept_scans", "pose_errors"]


def _beacons_in_view(sim: SimulatedScan, min_returns: int) -> int:
    per: dict[str, int] = {}
    for (beacon, _), count in sim.panel_hits().items():
        per[beacon] = per.get(beacon, 0) + count
    return sum(c >= min_returns for c in per.values())


def _drive(seed: int, count: int, model: ScannerModel | None) -> DriveScene:
    # A drive long enough for ``count`` scans with two beacons in view: about half of
    # its scans are, in the beacon stretches; the loop stops once it has them.
    scene = drive_scene(seed, scans=max(20 * count, 200))
    if model is None:
        return scene
    return replace(scene, shots=tuple(replace(s, scanner=model) for s in scene.shots))


@dataclass(frozen=True, slots=True)
class KeptScans:
    """Scans of a drive that give a fix or show two beacons, each located once.

    ``seconds`` is what each ``locate`` took (the first, untimed call before them
    built the survey's index).
    """

    survey: Survey
    scanner: ScannerModel
    sims: tuple[SimulatedScan, ...]
    fixes: tuple[Fix, ...]
    seconds: tuple[float, ...]


def kept_scans(seed: int, count: int, model: ScannerModel | None = None) -> KeptScans:
    """The first ``count`` scans of a simulated drive that give a fix or show two
    beacons (``IN_VIEW_RETURNS`` returns or more each), each located once, timed.

    ``model`` replaces the drive's scanner (270 deg at 0.25 deg, 12 mm); the locator
    is told the scanner's range noise.
    """
    scene = _drive(seed, count, model)
    scanner = scene.shots[0].scanner
    cfg = LocatorConfig(range_sigma_m=scanner.range_sigma_m)
    sims: list[SimulatedScan] = []
    fixes: list[Fix] = []
    seconds: list[float] = []
    warm = False
    # As `mast locate` and `mast live` do: what is alive once the first scan is located
    # is frozen, out of the collector's full passes (mast.core.heap).
    with QuietCollector() as heap:
        for sim in scene.iter_simulated():
            if len(sims) >= count:
                break
            # fewer than two beacons hit at all: no fix is possible (two are needed)
            if _beacons_in_view(sim, 1) < 2:
                continue
            if not warm:  # the survey's index, any compilation: once per run, not per scan
                locate(sim.scan, scene.survey, config=cfg)
                warm = True
            t0 = time.perf_counter()
            fix = locate(sim.scan, scene.survey, config=cfg)
            dt = time.perf_counter() - t0
            heap.step()
            if fix.ok or _beacons_in_view(sim, IN_VIEW_RETURNS) >= 2:
                sims.append(sim)
                fixes.append(fix)
                seconds.append(dt)
    return KeptScans(scene.survey, scanner, tuple(sims), tuple(fixes), tuple(seconds))


def pose_errors(truth: Pose2D, got: Pose2D) -> tuple[float, float]:
    """Position error in mm and azimuth error in arc-seconds."""
    pos = 1e3 * math.hypot(got.easting - truth.easting, got.northing - truth.northing)
    turn = math.remainder(got.azimuth - truth.azimuth, math.tau)
    return pos, abs(math.degrees(turn)) * 3600
