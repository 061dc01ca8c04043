"""A point list survey packages import: one row per point, name, easting, northing,
elevation, the azimuth in D°M'S.S" and the standard deviations.

The columns (:data:`POINT_LIST_COLUMNS`, with a header row, comma separated, UTF-8):
``name``, ``easting``, ``northing`` and ``elevation`` in metres (elevation empty: a
2D fix has none), ``azimuth`` as ``123°04'05.6"`` (clockwise from grid north,
:func:`mast.core.pose.format_dms`; the field is quoted, its ``"`` doubled, as CSV
does), ``azimuth_ddd_mmss`` the same azimuth in the packed ``DDD.MMSSs`` form total
stations and survey packages read (``309.53227``; no quoting needed),
``sigma_easting_m`` and ``sigma_northing_m`` in metres and
``sigma_azimuth_arcsec`` in arc-seconds. A point-import template of a survey package
maps these columns (name, E, N, Z, and the rest as attributes).
"""

from __future__ import annotations

import csv
import math
from typing import IO, Final

from mast.core.pose import format_ddd_mmss, format_dms

__all__ = ["POINT_LIST_COLUMNS", "PointListWriter"]

#: The point list's header row.
POINT_LIST_COLUMNS: Final = (
    "name",
    "easting",
    "northing",
    "elevation",
    "azimuth",
    "azimuth_ddd_mmss",
    "sigma_easting_m",
    "sigma_northing_m",
    "sigma_azimuth_arcsec",
)


def _num(value: float | None, decimals: int) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{decimals}f}"


class PointListWriter:
    """Rows of a point list written into an open text file (``newline=""``), the header
    first."""

    def __init__(self, fh: IO[str]) -> None:
        self._csv = csv.writer(fh)
        self._csv.writerow(POINT_LIST_COLUMNS)
        self.count = 0

    def add(
        self,
        name: str,
        easting: float,
        northing: float,
        elevation: float | None,
        azimuth_deg: float,
        sigma_easting_m: float | None,
        sigma_northing_m: float | None,
        sigma_azimuth_deg: float | None,
    ) -> None:
        """One point: coordinates and sigmas in metres, the azimuth and its sigma in
        degrees (written as D°M'S.S" and arc-seconds)."""
        sigma_az = None if sigma_azimuth_deg is None else 3600.0 * sigma_azimuth_deg
        self._csv.writerow(
            [
                name,
                _num(easting, 4),
                _num(northing, 4),
                _num(elevation, 4),
                format_dms(azimuth_deg, decimals=1),
                format_ddd_mmss(azimuth_deg, decimals=1),
                _num(sigma_easting_m, 4),
                _num(sigma_northing_m, 4),
                _num(sigma_az, 1),
            ]
        )
        self.count += 1
