"""The benchmark itself, and its tables."""

from __future__ import annotations

import math
import os
import platform
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from mast.bench.minewide import MinewideSummary
from mast.bench.speed.model import (
    DEFAULT_BAG_SCANS,
    DEFAULT_LOCATE_SCANS,
    DEFAULT_MINEWIDE_POSES,
    DEFAULT_SCANS_360,
    DEFAULT_STARTUP_RUNS,
    DEFAULT_SURVEY_BEACONS,
    DEFAULT_TRACK_SCANS,
    DEFAULT_TRACKED_SCANS,
    IN_VIEW_RETURNS,
    PEER_EPSILON,
    PEER_HEIGHTS_M,
    PEER_MAX_CORRESPONDENCE_M,
    PEER_MAX_ITERATIONS,
    PEER_MISSING,
    PEER_NEIGHBOURS,
    PEER_OFFSET_M,
    PEER_STEP_M,
    PEER_TURN_DEG,
    SCANNER_360,
    LocateSpeed,
    PeerSpeed,
    ProcessRun,
    SpeedFigures,
    StartupSpeed,
    TrackedSpeed,
)
from mast.bench.speed.peer import measure_peer, peer_module
from mast.bench.speed.runs import measure_minewide, measure_runs, measure_startup, measure_tracked
from mast.bench.speed.stages import measure_locate
from mast.sim import SCANNERS

__all__ = ["run_speed"]


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
        for line in _tracked_lines(tracked, PEER_MISSING if peer_module() is None else ""):
            say(line)
    if out is not None:
        out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return SpeedFigures(
        tuple(locates), tuple(runs), minewide, startup, peer, note, tuple(lines), tracked
    )
