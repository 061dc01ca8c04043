"""Planar poses in the mine grid, frame conversions and azimuth notation.

Conventions (DESIGN.md, "Frames and units"):

* mine frame: Easting ``E`` (x) and Northing ``N`` (y), metres, right-handed;
* azimuth: clockwise from grid north, radians inside the code;
* scanner frame: ROS REP 103, x forward, y left, beam angle ``phi``
  counter-clockwise from x;
* a beam of range ``r`` at angle ``phi`` from a scanner at ``(E0, N0)`` with
  azimuth ``A`` lands at ``E = E0 + r sin(A - phi)``, ``N = N0 + r cos(A - phi)``.

The scanner-to-mine rotation is proper, counter-clockwise by ``pi/2 - A``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.errors import InputError

__all__ = [
    "Pose2D",
    "format_ddd_mmss",
    "format_dms",
    "normalize_azimuth",
    "parse_azimuth",
    "wrap_angle",
    "wrap_angles",
]

TWO_PI = 2.0 * math.pi


def wrap_angle(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % TWO_PI - math.pi


def wrap_angles(angles_rad: NDArray[np.float64]) -> NDArray[np.float64]:
    """Wrap angles to [-pi, pi], element-wise (nearest multiple of 2 pi removed)."""
    return np.asarray(angles_rad - TWO_PI * np.round(angles_rad / TWO_PI))


def normalize_azimuth(azimuth_rad: float) -> float:
    """Wrap an azimuth to [0, 2 pi)."""
    a = azimuth_rad % TWO_PI
    return 0.0 if a >= TWO_PI else a


@dataclass(frozen=True, slots=True)
class Pose2D:
    """Scanner pose in the mine frame.

    Attributes
    ----------
    easting, northing : float
        Position of the scanner centre, metres.
    azimuth : float
        Azimuth of the scanner's +x axis, radians clockwise from grid north.
    """

    easting: float
    northing: float
    azimuth: float

    @classmethod
    def from_degrees(cls, easting: float, northing: float, azimuth_deg: float) -> Pose2D:
        return cls(float(easting), float(northing), math.radians(azimuth_deg))

    @property
    def azimuth_deg(self) -> float:
        """Azimuth in degrees, in [0, 360)."""
        d = math.degrees(normalize_azimuth(self.azimuth))
        return 0.0 if d >= 360.0 else d

    @property
    def position(self) -> NDArray[np.float64]:
        return np.array([self.easting, self.northing])

    def rotation(self) -> NDArray[np.float64]:
        """Rotation matrix taking scanner-frame vectors to mine-frame vectors."""
        s, c = math.sin(self.azimuth), math.cos(self.azimuth)
        # Counter-clockwise by (pi/2 - A): cos = sin A, sin = cos A.
        return np.array([[s, -c], [c, s]])

    def scanner_to_mine(self, points_scanner: ArrayLike) -> NDArray[np.float64]:
        """Map points ``(n, 2)`` in the scanner frame to ``(n, 2)`` (E, N)."""
        p = np.asarray(points_scanner, dtype=float)
        return p @ self.rotation().T + self.position

    def mine_to_scanner(self, points_mine: ArrayLike) -> NDArray[np.float64]:
        """Map points ``(n, 2)`` (E, N) to the scanner frame (x forward, y left)."""
        p = np.asarray(points_mine, dtype=float)
        return (p - self.position) @ self.rotation()

    def beam_to_mine(self, angle_rad: ArrayLike, range_m: ArrayLike) -> NDArray[np.float64]:
        """DESIGN.md's beam formula: ``E0 + r sin(A - phi)``, ``N0 + r cos(A - phi)``."""
        r = np.asarray(range_m, dtype=float)
        return self.position + r[..., None] * self.beam_directions(angle_rad)

    def beam_directions(self, angle_rad: ArrayLike) -> NDArray[np.float64]:
        """Unit mine-frame directions ``(sin(A - phi), cos(A - phi))`` of beams, shape (n, 2)."""
        bearing = self.azimuth - np.asarray(angle_rad, dtype=float)
        return np.stack([np.sin(bearing), np.cos(bearing)], axis=-1)

    def beam_angle_to(self, points_mine: ArrayLike) -> NDArray[np.float64]:
        """Beam angle ``phi`` (radians, in [-pi, pi)) under which mine points are seen."""
        q = self.mine_to_scanner(points_mine)
        return np.arctan2(q[..., 1], q[..., 0])

    def __str__(self) -> str:
        return f"E {self.easting:.4f} m, N {self.northing:.4f} m, Az {format_dms(self.azimuth_deg)}"


def _dms_parts(angle_deg: float, decimals: int, signed: bool) -> tuple[str, int, int, int]:
    """Sign, degrees, minutes and seconds times ``10**decimals`` of an angle, rounded
    once, the rounding carried into minutes and degrees (never 60")."""
    sign = ""
    if signed:
        if angle_deg < 0:
            sign = "-"
        value = abs(angle_deg)
    else:
        value = angle_deg % 360.0
    scale = 10**decimals
    tenths = round(value * 3600.0 * scale)
    if not signed:
        tenths %= 360 * 3600 * scale
    deg, rem = divmod(tenths, 3600 * scale)
    minutes, sec_scaled = divmod(rem, 60 * scale)
    return sign, deg, minutes, sec_scaled


def format_dms(angle_deg: float, *, decimals: int = 1, signed: bool = False) -> str:
    """Format degrees as ``D°MM'SS.S"``, carrying rounding into minutes and degrees.

    Azimuths (``signed=False``) are wrapped to [0, 360); ``signed=True`` keeps
    the sign, for differences and standard deviations.
    """
    if not math.isfinite(angle_deg):
        return str(angle_deg)
    sign, deg, minutes, sec_scaled = _dms_parts(angle_deg, decimals, signed)
    sec = sec_scaled / 10**decimals
    width = 3 + decimals if decimals else 2
    return f"{sign}{deg}°{minutes:02d}'{sec:0{width}.{decimals}f}\""


def format_ddd_mmss(angle_deg: float, *, decimals: int = 1) -> str:
    """An azimuth in the packed ``DDD.MMSSs`` form total stations and survey packages
    read (``309.53227`` is 309°53'22.7"), rounded as :func:`format_dms` rounds."""
    if not math.isfinite(angle_deg):
        return str(angle_deg)
    _, deg, minutes, sec_scaled = _dms_parts(angle_deg, decimals, False)
    return f"{deg}.{minutes:02d}{sec_scaled:0{2 + decimals}d}"


_DMS = re.compile(
    r"""^\s*(?P<sign>[-+])?\s*
    (?P<d>\d+(?:\.\d*)?)\s*(?:°|d|deg|\s)\s*
    (?:(?P<m>\d+(?:\.\d*)?)\s*(?:'|′|m|min|\s)\s*)?
    (?:(?P<s>\d+(?:\.\d*)?)\s*(?:"|″|s|sec|'')?\s*)?$""",
    re.VERBOSE,
)


def parse_azimuth(text: str) -> float:
    """Parse an azimuth or angle given as decimal degrees or D°M'S.S", into degrees.

    Accepted: ``"123.5"``, ``"123°30'00.0\\""``, ``"123 30 0"``, ``"123d30m0s"``.
    Minutes and seconds must be below 60.
    """
    s = text.strip()
    try:
        value = float(s)
    except ValueError:
        pass
    else:
        if not math.isfinite(value):
            raise InputError(f"angle {text!r} is not a finite number")
        return value
    m = _DMS.match(s)
    if m is None:
        raise InputError(f"angle {text!r} is neither decimal degrees nor D°M'S.S\"")
    d = float(m["d"])
    minutes = float(m["m"]) if m["m"] else 0.0
    seconds = float(m["s"]) if m["s"] else 0.0
    if minutes >= 60 or seconds >= 60:
        raise InputError(f"angle {text!r}: minutes and seconds must be below 60")
    value = d + minutes / 60.0 + seconds / 3600.0
    return -value if m["sign"] == "-" else value
