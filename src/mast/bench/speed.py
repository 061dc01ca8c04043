"""Speed benchmark (issue 11): a fix per scan, whole runs, a mine-wide survey, start-up,
and a general-purpose registration library beside MAST on the same scans.

Six measurements, printed as tables (figures, not timed assertions):

1. ``locate`` per scan, one core, on scans held in memory (no file parsing): a
   simulated drive (:func:`mast.sim.drive_scene`, 270 deg at 0.25 deg, 1081 beams,
   12 mm noise), keeping the scans that give a fix or show two beacons (five
   returns or more each); the same drive seen by the simulator's 360 deg scanner
   at 0.2 deg (1800 beams). Median, 95th percentile and maximum, with the pose
   errors against the truth. Then per stage: the stage functions the locator
   calls (segmentation, identification, hypotheses, verification with its ICP,
   adjustment with the integrity tests) are wrapped with a clock for a second
   pass; what no stage function covers (the survey index lookup, the choice
   between verified poses, the global test, the record) is ``other``. Last, the
   functions with the most own time under ``cProfile``.
2. Whole runs: simulated drive bags through reading only (``read_laserscans``),
   ``mast locate BAG --format json`` (standard output to ``/dev/null``) and
   ``mast track BAG --out DIR``, each in a fresh process timed from before its
   first ``mast`` import to its exit, with that process's peak resident memory.
3. A mine-wide survey: the mine-wide benchmark's owed scans
   (:func:`mast.bench.minewide.run_minewide`, 1081 beams) against their
   scene's own two or three beacons and against a survey of ``beacons`` (the
   same plus copies of their designs in other drifts, out of reach).
4. Start-up: ``mast --help`` in a fresh process.
5. Peer: small_gicp's point-to-plane ICP aligning each fixed scan's beacon returns
   (the beams the simulator says hit a beacon: a head start MAST does not get)
   to the surveyed panels, sampled every 5 mm and extruded +-10 mm vertically so
   that small_gicp can estimate their normals (its Python API takes no given
   normals), starting from the true pose moved 0.2 m and 2 deg. Its time per scan
   and pose error beside ``locate``'s on the same scans. small_gicp is optional
   (``pip install 'mast-survey[bench]'``); without it the benchmark says so.
6. Tracked scans: a 25 Hz drive located in sequence
   (:class:`~mast.pipeline.locator.SequenceLocator`, each scan first near the last
   fix), its scans timed apart by how they were found (fixed by the prior's own
   search, prior tried then the global search, no prior), the tracked fixes' time
   per stage (as the locator clocks them on each fix, ``Fix.stages_s``) and errors,
   and the peer on the same scans'
   beacon returns from the pose of each fix's prior.

Run: ``mast bench speed`` (or ``python -m mast.bench.speed``).
"""

from __future__ import annotations

import cProfile
import functools
import importlib
import json
import math
import os
import platform
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.bench.accuracy import ACCURACY_CONFIGS
from mast.bench.minewide import MinewideSummary, run_minewide
from mast.core.beacon import Survey
from mast.core.geometry import PanelSet
from mast.core.heap import QuietCollector
from mast.core.pose import Pose2D
from mast.pipeline.locator import STAGES as LOCATOR_STAGES
from mast.pipeline.locator import Fix, LocatorConfig, SequenceLocator, SequenceStep, locate
from mast.sim import SCANNERS, DriveScene, ScannerModel, SimulatedScan, drive_scene, write_scenario

__all__ = [
    "DEFAULT_BAG_SCANS",
    "DEFAULT_LOCATE_SCANS",
    "DEFAULT_SCANS_360",
    "DEFAULT_TRACKED_SCANS",
    "DEFAULT_TRACK_SCANS",
    "PEER_MISSING",
    "KeptScans",
    "LocateSpeed",
    "PeerSpeed",
    "ProcessRun",
    "SpeedFigures",
    "StartupSpeed",
    "Stats",
    "TrackedSpeed",
    "kept_scans",
    "measure_locate",
    "measure_minewide",
    "measure_peer",
    "measure_runs",
    "measure_startup",
    "measure_tracked",
    "run_speed",
]

#: Scans located per scanner: 1081 beams, then the 360 degree scanner's 1800.
DEFAULT_LOCATE_SCANS = 300
DEFAULT_SCANS_360 = 100
#: Bag lengths read and located by ``mast locate``, and those tracked (``mast track``
#: runs at about 10 scans a second today).
DEFAULT_BAG_SCANS = (1_000, 3_000)
DEFAULT_TRACK_SCANS = (1_000,)
#: The mine-wide survey's size, and the owed scans located against it.
DEFAULT_SURVEY_BEACONS = 200
DEFAULT_MINEWIDE_POSES = 40
#: ``mast --help`` runs, of which the median is quoted.
DEFAULT_STARTUP_RUNS = 5

#: Scans of a 25 Hz drive located in sequence, each near the last fix (section 6).
DEFAULT_TRACKED_SCANS = 600

#: The simulator's 360 degree scanner (1800 beams at 0.2 degrees).
SCANNER_360 = "spinning-360-0.2"
#: A beacon is in view with at least this many valid returns.
IN_VIEW_RETURNS = 5
#: Scans profiled with cProfile, and the functions listed.
PROFILE_SCANS = 50
PROFILE_TOP = 8

#: The peer's start: the true pose moved this far in a random direction and turned
#: this much either way.
PEER_OFFSET_M = 0.2
PEER_TURN_DEG = 2.0
#: The peer's model: panels sampled every ``PEER_STEP_M`` along and at these heights
#: (a vertical strip, so that a neighbourhood has a plane's normal), normals from
#: ``PEER_NEIGHBOURS`` neighbours.
PEER_STEP_M = 0.005
PEER_HEIGHTS_M = (-0.010, -0.005, 0.0, 0.005, 0.010)
PEER_NEIGHBOURS = 20
#: The peer's registration settings: correspondences within a metre (0.2 m and 2 deg
#: move a return 20 m away by 0.9 m), convergence far tighter than its defaults
#: (0.1 deg, 1 mm) so that its accuracy is not cut short, iterations to match.
PEER_MAX_CORRESPONDENCE_M = 1.0
PEER_MAX_ITERATIONS = 100
PEER_EPSILON = 1e-7
#: What the benchmark says when the peer library is not installed.
PEER_MISSING = (
    "peer not installed: pip install 'mast-survey[bench]' "
    "(from a checkout: pip install -e '.[bench]')"
)

#: The stage functions the locator calls, by their names in ``mast.pipeline.locator``.
STAGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("segmentation", ("segment_scan",)),
    ("identification", ("identify_panels",)),
    ("hypotheses", ("pose_hypotheses", "prior_hypotheses")),
    ("verification (ICP)", ("verify",)),
    (
        "adjustment + integrity",
        (
            "adjust_on_panels",
            "snoop",
            "exclude_inconsistent",
            "residual_summary",
            "cramer_rao_bound",
            "survey_covariance",
        ),
    ),
)
OTHER_STAGE = "other"

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


@dataclass(frozen=True, slots=True)
class Stats:
    """Median, 95th percentile, maximum and mean of some values (``nan`` when none)."""

    median: float
    p95: float
    max: float
    mean: float
    count: int

    @classmethod
    def of(cls, values: Sequence[float] | NDArray[np.float64]) -> Stats:
        v = np.asarray(values, dtype=float)
        if v.size == 0:
            return cls(math.nan, math.nan, math.nan, math.nan, 0)
        return cls(
            float(np.median(v)),
            float(np.percentile(v, 95)),
            float(np.max(v)),
            float(np.mean(v)),
            int(v.size),
        )

    def cells(self, fmt: str = "8.2f") -> str:
        return f"{self.median:{fmt}} {self.p95:{fmt}} {self.max:{fmt}}"


@dataclass(frozen=True, slots=True)
class LocateSpeed:
    """``locate`` on scans held in memory: per-scan times, per stage, and the errors.

    Times in milliseconds; errors of the fixes against the truth, position in mm
    and azimuth in arc-seconds; ``hot`` is (function, share of the profiled time).
    """

    scanner: str
    beams: int
    scans: int
    fixed: int
    time_ms: Stats
    stages_ms: tuple[tuple[str, Stats], ...]
    wrapped_total_ms: Stats
    position_err_mm: Stats
    azimuth_err_arcsec: Stats
    hot: tuple[tuple[str, float], ...]
    profiled_scans: int


@dataclass(frozen=True, slots=True)
class ProcessRun:
    """One step of a whole run in a fresh process: its time, its peak memory."""

    step: str
    scans: int
    seconds: float
    peak_mb: float
    exit_code: int

    @property
    def scans_per_s(self) -> float:
        return self.scans / self.seconds if self.seconds > 0 else math.nan


@dataclass(frozen=True, slots=True)
class StartupSpeed:
    """Wall time of ``mast --help`` and of a bare interpreter, fresh processes, seconds."""

    help_s: tuple[float, ...]
    python_s: tuple[float, ...]

    @property
    def help_median_s(self) -> float:
        return statistics.median(self.help_s)

    @property
    def python_median_s(self) -> float:
        return statistics.median(self.python_s)


@dataclass(frozen=True, slots=True)
class PeerSpeed:
    """The peer and ``locate`` on the same scans: time (ms) and pose errors."""

    library: str
    scans: int
    model_points: int
    model_build_ms: float
    time_ms: Stats
    position_err_mm: Stats
    azimuth_err_arcsec: Stats
    converged: float
    mast_time_ms: Stats
    mast_position_err_mm: Stats
    mast_azimuth_err_arcsec: Stats


@dataclass(frozen=True, slots=True)
class TrackedSpeed:
    """A drive located in sequence (:class:`~mast.pipeline.locator.SequenceLocator`).

    Milliseconds per scan by how it was found: ``tracked_ms`` the scans fixed by their
    prior's own search (``narrow`` of them in the constant-velocity window), ``lost_ms``
    those whose prior was tried and gave no fix (then the global search ran), and
    ``global_ms`` those without a prior. ``stages_ms`` splits the tracked fixes' time
    as section 1 does; the errors are those of the tracked fixes. ``peer_*``: the
    peer from each tracked fix's prior pose on the same scans (empty without it).
    """

    scans: int
    rate_hz: float
    fixed: int
    narrow: int
    tracked_ms: Stats
    lost_ms: Stats
    global_ms: Stats
    stages_ms: tuple[tuple[str, Stats], ...]
    position_err_mm: Stats
    azimuth_err_arcsec: Stats
    peer_ms: Stats
    peer_position_err_mm: Stats
    peer_azimuth_err_arcsec: Stats


@dataclass(frozen=True, slots=True)
class SpeedFigures:
    """Everything the benchmark measured, and the lines it printed."""

    locate: tuple[LocateSpeed, ...]
    runs: tuple[ProcessRun, ...]
    minewide: MinewideSummary | None
    startup: StartupSpeed | None
    peer: PeerSpeed | None
    peer_note: str
    lines: tuple[str, ...]
    tracked: TrackedSpeed | None = None


# --------------------------------------------------------------------------- scans


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


def _pose_errors(truth: Pose2D, got: Pose2D) -> tuple[float, float]:
    """Position error in mm and azimuth error in arc-seconds."""
    pos = 1e3 * math.hypot(got.easting - truth.easting, got.northing - truth.northing)
    turn = math.remainder(got.azimuth - truth.azimuth, math.tau)
    return pos, abs(math.degrees(turn)) * 3600


# --------------------------------------------------------------------------- stages


def _clocked(fn: Callable[..., Any], stage: str, clock: dict[str, float]) -> Callable[..., Any]:
    @functools.wraps(fn)
    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            clock[stage] = clock.get(stage, 0.0) + time.perf_counter() - t0

    return timed


@contextmanager
def _stage_clocks(clock: dict[str, float]) -> Iterator[None]:
    """Wrap the locator's stage functions with a clock adding into ``clock`` per stage.

    A function missing from the locator (renamed) is left out: its time is ``other``.
    """
    from mast.pipeline import locator as module

    saved: dict[str, Any] = {}
    for stage, names in STAGES:
        for name in names:
            fn = getattr(module, name, None)
            if callable(fn):
                saved[name] = fn
                setattr(module, name, _clocked(fn, stage, clock))
    try:
        yield
    finally:
        for name, fn in saved.items():
            setattr(module, name, fn)


def _stage_times(
    sims: Sequence[SimulatedScan], survey: Survey, cfg: LocatorConfig
) -> tuple[tuple[tuple[str, Stats], ...], Stats]:
    """Per-stage milliseconds per scan, and the wrapped total."""
    per: dict[str, list[float]] = {stage: [] for stage, _ in STAGES}
    per[OTHER_STAGE] = []
    totals: list[float] = []
    clock: dict[str, float] = {}
    with _stage_clocks(clock):
        for sim in sims:
            clock.clear()
            t0 = time.perf_counter()
            locate(sim.scan, survey, config=cfg)
            total = time.perf_counter() - t0
            totals.append(1e3 * total)
            for stage, _ in STAGES:
                per[stage].append(1e3 * clock.get(stage, 0.0))
            per[OTHER_STAGE].append(1e3 * (total - sum(clock.values())))
    return tuple((s, Stats.of(v)) for s, v in per.items()), Stats.of(totals)


def _hot_functions(
    sims: Sequence[SimulatedScan], survey: Survey, cfg: LocatorConfig
) -> tuple[tuple[str, float], ...]:
    """The functions with the most own time locating ``sims``, with their share."""
    if not sims:
        return ()
    prof = cProfile.Profile()
    prof.enable()
    for sim in sims:
        locate(sim.scan, survey, config=cfg)
    prof.disable()
    raw: dict[tuple[str, int, str], tuple[Any, ...]] = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    total = sum(v[2] for v in raw.values()) or math.nan
    top = sorted(raw.items(), key=lambda kv: -kv[1][2])[:PROFILE_TOP]
    out = []
    for (file, line, func), v in top:
        where = file
        if "site-packages/" in file:
            where = file.rsplit("site-packages/", 1)[1]
        elif "/mast/" in file:
            where = "mast/" + file.rsplit("/mast/", 1)[1]
        elif file.startswith("~"):
            where = "built-in"
        out.append((f"{where}:{line}:{func}" if line else f"{where}:{func}", v[2] / total))
    return tuple(out)


def measure_locate(
    count: int, *, seed: int = 0, model: ScannerModel | None = None, profile: bool = True
) -> tuple[LocateSpeed, KeptScans]:
    """Time ``locate`` on ``count`` kept scans of a drive, then per stage, then profile
    (``PROFILE_SCANS`` of them). Returns the figures and the scans (for the peer)."""
    kept = kept_scans(seed, count, model)
    cfg = LocatorConfig(range_sigma_m=kept.scanner.range_sigma_m)
    stages, wrapped = _stage_times(kept.sims, kept.survey, cfg)
    profiled = kept.sims[:PROFILE_SCANS] if profile else ()
    hot = _hot_functions(profiled, kept.survey, cfg)
    pos, az = [], []
    for sim, fix in zip(kept.sims, kept.fixes, strict=True):
        if fix.ok and fix.pose is not None:
            p, a = _pose_errors(sim.pose, fix.pose)
            pos.append(p)
            az.append(a)
    figures = LocateSpeed(
        scanner=kept.scanner.name,
        beams=kept.scanner.beam_count,
        scans=len(kept.sims),
        fixed=sum(f.ok for f in kept.fixes),
        time_ms=Stats.of(1e3 * np.asarray(kept.seconds)),
        stages_ms=stages,
        wrapped_total_ms=wrapped,
        position_err_mm=Stats.of(pos),
        azimuth_err_arcsec=Stats.of(az),
        hot=hot,
        profiled_scans=len(profiled),
    )
    return figures, kept


# --------------------------------------------------------------------------- whole runs


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
    sg = _peer_module()
    target = tree = None
    if sg is not None:
        target, tree, _ = _peer_target(scene.survey, sg)
    for sim, st, kept, radius in zip(sims, steps, found, wide, strict=True):
        prior = st.fix.config.prior
        if not kept or st.fix.pose is None or prior is None:
            continue
        p, a = _pose_errors(sim.pose, st.fix.pose)
        pos.append(p)
        az.append(a)
        narrow += prior.radius_m < radius
        if sg is not None:
            beams, points = sim.scan.points()
            source = points[sim.beacon_mask()[beams]]
            if len(source) >= 3:
                ms, got, _ = _peer_align(sg, target, tree, source, prior.pose)
                peer_ms.append(ms)
                pp, pa = _pose_errors(sim.pose, got)
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


# --------------------------------------------------------------------------- mine-wide, start-up


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


# --------------------------------------------------------------------------- the peer


def _peer_module() -> Any:
    """small_gicp, or ``None`` when it is not installed."""
    try:
        return importlib.import_module("small_gicp")
    except ImportError:
        return None


def _panel_model(survey: Survey) -> NDArray[np.float64]:
    """The surveyed panels as 3D points: every ``PEER_STEP_M`` along, at ``PEER_HEIGHTS_M``."""
    panels = PanelSet.from_survey(survey)
    rows = []
    for a, b, length in zip(panels.a, panels.b, panels.length, strict=True):
        t = np.linspace(0.0, 1.0, max(2, math.ceil(length / PEER_STEP_M) + 1))
        rows.append(a + t[:, None] * (b - a))
    xy = np.vstack(rows)
    z = np.asarray(PEER_HEIGHTS_M)
    return np.column_stack([np.repeat(xy, z.size, axis=0), np.tile(z, len(xy))])


def _matrix(pose: Pose2D) -> NDArray[np.float64]:
    """4x4 transform taking scanner-frame points (z = 0) to the mine frame."""
    m = np.eye(4)
    m[:2, :2] = pose.rotation()
    m[:2, 3] = pose.position
    return m


def _pose_of(m: NDArray[np.float64]) -> Pose2D:
    # Pose2D.rotation: [[sin A, -cos A], [cos A, sin A]]
    return Pose2D(float(m[0, 3]), float(m[1, 3]), math.atan2(m[0, 0], m[1, 0]))


def _peer_align(
    sg: Any, target: Any, tree: Any, source: NDArray[np.float64], start: Pose2D
) -> tuple[float, Pose2D, bool]:
    """The peer aligning scanner-frame ``source`` points to the panel model from
    ``start``: its milliseconds, the pose it ends at, and whether it converged."""
    lifted = np.column_stack([source, np.zeros(len(source))])
    t1 = time.perf_counter()
    cloud = sg.PointCloud(lifted)
    result = sg.align(
        target,
        cloud,
        tree,
        init_T_target_source=_matrix(start),
        registration_type="PLANE_ICP",
        max_correspondence_distance=PEER_MAX_CORRESPONDENCE_M,
        num_threads=1,
        max_iterations=PEER_MAX_ITERATIONS,
        rotation_epsilon=PEER_EPSILON,
        translation_epsilon=PEER_EPSILON,
    )
    ms = 1e3 * (time.perf_counter() - t1)
    return ms, _pose_of(np.asarray(result.T_target_source)), bool(result.converged)


def _peer_target(survey: Survey, sg: Any) -> tuple[Any, Any, float]:
    """The peer's model of the surveyed panels, its tree, and milliseconds to build."""
    t0 = time.perf_counter()
    target = sg.PointCloud(_panel_model(survey))
    tree = sg.KdTree(target, 1)
    sg.estimate_normals(target, tree, PEER_NEIGHBOURS, 1)
    return target, tree, 1e3 * (time.perf_counter() - t0)


def measure_peer(kept: KeptScans, *, seed: int = 0) -> PeerSpeed | None:
    """The peer on the scans ``locate`` fixed, beside ``locate``'s own figures on them;
    ``None`` when small_gicp is not installed."""
    sg = _peer_module()
    if sg is None:
        return None
    rng = np.random.default_rng([seed, 23])
    target, tree, build_ms = _peer_target(kept.survey, sg)
    times, pos, az, mast_t, mast_pos, mast_az = [], [], [], [], [], []
    converged = 0
    for sim, fix, dt in zip(kept.sims, kept.fixes, kept.seconds, strict=True):
        if not (fix.ok and fix.pose is not None):
            continue
        beams, points = sim.scan.points()
        source = points[sim.beacon_mask()[beams]]
        if len(source) < 3:
            continue
        truth = sim.pose
        heading = float(rng.uniform(0.0, math.tau))
        turn = math.radians(PEER_TURN_DEG) * float(rng.choice([-1.0, 1.0]))
        start = Pose2D(
            truth.easting + PEER_OFFSET_M * math.cos(heading),
            truth.northing + PEER_OFFSET_M * math.sin(heading),
            truth.azimuth + turn,
        )
        ms, got, ok = _peer_align(sg, target, tree, source, start)
        times.append(ms)
        converged += ok
        p, a = _pose_errors(truth, got)
        pos.append(p)
        az.append(a)
        mp, ma = _pose_errors(truth, fix.pose)
        mast_t.append(1e3 * dt)
        mast_pos.append(mp)
        mast_az.append(ma)
    version = getattr(sg, "__version__", None) or _dist_version("small_gicp")
    return PeerSpeed(
        library=f"small_gicp {version}",
        scans=len(times),
        model_points=int(target.size()),
        model_build_ms=build_ms,
        time_ms=Stats.of(times),
        position_err_mm=Stats.of(pos),
        azimuth_err_arcsec=Stats.of(az),
        converged=converged / len(times) if times else math.nan,
        mast_time_ms=Stats.of(mast_t),
        mast_position_err_mm=Stats.of(mast_pos),
        mast_azimuth_err_arcsec=Stats.of(mast_az),
    )


def _dist_version(name: str) -> str:
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "(version unknown)"


# --------------------------------------------------------------------------- the report


def _locate_lines(figs: Sequence[LocateSpeed]) -> list[str]:
    lines = [
        "1. locate per scan, one core, scans in memory (no file parsing); simulated drive, "
        "seed-drawn 12 mm (1081 beams) / 20 mm (1800 beams) range noise; scans kept when "
        f"fixed or showing two beacons (>= {IN_VIEW_RETURNS} returns each)",
        f"{'scanner':<22} {'beams':>5} {'scans':>5} {'fixed':>5}   "
        f"{'ms: median':>10} {'p95':>7} {'max':>7}   {'pos err mm: median':>18} {'p95':>6} "
        f"{'max':>6}   {'az err arcsec: median':>21} {'p95':>6} {'max':>6}",
    ]
    for f in figs:
        lines.append(
            f"{f.scanner:<22} {f.beams:>5} {f.scans:>5} {f.fixed:>5}   "
            f"{f.time_ms.median:>10.1f} {f.time_ms.p95:>7.1f} {f.time_ms.max:>7.1f}   "
            f"{f.position_err_mm.median:>18.2f} {f.position_err_mm.p95:>6.2f} "
            f"{f.position_err_mm.max:>6.2f}   {f.azimuth_err_arcsec.median:>21.1f} "
            f"{f.azimuth_err_arcsec.p95:>6.1f} {f.azimuth_err_arcsec.max:>6.1f}"
        )
    for f in figs:
        mean_total = f.wrapped_total_ms.mean
        lines += [
            "",
            f"stages of locate, {f.scanner} ({f.beams} beams), {f.scans} scans, ms per scan "
            "(a second pass, the stage functions wrapped with a clock)",
            f"  {'stage':<24} {'median':>8} {'p95':>8} {'max':>8} {'mean':>8} {'share':>7}",
        ]
        for stage, s in (*f.stages_ms, ("total (this pass)", f.wrapped_total_ms)):
            share = s.mean / mean_total if mean_total > 0 else math.nan
            lines.append(
                f"  {stage:<24} {s.median:8.2f} {s.p95:8.2f} {s.max:8.2f} {s.mean:8.2f} "
                f"{100 * share:6.1f}%"
            )
        if f.hot:
            lines.append(
                f"  hot functions (cProfile, own time, {f.profiled_scans} scans; profiling "
                "slows Python-level calls most):"
            )
            lines += [f"    {100 * share:5.1f}%  {name}" for name, share in f.hot]
    return lines


def _tracked_lines(t: TrackedSpeed, note: str) -> list[str]:
    lines = [
        f"6. tracked scans: a {t.rate_hz:g} Hz simulated drive (1081 beams, 12 mm) located in "
        f"sequence, each scan near the last fix (SequenceLocator); {t.scans} scans, "
        f"{t.fixed} fixed",
        f"  {'scans':<42} {'count':>6} {'ms: median':>10} {'p95':>7} {'max':>7} {'mean':>7}",
    ]
    for name, st in (
        (f"fixed in the prior's window ({t.narrow} predicted)", t.tracked_ms),
        ("prior tried, no fix there, then global", t.lost_ms),
        ("no prior (the first, or after a gap)", t.global_ms),
    ):
        figures = (
            f"{st.median:10.2f} {st.p95:7.2f} {st.max:7.2f} {st.mean:7.2f}"
            if st.count
            else f"{'-':>10} {'-':>7} {'-':>7} {'-':>7}"
        )
        lines.append(f"  {name:<42} {st.count:>6} {figures}")
    lines += [
        "  stages of the scans fixed by the prior's search, ms per scan (as the locator clocks "
        "them on each fix, Fix.stages_s):",
        f"  {'stage':<24} {'median':>8} {'p95':>8} {'max':>8} {'mean':>8}",
    ]
    lines += [
        f"  {stage:<24} {s.median:8.2f} {s.p95:8.2f} {s.max:8.2f} {s.mean:8.2f}"
        for stage, s in t.stages_ms
    ]
    lines.append(
        f"  errors of those fixes: position mm median {t.position_err_mm.median:.2f}, p95 "
        f"{t.position_err_mm.p95:.2f}, max {t.position_err_mm.max:.2f}; azimuth arcsec "
        f"median {t.azimuth_err_arcsec.median:.1f}, p95 {t.azimuth_err_arcsec.p95:.1f}, "
        f"max {t.azimuth_err_arcsec.max:.1f}"
    )
    if t.peer_ms.count:
        lines.append(
            f"  peer from each fix's prior pose, the same scans' beacon returns: ms median "
            f"{t.peer_ms.median:.2f}, p95 {t.peer_ms.p95:.2f}; position mm median "
            f"{t.peer_position_err_mm.median:.2f}, max {t.peer_position_err_mm.max:.2f}; "
            f"azimuth arcsec median {t.peer_azimuth_err_arcsec.median:.1f}, max "
            f"{t.peer_azimuth_err_arcsec.max:.1f}; time ratio MAST / peer (medians) "
            f"{t.tracked_ms.median / t.peer_ms.median:.1f}"
        )
    elif note:
        lines.append(f"  {note}")
    return lines


def _run_lines(runs: Sequence[ProcessRun]) -> list[str]:
    lines = [
        "2. whole runs: simulated drive bags (1081 beams, 25 Hz, ROS 1); each step in a "
        "fresh process, timed from before its first mast import to its exit",
        f"  {'bag scans':>9}  {'step':<44} {'seconds':>8} {'scans/s':>9} "
        f"{'time / read':>12} {'peak RSS MB':>12}",
    ]
    read = {r.scans: r for r in runs if r.step == "read"}
    label = {
        "read": "read + deserialise only (read_laserscans)",
        "locate": "mast locate BAG --format json >/dev/null",
        "track": "mast track BAG --out DIR",
    }
    for r in runs:
        base = read.get(r.scans)
        ratio = base.scans_per_s / r.scans_per_s if base is not None else math.nan
        code = "" if r.exit_code == 0 else f"  (exit {r.exit_code})"
        lines.append(
            f"  {r.scans:>9}  {label.get(r.step, r.step):<44} {r.seconds:8.2f} "
            f"{r.scans_per_s:9.1f} {ratio:11.1f}x {r.peak_mb:12.0f}{code}"
        )
    return lines


def _minewide_lines(s: MinewideSummary) -> list[str]:
    lo, hi = s.survey_beacons
    local = f"local ({lo - s.copies}-{hi - s.copies} beacons)"
    return [
        f"3. mine-wide survey: the minewide benchmark's owed scans ({s.config}, 1081 beams), "
        f"{s.poses} scans, each located against its scene's own beacons and against "
        f"{lo}-{hi} beacons (copies >= {s.min_copy_distance_m:.0f} m away, in other drifts)",
        f"  {'survey':<28} {'median ms':>9} {'max ms':>8} {'fixes':>6}",
        f"  {local:<28} {1e3 * s.local_median_s:9.1f} {1e3 * s.local_max_s:8.1f} "
        f"{s.local_fixes:>6}",
        f"  {f'mine-wide ({lo}-{hi} beacons)':<28} {1e3 * s.minewide_median_s:9.1f} "
        f"{1e3 * s.minewide_max_s:8.1f} {s.minewide_fixes:>6}",
        f"  ratio of medians {s.median_ratio:.2f}; status differs on {s.status_differ}, pose on "
        f"{s.pose_differ}; mine-wide index built once in {1e3 * s.index_build_s:.1f} ms",
    ]


def _startup_lines(s: StartupSpeed) -> list[str]:
    runs = ", ".join(f"{t:.2f}" for t in s.help_s)
    return [
        f"4. start-up: mast --help in a fresh process, median of {len(s.help_s)}: "
        f"{s.help_median_s:.2f} s (runs {runs}); a bare python -c pass: "
        f"{s.python_median_s:.2f} s"
    ]


def _peer_lines(p: PeerSpeed | None, note: str) -> list[str]:
    head = "5. peer: a general-purpose registration library on the same scans"
    if p is None:
        return [head, f"  {note}"]
    heights = ", ".join(f"{1e3 * h:g}" for h in PEER_HEIGHTS_M)
    lines = [
        head,
        f"  {p.library}, point-to-plane ICP (PLANE_ICP), one thread, on each scan's beacon "
        f"returns (chosen by the simulator's truth), from the true pose moved "
        f"{PEER_OFFSET_M:g} m (random direction) and {PEER_TURN_DEG:g} deg (either way); "
        f"target: the surveyed panels every {1e3 * PEER_STEP_M:g} mm at heights {heights} mm "
        f"({p.model_points} points, normals from {PEER_NEIGHBOURS} neighbours, built once in "
        f"{p.model_build_ms:.1f} ms); correspondences within {PEER_MAX_CORRESPONDENCE_M:g} m, "
        f"convergence {PEER_EPSILON:g} rad / m, at most {PEER_MAX_ITERATIONS} iterations",
        f"  on the {p.scans} scans MAST fixed:",
        f"  {'method':<34} {'ms: median':>10} {'p95':>7} {'max':>7}   "
        f"{'pos err mm: median':>18} {'p95':>7} {'max':>8}   "
        f"{'az err arcsec: median':>21} {'p95':>7} {'max':>8}",
    ]
    for name, t, e, a in (
        ("MAST locate (global search)", p.mast_time_ms, p.mast_position_err_mm,
         p.mast_azimuth_err_arcsec),
        (f"{p.library.split()[0]} PLANE_ICP (local)", p.time_ms, p.position_err_mm,
         p.azimuth_err_arcsec),
    ):  # fmt: skip
        lines.append(
            f"  {name:<34} {t.median:10.2f} {t.p95:7.2f} {t.max:7.2f}   "
            f"{e.median:18.2f} {e.p95:7.2f} {e.max:8.2f}   "
            f"{a.median:21.1f} {a.p95:7.1f} {a.max:8.1f}"
        )
    lines.append(
        f"  time ratio MAST / peer (medians) {p.mast_time_ms.median / p.time_ms.median:.1f}; "
        f"peer converged (by its own criteria) on {100 * p.converged:.0f} % of the scans"
    )
    return lines


def _header(seed: int) -> list[str]:
    from mast import __version__

    load = ""
    if hasattr(os, "getloadavg"):
        load = "; load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()) + " at start"
    return [
        f"mast bench speed: mast {__version__}, Python {platform.python_version()}, "
        f"numpy {np.__version__}, {os.cpu_count()} CPUs{load}; seed {seed}",
        "wall-clock figures: on a shared machine they are noisy, read the medians",
    ]


def run_speed(
    *,
    scans: int = DEFAULT_LOCATE_SCANS,
    scans_360: int = DEFAULT_SCANS_360,
    bag_scans: Sequence[int] = DEFAULT_BAG_SCANS,
    track_scans: Sequence[int] = DEFAULT_TRACK_SCANS,
    minewide_poses: int = DEFAULT_MINEWIDE_POSES,
    survey_beacons: int = DEFAULT_SURVEY_BEACONS,
    startup_runs: int = DEFAULT_STARTUP_RUNS,
    tracked_scans: int = DEFAULT_TRACKED_SCANS,
    seed: int = 0,
    out: Path | None = None,
    echo: Callable[[str], object] = print,
) -> SpeedFigures:
    """Measure everything the module describes; print each table as it is done.

    Parameters
    ----------
    scans, scans_360 : int
        Scans located at 1081 beams and at 1800 beams (0: skip).
    bag_scans, track_scans : sequence of int
        Bag lengths read and located by ``mast locate``, and tracked by ``mast track``
        (empty: skip).
    minewide_poses : int
        Owed scans of the mine-wide comparison (0: skip).
    survey_beacons : int
        Beacons of the mine-wide survey.
    startup_runs : int
        Fresh ``mast --help`` processes (0: skip).
    tracked_scans : int
        Scans of the drive located in sequence (0: skip).
    seed : int
        Seed of the drives, the mine-wide scenes and the peer's starts.
    out : Path, optional
        Also write every line to this text file.
    echo : callable
        Receives each line.
    """
    lines: list[str] = []

    def say(text: str) -> None:
        lines.append(text)
        echo(text)

    for line in _header(seed):
        say(line)
    locates: list[LocateSpeed] = []
    peer: PeerSpeed | None = None
    note = ""
    if scans > 0:
        first, kept = measure_locate(scans, seed=seed)
        locates.append(first)
        if scans_360 > 0:
            locates.append(measure_locate(scans_360, seed=seed, model=SCANNERS[SCANNER_360])[0])
        say("")
        for line in _locate_lines(locates):
            say(line)
        peer = measure_peer(kept, seed=seed)
        note = PEER_MISSING if peer is None else ""
    runs: list[ProcessRun] = []
    if bag_scans or track_scans:
        runs = measure_runs(bag_scans, track_scans, seed=seed)
        say("")
        for line in _run_lines(runs):
            say(line)
    minewide = None
    if minewide_poses > 0:
        minewide = measure_minewide(minewide_poses, survey_beacons, seed=seed)
        say("")
        for line in _minewide_lines(minewide):
            say(line)
    startup = None
    if startup_runs > 0:
        startup = measure_startup(startup_runs)
        say("")
        for line in _startup_lines(startup):
            say(line)
    if scans > 0:
        say("")
        for line in _peer_lines(peer, note):
            say(line)
    tracked = None
    if tracked_scans > 0:
        tracked = measure_tracked(tracked_scans, seed=seed)
        say("")
        for line in _tracked_lines(tracked, PEER_MISSING if _peer_module() is None else ""):
            say(line)
    if out is not None:
        out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return SpeedFigures(
        tuple(locates), tuple(runs), minewide, startup, peer, note, tuple(lines), tracked
    )


if __name__ == "__main__":  # pragma: no cover - benchmark entry point
    run_speed()
