"""The coordinate reference system of the mine grid, as ``--crs`` gives it.

MAST computes in a metric, right-handed grid (easting, northing in metres): a projected
CRS (a UTM zone, a national grid) or a mine's own local grid. :func:`parse_crs` reads
what a user gives (an EPSG code, a WKT file, a WKT or PROJ string, or ``local:NAME``),
checks it with pyproj and keeps it as :class:`GridCrs`, plain text that every output
writes its own way: the JSON records and ``transform.json`` (:meth:`GridCrs.record`),
LAS/LAZ (:meth:`GridCrs.las_wkt`, the OGC WKT VLR), GeoJSON
(:meth:`GridCrs.geojson_member`) and the reports (:meth:`GridCrs.line`).

A local grid stays a local grid: ``local:NAME`` is an engineering CRS of that name
(WKT2 ``ENGCRS``, metres, east and north axes), never a geographic one. A CRS in
degrees (geographic), geocentric or vertical only, in feet, or with axes that do not
point east and north is refused: MAST's coordinates are metres east and north.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from mast.errors import InputError, quoted

if TYPE_CHECKING:
    import pyproj

__all__ = ["LOCAL_PREFIX", "GridCrs", "local_grid", "parse_crs"]

#: ``--crs local:NAME`` names a local (engineering) grid.
LOCAL_PREFIX: Final = "local:"
#: The longest name a local grid may have (a WKT name is free text; a report line is not).
MAX_NAME_CHARS: Final = 80
#: File suffixes read as a WKT file even when the file is missing (then: no such file).
WKT_SUFFIXES: Final = frozenset({".wkt", ".prj", ".txt"})

_EPSG = re.compile(r"^(?:EPSG:)?(\d{4,6})$", re.IGNORECASE)


@dataclass(frozen=True, slots=True)
class GridCrs:
    """A checked CRS of the mine grid, as text (picklable, no pyproj object inside).

    Attributes
    ----------
    name : str
        The CRS's own name (``WGS 84 / UTM zone 35S``, ``Mine Grid A``).
    wkt : str
        Its WKT2 (ISO 19162:2019), the form written into JSON.
    epsg : int or None
        Its EPSG code, where it is exactly an EPSG entry.
    horizontal_epsg : int or None
        The EPSG code of its horizontal part (that of a compound CRS's projected
        component; ``epsg`` otherwise).
    local : bool
        An engineering (local) grid, not tied to the Earth.
    """

    name: str
    wkt: str
    epsg: int | None = None
    horizontal_epsg: int | None = None
    local: bool = False

    def pyproj(self) -> pyproj.CRS:
        """The CRS as a pyproj object."""
        from pyproj import CRS

        return CRS.from_wkt(self.wkt)

    def record(self) -> dict[str, Any]:
        """The ``crs`` object of the JSON outputs: ``name``, ``wkt`` and, with one,
        ``epsg``."""
        rec: dict[str, Any] = {"name": self.name, "wkt": self.wkt}
        if self.epsg is not None:
            rec["epsg"] = self.epsg
        return rec

    def brief(self) -> dict[str, Any]:
        """The ``crs`` object of a record written once a scan (a run's JSON Lines, the
        live topics): ``name`` and ``epsg`` where the EPSG code names it whole, else
        ``name`` and ``wkt``; 1.5 kB of UTM WKT on each of 100 000 records says nothing
        its code does not."""
        if self.epsg is not None:
            return {"name": self.name, "epsg": self.epsg}
        return {"name": self.name, "wkt": self.wkt}

    def line(self) -> str:
        """One line for a report: ``WGS 84 / UTM zone 35S (EPSG:32735)``, or
        ``Mine Grid A (local grid)``."""
        if self.epsg is not None:
            return f"{self.name} (EPSG:{self.epsg})"
        return f"{self.name} (local grid)" if self.local else self.name

    def las_wkt(self) -> str:
        """The WKT for a LAS 1.4 OGC WKT VLR: WKT1 (OGC 01-009, which LAS 1.4 cites) as
        GDAL writes it, or WKT2 when the CRS has no WKT1 form."""
        crs = self.pyproj()
        try:
            text = crs.to_wkt("WKT1_GDAL")
        except Exception:  # pyproj raises its own for a CRS WKT1 cannot hold
            text = None
        return text or self.wkt

    def geojson_member(self) -> dict[str, Any]:
        """The (2008, pre-RFC 7946) ``crs`` member of a GeoJSON object: an OGC URN for an
        EPSG CRS, else the CRS's name; GDAL and QGIS still read it."""
        name = self.name
        if self.horizontal_epsg is not None:
            name = f"urn:ogc:def:crs:EPSG::{self.horizontal_epsg}"
        return {"type": "name", "properties": {"name": name}}


def local_grid(name: str, *, option: str = "--crs") -> GridCrs:
    """A local mine grid: an engineering CRS named ``name``, easting and northing in
    metres (WKT2 ``ENGCRS`` with an engineering datum of the same name)."""
    clean = name.strip()
    if not clean:
        raise InputError(f"{option} {LOCAL_PREFIX}: a local grid needs a name ({LOCAL_PREFIX}NAME)")
    if len(clean) > MAX_NAME_CHARS or not clean.isprintable() or '"' in clean:
        raise InputError(
            f"{option} {quoted(LOCAL_PREFIX + name)}: a local grid's name is at most "
            f'{MAX_NAME_CHARS} printable characters without a double quote (")'
        )
    wkt = (
        f'ENGCRS["{clean}",EDATUM["{clean}"],CS[Cartesian,2],'
        'AXIS["easting (E)",east,ORDER[1],LENGTHUNIT["metre",1]],'
        'AXIS["northing (N)",north,ORDER[2],LENGTHUNIT["metre",1]]]'
    )
    return _checked(wkt, given=LOCAL_PREFIX + clean, option=option)


def parse_crs(text: str, *, option: str = "--crs") -> GridCrs:
    """The CRS ``text`` gives, checked to be a metric grid with east and north axes.

    Parameters
    ----------
    text : str
        ``EPSG:32735`` or ``32735``; ``local:NAME`` (a local grid,
        :func:`local_grid`); the path of a file holding WKT (a ``.prj`` too); or
        anything pyproj's ``CRS.from_user_input`` takes (WKT, a PROJ string,
        ``ESRI:102022``).
    option : str
        The option's name, for the error.

    Raises
    ------
    InputError
        One line: pyproj does not know the CRS, or it is not a metric grid whose
        axes point east and north.
    """
    given = text.strip()
    if given.lower().startswith(LOCAL_PREFIX):
        return local_grid(given[len(LOCAL_PREFIX) :], option=option)
    if not given:
        raise InputError(f"{option}: empty; give an EPSG code, a WKT file or {LOCAL_PREFIX}NAME")
    code = _EPSG.match(given)
    source = f"EPSG:{code[1]}" if code else given
    path = Path(given)
    looks_like_file = "[" not in given and "+proj" not in given and not code
    if looks_like_file and (path.exists() or path.suffix.lower() in WKT_SUFFIXES):
        from mast.limits import MAX_CRS_BYTES, read_bounded

        try:
            data = read_bounded(path, limit=MAX_CRS_BYTES, what="WKT file", name="MAX_CRS_BYTES")
        except InputError as err:
            raise InputError(f"{option}: {err.problem}", path=path, line=err.line) from None
        try:
            source = data.decode("utf-8-sig").strip()
        except UnicodeDecodeError:
            raise InputError("not UTF-8 text: a WKT file is text", path=path) from None
        return _checked(source, given=given, option=option, path=path)
    return _checked(source, given=given, option=option)


def _checked(source: str, *, given: str, option: str, path: Path | None = None) -> GridCrs:
    """``source`` through pyproj, refused unless it is a metric east-north grid."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    def bad(problem: str) -> InputError:
        if path is not None:
            return InputError(f"{option}: {problem}", path=path)
        return InputError(f"{option} {quoted(given)}: {problem}")

    try:
        crs = CRS.from_user_input(source)
    except CRSError as err:
        detail = str(err).rsplit("proj_create: ", 1)[-1].rstrip(")").strip()
        raise bad(f"not a coordinate reference system pyproj knows ({detail})") from None
    horizontal = _horizontal(crs)
    if horizontal is None or not (horizontal.is_projected or horizontal.is_engineering):
        kind = crs.type_name.lower().removesuffix(" crs")
        kind = "geographic (degrees)" if crs.is_geographic else kind
        raise bad(
            f"{crs.name} is a {kind} CRS; MAST's grid is metres east and north: give a "
            f"projected CRS (a UTM zone, a national grid) or {LOCAL_PREFIX}NAME"
        )
    axes = horizontal.axis_info[:2]
    if len(axes) < 2 or any(a.unit_name not in ("metre", "meter") for a in axes):
        units = ", ".join(sorted({a.unit_name for a in axes})) or "none"
        raise bad(f"{crs.name} is in {units}; MAST's grid coordinates are metres")
    directions = sorted(a.direction.lower() for a in axes)
    if directions != ["east", "north"]:
        raise bad(
            f"{crs.name} has axes pointing {' and '.join(a.direction for a in axes)}; "
            "MAST's grid is easting and northing (east, north)"
        )
    epsg = crs.to_epsg(min_confidence=100)
    return GridCrs(
        name=crs.name,
        wkt=crs.to_wkt(),
        epsg=epsg,
        horizontal_epsg=horizontal.to_epsg(min_confidence=100) if epsg is None else epsg,
        local=bool(horizontal.is_engineering),
    )


def _horizontal(crs: pyproj.CRS) -> pyproj.CRS | None:
    """The horizontal part: a bound CRS's source, a compound CRS's first component."""
    if crs.is_bound and crs.source_crs is not None:
        crs = crs.source_crs
    if crs.is_compound:
        parts = crs.sub_crs_list
        return _horizontal(parts[0]) if parts else None
    return crs
