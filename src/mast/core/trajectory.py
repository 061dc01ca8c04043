"""A trajectory in the mine grid: each scan placed (pose, covariance, whether a fix or
odometry placed it), and the placed scans of a run kept as columns. Written by ``mast
track`` (:mod:`mast.runs`), read and written as files by :mod:`mast.io.trajectory`."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, overload

import numpy as np
from numpy.typing import NDArray

from mast.core.pose import Pose2D

__all__ = ["PlacedScan", "ScannerPath", "Trajectory"]


@dataclass(frozen=True, slots=True)
class PlacedScan:
    """One scan placed in the mine grid.

    Attributes
    ----------
    scan : int
        Index of the LaserScan message on its topic, from 0.
    stamp_ns : int
        The message header's time stamp, nanoseconds since the Unix epoch.
    pose : Pose2D
        Smoothed pose (easting, northing, azimuth clockwise from grid north).
    covariance : ndarray, shape (3, 3)
        Marginal covariance of (easting [m], northing [m], azimuth [rad]).
    source : {"fix", "odometry"}
        ``fix`` when the scan itself was fixed from beacons, ``odometry`` when it
        was carried from fixes by scan-to-scan odometry.
    """

    scan: int
    stamp_ns: int
    pose: Pose2D
    covariance: NDArray[np.float64]
    source: Literal["fix", "odometry"]

    @property
    def sigma(self) -> NDArray[np.float64]:
        """Standard deviations of (easting [m], northing [m], azimuth [rad])."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))


_ROW = np.dtype(
    [
        ("scan", np.int64),
        ("stamp_ns", np.int64),
        ("pose", np.float64, (3,)),
        ("covariance", np.float64, (3, 3)),
        ("fix", np.bool_),
    ]
)


class Trajectory(Sequence[PlacedScan]):
    """Placed scans kept as columns: about 110 bytes a scan, not a Python object each.

    Appended in time order; indexing and iteration give :class:`PlacedScan`
    objects made on the fly, and :meth:`columns` the numbers as arrays (for
    the outputs that draw or write the whole run).
    """

    _BLOCK = 4096

    def __init__(self, placed: Sequence[PlacedScan] = ()) -> None:
        self._blocks: list[NDArray[np.void]] = []
        self._len = 0
        for p in placed:
            self.append(p)

    def append(self, p: PlacedScan) -> None:
        """Add the next placed scan."""
        k = self._len % self._BLOCK
        if k == 0:
            self._blocks.append(np.zeros(self._BLOCK, dtype=_ROW))
        row = self._blocks[-1][k]
        row["scan"], row["stamp_ns"], row["fix"] = p.scan, p.stamp_ns, p.source == "fix"
        row["pose"] = (p.pose.easting, p.pose.northing, p.pose.azimuth)
        row["covariance"] = p.covariance
        self._len += 1

    def __len__(self) -> int:
        return self._len

    @overload
    def __getitem__(self, i: int) -> PlacedScan: ...
    @overload
    def __getitem__(self, i: slice) -> list[PlacedScan]: ...
    def __getitem__(self, i: int | slice) -> PlacedScan | list[PlacedScan]:
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(self._len))]
        if i < 0:
            i += self._len
        if not 0 <= i < self._len:
            raise IndexError("trajectory index out of range")
        row = self._blocks[i // self._BLOCK][i % self._BLOCK]
        e, n, a = (float(v) for v in row["pose"])
        return PlacedScan(
            int(row["scan"]),
            int(row["stamp_ns"]),
            Pose2D(e, n, a),
            np.array(row["covariance"]),
            "fix" if row["fix"] else "odometry",
        )

    def __iter__(self) -> Iterator[PlacedScan]:
        return (self[i] for i in range(self._len))

    def columns(self) -> NDArray[np.void]:
        """All rows as one structured array (fields ``scan``, ``stamp_ns``, ``pose``
        (E, N, azimuth), ``covariance`` and ``fix``)."""
        if not self._blocks:
            return np.zeros(0, dtype=_ROW)
        return np.concatenate(self._blocks)[: self._len]


@dataclass(frozen=True, eq=False)
class ScannerPath:
    """The SLAM scanner's poses in the cloud's frame, read from a trajectory file: times
    (s), x, y, z and yaw (radians, from x). (A survey run's placed scans in the mine grid
    are :class:`Trajectory`.)"""

    time: NDArray[np.float64]
    xyz: NDArray[np.float64]
    yaw: NDArray[np.float64]
    path: Path
