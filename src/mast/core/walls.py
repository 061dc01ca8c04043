"""A drift's outline: its walls as polylines in the mine grid, as a drift outline file
(``mast plan --drift``, docs/design.md) gives them.

A data type of the file contract, below both the reader (:mod:`mast.io.drift`) and the
planner (:mod:`mast.plan`) that uses it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["Drift", "Wall"]


@dataclass(frozen=True, slots=True)
class Wall:
    """One wall polyline, mine frame (E, N), metres, vertices in order."""

    id: str
    points: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Drift:
    """The walls of a drift, as read from a drift outline file."""

    walls: tuple[Wall, ...]
    source: str | None = None

    def segments(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Every wall segment's start and end points, shapes (m, 2)."""
        a = np.vstack([w.points[:-1] for w in self.walls])
        b = np.vstack([w.points[1:] for w in self.walls])
        return a, b

    @property
    def length_m(self) -> float:
        """Total length of the walls."""
        a, b = self.segments()
        return float(np.sum(np.hypot(*(b - a).T)))
