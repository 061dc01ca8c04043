"""Robustness benchmark: hostile scenes and a many-beacon drift, thousands of scans.

Counts, per family: scans, scans owed a fix (two beacons each show two clean
panels: at least 8 returns seen at 15 degrees or more), the fix rate on
those, wrong fixes (a fix more than 5 cm or 0.25 degrees off *and* outside
five of its own standard deviations), and the no-fix reasons.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast.bench.rows import write_rows
from mast.core.pose import Pose2D
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.sim import Scene, drift_scene, hard_scene
from mast.sim.owed import OWED_CLEAN
from mast.sim.scanner import SimulatedScan

__all__ = ["RobustnessSummary", "is_wrong", "owed_clean", "pose_error", "run_robustness"]

WRONG_POSITION_M = 0.05
WRONG_AZIMUTH_RAD = math.radians(0.25)
#: ... and outside this many of its own standard deviations in one of its parameters.
WRONG_SIGMAS = 5.0


def owed_clean(sim: SimulatedScan) -> bool:
    """Two beacons each show two clean panels (>= 8 returns, >= 15 degrees incidence)."""
    return sim.owes_fix(OWED_CLEAN)


def pose_error(got: Pose2D, truth: Pose2D) -> NDArray[np.float64]:
    """``got - truth``: easting and northing (m), azimuth (rad, within +-pi)."""
    return np.array(
        [
            got.easting - truth.easting,
            got.northing - truth.northing,
            math.remainder(got.azimuth - truth.azimuth, 2 * math.pi),
        ]
    )


def is_wrong(fix: Fix, truth: SimulatedScan | Pose2D) -> bool:
    """More than 5 cm or 0.25 deg off and outside five of its own standard deviations."""
    if not fix.ok or fix.pose is None or fix.adjustment is None:
        return False
    err = pose_error(fix.pose, truth if isinstance(truth, Pose2D) else truth.pose)
    big = math.hypot(err[0], err[1]) > WRONG_POSITION_M or abs(err[2]) > WRONG_AZIMUTH_RAD
    outside = bool(np.any(np.abs(err) > WRONG_SIGMAS * fix.adjustment.sigma))
    return big and outside


@dataclass
class RobustnessSummary:
    family: str
    scans: int = 0
    owed: int = 0
    owed_fixed: int = 0
    fixes: int = 0
    wrong: int = 0
    reasons: Counter[str] = field(default_factory=Counter)
    seconds: float = 0.0

    @property
    def fix_rate_owed(self) -> float:
        return self.owed_fixed / self.owed if self.owed else math.nan

    def tally(self, fixed: bool, owed: bool, wrong: bool) -> None:
        """Count one scan: whether it was fixed, owed a fix, and fixed wrong."""
        self.scans += 1
        self.owed += owed
        self.owed_fixed += owed and fixed
        self.fixes += fixed
        self.wrong += wrong

    def line(self) -> str:
        reasons = ", ".join(f"{k} {v}" for k, v in self.reasons.most_common())
        return (
            f"{self.family:<7} scans {self.scans:5d}  owed {self.owed:5d}  fixed where owed "
            f"{self.owed_fixed:5d} ({100 * self.fix_rate_owed:5.1f} %)  fixes {self.fixes:5d}  "
            f"WRONG {self.wrong}  no-fix: {reasons}  ({self.seconds:.0f} s)"
        )


def _scenes(family: str, scenes: int, seed: int) -> Iterator[Scene]:
    for i in range(scenes):
        if family == "hard":
            yield hard_scene(seed + i // 4, i % 4, poses=5)
        else:
            yield drift_scene(seed + i, 0, poses=10)


def run_robustness(
    *,
    hard_scenes: int = 400,
    drift_scenes: int = 60,
    seed: int = 0,
    out_dir: Path | None = None,
    echo: Callable[[str], object] = print,
) -> list[RobustnessSummary]:
    """Run both families; write ``robustness_<family>.csv`` (one row per scan) when asked."""
    out: list[RobustnessSummary] = []
    cfg = LocatorConfig(range_sigma_m=0.012)
    for family, count in (("hard", hard_scenes), ("drift", drift_scenes)):
        t0 = time.perf_counter()
        s = RobustnessSummary(family)
        rows: list[dict[str, object]] = []
        for scene in _scenes(family, count, seed):
            for shot, sim in zip(scene.shots, scene.simulate_all(), strict=True):
                fix = locate(sim.scan, scene.survey, config=cfg)
                owed = owed_clean(sim)
                wrong = is_wrong(fix, sim)
                s.tally(fix.ok, owed, wrong)
                if not fix.ok:
                    s.reasons[fix.reason or "?"] += 1
                if wrong:
                    echo(
                        f"  WRONG FIX {scene.name} {shot.label}: {fix.pose} "
                        f"(true {shot.pose}), {fix.beacons}"
                    )
                rows.append(
                    {
                        "scene": scene.name,
                        "shot": shot.label,
                        "owed": int(owed),
                        "status": fix.status,
                        "reason": fix.reason or "",
                        "wrong": int(wrong),
                        "beacons": " ".join(fix.beacons),
                        "error_m": (
                            math.hypot(
                                fix.pose.easting - shot.pose.easting,
                                fix.pose.northing - shot.pose.northing,
                            )
                            if fix.pose is not None
                            else ""
                        ),
                    }
                )
        s.seconds = time.perf_counter() - t0
        out.append(s)
        echo(s.line())
        if out_dir is not None:
            write_rows(out_dir / f"robustness_{family}.csv", rows)
    return out
