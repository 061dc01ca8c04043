"""3D lidar frames (``sensor_msgs/PointCloud2``) through the one 3D locator, frame by
frame: what ``mast locate`` and ``mast track`` do with a PointCloud2 topic.

Each frame is located on its own by :func:`mast.pipeline.locator3d.locate3d` (the plan
view's 2D fix, then the six-parameter adjustment). The 2D tracker's prior (the previous
fix narrowing the next search) and its odometry and pose-graph smoothing are planar and
do not apply to a rolled and pitched sensor: a 3D run is per-frame fixes, and only the
frames fixed are placed. The run's summary says so.

A run writes ``fixes.jsonl`` (one 3D record a frame, :func:`mast.report.record.
fix3d_record`), ``trajectory.csv`` and ``trajectory.tum`` with the full 6-DoF pose of
each fix (:func:`mast.io.trajectory.write_trajectory3d_csv`, ``..._tum``), ``map.las``
with the fixed frames' points in the grid at their real elevation (a frame whose
elevation the fix did not observe to 5 cm is left out of it), ``fixes.geojson``
and ``fixes_points.csv`` (the fixes' plan positions).
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.heap import QuietCollector
from mast.core.pose3d import Frame3D, Pose3D
from mast.errors import InputError, OutputError
from mast.io.atomic import atomic_open
from mast.pipeline.adjust3d import PanelPlanes
from mast.pipeline.locator3d import Fix3D, Locator3DConfig, locate3d
from mast.report.record import ReportInputs, Stats3D, fix3d_record
from mast.runs.model import RunSummary

__all__ = [
    "PER_FRAME_NOTE",
    "FrameLocator",
    "PlacedFrame",
    "Run3DResult",
    "check_elevations",
    "track_run3d",
]

#: The run summary's note on what a 3D run is (docs/3d.md).
PER_FRAME_NOTE = (
    "3D frames are fixed one by one (no prior, odometry or smoothing in 3D); "
    "only the frames fixed are placed"
)

#: The files a 3D run writes into its folder.
RUN3D_FILES = (
    "fixes.jsonl",
    "trajectory.csv",
    "trajectory.tum",
    "map.las",
    "fixes.geojson",
    "fixes_points.csv",
)


def check_elevations(survey: Survey, path: str | Path) -> None:
    """A 3D frame needs every beacon's top-edge elevations: an :class:`InputError`
    naming the survey file and the beacons without them otherwise."""
    missing = [b.id for b in survey if b.elevations is None]
    if missing:
        shown = ", ".join(missing[:3]) + (
            f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        )
        raise InputError(
            f"3D lidar frames need each edge's elevation (the panels' top edges), and beacon(s) "
            f"{shown} have none: add an elevation column",
            path=path,
        )


class FrameLocator:
    """The 3D locator with its settings and the survey's panel planes, built once.

    Parameters
    ----------
    survey : Survey
        With elevations (:func:`check_elevations`).
    range_sigma_m, survey_sigma_m : float
        The lidar's range sigma and the survey's (metres).
    """

    def __init__(self, survey: Survey, *, range_sigma_m: float, survey_sigma_m: float) -> None:
        self.survey = survey
        self.config = Locator3DConfig(range_sigma_m=range_sigma_m, survey_sigma_m=survey_sigma_m)
        self.planes = PanelPlanes.of(survey)

    def locate(self, frame: Frame3D) -> Fix3D:
        return locate3d(frame, self.survey, config=self.config, planes=self.planes)

    def record(
        self,
        fix: Fix3D,
        *,
        source: str | None,
        index: int | None,
        frame: Frame3D | None,
        inputs: ReportInputs,
    ) -> dict[str, Any]:
        """The frame's record (:func:`mast.report.record.fix3d_record`)."""
        return fix3d_record(
            fix,
            source=source,
            index=index,
            frame=frame,
            inputs=inputs,
            range_sigma_m=self.config.range_sigma_m,
            survey_sigma_m=self.config.survey_sigma_m,
        )


@dataclass(frozen=True, slots=True)
class PlacedFrame:
    """A frame fixed in 3D: its message index, stamp, pose and 6×6 covariance (order
    :data:`mast.pipeline.adjust3d.PARAMETERS`; the elevation's variance ``None`` in
    :attr:`elevation_observed` terms when no top edge bracketed it)."""

    scan: int
    stamp_ns: int
    pose: Pose3D
    covariance: NDArray[np.float64]
    elevation_observed: bool

    @property
    def sigma(self) -> NDArray[np.float64]:
        """Standard deviations in :data:`~mast.pipeline.adjust3d.PARAMETERS` order (metres,
        radians); the elevation's NaN when not observed."""
        s = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        if not self.elevation_observed:
            s[2] = np.nan
        return s


@dataclass(slots=True)
class Run3DResult:
    """What a 3D run produced."""

    summary: RunSummary
    placed: list[PlacedFrame]
    out: Path
    interrupted: bool = False
    warnings: list[str] = field(default_factory=list)
    frame_times_s: list[float] = field(default_factory=list)


def _frames(bag: Path, topic: str | None, on_skip: Callable[[str], None]) -> Iterator[Frame3D]:
    from mast.io.pointclouds import read_pointclouds

    return read_pointclouds(bag, topic, on_skip=on_skip)


def track_run3d(
    bag: Path,
    survey: Survey,
    out: Path,
    *,
    locator: FrameLocator,
    topic: str | None = None,
    inputs: ReportInputs | None = None,
    warn: Callable[[str], object] = print,
    progress: Callable[[int, int, int | None], object] | None = None,
    interrupt: threading.Event | None = None,
) -> Run3DResult:
    """Locate every PointCloud2 frame of ``bag`` and write the run's files
    (:data:`RUN3D_FILES`) into ``out`` (see the module).

    ``warn`` is told of every message skipped (a damaged bag is read as from the field);
    ``progress`` gets (frames so far, fixes so far, the topic's frames from the bag's
    index or None); ``interrupt``, once set, ends the reading between two frames, the
    files then holding the frames read until then.
    """
    from mast.io.pointclouds import pointcloud_count, pointcloud_topic
    from mast.io.trajectory import write_trajectory3d_csv, write_trajectory3d_tum
    from mast.runs import outputs

    t0 = time.perf_counter()
    inputs = inputs or ReportInputs()
    name = inputs.topic if inputs.topic is not None else pointcloud_topic(bag, topic)
    inputs = replace(inputs, scan_file=inputs.scan_file or str(bag), topic=name)
    total = pointcloud_count(bag, topic) if progress is not None else None
    summary = RunSummary(run=str(bag), topic=name)
    result = Run3DResult(summary, [], out)

    def skipped(text: str) -> None:
        if "skipped" in text:
            summary.skipped += 1
        result.warnings.append(text)
        warn(text)

    try:
        with (
            atomic_open(out / "fixes.jsonl", "w", encoding="utf-8") as fh,
            outputs.FixExports(out, inputs.crs) as exports,
            QuietCollector() as heap,
        ):
            try:
                for i, frame in enumerate(heap.each(_frames(bag, topic, skipped))):
                    if interrupt is not None and interrupt.is_set():
                        result.interrupted = True
                        break
                    fix = locator.locate(frame)
                    result.frame_times_s.append(fix.elapsed_s)
                    rec = locator.record(fix, source=str(bag), index=i, frame=frame, inputs=inputs)
                    fh.write(json.dumps(rec) + "\n")
                    exports.add(rec)
                    summary.scans += 1
                    if summary.first_stamp_ns is None:
                        summary.first_stamp_ns = frame.stamp_ns
                    summary.last_stamp_ns = frame.stamp_ns
                    adj = fix.adjustment
                    if fix.ok and fix.pose is not None and adj is not None:
                        summary.fixes += 1
                        summary.reference_variances.append((adj.reference_variance, adj.dof))
                        st = Stats3D.of(adj)
                        summary.chi2_tests[st.test_code] = (
                            summary.chi2_tests.get(st.test_code, 0) + 1
                        )
                        result.placed.append(
                            PlacedFrame(
                                i, frame.stamp_ns, fix.pose, st.covariance, st.elevation_observed
                            )
                        )
                    else:
                        reason = fix.reason or "unknown"
                        summary.reasons[reason] = summary.reasons.get(reason, 0) + 1
                    if progress is not None:
                        progress(summary.scans, summary.fixes, total)
            except KeyboardInterrupt:
                result.interrupted = True
    except OSError as err:
        raise OutputError(
            f"cannot write: {err.strerror or err}", path=out / "fixes.jsonl"
        ) from None
    summary.placed = len(result.placed)
    try:
        write_trajectory3d_csv(out / "trajectory.csv", result.placed)
        write_trajectory3d_tum(out / "trajectory.tum", result.placed)
        _write_map(bag, topic, out / "map.las", survey, result, inputs)
    except OSError as err:
        raise OutputError(
            f"cannot write the run's files: {err.strerror or err}", path=out
        ) from None
    summary.elapsed_s = time.perf_counter() - t0
    return result


def _write_map(
    bag: Path,
    topic: str | None,
    path: Path,
    survey: Survey,
    result: Run3DResult,
    inputs: ReportInputs,
) -> None:
    """``map.las``: every fixed frame's points in the grid, at their real elevation (a
    second pass over the bag: memory holds one frame)."""
    from mast.runs.outputs import LasMapWriter

    pts = [b.edges.mean(axis=0) for b in survey]
    if result.placed:
        pts.append(result.placed[0].pose.position[:2])
    c = np.mean(pts, axis=0) if pts else np.zeros(2)
    origin = (float(np.floor(c[0] / 1000) * 1000), float(np.floor(c[1] / 1000) * 1000))
    placed = {p.scan: p for p in result.placed}
    tops = [float(np.mean(b.elevations)) for b in survey if b.elevations is not None]
    origin_z = float(np.floor(np.mean(tops) / 100) * 100) if tops else 0.0
    with LasMapWriter(
        path, origin_e=origin[0], origin_n=origin[1], crs=inputs.crs, origin_z=origin_z
    ) as las:
        if not placed:
            return
        last = max(placed)
        for i, frame in enumerate(_frames(bag, topic, lambda _: None)):
            if i > last:
                break
            here = placed.get(i)
            if here is None or not here.elevation_observed:
                continue  # a frame whose elevation is not known to 5 cm is no map's
            las.add(i, frame.stamp_ns, here.pose.sensor_to_grid(frame.points), frame.intensity)
