"""Tracking benchmark: a fix from a prior pose, and no fix from a wrong one.

The accuracy benchmark's owed poses and noise draws (its first ``draws``
draws of each pose), located with a prior as a vehicle's previous fix or a
surveyor's ``--near`` gives one:

- **good prior**: centred within ``radius_m`` and ``tolerance_deg`` of the
  true pose (drawn uniformly over the disc and the angle window), with that
  radius and tolerance. Every such scan is owed a fix.
- **wrong prior**: centred ``wrong_offset_m`` from the true pose (in a random
  direction), azimuth within the tolerance, same radius: the true pose lies
  outside the window, so the only right answer is ``no_fix``. A fix here
  followed the prior.

A good-prior fix is wrong when it is more than 5 cm or 0.25° off and outside
five of its own standard deviations (as in the robustness benchmark).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from mast.bench.accuracy import ACCURACY_CONFIGS, owed_poses
from mast.bench.robustness import is_wrong
from mast.core.pose import Pose2D
from mast.pipeline.locator import LocatorConfig, locate
from mast.pipeline.tracking import Prior
from mast.sim import ScannerModel, simulate_scan

__all__ = ["TrackingSummary", "prior_pair", "run_tracking"]


@dataclass(slots=True)
class TrackingSummary:
    config: str
    scans: int = 0
    fixed: int = 0
    wrong: int = 0
    wrong_prior_scans: int = 0
    wrong_prior_fixes: int = 0
    misses: Counter[str] = field(default_factory=Counter)
    seconds: float = 0.0

    @property
    def fix_rate(self) -> float:
        return self.fixed / self.scans if self.scans else math.nan

    def line(self) -> str:
        why = ", ".join(f"{k} {v}" for k, v in self.misses.most_common()) or "-"
        return (
            f"{self.config:22s} good prior: fixed {self.fixed}/{self.scans} "
            f"({100 * self.fix_rate:5.1f} %) WRONG {self.wrong}  misses: {why};  "
            f"wrong prior: fixes {self.wrong_prior_fixes}/{self.wrong_prior_scans}  "
            f"({self.seconds:.0f} s)"
        )


def _offset(pose: Pose2D, distance_m: float, bearing: float, turn: float) -> Pose2D:
    return Pose2D(
        pose.easting + distance_m * math.cos(bearing),
        pose.northing + distance_m * math.sin(bearing),
        (pose.azimuth + turn) % (2 * math.pi),
    )


def prior_pair(
    truth: Pose2D,
    rng: np.random.Generator,
    *,
    radius_m: float = 0.5,
    tolerance_deg: float = 5.0,
    wrong_offset_m: float = 1.5,
) -> tuple[Prior, Prior]:
    """A good prior about ``truth`` and a wrong one, both ``radius_m`` and ``tolerance_deg`` wide.

    The good one is centred uniformly over the disc and the angle window about
    the truth; the wrong one ``wrong_offset_m`` away in a random direction
    (the truth outside its window), azimuth within the tolerance.
    """
    tol = math.radians(tolerance_deg)
    r = radius_m * math.sqrt(rng.uniform())
    guess = _offset(truth, r, rng.uniform(0, 2 * math.pi), rng.uniform(-tol, tol))
    away = _offset(truth, wrong_offset_m, rng.uniform(0, 2 * math.pi), rng.uniform(-tol, tol))
    return Prior(guess, radius_m, tol), Prior(away, radius_m, tol)


def run_tracking(
    *,
    configs: Sequence[ScannerModel] = ACCURACY_CONFIGS,
    poses: int = 40,
    draws: int = 3,
    radius_m: float = 0.5,
    tolerance_deg: float = 5.0,
    wrong_offset_m: float = 1.5,
    seed: int = 0,
    echo: Callable[[str], object] = print,
) -> list[TrackingSummary]:
    """Locate the accuracy benchmark's owed draws with good and with wrong priors."""
    out: list[TrackingSummary] = []
    for model in configs:
        t0 = time.perf_counter()
        s = TrackingSummary(model.name)
        cfg = LocatorConfig(
            range_sigma_m=model.range_sigma_m,
            angle_sigma_rad=model.angle_sigma_rad,
            survey_sigma_m=0.0,
        )
        prng = np.random.default_rng([seed, 5])
        for p_idx, (scene, shot) in enumerate(owed_poses(model, poses, seed)):
            rng = np.random.default_rng([seed, p_idx, 7])  # the accuracy benchmark's draws
            truth = shot.pose
            for _ in range(draws):
                sim = simulate_scan(scene.world, truth, model, rng=rng)
                good, wrong = prior_pair(
                    truth,
                    prng,
                    radius_m=radius_m,
                    tolerance_deg=tolerance_deg,
                    wrong_offset_m=wrong_offset_m,
                )
                fix = locate(sim.scan, scene.survey, config=replace(cfg, prior=good))
                s.scans += 1
                s.fixed += fix.ok
                s.wrong += is_wrong(fix, truth)
                if not fix.ok:
                    s.misses[fix.reason or "no_fix"] += 1
                bad = locate(sim.scan, scene.survey, config=replace(cfg, prior=wrong))
                s.wrong_prior_scans += 1
                s.wrong_prior_fixes += bad.ok
        s.seconds = time.perf_counter() - t0
        echo(s.line())
        out.append(s)
    return out
