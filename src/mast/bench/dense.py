"""Dense-scan benchmark: read time, locate time and peak memory against a scan's beams.

For each beam count, one scan of the paper's parallel-wall layout (Table 2),
taken from its middle position (P4) over 270 degrees with that many beams,
is written as a scan CSV next to the survey; a fresh Python process then
reads it and locates it, as ``mast locate`` does, and reports the seconds
each took and its own peak resident memory (``VmHWM`` on Linux, else
``ru_maxrss``): one process per scan, so that the peaks of different scans
do not mix. Memory should stay within twice a normal scan's (1081 beams) at
100 000 beams and time grow about linearly with the beams.

Noise-free by default, so that every stage runs (the scan is fixed); with
``range_sigma_m`` the scan carries Gaussian range noise.

Run: ``python -m mast.bench.dense`` (or ``run_dense`` from Python).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mast.bench.rss import peak_rss_mb

__all__ = [
    "DEFAULT_BEAMS",
    "DenseFigures",
    "measure",
    "run_dense",
    "write_dense_scan",
]

#: Beam counts of the benchmark: a normal 270 degree scan at 0.25 degrees, then denser.
DEFAULT_BEAMS = (1081, 10_000, 100_000, 1_000_000)
#: The shot of the paper's parallel scene the scans are taken from (P4, between the beacons).
PAPER_SHOT = 1


@dataclass(frozen=True, slots=True)
class DenseFigures:
    """What one scan cost: its file, reading it, locating it, the process's peak memory."""

    beams: int
    file_mb: float
    read_s: float
    locate_s: float
    peak_rss_mb: float
    status: str
    """``fix``, or the no-fix reason."""

    def line(self, normal: DenseFigures | None = None) -> str:
        ratio = ""
        if normal is not None and normal.peak_rss_mb > 0:
            ratio = f" ({self.peak_rss_mb / normal.peak_rss_mb:.2f} x {normal.beams} beams)"
        per = 1e6 * (self.read_s + self.locate_s) / max(self.beams, 1)
        return (
            f"{self.beams:>9,d} beams  file {self.file_mb:6.1f} MB  read {self.read_s:6.2f} s  "
            f"locate {self.locate_s:6.2f} s  ({per:5.1f} us/beam)  "
            f"peak RSS {self.peak_rss_mb:6.0f} MB{ratio}  {self.status}"
        )


def write_dense_scan(
    folder: Path, beams: int, *, range_sigma_m: float = 0.0, seed: int = 0
) -> tuple[Path, Path]:
    """Write a ``beams``-beam scan of the paper's parallel scene and its survey into ``folder``.

    Returns the scan CSV and the survey CSV.
    """
    from mast.io import write_scan_csv, write_survey
    from mast.sim import ScannerModel, simulate_scan
    from mast.sim.scenarios import paper_scene

    if beams < 2:
        raise ValueError("a dense scan needs two beams or more")
    scene = paper_scene("parallel")
    shot = scene.shots[PAPER_SHOT]
    model = ScannerModel(
        f"dense-270-{beams}",
        270.0,
        270.0 / (beams - 1),
        range_max_m=30.0,
        range_sigma_m=range_sigma_m,
    )
    sim = simulate_scan(scene.world, shot.pose, model, rng=np.random.default_rng(seed))
    folder.mkdir(parents=True, exist_ok=True)
    survey = folder / "beacons.csv"
    write_survey(survey, scene.survey)
    scan = folder / f"scan_{beams}.csv"
    write_scan_csv(scan, sim.scan)
    return scan, survey


def measure(scan_csv: Path, survey_csv: Path, *, timeout_s: float | None = None) -> DenseFigures:
    """Read and locate ``scan_csv`` in a fresh Python process; its times and peak memory."""
    done = subprocess.run(
        [sys.executable, "-m", "mast.bench.dense", "--child", str(scan_csv), str(survey_csv)],
        capture_output=True,
        text=True,
        check=False,
        timeout=timeout_s,
    )
    if done.returncode != 0:
        raise RuntimeError(f"measuring {scan_csv} failed: {done.stderr.strip()[-2000:]}")
    got = json.loads(done.stdout.strip().splitlines()[-1])
    return DenseFigures(
        beams=int(got["beams"]),
        file_mb=scan_csv.stat().st_size / 1e6,
        read_s=float(got["read_s"]),
        locate_s=float(got["locate_s"]),
        peak_rss_mb=float(got["peak_rss_mb"]),
        status=str(got["status"]),
    )


def run_dense(
    beams: Sequence[int] = DEFAULT_BEAMS,
    *,
    range_sigma_m: float = 0.0,
    folder: Path | None = None,
    echo: Callable[[str], object] = print,
) -> list[DenseFigures]:
    """Measure reading and locating a scan of each beam count; one line per count.

    Parameters
    ----------
    beams : sequence of int
        Beam counts, the first taken as the normal scan the others' memory is
        compared with.
    range_sigma_m : float
        Range noise of the scans (0: noise-free, every scan fixed).
    folder : Path, optional
        Where to write the scans (kept); a temporary folder when not given.
    echo : callable
        Receives each line as it is measured.
    """
    with tempfile.TemporaryDirectory(prefix="mast-dense-") as tmp:
        where = Path(tmp) if folder is None else folder
        echo(
            f"dense scans: paper parallel scene, shot {PAPER_SHOT}, 270 deg, "
            f"range sigma {1000 * range_sigma_m:g} mm; each read and located in a fresh process"
        )
        out: list[DenseFigures] = []
        for n in beams:
            scan, survey = write_dense_scan(where, n, range_sigma_m=range_sigma_m)
            figures = measure(scan, survey)
            out.append(figures)
            echo(figures.line(out[0] if len(out) > 1 else None))
            if folder is None:
                scan.unlink()
    return out


def _child(scan_csv: str, survey_csv: str) -> None:
    """Read and locate one scan as ``mast locate`` does; print the figures as JSON."""
    from mast.io import read_scan_csv, read_survey
    from mast.pipeline.locator import locate

    survey = read_survey(survey_csv)
    t0 = time.perf_counter()
    scan = read_scan_csv(scan_csv)
    t1 = time.perf_counter()
    fix = locate(scan, survey)
    t2 = time.perf_counter()
    status = "fix" if fix.ok else str(fix.reason)
    figures = {
        "beams": len(scan),
        "read_s": t1 - t0,
        "locate_s": t2 - t1,
        "peak_rss_mb": peak_rss_mb(),
        "status": status,
    }
    print(json.dumps(figures))


def main(argv: Sequence[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["--child"] and len(args) == 3:
        _child(args[1], args[2])
        return
    counts = [int(a) for a in args] or list(DEFAULT_BEAMS)
    run_dense(counts)


if __name__ == "__main__":
    main()
