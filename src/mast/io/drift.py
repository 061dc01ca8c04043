"""The drift outline for planning: a CSV ``wall,vertex,easting,northing`` or a DXF.

DESIGN.md, "A drift outline": one polyline per ``wall`` id with its vertices in
order; or a DXF drawing with the walls as polylines.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from mast import limits
from mast.core.walls import Drift, Wall
from mast.errors import InputError, shorten
from mast.io._csv import CsvRows, parse_number, parse_within
from mast.limits import read_bounded

__all__ = ["MAX_COORDINATE_M", "read_drift"]

#: Coordinates beyond this are no mine grid (UTM northings stay under 10 000 km).
MAX_COORDINATE_M = limits.MAX_COORDINATE_M

#: DXF entities read as walls: 2D and 3D polylines and single lines (z is dropped).
_DXF_WALL_TYPES = ("LWPOLYLINE", "POLYLINE", "LINE")


def read_drift(path: str | Path, *, layers: tuple[str, ...] = ()) -> Drift:
    """Read a drift outline from a CSV (``.csv``) or a DXF (``.dxf``) file.

    Parameters
    ----------
    path : str or Path
    layers : tuple of str
        DXF only: read the walls from these layers (names matched without
        regard to case); every layer when empty.

    Raises
    ------
    InputError
        Naming the file, the line (CSV) or the entity (DXF), and the problem.
    """
    p = Path(path)
    drift = _read_dxf(p, layers) if p.suffix.lower() == ".dxf" else _read_csv(p)
    if drift.length_m > limits.MAX_WALL_LENGTH_M:
        raise InputError(
            f"walls {drift.length_m / 1000:.0f} km long in all, more than the "
            f"{limits.MAX_WALL_LENGTH_M / 1000:g} km MAST plans at once "
            "(mast.limits.MAX_WALL_LENGTH_M): a coordinate out of place, or a drawing to split",
            path=p,
        )
    return drift


def _read_csv(path: Path) -> Drift:
    rows = CsvRows(path, required=("wall", "vertex", "easting", "northing"))
    walls: dict[str, dict[int, tuple[float, float, int]]] = {}
    for line, f in rows:
        wid = f["wall"].strip()
        if not wid:
            raise InputError("column 'wall' is empty", path=path, line=line)
        v = parse_number(f["vertex"], column="vertex", path=path, line=line)
        if v != int(v):
            raise InputError(
                f"column 'vertex': {f['vertex'].strip()[:40]!r} is not a whole number",
                path=path,
                line=line,
            )
        east = parse_within(f["easting"], column="easting", path=path, line=line)
        north = parse_within(f["northing"], column="northing", path=path, line=line)
        got = walls.setdefault(wid, {})
        if int(v) in got:
            raise InputError(
                f"wall {wid[:40]!r} vertex {int(v)} given twice (first on line {got[int(v)][2]})",
                path=path,
                line=line,
            )
        got[int(v)] = (east, north, line)
    if not walls:
        raise InputError("no wall rows after the header", path=path, line=rows.header_line)
    out = []
    for wid, got in walls.items():
        order = sorted(got)
        xy = np.array([[got[k][0], got[k][1]] for k in order])
        lines = [got[k][2] for k in order]
        out.append(_wall(wid, xy, path, lines))
    return Drift(tuple(out), source=str(path))


def _wall(wid: str, xy: np.ndarray, path: Path, lines: list[int] | None) -> Wall:
    """A wall from its vertices, consecutive repeats dropped; fewer than two left is an error."""
    where = (lambda k: lines[k]) if lines is not None else (lambda k: None)
    if len(xy) < 2:
        raise InputError(
            f"wall {wid[:40]!r} has one vertex; a wall needs two or more", path=path, line=where(0)
        )
    step = np.hypot(*np.diff(xy, axis=0).T)
    keep = np.concatenate([[True], step > 1e-6])
    if keep.sum() < 2:
        raise InputError(
            f"wall {wid[:40]!r}: all its vertices coincide", path=path, line=where(len(xy) - 1)
        )
    return Wall(wid, xy[keep])


def _read_dxf(path: Path, layers: tuple[str, ...]) -> Drift:
    from ezdxf import recover
    from ezdxf.lldxf.const import DXFStructureError

    # Bounded like every text input (a drawing is text; binary DXF is not read).
    data = read_bounded(path, what="DXF drawing", text=False)
    try:
        doc, auditor = recover.read(io.BytesIO(data))
    except DXFStructureError as err:
        raise InputError(f"not a readable DXF drawing: {shorten(str(err))}", path=path) from None
    except Exception as err:  # ezdxf on hostile bytes: anything its parser or audit raises
        raise InputError(
            f"not a readable DXF drawing ({type(err).__name__}: {shorten(str(err))})", path=path
        ) from None
    if auditor.has_errors:
        raise InputError(
            f"DXF drawing damaged beyond recovery ({len(auditor.errors)} error(s))", path=path
        )
    wanted = {name.casefold() for name in layers}
    out: list[Wall] = []
    seen_layers: set[str] = set()
    from ezdxf.lldxf.const import DXFError

    try:
        for entity in doc.modelspace():
            kind = entity.dxftype()
            if kind not in _DXF_WALL_TYPES:
                continue
            layer = str(entity.dxf.layer)
            seen_layers.add(layer)
            if wanted and layer.casefold() not in wanted:
                continue
            if kind == "LINE":
                pts = [entity.dxf.start, entity.dxf.end]
                closed = False
            elif kind == "LWPOLYLINE":
                pts = [(x, y) for x, y, *_ in entity.get_points("xy")]  # type: ignore[attr-defined]
                closed = bool(entity.closed)  # type: ignore[attr-defined]
            else:
                pts = [v.dxf.location for v in entity.vertices]  # type: ignore[attr-defined]
                closed = bool(entity.is_closed)  # type: ignore[attr-defined]
            xy = np.array([[float(q[0]), float(q[1])] for q in pts], dtype=float).reshape(-1, 2)
            handle = entity.dxf.handle
            wid = f"{layer}:{handle}"
            if closed and len(xy) >= 2:
                xy = np.vstack([xy, xy[:1]])
            if not np.all(np.isfinite(xy)) or (xy.size and np.abs(xy).max() > MAX_COORDINATE_M):
                raise InputError(
                    f"{kind} {handle} on layer {layer!r}: a vertex is not a plausible coordinate",
                    path=path,
                )
            if len(xy) < 2:
                continue
            out.append(_wall(wid, xy, path, None))
    except (AttributeError, KeyError, ValueError, TypeError, IndexError, DXFError) as err:
        # The recovery reader let through a structure its own entities cannot read.
        # (InputError, raised above for implausible vertices, is none of these.)
        raise InputError(
            f"DXF drawing damaged beyond recovery ({type(err).__name__}: {shorten(str(err))})",
            path=path,
        ) from None
    if not out:
        if wanted:
            found = ", ".join(sorted(seen_layers)) or "none"
            raise InputError(
                f"no wall polylines on layer(s) {', '.join(layers)}; "
                f"layers with polylines: {found}",
                path=path,
            )
        raise InputError("no LWPOLYLINE, POLYLINE or LINE entities to read as walls", path=path)
    return Drift(tuple(out), source=str(path))
