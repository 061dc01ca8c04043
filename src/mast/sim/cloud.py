"""A simulated 3D SLAM point cloud of a mine drift with surveyed wall beacons.

The scene is built in the mine grid (Easting, Northing, elevation; seven-digit
grid numbers, elevations around -850 m): a main drift of ``length_m`` with two
gentle bends, a floor on a grade (a 1:20 decline over part of it), an arched
roof, rough rock walls in 3D (the plan profile from :func:`~mast.sim.tunnel.roughen`
plus a profile varying with height; smooth behind every beacon), one or two short
side drifts, faces at the ends, and clutter that must not be taken for beacons:
pipes and a ventilation duct along the walls, parked machines, vertical posts and
wall cabinets. Beacons (:func:`~mast.sim.design.paper_design`) stand on alternating
walls, their three panels vertical from ``beacon_top_m - panel_height_m`` to
``beacon_top_m`` above the local floor. Every visible surface is sampled uniformly
at ``density`` points per square metre (Poisson counts); wall, floor and machine
surfaces hidden behind a beacon, a cabinet, a machine or a pipe are left out.

**Time.** A scanner is carried along the main centreline at 1.2 m/s, 1.6 m above
the floor, from ``t0 = 345600 s`` (GPS week seconds). A point gets the time at
which the scanner's station was nearest the point's own station along the
centreline, plus a uniform offset of +-3 m of travel (clipped to the run); points of
a side drift take the junction's station. ``range`` is the distance from the
scanner's (SLAM) position at that time.

**Drift.** Let ``T0`` be the true rigid map local -> grid at time 0 (a random
rotation about z; the local origin is the scanner's start). The SLAM estimate of
the scanner is ``X_slam(t) = T0^-1 o D(t) o X_true(t)`` where ``D(t)`` is a rigid
error growing along the run: a heading error ``psi(t)`` (a smoothed random walk plus
a bias) and a scale error ``k`` integrated along the path, so that the position
error is ``e(t) = sum(((1 + k) R(psi) - I) dx)`` over the true steps ``dx``, and a
vertical drift ``zeta = +-0.3 drift * distance``. ``psi`` and ``k`` are scaled so that
the final horizontal error is ``drift * length``. ``D(t)`` rotates by ``psi(t)``
about the true scanner position and adds ``e(t)``; a point seen at ``t`` is mapped
``p_local = T0^-1 D(t) p_grid``, so the cloud is consistent locally and drifts
along the run, as SLAM does. With ``drift = 0``, ``p_local = T0^-1 p_grid`` exactly.

**Files** written to ``out`` (each atomically, :mod:`mast.io.atomic`):

- ``cloud.laz``: LAS 1.4, point format 6, LAZ (lazrs), in the local frame; scales
  0.0001 m, offsets the middle of the trajectory's bounding box rounded to the metre.
  ``x y z``; ``intensity`` (uint16, falling with range: rock 1200-2600, metal
  2500-6000, the retro-reflective beacon panels 48000-62000); ``gps_time`` (s, GPS
  week time, see above); return 1 of 1; ``classification`` 0; ``point_source_id`` 1;
  extra bytes ``range`` (float32, m). The header's date is fixed, so one seed gives
  the same bytes.
- ``beacons.csv``: the survey (:func:`mast.io.write_survey`), ``beacon,edge,easting,
  northing,elevation``, ids ``B01``, ``B02``... along the drift, the elevation that of
  each edge's top; ``survey_sigma_m`` of noise on every coordinate.
- ``trajectory.tum``: ``X_slam`` every 0.1 s, ``t x y z qx qy qz qw`` (yaw only).
- ``truth.json``: ``model`` ("4-parameter"), ``rotation_deg``, ``easting_m``,
  ``northing_m``, ``elevation_m`` (``T0``: ``grid_EN = R(rotation) local_xy + (E, N)``,
  counter-clockwise; ``grid_Z = local_z + elevation_m``), ``drift``, ``noise_m``,
  ``seed``, ``options``, ``points``, ``density`` (used), ``start_time_s``,
  ``speed_mps``, ``scanner_height_m``, ``final_error_m``; ``beacons``: per beacon
  ``id``, ``side``, ``station_m``, ``panel_points`` (points on P1, P2, P3),
  ``top_elevation_m``, ``time_s`` (when the scanner passed it), ``edges_grid`` (true
  ``[E, N, Z_top]`` x 4) and ``edges_local`` (where those appear in the drifted cloud,
  ``T0^-1 D(time_s)``); ``junctions`` and ``clutter`` (a record per object: ``kind``,
  ``side``, station or station range, sizes).

Points are generated stretch by stretch along the drift and written ``chunk_points``
at a time, so memory does not grow with the cloud (about 0.6 GB at the default chunk).
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import laspy
import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon, Survey
from mast.errors import InputError
from mast.io.atomic import atomic_open, write_atomic
from mast.io.beacons_csv import write_survey
from mast.io.las import LAS_SCALE_M, LasWriter, new_las_header
from mast.sim.design import paper_design, random_design
from mast.sim.tunnel import Roughness, Tunnel, roughen

__all__ = ["CloudOptions", "CloudScenario", "simulate_cloud"]

Array = NDArray[np.float64]

SPEED_MPS = 1.2
POSE_PERIOD_S = 0.1
START_TIME_S = 345_600.0
SCANNER_HEIGHT_M = 1.6
TIME_JITTER_M = 3.0
WIDTH_M, WALL_HEIGHT_M, CROWN_M = 5.0, 3.6, 4.5
#: Point kinds and their intensity: (low, high, range attenuation per metre).
ROCK, BEACON, METAL = 0, 1, 2
_INTENSITY = np.array([[1200.0, 2600.0, 0.02], [48000.0, 62000.0, 0.002], [2500.0, 6000.0, 0.02]])


@dataclass(frozen=True, slots=True)
class CloudOptions:
    """What to simulate.

    Attributes
    ----------
    length_m : float
        Length of the main drift along its centreline, metres.
    beacons : int
        Beacons mounted along the main drift (alternating walls, 15-40 m apart when
        the length allows, none within 5 m of a junction or an end).
    drift : float
        SLAM drift as a fraction of distance travelled: the final horizontal position
        error is ``drift * length_m``.
    noise_m : float
        Standard deviation of the isotropic 3D Gaussian noise of every point.
    density : float
        Points per square metre of every surface (rock, beacon panels, clutter). The
        default, 2 000, is a mobile scanner's near the walls, and above the density
        ``mast georef`` needs to find beacons
        (:data:`~mast.cloud.detect.BEACON_DENSITY_M2`, about 1 200).
    survey_sigma_m : float
        Noise added to the surveyed edge coordinates and elevations in ``beacons.csv``.
    panel_height_m, beacon_top_m : float
        Panel height, and height of the panels' tops above the local floor.
    chunk_points : int
        Points written per chunk; memory stays bounded by a few times this.
    max_points : int or None
        If given, the density is lowered (estimated from a sparse pilot run) so the
        cloud stays within this many points; a surplus is cut from the end.
    falloff_m : float or None
        If given, the density falls with range as a scanner's does: a point at range
        ``r`` from the scanner (at its time) is kept with probability
        ``min(1, (falloff_m / r)^2)``, so ``density`` holds within ``falloff_m`` and
        a quarter of it at twice that. None: every surface at ``density``.
    rock_behind_beacons : bool
        Rough rock right up to the beacons (their free ends among its bumps); False
        smooths the wall behind each beacon, as a surveyor's chosen spot would be.
    designs : int
        Beacon designs mounted in turn: 1, the paper's hat everywhere; more, the
        paper's hat and random hats with outer panels at a shallow angle to the wall
        (deflections 20-35 degrees, chords 0.7-1.3 m: outer panels of 0.1-0.5 m).
    """

    length_m: float = 300.0
    beacons: int = 12
    drift: float = 0.0
    noise_m: float = 0.01
    density: float = 2000.0
    survey_sigma_m: float = 0.003
    panel_height_m: float = 0.6
    beacon_top_m: float = 2.0
    chunk_points: int = 2_000_000
    max_points: int | None = None
    falloff_m: float | None = None
    rock_behind_beacons: bool = False
    designs: int = 1


@dataclass(frozen=True, slots=True)
class CloudScenario:
    """Files written by :func:`simulate_cloud` and a summary.

    Attributes
    ----------
    cloud, survey, trajectory, truth : Path
        ``cloud.laz``, ``beacons.csv``, ``trajectory.tum`` and ``truth.json``.
    points, beacons : int
        Points in the cloud; beacons in the survey.
    """

    cloud: Path
    survey: Path
    trajectory: Path
    truth: Path
    points: int
    beacons: int


def _arc(p: Array) -> Array:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])


def _rot(a: float) -> Array:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def _pick(lengths: Array, n: int, rng: np.random.Generator) -> tuple[NDArray[np.intp], Array]:
    """Segments drawn in proportion to ``lengths``, and a uniform fraction along each."""
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    u = rng.random(n) * cum[-1]
    i = np.clip(np.searchsorted(cum, u, side="right") - 1, 0, len(lengths) - 1)
    frac = np.clip((u - cum[i]) / np.where(lengths[i] > 0, lengths[i], 1.0), 0.0, 1.0)
    return i, frac


@dataclass(frozen=True, eq=False)
class _Waves:
    """A smooth random field ``f(a, b)``: a sum of plane waves, peak at most ``amp``."""

    k: Array
    phase: Array
    weight: Array

    @classmethod
    def draw(cls, rng: np.random.Generator, amp: float, lam: tuple[float, float]) -> _Waves:
        m = 8
        ang = rng.uniform(0, 2 * math.pi, m)
        k = (2 * math.pi / rng.uniform(*lam, m))[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
        w = rng.uniform(0.3, 1.0, m)
        return cls(k, rng.uniform(0, 2 * math.pi, m), w * amp / w.sum())

    def __call__(self, a: Array, b: Array) -> Array:
        out = np.zeros(len(a))
        for (ka, kb), ph, w in zip(self.k, self.phase, self.weight, strict=True):
            out += w * np.sin(ka * a + kb * b + ph)
        return out


@dataclass(eq=False)
class _Wall:
    """A rough wall: plan polyline ``xy`` with, at each vertex, the arc length along the
    un-roughened wall, the centreline station and the taper of the height profile."""

    xy: Array
    arc: Array
    station: Array
    taper: Array
    rough: _Waves

    def __post_init__(self) -> None:
        d = np.diff(self.xy, axis=0)
        self.seglen = np.hypot(d[:, 0], d[:, 1])
        self.normal = np.stack([-d[:, 1], d[:, 0]], 1) / np.maximum(self.seglen, 1e-12)[:, None]


@dataclass(eq=False)
class _Drift:
    """A drift around a centreline polyline: floor on ``knots``/``zk``, arched roof, walls."""

    centre: Array
    width: float
    knots: Array
    zk: Array
    walls: tuple[_Wall, _Wall] = field(init=False)

    def __post_init__(self) -> None:
        self.S = _arc(self.centre)
        d = np.diff(self.centre, axis=0)
        self.dirs = d / np.hypot(d[:, 0], d[:, 1])[:, None]
        self.normals = np.stack([-self.dirs[:, 1], self.dirs[:, 0]], 1)
        # Mitred normals at the vertices, as Tunnel.walls: offsets interpolated between them
        # meet the walls exactly and leave no wedge open at a bend.
        vn = np.vstack([self.normals[:1], self.normals[:-1] + self.normals[1:], self.normals[-1:]])
        vn /= np.hypot(vn[:, 0], vn[:, 1])[:, None]
        vn[1:-1] /= np.sum(vn[1:-1] * self.normals[:-1], axis=1)[:, None]
        self.vnormals = vn
        phi = np.linspace(math.pi, 0.0, 25)
        self.roof = np.stack(
            [self.width / 2 * np.cos(phi), WALL_HEIGHT_M + (CROWN_M - WALL_HEIGHT_M) * np.sin(phi)],
            1,
        )
        self.floor = np.array([[-self.width / 2, 0.0], [self.width / 2, 0.0]])
        self.tunnel = Tunnel(self.centre, self.width)
        self.base_walls = self.tunnel.walls()  # left (w > 0), right
        self.vertex_arcs = tuple(_arc(w) for w in self.base_walls)
        #: per wall: (arc from, arc to, low, high, heights above the floor?) hidden from view
        self.hidden: tuple[list[tuple[float, float, float, float, bool]], ...] = ([], [])

    def hide(self, side: int, s0: float, s1: float, low: float, high: float, rel: bool) -> None:
        """Hide wall ``side`` between stations ``s0`` and ``s1`` (behind a beacon, a machine...)."""
        self.hidden[side].append((self.wall_arc(side, s0), self.wall_arc(side, s1), low, high, rel))

    def build_walls(
        self, rng: np.random.Generator, smooth: tuple[list[tuple[float, float]], ...]
    ) -> None:
        rough = Roughness(amplitude_m=float(rng.uniform(0.05, 0.08)))
        walls = []
        for base, va, intervals in zip(self.base_walls, self.vertex_arcs, smooth, strict=True):
            xy = roughen(base, rough, rng, smooth_intervals=intervals)
            step = min(0.05, rough.wavelength_min_m / 4)  # the resampling roughen does
            n = max(2, math.ceil(va[-1] / step) + 1)
            ss = np.union1d(np.linspace(0.0, va[-1], n), va)
            if len(ss) != len(xy):  # pragma: no cover - roughen changed its resampling
                raise RuntimeError("cannot follow roughen's resampling of a wall")
            taper = np.ones_like(ss)
            for a, b in intervals:
                dist = np.maximum(a - ss, ss - b) / rough.beacon_margin_m
                taper = np.minimum(taper, np.clip(dist, 0.0, 1.0))
            station = np.interp(ss, va, self.S)
            walls.append(_Wall(xy, ss, station, taper, _Waves.draw(rng, 0.03, (0.3, 1.5))))
        self.walls = (walls[0], walls[1])
        self.floor_rough = _Waves.draw(rng, 0.02, (0.3, 2.0))
        self.roof_rough = _Waves.draw(rng, float(rng.uniform(0.05, 0.1)), (0.4, 2.5))

    def floor_z(self, s: Array) -> Array:
        return np.interp(s, self.knots, self.zk)

    def at(self, s: float) -> tuple[Array, Array]:
        """Centreline point and unit direction at station ``s``."""
        j = int(np.clip(np.searchsorted(self.S, s, side="right") - 1, 0, len(self.dirs) - 1))
        return self.centre[j] + (s - self.S[j]) * self.dirs[j], self.dirs[j]

    def wall_arc(self, side: int, s: float) -> float:
        return float(np.interp(s, self.S, self.vertex_arcs[side]))

    def sweep(
        self,
        profile: Array,
        s0: float,
        s1: float,
        rho: float,
        rng: np.random.Generator,
        rough: _Waves | None,
    ) -> tuple[Array, Array, Array]:
        """Sample ``profile`` (``(w, h)``: left offset, height above floor) swept along
        the centreline over ``[s0, s1)``; returns points, stations and offsets ``w``."""
        lo = np.maximum(self.S[:-1], s0)
        seg = np.clip(np.minimum(self.S[1:], s1) - lo, 0.0, None)
        plen = np.hypot(*np.diff(profile, axis=0).T)
        n = int(rng.poisson(rho * seg.sum() * plen.sum()))
        j, f = _pick(seg, n, rng)
        s = lo[j] + f * seg[j]
        q, g = _pick(plen, n, rng)
        wh = profile[q] + g[:, None] * (profile[q + 1] - profile[q])
        if rough is not None:
            tang = (profile[q + 1] - profile[q]) / plen[q][:, None]
            off = rough(s, _arc(profile)[q] + g * plen[q])
            wh += off[:, None] * np.stack([-tang[:, 1], tang[:, 0]], 1)
        along = (s - self.S[j])[:, None]
        normal = self.vnormals[j] + along / (self.S[j + 1] - self.S[j])[:, None] * (
            self.vnormals[j + 1] - self.vnormals[j]
        )
        xy = self.centre[j] + along * self.dirs[j] + wh[:, :1] * normal
        return np.column_stack([xy, self.floor_z(s) + wh[:, 1]]), s, wh[:, 0]

    def wall_points(
        self, side: int, s0: float, s1: float, rho: float, rng: np.random.Generator
    ) -> tuple[Array, Array]:
        """Sample a wall over the centreline stations ``[s0, s1)``: points and stations."""
        w = self.walls[side]
        k0, k1 = np.searchsorted(w.station, [s0, s1])
        k1 = min(int(k1), len(w.seglen))
        if k1 <= k0:
            return np.empty((0, 3)), np.empty(0)
        i, f = _pick(
            w.seglen[k0:k1], int(rng.poisson(rho * w.seglen[k0:k1].sum() * WALL_HEIGHT_M)), rng
        )
        k = k0 + i
        arc = w.arc[k] + f * (w.arc[k + 1] - w.arc[k])
        st = w.station[k] + f * (w.station[k + 1] - w.station[k])
        taper = w.taper[k] + f * (w.taper[k + 1] - w.taper[k])
        h = rng.random(len(k)) * WALL_HEIGHT_M
        off = taper * w.rough(arc, h)
        xy = w.xy[k] + f[:, None] * (w.xy[k + 1] - w.xy[k]) + off[:, None] * w.normal[k]
        z = self.floor_z(st) + h
        keep = np.ones(len(k), dtype=bool)
        for a, b, low, high, relative in self.hidden[side]:
            if b >= w.arc[k0] and a <= w.arc[k1]:
                v = h if relative else z
                keep &= ~((arc >= a) & (arc <= b) & (v >= low) & (v <= high))
        return np.column_stack([xy, z])[keep], st[keep]

    def face(self, s: float, rho: float, rng: np.random.Generator, rough: _Waves) -> Array:
        """Sample the rock face closing the drift at station ``s``."""
        half, rise = self.width / 2, CROWN_M - WALL_HEIGHT_M
        n = int(rng.poisson(rho * (self.width * WALL_HEIGHT_M + math.pi * half * rise / 2)))
        got: list[Array] = []
        while sum(len(g) for g in got) < n:
            cand = rng.random((n + 16, 2)) * [self.width, CROWN_M] - [half, 0.0]
            top = WALL_HEIGHT_M + rise * np.sqrt(np.clip(1 - (cand[:, 0] / half) ** 2, 0, 1))
            got.append(cand[cand[:, 1] <= top])
        wh = np.concatenate(got)[:n]
        c, d = self.at(s)
        xy = c + wh[:, :1] * np.array([-d[1], d[0]]) + rough(wh[:, 0], wh[:, 1])[:, None] * d
        return np.column_stack([xy, self.floor_z(np.full(n, s)) + wh[:, 1]])


@dataclass(frozen=True, eq=False)
class _Rect:
    """A flat rectangle ``origin + u a + v b``, at a station of the main drift."""

    origin: Array
    a: Array
    b: Array
    kind: int
    station: float
    tag: int = -1  # 3 * beacon + panel for beacon panels


@dataclass(frozen=True, eq=False)
class _Post:
    """A vertical cylinder, sampled over the 220 degrees from ``phi0`` (those facing the drift)."""

    centre: Array
    radius: float
    z0: float
    z1: float
    phi0: float
    station: float
    kind: int = METAL


def _box(
    c: Array, z0: float, yaw: float, size: Sequence[float] | Array, skip: str, s: float
) -> list[_Rect]:
    """Faces of a box (no bottom) standing at ``z0``, minus those named in ``skip``."""
    lx, ly, lz = size
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    v = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    up = np.array([0.0, 0.0, lz])
    base = np.array([c[0], c[1], z0]) - lx / 2 * u - ly / 2 * v
    faces = {
        "-x": (base, ly * v, up),
        "+x": (base + lx * u, ly * v, up),
        "-y": (base, lx * u, up),
        "+y": (base + ly * v, lx * u, up),
        "top": (base + up, lx * u, ly * v),
    }
    return [_Rect(o, a, b, METAL, s) for name, (o, a, b) in faces.items() if name not in skip]


@dataclass(frozen=True, eq=False)
class _BeaconTruth:
    id: str
    station: float
    side: int
    edges: Array  # (4, 2) site frame
    z_top: float


def _pack(
    parts: list[tuple[Array, Array, int, int]],
) -> tuple[Array, Array, NDArray[np.uint8], NDArray[np.intp]]:
    """Points, stations (one per point, or one for all), kinds and tags (a beacon
    panel's ``3 * beacon + panel``, else -1), as four arrays."""
    xyz = np.concatenate([p[0] for p in parts])
    st = np.concatenate([np.broadcast_to(p[1], len(p[0])) for p in parts])
    kind = np.concatenate([np.full(len(p[0]), p[2], dtype=np.uint8) for p in parts])
    return xyz, st, kind, np.concatenate([np.full(len(p[0]), p[3], dtype=np.intp) for p in parts])


@dataclass(eq=False)
class _Scene:
    """Everything placed, in the site frame (grid minus ``(E0, N0)``)."""

    main: _Drift
    length: float
    sides: list[tuple[float, _Drift, Array, Array]] = field(default_factory=list)
    items: list[_Rect | _Post] = field(default_factory=list)
    extras: list[tuple[Array, float, float]] = field(default_factory=list)
    floor_occ: list[tuple[float, float, float, float]] = field(default_factory=list)
    beacons: list[_BeaconTruth] = field(default_factory=list)
    clutter: list[dict[str, Any]] = field(default_factory=list)
    junctions: list[dict[str, Any]] = field(default_factory=list)

    def batches(
        self, rho: float, rng: np.random.Generator, step: float
    ) -> Iterator[tuple[Array, Array, NDArray[np.uint8], NDArray[np.intp]]]:
        """Points (true, site frame), stations, kinds and tags, stretch by stretch."""
        m, L = self.main, self.length
        starts = np.arange(0.0, L, step)
        face_rough = m.walls[0].rough
        for i, s0 in enumerate(starts):
            s1 = math.inf if i == len(starts) - 1 else float(starts[i + 1])
            parts: list[tuple[Array, Array, int, int]] = []
            xyz, s, w = m.sweep(m.floor, s0, s1, rho, rng, m.floor_rough)
            keep = np.ones(len(s), dtype=bool)
            for a, b, wa, wb in self.floor_occ:
                keep &= ~((s >= a) & (s <= b) & (w >= wa) & (w <= wb))
            parts.append((xyz[keep], s[keep], ROCK, -1))
            xyz, s, _ = m.sweep(m.roof, s0, s1, rho, rng, m.roof_rough)
            parts.append((xyz, s, ROCK, -1))
            for side in (0, 1):
                parts.append((*m.wall_points(side, s0, s1, rho, rng), ROCK, -1))
            for profile, a, b in self.extras:
                if a < s1 and b > s0:
                    xyz, s, _ = m.sweep(profile, max(a, s0), min(b, s1), rho, rng, None)
                    parts.append((xyz, s, METAL, -1))
            for at in (0.0, L):
                if s0 <= at < s1:
                    parts.append((m.face(at, rho, rng, face_rough), np.full(1, at), ROCK, -1))
            for item in self.items:
                if s0 <= item.station < s1:
                    tag = item.tag if isinstance(item, _Rect) else -1
                    parts.append((*self._item(item, rho, rng), item.kind, tag))
            yield _pack(parts)
            for sj, d, J, nm in self.sides:  # side drifts, in pieces, seen from the junction
                if not s0 <= sj < s1:
                    continue
                pieces = np.arange(0.0, d.S[-1], step)
                for k, a in enumerate(pieces):
                    b = math.inf if k == len(pieces) - 1 else float(pieces[k + 1])
                    pts = [d.sweep(d.floor, a, b, rho, rng, d.floor_rough)[0]]
                    pts.append(d.sweep(d.roof, a, b, rho, rng, d.roof_rough)[0])
                    pts += [d.wall_points(side, a, b, rho, rng)[0] for side in (0, 1)]
                    if b == math.inf:
                        pts.append(d.face(float(d.S[-1]), rho, rng, face_rough))
                    p = np.concatenate(pts)
                    p = p[np.abs((p[:, :2] - J) @ nm) >= m.width / 2]  # outside the main drift
                    yield _pack([(p, np.full(1, sj), ROCK, -1)])

    def _item(
        self, item: _Rect | _Post, rho: float, rng: np.random.Generator
    ) -> tuple[Array, Array]:
        if isinstance(item, _Rect):
            n = int(rng.poisson(rho * np.linalg.norm(np.cross(item.a, item.b))))
            uv = rng.random((n, 2))
            p = item.origin + uv[:, :1] * item.a + uv[:, 1:] * item.b
        else:
            arc = math.radians(220.0)
            n = int(rng.poisson(rho * item.radius * arc * (item.z1 - item.z0)))
            phi = item.phi0 + rng.random(n) * arc
            z = item.z0 + rng.random(n) * (item.z1 - item.z0)
            p = np.column_stack(
                [item.centre + item.radius * np.column_stack([np.cos(phi), np.sin(phi)]), z]
            )
        c, d = self.main.at(item.station)
        return p, item.station + (p[:, :2] - c) @ d


# --------------------------------------------------------------------------- the scene


def _centreline(rng: np.random.Generator, L: float) -> tuple[Array, list[tuple[float, float]]]:
    """Main centreline from the origin: straights and two gentle bends; the bends' stations."""
    bend = min(15.0, 0.1 * L)
    heading = float(rng.uniform(0, 2 * math.pi))
    stations, headings, bends = [0.0], [], []
    for frac in (1 / 3, 2 / 3):
        a = L * (frac + rng.uniform(-0.04, 0.04)) - bend / 2
        turn = math.radians(rng.uniform(12, 25)) * rng.choice([-1, 1])
        n = max(3, round(bend / 1.5))
        stations.append(a)
        headings.append(heading)
        for i in range(n):
            stations.append(a + (i + 1) * bend / n)
            headings.append(heading + turn * (i + 0.5) / n)
        heading += turn
        bends.append((a, a + bend))
    stations.append(L)
    headings.append(heading)
    ds, hd = np.diff(stations), np.array(headings)
    steps = ds[:, None] * np.stack([np.cos(hd), np.sin(hd)], 1)
    return np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)]), bends


class _Layout:
    """Station intervals taken along the main drift, per wall (0 left, 1 right)."""

    def __init__(self, length: float) -> None:
        self.length = length
        self.busy: list[tuple[float, float, int, int, bool]] = []  # lo, hi, side, tag, machine

    def take(self, lo: float, hi: float, side: int, tag: int = -1, machine: bool = False) -> None:
        self.busy.append((lo, hi, side, tag, machine))

    def free(
        self, lo: float, hi: float, side: int, ignore: int = -1, machine: bool = False
    ) -> bool:
        if lo < 3.0 or hi > self.length - 3.0:
            return False
        return not any(
            lo < b and hi > a and tag != ignore and (sd == side or (machine and mach))
            for a, b, sd, tag, mach in self.busy
        )

    def place(
        self, rng: np.random.Generator, half: float, side: int, machine: bool = False
    ) -> float | None:
        for _ in range(200):
            s = float(rng.uniform(5.0 + half, self.length - 5.0 - half))
            if self.free(s - half, s + half, side, machine=machine):
                return s
        return None


_SIDES = ("left", "right")


def _build(o: CloudOptions, rng: np.random.Generator) -> tuple[_Scene, float, float, float]:
    """The scene in the site frame, the floor elevation at the start, E0 and N0."""
    L = o.length_m
    centre, bends = _centreline(rng, L)
    knots = np.array([0.0, *np.sort(rng.uniform([0.1, 0.45, 0.7], [0.25, 0.6, 0.85])) * L, L])
    grades = [rng.uniform(-0.01, 0.01), -0.05, rng.uniform(-0.02, 0.01), rng.uniform(-0.05, -0.02)]
    z0 = -850.0 + float(rng.uniform(-25, 25))
    zk = z0 + np.concatenate([[0.0], np.cumsum(np.diff(knots) * grades)])
    m = _Drift(centre, WIDTH_M, knots, zk)
    scene, lay = _Scene(m, L), _Layout(L)
    half_w = WIDTH_M / 2
    # Junctions: on straights, away from bends and ends; the middle straight first.
    straights = [(bends[0][1] + 6, bends[1][0] - 6), (10.0, bends[0][0] - 6)]
    straights.append((bends[1][1] + 6, L - 10.0))
    exclude: list[tuple[float, float]] = []
    for lo, hi in straights[: 2 if L >= 150 else 1 if L >= 50 else 0]:
        if hi <= lo:
            continue
        sj, side = float(rng.uniform(lo, hi)), int(rng.integers(2))
        sigma = 1 - 2 * side
        J, dm = m.at(sj)
        nm = np.array([-dm[1], dm[0]])
        angle = math.radians(rng.uniform(55, 125))
        ds = _rot(sigma * angle) @ dm
        ns = np.array([-ds[1], ds[0]])
        width, stub = float(rng.uniform(4.0, 5.0)), float(rng.uniform(10, 20))
        v = [
            np.linalg.solve(np.column_stack([ds, -dm]), sigma * half_w * nm - off * ns)[1]
            for off in (width / 2, -width / 2)
        ]
        v_lo, v_hi = min(v), max(v)
        m.hide(side, sj + v_lo, sj + v_hi, -1e9, 1e9, True)
        exclude.append((sj + v_lo - 5.5, sj + v_hi + 5.5))
        lay.take(sj + v_lo - 1, sj + v_hi + 1, side)
        length = half_w / math.sin(angle) + stub
        grade = float(rng.uniform(-0.03, 0.03))
        zj = float(m.floor_z(np.array([sj]))[0])
        d = _Drift(
            np.array([J, J + length * ds]),
            width,
            np.array([0.0, length]),
            np.array([zj, zj + grade * length]),
        )
        d.build_walls(rng, ([], []))
        scene.sides.append((sj, d, J, nm))
        scene.junctions.append(
            _note(
                "junction",
                side,
                station_m=sj,
                angle_deg=math.degrees(angle),
                width_m=width,
                length_m=stub,
                grade=grade,
            )
        )
    # Beacons: random gaps fitted into the stations allowed, alternating walls.
    allowed = [(5.5, L - 5.5)]
    for a, b in sorted(exclude):
        allowed = [piece for lo, hi in allowed for piece in ((lo, min(hi, a)), (max(lo, b), hi))]
    allowed = [(lo, hi) for lo, hi in allowed if hi > lo]
    room = np.array([hi - lo for lo, hi in allowed])
    gaps = rng.uniform(15, 40, o.beacons + 1)
    gaps[[0, -1]] *= 0.5  # half a gap from the ends
    gaps *= room.sum() / gaps.sum()
    if o.beacons > 1 and gaps[1:-1].min() < 3.0:
        raise InputError(
            f"{o.beacons} beacons do not fit in a drift of {L:g} m (3 m apart at least)"
        )
    designs = [paper_design()] + [
        random_design(rng, chord_range_m=(0.7, 1.3), deflection_range_deg=(20.0, 35.0))
        for _ in range(o.designs - 1)
    ]
    first = int(rng.integers(2))
    cum = np.concatenate([[0.0], np.cumsum(room)])
    smooth: tuple[list[tuple[float, float]], list[tuple[float, float]]] = ([], [])
    for i, virtual in enumerate(np.cumsum(gaps)[:-1]):
        k = int(np.clip(np.searchsorted(cum, virtual, side="right") - 1, 0, len(room) - 1))
        s, side = allowed[k][0] + float(virtual - cum[k]), (first + i) % 2
        arc = m.wall_arc(side, s)
        point, tangent, tunnel_side = m.tunnel.wall_point(_SIDES[side], arc)
        design = designs[i % len(designs)]
        edges = design.mounted(point, tangent, tunnel_side=tunnel_side)
        top = float(m.floor_z(np.array([s]))[0]) + o.beacon_top_m
        half = design.chord_m / 2
        if not o.rock_behind_beacons:
            smooth[side].append((arc - half, arc + half))
        m.hidden[side].append((arc - half, arc + half, top - o.panel_height_m, top, False))
        lay.take(s - 1.5, s + 1.5, side, tag=i)
        for p in range(3):
            origin = np.array([*edges[p], top - o.panel_height_m])
            a3 = np.array([*(edges[p + 1] - edges[p]), 0.0])
            scene.items.append(
                _Rect(origin, a3, np.array([0, 0, o.panel_height_m]), BEACON, s, 3 * i + p)
            )
        scene.beacons.append(_BeaconTruth(f"B{i + 1:02d}", s, side, edges, top))
    m.build_walls(rng, smooth)
    _clutter(scene, lay, rng)
    return (
        scene,
        z0,
        452_000.0 + float(rng.uniform(0, 999)),
        7_101_000.0 + float(rng.uniform(0, 999)),
    )


def _note(kind: str, side: int, **fields: Any) -> dict[str, Any]:
    return {"kind": kind, "side": _SIDES[side], **fields}


def _clutter(scene: _Scene, lay: _Layout, rng: np.random.Generator) -> None:
    """Pipes, a duct, machines, posts and cabinets: things that are not beacons."""
    m, L, half_w = scene.main, scene.length, WIDTH_M / 2
    rise = CROWN_M - WALL_HEIGHT_M

    def frame(s: float, side: int) -> tuple[Array, Array, Array, int, float]:
        c, d = m.at(s)
        return c, d, np.array([-d[1], d[0]]), 1 - 2 * side, float(m.floor_z(np.array([s]))[0])

    duct_side = int(rng.integers(2))
    pipe_side = 1 - duct_side
    sigma = 1 - 2 * pipe_side
    for h_c in (rng.uniform(2.5, 2.65), rng.uniform(3.0, 3.2)):
        r = float(rng.uniform(0.05, 0.12))
        a, b = float(rng.uniform(0, 0.15 * L)), L - float(rng.uniform(0, 0.15 * L))
        w_c = sigma * (half_w - r - 0.08)
        ang = math.atan2(SCANNER_HEIGHT_M - h_c, -w_c) + np.radians(np.linspace(-100, 100, 17))
        scene.extras.append((np.column_stack([w_c + r * np.cos(ang), h_c + r * np.sin(ang)]), a, b))
        m.hide(pipe_side, a, b, h_c - r, h_c + r, True)
        note = _note("pipe", pipe_side, from_m=a, to_m=b, diameter_m=2 * r, height_m=float(h_c))
        scene.clutter.append(note)
    sigma = 1 - 2 * duct_side
    width, bottom = float(rng.uniform(0.8, 1.0)), 3.5 - float(rng.uniform(0.5, 0.6))
    a, b = float(rng.uniform(0, 0.1 * L)), L - float(rng.uniform(0, 0.1 * L))
    w_wall, w_in = sigma * (half_w - 0.08), sigma * (half_w - 0.08 - width)
    scene.extras.append((np.array([[w_wall, bottom], [w_in, bottom], [w_in, 3.5]]), a, b))
    m.hide(duct_side, a, b, bottom, 1e9, True)
    size = [width, 3.5 - bottom]
    scene.clutter.append(_note("duct", duct_side, from_m=a, to_m=b, size_m=size, bottom_m=bottom))
    # Machines; the first beside a beacon (a corner near it, not in front of it).
    for i in range(int(rng.integers(2, 5))):
        lx, ly, lz = rng.uniform([2.3, 1.8, 1.8], [2.8, 2.1, 2.0])
        gap, near = float(rng.uniform(0.15, 0.5)), None
        s: float | None = None
        if i == 0 and scene.beacons:
            bt = scene.beacons[int(rng.integers(len(scene.beacons)))]
            s = bt.station + rng.choice([-1, 1]) * (0.5 + rng.uniform(0.3, 1.0) + lx / 2)
            side = bt.side
            if lay.free(s - lx / 2 - 0.5, s + lx / 2 + 0.5, side, scene.beacons.index(bt), True):
                near = bt.id
            else:
                s = None
        if s is None:
            side = int(rng.integers(2))
            s = lay.place(rng, lx / 2 + 0.5, side, machine=True)
            if s is None:
                continue
        lay.take(s - lx / 2 - 0.5, s + lx / 2 + 0.5, side, machine=True)
        c, d, n, sigma, zf = frame(s, side)
        z_base = float(np.min(m.floor_z(np.array([s - lx / 2, s + lx / 2]))))
        centre = c + sigma * (half_w - gap - ly / 2) * n
        yaw = math.atan2(d[1], d[0]) + math.radians(rng.uniform(-3, 3))
        wall_face = "+y" if sigma > 0 else "-y"
        scene.items += _box(centre, z_base, yaw, (lx, ly, lz), wall_face, s)
        cab = rng.uniform([1.0, 1.2, 0.7], [1.4, 1.4, 0.9])
        u, v = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
        cab_c = centre + rng.choice([-1, 1]) * (lx - cab[0]) / 2 * u - sigma * (ly - cab[1]) / 2 * v
        scene.items += _box(cab_c, z_base + lz, yaw, cab, "", s)
        w_lo, w_hi = sorted((sigma * (half_w - gap - ly), sigma * half_w))
        scene.floor_occ.append((s - lx / 2, s + lx / 2, w_lo, w_hi))
        m.hide(side, s - lx / 2, s + lx / 2, -1e9, z_base + lz, False)
        size, cab_size = [lx, ly, lz], cab.tolist()
        scene.clutter.append(
            _note(
                "machine",
                side,
                station_m=s,
                size_m=size,
                cab_m=cab_size,
                gap_to_wall_m=gap,
                near_beacon=near,
            )
        )
    for _ in range(int(rng.integers(2, 5))):  # posts, floor to roof, beyond the pipes
        r, off = float(rng.uniform(0.05, 0.125)), float(rng.uniform(0.45, 0.8))
        s = lay.place(rng, 2.0, pipe_side)
        if s is None:
            continue
        lay.take(s - 0.5, s + 0.5, pipe_side)
        c, d, n, sigma, zf = frame(s, pipe_side)
        w = sigma * (half_w - off - r)
        roof = WALL_HEIGHT_M + rise * math.sqrt(max(0.0, 1 - (w / half_w) ** 2))
        facing = math.atan2(-sigma * n[1], -sigma * n[0])
        scene.items.append(_Post(c + w * n, r, zf, zf + roof, facing - math.radians(110), s))
        scene.clutter.append(_note("post", pipe_side, station_m=s, diameter_m=2 * r))
    for _ in range(int(rng.integers(1, 3))):  # wall cabinets: right-angled look-alikes
        side, bottom = int(rng.integers(2)), float(rng.uniform(0.4, 0.8))
        s = lay.place(rng, 1.0, side)
        if s is None:
            continue
        lay.take(s - 1.0, s + 1.0, side)
        c, d, n, sigma, zf = frame(s, side)
        skip = ("+y" if sigma > 0 else "-y") + "top"
        yaw = math.atan2(d[1], d[0])
        scene.items += _box(
            c + sigma * (half_w - 0.28) * n, zf + bottom, yaw, (1.0, 0.4, 1.5), skip, s
        )
        m.hide(side, s - 0.5, s + 0.5, zf + bottom, zf + bottom + 1.5, False)
        size = [1.0, 0.4, 1.5]
        scene.clutter.append(_note("cabinet", side, station_m=s, size_m=size, bottom_m=bottom))


# --------------------------------------------------------------------------- the run


@dataclass(eq=False)
class _Run:
    """Scanner poses every 0.1 s (true, site frame) and the SLAM error ``D`` at each."""

    s: Array
    t: Array
    xy: Array
    z: Array
    heading: Array
    psi: Array
    e: Array
    zeta: Array
    theta: float
    z_start: float
    final_error_m: float

    def __post_init__(self) -> None:
        # psi, e, true position, zeta, time; then the SLAM position in the local frame
        self.table = np.column_stack([self.psi, self.e, self.xy, self.zeta, self.t])
        self.poses = self.to_local(np.column_stack([self.xy, self.z]), self.table)
        self.table = np.column_stack([self.table, self.poses])

    def at(self, st: Array) -> Array:
        """Rows of :attr:`table` interpolated at stations ``st`` (one lookup for all)."""
        step = self.s[1] - self.s[0]
        i = np.clip((st / step).astype(np.intp), 0, len(self.s) - 2)
        f = (st - self.s[i]) / (self.s[i + 1] - self.s[i])
        lo = self.table[i]
        out: Array = lo + f[:, None] * (self.table[i + 1] - lo)
        return out

    def to_local(self, p: Array, rows: Array) -> Array:
        """``T0^-1 D(t) p`` for site points ``p`` seen at the times of ``rows``."""
        psi, ex, ey, x0, y0, zeta = rows[:, :6].T
        dx, dy = p[:, 0] - x0, p[:, 1] - y0
        c, sn = np.cos(psi) - 1.0, np.sin(psi)
        x = p[:, 0] + (c * dx - sn * dy) + ex
        y = p[:, 1] + (sn * dx + c * dy) + ey
        ct, st_ = math.cos(self.theta), math.sin(self.theta)
        return np.column_stack([ct * x + st_ * y, -st_ * x + ct * y, p[:, 2] + zeta - self.z_start])


def _run(scene: _Scene, drift: float, theta: float, rng: np.random.Generator) -> _Run:
    m, L = scene.main, scene.length
    step = SPEED_MPS * POSE_PERIOD_S
    n = math.ceil(L / step - 1e-9)
    s = np.minimum(np.arange(n + 1) * step, L)
    j = np.clip(np.searchsorted(m.S, s, side="right") - 1, 0, len(m.dirs) - 1)
    xy = m.centre[j] + (s - m.S[j])[:, None] * m.dirs[j]
    heading = np.arctan2(m.dirs[j, 1], m.dirs[j, 0])
    z = m.floor_z(s) + SCANNER_HEIGHT_M
    # Raw error shapes are always drawn, so the stream does not depend on ``drift``.
    # A random walk of the heading error through knots 15 m or more apart, linear between
    # them: the heading error changes slowly, so the cloud is consistent over a few metres.
    knots = np.linspace(0.0, L, max(2, round(min(6.0, L / 15.0))) + 1)
    steps = rng.normal(size=len(knots) - 1) * np.sqrt(np.diff(knots) / L)
    walk = np.interp(s, knots, 0.5 * np.concatenate([[0.0], np.cumsum(steps)]))
    # The bias turns the same way as the walk on average: the two never cancel, so the
    # end error is not made of large heading errors that happen to cancel out.
    bias = rng.uniform(0.5, 1.0) * (1.0 if walk.sum() >= 0 else -1.0)
    psi_raw = bias * s / L + walk
    k_raw, z_sign = rng.normal(0, 0.05), rng.choice([-1, 1]) * rng.uniform(0.8, 1.2)
    psi, e, zeta = np.zeros(n + 1), np.zeros((n + 1, 2)), np.zeros(n + 1)
    if drift > 0:
        dx, dy = np.diff(xy, axis=0).T
        alpha = drift
        for _ in range(10):
            psi, k = alpha * psi_raw, alpha * k_raw
            c, sn = np.cos(psi[:-1]), np.sin(psi[:-1])
            steps = np.column_stack(
                [(1 + k) * (c * dx - sn * dy) - dx, (1 + k) * (sn * dx + c * dy) - dy]
            )
            e = np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
            alpha *= drift * L / max(float(np.hypot(*e[-1])), 1e-12)
        zeta = z_sign * 0.3 * drift * s
    t = START_TIME_S + POSE_PERIOD_S * np.arange(n + 1, dtype=np.float64)
    return _Run(s, t, xy, z, heading, psi, e, zeta, theta, float(z[0]), float(np.hypot(*e[-1])))


# --------------------------------------------------------------------------- writing


def _las_header(offsets: Array) -> laspy.LasHeader:
    extra = laspy.ExtraBytesParams("range", np.float32, description="scanner range at gps_time")
    return new_las_header(
        offsets=offsets,
        software="mast.sim.cloud",
        system="MAST simulated SLAM",
        gps_standard=False,  # GPS week seconds, as a SLAM cloud often has
        extra=[extra],
        created=datetime.date(2026, 1, 1),  # fixed: same seed, same bytes
    )


def _write_cloud(
    path: Path, scene: _Scene, run: _Run, o: CloudOptions, rho: float, rng: np.random.Generator
) -> tuple[int, Array]:
    """Stream the cloud to ``path``; the number of points and the beacons' panel counts."""
    poses = run.poses
    offsets = np.round((poses.min(axis=0) + poses.max(axis=0)) / 2)
    header = _las_header(offsets)
    dtype = header.point_format.dtype()
    counts = np.zeros((len(scene.beacons), 3))
    step = float(np.clip(o.chunk_points / (4 * rho * 25.0), 0.25, 10.0))
    limit = o.max_points if o.max_points is not None else np.iinfo(np.int64).max
    written, pending = 0, []
    with LasWriter(path, header) as las:

        def flush(arr: NDArray[Any]) -> None:
            nonlocal written
            arr = arr[: max(0, limit - written)]
            if len(arr):
                written += las.write(las.record(arr))

        for xyz, st, kind, tag in scene.batches(rho, rng, step):
            n = len(st)
            sig = np.clip(st + rng.uniform(-TIME_JITTER_M, TIME_JITTER_M, n), 0.0, scene.length)
            rows = run.at(sig)
            p = run.to_local(xyz, rows)
            if o.noise_m > 0:
                p += rng.normal(0.0, o.noise_m, (n, 3))
            rng_m = np.sqrt(np.sum((p - rows[:, 7:10]) ** 2, axis=1))
            if o.falloff_m is not None:  # fewer points per square metre farther away
                kept = rng.random(n) < np.minimum(1.0, (o.falloff_m / rng_m) ** 2)
                xyz, st, kind, tag, sig, rows, p, rng_m = (
                    a[kept] for a in (xyz, st, kind, tag, sig, rows, p, rng_m)
                )
                n = len(st)
            on = tag >= 0
            np.add.at(counts, (tag[on] // 3, tag[on] % 3), 1)
            lo, hi, att = _INTENSITY[kind].T
            inten = (lo + rng.random(n) * (hi - lo)) / (1 + att * rng_m)
            rec = np.zeros(n, dtype=dtype)
            for i, name in enumerate("XYZ"):
                rec[name] = np.round((p[:, i] - offsets[i]) / LAS_SCALE_M)
            rec["intensity"] = np.clip(inten, 0, 65535)
            rec["bit_fields"] = 0x11  # return 1 of 1
            rec["point_source_id"] = 1
            rec["gps_time"] = rows[:, 6]
            rec["range"] = rng_m
            pending.append(rec)
            if sum(len(a) for a in pending) >= o.chunk_points:
                cat = np.concatenate(pending)
                for i in range(0, len(cat) - o.chunk_points + 1, o.chunk_points):
                    flush(cat[i : i + o.chunk_points])
                pending = [cat[len(cat) - len(cat) % o.chunk_points :]]
        if pending:
            flush(np.concatenate(pending))
    return written, counts


def _check(o: CloudOptions) -> None:
    problems = [
        (30.0 <= o.length_m <= 100_000.0, f"length_m {o.length_m} must be within 30-100000 m"),
        (o.beacons >= 0, f"beacons {o.beacons} must not be negative"),
        (0.0 <= o.drift < 0.2, f"drift {o.drift} must be within [0, 0.2)"),
        (
            o.noise_m >= 0 and o.survey_sigma_m >= 0,
            "noise_m and survey_sigma_m must not be negative",
        ),
        (o.density > 0, f"density {o.density} must be positive"),
        (
            0 < o.panel_height_m <= o.beacon_top_m <= 2.3,
            "need 0 < panel_height_m <= beacon_top_m <= 2.3 m (the pipes run above)",
        ),
        (o.chunk_points >= 1000, f"chunk_points {o.chunk_points} must be at least 1000"),
        (o.max_points is None or o.max_points >= 1, "max_points must be positive"),
        (1 <= o.designs <= 20, f"designs {o.designs} must be within 1-20"),
        (
            o.falloff_m is None or (math.isfinite(o.falloff_m) and o.falloff_m > 0),
            f"falloff_m {o.falloff_m} must be a positive number of metres",
        ),
    ]
    for ok, problem in problems:
        if not ok:
            raise InputError(f"cloud options: {problem}")


def simulate_cloud(
    out: str | Path, seed: int = 0, options: CloudOptions = CloudOptions()
) -> CloudScenario:
    """Simulate a SLAM point cloud of a drift with beacons and write it to ``out``.

    Parameters
    ----------
    out : str or Path
        Folder to write (created): ``cloud.laz``, ``beacons.csv``, ``trajectory.tum``,
        ``truth.json`` (see the module docstring for their contents).
    seed : int
        Seed of everything random; the geometry does not depend on ``drift``,
        ``noise_m``, ``density``, ``survey_sigma_m`` or the chunking.
    options : CloudOptions
        What to simulate.

    Returns
    -------
    CloudScenario
        The paths written, the number of points and of beacons.

    Raises
    ------
    InputError
        Options out of range, or more beacons than the drift holds.
    OutputError
        A file cannot be written.
    """
    o = options
    _check(o)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    geo, drift_rng, pts_rng, survey_rng, pilot_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(5)
    )
    scene, _, e0, n0 = _build(o, geo)
    theta = float(geo.uniform(0, 2 * math.pi))
    run = _run(scene, o.drift, theta, drift_rng)
    rho = o.density
    if o.max_points is not None:  # estimate the area from a sparse pilot, then thin
        pilot = min(rho, 2e5 / (25.0 * o.length_m))
        area = sum(len(b[1]) for b in scene.batches(pilot, pilot_rng, 10.0)) / pilot
        rho = min(rho, o.max_points * (1 - 4 / math.sqrt(o.max_points) - 0.01) / area)
        rho = max(rho, 1e-9)
    cloud, survey, trajectory = (
        folder / "cloud.laz",
        folder / "beacons.csv",
        folder / "trajectory.tum",
    )
    paths = CloudScenario(cloud, survey, trajectory, folder / "truth.json", 0, len(scene.beacons))
    sig, surveyed = o.survey_sigma_m, []
    for b in scene.beacons:  # survey noise on the edges' grid coordinates and top elevations
        en = b.edges + [e0, n0] + survey_rng.normal(0, sig, (4, 2))
        surveyed.append(Beacon(b.id, en, b.z_top + survey_rng.normal(0, sig, 4)))
    write_survey(paths.survey, Survey(surveyed))
    points, counts = _write_cloud(paths.cloud, scene, run, o, rho, pts_rng)
    pos, yaw = run.poses, run.heading + run.psi - run.theta
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [
        f"{t:.6f} {x:.6f} {y:.6f} {z:.6f} 0 0 {math.sin(a / 2):.9f} {math.cos(a / 2):.9f}"
        for t, (x, y, z), a in zip(run.t, pos, yaw, strict=True)
    ]
    with atomic_open(paths.trajectory, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
    beacons = []
    for i, b in enumerate(scene.beacons):
        t_b = np.interp(b.station, run.s, run.t)
        top = np.column_stack([b.edges, np.full(4, b.z_top)])
        local = run.to_local(top, run.at(np.full(4, b.station)))
        beacons.append(
            {
                "id": b.id,
                "side": _SIDES[b.side],
                "station_m": b.station,
                "panel_points": [int(c) for c in counts[i]],
                "top_elevation_m": b.z_top,
                "time_s": float(t_b),
                "edges_grid": (top + [e0, n0, 0.0]).tolist(),
                "edges_local": local.tolist(),
            }
        )
    truth = {
        "model": "4-parameter",
        "rotation_deg": math.degrees(theta),
        "easting_m": e0,
        "northing_m": n0,
        "elevation_m": run.z_start,
        "drift": o.drift,
        "noise_m": o.noise_m,
        "seed": seed,
        "options": dataclasses.asdict(o),
        "points": points,
        "density": rho,
        "start_time_s": START_TIME_S,
        "speed_mps": SPEED_MPS,
        "scanner_height_m": SCANNER_HEIGHT_M,
        "final_error_m": run.final_error_m,
        "beacons": beacons,
        "junctions": scene.junctions,
        "clutter": scene.clutter,
    }
    write_atomic(paths.truth, (json.dumps(truth, indent=1) + "\n").encode())
    return dataclasses.replace(paths, points=points)
