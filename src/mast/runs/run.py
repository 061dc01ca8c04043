"""``mast track``: a bag in; every scan located, placed, mapped and reported.

One pass streams the bag through :class:`~mast.runs.track.RunTracker` (the one
locator, tracked from the previous pose, plus odometry), writing each scan's
record to ``fixes.jsonl`` as it goes; the pose graph is then smoothed, and a
second pass over the bag puts every placed scan's returns into the map.
Memory holds a few numbers per scan, never the scans.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.heap import QuietCollector
from mast.core.scan import Scan
from mast.core.trajectory import Trajectory
from mast.errors import OutputError
from mast.io.atomic import atomic_open
from mast.pipeline.locator import segmentation_of
from mast.report.hints import Hints
from mast.report.record import ReportInputs, fix_record
from mast.runs.model import RunSummary
from mast.runs.track import Node, RunTracker, Smoother, TrackConfig

__all__ = ["RUN_FILES", "RunResult", "track_run"]

#: What a run writes into its folder.
RUN_FILES = (
    "fixes.jsonl",
    "trajectory.csv",
    "trajectory.tum",
    "map.las",
    "map.dxf",
    "report.html",
    "fixes.geojson",
    "fixes_points.csv",
    "trajectory.geojson",
)

#: Keys of a fix record kept for the report's table (the whole record is in fixes.jsonl).
_TABLE_KEYS = (
    "scan",
    "stamp_ns",
    "status",
    "easting",
    "northing",
    "azimuth_deg",
    "azimuth_dms",
    "sigma_easting_m",
    "sigma_northing_m",
    "sigma_azimuth_deg",
    "reference_variance",
    "degrees_of_freedom",
    "chi2_test",
    "beacons",
)
#: Wall pieces for the DXF are taken from scans at least this far apart.
WALL_SPACING_M = 2.0
#: Map points kept for the report's figure.
REPORT_POINTS = 20_000


@dataclass(slots=True)
class RunResult:
    """What a run produced."""

    summary: RunSummary
    placed: Trajectory
    out: Path
    interrupted: bool = False
    warnings: list[str] = field(default_factory=list)
    hints: list[str] = field(default_factory=list)
    """What the run's refusals point to (:class:`mast.report.hints.Hints`), one line each."""


def _walls(fix_segments: Any) -> NDArray[np.float64]:
    """The scan's straight pieces (scanner frame) as an (n, 2, 2) array of end points."""
    segs = [s for s in fix_segments if s.length >= 0.5]
    if not segs:
        return np.zeros((0, 2, 2))
    return np.array([[s.start, s.end] for s in segs], dtype=float)


def track_run(
    bag: Path,
    survey: Survey,
    out: Path,
    *,
    config: TrackConfig | None = None,
    topic: str | None = None,
    inputs: ReportInputs | None = None,
    range_limits: tuple[float | None, float | None] = (None, None),
    warn: Callable[[str], object] = print,
    progress: Callable[[int, int, int | None], object] | None = None,
    interrupt: threading.Event | None = None,
) -> RunResult:
    """Track every LaserScan of ``bag`` and write the run's files into ``out``.

    Parameters
    ----------
    bag : Path
        A ROS 1 bag, a ROS 2 bag folder, an MCAP file or a folder of scan CSVs
        (:func:`mast.io.scans.open_scans`).
    survey : Survey
    out : Path
        An existing, writable folder.
    config : TrackConfig, optional
    topic : str, optional
        The LaserScan topic (needed when the bag has several).
    inputs : ReportInputs, optional
        What to state in each record about the inputs; its ``crs`` (the grid's) also
        goes into the map, the GeoJSON and the report.
    range_limits : (min, max)
        Override the bag's range limits, metres.
    warn : callable
        Told about every message skipped and where a damaged bag stopped.
    progress : callable, optional
        Called with (scans so far, fixes so far, the run's scans) after each scan; the
        run's scans come from the bag's index or the folder's files, None when unknown
        (:func:`mast.io.scans.scan_count`).
    interrupt : threading.Event, optional
        Set (by a signal handler) to end the reading between two scans: a signal then
        never lands inside a compiled kernel or a half-written record.

    Returns
    -------
    RunResult
        ``interrupted`` when Ctrl-C stopped the reading: the files then hold the
        scans read until then, and are complete and valid.
    """
    from mast.io.scans import ScanReading, scan_format
    from mast.io.trajectory import write_trajectory_csv, write_trajectory_tum
    from mast.runs import outputs

    cfg = config or TrackConfig()
    t0 = time.perf_counter()
    inputs = inputs or ReportInputs()

    def skipped(text: str) -> None:
        if "skipped" in text:
            summary.skipped += 1
        result.warnings.append(text)
        warn(text)

    low, high = range_limits
    fmt = scan_format(bag, what="run")

    def scans(on_skip: Callable[[str], None]) -> Generator[Scan, None, None]:
        """The run's scans (read twice: located, then mapped)."""
        return fmt.read(bag, ScanReading(topic, range_min_m=low, range_max_m=high, on_skip=on_skip))

    # The caller may have resolved the topic already (opening a bag is not free).
    name = inputs.topic if inputs.topic is not None else fmt.topic_of(bag, topic)
    inputs = replace(inputs, scan_file=inputs.scan_file or str(bag), topic=name)
    total = fmt.count(bag, topic) if progress is not None else None
    summary = RunSummary(run=str(bag), topic=name)
    result = RunResult(summary, Trajectory(), out)

    from mast.runs.outputs import MAX_TABLE_ROWS

    tracker = RunTracker(survey, cfg)
    hints = Hints(survey, cfg.locator)
    # Each scan is placed for good once enough fixes after it are known: memory
    # holds the longest stretch between fixes, not the run.
    smoother = Smoother(cfg)
    placed = result.placed
    table: list[dict[str, Any]] = []
    walls: dict[int, NDArray[np.float64]] = {}
    last_wall: NDArray[np.float64] | None = None
    try:
        # What is alive once a scan is located is frozen, out of the collector's full
        # passes (mast.core.heap); again every thousand scans, what the run has kept.
        with (
            atomic_open(out / "fixes.jsonl", "w", encoding="utf-8") as fh,
            outputs.FixExports(out, inputs.crs) as exports,
            QuietCollector() as heap,
        ):
            try:
                for i, scan in enumerate(heap.each(scans(skipped))):
                    if interrupt is not None and interrupt.is_set():
                        result.interrupted = True
                        break
                    step = tracker.step(i, scan)
                    hints.add(scan, step.fix)
                    rec = fix_record(step.fix, source=str(bag), index=i, scan=scan, inputs=inputs)
                    fh.write(json.dumps(rec) + "\n")
                    exports.add(rec)
                    for p in smoother.push(Node.of(step)):
                        placed.append(p)
                    summary.scans += 1
                    if summary.first_stamp_ns is None:
                        summary.first_stamp_ns = scan.stamp_ns
                    summary.coasted += step.motion is not None and step.motion.matches == 0
                    if (
                        summary.last_stamp_ns is not None
                        and scan.stamp_ns - summary.last_stamp_ns > cfg.max_gap_s * 1e9
                    ):
                        summary.gaps += 1
                    summary.last_stamp_ns = scan.stamp_ns
                    if step.fix.ok:
                        summary.fixes += 1
                        adj = step.fix.adjustment
                        if adj is not None:
                            summary.reference_variances.append((adj.reference_variance, adj.dof))
                        test = str(rec.get("chi2_test") or "")
                        if test:
                            summary.chi2_tests[test] = summary.chi2_tests.get(test, 0) + 1
                        if len(table) < MAX_TABLE_ROWS:
                            table.append({k: rec.get(k) for k in _TABLE_KEYS})
                    else:
                        reason = step.fix.reason or "unknown"
                        summary.reasons[reason] = summary.reasons.get(reason, 0) + 1
                    pose = step.fix.pose if step.fix.ok else step.predicted
                    if pose is not None and (
                        last_wall is None or math.dist(pose.position, last_wall) >= WALL_SPACING_M
                    ):
                        # a scan fixed near the last fix was not segmented: now it is
                        walls[i] = _walls(segmentation_of(step.fix, scan).segments)
                        last_wall = pose.position
                    if progress is not None:
                        progress(summary.scans, summary.fixes, total)
            except KeyboardInterrupt:  # a caller that left Ctrl-C to Python
                result.interrupted = True
    except OSError as err:
        raise OutputError(
            f"cannot write: {err.strerror or err}", path=out / "fixes.jsonl"
        ) from None
    for p in smoother.finish():
        placed.append(p)
    summary.placed = len(placed)
    result.hints = hints.lines()
    try:
        write_trajectory_csv(out / "trajectory.csv", placed)
        write_trajectory_tum(out / "trajectory.tum", placed)
        outputs.write_trajectory_geojson(out / "trajectory.geojson", placed, inputs.crs)
        origin = _origin(survey, placed)
        sample: list[NDArray[np.float64]] = []
        wall_lines: list[NDArray[np.float64]] = []
        points = 0
        poses = iter(placed)
        here = next(poses, None)
        with outputs.LasMapWriter(
            out / "map.las", origin_e=origin[0], origin_n=origin[1], crs=inputs.crs
        ) as las:
            for i, scan in enumerate(scans(lambda _: None)):
                if i >= summary.scans or here is None:
                    break  # an interrupted run maps what it read
                if here.scan != i:
                    continue
                beams, pts = scan.points()
                mine = here.pose.scanner_to_mine(pts)
                inten = None if scan.intensities is None else scan.intensities[beams]
                las.add(i, scan.stamp_ns, mine, inten)
                points += len(mine)
                # A copy: a slice would keep every scan's returns alive to the end.
                sample.append(mine[:: max(1, len(placed) * len(mine) // REPORT_POINTS + 1)].copy())
                seg = walls.get(i)
                if seg is not None and len(seg):
                    wall_lines.extend(
                        here.pose.scanner_to_mine(seg.reshape(-1, 2)).reshape(-1, 2, 2)
                    )
                here = next(poses, None)
        outputs.write_map_dxf(
            out / "map.dxf",
            survey,
            placed,
            wall_lines,
            (q for q in placed if q.source == "fix"),
        )
        summary.elapsed_s = time.perf_counter() - t0
        wall_points = np.vstack(sample) if sample else np.zeros((0, 2))
        outputs.write_report_html(
            out / "report.html", summary, placed, table, survey, wall_points, crs=inputs.crs
        )
    except OSError as err:
        raise OutputError(
            f"cannot write the run's files: {err.strerror or err}", path=out
        ) from None
    return result


def _origin(survey: Survey, placed: Trajectory) -> tuple[float, float]:
    """A round point near the run, for the map's coordinate offsets."""
    pts = [b.edges.mean(axis=0) for b in survey]
    if placed:
        pts.append(placed[0].pose.position)
    c = np.mean(pts, axis=0) if pts else np.zeros(2)
    return float(np.floor(c[0] / 1000) * 1000), float(np.floor(c[1] / 1000) * 1000)
