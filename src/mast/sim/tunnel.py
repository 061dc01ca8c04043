"""Tunnels (drifts) made of two wall polylines, with optional rough walls."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Roughness", "Tunnel", "polyline_station", "project_station", "roughen"]


@dataclass(frozen=True, slots=True)
class Roughness:
    """Wall roughness: a sum of sinusoids, peak ``amplitude_m``, wavelengths in a band."""

    amplitude_m: float = 0.05
    wavelength_min_m: float = 0.2
    wavelength_max_m: float = 1.0
    components: int = 8
    #: a beacon's wall patch, plus this margin each side, is left smooth (dressed for mounting)
    beacon_margin_m: float = 0.15


def _arc_length(p: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])


def polyline_station(
    points: ArrayLike, station_m: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Point and unit tangent at arc length ``station_m`` along a polyline."""
    p = np.asarray(points, dtype=float)
    s = _arc_length(p)
    i = int(np.clip(np.searchsorted(s, station_m, side="right") - 1, 0, len(p) - 2))
    seg = p[i + 1] - p[i]
    length = float(np.hypot(*seg))
    t = seg / length
    return p[i] + t * (station_m - s[i]), t


def roughen(
    points: ArrayLike,
    rough: Roughness,
    rng: np.random.Generator,
    *,
    smooth_intervals: Sequence[tuple[float, float]] = (),
) -> NDArray[np.float64]:
    """Resample a wall polyline finely and offset it along its normal by a random profile.

    The profile is zero inside ``smooth_intervals`` (arc-length ranges) and
    ramps up over ``beacon_margin_m`` outside them.
    """
    p = np.asarray(points, dtype=float)
    s = _arc_length(p)
    step = min(0.05, rough.wavelength_min_m / 4)
    ss = np.linspace(0.0, s[-1], max(2, math.ceil(s[-1] / step) + 1))
    # Keep the original vertices so corners stay sharp.
    ss = np.union1d(ss, s)
    xy = np.stack([np.interp(ss, s, p[:, 0]), np.interp(ss, s, p[:, 1])], axis=1)
    tang = np.gradient(xy, axis=0)
    tang /= np.hypot(tang[:, 0], tang[:, 1])[:, None]
    normal = np.stack([-tang[:, 1], tang[:, 0]], axis=1)
    lam = rng.uniform(rough.wavelength_min_m, rough.wavelength_max_m, rough.components)
    phase = rng.uniform(0, 2 * math.pi, rough.components)
    weight = rng.uniform(0.3, 1.0, rough.components)
    prof = np.sum(
        weight[None, :] * np.sin(2 * math.pi * ss[:, None] / lam[None, :] + phase), axis=1
    )
    prof *= rough.amplitude_m / max(1e-12, float(np.max(np.abs(prof))))
    taper = np.ones_like(ss)
    for a, b in smooth_intervals:
        dist = np.maximum(a - ss, ss - b)  # < 0 inside the interval
        taper = np.minimum(taper, np.clip(dist / max(rough.beacon_margin_m, 1e-9), 0.0, 1.0))
    out: NDArray[np.float64] = xy + (prof * taper)[:, None] * normal
    return out


@dataclass(frozen=True, eq=False)
class Tunnel:
    """A drift of constant width around a centreline polyline (mine frame, metres).

    The left wall lies to the left of the centreline's direction of travel;
    the tunnel is on the right of the left wall and on the left of the right
    wall.
    """

    centreline: NDArray[np.float64]
    width_m: float

    def walls(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Left and right wall polylines, offset with mitred corners."""
        c = np.asarray(self.centreline, dtype=float)
        d = np.diff(c, axis=0)
        d /= np.hypot(d[:, 0], d[:, 1])[:, None]
        seg_n = np.stack([-d[:, 1], d[:, 0]], axis=1)
        vn = np.vstack([seg_n[:1], seg_n[:-1] + seg_n[1:], seg_n[-1:]])
        vn /= np.hypot(vn[:, 0], vn[:, 1])[:, None]
        # Mitre: scale so that each wall stays width/2 from both adjacent segments.
        cos_half = np.ones(len(c))
        cos_half[1:-1] = np.sum(vn[1:-1] * seg_n[:-1], axis=1)
        off = (self.width_m / 2) / cos_half
        return c + off[:, None] * vn, c - off[:, None] * vn

    def wall_point(
        self, side: str, station_m: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
        """Point, tangent and tunnel side (+1 left / -1 right) at a station along a wall."""
        left, right = self.walls()
        wall = left if side == "left" else right
        point, tangent = polyline_station(wall, station_m)
        return point, tangent, (-1 if side == "left" else 1)

    def centre_point(self, station_m: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return polyline_station(self.centreline, station_m)

    @property
    def length_m(self) -> float:
        return float(_arc_length(np.asarray(self.centreline))[-1])


def project_station(points: ArrayLike, point: ArrayLike) -> float:
    """Arc length along a polyline of the point on it closest to ``point``."""
    p = np.asarray(points, dtype=float)
    q = np.asarray(point, dtype=float)
    a, b = p[:-1], p[1:]
    ab = b - a
    length2 = np.sum(ab * ab, axis=1)
    t = np.clip(np.sum((q - a) * ab, axis=1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    closest = a + t[:, None] * ab
    i = int(np.argmin(np.sum((closest - q) ** 2, axis=1)))
    return float(_arc_length(p)[i] + t[i] * math.sqrt(length2[i]))
