"""Writing LAS 1.4 / LAZ point clouds: one streaming writer for every cloud MAST makes.

``mast track``'s ``map.las`` (:class:`mast.runs.outputs.LasMapWriter`), ``mast
georef``'s georeferenced copy (:mod:`mast.cloud.io`) and ``mast simulate``'s SLAM
cloud (:mod:`mast.sim.cloud`) all write through :class:`LasWriter`: points go out
chunk by chunk as they are made (memory does not grow with the cloud), under a
temporary name beside the target that is renamed onto it only once the header's
counts and bounds are final (:mod:`mast.io.atomic`), and a ``.laz`` target is
compressed with lazrs.

LAS stores each coordinate as a 32-bit integer multiple of the header's scale from
its offset. :func:`las_offsets` puts the offset on a round number near the data
and :func:`las_integers` says where a coordinate falls beyond the ±214 km that
int32 reaches at :data:`LAS_SCALE_M`; each caller names that problem its own way
(a scan of a run is bad input, a georeferenced cloud an output it cannot write).

``gps_time`` in a LAS 1.4 file is **Adjusted Standard GPS Time** when the header's
global encoding says so (bit 0): :func:`gps_adjusted_time` converts Unix stamps to
it with the leap seconds.

A grid's coordinate reference system (``--crs``, :class:`mast.io.crs.GridCrs`) goes
into the header as the OGC WKT VLR with the WKT bit set, which LAS 1.4 defines: a
header given one is made LAS 1.4 whatever version it would have had.
"""

from __future__ import annotations

import calendar
import contextlib
import datetime
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.errors import OutputError
from mast.io.atomic import commit, discard, part_path

if TYPE_CHECKING:
    import laspy

    from mast.io.crs import GridCrs

__all__ = [
    "INT32_MAX",
    "LAS_SCALE_M",
    "LasWriter",
    "gps_adjusted_time",
    "las_integers",
    "las_offsets",
    "new_las_header",
]

#: LAS coordinate quantum, metres: 0.1 mm, kept at UTM-sized coordinates because the
#: header offset sits near the data (LAS stores int32 multiples of it from the offset).
LAS_SCALE_M: Final = 1e-4

#: The largest integer a LAS coordinate holds (int32).
INT32_MAX: Final = 2**31 - 1

# --------------------------------------------------------------------------- time

#: Unix time (s) at the GPS epoch, 1980-01-06T00:00:00 UTC.
_GPS_EPOCH_UNIX: Final = 315_964_800
#: Adjusted Standard GPS Time is GPS time minus 10^9 s (LAS 1.4, global encoding bit 0).
_GPS_ADJUST_S: Final = 1_000_000_000
#: GPS − UTC in seconds, from each leap second on (IERS Bulletin C). No leap second has
#: been inserted since 2017-01-01; a new one would be added here.
_LEAP_SECONDS: Final = tuple(
    (calendar.timegm((y, m, 1, 0, 0, 0)), k)
    for k, (y, m) in enumerate(
        [
            (1981, 7),
            (1982, 7),
            (1983, 7),
            (1985, 7),
            (1988, 1),
            (1990, 1),
            (1991, 1),
            (1992, 7),
            (1993, 7),
            (1994, 7),
            (1996, 1),
            (1997, 7),
            (1999, 1),
            (2006, 1),
            (2009, 1),
            (2012, 7),
            (2015, 7),
            (2017, 1),
        ],
        start=1,
    )
)


def gps_adjusted_time(stamp_ns: ArrayLike) -> NDArray[np.float64]:
    """Adjusted Standard GPS Time (LAS ``gps_time``) of Unix time stamps.

    Parameters
    ----------
    stamp_ns : array_like of int
        Nanoseconds since the Unix epoch (UTC, as ROS message stamps are).

    Returns
    -------
    ndarray of float
        GPS seconds since 1980-01-06 minus 10^9 s: Unix seconds, plus the
        leap seconds GPS has gained on UTC by then (18 since 2017), minus
        315 964 800 s and 10^9 s. Computed in integer nanoseconds, so the only
        rounding is the final one to a double (0.1 µs near the present).
    """
    ns = np.asarray(stamp_ns, dtype=np.int64)
    bounds = np.array([t for t, _ in _LEAP_SECONDS], dtype=np.int64) * 1_000_000_000
    leap = np.searchsorted(bounds, ns, side="right").astype(np.int64)
    shift_ns = (leap - _GPS_EPOCH_UNIX - _GPS_ADJUST_S) * 1_000_000_000
    whole, frac = np.divmod(ns + shift_ns, 1_000_000_000)
    return np.asarray(whole.astype(np.float64) + frac.astype(np.float64) / 1e9)


# --------------------------------------------------------------------------- header


def las_offsets(origin: ArrayLike, step_m: float) -> NDArray[np.float64]:
    """Header offsets for coordinates near ``origin``: each rounded to a multiple of
    ``step_m`` (a number a reader recognises), so the int32 coordinates reach
    ±214 km about them at :data:`LAS_SCALE_M`."""
    # + 0.0: an origin just west or south of zero gives 0, not -0 (a header's bytes)
    return np.asarray(np.round(np.asarray(origin, dtype=float) / step_m) * step_m + 0.0)


def new_las_header(
    *,
    offsets: ArrayLike,
    software: str,
    system: str | None = None,
    point_format: int | laspy.PointFormat = 6,
    version: str = "1.4",
    gps_standard: bool = True,
    wkt: bool = False,
    extra: Sequence[laspy.ExtraBytesParams] = (),
    created: datetime.date | None = None,
    crs: GridCrs | None = None,
) -> laspy.LasHeader:
    """A LAS header (1.4 unless told) at :data:`LAS_SCALE_M` (0.1 mm) on every axis.

    Parameters
    ----------
    offsets : array_like, shape (3,)
        The header's offsets, metres (see :func:`las_offsets`).
    software : str
        The generating software (at most 32 characters).
    system : str, optional
        The system identifier (at most 32 characters); laspy's "OTHER" without it.
    point_format : int or laspy.PointFormat
        The point data record format (6: no colour, 7: RGB), or a copy's own format
        with its extra dimensions.
    version : str
        The LAS version ("1.4"; a copy keeps its source's).
    gps_standard : bool
        ``gps_time`` is Adjusted Standard GPS Time (global encoding bit 0), as
        :func:`gps_adjusted_time` makes it; otherwise GPS week time.
    wkt : bool
        Set the global encoding's WKT bit (a CRS, if ever written, is WKT).
    extra : sequence of laspy.ExtraBytesParams
        Extra dimensions, in this order.
    created : datetime.date, optional
        The creation date; today (laspy's default) without it. A simulator fixes it so
        that the same seed writes the same bytes.
    crs : GridCrs, optional
        The grid's CRS: written as the OGC WKT VLR (:meth:`GridCrs.las_wkt`) with the
        WKT bit set, in LAS 1.4 (an earlier ``version`` is raised to it: the WKT bit is
        1.4's). Without it, no CRS is recorded.
    """
    import laspy
    from laspy.vlrs.known import WktCoordinateSystemVlr

    if crs is not None and _version(version) < (1, 4):
        version = "1.4"
    header = laspy.LasHeader(point_format=point_format, version=version)
    for dim in extra:
        header.add_extra_dim(dim)
    header.offsets = np.asarray(offsets, dtype=float)
    header.scales = np.full(3, LAS_SCALE_M)
    if gps_standard:
        header.global_encoding.gps_time_type = laspy.header.GpsTimeType.STANDARD
    if wkt or crs is not None:
        header.global_encoding.wkt = True
    if crs is not None:
        header.vlrs.append(WktCoordinateSystemVlr(crs.las_wkt()))
    if created is not None:
        header.creation_date = created
    if system is not None:
        header.system_identifier = system
    header.generating_software = software
    return header


def _version(text: str) -> tuple[int, ...]:
    """``"1.4"`` -> ``(1, 4)``."""
    return tuple(int(part) for part in str(text).split("."))


def las_integers(
    coords: ArrayLike, offsets: ArrayLike, scales: ArrayLike = LAS_SCALE_M
) -> tuple[NDArray[np.int32], int]:
    """Coordinates as the integers LAS stores, and the row of the one farthest beyond
    their reach (``-1`` when every row fits).

    Parameters
    ----------
    coords : array_like, shape (n, k)
        Coordinates, metres (``k`` of the axes, from x).
    offsets, scales : array_like
        The header's offsets and scales of those axes.
    """
    shift = np.asarray(offsets, dtype=float)
    step = np.asarray(scales, dtype=float)
    counts = np.round((np.asarray(coords, dtype=float) - shift) / step)
    reach = np.max(np.abs(counts), axis=1) if counts.size else np.zeros(0)
    far = int(np.argmax(reach)) if np.any(reach > INT32_MAX) else -1
    if far >= 0:
        return np.zeros(counts.shape, dtype=np.int32), far
    return counts.astype(np.int32), -1


# --------------------------------------------------------------------------- writer


class LasWriter:
    """Stream point records into a LAS or LAZ file, whole or not at all.

    The file is written under a temporary name beside ``path`` and renamed onto it
    by :meth:`close` once laspy has finalised the header's counts and bounds; a
    block that ends with an error leaves no file (see :mod:`mast.io.atomic`).

    Parameters
    ----------
    path : str or Path
        The target (replaced if it exists). A ``.laz`` suffix compresses (lazrs).
    header : laspy.LasHeader
        The header (see :func:`new_las_header`); its point format makes the records.

    Raises
    ------
    OutputError
        The file cannot be written (at opening, writing or closing), naming ``path``.

    Examples
    --------
    >>> with LasWriter(out / "cloud.laz", header) as las:  # doctest: +SKIP
    ...     rec = las.zeros(len(xyz))
    ...     rec.X, rec.Y, rec.Z = las_integers(xyz, header.offsets)[0].T
    ...     las.write(rec)
    """

    def __init__(self, path: str | Path, header: laspy.LasHeader) -> None:
        import laspy

        self.path = Path(path)
        self.header = header
        self.count = 0
        self._closed = False
        self._tmp = part_path(self.path)
        discard(self._tmp)
        compress = self.path.suffix.lower() == ".laz"
        try:
            self._writer = laspy.open(self._tmp, mode="w", header=header, do_compress=compress)
        except OSError as exc:
            discard(self._tmp)
            raise self._failed(exc) from None
        except BaseException:  # laspy's own (no LAZ backend, a bad header): no file left
            discard(self._tmp)
            raise

    @property
    def writing(self) -> Path:
        """The temporary file being written; renamed onto :attr:`path` by :meth:`close`."""
        return self._tmp

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` or :meth:`abandon` has been called."""
        return self._closed

    def zeros(self, n: int) -> laspy.ScaleAwarePointRecord:
        """``n`` points of the header's format, every field zero."""
        import laspy

        return laspy.ScaleAwarePointRecord.zeros(n, header=self.header)

    def record(self, array: NDArray[Any]) -> laspy.ScaleAwarePointRecord:
        """A record over a structured array of the header's point format."""
        import laspy

        h = self.header
        return laspy.ScaleAwarePointRecord(array, h.point_format, h.scales, h.offsets)

    def write(self, record: laspy.ScaleAwarePointRecord) -> int:
        """Append ``record``'s points; the number written."""
        if self._closed:
            raise OutputError("already closed", path=self.path)
        try:
            self._writer.write_points(record)
        except OSError as exc:
            raise self._failed(exc) from None
        self.count += len(record)
        return len(record)

    def close(self) -> int:
        """Finalise the header, close the file and put it in place; the points written."""
        if not self._closed:
            self._closed = True
            try:
                self._writer.close()
            except OSError as exc:
                discard(self._tmp)
                raise self._failed(exc) from None
            except BaseException:
                discard(self._tmp)
                raise
            commit(self._tmp, self.path)
        return self.count

    def abandon(self) -> None:
        """Close and remove the unfinished file: no cloud rather than half of one."""
        self._closed = True
        with contextlib.suppress(Exception):
            self._writer.close()
        discard(self._tmp)

    def __enter__(self) -> LasWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abandon()

    def _failed(self, exc: OSError) -> OutputError:
        return OutputError(f"cannot write: {exc.strerror or exc}", path=self.path)
