"""A mine drift in 3D: rough rock walls, floor and roof on a grade, beacons' panels as
vertical rectangles, and ray casting into it, vectorised over rays.

The drift is the plan-view :class:`~mast.sim.tunnel.Tunnel` (a centreline polyline and a
width, the walls mitred at its bends) extruded between a floor and a roof:

* leg ``i`` (the centreline's segment ``i``) owns the points between the mitre planes
  at its two ends (the vertical planes through a bend's vertex that bisect it, where the
  2D walls meet); in it a point has a station ``s`` along the leg and an offset ``u``
  to the left of it;
* the smooth floor is one plane rising ``grade`` metres a metre along the drift's
  chord (its centreline's first point to its last, :attr:`Drift3D.grade_direction`):
  ``floor_elevation_m`` at the first point. On a straight drift that is the grade along
  it; a bend's legs share the plane, so each rises ``grade`` times the cosine of its
  angle to the chord (a per-leg grade would step at the mitre off the centreline).
  The roof is ``height_m`` above the floor; the walls are at ``u = ±width/2``; both
  ends of the drift are flat vertical faces;
* rock is rough: each rock surface is moved outwards by a smooth random field ``r(p)``
  of the grid position (a sum of sinusoids along random 3D directions, wavelengths
  and peak amplitude from :class:`~mast.sim.tunnel.Roughness`, ``|r| <= amplitude``),
  so the rock is ``F(p) = max_k g_k(p) = 0`` with ``g_wall = |u| - width/2 - r``,
  ``g_floor = floor + r - z``, ``g_roof = z - roof - r`` and ``g_face`` the end faces
  (the interior is ``F < 0``). A wall is left smooth behind each beacon, plus a margin
  each side, as :func:`~mast.sim.tunnel.roughen` does in 2D (dressed for mounting);
* panels (a beacon's three, or any other vertical plate) are vertical rectangles
  ``a -> b`` in plan between two elevations; they occlude what is behind them.

A ray's first rock hit is bracketed by the smooth drift shrunk and grown by the
amplitude (the rough rock lies between them), sampled every :data:`SAMPLE_STEP_M`
inside the bracket for the first sign change of ``F``, and refined by regula falsi
(Illinois) until ``|F|`` is below :data:`ROOT_TOL_M`. A bump thinner than the sampling
step on a grazing ray may be passed through (the hit found is still on the rock).

Inside, plan coordinates are taken from :attr:`Drift3D.origin` (the centreline's first
point) so that a survey far from the grid's origin keeps its precision; every public
argument and result is in the grid (easting, northing, elevation) unless its name says
``local``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core.beacon import Beacon
from mast.errors import InputError
from mast.sim.tunnel import Roughness, Tunnel
from mast.sim.world import Surface

__all__ = ["ROCK_SURFACES", "Drift3D", "Plate", "beacon_plates"]

#: The rock surfaces, in the order of the first entries of :attr:`Drift3D.surfaces`.
ROCK_SURFACES = (Surface("wall"), Surface("floor"), Surface("roof"), Surface("face"))
#: Sampling step along a ray's bracket when looking for the first rock crossing, metres
#: (a quarter of the shortest default rock wavelength: no crest of it is stepped over).
SAMPLE_STEP_M = 0.05
#: A rock hit is refined until ``|F|`` at it is below this, metres.
ROOT_TOL_M = 1e-11
#: The most samples a bracket gets (a grazing ray's long bracket is sampled coarser).
MAX_SAMPLES = 128


@dataclass(frozen=True, slots=True)
class Plate:
    """A flat vertical rectangle: in plan the segment ``a -> b`` (grid E, N), from
    ``z_bottom_m`` up to ``z_top_m``; ``surface`` says what it is (a beacon's panel is
    ``Surface("beacon", id, 1..3)``) and ``reflectivity`` its intensity."""

    a: tuple[float, float]
    b: tuple[float, float]
    z_bottom_m: float
    z_top_m: float
    surface: Surface
    reflectivity: float = 200.0


def beacon_plates(beacon: Beacon, height_m: float, *, reflectivity: float = 200.0) -> list[Plate]:
    """A surveyed beacon's three panels, from its edges' top elevations down ``height_m``."""
    if beacon.elevations is None:
        raise InputError(f"beacon {beacon.id!r} has no elevations: its panels have no height")
    top = float(np.mean(beacon.elevations))
    e = beacon.edges
    return [
        Plate(
            (float(e[k, 0]), float(e[k, 1])),
            (float(e[k + 1, 0]), float(e[k + 1, 1])),
            top - height_m,
            top,
            Surface("beacon", beacon.id, k + 1),
            reflectivity,
        )
        for k in range(3)
    ]


class _RockField:
    """``r(p)``: a sum of sinusoids along random 3D directions, ``|r| <= amplitude``."""

    def __init__(self, rough: Roughness, rng: np.random.Generator):
        lam = rng.uniform(rough.wavelength_min_m, rough.wavelength_max_m, rough.components)
        v = rng.normal(size=(rough.components, 3))
        v /= np.linalg.norm(v, axis=1)[:, None]
        self.k = v * (2 * math.pi / lam)[:, None]
        self.phase = rng.uniform(0, 2 * math.pi, rough.components)
        w = rng.uniform(0.3, 1.0, rough.components)
        # Normalised by the weights' sum, not a sampled peak: the bound is exact, which
        # the ray casting's bracket needs.
        self.weight = w * (rough.amplitude_m / float(w.sum()))

    def __call__(self, p: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(np.sin(p @ self.k.T + self.phase) @ self.weight)


class Drift3D:
    """A drift with rough rock and vertical plates (see the module).

    Parameters
    ----------
    tunnel : Tunnel
        Plan view: centreline (grid E, N) and width, metres.
    height_m : float
        Smooth floor to smooth roof.
    grade : float
        Rise of the floor per metre along the centreline (1 in 7 is ``1/7``).
    floor_elevation_m : float
        The smooth floor's elevation at the centreline's first point.
    rock : Roughness or None
        The rock's roughness (None: smooth rock).
    plates : sequence of Plate
        Beacons' panels and any other vertical plates.
    seed : int
        Seeds the rock's random field.
    rock_reflectivity : float
        The rock's mean intensity.
    """

    def __init__(
        self,
        tunnel: Tunnel,
        height_m: float,
        *,
        grade: float = 0.0,
        floor_elevation_m: float = 0.0,
        rock: Roughness | None = None,
        plates: Sequence[Plate] = (),
        seed: int = 0,
        rock_reflectivity: float = 30.0,
    ):
        c = np.asarray(tunnel.centreline, dtype=float)
        if c.ndim != 2 or c.shape[0] < 2 or c.shape[1] != 2:
            raise InputError("a drift's centreline needs two or more (E, N) points")
        if not (tunnel.width_m > 0 and height_m > 0):
            raise InputError(f"a drift {tunnel.width_m} m wide, {height_m} m high is invalid")
        self.tunnel = tunnel
        self.width_m = float(tunnel.width_m)
        self.height_m = float(height_m)
        self.grade = float(grade)
        self.floor_elevation_m = float(floor_elevation_m)
        self.rock = rock
        self.rock_reflectivity = float(rock_reflectivity)
        self.plates = tuple(plates)
        self.origin = c[0].copy()
        local = c - self.origin
        seg = np.diff(local, axis=0)
        lengths = np.hypot(seg[:, 0], seg[:, 1])
        if np.any(lengths <= 0):
            raise InputError("a drift's centreline has two equal consecutive points")
        self._start = local[:-1]
        self._dir = seg / lengths[:, None]
        self._left = np.stack([-self._dir[:, 1], self._dir[:, 0]], axis=1)
        self._length = lengths
        # The mitre between legs j-1 and j: through vertex j, normal bisecting them.
        mitre = self._dir[:-1] + self._dir[1:]
        self._mitre_n = mitre / np.hypot(mitre[:, 0], mitre[:, 1])[:, None]
        self._mitre_p = local[1:-1]
        chord = local[-1] - local[0]
        self.grade_direction = chord / float(np.hypot(*chord))
        self._field = _RockField(rock, np.random.default_rng(seed)) if rock else None
        self._amp = float(rock.amplitude_m) if rock else 0.0
        self._margin = float(rock.beacon_margin_m) if rock else 0.0
        surfaces = list(ROCK_SURFACES)
        idx = []
        for plate in self.plates:
            if plate.surface not in surfaces:
                surfaces.append(plate.surface)
            idx.append(surfaces.index(plate.surface))
        self.surfaces: tuple[Surface, ...] = tuple(surfaces)
        pa = np.array([p.a for p in self.plates], dtype=float).reshape(-1, 2) - self.origin
        pb = np.array([p.b for p in self.plates], dtype=float).reshape(-1, 2) - self.origin
        self._pa, self._pb = pa, pb
        self._pz = np.array([(p.z_bottom_m, p.z_top_m) for p in self.plates]).reshape(-1, 2)
        self._psurf = np.asarray(idx, dtype=np.intp)
        self._prefl = np.array([p.reflectivity for p in self.plates], dtype=float)
        self._smooth = self._smooth_patches()

    # -- geometry of the smooth drift -------------------------------------------------

    def leg_of(self, xy_local: NDArray[np.float64]) -> NDArray[np.intp]:
        """The leg each plan point (local) is in: how many mitres it is past."""
        xy = np.asarray(xy_local, dtype=float).reshape(-1, 2)
        if not len(self._mitre_p):
            return np.zeros(len(xy), dtype=np.intp)
        past = ((xy[:, None, :] - self._mitre_p[None]) * self._mitre_n[None]).sum(axis=2) > 0
        return np.asarray(past.sum(axis=1), dtype=np.intp)

    def _su(
        self, xy: NDArray[np.float64], leg: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Station along each point's leg (from the leg's start) and offset to its left."""
        s = np.empty(len(xy))
        u = np.empty(len(xy))
        for k in range(len(self._length)):
            sel = leg == k if len(self._length) > 1 else slice(None)
            dx = xy[sel, 0] - self._start[k, 0]
            dy = xy[sel, 1] - self._start[k, 1]
            cx, cy = self._dir[k]
            s[sel] = dx * cx + dy * cy
            u[sel] = dy * cx - dx * cy
        return s, u

    def floor_at(self, points: ArrayLike) -> NDArray[np.float64]:
        """The smooth floor's elevation under each grid point ``(n, 2)`` or ``(n, 3)``."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        xy = p[:, :2] - self.origin
        return np.asarray(self.floor_elevation_m + self.grade * (xy @ self.grade_direction))

    def _smooth_patches(self) -> list[tuple[int, NDArray[np.float64], NDArray[np.float64], float]]:
        """Each beacon's wall patch left smooth: (side +1 left / -1 right, chord centre,
        chord direction, half chord), local plan coordinates."""
        out = []
        by_beacon: dict[str, list[int]] = {}
        for i, plate in enumerate(self.plates):
            if plate.surface.kind == "beacon":
                by_beacon.setdefault(plate.surface.beacon, []).append(i)
        for members in by_beacon.values():
            ends = np.vstack([self._pa[members], self._pb[members]])
            i0, i1 = min(members), max(members)
            a, b = self._pa[i0], self._pb[i1]
            mid = (a + b) / 2
            chord = b - a
            half = float(np.hypot(*chord)) / 2
            t = chord / max(2 * half, 1e-12)
            leg = self.leg_of(mid)
            _, u = self._su(mid[None], leg)
            side = 1 if float(u[0]) > 0 else -1
            far = float(np.max(np.abs((ends - mid) @ t))) - half
            out.append((side, mid, t, half + max(0.0, far)))
        return out

    def _taper(self, xy: NDArray[np.float64], side: int) -> NDArray[np.float64]:
        taper = np.ones(len(xy))
        for s, mid, t, half in self._smooth:
            if s != side:
                continue
            rel = xy - mid
            along = np.abs(rel @ t) - half
            across = np.abs(rel[:, 0] * t[1] - rel[:, 1] * t[0])
            near = across < 1.0
            ramp = np.clip(along / max(self._margin, 1e-9), 0.0, 1.0)
            taper = np.where(near, np.minimum(taper, ramp), taper)
        return taper

    def rock_functions(self, points_local: NDArray[np.float64]) -> NDArray[np.float64]:
        """``g_k`` of each rock surface (wall, floor, roof, face) at each point (local
        plan, grid elevation), shape ``(n, 4)``: zero on the rock, negative inside."""
        p = np.asarray(points_local, dtype=float).reshape(-1, 3)
        xy = p[:, :2]
        leg = self.leg_of(xy)
        s, u = self._su(xy, leg)
        floor = self.floor_elevation_m + self.grade * (xy @ self.grade_direction)
        if self._field is not None:
            r = self._field(p)
            taper = np.where(u > 0, self._taper(xy, 1), self._taper(xy, -1))
            r_wall = r * taper
        else:
            r = r_wall = np.zeros(len(p))
        g = np.empty((len(p), 4))
        g[:, 0] = np.abs(u) - self.width_m / 2 - r_wall
        g[:, 1] = floor + r - p[:, 2]
        g[:, 2] = p[:, 2] - floor - self.height_m - r
        first, last = leg == 0, leg == len(self._length) - 1
        face = np.full(len(p), -np.inf)
        face = np.where(first, -s, face)
        face = np.where(last, np.maximum(face, s - self._length[-1]), face)
        g[:, 3] = face
        return g

    # -- ray casting --------------------------------------------------------------------

    def _box_exit(
        self, o: NDArray[np.float64], d: NDArray[np.float64], grow: float
    ) -> NDArray[np.float64]:
        """Where each ray leaves the smooth drift grown by ``grow`` metres (walls, floor
        and roof; the faces never move), following it through the bends: each leg is
        convex, so a ray leaves it at the nearest of its bounding planes ahead, and
        goes on into the next leg when that plane is a mitre."""
        n = len(d)
        legs = len(self._length)
        leg = np.full(n, int(self.leg_of(o[None, :2])[0]), dtype=np.intp)
        t_exit = np.full(n, np.inf)
        todo = np.ones(n, dtype=bool)
        half = self.width_m / 2 + grow
        gd = self.grade_direction
        for _ in range(legs + 1):
            for k in range(legs):
                sel = np.flatnonzero(todo & (leg == k))
                if not len(sel):
                    continue
                dd = d[sel]
                rel = o[:2] - self._start[k]
                cx, cy = self._dir[k]
                s0 = float(rel[0] * cx + rel[1] * cy)
                u0 = float(rel[1] * cx - rel[0] * cy)
                ds = dd[:, 0] * cx + dd[:, 1] * cy
                du = dd[:, 1] * cx - dd[:, 0] * cy
                floor0 = self.floor_elevation_m + self.grade * float(o[:2] @ gd)
                b_floor = self.grade * (dd[:, :2] @ gd) - dd[:, 2]  # d(floor - z)/dt
                inf = np.full(len(sel), np.inf)
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = np.where(du > 0, (half - u0) / du, inf)
                    t = np.minimum(t, np.where(du < 0, (-half - u0) / du, inf))
                    t = np.minimum(t, np.where(b_floor > 0, (o[2] - floor0 + grow) / b_floor, inf))
                    roof = floor0 + self.height_m + grow - o[2]
                    t = np.minimum(t, np.where(b_floor < 0, roof / -b_floor, inf))
                    if k == 0:
                        t = np.minimum(t, np.where(ds < 0, -s0 / ds, inf))
                    if k == legs - 1:
                        t = np.minimum(t, np.where(ds > 0, (self._length[k] - s0) / ds, inf))
                    t_next, t_prev = inf, inf
                    if k < legs - 1:
                        m, mp = self._mitre_n[k], self._mitre_p[k]
                        dm = dd[:, :2] @ m
                        t_next = np.where(dm > 0, -float((o[:2] - mp) @ m) / dm, inf)
                    if k > 0:
                        m, mp = self._mitre_n[k - 1], self._mitre_p[k - 1]
                        dm = dd[:, :2] @ m
                        t_prev = np.where(dm < 0, -float((o[:2] - mp) @ m) / dm, inf)
                done = t <= np.minimum(t_next, t_prev)
                t_exit[sel[done]] = t[done]
                todo[sel[done]] = False
                leg[sel] = np.where(t_next < t_prev, k + 1, k - 1)
            if not np.any(todo):
                break
        return np.asarray(np.maximum(t_exit, 0.0))

    def _rock_f(
        self, o: NDArray[np.float64], d: NDArray[np.float64], t: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """``F`` at distance ``t`` along each ray."""
        return np.asarray(self.rock_functions(o + t[:, None] * d).max(axis=1))

    def _rock_hits(self, o: NDArray[np.float64], d: NDArray[np.float64]) -> NDArray[np.float64]:
        t_hi = self._box_exit(o, d, self._amp)
        if self._field is None:
            return t_hi
        t_lo = np.minimum(self._box_exit(o, d, -self._amp), t_hi)
        n = len(d)
        lo, hi = t_lo.copy(), t_hi.copy()
        samples = np.clip(np.ceil((t_hi - t_lo) / SAMPLE_STEP_M), 1, MAX_SAMPLES).astype(int)
        # Rays grouped by sample count (powers of two), each group sampled at once.
        bucket = np.ceil(np.log2(samples)).astype(int)
        f_lo = np.full(n, -np.inf)
        f_hi = np.zeros(n)
        for b in np.unique(bucket):
            sel = np.flatnonzero(bucket == b)
            k = 2 ** int(b)
            frac = np.arange(1, k + 1) / k
            ts = t_lo[sel, None] + (t_hi - t_lo)[sel, None] * frac[None, :]
            pts = o + ts[..., None] * d[sel, None, :]
            f = self.rock_functions(pts.reshape(-1, 3)).max(axis=1).reshape(len(sel), k)
            # Outside the grown drift is on or past the rock (rounding aside).
            f[:, -1] = np.maximum(f[:, -1], 0.0)
            first = np.argmax(f >= 0, axis=1)
            rows = np.arange(len(sel))
            hi[sel] = ts[rows, first]
            f_hi[sel] = f[rows, first]
            later = first > 0
            lo[sel[later]] = ts[rows[later], first[later] - 1]
            f_lo[sel[later]] = f[rows[later], first[later] - 1]
        # Regula falsi (Illinois) on [lo, hi], F(lo) < 0 <= F(hi).
        unknown = np.flatnonzero(np.isinf(f_lo))
        f_lo[unknown] = self._rock_f(o, d[unknown], lo[unknown])
        t = hi.copy()
        active = np.flatnonzero((f_lo < 0) & (f_hi > ROOT_TOL_M))
        t[f_lo >= 0] = lo[f_lo >= 0]
        side = np.zeros(n, dtype=int)
        for _ in range(100):
            if not len(active):
                break
            a, b_, fa, fb = lo[active], hi[active], f_lo[active], f_hi[active]
            tm = np.where(fb > fa, (a * fb - b_ * fa) / (fb - fa), (a + b_) / 2)
            bad = ~((tm > a) & (tm < b_))
            tm = np.where(bad, (a + b_) / 2, tm)
            fm = self._rock_f(o, d[active], tm)
            t[active] = tm
            conv = (np.abs(fm) < ROOT_TOL_M) | (b_ - a < 1e-13)
            inside = fm < 0
            # Illinois: halve the stale end's value when the same end is kept twice.
            keep_hi = inside & (side[active] == -1)
            keep_lo = ~inside & (side[active] == 1)
            lo[active] = np.where(inside, tm, a)
            f_lo[active] = np.where(inside, fm, np.where(keep_lo, fa / 2, fa))
            hi[active] = np.where(inside, b_, tm)
            f_hi[active] = np.where(inside, np.where(keep_hi, fb / 2, fb), fm)
            side[active] = np.where(inside, -1, 1)
            active = active[~conv]
        return t

    def raycast(
        self, origin: ArrayLike, directions: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        """Distance to the first surface along each ray, and what it hit.

        Parameters
        ----------
        origin : array_like, shape (3,)
            The rays' origin in the grid (E, N, elevation), inside the drift.
        directions : array_like, shape (n, 3)
            Unit directions in the grid.

        Returns
        -------
        ranges : ndarray, shape (n,)
            Metres.
        surface : ndarray of int, shape (n,)
            Index into :attr:`surfaces` of what each ray hit.
        """
        o = np.asarray(origin, dtype=float).reshape(3).copy()
        o[:2] -= self.origin
        d = np.asarray(directions, dtype=float).reshape(-1, 3)
        t = self._rock_hits(o, d)
        g = self.rock_functions(o + t[:, None] * d)
        surf = np.argmax(g, axis=1).astype(np.intp)
        if len(self.plates):
            tp, jp = self._plate_hits(o, d)
            nearer = tp < t
            t = np.where(nearer, tp, t)
            surf = np.where(nearer, self._psurf[np.maximum(jp, 0)], surf)
        return t, surf

    def _plate_hits(
        self, o: NDArray[np.float64], d: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        ab = self._pb - self._pa  # (m, 2)
        normal = np.stack([-ab[:, 1], ab[:, 0]], axis=1)
        denom = d[:, :2] @ normal.T  # (n, m)
        num = ((self._pa - o[:2]) * normal).sum(axis=1)  # (m,)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num[None, :] / denom
            xy = o[:2] + t[..., None] * d[:, None, :2]
            along = ((xy - self._pa) * ab).sum(axis=2) / (ab * ab).sum(axis=1)
            z = o[2] + t * d[:, 2:3]
        ok = (t > 0) & (along >= 0) & (along <= 1) & (z >= self._pz[:, 0]) & (z <= self._pz[:, 1])
        t = np.where(ok, t, np.inf)
        j = np.argmin(t, axis=1)
        tj = t[np.arange(len(d)), j]
        return tj, np.where(np.isfinite(tj), j, -1).astype(np.intp)

    def plate_normal(self, surface: int) -> NDArray[np.float64]:
        """The unit plan normal (E, N) of the first plate labelled ``surface``."""
        j = int(np.flatnonzero(self._psurf == surface)[0])
        ab = self._pb[j] - self._pa[j]
        return np.array([-ab[1], ab[0]]) / float(np.hypot(*ab))

    def reflectivity(self, surface: NDArray[np.intp]) -> NDArray[np.float64]:
        """The mean intensity of each surface index."""
        table = np.full(len(self.surfaces), self.rock_reflectivity)
        for k, refl in zip(self._psurf, self._prefl, strict=True):
            table[k] = refl
        return np.asarray(table[surface])

    def surface_gap(self, points: ArrayLike, surface: ArrayLike) -> NDArray[np.float64]:
        """How far each grid point is off the surface it is labelled with, metres: the
        rock's ``g_k`` (zero on the rock), or a plate's distance from its vertical
        plane (then zero within its rectangle). For checks of the simulation."""
        p = np.asarray(points, dtype=float).reshape(-1, 3).copy()
        p[:, :2] -= self.origin
        s = np.asarray(surface, dtype=np.intp).reshape(-1)
        gap = np.full(len(p), np.inf)
        rock = s < len(ROCK_SURFACES)
        if np.any(rock):
            g = self.rock_functions(p[rock])
            gap[rock] = np.abs(g[np.arange(int(rock.sum())), s[rock]])
        for k in np.unique(s[~rock]):
            for j in np.flatnonzero(self._psurf == k):
                sel = s == k
                a, b = self._pa[j], self._pb[j]
                ab = b - a
                length = float(np.hypot(*ab))
                rel = p[sel, :2] - a
                along = rel @ ab / length
                dist = np.abs(rel[:, 0] * ab[1] - rel[:, 1] * ab[0]) / length
                outside = np.maximum.reduce(
                    [
                        -along,
                        along - length,
                        self._pz[j, 0] - p[sel, 2],
                        p[sel, 2] - self._pz[j, 1],
                        np.zeros(int(sel.sum())),
                    ]
                )
                gap[sel] = np.minimum(gap[sel], np.hypot(dist, outside))
        return gap
