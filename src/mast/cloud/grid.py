"""Sparse plan grids accumulated over a cloud streamed in chunks.

A cell is keyed by its integer column and row packed into one ``int64``; each
chunk's cells are reduced with ``numpy`` (sort, then ``reduceat``) and merged
into the running grid, so memory follows the cells occupied, not the points.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "EIGHT",
    "PlanGrid",
    "PlanIndex",
    "cell_keys",
    "key_ij",
    "neighbours",
    "pack_ij",
    "within",
]

_SHIFT = np.int64(1 << 30)  # keys stay positive: (i + 2^30) << 32 < 2^63


def cell_keys(
    xy: NDArray[np.float64], origin: NDArray[np.float64], cell_m: float
) -> NDArray[np.int64]:
    """Packed keys of the cells of side ``cell_m`` holding ``xy`` (columns from ``origin``)."""
    return pack_ij(np.floor((xy - origin) / cell_m).astype(np.int64))


def pack_ij(ij: NDArray[np.int64]) -> NDArray[np.int64]:
    """Packed keys of integer columns and rows ``(n, 2)`` (the inverse of :func:`key_ij`)."""
    ij = np.asarray(ij, dtype=np.int64) + _SHIFT
    return np.asarray((ij[:, 0] << np.int64(32)) | ij[:, 1], dtype=np.int64)


def within(cells: int) -> tuple[tuple[int, int], ...]:
    """The offsets of the cells within ``cells`` of one (a square block but its centre)."""
    r = range(-cells, cells + 1)
    return tuple((di, dj) for di in r for dj in r if (di, dj) != (0, 0))


#: The offsets of a cell's eight neighbours.
EIGHT = within(1)


def neighbours(
    keys: NDArray[np.int64],
    offsets: tuple[tuple[int, int], ...] = EIGHT,
    among: NDArray[np.int64] | None = None,
) -> list[tuple[NDArray[np.bool_], NDArray[np.intp]]]:
    """For each neighbour in turn (the eight, or ``offsets``): whether each of ``keys``
    has that neighbour among the sorted ``among`` (``keys`` themselves, sorted, when not
    given), and where it is there."""
    pool = keys if among is None else among
    ij = key_ij(keys)
    out = []
    for off in offsets:
        nk = pack_ij(ij + np.array(off))
        pos = np.minimum(np.searchsorted(pool, nk), max(pool.size - 1, 0)).astype(np.intp)
        hit = (pool[pos] == nk) if pool.size else np.zeros(nk.size, bool)
        out.append((hit, pos))
    return out


def key_ij(keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """Column and row of packed keys, ``(n, 2)``."""
    return np.column_stack(
        [(keys >> np.int64(32)) - _SHIFT, (keys & np.int64(0xFFFFFFFF)) - _SHIFT]
    )


@dataclass
class PlanGrid:
    """Per plan cell: lowest and highest z, point count and a bit mask of occupied
    height bins (bin ``k`` is ``[base + k h, base + (k + 1) h)``, 64 bins)."""

    origin: NDArray[np.float64]
    cell_m: float
    keys: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    zmin: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    zmax: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    count: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    bins: NDArray[np.uint64] = field(default_factory=lambda: np.zeros(0, np.uint64))

    def add(
        self, xyz: NDArray[np.float64], bins: NDArray[np.uint64] | None = None
    ) -> NDArray[np.int64]:
        """Accumulate points (and their height-bin bits); returns their cell keys."""
        keys = cell_keys(xyz[:, :2], self.origin, self.cell_m)
        if keys.size == 0:
            return keys
        b = np.zeros(keys.size, np.uint64) if bins is None else bins
        self._merge(keys, xyz[:, 2], xyz[:, 2], np.ones(keys.size, np.int64), b)
        return keys

    def _merge(
        self,
        keys: NDArray[np.int64],
        lo: NDArray[np.float64],
        hi: NDArray[np.float64],
        n: NDArray[np.int64],
        bits: NDArray[np.uint64],
    ) -> None:
        k = np.concatenate([self.keys, keys])
        lo = np.concatenate([self.zmin, lo])
        hi = np.concatenate([self.zmax, hi])
        n = np.concatenate([self.count, n])
        bits = np.concatenate([self.bins, bits])
        order = np.argsort(k, kind="stable")
        k = k[order]
        starts = np.flatnonzero(np.concatenate([[True], k[1:] != k[:-1]]))
        self.keys = k[starts]
        self.zmin = np.minimum.reduceat(lo[order], starts)
        self.zmax = np.maximum.reduceat(hi[order], starts)
        self.count = np.add.reduceat(n[order], starts)
        self.bins = np.bitwise_or.reduceat(bits[order], starts)

    def lookup(self, keys: NDArray[np.int64]) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """Row of every key in the grid, and whether it is there at all."""
        pos = np.searchsorted(self.keys, keys)
        pos = np.minimum(pos, max(self.keys.size - 1, 0))
        found = self.keys.size > 0
        hit = (self.keys[pos] == keys) if found else np.zeros(keys.size, bool)
        return pos.astype(np.intp), hit

    def at(self, xy: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """Row and presence of the cells holding ``xy``."""
        return self.lookup(cell_keys(xy, self.origin, self.cell_m))

    def centres(self) -> NDArray[np.float64]:
        """Plan centre of every cell."""
        return np.asarray(self.origin + (key_ij(self.keys) + 0.5) * self.cell_m, dtype=float)


class PlanIndex:
    """Points in plan, sorted by x once, for the points in many small squares: a slice
    by x, then a test of y (a beacon's neighbourhood among millions of candidates)."""

    def __init__(self, xy: NDArray[np.float64]) -> None:
        self.order = np.argsort(xy[:, 0], kind="stable")
        self.x = np.ascontiguousarray(xy[self.order, 0])
        self.y = np.ascontiguousarray(xy[self.order, 1])

    def square(self, centre: NDArray[np.float64], half_m: float) -> NDArray[np.intp]:
        """Rows (in order) of the points nearer than ``half_m`` to ``centre`` in x and in y."""
        lo = int(np.searchsorted(self.x, centre[0] - half_m, side="right"))
        hi = int(np.searchsorted(self.x, centre[0] + half_m, side="left"))
        inside = np.abs(self.y[lo:hi] - centre[1]) < half_m
        return np.asarray(np.sort(self.order[lo:hi][inside]), dtype=np.intp)
