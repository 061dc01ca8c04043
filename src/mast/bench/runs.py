"""Survey-run benchmark: a simulated drive through ``mast track``, against its truth.

For each drive length a bag is simulated (``drive_scene``: 25 Hz, beacons every
6-14 m with 30-60 m stretches without any), then, each in a fresh process so
that peaks do not mix: the bag is only read and deserialised (the floor any
tool pays), and tracked by ``mast track`` into a folder. Printed per length:
throughput of both, peak memory, the share of scans fixed and placed, and the
errors of the placed scans against the truth, for fixed scans and for scans
carried by odometry, with the share of 95 % intervals (per axis) that hold
the truth.

Run: ``mast bench run`` (or ``python -m mast.bench.runs``).
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mast.bench.rss import peak_rss_mb

__all__ = ["DEFAULT_SCANS", "RunFigures", "run_runs"]

#: Drive lengths, scans at 25 Hz: memory must be the same for both.
DEFAULT_SCANS = (1_000, 10_000)


@dataclass(frozen=True, slots=True)
class RunFigures:
    scans: int
    read_scans_per_s: float
    read_peak_mb: float
    track_scans_per_s: float
    track_peak_mb: float
    fixed: float
    placed: float
    fix_median_mm: float
    fix_max_mm: float
    odo_median_mm: float
    odo_p95_mm: float
    odo_max_mm: float
    fix_coverage: float
    odo_coverage: float

    def line(self) -> str:
        return (
            f"{self.scans:>6} scans  read {self.read_scans_per_s:7.0f} scans/s "
            f"({self.read_peak_mb:4.0f} MB)  track {self.track_scans_per_s:5.1f} scans/s "
            f"({self.track_peak_mb:4.0f} MB)  fixed {100 * self.fixed:5.1f} %  placed "
            f"{100 * self.placed:5.1f} %  fix err median {self.fix_median_mm:.1f} max "
            f"{self.fix_max_mm:.1f} mm  odometry err median {self.odo_median_mm:.1f} p95 "
            f"{self.odo_p95_mm:.1f} max {self.odo_max_mm:.1f} mm  95 % coverage fix "
            f"{self.fix_coverage:.3f} odometry {self.odo_coverage:.3f}"
        )


def _child(mode: str, args: list[str]) -> None:
    t0 = time.perf_counter()
    if mode == "read":
        from mast.io import read_laserscans

        n = sum(1 for _ in read_laserscans(args[0]))
    else:
        from mast.io import read_survey
        from mast.pipeline import LocatorConfig
        from mast.runs.run import track_run
        from mast.runs.track import TrackConfig

        out = Path(args[2])
        out.mkdir(parents=True, exist_ok=True)
        result = track_run(
            Path(args[0]),
            read_survey(args[1]),
            out,
            config=TrackConfig(locator=LocatorConfig(range_sigma_m=0.012)),
            warn=lambda _: None,
        )
        n = result.summary.scans
    print(json.dumps({"scans": n, "s": time.perf_counter() - t0, "peak_mb": peak_rss_mb()}))


def _measure(*args: str) -> dict[str, float]:
    done = subprocess.run(
        [sys.executable, "-m", "mast.bench.runs", "--child", *args],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise RuntimeError(f"benchmark child failed: {done.stderr.strip()[-2000:]}")
    got: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return got


def _errors(truth_csv: Path, trajectory_csv: Path) -> dict[str, list[float]]:
    with truth_csv.open(encoding="utf-8", newline="") as fh:
        truth = {r["stamp_ns"]: r for r in csv.DictReader(fh)}
    out: dict[str, list[float]] = {"fix": [], "odometry": [], "fix_z": [], "odometry_z": []}
    with trajectory_csv.open(encoding="utf-8", newline="") as fh:
        for r in csv.DictReader(fh):
            t = truth[r["stamp_ns"]]
            de = float(r["easting"]) - float(t["easting"])
            dn = float(r["northing"]) - float(t["northing"])
            out[r["source"]].append(1e3 * math.hypot(de, dn))
            out[r["source"] + "_z"] += [
                de / float(r["sigma_easting_m"]),
                dn / float(r["sigma_northing_m"]),
            ]
    return out


def run_runs(
    scans: Sequence[int] = DEFAULT_SCANS,
    *,
    seed: int = 0,
    folder: Path | None = None,
    echo: Callable[[str], object] = print,
) -> list[RunFigures]:
    """Simulate, read and track a drive of each length; print and return the figures."""
    from mast.cli.warmup import compile_all
    from mast.sim import drive_scene, write_scenario

    compile_all()  # the children load the compiled kernels, as an installed tool does

    figures = []
    with tempfile.TemporaryDirectory(prefix="mast-bench-run-") as tmp:
        root = folder or Path(tmp)
        echo(
            f"survey runs: simulated drive, seed {seed}, 25 Hz, 270 deg at 0.25 deg, 12 mm noise; "
            "read and track each in a fresh process"
        )
        for n in scans:
            (w,) = write_scenario([drive_scene(seed, scans=n)], root / f"drive-{n}", fmt="bag")
            bag = w.scans[0]
            read = _measure("read", str(bag))
            out = root / f"run-{n}"
            track = _measure("track", str(bag), str(w.survey), str(out))
            err = _errors(w.truth, out / "trajectory.csv")
            fixes = sum(
                json.loads(line)["status"] == "fix"
                for line in (out / "fixes.jsonl").read_text().splitlines()
            )
            odo = np.array(err["odometry"]) if err["odometry"] else np.array([math.nan])
            fx = np.array(err["fix"]) if err["fix"] else np.array([math.nan])

            def cover(z: list[float]) -> float:
                return float(np.mean(np.abs(z) <= 1.96)) if z else math.nan

            f = RunFigures(
                scans=n,
                read_scans_per_s=n / read["s"],
                read_peak_mb=read["peak_mb"],
                track_scans_per_s=n / track["s"],
                track_peak_mb=track["peak_mb"],
                fixed=fixes / n,
                placed=(len(err["fix"]) + len(err["odometry"])) / n,
                fix_median_mm=float(np.median(fx)),
                fix_max_mm=float(np.max(fx)),
                odo_median_mm=float(np.median(odo)),
                odo_p95_mm=float(np.percentile(odo, 95)),
                odo_max_mm=float(np.max(odo)),
                fix_coverage=cover(err["fix_z"]),
                odo_coverage=cover(err["odometry_z"]),
            )
            echo(f.line())
            figures.append(f)
    return figures


if __name__ == "__main__":  # pragma: no cover - benchmark entry point
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[3:])
    else:
        run_runs(tuple(int(a) for a in sys.argv[1:]) or DEFAULT_SCANS)
