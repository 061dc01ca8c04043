"""Nearest neighbours within a gate, for 2D scans: a uniform grid and a compiled search.

Scan matching asks, dozens of times a scan, for the nearest return of another
scan within a few decimetres. A k-d tree answers any radius; a grid whose cells
are as wide as the largest gate answers these in a few cells per point, and its
search is compiled (:func:`mast.core._kernels.nearest_within`). The answers are
those of ``scipy.spatial.cKDTree.query`` with ``distance_upper_bound`` (the tests
compare the two).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["BearingIndex", "PointGrid"]

#: Most cells a grid holds: wider extents get wider cells (the search then
#: looks at fewer, fuller cells; the answers are the same).
MAX_CELLS = 1 << 20


@dataclass(frozen=True, slots=True)
class PointGrid:
    """Points binned in square cells, for nearest-neighbour queries within a gate."""

    points: NDArray[np.float64]
    origin: NDArray[np.float64]
    cell: float
    nx: int
    ny: int
    start: NDArray[np.intp]
    order: NDArray[np.intp]

    @classmethod
    def build(cls, points: NDArray[np.float64], cell: float) -> PointGrid:
        """Bin ``(n, 2)`` finite points in cells of side ``cell`` (metres, > 0) or wider."""
        pts = np.ascontiguousarray(points, dtype=float).reshape(-1, 2)
        if not (math.isfinite(cell) and cell > 0):
            raise ValueError(f"grid cell must be positive, got {cell}")
        if pts.shape[0] == 0:
            none = np.zeros(0, dtype=np.intp)
            return cls(pts, np.zeros(2), cell, 1, 1, np.zeros(2, dtype=np.intp), none)
        lo = pts.min(axis=0)
        extent = pts.max(axis=0) - lo
        cell = max(cell, math.sqrt(float(extent[0] + cell) * float(extent[1] + cell) / MAX_CELLS))
        nx, ny = (int(e // cell) + 1 for e in extent)
        ix = np.minimum(((pts[:, 0] - lo[0]) // cell).astype(np.intp), nx - 1)
        iy = np.minimum(((pts[:, 1] - lo[1]) // cell).astype(np.intp), ny - 1)
        flat = ix * ny + iy
        order = np.argsort(flat, kind="stable").astype(np.intp)
        start = np.searchsorted(flat[order], np.arange(nx * ny + 1)).astype(np.intp)
        return cls(pts, lo, float(cell), nx, ny, start, order)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def query(
        self, query: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """Distance to and index of each query point's nearest point closer than ``gate``
        (``inf`` and ``len(self)`` when there is none), as ``cKDTree.query`` gives them."""
        from mast.core._kernels import nearest_within

        dist, idx = nearest_within(
            np.ascontiguousarray(query, dtype=float).reshape(-1, 2),
            self.points,
            self.origin,
            self.cell,
            self.nx,
            self.ny,
            self.start,
            self.order,
            float(gate),
        )
        return np.asarray(dist), np.asarray(idx)


@dataclass(frozen=True, slots=True)
class BearingIndex:
    """Points sorted by their bearing from the origin, for nearest-neighbour queries
    within a gate around a scanner: a point nearer than the gate to a query point at
    range ``r`` lies within ``asin(gate / r)`` of its bearing. A scan's returns (one a
    beam) then offer a few beams' worth of candidates a query, where a grid's cells as
    wide as the widest gate hold a wall's metre of them. The answers are
    :class:`PointGrid`'s (the tests compare both with the k-d tree)."""

    points: NDArray[np.float64]
    bearing: NDArray[np.float64]
    order: NDArray[np.intp]

    @classmethod
    def build(cls, points: NDArray[np.float64]) -> BearingIndex:
        """Index ``(n, 2)`` finite points by bearing from the origin."""
        pts = np.ascontiguousarray(points, dtype=float).reshape(-1, 2)
        bearing = np.arctan2(pts[:, 1], pts[:, 0])
        order = np.argsort(bearing, kind="stable").astype(np.intp)
        return cls(pts, np.ascontiguousarray(bearing[order]), order)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def query(
        self, query: NDArray[np.float64], gate: float
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """As :meth:`PointGrid.query`."""
        from mast.core._kernels import nearest_by_bearing

        dist, idx = nearest_by_bearing(
            np.ascontiguousarray(query, dtype=float).reshape(-1, 2),
            self.points,
            self.bearing,
            self.order,
            float(gate),
            _NOTHING_KNOWN,
        )
        return np.asarray(dist), np.asarray(idx)


#: No distance known to hold a neighbour (:func:`mast.core._kernels.nearest_by_bearing`).
_NOTHING_KNOWN = np.zeros(0)
