"""Real-log run benchmark: ``mast track``'s tracker and smoother on real laser logs.

Beacons are mounted on the real walls of the CARMEN logs with corrected poses
and ray-cast into every scan (as in :mod:`mast.bench.clutter`); the whole
log is then tracked in sequence exactly as ``mast track`` does
(:class:`~mast.runs.track.RunTracker`, then :class:`~mast.runs.track.Smoother`),
with the scans' own time stamps. These logs keep a scan only every metre or
so (1.6-2.6 s apart, up to 33 degrees of turn), so they are tracked with
``max_gap_s`` above that spacing; at the default 0.5 s nothing is chained and
only fixes are placed.

Printed per log: scans, fixes, scans placed, and for the scans placed by
odometry alone (between fixes) their position error against the corrected
pose (median, p95, max) and the share whose 95 % ellipse (position) and
95 % interval (azimuth) hold it. The corrected poses are themselves good to
"a few centimetres" (the logs' own description), which is also about the
size of one step's error here: coverage below a few centimetres is the
truth's as much as the tracker's.

Run: ``mast bench reallog``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mast.bench.clutter import (
    CARMEN_LOGS,
    PANEL_NOISE_M,
    carmen_logs,
    cast_beacons,
    mount_beacons,
    scanner_model,
)
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.core.trajectory import PlacedScan
from mast.pipeline.locator import LocatorConfig
from mast.runs.track import Node, RunTracker, Smoother, TrackConfig

__all__ = ["RealRunFigures", "run_real_log", "run_real_logs"]

#: Chi-square 95 % quantiles: two degrees of freedom (an ellipse), one (an interval).
CHI2_95_2 = 5.991
CHI2_95_1 = 3.841


@dataclass(slots=True)
class RealRunFigures:
    """What tracking one real log gave."""

    name: str
    scans: int = 0
    fixes: int = 0
    placed: int = 0
    errors_m: list[float] = field(default_factory=list)
    inside_95: list[bool] = field(default_factory=list)
    azimuth_inside_95: list[bool] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def odometry(self) -> int:
        return len(self.errors_m)

    def line(self) -> str:
        e = np.asarray(self.errors_m)
        odo = (
            f"odometry-placed {self.odometry}: error median {np.median(e):.3f} "
            f"p95 {np.percentile(e, 95):.3f} max {e.max():.3f} m, "
            f"95 % coverage position {np.mean(self.inside_95):.3f} "
            f"azimuth {np.mean(self.azimuth_inside_95):.3f}"
            if e.size
            else "odometry-placed 0"
        )
        return (
            f"{self.name:>13}: {self.scans} scans, {self.fixes} fixed, {self.placed} placed; "
            f"{odo} ({self.seconds:.0f} s)"
        )


def judge(figures: RealRunFigures, placed: Iterable[PlacedScan], truth: list[Pose2D]) -> None:
    """Add the placed scans' errors against the truth to ``figures``."""
    for p in placed:
        figures.placed += 1
        if p.source != "odometry":
            continue
        t = truth[p.scan]
        d = np.array([p.pose.easting - t.easting, p.pose.northing - t.northing])
        figures.errors_m.append(math.hypot(*d))
        figures.inside_95.append(float(d @ np.linalg.solve(p.covariance[:2, :2], d)) <= CHI2_95_2)
        da = math.remainder(p.pose.azimuth - t.azimuth, math.tau)
        figures.azimuth_inside_95.append(da**2 <= CHI2_95_1 * p.covariance[2, 2])


def run_real_log(
    name: str,
    data: Sequence[tuple[Scan, Pose2D]],
    *,
    beacons: int = 29,
    seed: int = 0,
    max_gap_s: float = 3.0,
    echo: Callable[[str], object] = print,
) -> RealRunFigures:
    """Mount beacons on one log's walls, cast them into its scans and track it."""
    t0 = time.perf_counter()
    figures = RealRunFigures(name)
    pairs = list(data)
    if not pairs:
        return figures
    rng = np.random.default_rng(seed)
    survey, _, _, _ = mount_beacons(pairs, beacons, rng)
    model = scanner_model(pairs[0][0], name)
    config = TrackConfig(locator=LocatorConfig(range_sigma_m=0.01), max_gap_s=max_gap_s)
    tracker, smoother = RunTracker(survey, config), Smoother(config)
    truth = [p for _, p in pairs]
    for i, (scan, pose) in enumerate(pairs):
        sim = cast_beacons(scan, pose, survey, rng, noise_m=PANEL_NOISE_M, scanner=model)
        step = tracker.step(i, sim.scan)
        figures.scans += 1
        figures.fixes += step.fix.ok
        judge(figures, smoother.push(Node.of(step)), truth)
    judge(figures, smoother.finish(), truth)
    figures.seconds = time.perf_counter() - t0
    echo(figures.line())
    return figures


def run_real_logs(
    data_dir: Path,
    *,
    beacons: int = 29,
    seed: int = 0,
    max_gap_s: float = 3.0,
    logs: Iterable[str] = tuple(CARMEN_LOGS),
    echo: Callable[[str], object] = print,
) -> list[RealRunFigures]:
    """:func:`run_real_log` on each CARMEN log under ``data_dir``
    (:func:`~mast.bench.clutter.carmen_logs` gives each its seed)."""
    return [
        run_real_log(name, data, beacons=beacons, seed=s, max_gap_s=max_gap_s, echo=echo)
        for name, data, s in carmen_logs(data_dir, logs, seed)
    ]
