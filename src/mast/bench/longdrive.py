"""Long-drive integrity benchmark: many drives' scans located in sequence, never a wrong fix.

A wrong fix in a long run is the failure a surveyor cannot see: one in ten
thousand is enough to spoil a trajectory. Each drive (:func:`mast.sim.drive.drive_scene`:
a rough-rock drift with beacons every 6-14 m and 30-60 m stretches without any,
0.5°, 12 mm) is simulated at a SICK-like 50 Hz and a Hokuyo-like 40 Hz, each
scan's ranges sent through its protocol's real codec as the scanner sends them
(CoLa-A ``LMDscandata``: millimetres; SCIP 2.0 ``MD``: millimetres, 18-bit codes)
and read back as :mod:`mast.live.sources` reads them, then located in sequence
by :class:`mast.pipeline.locator.SequenceLocator` with ``--scanner lms1xx-0.5``'s
precisions: the one tracking rule of ``mast locate RUN`` and ``mast live``.

Printed per drive and in all: scans, owed scans and how many were fixed, fixes
tracked and from scratch, wrong fixes (more than 5 cm or 0.25° off *and* outside
five of their own standard deviations, :func:`mast.bench.robustness.is_wrong`),
each listed, and the share of fixes whose position lies outside its own 99 %
error ellipse (expected 1 %).

Also printed: the median and 95th percentile of the time ``SequenceLocator.step`` took a
scan (the drives run side by side, one a worker). With ``--out DIR``, every scan's
outcome is written to ``DIR/longdrive_<protocol>_<seed>.csv`` (scan, owed, status or
reason, tracked, track lost, position and azimuth error of a fix, milliseconds), for
comparing two versions scan by scan.

Run: ``mast bench longdrive [--scans 10000] [--seeds 5] [--out DIR]`` (2 x seeds x scans
scans).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mast.bench.rows import write_rows
from mast.core.scan import Scan

__all__ = ["LONG_SCANNERS", "DriveFigures", "as_sent", "run_longdrive"]

#: (protocol, scan rate Hz) of each scanner the drives are located as.
LONG_SCANNERS = (("sick", 50.0), ("hokuyo", 40.0))
#: The named scanner model whose precisions the locator is given (the drive's 12 mm).
SCANNER = "lms1xx-0.5"
#: chi-square(2) at 0.99: a fix's position outside its own 99 % ellipse beyond this.
ELLIPSE_99 = -2.0 * math.log(0.01)


def as_sent(kind: str, scan: Scan, counter: int = 0) -> Scan:
    """``scan`` as a ``kind`` scanner sends it and :mod:`mast.live.sources` reads it back:
    encoded to its telegram with the protocol's own codec and decoded again (ranges in
    whole millimetres, the protocol's no-return codes); the stamp is kept."""
    from mast.live.protocols import protocol

    device = protocol(kind).emulation(scan)
    sent = device.encode(scan, ticks=counter, counter=counter, hz=50.0)
    return device.read_back(sent, scan.stamp_ns)


@dataclass(slots=True)
class DriveFigures:
    kind: str
    rate_hz: float
    seed: int
    scans: int = 0
    owed: int = 0
    owed_fixed: int = 0
    fixes: int = 0
    tracked_fixes: int = 0
    outside_99: int = 0
    wrong: list[str] = field(default_factory=list)
    seconds: float = 0.0
    rows: list[dict[str, object]] = field(default_factory=list)
    """Per scan: index, owed, status ("fix" or the reason), tracked, track lost, position
    error mm and azimuth error arc-seconds of a fix (empty otherwise), milliseconds."""

    def line(self) -> str:
        share = 100 * self.owed_fixed / max(self.owed, 1)
        out = 100 * self.outside_99 / max(self.fixes, 1)
        ms = [float(str(r["elapsed_ms"])) for r in self.rows] or [0.0]
        return (
            f"{self.kind:>6} {self.rate_hz:g} Hz seed {self.seed}: {self.scans} scans, owed "
            f"{self.owed}, fixed {self.owed_fixed} ({share:.2f} %); fixes {self.fixes} "
            f"({self.tracked_fixes} tracked); outside their 99 % ellipse {self.outside_99} "
            f"({out:.2f} %); WRONG {len(self.wrong)}; ms a scan median "
            f"{np.median(ms):.2f} p95 {np.percentile(ms, 95):.2f}  ({self.seconds:.0f} s)"
        )

    def write_rows(self, folder: Path) -> Path:
        """The per-scan outcomes as ``folder/longdrive_<protocol>_<seed>.csv``."""
        path = folder / f"longdrive_{self.kind}_{self.seed}.csv"
        write_rows(path, self.rows)
        return path


def _drive(job: tuple[str, float, int, int]) -> DriveFigures:
    """Simulate one drive, send it through its protocol and locate it in sequence."""
    from mast.bench.robustness import is_wrong
    from mast.core.heap import QuietCollector
    from mast.pipeline.locator import LocatorConfig, SequenceLocator
    from mast.sim import scanner_model
    from mast.sim.drive import drive_scene

    kind, rate_hz, seed, scans = job
    t0 = time.perf_counter()
    scene = drive_scene(seed, scans=scans, rate_hz=rate_hz)
    noise = scanner_model(SCANNER).noise()
    config = LocatorConfig(range_sigma_m=noise.range_sigma_m, angle_sigma_rad=noise.angle_sigma_rad)
    tracker = SequenceLocator(scene.survey, config=config)
    fig = DriveFigures(kind, rate_hz, seed)
    # As mast live does (mast.core.heap): what is alive after the first scan frozen.
    with QuietCollector() as heap:
        for i, sim in enumerate(heap.each(scene.iter_simulated())):
            sent = as_sent(kind, sim.scan, i)
            t_step = time.perf_counter()
            step = tracker.step(sent)
            ms = round(1e3 * (time.perf_counter() - t_step), 3)
            fix, truth = step.fix, sim.pose
            fig.scans += 1
            owed = sim.owes_fix()
            fig.owed += owed
            row: dict[str, object] = {
                "scan": i,
                "owed": int(owed),
                "status": fix.reason or fix.status,
                "tracked": int(step.tracked),
                "track_lost": int(step.track_lost),
                "error_mm": "",
                "error_az_arcsec": "",
                "elapsed_ms": ms,
            }
            fig.rows.append(row)
            if not fix.ok or fix.pose is None or fix.adjustment is None:
                continue
            row["status"] = "fix"
            off = math.hypot(fix.pose.easting - truth.easting, fix.pose.northing - truth.northing)
            turn = math.remainder(fix.pose.azimuth - truth.azimuth, math.tau)
            row["error_mm"] = f"{1e3 * off:.3f}"
            row["error_az_arcsec"] = f"{3600 * math.degrees(turn):.2f}"
            fig.owed_fixed += owed
            fig.fixes += 1
            fig.tracked_fixes += step.tracked
            d = np.array([fix.pose.easting - truth.easting, fix.pose.northing - truth.northing])
            cov = fix.adjustment.covariance[:2, :2]
            fig.outside_99 += float(d @ np.linalg.solve(cov, d)) > ELLIPSE_99
            if is_wrong(fix, truth):
                dist = math.hypot(*d)
                daz = math.degrees(math.remainder(fix.pose.azimuth - truth.azimuth, 2 * math.pi))
                fig.wrong.append(
                    f"scan {i}: {dist:.3f} m and {daz:+.3f} deg off, sigmas "
                    f"{1e3 * fix.adjustment.sigma[0]:.1f} / "
                    f"{1e3 * fix.adjustment.sigma[1]:.1f} mm, "
                    f"beacons {', '.join(fix.beacons)}, {'tracked' if step.tracked else 'global'}"
                )
    fig.seconds = time.perf_counter() - t0
    return fig


def _jobs(scans: int, seeds: int) -> Iterator[tuple[str, float, int, int]]:
    for seed in range(seeds):
        for kind, rate in LONG_SCANNERS:
            yield kind, rate, seed, scans


def run_longdrive(
    *,
    scans: int = 10_000,
    seeds: int = 5,
    workers: int = 2,
    out_dir: Path | None = None,
    echo: Callable[[str], None] = print,
) -> list[DriveFigures]:
    """Run the benchmark (see the module), one drive a worker process, and print its figures
    (and, with ``out_dir``, write every scan's outcome there)."""
    out: list[DriveFigures] = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for fig in pool.map(_drive, _jobs(scans, seeds)):
            echo(fig.line())
            if out_dir is not None:
                fig.write_rows(out_dir)
            for w in fig.wrong:
                echo(f"    WRONG {w}")
            out.append(fig)
    total = sum(f.scans for f in out)
    owed = sum(f.owed for f in out)
    fixed = sum(f.owed_fixed for f in out)
    fixes = sum(f.fixes for f in out)
    outside = sum(f.outside_99 for f in out)
    wrong = sum(len(f.wrong) for f in out)
    echo(
        f"all: {total} scans, owed {owed}, fixed {fixed} ({100 * fixed / max(owed, 1):.2f} %); "
        f"fixes {fixes}, outside their 99 % ellipse {outside} "
        f"({100 * outside / max(fixes, 1):.2f} %); WRONG {wrong}"
    )
    return out
