"""GeoJSON of grid coordinates, for GIS: a FeatureCollection written feature by feature.

RFC 7946 GeoJSON is in WGS 84 longitude and latitude; MAST's coordinates are the mine
grid's, easting and northing in metres, and are written as they are (x = easting,
y = northing, to 0.1 mm), never reprojected. A grid named by ``--crs`` is stated with
the 2008 GeoJSON ``crs`` member that GDAL and QGIS still read
(:meth:`mast.io.crs.GridCrs.geojson_member`: an OGC URN for an EPSG CRS, a local grid's
name otherwise); without ``--crs`` there is none, and a GIS must be told the grid.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import IO, Any, Final

import numpy as np
from numpy.typing import ArrayLike

from mast.io.crs import GridCrs

__all__ = ["COORDINATE_DECIMALS", "FeatureCollectionWriter", "line_string", "point"]

#: Decimals of a coordinate in metres: 0.1 mm, as in the LAS map.
COORDINATE_DECIMALS: Final = 4


def _position(easting: float, northing: float) -> list[float]:
    if not (math.isfinite(easting) and math.isfinite(northing)):
        raise ValueError(f"position ({easting}, {northing}) is not finite")
    return [round(float(easting), COORDINATE_DECIMALS), round(float(northing), COORDINATE_DECIMALS)]


def point(easting: float, northing: float) -> dict[str, Any]:
    """A Point geometry at a grid position (metres); ValueError when not finite."""
    return {"type": "Point", "coordinates": _position(easting, northing)}


def line_string(positions: ArrayLike) -> dict[str, Any]:
    """A LineString geometry through ``positions`` (shape (n, 2), easting and northing,
    metres); ValueError when fewer than two or one is not finite."""
    xy = np.asarray(positions, dtype=float).reshape(-1, 2)
    if len(xy) < 2:
        raise ValueError(f"a LineString needs at least two positions, got {len(xy)}")
    return {"type": "LineString", "coordinates": [_position(e, n) for e, n in xy]}


class FeatureCollectionWriter:
    """One FeatureCollection written into an open text file, one feature at a time
    (memory does not grow with the features); :meth:`close` ends it.

    Parameters
    ----------
    fh : text file
        Open for writing (``mast.io.atomic.atomic_open``: whole or not at all).
    crs : GridCrs, optional
        The grid's CRS: the collection's ``crs`` member.
    name : str, optional
        The collection's ``name`` member (GDAL names the layer after it).
    """

    def __init__(self, fh: IO[str], *, crs: GridCrs | None = None, name: str | None = None):
        self._fh = fh
        self.count = 0
        head: dict[str, Any] = {"type": "FeatureCollection"}
        if name is not None:
            head["name"] = name
        if crs is not None:
            head["crs"] = crs.geojson_member()
        text = json.dumps(head)
        fh.write(text[:-1] + ', "features": [')

    def add(self, geometry: Mapping[str, Any], properties: Mapping[str, Any]) -> None:
        """Append a Feature (``properties`` must be JSON: no NaN, say None)."""
        feature = {"type": "Feature", "geometry": geometry, "properties": dict(properties)}
        self._fh.write(
            ("\n" if self.count == 0 else ",\n")
            + json.dumps(feature, allow_nan=False, ensure_ascii=False)
        )
        self.count += 1

    def close(self) -> int:
        """End the collection; the features written."""
        self._fh.write("\n]}\n")
        return self.count
