"""A plan-view world of straight surfaces and round objects, and ray casting into it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core.geometry import first_hits

__all__ = ["Surface", "World", "WorldBuilder"]

#: Surface kinds the simulator labels every hit with.
KINDS = ("wall", "beacon", "clutter", "person", "lookalike")


@dataclass(frozen=True, slots=True)
class Surface:
    """What a beam hit: its kind and, for a beacon panel, which beacon and panel (1..3)."""

    kind: str
    beacon: str = ""
    panel: int = 0


@dataclass(frozen=True, eq=False)
class World:
    """Straight segments ``a[i] -> b[i]`` and circles, each tagged with a surface.

    Attributes
    ----------
    seg_a, seg_b : ndarray, shape (m, 2)
        Segment end points, mine frame (E, N), metres.
    seg_surface : ndarray of int, shape (m,)
        Index into ``surfaces`` for each segment.
    circ_c : ndarray, shape (k, 2); circ_r : ndarray, shape (k,)
        Circle centres and radii.
    circ_surface : ndarray of int, shape (k,)
    surfaces : tuple of Surface
    """

    seg_a: NDArray[np.float64]
    seg_b: NDArray[np.float64]
    seg_surface: NDArray[np.intp]
    circ_c: NDArray[np.float64]
    circ_r: NDArray[np.float64]
    circ_surface: NDArray[np.intp]
    surfaces: tuple[Surface, ...]

    def raycast(
        self, origin: ArrayLike, directions: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """Distance to the first surface along each ray.

        Parameters
        ----------
        origin : array_like, shape (2,)
            Ray origin (E, N).
        directions : array_like, shape (n, 2)
            Unit direction of each ray.

        Returns
        -------
        ranges : ndarray, shape (n,)
            Distance to the first hit, ``inf`` where nothing is hit.
        surface : ndarray of int, shape (n,)
            Index into ``surfaces`` of what was hit, -1 where nothing.
        """
        o = np.asarray(origin, dtype=float).reshape(2)
        d = np.asarray(directions, dtype=float).reshape(-1, 2)
        n = d.shape[0]
        best = np.full(n, np.inf)
        which = np.full(n, -1, dtype=np.intp)
        if self.seg_a.shape[0]:
            best, j = first_hits(o, d, self.seg_a, self.seg_b)
            which = np.where(j >= 0, self.seg_surface[np.maximum(j, 0)], -1)
        if self.circ_c.shape[0]:
            w = self.circ_c - o  # (k, 2)
            proj = d @ w.T  # (n, k): distance along the ray to the closest approach
            c2 = np.sum(w * w, axis=1)[None, :] - self.circ_r[None, :] ** 2
            disc = proj**2 - c2
            with np.errstate(invalid="ignore"):
                t = proj - np.sqrt(disc)
            ok = (disc >= 0) & (t > 1e-12)
            t = np.where(ok, t, np.inf)
            j = np.argmin(t, axis=1)
            tj = t[np.arange(n), j]
            hit = tj < best
            best[hit] = tj[hit]
            which[hit] = self.circ_surface[j[hit]]
        return best, which


@dataclass
class WorldBuilder:
    """Collects surfaces, then freezes them into a :class:`World`."""

    _a: list[NDArray[np.float64]] = field(default_factory=list)
    _b: list[NDArray[np.float64]] = field(default_factory=list)
    _seg_s: list[int] = field(default_factory=list)
    _cc: list[tuple[float, float]] = field(default_factory=list)
    _cr: list[float] = field(default_factory=list)
    _circ_s: list[int] = field(default_factory=list)
    _surfaces: list[Surface] = field(default_factory=list)

    def _surface(self, surface: Surface) -> int:
        if surface in self._surfaces:
            return self._surfaces.index(surface)
        self._surfaces.append(surface)
        return len(self._surfaces) - 1

    def polyline(self, points: ArrayLike, surface: Surface) -> None:
        """Add the segments of an open polyline ``(k, 2)``."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        k = self._surface(surface)
        self._a.append(p[:-1])
        self._b.append(p[1:])
        self._seg_s.extend([k] * (p.shape[0] - 1))

    def panels(self, edges: ArrayLike, beacon: str, kind: str = "beacon") -> None:
        """Add a beacon's three panels, each labelled with its panel number."""
        e = np.asarray(edges, dtype=float).reshape(4, 2)
        for i in range(3):
            self.polyline(e[i : i + 2], Surface(kind, beacon, i + 1))

    def polygon(self, points: ArrayLike, surface: Surface) -> None:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        self.polyline(np.vstack([p, p[:1]]), surface)

    def box(
        self, center: ArrayLike, size: tuple[float, float], yaw_rad: float, surface: Surface
    ) -> None:
        """A rectangle ``size = (length, width)`` rotated counter-clockwise by ``yaw_rad``."""
        c = np.asarray(center, dtype=float)
        hx, hy = size[0] / 2, size[1] / 2
        corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        cs, sn = np.cos(yaw_rad), np.sin(yaw_rad)
        rot = np.array([[cs, -sn], [sn, cs]])
        self.polygon(corners @ rot.T + c, surface)

    def circle(self, center: ArrayLike, radius: float, surface: Surface) -> None:
        c = np.asarray(center, dtype=float).reshape(2)
        self._cc.append((float(c[0]), float(c[1])))
        self._cr.append(float(radius))
        self._circ_s.append(self._surface(surface))

    def build(self) -> World:
        a = np.vstack(self._a) if self._a else np.zeros((0, 2))
        b = np.vstack(self._b) if self._b else np.zeros((0, 2))
        return World(
            a,
            b,
            np.asarray(self._seg_s, dtype=np.intp),
            np.asarray(self._cc, dtype=float).reshape(-1, 2),
            np.asarray(self._cr, dtype=float),
            np.asarray(self._circ_s, dtype=np.intp),
            tuple(self._surfaces),
        )
