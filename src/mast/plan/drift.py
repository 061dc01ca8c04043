"""A drift outline (its walls) and the centreline and grid of scanner positions in it.

The centreline is the drift's medial axis: the points as far from one wall as
from the opposite one. It is found from the Voronoi diagram of points sampled
densely along the walls (Blum's medial axis, approximated as in Brandt and
Algazi 1992): a Voronoi ridge between two wall samples lies on the medial axis
when it crosses the segment joining them near its middle, that is when the two
samples face each other across the drift. The longest path through those
ridges, smoothed and resampled, is the centreline.

One drift per plan: at a junction the longest branch is the centreline and the
side branches are not gridded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.geometry import first_hits
from mast.core.walls import Drift
from mast.errors import InputError

__all__ = ["Grid", "build_grid", "centreline", "wall_distance"]

#: Wall sampling for the medial axis, metres (finer for narrow drifts).
_SAMPLE_M = 0.2
#: A ridge is medial when both its ends lie within this share of the samples'
#: distance from their midpoint.
_MEDIAL_TOLERANCE = 0.25
#: A cell this much inside the margin still counts (the centreline is found to millimetres).
_MARGIN_TOLERANCE_M = 0.01
#: The centreline is smoothed over this length (the Voronoi ridges zig-zag by a sample).
_SMOOTH_M = 2.0


def _samples(drift: Drift, spacing_m: float) -> NDArray[np.float64]:
    out = []
    for w in drift.walls:
        p = w.points
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
        ss = np.union1d(np.linspace(0.0, s[-1], max(2, math.ceil(s[-1] / spacing_m) + 1)), s)
        out.append(np.stack([np.interp(ss, s, p[:, 0]), np.interp(ss, s, p[:, 1])], axis=1))
    pts = np.unique(np.vstack(out).round(6), axis=0)
    return np.asarray(pts, dtype=np.float64)


def wall_distance(drift: Drift, points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance from each point ``(n, 2)`` to the nearest wall."""
    a, b = drift.segments()
    ab = b - a
    len2 = np.maximum(np.sum(ab * ab, axis=1), 1e-300)
    out = np.empty(len(points))
    for k0 in range(0, len(points), 256):  # bounded memory: 256 points x every segment
        p = points[k0 : k0 + 256, None, :]
        u = np.clip(np.sum((p - a) * ab, axis=2) / len2, 0.0, 1.0)
        d = p - (a + u[..., None] * ab)
        out[k0 : k0 + 256] = np.sqrt(np.min(np.sum(d * d, axis=2), axis=1))
    return out


def centreline(drift: Drift, *, spacing_m: float = 0.5) -> NDArray[np.float64]:
    """The drift's centreline, a polyline with vertices every ``spacing_m``.

    It runs from the end nearer the first wall's first vertex.

    Raises
    ------
    InputError
        When the walls enclose no drift (a single straight wall, walls that
        never face each other).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components, dijkstra
    from scipy.spatial import QhullError, Voronoi

    lo, hi = (
        np.min(np.vstack([w.points for w in drift.walls]), axis=0),
        np.max(np.vstack([w.points for w in drift.walls]), axis=0),
    )
    origin = 0.5 * (lo + hi)  # Qhull works in local coordinates: UTM-sized ones lose digits
    pts = _samples(drift, _SAMPLE_M) - origin
    where = drift.source
    try:
        vor = Voronoi(pts)
    except (QhullError, ValueError):
        raise InputError("the walls enclose no drift (too few wall points)", path=where) from None
    rp = vor.ridge_points
    rv = np.asarray(vor.ridge_vertices, dtype=np.intp)
    finite = np.all(rv >= 0, axis=1)
    p, q = pts[rp[:, 0]], pts[rp[:, 1]]
    mid = 0.5 * (p + q)
    span = np.hypot(*(q - p).T)
    v1 = vor.vertices[np.maximum(rv[:, 0], 0)]
    v2 = vor.vertices[np.maximum(rv[:, 1], 0)]
    tol = _MEDIAL_TOLERANCE * span
    keep = (
        finite
        & (span >= 4 * _SAMPLE_M)
        & (np.hypot(*(v1 - mid).T) <= tol)
        & (np.hypot(*(v2 - mid).T) <= tol)
    )
    if not np.any(keep):
        raise InputError("the walls enclose no drift: no two walls face each other", path=where)
    i, j = rv[keep, 0], rv[keep, 1]
    w = np.hypot(*(vor.vertices[i] - vor.vertices[j]).T) + 1e-12
    n = len(vor.vertices)
    graph = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    graph = graph.maximum(graph.T)
    _, label = connected_components(graph, directed=False)
    used = np.unique(np.concatenate([i, j]))
    # the component with the most medial length
    length_of = np.bincount(label[i], weights=w, minlength=label.max() + 1)
    best = int(np.argmax(length_of))
    start = int(used[label[used] == best][0])
    dist = dijkstra(graph, directed=False, indices=start)
    u = int(np.argmax(np.where(np.isfinite(dist), dist, -1.0)))
    dist, pred = dijkstra(graph, directed=False, indices=u, return_predecessors=True)
    v = int(np.argmax(np.where(np.isfinite(dist), dist, -1.0)))
    path = [v]
    while path[-1] != u:
        path.append(int(pred[path[-1]]))
    line = vor.vertices[path]
    if math.dist(line[0], drift.walls[0].points[0] - origin) > math.dist(
        line[-1], drift.walls[0].points[0] - origin
    ):
        line = line[::-1]
    out: NDArray[np.float64] = _resample(line, spacing_m) + origin
    return out


def _resample(line: NDArray[np.float64], spacing_m: float) -> NDArray[np.float64]:
    """The polyline smoothed over :data:`_SMOOTH_M` and resampled every ``spacing_m``."""
    from scipy.ndimage import uniform_filter1d

    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    fine = 0.1
    ss = np.linspace(0.0, s[-1], max(2, math.ceil(s[-1] / fine) + 1))
    xy = np.stack([np.interp(ss, s, line[:, 0]), np.interp(ss, s, line[:, 1])], axis=1)
    size = max(1, round(_SMOOTH_M / fine)) | 1
    if len(ss) > size:
        smooth = uniform_filter1d(xy, size=size, axis=0, mode="nearest")
        # keep the ends where they were: the filter would pull them inwards
        ramp = np.clip(np.minimum(ss, ss[-1] - ss) / (_SMOOTH_M / 2), 0.0, 1.0)[:, None]
        xy = ramp * smooth + (1 - ramp) * xy
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    ss = np.linspace(0.0, s[-1], max(2, math.ceil(s[-1] / spacing_m) + 1))
    out = np.stack([np.interp(ss, s, xy[:, 0]), np.interp(ss, s, xy[:, 1])], axis=1)
    return np.asarray(out, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Grid:
    """Scanner positions along the centreline and across the drift.

    Attributes
    ----------
    centreline : ndarray, shape (k, 2)
    stations_m : ndarray, shape (s,)
        Distance along the centreline of each row of cells.
    offsets_m : ndarray, shape (o,)
        Distance across, positive to the left of the centreline's direction;
        the middle one is 0.
    xy : ndarray, shape (s, o, 2)
        Each cell's position (E, N); defined for every cell, used where ``inside``.
    inside : ndarray of bool, shape (s, o)
        Cells at least the margin from every wall and in sight of the centreline.
    azimuth_rad : ndarray, shape (s,)
        Azimuth of the centreline's direction at each station.
    step_m : float
        Spacing of the stations (each stands for this much of the centreline).
    """

    centreline: NDArray[np.float64]
    stations_m: NDArray[np.float64]
    offsets_m: NDArray[np.float64]
    xy: NDArray[np.float64]
    inside: NDArray[np.bool_]
    azimuth_rad: NDArray[np.float64]
    step_m: float

    @property
    def centre(self) -> int:
        """Column of the centreline cells (offset 0)."""
        return len(self.offsets_m) // 2

    @property
    def length_m(self) -> float:
        c = self.centreline
        return float(np.sum(np.hypot(*np.diff(c, axis=0).T)))

    def corners(self) -> NDArray[np.float64]:
        """(s + 1, o + 1, 2) corners of the cells, half a step either side of each centre."""
        half = self.step_m / 2
        edges = np.concatenate([self.stations_m - half, self.stations_m[-1:] + half])
        edges = np.clip(edges, 0.0, self.length_m)
        across = self.offsets_m[1] - self.offsets_m[0] if len(self.offsets_m) > 1 else self.step_m
        sides = np.concatenate([self.offsets_m - across / 2, self.offsets_m[-1:] + across / 2])
        point, tangent = _frame(self.centreline, edges)
        left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
        out: NDArray[np.float64] = point[:, None, :] + sides[None, :, None] * left[:, None, :]
        return out


def _frame(
    line: NDArray[np.float64], stations: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points and unit tangents (over a metre) of a polyline at the given arc lengths."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
    length = float(s[-1])

    def at(q: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.stack([np.interp(q, s, line[:, k]) for k in (0, 1)], axis=1)

    tangent = at(np.minimum(stations + 0.5, length)) - at(np.maximum(stations - 0.5, 0.0))
    tangent /= np.maximum(np.hypot(*tangent.T), 1e-12)[:, None]
    return at(stations), tangent


def build_grid(drift: Drift, step_m: float, across_m: float, margin_m: float) -> Grid:
    """Cells every ``step_m`` along the centreline and ``across_m`` across it.

    A cell is inside when it is at least ``margin_m`` from every wall and no
    wall stands between it and its centreline point. A centreline cell closer
    than the margin to a wall (a drift narrower than twice the margin) is
    still kept: the centreline is where a vehicle drives.
    """
    for name, value in (("step", step_m), ("across step", across_m)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number of metres, got {value:g}")
    if not (math.isfinite(margin_m) and margin_m >= 0):
        raise InputError(f"margin must be a non-negative number of metres, got {margin_m:g}")
    line = centreline(drift, spacing_m=min(0.5, step_m / 2))
    length = float(np.sum(np.hypot(*np.diff(line, axis=0).T)))
    stations = np.array([length / 2]) if length < step_m else np.arange(step_m / 2, length, step_m)
    centre, tangent = _frame(line, stations)
    left = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    clearance = wall_distance(drift, centre)
    half = int(max(0.0, float(np.max(clearance)) - margin_m) / across_m + 1e-6)
    offsets = across_m * np.arange(-half, half + 1, dtype=float)
    xy = centre[:, None, :] + offsets[None, :, None] * left[:, None, :]
    clear = wall_distance(drift, xy.reshape(-1, 2)).reshape(xy.shape[:2])
    inside = clear >= margin_m - _MARGIN_TOLERANCE_M
    # in sight of the centreline: no wall between a cell and its centre point
    a, b = drift.segments()
    for k in range(len(offsets)):
        if offsets[k] == 0.0:
            continue
        direction = left * math.copysign(1.0, offsets[k])
        for row in np.flatnonzero(inside[:, k]):
            t, _ = first_hits(centre[row], direction[row : row + 1], a, b)
            if t[0] < abs(offsets[k]):
                inside[row, k] = False
    inside[:, half] = True
    azimuth = np.arctan2(tangent[:, 0], tangent[:, 1]) % (2 * math.pi)
    return Grid(line, stations, offsets, xy, inside, azimuth, step_m)
