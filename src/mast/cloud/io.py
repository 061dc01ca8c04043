"""Point clouds in and out: LAS/LAZ (laspy with lazrs), E57 (pye57) and PLY (plyfile).

A cloud is read in chunks of coordinates (and the time of every point where
the file has one), so that a cloud larger than memory can be searched for
beacons; the georeferenced copy is written chunk by chunk as LAZ with every
original attribute kept.

* **LAS/LAZ** is streamed (``laspy.open(...).chunk_iterator``); the copy keeps the
  point format, every dimension (extra bytes included) and the non-CRS VLRs,
  with new scales and offsets for grid coordinates (the old CRS is dropped: it
  described the local frame; the grid's, given, is written instead, the copy then
  LAS 1.4 for its WKT VLR).
* **PLY** binary files are memory-mapped (plyfile), so they stream too; ASCII
  PLY is read whole.
* **E57** is read one scan at a time (pye57 has no partial reads), each scan
  placed by its own pose: one scan must fit in memory.

Times: ``gps_time`` of LAS, ``timeStamp`` of E57, ``time``, ``timestamp``,
``gps_time`` or ``t`` of PLY; any other name with ``time_field``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from mast.errors import InputError, OutputError
from mast.io.crs import GridCrs
from mast.io.las import LasWriter, las_integers, las_offsets, new_las_header

__all__ = [
    "CLOUD_SUFFIXES",
    "Chunk",
    "Cloud",
    "open_cloud",
]

#: The suffixes ``mast georef`` reads, lower case.
CLOUD_SUFFIXES = (".las", ".laz", ".e57", ".ply")

#: Point names PLY writers give a time.
_PLY_TIMES = ("gps_time", "time", "timestamp", "t")

Transform = Callable[[NDArray[np.float64], NDArray[np.float64] | None], NDArray[np.float64]]


@dataclass(frozen=True, slots=True)
class Chunk:
    """Coordinates ``(n, 3)`` of a run of points, and their times (``None`` without)."""

    xyz: NDArray[np.float64]
    time: NDArray[np.float64] | None


class Cloud:
    """A point cloud file opened for reading in chunks (see :func:`open_cloud`)."""

    path: Path
    count: int
    time_field: str | None

    def chunks(self, size: int = 2_000_000) -> Iterator[Chunk]:  # pragma: no cover - abstract
        raise NotImplementedError

    def write_georeferenced(
        self,
        out: Path,
        transform: Transform,
        origin: NDArray[np.float64],
        size: int = 2_000_000,
        *,
        crs: GridCrs | None = None,
    ) -> int:  # pragma: no cover - abstract
        """Write every point moved by ``transform`` (its attributes kept) as LAZ/LAS, with
        the grid's ``crs`` when given."""
        raise NotImplementedError

    def bad(self, problem: str) -> InputError:
        return InputError(problem, path=self.path)


def open_cloud(path: str | Path, *, time_field: str | None = None) -> Cloud:
    """Open a LAS, LAZ, E57 or PLY file; bad or unreadable files are :class:`InputError`."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise InputError(
            f"not a point cloud this tool reads (the suffix must be one of "
            f"{', '.join(CLOUD_SUFFIXES)})",
            path=p,
        )
    if not p.is_file():
        raise InputError("no such file", path=p)
    if suffix in (".las", ".laz"):
        return _LasCloud(p, time_field)
    if suffix == ".ply":
        return _PlyCloud(p, time_field)
    return _E57Cloud(p, time_field)


def _finite(cloud: Cloud, xyz: NDArray[np.float64], where: str) -> None:
    if not np.all(np.isfinite(xyz)):
        raise cloud.bad(f"{where}: a point with a coordinate that is not a finite number")


#: Grid coordinates are written at :data:`~mast.io.las.LAS_SCALE_M` (0.1 mm) from offsets
#: rounded to this (metres): seven digits of easting and northing fit comfortably in
#: the 32-bit integers.
GRID_OFFSET_STEP_M = 1000.0


def grid_header_offsets(origin: NDArray[np.float64]) -> NDArray[np.float64]:
    """LAS offsets for grid coordinates near ``origin``: rounded to
    :data:`GRID_OFFSET_STEP_M`, so the 32-bit integers at 0.1 mm hold ±214 km about
    them."""
    return las_offsets(origin, GRID_OFFSET_STEP_M)


class _LasCloud(Cloud):
    def __init__(self, path: Path, time_field: str | None) -> None:
        import laspy

        self.path = path
        try:
            with laspy.open(path) as reader:
                header = reader.header
                self.count = int(header.point_count)
                names = set(header.point_format.dimension_names)
        except Exception as err:  # laspy raises its own, numpy's and OSError alike
            raise InputError(f"cannot read as LAS/LAZ: {err}", path=path) from None
        if time_field is None:
            self.time_field = "gps_time" if "gps_time" in names else None
        elif time_field not in names:
            raise InputError(
                f"no point attribute {time_field!r} (it has {', '.join(sorted(names))})",
                path=path,
            )
        else:
            self.time_field = time_field

    def _xyz_time(self, pts: Any) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
        """Coordinates ``(n, 3)`` and times of a chunk laspy read."""
        xyz = np.column_stack([np.asarray(pts.x), np.asarray(pts.y), np.asarray(pts.z)])
        t = None if self.time_field is None else np.asarray(pts[self.time_field], dtype=float)
        return xyz.astype(float, copy=False), t

    def chunks(self, size: int = 2_000_000) -> Iterator[Chunk]:
        import laspy

        done = 0
        try:
            with laspy.open(self.path) as reader:
                for pts in reader.chunk_iterator(size):
                    xyz, t = self._xyz_time(pts)
                    _finite(self, xyz, f"point {done + 1}")
                    done += len(xyz)
                    yield Chunk(xyz, t)
        except InputError:
            raise
        except Exception as err:
            raise InputError(
                f"cannot read as LAS/LAZ after {done} points: {err}", path=self.path
            ) from None
        if done != self.count:
            raise InputError(
                f"the header promises {self.count} points, the file holds {done}", path=self.path
            )

    def write_georeferenced(
        self,
        out: Path,
        transform: Transform,
        origin: NDArray[np.float64],
        size: int = 2_000_000,
        *,
        crs: GridCrs | None = None,
    ) -> int:
        import laspy

        with laspy.open(self.path) as reader:
            old = reader.header
            header = new_las_header(
                offsets=grid_header_offsets(origin),
                software="mast georef",
                system="MAST georef",
                point_format=old.point_format,
                version=str(old.version),
                gps_standard=False,
                crs=crs,
            )
            header.global_encoding.gps_time_type = old.global_encoding.gps_time_type
            for vlr in old.vlrs:
                if _keeps(vlr):
                    header.vlrs.append(vlr)
            with LasWriter(out, header) as las:
                for pts in reader.chunk_iterator(size):
                    rec = las.record(pts.array.copy())
                    _set_xyz(rec, transform(*self._xyz_time(pts)), out)
                    las.write(rec)
                return las.count


def _keeps(vlr: Any) -> bool:
    """Whether a VLR still holds after the move: not the local frame's CRS."""
    user = str(getattr(vlr, "user_id", ""))
    record = int(getattr(vlr, "record_id", 0))
    if user == "LASF_Projection":
        return False
    # the extra-bytes description (LASF_Spec 4) is written again by laspy from the format
    return not ((user == "LASF_Spec" and record in (4, 100)) or record in (2111, 2112))


def _set_xyz(rec: Any, grid: NDArray[np.float64], out: Path) -> None:
    ints, far = las_integers(grid, rec.offsets, rec.scales)
    if far >= 0:
        raise OutputError("a grid coordinate is beyond what LAS can hold at 0.1 mm", path=out)
    rec.X, rec.Y, rec.Z = ints.T


class _ColumnCloud(Cloud):
    """A cloud read as named columns (PLY, E57): written to LAS point format 7 (with
    colour) or 6, the columns LAS has a place for in it, the others as extra bytes."""

    def _columns(self) -> Iterator[dict[str, NDArray[Any]]]:  # pragma: no cover - abstract
        raise NotImplementedError

    #: column name -> LAS dimension, where LAS has one
    _las_names: dict[str, str]

    def _slices(self, size: int) -> Iterator[tuple[dict[str, NDArray[Any]], int, int, Chunk]]:
        """Every run of at most ``size`` points: its columns, where it starts and ends in
        them, and its coordinates and times."""
        done = 0
        for cols in self._columns():
            n = len(cols["x"])
            for lo in range(0, n, size):
                hi = min(n, lo + size)
                xyz = np.column_stack([cols[k][lo:hi] for k in ("x", "y", "z")]).astype(float)
                _finite(self, xyz, f"point {done + lo + 1}")
                t = None if self.time_field is None else cols[self.time_field][lo:hi]
                yield cols, lo, hi, Chunk(xyz, None if t is None else np.asarray(t, dtype=float))
            done += n

    def chunks(self, size: int = 2_000_000) -> Iterator[Chunk]:
        for *_, chunk in self._slices(size):
            yield chunk

    def write_georeferenced(
        self,
        out: Path,
        transform: Transform,
        origin: NDArray[np.float64],
        size: int = 2_000_000,
        *,
        crs: GridCrs | None = None,
    ) -> int:
        las: LasWriter | None = None
        try:
            for cols, lo, hi, chunk in self._slices(size):
                if las is None:
                    las = LasWriter(out, self._header(cols, origin, crs))
                rec = las.zeros(hi - lo)
                _set_xyz(rec, transform(chunk.xyz, chunk.time), out)
                for name, values in cols.items():
                    if name in ("x", "y", "z"):
                        continue
                    dim = self._las_names.get(name, name)
                    rec[dim] = _fit_dtype(values[lo:hi], rec[dim].dtype)
                las.write(rec)
        except BaseException:
            if las is not None:
                las.abandon()
            raise
        return 0 if las is None else las.close()

    def _header(
        self, cols: dict[str, NDArray[Any]], origin: NDArray[np.float64], crs: GridCrs | None
    ) -> Any:
        import laspy

        colour = all(k in self._las_names for k in ("red", "green", "blue"))
        extra = [
            laspy.ExtraBytesParams(name=name, type=values.dtype)
            for name, values in cols.items()
            if name not in ("x", "y", "z") and name not in self._las_names
        ]
        return new_las_header(
            offsets=grid_header_offsets(origin),
            software="mast georef",
            system="MAST georef",
            point_format=7 if colour else 6,
            extra=extra,
            crs=crs,
        )


def _fit_dtype(values: NDArray[Any], dtype: np.dtype[Any]) -> NDArray[Any]:
    """Values in a LAS dimension's type: integers clipped to its range."""
    if np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        return np.clip(np.round(np.asarray(values, dtype=float)), info.min, info.max).astype(dtype)
    return np.asarray(values).astype(dtype)


class _PlyCloud(_ColumnCloud):
    def __init__(self, path: Path, time_field: str | None) -> None:
        from plyfile import PlyData

        self.path = path
        try:
            self._ply = PlyData.read(str(path), mmap="r")
        except Exception as err:
            raise InputError(f"cannot read as PLY: {err}", path=path) from None
        try:
            vertex = self._ply["vertex"]
        except KeyError:
            raise InputError("no 'vertex' element", path=path) from None
        names = [p.name for p in vertex.properties]
        missing = [k for k in ("x", "y", "z") if k not in names]
        if missing:
            raise InputError(f"the vertices have no {', '.join(missing)}", path=path)
        self.count = int(vertex.count)
        for prop in vertex.properties:
            if not hasattr(prop, "val_dtype"):
                raise InputError(f"vertex property {prop.name!r} is a list", path=path)
        self._names = names
        self._dtypes = {p.name: np.dtype(p.val_dtype) for p in vertex.properties}
        self.time_field = _pick_time(path, names, time_field, _PLY_TIMES)
        self._las_names = {"intensity": "intensity", "red": "red", "green": "green"}
        self._las_names |= {"blue": "blue"}
        if self.time_field is not None:
            self._las_names = {**self._las_names, self.time_field: "gps_time"}
        if not all(k in names for k in ("red", "green", "blue")):
            for k in ("red", "green", "blue"):
                self._las_names.pop(k, None)

    def _columns(self) -> Iterator[dict[str, NDArray[Any]]]:
        data = self._ply["vertex"].data
        cols: dict[str, NDArray[Any]] = {}
        for name in self._names:
            v = data[name]
            if name in ("red", "green", "blue") and self._dtypes[name] == np.uint8:
                v = np.asarray(v, dtype=np.uint16) * 257  # 8 bits to LAS's 16
            elif name == "intensity" and np.issubdtype(self._dtypes[name], np.floating):
                top = float(np.max(v)) if len(v) else 1.0
                v = np.asarray(v, dtype=float) * (65535.0 if top <= 1.0 else 1.0)
            elif name not in ("x", "y", "z") and name not in self._las_names:
                cols[_extra_name(name)] = v
                continue
            cols[name] = v
        yield cols


class _E57Cloud(_ColumnCloud):
    _FIELDS: ClassVar[dict[str, str]] = {
        "cartesianX": "x",
        "cartesianY": "y",
        "cartesianZ": "z",
        "intensity": "intensity",
        "colorRed": "red",
        "colorGreen": "green",
        "colorBlue": "blue",
    }

    def __init__(self, path: Path, time_field: str | None) -> None:
        import pye57

        self.path = path
        try:
            e57 = pye57.E57(str(path))
            self._scans = int(e57.scan_count)
            header = e57.get_header(0) if self._scans else None
            names = list(header.point_fields) if header is not None else []
            self.count = sum(int(e57.get_header(i).point_count) for i in range(self._scans))
            e57.close()
        except Exception as err:
            raise InputError(f"cannot read as E57: {err}", path=path) from None
        if self._scans == 0:
            raise InputError("holds no scan", path=path)
        if not all(k in names for k in ("cartesianX", "cartesianY", "cartesianZ")):
            raise InputError("its scans have no cartesian coordinates", path=path)
        self._names = [k for k in self._FIELDS if k in names]
        mapped = [self._FIELDS[k] for k in self._names]
        if time_field is not None:
            # pye57 reads no per-point time stamps (timeStamp is not among its fields)
            raise InputError(
                "E57 point times cannot be read (pye57 has no timeStamp); export the cloud "
                "as LAS/LAZ with gps_time for --time-field or --trajectory",
                path=path,
            )
        self.time_field = None
        self._las_names = {"intensity": "intensity"}
        if all(k in mapped for k in ("red", "green", "blue")):
            self._las_names |= {"red": "red", "green": "green", "blue": "blue"}
        if self.time_field is not None:
            self._las_names[self.time_field] = "gps_time"

    def _columns(self) -> Iterator[dict[str, NDArray[Any]]]:
        import pye57

        e57 = pye57.E57(str(self.path))
        try:
            for i in range(self._scans):
                try:
                    raw = e57.read_scan(
                        i,
                        intensity="intensity" in self._names,
                        colors="colorRed" in self._names,
                        transform=True,
                        ignore_missing_fields=True,
                    )
                except Exception as err:
                    raise InputError(f"cannot read scan {i}: {err}", path=self.path) from None
                cols = {self._FIELDS[k]: np.asarray(v) for k, v in raw.items() if k in self._FIELDS}
                if "red" in cols:  # E57 colours are 0-255: LAS keeps 16 bits
                    for k in ("red", "green", "blue"):
                        cols[k] = np.asarray(cols[k], dtype=np.uint16) * 257
                if "intensity" in cols:  # E57 intensity is 0..1 (or the limits): 16 bits
                    v = np.asarray(cols["intensity"], dtype=float)
                    top = float(v.max()) if v.size else 1.0
                    cols["intensity"] = v / (top if top > 1.0 else 1.0) * 65535.0
                yield cols
        finally:
            e57.close()


@functools.cache
def _las_dims() -> frozenset[str]:
    """LAS point format 7's own dimensions (laspy's list, and the x, y, z it reads them
    as): a PLY property of one of these names (not mapped to it) is kept as an extra
    dimension under another name."""
    import laspy

    return frozenset(laspy.PointFormat(7).dimension_names) | {"x", "y", "z"}


def _extra_name(name: str) -> str:
    """A PLY property's name as a LAS extra dimension: prefixed when LAS has the name
    already, cut to the 32 bytes an extra-bytes name may have."""
    out = f"ply_{name}" if name in _las_dims() else name
    return out[:32]


def _pick_time(
    path: Path, names: list[str], wanted: str | None, known: tuple[str, ...]
) -> str | None:
    if wanted is not None:
        if wanted not in names:
            raise InputError(
                f"no point attribute {wanted!r} (it has {', '.join(names)})", path=path
            )
        return wanted
    return next((k for k in known if k in names), None)
