"""The files a survey run leaves behind: trajectory, point map, plan and report.

``mast track RUN --beacons B --out DIR`` writes (docs/design.md, "A run"):

* ``trajectory.csv`` (:func:`mast.io.trajectory.write_trajectory_csv`): one row per placed scan,
  full precision, the file contract
  ``stamp_ns,easting,northing,azimuth_deg,sigma_easting_m,sigma_northing_m,
  sigma_azimuth_deg,source``;
* ``trajectory.tum`` (:func:`mast.io.trajectory.write_trajectory_tum`): the same poses as TUM
  ``t x y z qx qy qz qw`` for trajectory tools such as evo;
* ``map.las`` (:class:`LasMapWriter`): every return of every placed scan in
  the mine grid, streamed scan by scan;
* ``map.dxf`` (:func:`write_map_dxf`): a plan for CAD: walls, surveyed
  beacons, trajectory and fixes on named layers, in metres;
* ``fixes.geojson`` and ``fixes_points.csv`` (:class:`FixExports`): every fix from
  beacons as a GeoJSON Point and as a row of a point list survey packages import;
  ``trajectory.geojson`` (:func:`write_trajectory_geojson`): the placed trajectory,
  one LineString per unbroken stretch, for GIS;
* ``report.html`` (:func:`write_report_html`): one self-contained page
  (figures inline as SVG, no network) with the run's counts, figures of the
  trajectory, its precision and the fixes' global tests, and a table of fixes.

Frames (docs/design.md, "Frames and units"): mine frame E = x, N = y in
metres; azimuth clockwise from grid north. A TUM or GTSAM heading (yaw) is
counter-clockwise from +E, so ``yaw = 90° − azimuth``.

Every writer raises :class:`~mast.errors.OutputError` naming the file when it
cannot be written. The grid's CRS (``--crs``), when given, is stated in ``map.las``,
the GeoJSON and the report.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core.beacon import Survey
from mast.core.pose import format_dms
from mast.core.trajectory import PlacedScan, Trajectory
from mast.errors import InputError, OutputError
from mast.io.atomic import atomic_open, write_lines
from mast.io.crs import GridCrs
from mast.io.dxf import add_dxf_beacons, new_dxf, save_dxf
from mast.io.geojson import FeatureCollectionWriter, line_string, point
from mast.io.las import (
    INT32_MAX,
    LAS_SCALE_M,
    LasWriter,
    gps_adjusted_time,
    las_integers,
    las_offsets,
    new_las_header,
)
from mast.io.point_list import PointListWriter
from mast.report.html import (
    CSS,
    axis_label,
    escape,
    group_thousands,
    inline_svg,
    new_figure,
    plot_origin,
)
from mast.runs.model import RunSummary

__all__ = [
    "DXF_LAYERS",
    "MAX_TABLE_ROWS",
    "FixExports",
    "LasMapWriter",
    "fix_name",
    "write_map_dxf",
    "write_report_html",
    "write_trajectory_geojson",
]

#: The LAS offset is rounded to a multiple of this (metres): a round number a reader
#: recognises, still well inside the int32 reach of ±214 km at 0.1 mm.
LAS_OFFSET_STEP_M: Final = 1.0

#: The layers of ``map.dxf`` and their AutoCAD colour index.
DXF_LAYERS: Final[Mapping[str, int]] = {
    "MAST_WALLS": 8,  # grey
    "MAST_BEACONS": 1,  # red
    "MAST_TRAJECTORY": 5,  # blue
    "MAST_FIXES": 3,  # green
}

#: Radius of the circle marking a fix in the DXF, metres.
DXF_FIX_RADIUS_M: Final = 0.05
#: Length of a fix's azimuth tick in the DXF (from the fix along the scanner's +x), metres.
DXF_FIX_TICK_M: Final = 0.5
#: The DXF's trajectory keeps a vertex at least this far from the last one kept
#: (and the last of each stretch): a scan every few centimetres is noise in CAD.
DXF_VERTEX_SPACING_M: Final = 0.1
#: Fixes are drawn in the DXF at least this far apart (every fix is in trajectory.csv).
DXF_FIX_SPACING_M: Final = 1.0

#: The report's table of fixes stops after this many rows (a note says so).
MAX_TABLE_ROWS: Final = 2000
#: At most this many wall points are drawn in the report's map (evenly thinned).
MAX_FIGURE_POINTS: Final = 50_000
#: At most this many poses of a run are drawn per series in the report (evenly thinned).
MAX_FIGURE_POSES: Final = 4000
#: Markers beyond this many in one series are drawn as an image inside the SVG:
#: as vector marks they would make the page megabytes long.
MAX_VECTOR_MARKERS: Final = 5000

_ARCSEC_PER_RAD: Final = 180.0 / math.pi * 3600.0


@dataclass(frozen=True, slots=True)
class _Poses:
    """A run's placed scans as arrays; ``stretch`` numbers the unbroken stretches.

    Between two stretches (a scan index skipped) the scanner's path is unknown:
    the scans there were neither fixed nor chained to a fix, so the trajectory
    is not drawn across.
    """

    scan: NDArray[np.int64]
    stamp_ns: NDArray[np.int64]
    xy: NDArray[np.float64]
    azimuth: NDArray[np.float64]
    sigma: NDArray[np.float64]
    fix: NDArray[np.bool_]
    stretch: NDArray[np.int64]

    @classmethod
    def of(cls, placed: Iterable[PlacedScan]) -> _Poses:
        if isinstance(placed, Trajectory):
            c = placed.columns()
            scan, stamp, pose, fix = c["scan"], c["stamp_ns"], c["pose"], c["fix"]
            var = np.diagonal(c["covariance"], axis1=1, axis2=2)
        else:
            rows = list(placed)
            scan = np.array([p.scan for p in rows], dtype=np.int64)
            stamp = np.array([p.stamp_ns for p in rows], dtype=np.int64)
            pose = np.array(
                [(p.pose.easting, p.pose.northing, p.pose.azimuth) for p in rows], dtype=float
            ).reshape(-1, 3)
            fix = np.array([p.source == "fix" for p in rows], dtype=bool)
            var = np.array([np.diag(p.covariance) for p in rows], dtype=float).reshape(-1, 3)
        stretch = np.concatenate([[0], np.cumsum(np.diff(scan) != 1)]) if len(scan) else scan
        return cls(
            scan.astype(np.int64),
            stamp.astype(np.int64),
            pose[:, :2].astype(float),
            pose[:, 2].astype(float),
            np.sqrt(np.maximum(var, 0.0)),
            fix.astype(bool),
            stretch.astype(np.int64),
        )

    def __len__(self) -> int:
        return len(self.scan)

    def spans(self) -> Iterator[slice]:
        """Each unbroken stretch as a slice."""
        cuts = np.flatnonzero(np.diff(self.stretch)) + 1
        bounds = [0, *cuts.tolist(), len(self)]
        for a, b in itertools.pairwise(bounds):
            if b > a:
                yield slice(a, b)

    def thinned(self, limit: int) -> NDArray[np.intp]:
        """Indices of at most about ``limit`` poses, evenly spread (first and last kept)."""
        n = len(self)
        if n <= limit:
            return np.arange(n)
        return np.unique(np.round(np.linspace(0, n - 1, limit)).astype(np.intp))

    def length_m(self) -> float:
        """Distance along the placed trajectory, not across its breaks."""
        if len(self) < 2:
            return 0.0
        step = np.hypot(*np.diff(self.xy, axis=0).T)
        return float(np.sum(step[np.diff(self.stretch) == 0]))


# --------------------------------------------------------------------------- LAS


class LasMapWriter:
    """Stream the returns of a run's placed scans into a LAS 1.4 point cloud.

    Points are written scan by scan as they are added, through
    :class:`mast.io.las.LasWriter` (nothing accumulates: memory does not grow with
    the run); the header's counts and bounds are finalised by :meth:`close`. A
    ``.laz`` path is compressed (lazrs).

    Parameters
    ----------
    path : str or Path
        ``map.las`` (replaced if it exists).
    origin_e, origin_n : float
        A point near the survey, metres (``origin_z`` its elevation, for a 3D run's
        map; 0 by default). The header offsets are these rounded
        to :data:`LAS_OFFSET_STEP_M`, and the scales :data:`LAS_SCALE_M`
        (0.1 mm), so UTM-sized coordinates keep 0.1 mm: LAS stores each
        coordinate as an int32 multiple of the scale from the offset, which
        reaches ±214 km around the origin.
    crs : GridCrs, optional
        The grid's coordinate reference system (``--crs``).

    Notes
    -----
    Point data record format 6 (LAS 1.4): x = easting, y = northing, z = the
    elevation for 3D frames' points and 0 for a 2D scan's,
    ``intensity`` (uint16), ``return_number`` = ``number_of_returns`` = 1,
    ``gps_time`` and the extra dimension ``scan_index`` (uint32, the
    LaserScan message index of the point's scan).

    ``gps_time`` is **Adjusted Standard GPS Time** (GPS seconds since
    1980-01-06 minus 10^9, :func:`gps_adjusted_time`), converted from the
    scans' Unix (UTC) stamps with the leap seconds; the header's global
    encoding says so (bit 0, GPS time type, set), as it also sets the WKT bit
    that LAS 1.4 requires with format 6. The grid's CRS, when given, is the
    OGC WKT VLR (:func:`mast.io.las.new_las_header`); without it none is
    recorded: the mine grid is the survey's.

    Examples
    --------
    How ``mast track`` would use it (``scans[i]`` the Scan of message i)::

        with LasMapWriter(out / "map.las", origin_e=e0, origin_n=n0) as las:
            for p in placed:
                _, pts = scans[p.scan].points()
                las.add(p.scan, p.stamp_ns, p.pose.scanner_to_mine(pts))
    """

    def __init__(
        self,
        path: str | Path,
        *,
        origin_e: float,
        origin_n: float,
        crs: GridCrs | None = None,
        origin_z: float = 0.0,
    ) -> None:
        import laspy

        if not (math.isfinite(origin_e) and math.isfinite(origin_n) and math.isfinite(origin_z)):
            raise InputError(f"map origin ({origin_e}, {origin_n}, {origin_z}) is not finite")
        self.path = Path(path)
        scan_index = laspy.ExtraBytesParams(
            name="scan_index", type=np.uint32, description="LaserScan message index"
        )
        offsets = las_offsets([origin_e, origin_n, origin_z], LAS_OFFSET_STEP_M)
        header = new_las_header(
            offsets=offsets,
            software="mast",
            system="MAST survey run",
            wkt=True,
            extra=[scan_index],
            crs=crs,
        )
        self._offset = offsets
        self._las = LasWriter(self.path, header)

    @property
    def count(self) -> int:
        """Points written so far."""
        return self._las.count

    @property
    def writing(self) -> Path:
        """The temporary file being written; renamed onto :attr:`path` by :meth:`close`."""
        return self._las.writing

    def __enter__(self) -> LasMapWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # Failed part-way: no map rather than half of one.
        self._las.__exit__(exc_type, exc, tb)

    def add(
        self,
        scan_index: int,
        stamp_ns: int,
        points_mine: ArrayLike,
        intensity: ArrayLike | None = None,
    ) -> int:
        """Append the returns of one scan.

        Parameters
        ----------
        scan_index : int
            The scan's LaserScan message index (from 0).
        stamp_ns : int
            Its stamp, nanoseconds since the Unix epoch.
        points_mine : array_like, shape (n, 2) or (n, 3)
            Its returns in the mine frame (E, N), metres, or (E, N, elevation) for a
            3D frame's (z 0 otherwise). Rows with a coordinate that is not finite
            (beams without a return) are left out.
        intensity : array_like, shape (n,), optional
            The returns' intensities, rounded and clipped to LAS's uint16
            (0..65535); not finite gives 0. Without it, 0.

        Returns
        -------
        int
            Points written for this scan.

        Raises
        ------
        InputError
            Shapes do not match, or a point lies beyond the ±214 km that LAS
            can store at 0.1 mm around the origin.
        OutputError
            The writer is closed, or the file cannot be written.
        """
        if self._las.closed:
            raise OutputError("already closed", path=self.path)
        pts = np.asarray(points_mine, dtype=float)
        if pts.ndim != 2 or pts.shape[1] not in (2, 3):
            raise InputError(f"points_mine must have shape (n, 2) or (n, 3), got {pts.shape}")
        keep = np.all(np.isfinite(pts), axis=1)
        inten = np.zeros(len(pts))
        if intensity is not None:
            inten = np.asarray(intensity, dtype=float).reshape(-1)
            if inten.shape != (len(pts),):
                raise InputError(
                    f"intensity must have shape ({len(pts)},) like the points, got {inten.shape}"
                )
        pts, inten = pts[keep], inten[keep]
        n = len(pts)
        if n == 0:
            return 0
        dims = pts.shape[1]
        counts, far = las_integers(pts, self._offset[:dims])
        if far >= 0:
            e, north = pts[far][:2]
            raise InputError(
                f"scan {scan_index}: point ({e:.3f}, {north:.3f}) is more than "
                f"{INT32_MAX * LAS_SCALE_M / 1000:.0f} km from the map origin "
                f"({self._offset[0]:.0f}, {self._offset[1]:.0f}); LAS cannot store it at "
                f"{LAS_SCALE_M * 1000:g} mm"
            )
        record = self._las.zeros(n)
        record.X = counts[:, 0]
        record.Y = counts[:, 1]
        record.Z = counts[:, 2] if dims == 3 else np.zeros(n, dtype=np.int32)
        record.intensity = np.clip(np.round(np.nan_to_num(inten, nan=0.0)), 0, 65535).astype(
            np.uint16
        )
        record.return_number = np.ones(n, dtype=np.uint8)
        record.number_of_returns = np.ones(n, dtype=np.uint8)
        record.gps_time = np.full(n, gps_adjusted_time(np.int64(stamp_ns)))
        record.scan_index = np.full(n, scan_index, dtype=np.uint32)
        return self._las.write(record)

    def close(self) -> int:
        """Finalise the header (counts, bounds) and close the file; the points written."""
        return self._las.close()


# --------------------------------------------------------------------------- GIS and survey


def fix_name(scan: int) -> str:
    """A fix's point name in the exports: ``F`` and its scan index (``F123``)."""
    return f"F{scan}"


class FixExports:
    """``fixes.geojson`` and ``fixes_points.csv``, written fix by fix as a run goes
    (whole or not at all, :mod:`mast.io.atomic`).

    ``fixes.geojson`` is a FeatureCollection of one Point per fix from beacons
    (:mod:`mast.io.geojson`: grid coordinates, the grid's CRS member when given) with
    the fix's name, scan, stamp, azimuth, sigmas, reference variance, global test
    and beacons; ``fixes_points.csv`` the same fixes as a point list
    (:mod:`mast.io.point_list`). Both hold the fix's own pose, as ``fixes.jsonl``
    does, not the smoothed trajectory's.

    Parameters
    ----------
    out : Path
        The run's folder.
    crs : GridCrs, optional
        The grid's CRS.
    """

    def __init__(self, out: Path, crs: GridCrs | None = None) -> None:
        self._out = out
        self._crs = crs
        self._stack = ExitStack()
        self.count = 0

    def __enter__(self) -> FixExports:
        with ExitStack() as stack:
            gj = stack.enter_context(
                atomic_open(self._out / "fixes.geojson", "w", encoding="utf-8")
            )
            pl = stack.enter_context(
                atomic_open(self._out / "fixes_points.csv", "w", newline="", encoding="utf-8")
            )
            self._geojson = FeatureCollectionWriter(gj, crs=self._crs, name="fixes")
            self._points = PointListWriter(pl)
            self._stack = stack.pop_all()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self._geojson.close()
        self._stack.__exit__(exc_type, exc, tb)

    def add(self, record: Mapping[str, Any]) -> None:
        """A fix record of a sequence (:func:`mast.report.record.fix_record` with its
        ``scan``); one that is not a fix is passed over."""
        if record.get("status") != "fix":
            return
        scan = int(record["scan"])
        name = fix_name(scan)
        e, n = float(record["easting"]), float(record["northing"])
        az = float(record["azimuth_deg"])
        sigma_e, sigma_n, sigma_az = (
            record.get(k) for k in ("sigma_easting_m", "sigma_northing_m", "sigma_azimuth_deg")
        )
        self._geojson.add(
            point(e, n),
            {
                "name": name,
                "scan": scan,
                "stamp_ns": record.get("stamp_ns"),
                "azimuth_deg": az,
                "azimuth_dms": format_dms(az),
                "sigma_easting_m": sigma_e,
                "sigma_northing_m": sigma_n,
                "sigma_azimuth_deg": sigma_az,
                "reference_variance": record.get("reference_variance"),
                "chi2_test": record.get("chi2_test"),
                "beacons": ",".join(str(b) for b in record.get("beacons") or ()),
            },
        )
        z = record.get("elevation_m")  # a 3D lidar frame's fix has its elevation
        if record.get("elevation_observed") is False:
            z = None  # not to survey precision: no point-list elevation
        self._points.add(
            name, e, n, None if z is None else float(z), az, sigma_e, sigma_n, sigma_az
        )
        self.count += 1


def write_trajectory_geojson(
    path: str | Path, placed: Iterable[PlacedScan], crs: GridCrs | None = None
) -> int:
    """Write ``trajectory.geojson``; the stretches written.

    One LineString Feature per unbroken stretch of at least two placed scans
    (consecutive scan indices: the path is not drawn across a break; a stretch of one
    scan makes no line and is left out, it is in ``trajectory.csv``), with its first
    and last scan and stamp, its scans and its fixes. Grid coordinates of the smoothed
    poses, the grid's CRS member when given (:mod:`mast.io.geojson`).
    """
    poses = _Poses.of(placed)
    with atomic_open(path, "w", encoding="utf-8") as fh:
        lines = FeatureCollectionWriter(fh, crs=crs, name="trajectory")
        for k, span in enumerate(poses.spans()):
            if span.stop - span.start < 2:
                continue
            lines.add(
                line_string(poses.xy[span]),
                {
                    "stretch": k,
                    "first_scan": int(poses.scan[span.start]),
                    "last_scan": int(poses.scan[span.stop - 1]),
                    "first_stamp_ns": int(poses.stamp_ns[span.start]),
                    "last_stamp_ns": int(poses.stamp_ns[span.stop - 1]),
                    "scans": span.stop - span.start,
                    "fixes": int(np.count_nonzero(poses.fix[span])),
                },
            )
        return lines.close()


# --------------------------------------------------------------------------- DXF


def _finite_rows(points: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    return p[np.all(np.isfinite(p), axis=1)]


def write_map_dxf(
    path: str | Path,
    survey: Survey,
    placed: Iterable[PlacedScan],
    walls: Iterable[ArrayLike],
    fixes: Iterable[PlacedScan],
) -> None:
    """Write ``map.dxf``: the run's plan in the mine grid, for CAD.

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists).
    survey : Survey
        The surveyed beacons.
    placed : iterable of PlacedScan
        Every placed scan, in time order.
    walls : iterable of array_like, shape (n, 2)
        Wall pieces in the mine frame (E, N), metres, e.g. the scans' straight
        segments mapped to the mine frame; each becomes one polyline. Rows
        that are not finite are dropped; a piece with fewer than two points
        left is skipped.
    fixes : iterable of PlacedScan
        The placed scans that were fixed from beacons.

    Notes
    -----
    DXF R2010, units metres (``$INSUNITS`` = 6, ``$MEASUREMENT`` = 1 metric);
    coordinates are written as full doubles, so UTM-sized ones are kept
    exactly. Layers (:data:`DXF_LAYERS`):

    ``MAST_WALLS``
        one LWPOLYLINE per wall piece;
    ``MAST_BEACONS``
        per beacon, an LWPOLYLINE through its four surveyed edges and a TEXT
        with its id at its centre (:data:`mast.io.dxf.DXF_TEXT_HEIGHT_M` high);
    ``MAST_TRAJECTORY``
        one LWPOLYLINE per unbroken stretch of placed scans (consecutive scan
        indices), a POINT for a stretch of one scan: the path is not drawn
        where the run was not placed; a vertex at least
        :data:`DXF_VERTEX_SPACING_M` from the last one kept;
    ``MAST_FIXES``
        per fix at least :data:`DXF_FIX_SPACING_M` from the last one drawn, a
        CIRCLE (:data:`DXF_FIX_RADIUS_M`) and a LINE of :data:`DXF_FIX_TICK_M`
        from it along its azimuth.

    The drawing grows with the distance driven, not with the scans: a run
    scanned at 50 Hz draws as one at 10 Hz.

    Raises
    ------
    OutputError
        The file cannot be written.
    """
    doc, msp = new_dxf(DXF_LAYERS)

    for piece in walls:
        p = _finite_rows(piece)
        if len(p) >= 2:
            msp.add_lwpolyline(p.tolist(), dxfattribs={"layer": "MAST_WALLS"})

    add_dxf_beacons(msp, survey, "MAST_BEACONS")

    poses = _Poses.of(placed)
    for span in poses.spans():
        xy = poses.xy[span]
        keep = [0]
        for k in range(1, len(xy) - 1):
            if math.dist(xy[k], xy[keep[-1]]) >= DXF_VERTEX_SPACING_M:
                keep.append(k)
        if len(xy) > 1:
            keep.append(len(xy) - 1)
        if len(keep) == 1:
            msp.add_point(xy[0].tolist(), dxfattribs={"layer": "MAST_TRAJECTORY"})
        else:
            msp.add_lwpolyline(xy[keep].tolist(), dxfattribs={"layer": "MAST_TRAJECTORY"})

    last: tuple[float, float] | None = None
    for f in fixes:
        e, n, a = f.pose.easting, f.pose.northing, f.pose.azimuth
        if last is not None and math.dist((e, n), last) < DXF_FIX_SPACING_M:
            continue
        last = (e, n)
        msp.add_circle((e, n), DXF_FIX_RADIUS_M, dxfattribs={"layer": "MAST_FIXES"})
        tip = (e + DXF_FIX_TICK_M * math.sin(a), n + DXF_FIX_TICK_M * math.cos(a))
        msp.add_line((e, n), tip, dxfattribs={"layer": "MAST_FIXES"})

    save_dxf(doc, path)


# --------------------------------------------------------------------------- report

_FIX_COLOUR: Final = "tab:red"
_ODO_COLOUR: Final = "tab:blue"
_WALL_COLOUR: Final = "0.6"
_BEACON_COLOUR: Final = "tab:green"
_NICE: Final = (1.0, 2.0, 5.0)


def _broken(
    t: NDArray[np.float64], y: NDArray[np.float64], stretch: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``t, y`` with a NaN inserted where the stretch changes: lines break at gaps."""
    if len(t) < 2:
        return t, y
    gaps = np.nonzero(np.diff(stretch) != 0)[0] + 1
    return np.insert(t, gaps, np.nan), np.insert(y, gaps, np.nan)


def _map_figure(
    survey: Survey,
    poses: _Poses,
    wall_points: NDArray[np.float64],
) -> tuple[str, str]:
    """The trajectory over the beacons and the wall points; SVG and caption."""
    drawn = poses.thinned(MAX_FIGURE_POSES)
    pose_xy = poses.xy[drawn]
    edges = np.vstack([b.edges for b in survey]) if len(survey) else np.zeros((0, 2))
    walls = _finite_rows(wall_points)
    if len(walls) > MAX_FIGURE_POINTS:
        walls = walls[:: math.ceil(len(walls) / MAX_FIGURE_POINTS)]
    extent = np.vstack([pose_xy, edges, walls])
    oe, on = plot_origin(extent)
    o = np.array([oe, on])
    fig, (ax,) = new_figure(10.0, 7.0)
    if len(walls):
        # Rasterised: tens of thousands of dots as vector marks would bloat the page.
        ax.scatter(
            *(walls - o).T,
            s=0.4,
            c=_WALL_COLOUR,
            linewidths=0,
            rasterized=True,
            label=f"wall returns ({len(walls)} drawn)",
            zorder=1,
        )
    for k, b in enumerate(survey):
        e = np.asarray(b.edges) - o
        ax.plot(*e.T, "-", color=_BEACON_COLOUR, lw=2.0, zorder=3, label="beacon" if k == 0 else "")
        c = b.centroid - o
        ax.annotate(
            b.id,
            (float(c[0]), float(c[1])),
            xytext=(0, 6),
            textcoords="offset points",
            ha="center",
            fontsize=8,
            color="darkgreen",
            zorder=5,
        )
    if len(drawn):
        xy = pose_xy - o
        te, tn = _broken(xy[:, 0], xy[:, 1], poses.stretch[drawn])
        ax.plot(te, tn, "-", color=_ODO_COLOUR, lw=1.0, zorder=4, label="trajectory")
        fix = poses.fix[drawn]
        if np.any(~fix):
            ax.plot(
                *xy[~fix].T,
                ".",
                ms=2.5,
                color=_ODO_COLOUR,
                zorder=4,
                label="placed by odometry",
                rasterized=bool(np.count_nonzero(~fix) > MAX_VECTOR_MARKERS),
            )
        if np.any(fix):
            ax.plot(
                *xy[fix].T,
                "o",
                ms=4,
                mfc="none",
                mec=_FIX_COLOUR,
                zorder=6,
                label="fixed from beacons",
                rasterized=bool(np.count_nonzero(fix) > MAX_VECTOR_MARKERS),
            )
        ax.plot(*xy[0], ">", ms=8, color="k", zorder=7, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(axis_label("E", oe))
    ax.set_ylabel(axis_label("N", on))
    for axis in (ax.xaxis, ax.yaxis):
        axis.get_major_formatter().set_useOffset(False)
        axis.get_major_formatter().set_scientific(False)
    ax.grid(True, color="0.92", lw=0.6, zorder=0)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best", framealpha=0.85)
    svg = inline_svg(fig, "trajectory-map")
    where = (
        "Axes in metres of the mine grid."
        if oe == 0.0 and on == 0.0
        else f"Axes in metres from E {group_thousands(oe)}, N {group_thousands(on)} "
        "(the origin of the axes)."
    )
    caption = (
        "Trajectory of the scanner over the surveyed beacons (green, with their ids) and "
        "the wall returns (grey). Circles: scans fixed from beacons; dots: scans placed by "
        "odometry between fixes; the line breaks where scans could not be placed. "
        f"{where} Equal scales in E and N."
    )
    return svg, caption


def _precision_figure(poses: _Poses, t0_ns: int) -> tuple[str, str]:
    """σE, σN (mm) and σA (arc-seconds) against time since the first scan."""
    drawn = poses.thinned(MAX_FIGURE_POSES)
    t = (poses.stamp_ns[drawn] - t0_ns) / 1e9
    sig = poses.sigma[drawn]
    stretch = poses.stretch[drawn]
    fix = poses.fix[drawn]
    fig, (ax_pos, ax_az) = new_figure(10.0, 5.5, rows=2)
    series = (
        (ax_pos, sig[:, 0] * 1000.0, "σE", "tab:blue"),
        (ax_pos, sig[:, 1] * 1000.0, "σN", "tab:orange"),
        (ax_az, sig[:, 2] * _ARCSEC_PER_RAD, "σA", "tab:purple"),
    )
    for ax, y, name, colour in series:
        ax.plot(*_broken(t, y, stretch), "-", lw=1.0, color=colour, label=name)
        if np.any(fix):
            ax.plot(
                t[fix],
                y[fix],
                "o",
                ms=3.5,
                mfc="none",
                mec=colour,
                label=f"{name} at fixes",
                rasterized=bool(np.count_nonzero(fix) > MAX_VECTOR_MARKERS),
            )
    for ax, unit in ((ax_pos, "σ (mm)"), (ax_az, "σA (″)")):
        y = np.concatenate([line.get_ydata() for line in ax.get_lines()]).astype(float)
        y = y[np.isfinite(y) & (y > 0)]
        # A log axis when odometry's growth between fixes dwarfs the fixes' own sigma.
        if len(y) and y.max() / y.min() > 50.0:
            ax.set_yscale("log")
        ax.set_ylabel(unit)
        ax.grid(True, color="0.92", lw=0.6)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0), framealpha=0.85)
    ax_az.set_xlabel("time since the first scan (s)")
    svg = inline_svg(fig, "precision")
    caption = (
        "Standard deviations of the smoothed poses along the run: easting and northing in "
        "millimetres (top), azimuth in arc-seconds (bottom), against the time since the "
        "first scan; circles mark the scans fixed from beacons, lines break where scans "
        "were not placed."
    )
    return svg, caption


def _reference_variance_figure(values: Sequence[tuple[float, int]]) -> tuple[str, str] | None:
    """Histogram of the fixes' reference variances with the density they should follow."""
    from scipy import stats

    v = np.array([x for x, d in values if d > 0 and math.isfinite(x)], dtype=float)
    dof = np.array([d for x, d in values if d > 0 and math.isfinite(x)], dtype=float)
    if len(v) == 0:
        return None
    lo_q = float(min(stats.chi2.ppf(0.0005, d) / d for d in np.unique(dof)))
    hi_q = float(max(stats.chi2.ppf(0.9995, d) / d for d in np.unique(dof)))
    lo = min(lo_q, float(v.min()))
    hi = max(hi_q, float(v.max()))
    pad = 0.05 * (hi - lo)
    lo, hi = max(lo - pad, 0.0), hi + pad
    x = np.linspace(lo, hi, 400)
    # Under the model each fix's reference variance is chi-square(dof)/dof; the pooled
    # sample follows the mixture of those densities, weighted by how many fixes have each.
    ds, counts = np.unique(dof, return_counts=True)
    dens = sum(c * d * stats.chi2.pdf(d * x, d) for d, c in zip(ds, counts, strict=True))
    dens = np.asarray(dens, dtype=float) / len(v)
    fig, (ax,) = new_figure(8.0, 4.0)
    bins = int(min(60, max(10, math.ceil(2 * len(v) ** (1 / 3)) * 2)))
    ax.hist(
        v,
        bins=bins,
        range=(lo, hi),
        density=True,
        color="0.75",
        edgecolor="white",
        label=f"{len(v)} fixes",
    )
    ax.plot(x, dens, "-", color="tab:red", lw=1.5, label="χ²(ν)/ν, mixture over the fixes' ν")
    ax.axvline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xlabel("reference variance (a-posteriori / a-priori)")
    ax.set_ylabel("density")
    ax.grid(True, color="0.92", lw=0.6)
    ax.legend(fontsize=8, framealpha=0.85)
    svg = inline_svg(fig, "reference-variance")
    med = float(np.median(dof))
    caption = (
        f"Histogram (as a density) of the reference variances of the {len(v)} fixes. "
        "The red curve is the density they follow when the precisions used are right: "
        "each fix's reference variance is then χ²(ν)/ν with ν its degrees of freedom, and "
        "the curve is the mixture of those densities over all fixes (ν from "
        f"{group_thousands(ds.min())} to {group_thousands(ds.max())}, "
        f"median {group_thousands(med)}). Bars to the "
        "right of the curve: returns scatter more than the range precision says; to the "
        "left: less."
    )
    return svg, caption


def _record_time(rec: Mapping[str, Any], t0_ns: int | None) -> str:
    stamp = rec.get("stamp_ns")
    if stamp is None or t0_ns is None:
        return ""
    return f"{(int(stamp) - t0_ns) / 1e9:.3f}"


def _fmt(value: Any, spec: str, scale: float = 1.0) -> str:
    if value is None:
        return ""
    try:
        return format(float(value) * scale, spec)
    except (TypeError, ValueError):
        return escape(value)


def _fix_table(
    records: Sequence[Mapping[str, Any]], t0_ns: int | None, max_rows: int
) -> tuple[str, int]:
    """The table of fixes (at most ``max_rows``) and how many fixes there are."""
    fixes = [r for r in records if r.get("status") == "fix"]
    head = (
        "<tr><th class='n'>scan</th><th class='n'>t (s)</th><th class='n'>E (m)</th>"
        "<th class='n'>N (m)</th><th class='n'>azimuth</th><th class='n'>σE (mm)</th>"
        "<th class='n'>σN (mm)</th><th class='n'>σA (″)</th>"
        "<th class='n'>ref. variance</th><th class='n'>ν</th><th>χ² test</th>"
        "<th>beacons</th></tr>"
    )
    rows = []
    for r in fixes[:max_rows]:
        az = r.get("azimuth_dms")
        if az is None and r.get("azimuth_deg") is not None:
            az = format_dms(float(r["azimuth_deg"]))
        test = str(r.get("chi2_test") or "")
        beacons = r.get("beacons") or []
        rows.append(
            "<tr>"
            f"<td class='n'>{escape(r.get('scan', ''))}</td>"
            f"<td class='n'>{_record_time(r, t0_ns)}</td>"
            f"<td class='n'>{_fmt(r.get('easting'), '.4f')}</td>"
            f"<td class='n'>{_fmt(r.get('northing'), '.4f')}</td>"
            f"<td class='n'>{escape(az or '')}</td>"
            f"<td class='n'>{_fmt(r.get('sigma_easting_m'), '.2f', 1000.0)}</td>"
            f"<td class='n'>{_fmt(r.get('sigma_northing_m'), '.2f', 1000.0)}</td>"
            f"<td class='n'>{_fmt(r.get('sigma_azimuth_deg'), '.1f', 3600.0)}</td>"
            f"<td class='n'>{_fmt(r.get('reference_variance'), '.3f')}</td>"
            f"<td class='n'>{escape(r.get('degrees_of_freedom', ''))}</td>"
            f"<td class='test-{escape(test)}'>{escape(test)}</td>"
            f"<td>{escape(', '.join(str(b) for b in beacons))}</td>"
            "</tr>"
        )
    return f"<table class='fixes'>{head}{''.join(rows)}</table>", len(fixes)


def _utc(stamp_ns: int) -> str:
    return datetime.fromtimestamp(stamp_ns // 1_000_000_000, tz=UTC).strftime(
        "%Y-%m-%d %H:%M:%S UTC"
    )


def _summary_rows(
    summary: RunSummary,
    poses: _Poses,
    t0_ns: int | None,
    t1_ns: int | None,
    crs: GridCrs | None,
) -> list[tuple[str, str]]:
    n_odo = int(np.count_nonzero(~poses.fix))

    def share(k: int) -> str:
        return f"{k}" if summary.scans <= 0 else f"{k} ({100.0 * k / summary.scans:.1f} %)"

    rows = [
        ("Run", summary.run),
        ("Topic", summary.topic or "(not named)"),
        ("Scans read", f"{summary.scans}"),
        ("Fixed from beacons", share(summary.fixes)),
        ("Placed in the mine grid", share(summary.placed)),
        ("of which by odometry", f"{n_odo}"),
        ("Not placed", f"{max(summary.scans - summary.placed, 0)}"),
        ("Messages skipped (not decodable)", f"{summary.skipped}"),
    ]
    if crs is not None:
        rows.insert(2, ("Grid CRS", crs.line()))
    if t0_ns is not None and t1_ns is not None:
        rows.append(
            ("Recorded", f"{_utc(t0_ns)}, {(t1_ns - t0_ns) / 1e9:.1f} s from first to last scan")
        )
    if len(poses):
        rows.append(("Distance along the placed trajectory", f"{poses.length_m():.1f} m"))
    rate = f", {summary.scans / summary.elapsed_s:.1f} scans/s" if summary.elapsed_s > 0 else ""
    rows.append(("Processing time", f"{summary.elapsed_s:.1f} s{rate}"))
    return rows


def write_report_html(
    path: str | Path,
    summary: RunSummary,
    placed: Sequence[PlacedScan],
    records: Sequence[Mapping[str, Any]],
    survey: Survey,
    wall_points: ArrayLike,
    *,
    max_table_rows: int = MAX_TABLE_ROWS,
    crs: GridCrs | None = None,
) -> None:
    """Write ``report.html``: one self-contained page about a run.

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists).
    summary : RunSummary
        The run's counts, no-fix reasons, reference variances and time.
    placed : sequence of PlacedScan
        Every placed scan, in time order.
    records : sequence of dict
        The run's fix records (``fixes.jsonl``, docs/fix.schema.json); those
        with ``status`` ``fix`` make the table. The first ``max_table_rows``
        fixes are enough: the counts come from ``summary`` when it has them.
    survey : Survey
        The surveyed beacons.
    wall_points : array_like, shape (n, 2)
        A sample of wall returns in the mine frame (E, N), metres; at most
        :data:`MAX_FIGURE_POINTS` are drawn (evenly thinned).
    max_table_rows : int
        The table of fixes stops after this many rows, with a note.
    crs : GridCrs, optional
        The grid's CRS, named in the summary.

    Notes
    -----
    The page holds, in order: a summary (run, topic, scans, fixes, placed,
    skipped messages, recording time, distance, processing time and scans
    per second); the no-fix reasons with their counts and meanings; a map of
    the trajectory (fixes and odometry-placed scans distinguished) over the
    beacons with their ids and the wall returns, equal scales, axes in metres
    from a stated round origin at UTM-sized coordinates; the precision along
    the run (σE, σN in mm, σA in arc-seconds against time since the first
    scan, fixes marked); a histogram of the fixes' reference variances against
    the mixture of the χ²(ν)/ν densities of their degrees of freedom ν; and a
    table of the fixes (scan, time, E, N, azimuth D°MM'SS.S", σ's in mm and
    arc-seconds, reference variance, ν, χ² test, beacons).

    Figures are matplotlib SVG inlined in the page, the style sheet is
    inline, there are no scripts and nothing is fetched: the file can be
    mailed or opened offline. All text taken from inputs is HTML-escaped.

    Raises
    ------
    OutputError
        The file cannot be written.
    """
    from mast import __version__
    from mast.pipeline.locator import NO_FIX_REASONS

    walls = np.asarray(wall_points, dtype=float).reshape(-1, 2)
    poses = _Poses.of(placed)
    stamps = [int(r["stamp_ns"]) for r in records if r.get("stamp_ns") is not None]
    stamps += [t for t in (summary.first_stamp_ns, summary.last_stamp_ns) if t is not None]
    if len(poses):
        stamps += [int(poses.stamp_ns.min()), int(poses.stamp_ns.max())]
    t0 = min(stamps) if stamps else None
    t1 = max(stamps) if stamps else None

    parts: list[str] = [
        "<!DOCTYPE html>",
        "<html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>MAST run report: {escape(summary.run)}</title>",
        f"<style>{CSS}</style></head><body>",
        "<h1>MAST survey run</h1>",
        f"<p class='sub'>{escape(summary.run)}</p>",
        "<h2>Summary</h2><table class='summary'>",
    ]
    for key, value in _summary_rows(summary, poses, t0, t1, crs):
        parts.append(f"<tr><th>{escape(key)}</th><td>{escape(value)}</td></tr>")
    parts.append("</table>")

    parts.append("<h2>Scans without a fix</h2>")
    reasons = {k: v for k, v in summary.reasons.items() if v}
    if reasons:
        parts.append("<table><tr><th>reason</th><th class='n'>scans</th><th>meaning</th></tr>")
        for reason, count in sorted(reasons.items(), key=lambda kv: (-kv[1], kv[0])):
            parts.append(
                f"<tr><td>{escape(reason)}</td><td class='n'>{count}</td>"
                f"<td>{escape(NO_FIX_REASONS.get(reason, ''))}</td></tr>"
            )
        parts.append("</table>")
    else:
        parts.append("<p>Every scan read was fixed.</p>" if summary.scans else "<p>No scan.</p>")

    figures: list[tuple[str, str, str]] = []
    if len(poses) or len(survey) or len(walls):
        svg, cap = _map_figure(survey, poses, walls)
        figures.append(("Trajectory", svg, cap))
    if len(poses) and t0 is not None:
        svg, cap = _precision_figure(poses, t0)
        figures.append(("Precision along the run", svg, cap))
    rv = _reference_variance_figure(summary.reference_variances)
    for k, (title, svg, cap) in enumerate(figures, start=1):
        parts.append(f"<h2>{escape(title)}</h2><figure>{svg}")
        parts.append(f"<figcaption>Figure {k}. {escape(cap)}</figcaption></figure>")
    parts.append("<h2>Global test of the fixes</h2>")
    if rv is None:
        parts.append("<p>No fix: no reference variance to show.</p>")
    else:
        svg, cap = rv
        parts.append(
            f"<figure>{svg}<figcaption>Figure {len(figures) + 1}. {escape(cap)}"
            "</figcaption></figure>"
        )
        tests = dict(summary.chi2_tests)
        if not tests:
            for r in records:
                if r.get("status") == "fix" and r.get("chi2_test"):
                    tests[str(r["chi2_test"])] = tests.get(str(r["chi2_test"]), 0) + 1
        if tests:
            words = ", ".join(f"{escape(k)} {v}" for k, v in sorted(tests.items()))
            parts.append(f"<p>χ² test of the reference variance at 5 %: {words}.</p>")

    parts.append("<h2>Fixes</h2>")
    table, n_fix = _fix_table(records, t0, max_table_rows)
    n_fix = max(n_fix, summary.fixes)
    if n_fix == 0:
        parts.append("<p>No fix.</p>")
    else:
        if n_fix > max_table_rows:
            parts.append(
                f"<p class='note'>The first {max_table_rows} of {n_fix} fixes are listed; "
                "every fix is in fixes.jsonl.</p>"
            )
        parts.append(
            "<p>t: seconds since the first scan; E, N: metres; azimuth clockwise from grid "
            "north; ν: degrees of freedom.</p>"
        )
        parts.append(table)
    now = datetime.now(tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    parts.append(f"<footer>mast {escape(__version__)}, {escape(now)}</footer></body></html>")

    write_lines(path, parts)
