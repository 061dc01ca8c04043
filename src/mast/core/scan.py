"""One horizontal 2D laser scan, with ``sensor_msgs/LaserScan`` semantics."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast import limits
from mast.errors import InputError

__all__ = ["Scan", "split_stamp", "stamp_of"]

#: Nanoseconds in a second: a stamp's (sec, nanosec) as ROS messages carry it.
NS_PER_S = 1_000_000_000


def split_stamp(stamp_ns: int) -> tuple[int, int]:
    """A stamp in integer nanoseconds as ROS's ``(sec, nanosec)``."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return sec, nanosec


def stamp_of(sec: int, nanosec: int) -> int:
    """ROS's ``(sec, nanosec)`` as one stamp in integer nanoseconds."""
    return int(sec) * NS_PER_S + int(nanosec)


def _frozen(a: ArrayLike) -> NDArray[np.float64]:
    arr: NDArray[np.float64] = np.array(a, dtype=np.float64, copy=True).reshape(-1)
    arr.setflags(write=False)
    return arr


#: A median range beyond this is not a scan in metres (millimetres, most likely).
MAX_PLAUSIBLE_RANGE_M = 1000.0
#: When no return lies within the scanner's limits and their median is this many times
#: the longest valid range, the ranges are in another unit (millimetres), not "no echo"
#: (which drivers report just beyond the limit).
UNIT_MISTAKE_RATIO = 20.0


@dataclass(frozen=True, eq=False)
class Scan:
    """A single scan in the scanner frame (REP 103: x forward, y left).

    Attributes
    ----------
    angles_rad : ndarray, shape (n,)
        Beam angles, counter-clockwise from +x, strictly increasing.
    ranges_m : ndarray, shape (n,)
        Measured ranges; ``nan``, ``inf``, ``0`` or a value outside
        ``[range_min_m, range_max_m]`` means no return.
    intensities : ndarray, shape (n,), optional
    range_min_m, range_max_m : float
        The scanner's stated range limits.
    stamp_ns : int
        Time stamp, nanoseconds.
    frame_id : str
    """

    angles_rad: NDArray[np.float64]
    ranges_m: NDArray[np.float64]
    intensities: NDArray[np.float64] | None = None
    range_min_m: float = 0.0
    range_max_m: float = math.inf
    stamp_ns: int = 0
    frame_id: str = "laser"
    _valid: NDArray[np.bool_] = field(init=False, repr=False)
    _points: tuple[NDArray[np.intp], NDArray[np.float64]] | None = field(
        init=False, repr=False, default=None
    )

    def __post_init__(self) -> None:
        angles = _frozen(self.angles_rad)
        ranges = _frozen(self.ranges_m)
        object.__setattr__(self, "angles_rad", angles)
        object.__setattr__(self, "ranges_m", ranges)
        if angles.shape != ranges.shape:
            raise InputError(
                f"scan has {angles.size} angles but {ranges.size} ranges; they must match"
            )
        if angles.size > limits.MAX_BEAMS:
            raise InputError(
                f"scan has {angles.size} beams, more than the {limits.MAX_BEAMS} MAST takes "
                "(mast.limits.MAX_BEAMS)"
            )
        if self.intensities is not None:
            inten: NDArray[np.float64] | None = _frozen(self.intensities)
            if inten is not None and inten.size == 0:
                inten = None
            elif inten is not None and inten.shape != ranges.shape:
                raise InputError(
                    f"scan has {inten.size} intensities for {ranges.size} ranges; they must match"
                )
            object.__setattr__(self, "intensities", inten)
        if not np.all(np.isfinite(angles)):
            raise InputError("scan has a beam angle that is not a finite number")
        span = float(angles[-1] - angles[0]) if angles.size > 1 else 0.0
        if span > 2 * math.pi + 1e-6:
            raise InputError(
                f"scan angles span {span:.6g} rad ({span / (2 * math.pi):.1f} turns), more "
                "than a full turn: they look like degrees; angles must be in radians "
                "(degrees x pi/180)"
            )
        if angles.size > 1 and not np.all(np.diff(angles) > 0):
            i = int(np.argmin(np.diff(angles) > 0))
            raise InputError(
                f"scan angles must strictly increase, but beam {i + 1} "
                f"({angles[i + 1]!r} rad) follows {angles[i]!r} rad"
            )
        rmin, rmax = float(self.range_min_m), float(self.range_max_m)
        if math.isnan(rmin) or math.isnan(rmax) or rmin < 0 or rmax <= rmin:
            raise InputError(f"scan range limits [{rmin}, {rmax}] m are not a valid interval")
        object.__setattr__(self, "range_min_m", rmin)
        object.__setattr__(self, "range_max_m", rmax)
        with np.errstate(invalid="ignore"):
            returned = np.isfinite(ranges) & (ranges > 0)
            valid = returned & (ranges >= rmin) & (ranges <= rmax)
        with np.errstate(over="ignore"):  # two ranges near 1e308 average to inf: refused
            median = float(np.median(ranges[returned])) if returned.any() else 0.0
        if median > MAX_PLAUSIBLE_RANGE_M:
            raise InputError(
                f"scan's median range is {median:.6g} m, beyond any laser "
                f"scanner underground (> {MAX_PLAUSIBLE_RANGE_M:g} m): the ranges look like "
                "millimetres; ranges must be in metres (millimetres / 1000)"
            )
        if returned.any() and not valid.any() and median > UNIT_MISTAKE_RATIO * rmax:
            raise InputError(
                f"no range lies within the scanner's limits {rmin:g} to {rmax:g} m and their "
                f"median is {median:.6g}: the ranges look like millimetres; ranges must be "
                "in metres (millimetres / 1000)"
            )
        valid.setflags(write=False)
        object.__setattr__(self, "_valid", valid)

    @classmethod
    def from_laserscan(
        cls,
        *,
        angle_min: float,
        angle_increment: float,
        ranges: ArrayLike,
        range_min: float = 0.0,
        range_max: float = math.inf,
        intensities: ArrayLike | None = None,
        stamp_ns: int = 0,
        frame_id: str = "laser",
    ) -> Scan:
        """Build a scan from the fields of a ``sensor_msgs/LaserScan`` message."""
        r: NDArray[np.float64] = np.asarray(ranges, dtype=np.float64).reshape(-1)
        if not (math.isfinite(angle_min) and math.isfinite(angle_increment)):
            raise InputError("LaserScan angle_min and angle_increment must be finite")
        if angle_increment == 0 and r.size > 1:
            raise InputError("LaserScan angle_increment is 0: every beam at the same angle")
        angles = np.asarray(angle_min + angle_increment * np.arange(r.size), dtype=np.float64)
        inten = None if intensities is None else np.asarray(intensities, dtype=np.float64)
        if angle_increment < 0:
            # Legal in ROS (a scanner mounted upside down sweeps clockwise): the same
            # beams, listed in increasing angle order.
            angles, r = angles[::-1], r[::-1]
            inten = None if inten is None else inten[::-1]
        return cls(angles, r, inten, range_min, range_max, stamp_ns, frame_id)

    @classmethod
    def from_message(cls, msg: Any) -> Scan:
        """Build a scan from a ``sensor_msgs/LaserScan`` message of any binding (a bag's,
        a DDS sample's): its fields checked as a damaged message needs."""
        stamp = msg.header.stamp
        n = len(msg.ranges)
        a0, a1, inc = float(msg.angle_min), float(msg.angle_max), float(msg.angle_increment)
        # angle_max is redundant: where it disagrees with angle_min + (n - 1) * increment by
        # more than one increment (drivers differ by that much), a field is damaged, and
        # every beam's angle would be wrong (a rotated scan fixes a rotated pose).
        if n > 1 and all(map(math.isfinite, (a0, a1, inc))):
            off = a0 + (n - 1) * inc - a1
            if abs(off) > 1.01 * abs(inc) + 1e-5:
                raise InputError(
                    f"angle_min {a0:.9g} + {n - 1} x angle_increment {inc:.9g} misses "
                    f"angle_max {a1:.9g} by {off:.3g} rad; the message is damaged"
                )
        return cls.from_laserscan(
            angle_min=a0,
            angle_increment=inc,
            ranges=np.asarray(msg.ranges, dtype=float),
            range_min=float(msg.range_min) if math.isfinite(msg.range_min) else 0.0,
            range_max=float(msg.range_max) if msg.range_max > msg.range_min else math.inf,
            intensities=np.asarray(msg.intensities, dtype=float),
            stamp_ns=stamp_of(stamp.sec, stamp.nanosec),
            frame_id=str(msg.header.frame_id),
        )

    def message_fields(self) -> dict[str, Any]:
        """The scan as the fields of a ``sensor_msgs/LaserScan`` (float32 arrays, as a
        driver sends them; ``stamp`` as (sec, nanosec)); its beams must be evenly spaced."""
        if not self.is_uniform:
            raise InputError("beams are not evenly spaced; a LaserScan needs that")
        inten = self.intensities
        return {
            "stamp": split_stamp(self.stamp_ns),
            "frame_id": self.frame_id,
            "angle_min": float(self.angles_rad[0]),
            "angle_max": float(self.angles_rad[-1]),
            "angle_increment": float(self.angle_increment if len(self) > 1 else 0.0),
            "time_increment": 0.0,
            "scan_time": 0.0,
            "range_min": float(self.range_min_m),
            "range_max": float(self.range_max_m),
            "ranges": np.asarray(self.ranges_m, dtype=np.float32),
            "intensities": np.zeros(0, np.float32) if inten is None else inten.astype(np.float32),
        }

    def __len__(self) -> int:
        return int(self.ranges_m.size)

    def with_range_limits(self, range_min_m: float | None, range_max_m: float | None) -> Scan:
        """The same beams with other range limits (None keeps the scan's own)."""
        if range_min_m is None and range_max_m is None:
            return self
        return Scan(
            self.angles_rad,
            self.ranges_m,
            self.intensities,
            self.range_min_m if range_min_m is None else range_min_m,
            self.range_max_m if range_max_m is None else range_max_m,
            self.stamp_ns,
            self.frame_id,
        )

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Mask of beams with a usable return."""
        return self._valid

    @property
    def angle_increment(self) -> float:
        """Median spacing between beams, radians (nan for fewer than two beams)."""
        if self.angles_rad.size < 2:
            return math.nan
        return float(np.median(np.diff(self.angles_rad)))

    @property
    def is_uniform(self) -> bool:
        """True when beams are evenly spaced (as a LaserScan message requires)."""
        if self.angles_rad.size < 3:
            return True
        d = np.diff(self.angles_rad)
        return bool(np.ptp(d) <= 1e-9 * max(1.0, abs(float(np.mean(d)))) + 1e-12)

    def points(self) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """Valid returns as points in the scanner frame.

        Returns
        -------
        index : ndarray of int, shape (m,)
            Beam indices of the valid returns.
        points_scanner : ndarray, shape (m, 2)
            ``x = r cos(phi)``, ``y = r sin(phi)``, metres.

        Both are read-only and computed once per scan (every stage reads them).
        """
        if self._points is None:
            idx = np.flatnonzero(self._valid)
            r = self.ranges_m[idx]
            a = self.angles_rad[idx]
            pts = np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)
            idx.setflags(write=False)
            pts.setflags(write=False)
            object.__setattr__(self, "_points", (idx, pts))
        assert self._points is not None
        return self._points
