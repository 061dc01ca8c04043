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
   sensor's x projected on the horizontal (``resolution`` wide). A bin's range is
   that of its nearest surface: the returns within ``surface_m`` of the bin's nearest
   one, averaged (a vertical surface gives every ring the same plan range; the
   average of k returns has 1/sqrt(k) of one's noise, and the farther wall seen
   above or beside a panel is left out).

The scan's angles are the bins' centres; a bin without returns is no return. What the
2D pipeline makes of it (position and azimuth, the beacons and panels identified) is
where the 3D adjustment starts (docs/3d.md).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core.pose3d import Frame3D
from mast.core.scan import Scan
from mast.errors import InputError

__all__ = ["level_rotation", "plan_scan"]


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
    surface_m: float = 0.05,
) -> Scan:
    """The plan-view scan of ``frame`` (see the module), stamped and named as it."""
    if not (0.0 < resolution_deg <= 5.0):
        raise InputError(f"plan-view resolution {resolution_deg} deg: give 0-5 deg")
    low, high = band
    if not low < high:
        raise InputError(f"plan-view band {band}: the lower bound must be below the upper")
    p = frame.points @ level_rotation(up).T
    keep = (p[:, 2] >= low) & (p[:, 2] <= high)
    x, y = p[keep, 0], p[keep, 1]
    r = np.hypot(x, y)
    step = math.radians(resolution_deg)
    n = round(2.0 * math.pi / step)
    step = 2.0 * math.pi / n
    angle_min = -math.pi + step / 2
    ranges = np.full(n, np.nan)
    if r.size:
        bins = np.floor((np.arctan2(y, x) + math.pi) / step).astype(np.intp) % n
        order = np.lexsort((r, bins))
        bins, r = bins[order], r[order]
        starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
        nearest = np.repeat(r[starts], np.diff(np.r_[starts, r.size]))
        near = r <= nearest + surface_m  # the nearest surface of each bin
        group = np.cumsum(np.r_[True, bins[1:] != bins[:-1]]) - 1
        total = np.bincount(group, weights=np.where(near, r, 0.0))
        count = np.bincount(group, weights=near.astype(float))
        ranges[bins[starts]] = total / count
    return Scan.from_laserscan(
        angle_min=angle_min,
        angle_increment=step,
        ranges=ranges,
        stamp_ns=frame.stamp_ns,
        frame_id=frame.frame_id,
    )
