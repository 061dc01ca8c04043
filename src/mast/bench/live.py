"""Live benchmark: a simulated drive served by the scanner emulators, located by ``mast live``.

For each scanner (SICK LMS1xx at 50 Hz, CoLa-A; Hokuyo at 40 Hz, SCIP 2.0) a drive
of ``scans`` scans with beacon gaps (:func:`mast.sim.drive.drive_scene`, 0.5°,
541 beams) is simulated into an MCAP bag, with which scans owe a fix (two
beacons, each showing two panels). ``mast emulate`` serves the bag on loopback
in its own process at the drive's rate; this process runs the live session
(with the precisions of ``--scanner lms1xx-0.5``, the drive's 12 mm)
(:func:`mast.live.session.run_live`, the code behind ``mast live``) on it and
prints: scans received, located and dropped; latency from receipt to pose,
median / p95 / max; resident memory over the first and the last thousand
scans; the share of one core used (both threads); owed scans fixed (all of
them, and those located while tracking); fixes farther than 0.1 m from the truth;
and the scans from a wrong prior injected half-way (3 m and 20° off) to the
first fix, against the first scan after it that owes one.

Run: ``mast bench live [--scans 30000]``.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["LIVE_SCANNERS", "LiveFigures", "run_live_bench", "simulate_drive"]

#: (kind, scan rate Hz) of each emulated scanner.
LIVE_SCANNERS = (("sick", 50.0), ("hokuyo", 40.0))
#: The named scanner model whose precisions the drive's scanner has (270°, 0.5°, 12 mm).
SCANNER = "lms1xx-0.5"
#: The injected wrong prior: this far off, this much turned.
WRONG_PRIOR_M, WRONG_PRIOR_DEG = 3.0, 20.0


@dataclass(frozen=True, slots=True)
class LiveFigures:
    kind: str
    rate_hz: float
    scans: int
    received: int
    located: int
    dropped: int
    late: int
    latency_ms: tuple[float, float, float]
    locate_ms: tuple[float, float, float]
    rss_mb: tuple[float, float]
    cpu_share: float
    owed: int
    owed_located: int
    owed_fixed: int
    owed_tracking: int
    owed_tracking_fixed: int
    wrong: int
    recovery: str

    def lines(self) -> list[str]:
        lat = self.latency_ms
        share = 100 * self.owed_fixed / max(self.owed_located, 1)
        tshare = 100 * self.owed_tracking_fixed / max(self.owed_tracking, 1)
        return [
            f"{self.kind} at {self.rate_hz:g} Hz: {self.received} of {self.scans} scans received, "
            f"{self.located} located, {self.dropped} dropped; {self.late} located later than "
            f"one scan period",
            f"  latency receipt -> pose, ms: median {lat[0]:.2f}  p95 {lat[1]:.2f}  "
            f"max {lat[2]:.1f}",
            f"  of which locating the scan and making its record, ms: median "
            f"{self.locate_ms[0]:.2f}  p95 {self.locate_ms[1]:.2f}  max {self.locate_ms[2]:.1f}",
            f"  resident memory, MB: first 1000 scans {self.rss_mb[0]:.1f}, last 1000 "
            f"{self.rss_mb[1]:.1f}; CPU {100 * self.cpu_share:.0f} % of one core",
            f"  owed scans: {self.owed}, located {self.owed_located}, fixed {self.owed_fixed} "
            f"({share:.2f} %); while tracking {self.owed_tracking_fixed} of "
            f"{self.owed_tracking} ({tshare:.2f} %); fixes > 0.1 m from the truth: {self.wrong}",
            f"  wrong prior injected: {self.recovery}",
        ]


def _spread(values: Any) -> tuple[float, float, float]:
    return float(np.median(values)), float(np.percentile(values, 95)), float(np.max(values))


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def simulate_drive(folder: Path, scans: int, rate_hz: float, seed: int) -> tuple[Path, Path, Any]:
    """The drive's survey and bag, and per scan in order: true position, owed."""
    from mast.io import write_survey
    from mast.io.bags import write_laserscans
    from mast.sim.drive import drive_scene

    scene = drive_scene(seed, scans=scans, rate_hz=rate_hz)
    survey = folder / "beacons.csv"
    write_survey(survey, scene.survey)
    truth: list[tuple[float, float, bool]] = []

    def sims() -> Iterator[Any]:
        for shot, sim in zip(scene.shots, scene.iter_simulated(), strict=True):
            truth.append((shot.pose.easting, shot.pose.northing, sim.owes_fix()))
            yield sim.scan

    bag = folder / "drive.mcap.d"
    write_laserscans(bag, sims(), kind="mcap")
    return survey, bag, truth


def _one(
    kind: str, rate_hz: float, scans: int, seed: int, folder: Path, echo: Callable[[str], None]
) -> LiveFigures:
    from mast.core.pose import Pose2D
    from mast.io import read_survey
    from mast.live.session import run_live
    from mast.live.sources import open_source
    from mast.pipeline.locator import LocatorConfig, SequenceLocator
    from mast.sim import scanner_model

    t0 = time.perf_counter()
    survey_csv, bag, truth = simulate_drive(folder, scans, rate_hz, seed)
    echo(f"{kind}: {scans} scans at {rate_hz:g} Hz simulated in {time.perf_counter() - t0:.0f} s")
    emulator = subprocess.Popen(
        [sys.executable, "-m", "mast", "emulate", kind, "--from", str(bag), "--port", "0"],
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert emulator.stderr is not None
        line = emulator.stderr.readline()
        port = int(line.rsplit(":", 1)[1])
        survey = read_survey(survey_csv)
        records: list[tuple[int, float, bool, bool, float, float, int]] = []
        rss: list[float] = []
        inject_at = scans // 2
        injected: list[int] = []
        locate_s: list[float] = []  # from before_step to emit: the step and its record
        started = [0.0]

        def emit(rec: dict[str, Any]) -> None:
            locate_s.append(time.perf_counter() - started[0])  # the step and its record
            ok = rec["status"] == "fix"
            records.append(
                (
                    rec["stamp_ns"],
                    rec["latency_ms"],
                    ok,
                    rec["tracking"],
                    rec["easting"] if ok else math.nan,
                    rec["northing"] if ok else math.nan,
                    rec["scan"],
                )
            )
            rss.append(_rss_mb())

        def before(index: int, tracker: SequenceLocator) -> None:
            started[0] = time.perf_counter()
            if injected or index < inject_at or tracker.last_pose is None:
                return
            p = tracker.last_pose
            wrong = Pose2D(
                p.easting + WRONG_PRIOR_M,
                p.northing,
                p.azimuth + math.radians(WRONG_PRIOR_DEG),
            )
            tracker.assume(wrong, tracker.last_stamp_ns)
            injected.append(index)

        source = open_source(f"{kind}://127.0.0.1:{port}")
        noise = scanner_model(SCANNER).noise()  # as `mast live --scanner lms1xx-0.5`
        config = LocatorConfig(
            range_sigma_m=noise.range_sigma_m, angle_sigma_rad=noise.angle_sigma_rad
        )
        cpu0, wall0 = time.process_time(), time.perf_counter()
        summary = run_live(
            source,
            survey,
            emit=emit,
            config=config,
            max_scans=scans,
            before_step=before,
        )
        cpu = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
    finally:
        emulator.terminate()
        emulator.wait(10)
    lat = np.array([r[1] for r in records])
    period_ms = 1e3 / rate_hz
    # The stream's k-th scan is the bag's k-th (the emulator sends them in order).
    owed = sum(1 for v in truth if v[2])
    owed_rows = [r for r in records if truth[r[6]][2]]
    wrong = 0
    for r in records:
        if r[2]:
            e, n, _ = truth[r[6]]
            wrong += math.hypot(r[4] - e, r[5] - n) > 0.1
    recovery = "not injected (no fix before half-way)"
    if injected:
        after = [r for r in records if r[6] >= injected[0]]
        first_owed = next((r for r in after if truth[r[6]][2]), None)
        first_fix = next((r for r in after if r[2]), None)
        if first_owed is None:
            recovery = "no owed scan after it"
        else:
            k_owed = first_owed[6] - injected[0]
            k_fix = math.inf if first_fix is None else first_fix[6] - injected[0]
            recovery = (
                f"at scan {injected[0]}; first scan owing a fix {k_owed} scans later, first "
                f"fix {k_fix} scans later" + (" (the same scan)" if k_fix == k_owed else "")
            )
    n1 = min(1000, len(rss))
    return LiveFigures(
        kind=kind,
        rate_hz=rate_hz,
        scans=scans,
        received=summary.received,
        located=summary.located,
        dropped=summary.dropped,
        late=int(np.sum(lat > period_ms)),
        latency_ms=_spread(lat),
        locate_ms=_spread(1e3 * np.array(locate_s)),
        rss_mb=(float(np.median(rss[:n1])), float(np.median(rss[-n1:]))),
        cpu_share=cpu,
        owed=owed,
        owed_located=len(owed_rows),
        owed_fixed=sum(r[2] for r in owed_rows),
        owed_tracking=sum(r[3] for r in owed_rows),
        owed_tracking_fixed=sum(r[2] and r[3] for r in owed_rows),
        wrong=wrong,
        recovery=recovery,
    )


def run_live_bench(
    *,
    scans: int = 30_000,
    seed: int = 0,
    kinds: tuple[str, ...] = ("sick", "hokuyo"),
    echo: Callable[[str], None] = print,
) -> list[LiveFigures]:
    """Run the benchmark (see the module) and print its figures."""
    from mast.cli.warmup import compile_all

    compile_all()
    out = []
    for kind, rate in LIVE_SCANNERS:
        if kind not in kinds:
            continue
        with tempfile.TemporaryDirectory(prefix="mast-bench-live-") as tmp:
            figures = _one(kind, rate, scans, seed, Path(tmp), echo)
        for line in figures.lines():
            echo(line)
        out.append(figures)
    return out
