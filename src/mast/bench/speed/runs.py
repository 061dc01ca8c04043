"""Whole runs in fresh processes (reading, locate, track), tracked sequences, a mine-wide
survey and start-up."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mast.bench.accuracy import ACCURACY_CONFIGS
from mast.bench.minewide import MinewideSummary, run_minewide
from mast.bench.speed.model import (
    DEFAULT_BAG_SCANS,
    DEFAULT_MINEWIDE_POSES,
    DEFAULT_STARTUP_RUNS,
    DEFAULT_SURVEY_BEACONS,
    DEFAULT_TRACK_SCANS,
    OTHER_STAGE,
    ProcessRun,
    StartupSpeed,
    Stats,
    TrackedSpeed,
)
from mast.bench.speed.peer import peer_align, peer_module, peer_target
from mast.bench.speed.scans import pose_errors
from mast.core.heap import QuietCollector
from mast.pipeline.locator import STAGES as LOCATOR_STAGES
from mast.pipeline.locator import LocatorConfig, SequenceLocator, SequenceStep, locate
from mast.sim import drive_scene, write_scenario

__all__ = ["measure_minewide", "measure_runs", "measure_startup", "measure_tracked"]

# A fresh process for a whole run: times itself from before its first mast import to
# its end and writes its figures to a side file (standard output may be /dev/null).
# Its peak memory comes from mast.bench.rss (standard library only), imported after
# the measured work.
_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
side, mode, *args = sys.argv[1:]
code, scans = 0, -1
try:
    if mode == "read":
        from mast.io.bags import read_laserscans
        scans = sum(1 for _ in read_laserscans(args[0]))
    else:
        from mast.program import main
        sys.argv = ["mast", *args]
        main()
except SystemExit as stop:
    code = 0 if stop.code is None else stop.code if isinstance(stop.code, int) else 1
seconds = time.perf_counter() - t0
from mast.bench.rss import peak_rss_mb
peak = peak_rss_mb()
with open(side, "w") as fh:
    json.dump({"s": seconds, "peak_mb": peak, "code": code, "scans": scans}, fh)
"""


def measure_tracked(count: int, *, seed: int = 0) -> TrackedSpeed:
    """Locate ``count`` scans of a 25 Hz drive in sequence, timed, each tracked fix's time
    split by the stages the locator clocks on it; the peer from each tracked fix's prior
    on the same scans."""
    from mast.cli.warmup import compile_all

    scene = drive_scene(seed, scans=count)
    sims = tuple(scene.iter_simulated())
    cfg = LocatorConfig(range_sigma_m=scene.shots[0].scanner.range_sigma_m)
    # Every kernel loaded, the window search's too, as `mast live` does before its first
    # scan (the first tracked scan took 40 ms loading them); the survey's index built.
    compile_all()
    if sims:
        locate(sims[0].scan, scene.survey, config=cfg)
    steps: list[SequenceStep] = []
    seconds: list[float] = []
    wide: list[float] = []  # the radius of the window of all the vehicle can have done
    tracker = SequenceLocator(scene.survey, config=cfg)
    with QuietCollector() as heap:  # as `mast live` and `mast locate RUN` do
        for sim in sims:
            last = tracker.last_pose
            elapsed = abs(sim.scan.stamp_ns - tracker.last_stamp_ns) / 1e9
            radius = math.inf if last is None else tracker.sequence.prior(last, elapsed).radius_m
            wide.append(radius)
            t0 = time.perf_counter()
            steps.append(tracker.step(sim.scan))
            seconds.append(time.perf_counter() - t0)
            heap.step()
    found = [st.tracked and not st.track_lost and st.fix.ok for st in steps]
    # Per stage, as the locator clocked them on each fix (Fix.stages_s); "other" is the
    # rest of the step's time (choosing between poses, the sequence's bookkeeping).
    per: dict[str, list[float]] = {stage: [] for stage in LOCATOR_STAGES}
    per[OTHER_STAGE] = []
    for st, took, kept in zip(steps, seconds, found, strict=True):
        if kept:
            for stage in LOCATOR_STAGES:
                per[stage].append(1e3 * st.fix.stages_s.get(stage, 0.0))
            per[OTHER_STAGE].append(1e3 * (took - sum(st.fix.stages_s.values())))
    pos, az, narrow = [], [], 0
    peer_ms, peer_pos, peer_az = [], [], []
    sg = peer_module()
    target = tree = None
    if sg is not None:
        target, tree, _ = peer_target(scene.survey, sg)
    for sim, st, kept, radius in zip(sims, steps, found, wide, strict=True):
        prior = st.fix.config.prior
        if not kept or st.fix.pose is None or prior is None:
            continue
        p, a = pose_errors(sim.pose, st.fix.pose)
        pos.append(p)
        az.append(a)
        narrow += prior.radius_m < radius
        if sg is not None:
            beams, points = sim.scan.points()
            source = points[sim.beacon_mask()[beams]]
            if len(source) >= 3:
                ms, got, _ = peer_align(sg, target, tree, source, prior.pose)
                peer_ms.append(ms)
                pp, pa = pose_errors(sim.pose, got)
                peer_pos.append(pp)
                peer_az.append(pa)
    times = 1e3 * np.asarray(seconds)
    tracked = np.asarray([st.tracked for st in steps], dtype=bool)
    lost = np.asarray([st.track_lost for st in steps], dtype=bool)
    return TrackedSpeed(
        scans=len(sims),
        rate_hz=scene.rate_hz,
        fixed=sum(st.fix.ok for st in steps),
        narrow=narrow,
        tracked_ms=Stats.of(times[np.asarray(found, dtype=bool)]),
        lost_ms=Stats.of(times[lost]),
        global_ms=Stats.of(times[~tracked]),
        stages_ms=tuple((stage, Stats.of(v)) for stage, v in per.items()),
        position_err_mm=Stats.of(pos),
        azimuth_err_arcsec=Stats.of(az),
        peer_ms=Stats.of(peer_ms),
        peer_position_err_mm=Stats.of(peer_pos),
        peer_azimuth_err_arcsec=Stats.of(peer_az),
    )


def _child_run(step: str, scans: int, mode: str, args: Sequence[str], tmp: Path) -> ProcessRun:
    side = tmp / f"child-{step.split()[0]}-{scans}.json"
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, str(side), mode, *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        check=False,
    )
    if done.returncode != 0 or not side.exists():
        raise RuntimeError(f"benchmark child {step!r} failed: {done.stderr.strip()[-2000:]}")
    got = json.loads(side.read_text())
    code = int(got["code"])
    # 3: no scan fixed (locate) or placed (track); the time is still what it took
    if code not in (0, 3):
        raise RuntimeError(f"{step} exited {code}: {done.stderr.strip()[-2000:]}")
    if mode == "read" and int(got["scans"]) != scans:
        raise RuntimeError(f"read {got['scans']} scans of a {scans}-scan bag")
    return ProcessRun(step, scans, float(got["s"]), float(got["peak_mb"]), code)


def measure_runs(
    bag_scans: Sequence[int] = DEFAULT_BAG_SCANS,
    track_scans: Sequence[int] = DEFAULT_TRACK_SCANS,
    *,
    seed: int = 0,
    folder: Path | None = None,
) -> list[ProcessRun]:
    """Simulate a drive bag of each length; read it, ``mast locate`` it (``bag_scans``)
    and ``mast track`` it (``track_scans``), each in a fresh process."""
    from mast.cli.warmup import compile_all

    compile_all()  # the children load the compiled kernels, as an installed tool does
    runs: list[ProcessRun] = []
    with tempfile.TemporaryDirectory(prefix="mast-bench-speed-") as tmp:
        root = Path(folder or tmp)
        for n in sorted(set(bag_scans) | set(track_scans)):
            (w,) = write_scenario([drive_scene(seed, scans=n)], root / f"drive-{n}", fmt="bag")
            bag, survey = str(w.scans[0]), str(w.survey)
            sigma = ["--range-sigma", "0.012"]  # the drive's scanner
            runs.append(_child_run("read", n, "read", [bag], root))
            if n in bag_scans:
                cmd = ["locate", bag, "-b", survey, *sigma, "--format", "json"]
                runs.append(_child_run("locate", n, "cli", cmd, root))
            if n in track_scans:
                out = str(root / f"track-{n}")
                cmd = ["track", bag, "-b", survey, "--out", out, *sigma]
                runs.append(_child_run("track", n, "cli", cmd, root))
    return runs


def measure_minewide(
    poses: int = DEFAULT_MINEWIDE_POSES, beacons: int = DEFAULT_SURVEY_BEACONS, *, seed: int = 0
) -> MinewideSummary:
    """The mine-wide benchmark at 1081 beams: local surveys of two or three beacons,
    against ``beacons`` (copies added to a two-beacon scene's survey make ``beacons``)."""
    model = next(m for m in ACCURACY_CONFIGS if m.name.startswith("270deg-0.25deg"))
    return run_minewide(
        poses=poses, copies=max(beacons - 2, 0), seed=seed, model=model, echo=lambda _: None
    )


def _wall(cmd: Sequence[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
    return time.perf_counter() - t0


def measure_startup(runs: int = DEFAULT_STARTUP_RUNS) -> StartupSpeed:
    """``mast --help`` (the installed command, else the CLI's entry point) and a bare
    ``python -c pass``, each ``runs`` times in fresh processes."""
    script = Path(sys.executable).with_name("mast")
    cmd = (
        [str(script), "--help"]
        if script.exists()
        else [sys.executable, "-c", "from mast.program import main; main()", "--help"]
    )
    return StartupSpeed(
        tuple(_wall(cmd) for _ in range(runs)),
        tuple(_wall([sys.executable, "-c", "pass"]) for _ in range(runs)),
    )
