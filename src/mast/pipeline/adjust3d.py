"""The six parameters of a 3D sensor's pose from the returns on surveyed beacon panels.

Each panel is a vertical rectangle; in plan it is the segment between two surveyed
edges, and its top is at the elevation the survey gives (DESIGN.md: an edge's
elevation is its top end). Two kinds of evidence, each from the frame alone:

* **Panel points** (easting, northing, azimuth, pitch, roll). A return on panel k,
  moved into the grid by the pose, lies in the panel's vertical plane
  ``n_k · X = d_k``: its residual is ``n_k · (R p + t) - d_k``. A tilt about the
  panel's horizontal axis moves its returns off the plane in proportion to their
  height, so panels of different directions (the deflection angles, two beacons)
  observe pitch and roll. The elevation does not enter (the plane is vertical).
  The observation is the return's range, as in 2D: its row is that residual over the
  ray's incidence ``cos i = n_k · (R u)``, the measured range less the range along the
  ray to the plane, weighed by the range sigma. Gauss-Newton with analytic derivatives
  of ``R = Rz(yaw) Ry(pitch) Rx(roll)``, through the incidence too: weighing the
  residual across the plane by ``1 / cos² i`` at each iteration's pose instead leaves
  out that derivative, whose expectation over the range noise is not zero, and biases
  the pose (by half its sigma in roll and azimuth at 2 cm, on a drift's panels seen
  obliquely). A return within 2° of grazing its panel is left out (it carries no
  usable range, as in 2D: :data:`GRAZING_DEG`); the survey's
  sigma, shared by every return of a panel, is propagated into the covariance after
  (as in 2D, :func:`mast.pipeline.adjustment.survey_covariance`).
* **Top edges** (elevation). Every ray that crosses a panel's plane inside its plan
  extent either hit the panel (it crossed below the top) or went over it (it crossed
  above: its return lies beyond the plane). With the tilt known, each crossing's
  height relative to the sensor is known (from the ray's direction: no range noise),
  so the sensor's elevation ``Z`` is bracketed: ``h_k - Z`` is at least a hit and
  below a crossing over, the pair split where the fewest of the panel's hits and
  crossings contradict its top (:func:`_top_edges`: the wall just above a shallow
  beacon puts a hit or two over it). A beacon's panels are crossed by the same
  rings, so per beacon the brackets of its panels are intersected into one
  observation of ``Z``: the middle, with the variance of a uniform over the width,
  and the beams' angular error at the two ends (:data:`BEAM_ANGLE_SIGMA`); its
  derivatives by all six parameters are those of the two rays that set its ends. The
  rays are chosen at the start of each adjustment and kept through its iterations
  (chosen again, and the adjustment run again, until the choice holds, at most six
  times: :attr:`Adjustment3D.settled`); a beacon's bracket that fails its w-test
  against the others is left out. Where the choice alternates between two, each
  chosen at the pose the other adjusts to, the pose is the two adjustments' mean and
  its covariance their equal mixture's (:attr:`Adjustment3D.mixed`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core._kernels import assigns3d, brackets3d, gauss_newton3d, rays3d, top_edges3d
from mast.core.beacon import Survey
from mast.core.frames import yaw_of_azimuth
from mast.core.pose import normalize_azimuth
from mast.core.pose3d import Pose3D, rotation_rpy
from mast.core.quantiles import chi2_sf
from mast.core.stats import w_critical

__all__ = ["Adjustment3D", "PanelPlanes", "adjust_pose"]

#: Order of the parameters in :attr:`Adjustment3D.covariance` (as the record names them).
PARAMETERS = ("easting_m", "northing_m", "elevation_m", "roll_rad", "pitch_rad", "azimuth_rad")
#: Variance of the elevation when no top edge brackets it: not observed (m²).
UNBRACKETED = 1e6
#: How far out from its wall past its beacon's panels a floor's lowest returns must
#: reach (their 90th percentile), metres. Of the 881 floors the test found by beacons
#: standing out, at the true poses of 240 frames (seed 3000; VLP-16 and OS1-64, at 2 cm
#: and at 3 cm with look-alikes), the 75 false ones (a beacon's own panels and its wall
#: at the lidar's lowest rings, 0.8 to 1.7 m above the floor) reached 0.02 m past its
#: panels at most; 11 of the 806 true ones reached less than 0.1 m past (a floor seen
#: under the beacon alone).
FLOOR_PAST_M = 0.1
#: The share of the gate a panel return must be within to bracket its top (the gate is
#: four range sigmas: this is 2.5, which a hit's noise across the panel passes 99 % of
#: the time).
HIT_SHARE = 0.625
#: How far rough rock may bulge from a beacon's wall towards its panels' planes near a
#: free end, where a return on it may pass for a panel's top hit, metres.
ROCK_M = 0.05
#: The lines at a panel's bottom or top stand behind it (:func:`_behind`) where their
#: hits' mean lies beyond its plane by more than this many gates over the root of their
#: count (three sigmas of the mean: one such test of the panel's own returns takes them
#: for the wall behind once in 700), and each of them leans behind it, its own mean
#: beyond the plane by more than BEHIND_LEAN_GATES gates over the root of its count
#: (one sigma: three lines of a wall 4.5 cm behind would otherwise take ten of the
#: panel's own with them in the pooled mean).
BEHIND_GATES = 0.75
BEHIND_LEAN_GATES = 0.25
#: A return whose ray is nearer than this to grazing its panel, degrees, is no panel
#: return for the adjustment (:func:`_grazing`) nor for the bound
#: (:mod:`mast.pipeline.bounds3d`), as in 2D
#: (:data:`mast.pipeline.adjustment.MIN_INCIDENCE_COS`). 3 to 5 deg, tried, trade one
#: wrong fix for others (docs/3d.md).
GRAZING_DEG = 2.0
#: Its cosine of incidence: a return whose ray's is below it is left out.
GRAZING_COS = math.sin(math.radians(GRAZING_DEG))
#: A panel is seen down to its this-many-th lowest return of its middle half
#: (:meth:`PanelPlanes.seen`).
SEEN_NTH = 3
#: A lidar beam's angular error (one sigma, radians): the height of a top edge's bracket
#: ends is a ray's direction's, known to this times its range.
BEAM_ANGLE_SIGMA = 5e-4


@dataclass(frozen=True, slots=True)
class PanelPlanes:
    """Every surveyed panel as a vertical plane, in survey order.

    ``normal`` (k, 2) unit horizontal normals and ``offset`` (k,) with ``n · X = d``
    on the plane; ``start`` (k, 2) and ``along`` (k, 2) the first edge and the unit
    direction to the second, ``length`` (k,); ``top`` (k,) the top's elevation
    (NaN where the survey has none); ``beacon`` and ``panel`` (1..3) name them."""

    normal: NDArray[np.float64]
    offset: NDArray[np.float64]
    start: NDArray[np.float64]
    along: NDArray[np.float64]
    length: NDArray[np.float64]
    top: NDArray[np.float64]
    beacon: tuple[str, ...]
    panel: tuple[int, ...]
    wall_sine: NDArray[np.float64]
    """(k, 2): at each end of a panel, the sine of its angle to the beacon's chord e1-e4
    (the wall's direction) where that end is the beacon's free end (e1 of P1, e4 of
    P3); infinite at a joint. Near a wall end the wall above and below a panel is
    within a gate of its plane for gate / sine: those returns are not the panel's.
    At a joint the returns within the gate of both panels' planes are neither's, unless
    only one of the two turns its face to the sensor (:attr:`front`)."""
    front: NDArray[np.float64]
    """(k,): the side of each panel's plane, as the sign of ``n · X - d``, its face turns
    to: the side of the chord e1-e4 its beacon's middle edges e2 and e3 stand out to (a
    beacon stands on its wall, so its faces turn to the drift: the panels' normals turn
    with the polyline, each on the same side of it as the chord's). 0 where the middle
    edges lie within a centimetre of the chord, with no side told. Near a joint, a
    return within the gate of a panel turning its face to the sensor and of one turned
    away is the first's: there the one turned away is behind it (past a free end, where
    rough rock may leave a gap, the back of a panel may be seen: its returns are kept)."""
    wall: NDArray[np.float64]
    """(k, 3): the wall each panel's beacon is mounted on, the vertical plane through its
    free ends e1 and e4, as (nx, ny, d) with ``n · X = d``. A shallow beacon's middle
    panel, or any panel near a free end, is within the gate of the wall above and below
    it: a return nearer the wall is the wall's."""
    depth: NDArray[np.float64]
    """(k,): how far out from its wall, to the side :attr:`front` tells, each panel's
    beacon reaches (the furthest of its edges), metres; 0 where ``front`` is."""

    @classmethod
    def of(cls, survey: Survey) -> PanelPlanes:
        starts, alongs, lengths, tops, ids, panels, sines = [], [], [], [], [], [], []
        walls: list[tuple[float, float, float]] = []
        fronts: list[float] = []
        depths: list[float] = []
        for b in survey:
            chord = b.edges[3] - b.edges[0]
            chord = chord / np.hypot(*chord)
            wall = np.array([chord[1], -chord[0]])
            walls += [(wall[0], wall[1], float(wall @ b.edges[0]))] * 3
            bulge = float(wall @ (0.5 * (b.edges[1] + b.edges[2]) - b.edges[0]))
            front = 0.0 if abs(bulge) < 0.01 else math.copysign(1.0, bulge)
            fronts += [front] * 3
            depths += [float(np.max(front * ((b.edges - b.edges[0]) @ wall)))] * 3  # 0 if no side
            for k in range(3):
                a, c = b.edges[k], b.edges[k + 1]
                u = c - a
                length = float(np.hypot(*u))
                sine = abs(float(u[0] * chord[1] - u[1] * chord[0])) / length
                sines.append((sine if k == 0 else math.inf, sine if k == 2 else math.inf))
                starts.append(a)
                alongs.append(u / length)
                lengths.append(length)
                z = b.elevations
                tops.append(np.nan if z is None else 0.5 * float(z[k] + z[k + 1]))
                ids.append(b.id)
                panels.append(k + 1)
        start = np.array(starts, dtype=float).reshape(-1, 2)
        along = np.array(alongs, dtype=float).reshape(-1, 2)
        normal = np.stack([along[:, 1], -along[:, 0]], axis=1)
        return cls(
            normal=normal,
            offset=np.einsum("ij,ij->i", normal, start),
            start=start,
            along=along,
            length=np.array(lengths),
            top=np.array(tops),
            beacon=tuple(ids),
            panel=tuple(panels),
            wall_sine=np.array(sines, dtype=float).reshape(-1, 2),
            wall=np.array(walls, dtype=float).reshape(-1, 3),
            front=np.array(fronts, dtype=float),
            depth=np.array(depths, dtype=float),
        )

    def crossing(
        self, k: int, origin: NDArray[np.float64], rel: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Where the rays from ``origin`` to ``origin + rel`` (n, 3) cross panel ``k``'s
        plane: how far along each ray (1 at its return), how far along the panel from
        its first edge, and at what elevation."""
        n = self.normal[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (self.offset[k] - origin[:2] @ n) / (rel[:, :2] @ n)
        cross = origin + s[:, None] * rel
        return s, (cross[:, :2] - self.start[k]) @ self.along[k], cross[:, 2]

    def assign(
        self,
        grid: NDArray[np.float64],
        origin: NDArray[np.float64],
        gate_m: float,
        *,
        top_margin_m: float = math.inf,
        clear_m: float | None = None,
        bottoms: NDArray[np.float64] | None = None,
        reach_m: float = math.inf,
        ceilings: NDArray[np.float64] | None = None,
        local: list[NDArray[np.intp]] | None = None,
        boxes: NDArray[np.float64] | None = None,
    ) -> NDArray[np.intp]:
        """The panel each grid point (n, 3), seen from the sensor at ``origin``, lies
        on, or -1 (looking at each panel's :meth:`local` points only, where given):

        * within ``gate_m`` of its plane along its ray (where the ray crosses, not where
          the return lies: a return's range noise moves it along its ray, and choosing
          by its own place would keep, near an end, those whose noise pointed one way);
        * the ray crossing it inside the panel's plan extent, kept clear of the wall at
          a free end by ``clear_m`` (twice the gate unless given) over
          :attr:`wall_sine`;
        * not above its top by more than ``top_margin_m`` where the top is known, not
          below ``bottoms`` nor above ``ceilings`` (per panel, where given and finite:
          the survey has no bottom edge, the data do), and within ``reach_m`` of the
          sensor's height (a tilt's error moves a return by its height times it);
        * within the gate of no other panel's plane inside its extent (whatever the
          heights), or of none turning its face to the sensor (:meth:`facing`) where
          the panel does; and nearer the panel's plane than its beacon's wall
          (:attr:`wall`), unless it crosses the panel between ``boxes`` (per panel: the
          heights its returns show it at, :meth:`seen`) and its top, each
          ``top_margin_m`` inside, where the panel hides the wall."""
        o = np.asarray(origin, dtype=float).reshape(3)
        rays = self._rays(grid - o, o, local or self._everywhere(len(grid)))
        return self._assign(
            rays, grid, gate_m, top_margin_m=top_margin_m, clear_m=clear_m, bottoms=bottoms,
            reach_m=reach_m, ceilings=ceilings, boxes=boxes,
        )  # fmt: skip

    def _assign(
        self,
        rays: _Rays,
        grid: NDArray[np.float64],
        gate_m: float,
        *,
        top_margin_m: float = math.inf,
        clear_m: float | None = None,
        bottoms: NDArray[np.float64] | None = None,
        reach_m: float = math.inf,
        ceilings: NDArray[np.float64] | None = None,
        boxes: NDArray[np.float64] | None = None,
    ) -> NDArray[np.intp]:
        """:meth:`assign` on the pairs of returns and panels of ``rays``."""
        clear = 2.0 * gate_m if clear_m is None else clear_m
        return self._assigns(
            rays, grid, gate_m, (clear,), top_margin_m=top_margin_m, bottoms=bottoms,
            reach_m=reach_m, ceilings=ceilings, boxes=boxes,
        )[0]  # fmt: skip

    def _assigns(
        self,
        rays: _Rays,
        grid: NDArray[np.float64],
        gate_m: float,
        clears_m: Sequence[float],
        *,
        top_margin_m: float = math.inf,
        bottoms: NDArray[np.float64] | None = None,
        reach_m: float = math.inf,
        ceilings: NDArray[np.float64] | None = None,
        boxes: NDArray[np.float64] | None = None,
    ) -> list[NDArray[np.intp]]:
        """:meth:`_assign` with each of the clearances ``clears_m`` from the free ends,
        the gate and the heights' cuts made once for all. Where ``boxes`` (per panel, from
        :meth:`seen`) and the top are known, a crossing between them, each ``top_margin_m``
        inside, is the panel's without the wall test. In one compiled pass
        (:meth:`_assigns_reference` in numpy)."""
        if not clears_m:
            return []
        cap = np.full(len(self), math.inf)
        if math.isfinite(top_margin_m):
            cap = np.where(np.isfinite(self.top), self.top + top_margin_m, math.inf)
        if ceilings is not None:
            cap = np.minimum(cap, np.where(np.isfinite(ceilings), ceilings, math.inf))
        floor = cap if bottoms is None else np.where(np.isfinite(bottoms), bottoms, -math.inf)
        inner = above = cap
        boxed = boxes is not None and math.isfinite(top_margin_m)
        if boxes is not None and boxed:
            inner = np.fmin(self.top, cap) - top_margin_m
            inner = np.where(np.isfinite(boxes) & np.isfinite(self.top), inner, -math.inf)
            above = boxes + top_margin_m
        extents = [self._inside_all(clear) for clear in clears_m]
        out = assigns3d(
            rays.i, rays.k, rays.s, rays.t, rays.z, rays.reach, grid, gate_m,
            float(rays.origin[2]), reach_m, cap, bool(np.isfinite(cap).any()), floor,
            bottoms is not None, inner, above, boxed, self.facing(rays.origin),
            np.array([lo for lo, _ in extents]), np.array([hi for _, hi in extents]),
            self.wall, self.normal, self.offset,
        )  # fmt: skip
        return list(out)

    def _assigns_reference(
        self,
        rays: _Rays,
        grid: NDArray[np.float64],
        gate_m: float,
        clears_m: Sequence[float],
        *,
        top_margin_m: float = math.inf,
        bottoms: NDArray[np.float64] | None = None,
        reach_m: float = math.inf,
        ceilings: NDArray[np.float64] | None = None,
        boxes: NDArray[np.float64] | None = None,
    ) -> list[NDArray[np.intp]]:
        """The numpy reference of :meth:`_assigns` (of
        :func:`mast.core._kernels.assigns3d`)."""
        s = rays.s
        # how far along its ray the return lies from the plane: its range error, were
        # it on the panel (a gate on it keeps both signs of the noise alike)
        gated = np.flatnonzero((np.abs(1.0 - s) * rays.reach[rays.i] < gate_m) & (s > 0))
        k, i, t, z = rays.k[gated], rays.i[gated], rays.t[gated], rays.z[gated]
        cut = np.ones(len(k), dtype=np.bool_)  # the heights allowed
        if math.isfinite(reach_m):
            cut &= np.abs(z - rays.origin[2]) <= reach_m
        # each panel's highest and lowest crossing allowed (infinite: none)
        cap = np.full(len(self), math.inf)
        if math.isfinite(top_margin_m):
            cap = np.where(np.isfinite(self.top), self.top + top_margin_m, math.inf)
        if ceilings is not None:
            cap = np.minimum(cap, np.where(np.isfinite(ceilings), ceilings, math.inf))
        if np.isfinite(cap).any():
            cut &= z <= cap[k]
        if bottoms is not None:
            floor = np.where(np.isfinite(bottoms), bottoms, -math.inf)
            cut &= z >= floor[k]
        # crossing a panel between the heights its returns show it at (``boxes``) and its
        # top, each less the margin, a ray meets the panel, not the wall behind it (the
        # plate hides the wall there): no wall test, whose choice by the return's own
        # place would keep the noise that points one way
        boxed = np.zeros(len(k), dtype=np.bool_)
        if boxes is not None and math.isfinite(top_margin_m):
            inner = np.fmin(self.top, cap) - top_margin_m
            inner = np.where(np.isfinite(boxes) & np.isfinite(self.top), inner, -math.inf)
            boxed = (z < inner[k]) & (z > boxes[k] + top_margin_m)
        n = len(grid)
        turned = self.facing(rays.origin)[k]
        out = []
        for clear in clears_m:
            lo, hi = self._inside_all(clear)
            # the panels whose plane (within the gate) and extent a return is on: it is
            # one of theirs, or neither's (their heights are the beacon's, not one
            # panel's: cut off one by a height, a return is not its neighbour's for that)
            near = (t > lo[k]) & (t < hi[k])
            on = near & cut
            # near a joint, within the gate of two panels: neither's, unless one only
            # turns its face to the sensor (the other is behind it there)
            facing = np.bincount(i[near & turned], minlength=n)[i]
            either = np.bincount(i[near], minlength=n)[i]
            on &= np.where(facing > 0, turned & (facing == 1), either == 1)
            which = np.full(n, -1, dtype=np.intp)
            which[i[on]] = k[on]
            tested = np.zeros(n, dtype=np.bool_)
            tested[i[on & ~boxed]] = True
            mine = np.flatnonzero(tested)  # nearer its beacon's wall than it: the wall's
            ks, xy = which[mine], np.take(grid, mine, axis=0)[:, :2]
            wall = np.take(self.wall, ks, axis=0)
            to_wall = np.abs(np.einsum("ij,ij->i", xy, wall[:, :2]) - wall[:, 2])
            to_panel = np.abs(
                np.einsum("ij,ij->i", xy, np.take(self.normal, ks, axis=0)) - self.offset[ks]
            )
            which[mine[to_wall < to_panel]] = -1
            out.append(which)
        return out

    def _pairs(self, lists: Sequence[NDArray[np.intp]]) -> _Pairs:
        """Each return paired with the panels whose ``lists`` (one per panel) name it."""
        if isinstance(lists, _Local):
            return lists.pairs
        i = np.concatenate(lists).astype(np.intp) if len(lists) else np.zeros(0, np.intp)
        k = np.repeat(np.arange(len(lists), dtype=np.intp), [len(idx) for idx in lists])
        return _Pairs(i, k, self.normal[k].T.copy(), self.along[k].T.copy())

    def _paired(self, lists: Sequence[NDArray[np.intp]]) -> _Local:
        """Each panel's ``lists`` of returns (:meth:`local`), carrying their pairs."""
        return _Local(lists, self._pairs(lists))

    def _rays(
        self,
        rel: NDArray[np.float64],
        origin: NDArray[np.float64],
        pairs: _Pairs | Sequence[NDArray[np.intp]],
    ) -> _Rays:
        """The rays from ``origin`` to the returns ``origin + rel`` (n, 3), each return
        paired with the panels ``pairs`` name (or whose lists, one per panel, name it),
        and where each pair's ray crosses its panel's plane (as :meth:`crossing`)."""
        o = np.asarray(origin, dtype=float).reshape(3)
        if not isinstance(pairs, _Pairs):
            pairs = self._pairs(pairs)
        s, t, z = rays3d(rel, o, pairs.i, pairs.k, self.normal, self.offset, self.start, self.along)
        return _Rays(o, rel, pairs.i, pairs.k, s, t, z)

    def _rays_reference(
        self, rel: NDArray[np.float64], origin: NDArray[np.float64], pairs: _Pairs
    ) -> _Rays:
        """The numpy reference of :meth:`_rays` (of :func:`mast.core._kernels.rays3d`)."""
        o = np.asarray(origin, dtype=float).reshape(3)
        k = pairs.k
        (nx, ny), (ax, ay) = pairs.normal, pairs.along
        r = np.take(rel, pairs.i, axis=0)  # a 2D array's rows: take is 4x fancy indexing
        rx, ry = r[:, 0], r[:, 1]
        plane = (self.offset - self.normal @ o[:2])[k]
        ahead = ((o[:2] - self.start) * self.along).sum(axis=1)[k]  # the sensor along it
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            s = plane / (rx * nx + ry * ny)
            z = o[2] + s * r[:, 2]
            t = ahead + s * (rx * ax + ry * ay)
        return _Rays(o, rel, pairs.i, k, s, t, z)

    def _own(self, rays: _Rays, which: NDArray[np.intp]) -> tuple[_Rays, NDArray[np.intp]]:
        """Rays holding each return ``which`` gives a panel paired with that panel
        (``rays`` where it does), and those pairs (grouped by panel)."""
        j = np.flatnonzero(rays.k == which[rays.i])
        if j.size != np.count_nonzero(which >= 0):
            rays = self._rays(rays.rel, rays.origin, _panel_lists(which, len(self)))
            j = np.arange(len(rays.k))
        return rays, j

    def _inside_all(
        self, clear_m: float, least_m: float | NDArray[np.float64] = 0.0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`inside` for every panel at once (``least_m`` one or one per panel)."""
        lo = np.maximum(least_m, clear_m / np.maximum(self.wall_sine[:, 0], 0.2))
        hi = self.length - np.maximum(least_m, clear_m / np.maximum(self.wall_sine[:, 1], 0.2))
        return lo, hi

    def __len__(self) -> int:
        return len(self.beacon)

    def facing(self, origin: NDArray[np.float64]) -> NDArray[np.bool_]:
        """(k,): whether each panel turns its face to a sensor at ``origin`` (a panel
        with no side told does, :attr:`front`)."""
        side = self.normal @ np.asarray(origin, dtype=float)[:2] - self.offset
        return np.asarray(self.front * side >= 0.0)

    def inside(self, k: int, clear_m: float, least_m: float = 0.0) -> tuple[float, float]:
        """Where along panel ``k`` (from its first edge) the wall at a free end is more
        than ``clear_m`` off its plane: ``clear_m`` over :attr:`wall_sine` in from each
        free end (a sine below 0.2 taken as 0.2), and at least ``least_m`` in from
        either end."""
        lo = max(least_m, clear_m / max(float(self.wall_sine[k, 0]), 0.2))
        hi = self.length[k] - max(least_m, clear_m / max(float(self.wall_sine[k, 1]), 0.2))
        return lo, hi

    def local(self, grid: NDArray[np.float64], margin_m: float) -> list[NDArray[np.intp]]:
        """Per panel, the grid points (n, 2 or 3) within ``margin_m`` of it in plan: all
        its assignment, bottom, top edges and checks could use (the wall just behind
        it included), so that they need not look at the rest of a frame. A beacon's
        box, grown by the margin, is looked in first."""
        return self._local(grid, margin_m)[0]

    def _local(
        self, grid: NDArray[np.float64], margin_m: float
    ) -> tuple[list[NDArray[np.intp]], list[NDArray[np.float64]]]:
        """:meth:`local`, and each of its points' squared distance from its panel."""
        xy = np.asarray(grid, dtype=float)[:, :2]
        x, y = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
        out: list[NDArray[np.intp]] = []
        far: list[NDArray[np.float64]] = []
        boxes: dict[str, tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]] = {}
        for k in range(len(self)):
            b = self.beacon[k]
            if b not in boxes:
                mine = [j for j in range(len(self)) if self.beacon[j] == b]
                ends = np.vstack(
                    [
                        self.start[mine],
                        self.start[mine] + self.along[mine] * self.length[mine, None],
                    ]
                )
                lo, hi = ends.min(axis=0) - margin_m, ends.max(axis=0) + margin_m
                box = np.flatnonzero((x >= lo[0]) & (x <= hi[0]))
                across = y[box]
                box = box[(across >= lo[1]) & (across <= hi[1])]
                boxes[b] = box, x[box], y[box]
            idx, bx, by = boxes[b]
            (sx, sy), (ax, ay) = self.start[k], self.along[k]
            dx, dy = bx - sx, by - sy
            t = np.clip(dx * ax + dy * ay, 0.0, self.length[k])
            gx, gy = dx - t * ax, dy - t * ay
            square = gx * gx + gy * gy
            close = square <= margin_m**2
            out.append(idx[close])
            far.append(square[close])
        return out, far

    def _everywhere(self, n: int) -> list[NDArray[np.intp]]:
        every = np.arange(n)
        return [every] * len(self)

    def floors(
        self, grid: NDArray[np.float64], about: list[NDArray[np.intp]]
    ) -> NDArray[np.float64]:
        """Each panel's floor: the lowest of the grid points (n, 3) ``about`` it (its
        :meth:`local` points, a metre or two about; their 2nd percentile, against stray
        low returns: the floor, or the wall's foot); NaN for a panel with fewer than 50,
        or where those lowest returns do not spread out from its beacon's wall by 30 cm
        (the lowest ring on a wall is a line along it, and no floor), or, for a beacon
        that stands out from its wall, where they reach no further out than its panels
        do, by :data:`FLOOR_PAST_M` (a beacon at the lidar's lowest rings is seen no lower
        than its own panels, which stand out from the wall and would pass for a floor). A
        beacon stands on no floor: near its plane's foot the floor is within the gate of
        the plane, and is no panel's."""
        return self._floors(
            np.ascontiguousarray(grid[:, 2]), lambda idx: np.take(grid, idx, axis=0)[:, :2], about
        )

    def _floors(
        self,
        height: NDArray[np.float64],
        plan: Callable[[NDArray[np.intp]], NDArray[np.float64]],
        about: list[NDArray[np.intp]],
    ) -> NDArray[np.float64]:
        """:meth:`floors` from the points' ``height`` (n,) and ``plan``, their places in
        plan ((m, 2), of the points' indices it is given)."""
        out = np.full(len(self), np.nan)
        side = self.front
        for k, close in enumerate(about):
            if close.size < 50:
                continue
            z = height[close]
            low = float(np.partition(z, len(z) // 50)[len(z) // 50])  # its 2nd percentile
            # a floor spreads out from the wall; the lowest ring on a wall is a line
            lowest = close[np.abs(z - low) < 0.05]
            n = lowest.size
            if n < 20:
                continue
            ends = (n // 10, (9 * n) // 10 - 1)  # its 10th and 90th percentiles
            across = np.partition(plan(lowest) @ self.wall[k, :2], ends)
            if across[ends[1]] - across[ends[0]] <= 0.3:
                continue
            # the 90th percentile out from the wall, on the side the panels stand out to
            reach = side[k] * (across[ends[1] if side[k] > 0.0 else ends[0]] - self.wall[k, 2])
            if side[k] == 0.0 or reach > self.depth[k] + FLOOR_PAST_M:
                out[k] = low
        return out

    def ceilings(
        self,
        grid: NDArray[np.float64],
        origin: NDArray[np.float64],
        which: NDArray[np.intp],
        margin_m: float,
    ) -> NDArray[np.float64]:
        """Each panel's highest crossing among the returns ``which`` gives it, plus
        ``margin_m``; NaN for a panel without returns. With a tight gate, the wall just
        above a panel (behind it by the beacon's depth) is no hit, and no ray crosses
        the panel between its highest hit and its top."""
        o = np.asarray(origin, dtype=float).reshape(3)
        return self._ceilings(
            self._rays(grid - o, o, _panel_lists(which, len(self))), which, margin_m
        )

    def _ceilings(
        self, rays: _Rays, which: NDArray[np.intp], margin_m: float
    ) -> NDArray[np.float64]:
        """:meth:`ceilings` with the crossings of ``rays``."""
        rays, j = self._own(rays, which)
        return _per_panel(rays.k[j], rays.z[j], len(self), np.maximum, np.nan) + margin_m

    def misfits(
        self,
        grid: NDArray[np.float64],
        origin: NDArray[np.float64],
        which: NDArray[np.intp],
        gate_m: float,
        local: list[NDArray[np.intp]] | None = None,
        below: NDArray[np.float64] | None = None,
        lines: NDArray[np.intp] | None = None,
    ) -> NDArray[np.intp]:
        """Per panel, the rays (its :meth:`local` ones, where given) that cross it and
        do not fit it: crossing its plane well inside its plan extent (:meth:`inside`
        the gate) between its lowest and highest hits (and, where ``below`` gives a
        height for the panel, below it: its surveyed top, where the elevation is known)
        twice the gate clear of a free end
        (:meth:`inside`: near one the wall just below or above a panel is within the
        gate of its plane, and one such return would open the window to rays that pass
        under or over the panel; a panel with no such hit, a short end panel at a
        shallow angle to its wall, is not looked at), and returning from beyond the
        plane by more than the gate, or from in front of it by more than the gate but
        within three (nearer still, something stands in front of it) on no other panel
        (``which``: a return on another panel is a beam that panel stopped). A panel where the
        pose puts it is hit by every such ray (a range noise beyond four sigmas aside);
        a panel put where it is not is seen through, and one put tilted is missed at its
        top or bottom (the beam verification of 2D, in 3D). Where ``lines`` gives each
        return's line (ring), the lowest and highest hits are those of the lines left
        when the panel's lowest and highest lines whose hits stand behind it are dropped
        (:func:`_behind`), as long as a line is left."""
        o = np.asarray(origin, dtype=float).reshape(3)
        rays = self._rays(grid - o, o, local or self._everywhere(len(grid)))
        return self._misfits(rays, which, gate_m, below, lines)

    def _misfits(
        self,
        rays: _Rays,
        which: NDArray[np.intp],
        gate_m: float,
        below: NDArray[np.float64] | None = None,
        lines: NDArray[np.intp] | None = None,
    ) -> NDArray[np.intp]:
        """:meth:`misfits` with the crossings of ``rays``."""
        own, j = self._own(rays, which)
        clear_lo, clear_hi = self._inside_all(2.0 * gate_m)  # clear of a free end's wall
        j = j[(own.t[j] > clear_lo[own.k[j]]) & (own.t[j] < clear_hi[own.k[j]])]
        if lines is not None and j.size:
            off = (1.0 - own.s[j]) * own.reach[own.i[j]]
            j = j[~_behind(own.k[j], lines[own.i[j]], own.z[j], off, gate_m)]
        low = _per_panel(own.k[j], own.z[j], len(self), np.minimum, math.inf)
        high = _per_panel(own.k[j], own.z[j], len(self), np.maximum, -math.inf)
        if below is not None:
            high = np.fmin(high, below)  # NaN: no height given
        k, s, t, z = rays.k, rays.s, rays.t, rays.z
        lo, hi = self._inside_all(gate_m, 0.05)
        off = (1.0 - s) * rays.reach[rays.i]  # along the ray: > 0 beyond the plane
        across = (t > lo[k]) & (t < hi[k]) & (z > low[k]) & (z < high[k]) & (s > 0)
        # in front of the panel on another panel (a deep beacon's middle panel before an
        # end panel, seen from the side): the beam was stopped by a panel where the pose
        # puts that one, and says nothing against this one
        other = which[rays.i]
        shaded = (other >= 0) & (other != k)
        bad = across & ((off > gate_m) | (off < -gate_m) & (off > -3.0 * gate_m) & ~shaded)
        return np.bincount(k[bad], minlength=len(self)).astype(np.intp)

    def bottoms(
        self,
        grid: NDArray[np.float64],
        origin: NDArray[np.float64],
        which: NDArray[np.intp],
        margin_m: float,
    ) -> NDArray[np.float64]:
        """Each panel's bottom as its returns show it: the lowest crossing of the middle
        half of the panel (where no wall is near its plane) less ``margin_m``; NaN for a
        panel without returns there. Near a free end the wall below a panel is within
        the gate of its plane; below this it is not taken for the panel."""
        o = np.asarray(origin, dtype=float).reshape(3)
        rays = self._rays(grid - o, o, _panel_lists(which, len(self)))
        return self._lows(rays, grid, which, margin_m)[0]

    def seen(
        self, grid: NDArray[np.float64], origin: NDArray[np.float64], which: NDArray[np.intp]
    ) -> NDArray[np.float64]:
        """Each panel's lowest height its returns show it at: the :data:`SEEN_NTH`-th
        lowest crossing of the middle half of the panel (one return of the wall just
        below, let through by its noise, does not lower it; :meth:`assign`'s
        ``boxes``); NaN for a panel with fewer returns there."""
        o = np.asarray(origin, dtype=float).reshape(3)
        rays = self._rays(grid - o, o, _panel_lists(which, len(self)))
        return self._lows(rays, grid, which, 0.0)[1]

    def _lows(
        self, rays: _Rays, grid: NDArray[np.float64], which: NDArray[np.intp], margin_m: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`bottoms` (less ``margin_m``) and :meth:`seen`, with the crossings of
        ``rays``, from one look at the panels' middle halves."""
        k, z = self._middle(rays, grid, which)
        bottoms = _per_panel(k, z, len(self), np.minimum, np.nan) - margin_m
        seen = np.full(len(self), np.nan)
        if k.size:
            order = np.lexsort((z, k))
            k, z = k[order], z[order]
            first, count = _runs(k)
            enough = count >= SEEN_NTH
            seen[k[first[enough]]] = z[first[enough] + SEEN_NTH - 1]
        return bottoms, seen

    def _middle(
        self, rays: _Rays, grid: NDArray[np.float64], which: NDArray[np.intp]
    ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """The panels and crossing heights of the returns ``which`` gives a panel in
        the middle half of it, where no wall is near its plane."""
        rays, j = self._own(rays, which)
        k, i = rays.k[j], rays.i[j]
        start, along = self.start[k], self.along[k]
        t = (grid[i, 0] - start[:, 0]) * along[:, 0] + (grid[i, 1] - start[:, 1]) * along[:, 1]
        mid = np.abs(t - self.length[k] / 2) < self.length[k] / 4
        return k[mid], rays.z[j[mid]]


@dataclass(slots=True)
class _Rays:
    """The rays from the sensor at ``origin`` to returns ``origin + rel`` (n, 3), of
    range ``reach`` (n,), each paired with the panels it is looked at for (as
    :class:`_Pairs`); ``s``, ``t`` and ``z`` where each pair's ray crosses its panel's
    plane (:meth:`PanelPlanes.crossing`). One pose's crossings, for all that looks at
    them."""

    origin: NDArray[np.float64]
    rel: NDArray[np.float64]
    i: NDArray[np.intp]
    k: NDArray[np.intp]
    s: NDArray[np.float64]
    t: NDArray[np.float64]
    z: NDArray[np.float64]
    _reach: NDArray[np.float64] | None = None

    @property
    def reach(self) -> NDArray[np.float64]:
        """Each return's range (n,)."""
        if self._reach is None:
            self._reach = np.linalg.norm(self.rel, axis=1)
        return self._reach


@dataclass(frozen=True, slots=True)
class _Pairs:
    """Returns paired with the panels each is looked at for: pair j is return ``i[j]``
    and panel ``k[j]``, grouped by panel; that panel's ``normal`` and ``along`` (2, m)."""

    i: NDArray[np.intp]
    k: NDArray[np.intp]
    normal: NDArray[np.float64]
    along: NDArray[np.float64]


class _Local(list[NDArray[np.intp]]):
    """Each panel's :meth:`PanelPlanes.local` returns, carrying their :class:`_Pairs`
    (built once for every pose and adjustment that looks at them)."""

    def __init__(self, lists: Sequence[NDArray[np.intp]], pairs: _Pairs) -> None:
        super().__init__(lists)
        self.pairs = pairs


def _panel_lists(which: NDArray[np.intp], panels: int) -> list[NDArray[np.intp]]:
    """Per panel, the returns ``which`` gives it, in their order."""
    order = np.argsort(which, kind="stable")
    ends = np.searchsorted(which[order], np.arange(panels + 1) - 0.5)
    return [order[ends[k] : ends[k + 1]] for k in range(panels)]


def _per_panel(
    k: NDArray[np.intp],
    values: NDArray[np.float64],
    panels: int,
    reduce: np.ufunc,
    empty: float,
) -> NDArray[np.float64]:
    """``reduce`` (np.minimum, np.maximum) of ``values`` per panel ``k`` (grouped by
    panel), ``empty`` for a panel with none."""
    out = np.full(panels, empty)
    if k.size:
        first, _ = _runs(k)
        out[k[first]] = reduce.reduceat(values, first)
    return out


def _behind(
    k: NDArray[np.intp],
    line: NDArray[np.intp],
    z: NDArray[np.float64],
    off: NDArray[np.float64],
    gate_m: float,
) -> NDArray[np.bool_]:
    """Which hits (panel ``k``, line ``line``, crossing at height ``z``, ``off`` beyond
    the plane along the ray, finite) are on the lines at a panel's bottom or top whose
    hits stand behind it: the most lines from the lowest up (and from the highest
    down), each leaning behind it (:data:`BEHIND_LEAN_GATES`), whose hits' mean lies
    beyond the plane by more than :data:`BEHIND_GATES` gates over the root of their
    count. Below or above a shallow panel, the wall behind it lies within the gate of
    its plane, and a ring there puts the returns its noise brings within the gate on
    the panel and the others beyond it; those lines open the beam test's window to rays
    that miss the panel for no fault of the pose (a middle panel 0.29 m wide had 107
    such misfits at a fix 0.6 sigma off, its five lowest lines' 16 hits 4.5 cm behind
    it on average). A panel put tilted is missed at its bottom or top by rays whose
    lines' hits are its own, which do not lean behind it; where the lines dropped from
    either end would be all of a panel's, none is (a panel put where it is not is seen
    through on every line)."""
    out = np.zeros(len(k), dtype=np.bool_)
    if not len(k):
        return out
    order = np.lexsort((line, k))
    ks, ls = k[order], line[order] - line.min()
    first, count = _runs(ks * (int(ls.max()) + 1) + ls)  # each (panel, line)
    total = np.add.reduceat(off[order], first)
    height = np.add.reduceat(z[order], first) / count
    # the lines by panel, and by height within it; the most lines that stand behind
    # from a panel's lowest up (a prefix) and from its highest down (a suffix)
    by = np.lexsort((height, ks[first]))
    panel, n, t = ks[first][by], count[by].astype(float), total[by]
    start, size = _runs(panel)
    group = np.repeat(np.arange(len(start)), size)
    at = np.arange(len(by)) - start[group]  # a line's place in its panel, bottom up
    before_n = np.concatenate([[0.0], np.cumsum(n)])[start][group]
    before_t = np.concatenate([[0.0], np.cumsum(t)])[start][group]
    low_n, low_t = np.cumsum(n) - before_n, np.cumsum(t) - before_t  # lowest to this
    all_n, all_t = np.add.reduceat(n, start)[group], np.add.reduceat(t, start)[group]
    high_n, high_t = all_n - low_n + n, all_t - low_t + t  # this to the highest
    bar = BEHIND_GATES * gate_m
    # only lines each leaning behind the panel, from either end, may be dropped: a few
    # far behind must not take the panel's own lines with them in the pooled mean
    upright = t <= BEHIND_LEAN_GATES * gate_m * np.sqrt(n)
    place = at[upright].astype(float)
    below = _per_panel(group[upright], place, len(start), np.minimum, math.inf)  # lowest
    above = _per_panel(group[upright], place, len(start), np.maximum, -1.0)  # upright line
    ok = (at < below[group]) & (low_t > bar * np.sqrt(low_n))
    lows = np.maximum.reduceat(np.where(ok, at + 1, 0), start)  # dropped from the lowest up
    ok = (at > above[group]) & (high_t > bar * np.sqrt(high_n))
    highs = np.maximum.reduceat(np.where(ok, size[group] - at, 0), start)  # highest down
    some = lows + highs < size  # a line left that does not stand behind
    drop = some[group] & ((at < lows[group]) | (at >= size[group] - highs[group]))
    dropped = np.zeros(len(first), dtype=np.bool_)
    dropped[by] = drop
    out[order] = np.repeat(dropped, count)
    return out


def _runs(keys: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Where each run of equal ``keys`` (grouped, not empty) starts, and its length."""
    first = np.flatnonzero(np.concatenate([[True], keys[1:] != keys[:-1]]))
    return first, np.diff(np.append(first, len(keys)))


def _sorted_medians(
    values: NDArray[np.float64], first: NDArray[np.intp], count: NDArray[np.intp]
) -> NDArray[np.float64]:
    """The median of each run ``values[first:first + count]``, each sorted (as
    np.median: the middle one, or the mean of the middle two)."""
    mid = first + count // 2
    odd = values[mid]
    return np.asarray(np.where(count % 2 == 1, odd, (values[mid - 1] + odd) / 2), dtype=np.float64)


@dataclass(frozen=True, slots=True)
class Adjustment3D:
    """A 3D pose adjusted on panel returns and bracketed by top edges.

    ``covariance`` is 6×6 in :data:`PARAMETERS` order (metres and radians); the
    elevation's variance is :data:`UNBRACKETED` where no top edge bracketed it."""

    pose: Pose3D
    covariance: NDArray[np.float64]
    reference_variance: float
    dof: int
    test_p: float
    """The global test's p-value (the chance of a reference variance this far above 1)."""
    returns: int
    iterations: int
    top_edges: int
    """Beacons whose top edges bracketed the elevation (none: its variance is
    :data:`UNBRACKETED`)."""
    used: NDArray[np.intp] | None = None
    """The panel each return was taken for in the end (``which`` less the returns the
    snooping left out), -1 for none."""
    settled: bool = True
    """Whether the top edges' rays, chosen again at the adjusted pose, held and passed
    their w-test, or alternated between two choices that each passed it (``mixed``):
    otherwise the elevation and the tilt they lever are not known, and a locator should
    not give the fix."""
    mixed: bool = False
    """Whether the top edges' rays alternated between two choices, each chosen at the
    pose the other adjusts to and each passing its w-test: the pose is then the two
    adjustments' mean, and its covariance their equal mixture's (their mean covariance
    plus the outer product of half their difference), which covers either."""


def _derivatives(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """R = Rz(yaw) Ry(pitch) Rx(roll) and its derivatives by roll, pitch and yaw (``R Kx``,
    ``Rz Ry Ky Rx`` and ``Kz R``, K the turns' generators), (4, 3, 3)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    r0 = [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr]  # as rotation_rpy
    r1 = [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr]
    r2 = [-sp, cp * sr, cp * cr]
    return np.array(
        [
            [r0, r1, r2],
            [[0.0, r0[2], -r0[1]], [0.0, r1[2], -r1[1]], [0.0, r2[2], -r2[1]]],
            [
                [-cy * sp, cy * cp * sr, cy * cp * cr],
                [-sy * sp, sy * cp * sr, sy * cp * cr],
                [-cp, -sp * sr, -sp * cr],
            ],
            [[-r1[0], -r1[1], -r1[2]], r0, [0.0, 0.0, 0.0]],
        ]
    )


def _top_edges(
    grid: NDArray[np.float64],
    rel: NDArray[np.float64],
    which: NDArray[np.intp],
    origin: NDArray[np.float64],
    planes: PanelPlanes,
    gate_m: float,
    local: list[NDArray[np.intp]] | None = None,
    inset_m: float = 0.05,
    rays: _Rays | None = None,
) -> list[tuple[int, int, int]]:
    """For each panel with a top, both hit and passed over inside its plan extent: the
    panel, and the hit and the crossing over that bracket its top, heights where the
    rays cross the panel's plane. Of its hits at or above the median of its hits and its
    crossings over above it (a ray crossing under the panel is no evidence of its top),
    the height the fewest of them contradict (hits above it, crossings below; fewer than
    the crossings above it; the lowest such, at a tie) splits them, and the highest hit
    below it and the lowest crossing above it are the bracket (the least return of hits
    at one height, the first pair of crossings). A highest hit alone may be the wall's:
    just above a shallow beacon, a ring or three up, the wall may put a return or two
    within the gate of its plane (a VLP-16 frame's elevation came out a ring off, 0.28 m
    at 41 sigma); a lowest crossing alone may be a stray, a ray that no solid panel lets
    through. ``grid`` the returns in the grid, ``rel`` the same relative to the sensor
    origin ``origin``; the rays over a panel are looked for among its ``local`` ones
    (:meth:`PanelPlanes.local`), where given, or the pairs of ``rays`` (``rel`` from
    ``origin``), where given."""
    if rays is None:
        rays = planes._rays(rel, origin, local or planes._everywhere(len(grid)))
    own, j = planes._own(rays, which)
    n, d = planes.normal, planes.offset
    inset, lo, hi = _top_extents(planes, gate_m, inset_m)
    # a hit well within the gate: the wall just above a panel, behind it by the
    # beacon's depth, may be within the gate, and is no hit
    k, i, t = own.k[j], own.i[j], own.t[j]
    across = grid[i, 0] * n[k, 0] + grid[i, 1] * n[k, 1] - d[k]
    close = (np.abs(across) <= HIT_SHARE * gate_m) & (t > lo[k]) & (t < hi[k])
    close &= np.isfinite(planes.top[k])
    height = own.s[j] * rel[i, 2]
    close &= np.isfinite(height)
    c = np.flatnonzero(close)
    if c.size == 0:
        return []
    k, i, height = k[c], i[c], height[c]
    # each panel's hits by height: their median
    order = np.lexsort((height, k))
    first, count = _runs(k[order])
    middle = np.full(len(planes), math.nan)
    middle[k[order[first]]] = _sorted_medians(height[order], first, count)
    # the crossings over (s: where each ray crosses, 0..1) above it
    ahead = np.flatnonzero(np.isfinite(middle)[rays.k] & (rays.s > 0) & (rays.s < 1))
    ka, ia, s, ta = rays.k[ahead], rays.i[ahead], rays.s[ahead], rays.t[ahead]
    across = grid[ia, 0] * n[ka, 0] + grid[ia, 1] * n[ka, 1] - d[ka]
    side = origin[0] * n[:, 0] + origin[1] * n[:, 1] - d
    over = (ta > inset[ka]) & (ta < planes.length[ka] - inset[ka])
    over &= (across * side[ka] < 0) & (np.abs(across) >= gate_m)
    over_h = s * rel[ia, 2]
    over &= over_h > middle[ka]
    up = height >= middle[k]
    out = []
    for panel in np.unique(ka[over]).tolist():
        mine = up & (k == panel)
        crossing = over & (ka == panel)
        h = np.concatenate([height[mine], over_h[crossing]])
        is_hit = np.concatenate([np.ones(mine.sum(), bool), np.zeros(crossing.sum(), bool)])
        ray = np.concatenate([i[mine], ia[crossing]])
        # by height; at one height, hits first (by return, descending), then crossings
        # by pair
        tie = np.concatenate([-i[mine] - 1, np.arange(crossing.sum())])
        order = np.lexsort((tie, h))
        h, is_hit, ray = h[order], is_hit[order], ray[order]
        # contradictions of a split just below each: the hits from it up, the crossings
        # below it
        wrong = np.cumsum(is_hit[::-1])[::-1] + np.concatenate([[0], np.cumsum(~is_hit)[:-1]])
        split = np.flatnonzero(is_hit[:-1] & ~is_hit[1:] & (h[:-1] < h[1:])) + 1
        # fewer contradictions than crossings over above it
        split = split[wrong[split] < (~is_hit).sum() - np.cumsum(~is_hit)[split - 1]]
        if split.size == 0:
            continue
        best = split[np.argmin(wrong[split])]
        out.append((panel, int(ray[best - 1]), int(ray[best])))
    return out


def _top_extents(
    planes: PanelPlanes, gate_m: float, inset_m: float = 0.05
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Where along each panel :func:`_top_edges` looks: a crossing over ``inset`` (at
    least ``inset_m``, a tenth of the panel) in from either end, a hit between ``lo``
    and ``hi``. Well inside: a ray just past a panel's side passes beside it, not over
    it; and near a free end the wall just above the panel is within the gate of its
    plane (and rough rock bulges towards it by up to :data:`ROCK_M`)."""
    inset = np.maximum(inset_m, 0.1 * planes.length)
    lo, hi = planes._inside_all(gate_m + ROCK_M, inset)
    return inset, lo, hi


def _height_gradients(
    points: NDArray[np.float64],
    rel: NDArray[np.float64],
    s: NDArray[np.float64],
    normal: NDArray[np.float64],
    dR: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
) -> NDArray[np.float64]:
    """How the height ``h = s rel_z`` at which each ray (its return ``points`` (r, 3) in
    the sensor frame, ``rel`` (r, 3) in the grid's axes from the sensor) crosses a
    vertical plane of horizontal ``normal`` (r, 2) changes with (E, N, A, pitch, roll,
    Z), (r, 6): ``s`` (r,) is the plane's distance over the ray's, so moving the sensor
    or turning the ray moves it too."""
    across = rel[:, 0] * normal[:, 0] + rel[:, 1] * normal[:, 1]
    g = np.zeros((len(points), 6))
    g[:, :2] = -(rel[:, 2] / across)[:, None] * normal
    # each ray turned by each angle: turn[:, j] = dR[j] @ point
    turn = (points @ np.concatenate([dRj.T for dRj in dR], axis=1)).reshape(-1, 3, 3)
    sideways = turn[:, :, 0] * normal[:, :1] + turn[:, :, 1] * normal[:, 1:]
    g[:, 2:5] = s[:, None] * turn[:, :, 2] - (s * rel[:, 2])[:, None] * sideways / across[:, None]
    g[:, 2] = -g[:, 2]  # d yaw / d A = -1
    return g


@functools.lru_cache(maxsize=32)
def _beacon_groups(beacon: tuple[str, ...]) -> tuple[tuple[str, ...], NDArray[np.intp]]:
    """The beacons' names, sorted, and each panel's beacon as an index into them."""
    names = tuple(sorted(set(beacon)))
    number = np.array([names.index(b) for b in beacon], dtype=np.intp)
    number.flags.writeable = False
    return names, number


def _brackets(
    tops: list[tuple[int, int, int]],
    p: NDArray[np.float64],
    rel: NDArray[np.float64],
    origin: NDArray[np.float64],
    planes: PanelPlanes,
    dR: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
) -> list[tuple[float, float, NDArray[np.float64]]]:
    """The sensor's elevation bracketed by each beacon's top edges: each panel ``k``
    says ``top_k - crossing over < Z <= top_k - highest hit``; a beacon's panels are
    crossed by the same rings, so their brackets are one piece of evidence, and the
    elevation is in their intersection (where it is uniform, were the hits and
    crossings exact). Per beacon: the middle, its variance (the uniform's over the
    width, or where the ends crossed, over the gap between them: an empty
    intersection is as uncertain as it is wide; and the beams' angular error at its
    ends) and the derivatives of its residual ``Z - middle`` by (E, N, A, pitch,
    roll, Z) (through the two rays that set its ends; ``dR`` R's derivatives by yaw,
    pitch and roll). Heights are where the rays cross the panel's plane, the hit's
    too: a ray's direction carries no range noise. Different beacons are crossed by
    different rings at different ranges: their brackets are independent observations
    (intersecting them too would let a tilt's error cross their ends)."""
    if not tops:
        return []
    edges = _TopEdges.of(tops, planes)
    middle, spread, d = edges.brackets_reference(p[edges.rows], rel[edges.rows], origin, dR)
    return [(float(middle[i]), float(spread[i]), d[i]) for i in range(len(middle))]


@dataclass(frozen=True, slots=True)
class _TopEdges:
    """The top edges (panel, highest hit, lowest crossing over) an adjustment keeps
    through its iterations, for :func:`_brackets`: the returns of their rays ``rows``;
    each top edge's two rays, its hit's and its crossing over's (those of all hits
    first, then those of all crossings over), as indices ``ray`` into ``rows``, with
    their panel's ``normal`` (2, rays), ``offset`` and ``top``; ``member`` (beacons, top
    edges) whose each is, the beacons in name order."""

    rows: NDArray[np.intp]
    ray: NDArray[np.intp]
    normal: NDArray[np.float64]
    offset: NDArray[np.float64]
    top: NDArray[np.float64]
    member: NDArray[np.bool_]

    @classmethod
    def of(cls, tops: list[tuple[int, int, int]], planes: PanelPlanes) -> _TopEdges:
        k, a, b = (np.array(column, dtype=np.intp) for column in zip(*tops, strict=True))
        rows, ray = np.unique(np.concatenate([a, b]), return_inverse=True)
        _, number = _beacon_groups(planes.beacon)
        group = number[k]
        member = np.unique(group)[:, None] == group[None, :]
        both = np.concatenate([k, k])
        return cls(rows, ray, planes.normal[both].T.copy(), planes.offset[both],
                   planes.top[both], member)  # fmt: skip

    @classmethod
    def none(cls) -> _TopEdges:
        """No top edge: no bracket."""
        empty = np.zeros(0, dtype=np.intp)
        return cls(empty, empty, np.zeros((2, 0)), np.zeros(0), np.zeros(0),
                   np.zeros((0, 0), dtype=np.bool_))  # fmt: skip

    def brackets(
        self, p: NDArray[np.float64], origin: NDArray[np.float64], D: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Per beacon (see :func:`_brackets`), the middle, its variance and the
        derivatives (beacons, 6) of its residual, from the frame's returns ``p`` (its
        :attr:`rows` those of the rays) seen from the sensor at ``origin``, ``D`` the
        pose's R and its derivatives by roll, pitch and yaw (as :func:`_derivatives`):
        :meth:`brackets_reference` in one compiled pass."""
        return brackets3d(  # type: ignore[no-any-return]
            p, self.rows, self.ray, D, origin, self.normal[0], self.normal[1], self.offset,
            self.top, self.member, BEAM_ANGLE_SIGMA,
        )  # fmt: skip

    def brackets_reference(
        self,
        p: NDArray[np.float64],
        rel: NDArray[np.float64],
        origin: NDArray[np.float64],
        dR: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """The numpy reference of :meth:`brackets`: from the returns ``p`` of
        :attr:`rows`, their ``rel`` from the sensor at ``origin`` and R's derivatives by
        yaw, pitch and roll ``dR``."""
        (nx, ny), r = self.normal, rel[self.ray]
        plane = self.offset - (origin[0] * nx + origin[1] * ny)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = plane / (r[:, 0] * nx + r[:, 1] * ny)
        # a top edge says top - its crossing over < Z <= top - its hit: the highs, lows
        ends = self.top - s * r[:, 2]
        tops = self.member.shape[1]
        # per beacon, the top edges setting its ends (the first, at a tie)
        hi = np.argmin(np.where(self.member, ends[:tops], math.inf), axis=1)
        lo = np.argmax(np.where(self.member, ends[tops:], -math.inf), axis=1) + tops
        pick = np.concatenate([hi, lo])
        normal = np.stack([nx[pick], ny[pick]], axis=1)
        grad = _height_gradients(p[self.ray[pick]], r[pick], s[pick], normal, dR)
        half = len(hi)
        d = 0.5 * grad[:half]
        d += 0.5 * grad[half:]
        d[:, 5] = 1.0
        middle = 0.5 * (ends[lo] + ends[hi])
        # the beams' angular error moves each end by it times the range to the crossing
        reach = BEAM_ANGLE_SIGMA * np.linalg.norm(s[pick, None] * r[pick], axis=1)
        # an empty intersection (a panel's hit above another's ray over: one of them is
        # not what it is taken for, or the tilt is off) is as uncertain as it is wide
        width = ends[hi] - ends[lo]
        spread = width**2 / 12.0 + 0.25 * (reach[:half] ** 2 + reach[half:] ** 2)
        return middle, spread, d


@dataclass(slots=True)
class _Solved:
    x: NDArray[np.float64]  # (E, N, A, pitch, roll, Z)
    J: NDArray[np.float64]
    W: NDArray[np.float64]
    v: NDArray[np.float64]
    N: NDArray[np.float64]
    n_points: int
    tops: list[tuple[int, int, int]]
    iterations: int
    cosines: NDArray[np.float64]  # each panel return's incidence, cos i (signed)

    def offsets(self) -> NDArray[np.float64]:
        """Each panel return's row's change per metre its panel's plane moves along its
        normal: ``-1 / cos i`` (a range residual; the rows past the panel returns'
        are not a plane's)."""
        return -1.0 / self.cosines


def _solve(
    p: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    x0: NDArray[np.float64],
    range_sigma_m: float,
    survey_sigma_m: float,
    gate_m: float,
    iterations: int,
    tops: list[tuple[int, int, int]] | None = None,
    tilt_prior: tuple[float, float, float] | None = None,
    skip: frozenset[str] = frozenset(),
    panels: frozenset[int] | None = None,
    pairs: _Pairs | None = None,
) -> _Solved:
    """Gauss-Newton over (E, N, A, pitch, roll, Z) (see :func:`adjust_pose`), the top
    edges' rays those given or, without, those chosen at ``x0`` (among ``pairs``, each
    panel's :meth:`PanelPlanes.local` returns, where given): kept through the
    iterations, so that a ray's choice cannot flip back and forth with the pose."""
    mine = which >= 0
    pts, k_of = np.compress(mine, p, axis=0), which[mine]
    m = len(pts)
    n_k, d_k = np.take(planes.normal, k_of, axis=0), planes.offset[k_of]
    ray = pts / np.linalg.norm(pts, axis=1)[:, None]
    # n · (M q + x)[:2] for a 3×3 M is [n_x q, n_y q, n] · [M[0], M[1], x[:2]]: the
    # returns (and their rays) weighed by their normals once, each iteration's
    # residuals, their derivatives by the three angles and the incidences are one product
    weighed = np.hstack(
        [n_k[:, :1] * pts, n_k[:, 1:] * pts, n_k[:, :1] * ray, n_k[:, 1:] * ray, n_k]
    )
    x = x0.copy()
    if tops is None:
        tops = _chosen_tops(p, which, planes, x, gate_m, skip, panels, pairs)
    # only the top edges' rays are turned each iteration
    edges = _TopEdges.of(tops, planes) if tops else _TopEdges.none()
    # the rows: the panel returns', one per beacon's top edges, the tilt prior's two
    rows = m + len(edges.member) + (2 if tilt_prior is not None else 0)
    J, v, W = np.zeros((rows, 6)), np.zeros(rows), np.zeros(rows)
    cosines = np.zeros(m)
    tilt = np.zeros(0)
    if tilt_prior is not None:  # the walls' vertical, as two observations
        J[-2:] = _TILT_ROWS
        W[-2:] = tilt_prior[2] ** -2
        tilt = np.array(tilt_prior[:2])
    N = np.zeros((6, 6))
    done = gauss_newton3d(
        weighed, d_k, range_sigma_m**-2, p, edges.rows, edges.ray, edges.normal[0],
        edges.normal[1], edges.offset, edges.top, edges.member, BEAM_ANGLE_SIGMA,
        survey_sigma_m**2, tilt, 1.0 / UNBRACKETED, x, iterations, _CONVERGED, J, v, W, N,
        cosines,
    )  # fmt: skip
    if done < 0:
        raise np.linalg.LinAlgError("Singular matrix")
    return _Solved(x, J, W, v, N, m, tops, done, cosines)


def _gauss_newton3d_reference(
    weighed: NDArray[np.float64],
    offset_k: NDArray[np.float64],
    weight: float,
    p: NDArray[np.float64],
    edges: _TopEdges,
    survey_var: float,
    tilt: NDArray[np.float64],
    x: NDArray[np.float64],
    iterations: int,
    J: NDArray[np.float64],
    v: NDArray[np.float64],
    W: NDArray[np.float64],
    N: NDArray[np.float64],
    cosines: NDArray[np.float64],
) -> int:
    """The numpy reference of :func:`mast.core._kernels.gauss_newton3d`, the iterations
    of :func:`_solve` (``edges`` for its top edges' arrays; the brackets' beam error
    :data:`BEAM_ANGLE_SIGMA`, the unobserved elevation's :data:`UNBRACKETED` and the
    steps :data:`_CONVERGED`): ``x``, ``J``, ``v``, ``W``, ``N``, ``cosines`` set in
    place, the iterations done returned (numpy's own error where singular)."""
    m = len(weighed)
    rotations = np.zeros((14, 8))
    g = np.zeros(6)
    done = 0
    while True:
        done += 1
        D = _derivatives(x[4], x[3], yaw_of_azimuth(x[2]))
        rotations[:6, :4] = D[_BY_PARAMETER, :2].reshape(4, 6).T  # R, d yaw, d pitch, d roll
        rotations[6:12, 4:] = rotations[:6, :4]  # the rays', for their incidences
        rotations[12:, 0] = x[:2]
        _panel_rows_reference(
            weighed, rotations, offset_k, weight, v[:m], J[:m], W[:m], N, g, cosines
        )
        if len(edges.member):
            at = p[edges.rows]
            middle, spread, dz = edges.brackets_reference(
                at, at @ D[0].T, np.array([x[0], x[1], x[5]]), (D[3], D[2], D[1])
            )
            seen = slice(m, m + len(middle))
            J[seen], v[seen], W[seen] = dz, x[5] - middle, 1.0 / (spread + survey_var)
        if len(tilt):
            v[-2:] = x[3] - tilt[0], x[4] - tilt[1]
        WJ = W[m:, None] * J[m:]  # the brackets' and the tilt prior's rows
        N += J[m:].T @ WJ
        if not len(edges.member):
            N[5, 5] += 1.0 / UNBRACKETED  # the elevation unobserved: kept, with no weight
        step = np.linalg.solve(N, -(g + WJ.T @ v[m:]))
        x += step
        if done >= iterations or np.all(np.abs(step) < _CONVERGED):
            return done


def _panel_rows_reference(
    weighed: NDArray[np.float64],
    rotations: NDArray[np.float64],
    offset: NDArray[np.float64],
    weight: float,
    v: NDArray[np.float64],
    J: NDArray[np.float64],
    W: NDArray[np.float64],
    N: NDArray[np.float64],
    g: NDArray[np.float64],
    cosines: NDArray[np.float64],
) -> None:
    """The numpy reference of :func:`mast.core._kernels.panel_rows3d`, the panel
    returns' rows of one Gauss-Newton iteration of :func:`_solve`: the range residuals
    ``v`` (the offset across the plane over the incidence ``cos i``, into ``cosines``),
    their derivatives by the five the plane observes ``J[:, :5]`` (through the incidence
    too), the weights ``W`` (the range noise's) and their normal equations ``N``, ``g``."""
    product = weighed @ rotations
    cos = product[:, 4]
    cos = np.where(np.abs(cos) < 1e-3, np.where(cos >= 0.0, 1e-3, -1e-3), cos)
    cosines[:] = cos
    r = (product[:, 0] - offset) / cos
    v[:] = r
    J[:, :2] = weighed[:, 12:] / cos[:, None]
    # d yaw / d A = -1
    J[:, 2] = (r * product[:, 5] - product[:, 1]) / cos
    J[:, 3:5] = (product[:, 2:4] - r[:, None] * product[:, 6:8]) / cos[:, None]
    W[:] = weight
    WJ = W[:, None] * J
    N[:] = J.T @ WJ
    g[:] = WJ.T @ v


def _chosen_tops(
    p: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    x: NDArray[np.float64],
    gate_m: float,
    skip: frozenset[str] = frozenset(),
    panels: frozenset[int] | None = None,
    pairs: _Pairs | None = None,
) -> list[tuple[int, int, int]]:
    """The top edges' rays (:func:`_top_edges`) chosen at the pose ``x`` (E, N, A,
    pitch, roll, Z), among ``pairs`` (every return with every panel, where not given),
    but those of the beacons in ``skip`` and of panels not in ``panels`` (where given)."""
    R = _derivatives(x[4], x[3], yaw_of_azimuth(x[2]))[0]
    origin = np.array([x[0], x[1], x[5]])
    rel = p @ R.T
    if pairs is None:
        pairs = planes._pairs(planes._everywhere(len(p)))
    # _top_edges in one compiled pass over the pairs (its numpy reference), unless a
    # return is given a panel it is not paired with (the reference then pairs them)
    inset, lo, hi = _top_extents(planes, gate_m)
    k, hit, over, paired = top_edges3d(
        rel, origin, which, pairs.i, pairs.k, planes.normal, planes.offset, planes.start,
        planes.along, planes.length, planes.top, lo, hi, inset, HIT_SHARE * gate_m, gate_m,
    )  # fmt: skip
    if paired:
        tops = list(zip(k.tolist(), hit.tolist(), over.tolist(), strict=True))
    else:
        rays = planes._rays(rel, origin, pairs)
        tops = _top_edges(rel + origin, rel, which, origin, planes, gate_m, rays=rays)
    return [
        top
        for top in tops
        if planes.beacon[top[0]] not in skip and (panels is None or top[0] in panels)
    ]


#: R and its derivatives by yaw, pitch and roll, as :func:`_derivatives` stacks them.
_BY_PARAMETER = np.array([0, 3, 2, 1])
#: The tilt prior's two rows of the design matrix (pitch, roll).
_TILT_ROWS = np.array([[0.0, 0.0, 0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0]])
#: Steps below these end the Gauss-Newton iterations (E, N, A, pitch, roll, Z): 0.01 mm
#: and 0.02 arc-seconds. The iterations close in linearly, by about a fifth a step (the
#: range residuals' curvature through the incidence is not in the normal equations: on
#: a VLP-16 frame at 3 cm, 0.22), so what is left is a fifth of these, microns and
#: thousandths of an arc-second; 1e-7 m and 1e-9 rad took two more iterations a solve
#: for a pose within 1e-7 of its sigma.
_CONVERGED = np.array([1e-5, 1e-5, 1e-7, 1e-7, 1e-7, 1e-5])


def _failed_bracket(solved: _Solved, planes: PanelPlanes) -> str | None:
    """The beacon whose top edges' bracket fails Baarda's w-test worst, beyond the
    critical value of the largest of as many as there are, or None. A far panel's
    sparse rings may take the wall well above it for a hit (a shallow beacon's wall is
    within the gate of its plane); the other beacons' brackets and the tilt the panel
    returns hold tell. One bracket alone has no redundancy and is not tested."""
    beacons = sorted({planes.beacon[k] for k, _, _ in solved.tops})
    n = solved.n_points
    rows = np.arange(n, n + len(beacons))
    if len(beacons) < 2:
        return None
    Q = np.linalg.inv(solved.N)
    J, W = solved.J[rows], solved.W[rows]
    qvv = 1.0 / W - ((J @ Q) * J).sum(axis=1)
    ok = qvv > 1e-6 / W
    w = np.where(ok, np.abs(solved.v[rows]) / np.sqrt(np.where(ok, qvv, 1.0)), 0.0)
    worst = int(np.argmax(w))
    return beacons[worst] if w[worst] > w_critical(len(beacons)) else None


def _group_w(
    solved: _Solved,
    group: NDArray[np.intp],
    c: NDArray[np.float64],
    groups: int,
    survey_var: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Baarda's w-test of each group of the panel returns' rows (``group``, 0 to
    ``groups``) for a common offset, ``c`` each row's change by it: c'Wv over its sigma,
    with the leverage the pose gives the group (c'W Qvv W c, Qvv = W^-1 - J Q J') and a
    survey offset's share (``survey_var`` times that squared); and whether each is
    tested. A group whose offset the pose alone sets (no other return checks it) is
    not: its residuals are the rounding's."""
    n = solved.n_points
    Wc, J = solved.W[:n] * c, solved.J[:n]
    weight = np.bincount(group, weights=Wc * c, minlength=groups)
    shift = np.bincount(group, weights=Wc * solved.v[:n], minlength=groups)
    pull = np.stack(
        [np.bincount(group, weights=Wc * J[:, j], minlength=groups) for j in range(6)], axis=1
    )
    spread = weight - np.einsum("ij,jk,ik->i", pull, np.linalg.inv(solved.N), pull)
    tested = (weight > 0) & (spread > 1e-6 * weight)
    w = np.zeros(groups)
    w[tested] = np.abs(shift[tested]) / np.sqrt(spread[tested] + survey_var * spread[tested] ** 2)
    return w, tested


def _snoop_pieces(
    p: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    solved: _Solved,
    lines: NDArray[np.intp],
    solve: Callable[[NDArray[np.float64]], _Solved],
    rounds: int = 12,
) -> _Solved:
    """Leave out, one at a time, the piece of panel returns (a quarter of a panel along
    one line) whose common range offset fails Baarda's w-test (:func:`_group_w`; see
    :func:`adjust_pose`); ``which`` is changed in place."""
    for _ in range(rounds):
        on = np.flatnonzero(which >= 0)
        k = which[on]
        R = rotation_rpy(solved.x[4], solved.x[3], yaw_of_azimuth(solved.x[2]))
        xy = np.take(p, on, axis=0) @ R[:2].T + solved.x[:2]
        t = np.einsum("ij,ij->i", xy - planes.start[k], planes.along[k]) / planes.length[k]
        quarter = np.clip(np.floor(4.0 * t), 0, 3).astype(np.intp)
        # the pieces in the order of (panel, line, quarter), as one key each
        line = lines[on] - lines[on].min(initial=0)
        key = (k * (int(line.max(initial=0)) + 1) + line) * 4 + quarter
        _, piece = np.unique(key, return_inverse=True)
        w, tested = _group_w(solved, piece, np.ones(len(piece)), int(piece.max()) + 1)
        worst = int(np.argmax(w))
        if w[worst] <= w_critical(max(int(np.count_nonzero(tested)), 1)):
            break
        which[on[piece == worst]] = -1
        solved = solve(solved.x)
    return solved


def _snoop_panels(
    which: NDArray[np.intp],
    solved: _Solved,
    solve: Callable[[NDArray[np.float64]], _Solved],
    survey_sigma_m: float,
    rounds: int = 3,
) -> _Solved:
    """Leave out, one at a time, the panel whose returns' common shift fails Baarda's
    w-test (``which`` is changed in place): c'Wv over its sigma, c its returns' rows'
    change as its plane moves along its normal (:meth:`_Solved.offsets`), with the
    leverage the pose gives the panel (c'W Qvv W c, Qvv = W^-1 - J Q J') and its survey
    offset's share (sigma_s^2 times that squared). A few returns
    with much weight, alone on their panel (wall returns near grazing a short end panel),
    bend the pose to fit them: each is then within its own w-test, but not their panel."""
    for _ in range(rounds):
        k = which[which >= 0]
        panels = int(k.max(initial=-1)) + 1
        if panels < 2:
            break
        w, tested = _group_w(solved, k, solved.offsets(), panels, survey_sigma_m**2)
        worst = int(np.argmax(w))
        if w[worst] <= w_critical(max(int(np.count_nonzero(tested)), 1)):
            break
        which[which == worst] = -1
        solved = solve(solved.x)
    return solved


def _grazing(
    p: NDArray[np.float64], which: NDArray[np.intp], planes: PanelPlanes, pose: Pose3D
) -> NDArray[np.intp]:
    """The returns ``which`` gives a panel whose rays, at ``pose``, are within
    :data:`GRAZING_DEG` of grazing it: a flat plane's grazing ray would claim a
    precision across it no real panel gives (its range noise barely crosses the plane,
    its direction's error and its footprint fully), and the
    bound (:mod:`mast.pipeline.bounds3d`) leaves them out too. Weighed as the range's,
    one such return, the neighbouring panel's at a joint and alone on its panel, held a
    fix's northing to 0.56 mm and moved it 5.4 mm (9.8 sigma). Left out of ``which``, it
    is no panel's highest hit for the top edges either."""
    on = np.flatnonzero(which >= 0)
    u = np.take(p, on, axis=0) @ pose.rotation.T
    n = np.take(planes.normal, which[on], axis=0)
    cos = np.abs(u[:, 0] * n[:, 0] + u[:, 1] * n[:, 1]) / np.linalg.norm(u, axis=1)
    return np.asarray(on[cos < GRAZING_COS], dtype=np.intp)


def adjust_pose(
    points: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    start: Pose3D,
    *,
    range_sigma_m: float,
    survey_sigma_m: float,
    gate_m: float,
    iterations: int = 12,
    snooping_rounds: int = 6,
    lines: NDArray[np.intp] | None = None,
    elevation: bool = True,
    tilt_prior: tuple[float, float, float] | None = None,
    local: list[NDArray[np.intp]] | None = None,
    top_panels: frozenset[int] | None = None,
) -> Adjustment3D:
    """All six parameters from a frame's returns ``points`` (sensor frame, (n, 3)), those
    on panels named by ``which`` (indices into ``planes``, -1 for none), from ``start``
    (see the module). The top edges enter as one observation of the sensor's elevation
    per beacon: the middle of the intersection of its panels' brackets, with a
    uniform's variance over it and the beams' angular error at its ends, its
    derivatives by all six parameters those of the two rays that set its ends. The
    rays are chosen again at the adjusted pose until the choice holds and every
    beacon's bracket passes its w-test (at most six times: :attr:`Adjustment3D.settled`
    says whether it did; where the choice alternates between two, the two adjustments'
    mixture: :attr:`Adjustment3D.mixed`).

    Returns that are not the panel's (the wall just above, below or beside one, within
    the gate of its plane) are found by data snooping: Baarda's w-test on each
    panel return's standardised residual, those beyond the critical value of the
    largest of n left out, and the adjustment run again.

    Before that, whole pieces: the wall beside a panel's free end, or one ring's run on
    the wall just above its top, is within the gate of the plane as a group, each
    return too near to fail alone. So the panel returns are grouped into pieces (a
    panel's quarter along its length on one of ``lines``: the ring of each return,
    or any label of returns that lie on one line across a panel), and the piece whose
    common range offset is furthest out by Baarda's w-test (its leverage counted: a
    lone return that bends the pose to fit it is tested as one), beyond the critical
    value of the largest of that many, is left out and the adjustment run again, until
    none is.

    Without ``elevation`` no top edge enters: the elevation stays the start's (its
    variance :data:`UNBRACKETED`). ``tilt_prior`` (pitch, roll, sigma; radians) adds
    the two as observations (the vertical of the walls, say): a few panels' returns
    alone may leave the tilt loose. ``local``: each panel's :meth:`PanelPlanes.local`
    returns, where the rays over its top are looked for. ``top_panels``: the panels
    whose top edges may bracket the elevation (all, unless given): a far panel a ring
    or two crosses gives a bracket whose one hit may be the wall's, and whose range
    levers a tilt; a panel whose only returns are the floor at its foot gives a bracket
    far from its top."""
    p = np.asarray(points, dtype=float)
    which = np.asarray(which, dtype=np.intp).copy()
    which[_grazing(p, which, planes, start)] = -1
    x = np.array(
        [start.easting, start.northing, start.azimuth, start.pitch, start.roll, start.elevation]
    )

    def solve(
        x0: NDArray[np.float64], tops: list[tuple[int, int, int]] | None = None
    ) -> _Solved:  # ``which`` as it is now: the snooping leaves returns out of it
        if not elevation:
            tops = []
        return _solve(p, which, planes, x0, range_sigma_m, survey_sigma_m, gate_m, iterations,
                      tops=tops, tilt_prior=tilt_prior, skip=frozenset(distrust), panels=top_panels,
                      pairs=pairs)  # fmt: skip

    # beacons whose top edges failed their w-test, or are not to be used
    distrust: set[str] = set()
    pairs = planes._pairs(local) if local is not None else None

    def choose(x0: NDArray[np.float64]) -> list[tuple[int, int, int]]:
        return _chosen_tops(p, which, planes, x0, gate_m, frozenset(distrust), top_panels,
                            pairs)  # fmt: skip

    solved = solve(x)
    if lines is not None:
        solved = _snoop_pieces(p, which, planes, solved, lines, solve)
        solved = _snoop_panels(which, solved, solve, survey_sigma_m)
    for _ in range(snooping_rounds):
        n = solved.n_points
        Q = np.linalg.inv(solved.N)
        Jp, Wp = solved.J[:n], solved.W[:n]
        leverage = ((Jp @ Q) * Jp).sum(axis=1) * Wp
        w = solved.v[:n] * np.sqrt(Wp) / np.sqrt(np.maximum(1.0 - leverage, 1e-9))
        bad = np.abs(w) > w_critical(n)
        if not bad.any():
            break
        which[np.flatnonzero(which >= 0)[bad]] = -1
        solved = solve(solved.x)
    settled = not elevation
    before: _Solved | None = None  # the adjustment on the rays chosen before the last
    for _ in range(6 if elevation else 0):
        # the top edges' rays chosen again where the pose moved: the same rays, the same
        # adjustment (where it converged on them); others, the adjustment again on them
        tops = choose(solved.x)
        if tops != solved.tops or solved.iterations >= iterations:
            before, solved = solved, solve(solved.x, tops)
            continue
        worst = _failed_bracket(solved, planes)
        if worst is None:
            settled = True
            break
        distrust.add(worst)
        before, solved = None, solve(solved.x)
    other = None if settled else _alternate(solved, before, iterations, planes, choose)
    x, W, v, n_points = solved.x, solved.W, solved.v, solved.n_points
    dof = n_points - 5
    s0 = float(W[:n_points] @ (v[:n_points] ** 2)) / dof if dof > 0 else math.nan
    cov = _covariance(solved, which, planes, survey_sigma_m)
    if other is not None:
        # the two choices' equal mixture: their mean, and a covariance that covers either
        half = 0.5 * (other.x - x)
        half[2] = 0.5 * math.remainder(other.x[2] - x[2], 2.0 * math.pi)
        x = x + half
        cov = 0.5 * (cov + _covariance(other, which, planes, survey_sigma_m))
        cov += np.outer(half, half)
        settled = True
    # (E, N, A, pitch, roll, Z) → (E, N, Z, roll, pitch, A)
    order = [0, 1, 5, 4, 3, 2]
    pose = Pose3D(x[0], x[1], x[5], normalize_azimuth(x[2]), x[3], x[4])
    return Adjustment3D(
        pose=pose,
        covariance=np.asarray(cov[np.ix_(order, order)], dtype=np.float64),
        reference_variance=s0,
        dof=dof,
        test_p=float(chi2_sf(s0 * dof, dof)) if dof > 0 else 1.0,
        returns=n_points,
        iterations=solved.iterations,
        top_edges=len({planes.beacon[k] for k, _, _ in solved.tops}),
        used=which,
        settled=settled,
        mixed=other is not None,
    )


def _covariance(
    solved: _Solved, which: NDArray[np.intp], planes: PanelPlanes, survey_sigma_m: float
) -> NDArray[np.float64]:
    """An adjustment's covariance (E, N, A, pitch, roll, Z): its normal equations' inverse,
    and the survey's error, one offset per panel shared by all its returns."""
    Q = np.linalg.inv(solved.N)
    n_points = solved.n_points
    G = Q @ (solved.J.T * solved.W)
    shared = np.zeros((n_points, len(planes)))
    shared[np.arange(n_points), which[which >= 0]] = solved.offsets()
    g = G[:, :n_points] @ shared  # (6, panels): each panel's offset's effect
    return np.asarray(Q + survey_sigma_m**2 * (g @ g.T), dtype=np.float64)


def _alternate(
    solved: _Solved,
    before: _Solved | None,
    iterations: int,
    planes: PanelPlanes,
    choose: Callable[[NDArray[np.float64]], list[tuple[int, int, int]]],
) -> _Solved | None:
    """``before``, where the top edges' rays alternate between its choice and
    ``solved``'s: each chosen at the pose the other adjusts to, both choices bracketing
    the elevation, both adjustments converged and each beacon's bracket passing its
    w-test; else None (``choose``: the rays chosen at a pose). ``solved`` is the
    adjustment on the rays chosen at ``before``'s pose (:func:`adjust_pose` keeps it
    so), so only the way back is chosen here."""
    if before is None or not before.tops or not solved.tops or before.tops == solved.tops:
        return None
    if max(before.iterations, solved.iterations) >= iterations:
        return None
    if choose(solved.x) != before.tops:
        return None
    if _failed_bracket(solved, planes) is not None or _failed_bracket(before, planes) is not None:
        return None
    return before
