"""A 3D lidar frame seen from above: the plan-view scan the 2D pipeline locates.

A beacon's panels are vertical, and so are a drift's walls to within their roughness:
every return on them, whatever its height, projects onto the horizontal plane on the
panel's or wall's plan-view line. So a 3D frame, levelled and projected, *is* a 2D
scan of the plan view, sampled by every ring at once. :func:`plan_scan` builds it:

1. **Level.** The frame is turned so that ``up`` (the grid's vertical in the sensor
   frame: the sensor's z for a level sensor, or an estimate) becomes z.
2. **Band.** Returns lower than ``band[0]`` or higher than ``band[1]`` (metres,
   relative to the sensor after levelling) are left out: the floor and the roof are
   not vertical, and a grade tilts them.
3. **Bearing bins.** The rest are binned by bearing, counter-clockwise from the
   sensor's x projected on the horizontal (``resolution`` wide). A bin's beam is its
   nearest surface: the returns within a window (three range sigmas, at least 5 cm) of
   the bin's nearest one. A vertical surface gives every ring the same plan range; the
   mean of k returns has 1/sqrt(k) of one's noise, and the farther wall seen above or
   beside a panel is left out. The beam is at the returns' centroid, bearing and
   range: across a bin a panel seen at a slant is nearer at one side than the other,
   and the centroid of its returns lies on it where the bin's centre at their mean
   range does not.

A bin without returns is no return at the bin's centre. What the 2D pipeline makes of
it (position and azimuth, the beacons and panels identified) is where the 3D adjustment
starts (docs/3d.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core._kernels import floor_lows, plan_ranges
from mast.core.pose3d import Frame3D
from mast.core.scan import Scan
from mast.errors import InputError

__all__ = ["estimate_up", "level_rotation", "plan_scan", "rings_bottom_up"]

#: A return the floor's may be is this far below the sensor at least (levelled), metres.
FLOOR_DEPTH_M = 0.3
#: A bin's nearest surface: the returns within this many range sigmas of its nearest
#: one, and within SURFACE_M metres at least. Cut at 5 cm whatever the noise, a bin's
#: returns on a panel at 3 cm range noise were the nearer part of their noise: the
#: 64-ring lidar's panels came out 20 / 9 / 6 mm in front of their planes at 0-5 / 5-10
#: / 10-20 m (median; 40 frames at the true vertical), the more the more returns a bin
#: held, and beacons at different ranges disagreed. At three sigmas 5 / 2 / 1 mm (four:
#: 0.4 / 0.3 / -0.2 mm, but a shallow beacon's wall, 11 cm behind its middle panel, is
#: then within the window: on 21 benchmark frames that changed outcome, four sigmas kept
#: 5 of 10 fixes where three kept 9; centring the window on its returns' mean drew an
#: end panel near its free end onto the wall beside it).
SURFACE_SIGMAS = 3.0
SURFACE_M = 0.05


def level_rotation(up: ArrayLike) -> NDArray[np.float64]:
    """The rotation that levels the sensor frame: ``up`` (the grid's vertical, in the
    sensor frame) onto z, and the sensor's x, projected on the horizontal, onto x. Its
    rows are that projected x, z × it, and ``up``; for a pose it is ``Ry(pitch) Rx(roll)``,
    so that a bearing in the levelled frame is counter-clockwise from the heading the
    azimuth names (docs/3d.md). (The smallest rotation taking ``up`` onto z would turn
    the heading by about pitch × roll / 2: 0.2° at 6° and 4°.)"""
    u = np.asarray(up, dtype=float).reshape(3)
    norm = float(np.linalg.norm(u))
    if not (math.isfinite(norm) and norm > 0):
        raise InputError("the vertical to level by is not a direction")
    z = u / norm
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    nx = float(np.linalg.norm(x))
    if nx < 1e-6 or z[2] <= 0:
        raise InputError("the sensor's x axis is vertical, or it is upside down: no heading")
    x /= nx
    return np.array([x, np.cross(z, x), z])


def plan_scan(
    frame: Frame3D,
    *,
    up: ArrayLike = (0.0, 0.0, 1.0),
    band: tuple[float, float] = (-1.0, 1.5),
    resolution_deg: float = 0.25,
    range_sigma_m: float = 0.0,
    surface_m: float | None = None,
    bands: Sequence[tuple[float, float, float, float]] = (),
) -> Scan:
    """The plan-view scan of ``frame`` (see the module), stamped and named as it: one
    beam a bearing bin, at its returns' centroid (a bin without returns: its centre, no
    return). The nearest surface's window is ``surface_m``, or where not given
    :data:`SURFACE_SIGMAS` of the lidar's ``range_sigma_m`` and at least
    :data:`SURFACE_M`. ``bands`` (from, to, low, high) gives the bearings from ``from``
    to ``to`` (radians, counter-clockwise from the levelled x axis; ``to`` may pass pi)
    their own band instead."""
    if not (0.0 < resolution_deg <= 5.0):
        raise InputError(f"plan-view resolution {resolution_deg} deg: give 0-5 deg")
    low, high = band
    if not low < high:
        raise InputError(f"plan-view band {band}: the lower bound must be below the upper")
    if surface_m is None:
        surface_m = max(SURFACE_M, SURFACE_SIGMAS * range_sigma_m)
    n = round(360.0 / resolution_deg)
    step = 2.0 * math.pi / n
    points = np.ascontiguousarray(frame.points, dtype=np.float64)
    lows, highs = _bin_bands(n, band, bands)
    bearings, ranges = plan_ranges(points, level_rotation(up), lows, highs, n, step, surface_m)
    return Scan(
        angles_rad=bearings, ranges_m=ranges, stamp_ns=frame.stamp_ns, frame_id=frame.frame_id
    )


def _bin_bands(
    n: int, band: tuple[float, float], bands: Sequence[tuple[float, float, float, float]]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each of ``n`` bearing bins' band (low, high): ``band``, or where one of ``bands``
    (from, to, low, high) covers its bearings, that one's (the last given wins)."""
    step = 2.0 * math.pi / n
    lows, highs = np.full(n, float(band[0])), np.full(n, float(band[1]))
    for start, end, lo, hi in bands:
        first = math.floor((start + math.pi) / step)
        last = math.floor((end + math.pi) / step)
        which = np.arange(first, last + 1) % n
        lows[which], highs[which] = lo, hi
    return lows, highs


def _plan_ranges_reference(
    points: NDArray[np.float64],
    L: NDArray[np.float64],
    low: NDArray[np.float64],
    high: NDArray[np.float64],
    n: int,
    step: float,
    surface: float,
) -> NDArray[np.float64]:
    """The numpy reference of :func:`mast.core._kernels.plan_ranges`: the (2, n)
    bearings and ranges of :func:`plan_scan`."""
    p = points @ L.T
    every = np.floor((np.arctan2(p[:, 1], p[:, 0]) + math.pi) / step).astype(np.intp) % n
    keep = (p[:, 2] >= low[every]) & (p[:, 2] <= high[every])
    x, y, bins = p[keep, 0], p[keep, 1], every[keep]
    r = np.hypot(x, y)
    out = np.stack([-math.pi + (np.arange(n) + 0.5) * step, np.full(n, np.nan)])
    if r.size == 0:
        return out
    nearest = np.full(n, np.inf)
    np.minimum.at(nearest, bins, r)
    near = r <= nearest[bins] + surface  # the nearest surface of each bin
    count = np.bincount(bins[near], minlength=n).astype(np.float64)
    seen = count > 0
    sx = np.bincount(bins[near], x[near], minlength=n)[seen]
    sy = np.bincount(bins[near], y[near], minlength=n)[seen]
    edge = -math.pi + np.flatnonzero(seen) * step
    out[0, seen] = np.clip(np.arctan2(sy, sx), edge + 1e-9, edge + step - 1e-9)
    out[1, seen] = np.hypot(sx, sy) / count[seen]
    return out


def estimate_up(
    frame: Frame3D,
    *,
    sample: int = 6000,
    neighbours: int = 10,
    flatness: float = 0.02,
    rings: list[tuple[float, NDArray[np.intp]]] | None = None,
) -> NDArray[np.float64]:
    """The grid's vertical in the sensor frame, from the frame's own surfaces.

    Walls and panels are vertical, so their normals are horizontal: the vertical is
    the direction the wall normals are least along (the smallest eigenvector of the
    sum of their outer products). In a straight drift the walls face one way and leave
    the direction along the drift free as well; there the floor and the roof, whose
    normals are the vertical tilted by the grade along the drift, choose within the two
    the walls leave. A pitch left off by the grade turns a wall's plan view along the
    wall, and is the 3D adjustment's to find (docs/3d.md).

    Normals come from the rings where the frame says which ring each return is: at a
    return, the cross product of the step to the next return of its ring and the step
    to the nearest return, by bearing, of the ring above (a ring alone is a line, and
    the nearest returns of a return are mostly on its own ring). Without rings, from
    the ``neighbours`` nearest returns of ``sample`` returns, kept where that patch is
    flat and not a line (its smallest eigenvalue below ``flatness`` of the sum, its
    middle one above a tenth). ``rings``: the frame's :func:`rings_bottom_up`, where the
    caller has them."""
    normals = _ring_normals(frame, sample, rings) if frame.ring is not None else None
    if normals is None:
        normals = _patch_normals(frame.points, sample, neighbours, flatness)
    z = np.abs(normals[:, 2])
    walls = normals[z < math.sin(math.radians(45.0))]
    level = normals[z > math.cos(math.radians(30.0))]
    if len(walls) < 20:
        return np.array([0.0, 0.0, 1.0])
    _, axes = np.linalg.eigh(walls.T @ walls)
    span = axes[:, :2]  # the two directions the walls leave free
    guide = np.array([0.0, 0.0, 1.0])
    first = span @ (span.T @ guide)
    floor = _floor_normal(frame.points, first / max(float(np.linalg.norm(first)), 1e-9))
    if floor is not None:
        guide = floor
    elif len(level) >= 20:
        level = level * np.sign(level[:, 2])[:, None]
        guide = level.mean(axis=0)
    up = span @ (span.T @ guide)
    norm = float(np.linalg.norm(up))
    if norm < 0.5:  # the walls leave a vertical far from the floor's: trust neither
        return np.array([0.0, 0.0, 1.0])
    return np.asarray(up / norm, dtype=np.float64)


def _floor_normal(
    p: NDArray[np.float64], up: NDArray[np.float64], cell_m: float = 0.5, reach_m: float = 12.0
) -> NDArray[np.float64] | None:
    """The floor's normal in the sensor frame, or None where too little floor is seen:
    the frame levelled by ``up`` (roughly), the lowest return of each ``cell_m`` column
    within ``reach_m`` and :data:`FLOOR_DEPTH_M` or more below the sensor (a column's
    lowest return is the floor, or a wall's foot on it), and a plane fitted to them,
    trimmed twice to those within 10 cm (the rock's roughness; a kerb or a heap of muck
    is left out). Rings reach the floor metres apart, too far for the ring normals to
    see it."""
    L = level_rotation(up)
    q = p[:: max(1, len(p) // 20_000)] @ L.T  # a floor is seen by far fewer returns
    lowest, near = floor_lows(q, -FLOOR_DEPTH_M, reach_m, cell_m)  # _floor_lows_reference
    if near < 50 or len(lowest) < 30:
        return None
    low = q[lowest]
    A = np.c_[low[:, 0], low[:, 1], np.ones(len(low))]
    use = np.ones(len(low), dtype=bool)
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(A[use], low[use, 2], rcond=None)
        use = np.abs(A @ coef - low[:, 2]) < 0.1
        if use.sum() < 30:
            return None
    n = np.array([-coef[0], -coef[1], 1.0])
    return np.asarray(L.T @ (n / np.linalg.norm(n)), dtype=np.float64)


def _floor_lows_reference(
    q: NDArray[np.float64], below: float, reach: float, cell: float
) -> tuple[NDArray[np.intp], int]:
    """The numpy reference of :func:`mast.core._kernels.floor_lows`: of the levelled
    returns ``q`` lower than ``below`` and within ``reach`` in plan, the index of the
    lowest in each ``cell`` square column (the first of those as low), by column; and
    how many returns were that low and near."""
    kept = np.flatnonzero((q[:, 2] < below) & (np.hypot(q[:, 0], q[:, 1]) < reach))
    if kept.size == 0:
        return kept, 0
    cells = np.floor(q[kept, :2] / cell).astype(np.int64)
    cells -= cells.min(axis=0)
    key = cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1]  # ordered as (x, y)
    order = np.lexsort((q[kept, 2], key))  # by column, lowest first, ties in their order
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return np.asarray(kept[order[first]], dtype=np.intp), int(kept.size)


def _patch_normals(
    p: NDArray[np.float64], sample: int, neighbours: int, flatness: float
) -> NDArray[np.float64]:
    from scipy.spatial import cKDTree

    if len(p) < 3 * neighbours:
        return np.zeros((0, 3))
    centres = p[:: max(1, len(p) // sample)]
    _, idx = cKDTree(p).query(centres, k=neighbours)
    patch = p[idx] - p[idx].mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", patch, patch))
    total = values.sum(axis=1)
    flat = (values[:, 0] < flatness * total) & (values[:, 1] > 0.1 * total)
    return np.asarray(vectors[flat, :, 0], dtype=np.float64)


def rings_bottom_up(frame: Frame3D) -> list[tuple[float, NDArray[np.intp]]]:
    """Each ring of a frame (none without rings) as its median elevation angle (radians,
    in the sensor frame) and its returns' indices, bottom to top whatever the driver's
    numbering."""
    if frame.ring is None or frame.ring.size == 0:
        return []
    ring = frame.ring
    lo = int(ring.min())
    if int(ring.max()) - lo < 1 << 16:  # a radix sort, on 16-bit keys
        small = (ring - lo).astype(np.uint16)
        counts = np.bincount(small)
        counts = counts[counts > 0]
        order = np.argsort(small, kind="stable")
    else:
        _, counts = np.unique(ring, return_counts=True)
        order = np.argsort(ring, kind="stable")
    # order: the returns by ring number, each ring's in their order
    p = frame.points
    elevation = np.hypot(p[:, 0], p[:, 1])
    elevation = np.arctan2(p[:, 2], elevation, out=elevation)[order]
    ends = np.cumsum(counts)
    out = []
    for start, end in zip(ends - counts, ends, strict=True):
        part, half = elevation[start:end], int(end - start) // 2
        # np.median's order statistics, partitioned in place
        if (end - start) % 2:
            part.partition(half)
            median = float(part[half])
        else:
            part.partition((half - 1, half))
            median = float((part[half - 1] + part[half]) / 2)
        out.append((median, order[start:end]))
    out.sort(key=lambda item: item[0])
    return out


def _ring_normals(
    frame: Frame3D, sample: int, by_ring: list[tuple[float, NDArray[np.intp]]] | None = None
) -> NDArray[np.float64] | None:
    """Normals from each ring and the one above it (see :func:`estimate_up`); None when
    the frame has fewer than two rings. ``by_ring``: its :func:`rings_bottom_up`, if known."""
    if by_ring is None:
        by_ring = rings_bottom_up(frame)
    if len(by_ring) < 2:
        return None
    x, y, z = np.array(frame.points.T)  # each coordinate contiguous
    bearing = np.arctan2(y, x)
    rings, bearings = [], []
    for _, idx in by_ring:
        b = bearing[idx]
        # a sort by bearing: stable, which is quick on a ring in the order it was
        # scanned; where two returns are at one bearing, the same as np.argsort's
        order = np.argsort(b, kind="stable")
        b = b[order]
        if b.size > 1 and (b[1:] == b[:-1]).any():
            order = np.argsort(bearing[idx])
            b = bearing[idx][order]
        rings.append(idx[order])
        bearings.append(b)
    stride = max(1, len(x) // sample)
    here, after, above = [], [], []
    for k in range(len(rings) - 1):
        low, high = rings[k], rings[k + 1]
        if low.size < 3 or high.size < 2:
            continue
        at = slice(0, low.size - 1, stride)
        here.append(low[at])
        after.append(low[1::stride][: here[-1].size])
        near = np.searchsorted(bearings[k + 1], bearings[k][at])
        above.append(high[np.minimum(near, high.size - 1)])
    if not here:
        return np.zeros((0, 3))
    h, a, u = np.concatenate(here), np.concatenate(after), np.concatenate(above)
    ax, ay, az = x[a] - x[h], y[a] - y[h], z[a] - z[h]  # the step along the ring
    ux, uy, uz = x[u] - x[h], y[u] - y[h], z[u] - z[h]  # and to the ring above
    # their cross product, and the lengths, as np.cross and np.linalg.norm have them
    nx, ny, nz = ay * uz - az * uy, az * ux - ax * uz, ax * uy - ay * ux
    size = np.sqrt(nx * nx + ny * ny + nz * nz)
    ok = np.sqrt(ax * ax + ay * ay + az * az) < 0.3
    ok &= np.sqrt(ux * ux + uy * uy + uz * uz) < 0.6
    ok &= size > 1e-6
    return np.stack([nx[ok] / size[ok], ny[ok] / size[ok], nz[ok] / size[ok]], axis=1)
