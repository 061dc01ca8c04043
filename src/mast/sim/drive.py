"""A simulated drive: a vehicle carrying a scanner along a drift, scan by scan at the
scanner's rate, with beacons in stretches and long stretches without any.

The drift is a smooth centreline (straights joined by circular bends) with rough rock
walls and a face at each end. Beacons of the three standard designs
(:data:`mast.sim.hard.DRIFT_CATALOGUE`) stand every 6-14 m on alternating walls in
stretches of 20-70 m, separated by 30-60 m without any, so that many scans see fewer
than two beacons and a run must be carried across the gaps by odometry.

The vehicle drives forward along the centreline at 1-3 m/s (a smooth sum of slow
sinusoids), wanders a little from side to side, and its heading follows the path
with a small correlated yaw noise. The scanner is LMS1xx-like: 270°, 0.25° at 25 Hz
or 0.5° at 50 Hz, 12 mm range noise, 30 m range; stamps run at the scanner's rate
from 2026-01-01 06:00 UTC. Each scan is taken at one instant (no motion skew within
a sweep).

Scans are simulated one at a time (:meth:`DriveScene.iter_simulated`), each
ray-cast only against the walls within the scanner's reach, so that a drive of any
length can be streamed to a bag without holding its scans.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core.beacon import Survey
from mast.core.pose import Pose2D
from mast.errors import InputError
from mast.sim.design import BeaconDesign
from mast.sim.mounting import DRIFT_CATALOGUE, mount_beacons
from mast.sim.scanner import ScannerModel, SimulatedScan, simulate_scan
from mast.sim.scene import Scene, Shot
from mast.sim.tunnel import Roughness, Tunnel, roughen
from mast.sim.world import Surface, World

__all__ = [
    "DEFAULT_DRIVE_SCANS",
    "DRIVE_START_NS",
    "DriveScene",
    "Reach",
    "drive_scanner",
    "drive_scenario",
    "drive_scene",
]

#: Scans of the default drive: 20 s at 25 Hz, from a stretch of beacons into a gap.
DEFAULT_DRIVE_SCANS = 500
#: When the drive starts: 2026-01-01 06:00 UTC, the start of a shift (Unix ns).
DRIVE_START_NS = int(datetime(2026, 1, 1, 6, 0, tzinfo=UTC).timestamp()) * 1_000_000_000

#: Speed of the vehicle, m/s: a smooth profile between these.
SPEED_MIN_MPS, SPEED_MAX_MPS = 1.0, 3.0
#: Beacon spacing within a stretch, stretch lengths, and gaps between stretches (m).
SPACING_M = (6.0, 14.0)
FIRST_STRETCH_M = (20.0, 30.0)
STRETCH_M = (25.0, 70.0)
GAP_M = (30.0, 60.0)
#: Drift behind the vehicle's start and ahead of its end, metres.
START_STATION_M = 12.0
END_MARGIN_M = 20.0
#: How finely the centreline is integrated, and the vertex spacing of the walls (m).
_DENSE_STEP_M = 0.05
_WALL_STEP_M = 0.5
#: Surfaces are kept for a scan when within its range limit plus this (m): noise
#: can bring a surface just beyond the limit back inside it.
_CULL_MARGIN_M = 1.0


def drive_scanner(rate_hz: float = 25.0, *, noise: bool = True) -> ScannerModel:
    """The LMS1xx-like scanner of the drive: 270°, 0.25° at up to 25 Hz, else 0.5°;
    12 mm range noise (none with ``noise=False``), 0.05-30 m."""
    res = 0.25 if rate_hz <= 25.0 else 0.5
    sigma = 0.012 if noise else 0.0
    name = f"drive-lms1xx-{res:g}" + ("" if noise else "-exact")
    return ScannerModel(name, 270.0, res, range_min_m=0.05, range_max_m=30.0, range_sigma_m=sigma)


# --------------------------------------------------------------------------- ray casting


def _sector_first_hits(
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """:func:`mast.core.geometry.first_hits`, testing each segment only against the rays
    within the angle it subtends (the same arithmetic, hence the same answer).

    A wall of many short segments subtends few beams each, so the work grows with
    beams plus segments instead of their product.
    """
    n, m = directions.shape[0], seg_a.shape[0]
    best = np.full(n, np.inf)
    which = np.full(n, -1, dtype=np.intp)
    if n == 0 or m == 0:
        return best, which
    ray_ang = np.arctan2(directions[:, 1], directions[:, 0])
    order = np.argsort(ray_ang, kind="stable")
    two_pi = 2 * math.pi
    ext = np.concatenate([ray_ang[order] - two_pi, ray_ang[order], ray_ang[order] + two_pi])
    ext_ray = np.tile(order, 3)
    w = seg_a - origin
    wb = seg_b - origin
    ang_a = np.arctan2(w[:, 1], w[:, 0])
    sweep = (np.arctan2(wb[:, 1], wb[:, 0]) - ang_a + math.pi) % two_pi - math.pi
    eps = 1e-9  # the exact test below decides; this only keeps grazing rays in
    i0 = np.searchsorted(ext, ang_a + np.minimum(sweep, 0.0) - eps, side="left")
    i1 = np.searchsorted(ext, ang_a + np.maximum(sweep, 0.0) + eps, side="right")
    count = np.maximum(i1 - i0, 0)
    total = int(count.sum())
    if total == 0:
        return best, which
    seg = np.repeat(np.arange(m), count)
    starts = np.cumsum(count) - count
    ray = ext_ray[np.arange(total) - np.repeat(starts - i0, count)]
    e = seg_b[seg] - seg_a[seg]
    ws = w[seg]
    d = directions[ray]
    w_x_e = ws[:, 0] * e[:, 1] - ws[:, 1] * e[:, 0]
    den = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    w_x_d = ws[:, 0] * d[:, 1] - ws[:, 1] * d[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = w_x_e / den
        s = w_x_d / den
    ok = (den != 0) & (t > 1e-12) & (s >= 0.0) & (s <= 1.0)
    ray, seg, t = ray[ok], seg[ok], t[ok]
    # Nearest hit per ray; equal distances go to the lower segment, as argmin does.
    k = np.lexsort((seg, t, ray))
    rays, first = np.unique(ray[k], return_index=True)
    best[rays] = t[k][first]
    which[rays] = seg[k][first]
    return best, which


@dataclass(frozen=True, eq=False)
class _SectorWorld(World):
    """A :class:`World` of segments only, ray-cast by :func:`_sector_first_hits`."""

    def raycast(
        self, origin: ArrayLike, directions: ArrayLike
    ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        if self.circ_c.shape[0]:  # pragma: no cover - the drive has no round objects
            return super().raycast(origin, directions)
        o = np.asarray(origin, dtype=float).reshape(2)
        d = np.asarray(directions, dtype=float).reshape(-1, 2)
        t, j = _sector_first_hits(o, d, self.seg_a, self.seg_b)
        return t, np.where(j >= 0, self.seg_surface[np.maximum(j, 0)], -1)


@dataclass(frozen=True, eq=False)
class Reach:
    """The segments of a world within reach of a point (a whole drift is long)."""

    world: World
    mid: NDArray[np.float64]
    half: NDArray[np.float64]

    @classmethod
    def of(cls, world: World) -> Reach:
        mid = 0.5 * (world.seg_a + world.seg_b)
        half = 0.5 * np.hypot(*(world.seg_b - world.seg_a).T)
        return cls(world, mid, half)

    def near(self, point: NDArray[np.float64], reach_m: float) -> World:
        w = self.world
        d2 = np.sum((self.mid - point) ** 2, axis=1)
        keep = d2 <= (reach_m + self.half) ** 2
        return _SectorWorld(
            w.seg_a[keep],
            w.seg_b[keep],
            w.seg_surface[keep],
            w.circ_c,
            w.circ_r,
            w.circ_surface,
            w.surfaces,
        )


# --------------------------------------------------------------------------- the scene


@dataclass(frozen=True, eq=False)
class DriveScene(Scene):
    """A drive: one drift, its survey, and a shot per scan in time order.

    Attributes (besides :class:`Scene`'s)
    ----------
    stamps_ns : ndarray of int64, shape (n,)
        Each scan's time stamp (Unix ns), at the scanner's rate.
    stations_m, speeds_mps : ndarray, shape (n,)
        Each scan's distance along the drift's centreline and the vehicle's speed.
    beacon_stations_m : tuple of float
        Each beacon's station along the centreline (the survey's order).
    gaps_m : tuple of (float, float)
        Stretches of the drift without beacons, (from, to) stations; the last one
        may be cut short by the drift's end.
    length_m : float
        The drift's length along its centreline (face to face).
    rate_hz : float
    """

    stamps_ns: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    stations_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    speeds_mps: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    beacon_stations_m: tuple[float, ...] = ()
    gaps_m: tuple[tuple[float, float], ...] = ()
    length_m: float = 0.0
    rate_hz: float = 25.0

    def iter_simulated(self) -> Iterator[SimulatedScan]:
        """Every scan in time order, one at a time, ray-cast against the walls in reach."""
        rng = np.random.default_rng(self.seed)
        reach = Reach.of(self.world)
        for shot, stamp in zip(self.shots, self.stamps_ns, strict=True):
            world = reach.near(shot.pose.position, shot.scanner.range_max_m + _CULL_MARGIN_M)
            yield simulate_scan(world, shot.pose, shot.scanner, rng=rng, stamp_ns=int(stamp))


def _sinusoids(
    rng: np.random.Generator, count: int, period: tuple[float, float]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Weights (summing to 1), angular frequencies and phases of a smooth random profile."""
    weight = rng.uniform(0.3, 1.0, count)
    omega = 2 * math.pi / rng.uniform(*period, count)
    phase = rng.uniform(0, 2 * math.pi, count)
    return weight / weight.sum(), omega, phase


def _heading_profile(
    rng: np.random.Generator, length_m: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Breakpoints (station, azimuth) of a centreline of straights and circular bends:
    the azimuth is piecewise linear in the station."""
    s, psi = 0.0, float(rng.uniform(0, 2 * math.pi))
    st, az = [s], [psi]
    while s < length_m:
        s += float(rng.uniform(20.0, 80.0))  # a straight
        st.append(s)
        az.append(psi)
        bend = math.radians(float(rng.uniform(8.0, 30.0))) * (1 if rng.random() < 0.5 else -1)
        s += float(rng.uniform(12.0, 30.0))  # a bend, radius 23 m or more
        psi += bend
        st.append(s)
        az.append(psi)
    return np.array(st), np.array(az)


def _layout(
    rng: np.random.Generator, start_m: float, end_m: float, drift_m: float
) -> tuple[list[float], list[tuple[float, float]]]:
    """Beacon stations from ``start_m`` to ``end_m`` in stretches (spacing 6-14 m, the
    first stretch short) separated by gaps of 30-60 m (from, to; the last one cut at
    the drift's end ``drift_m``)."""
    stations: list[float] = []
    gaps: list[tuple[float, float]] = []
    s, bounds = start_m, FIRST_STRETCH_M
    while s <= end_m:
        stretch_end = s + float(rng.uniform(*bounds))
        stations.append(s)
        while True:
            nxt = s + float(rng.uniform(*SPACING_M))
            if nxt > min(stretch_end, end_m):
                break
            stations.append(nxt)
            s = nxt
        gap = float(rng.uniform(*GAP_M))
        gaps.append((s, min(s + gap, drift_m)))
        s += gap
        bounds = STRETCH_M
    return stations, gaps


def drive_scene(
    seed: int = 0,
    *,
    scans: int = DEFAULT_DRIVE_SCANS,
    rate_hz: float = 25.0,
    noise: bool = True,
    start_ns: int = DRIVE_START_NS,
) -> DriveScene:
    """A vehicle driving a drift for ``scans`` scans at ``rate_hz`` (see the module).

    The drift is as long as the drive needs (the vehicle covers 1-3 m/s times
    ``scans / rate_hz`` seconds) plus 12 m behind and 20 m ahead; everything is
    drawn from ``seed``.
    """
    if not 1 <= scans <= 10_000_000:
        raise InputError(f"drive: {scans} scans; give 1 to 10 000 000")
    if not 1.0 <= rate_hz <= 100.0:
        raise InputError(f"drive: scan rate {rate_hz:g} Hz; give 1 to 100 Hz (LMS1xx: 25 or 50)")
    # One stream per part, each drawn in order along the drift, so that a longer drive
    # with the same seed continues a shorter one: same drift, beacons, path, stamps and
    # range noise (the rock's texture is scaled to its own drift's length).
    path_rng, beacon_rng, design_rng, wall_rng, motion_rng, yaw_rng = (
        np.random.default_rng([seed, 17, k]) for k in range(6)
    )

    # The vehicle: speed along the centreline, a smooth profile within 1-3 m/s,
    # integrated exactly, so that a longer drive only adds to a shorter one's path.
    t = np.arange(scans) / rate_hz
    w_v, om_v, ph_v = _sinusoids(motion_rng, 3, (15.0, 90.0))
    mid_v, amp_v = (SPEED_MIN_MPS + SPEED_MAX_MPS) / 2, (SPEED_MAX_MPS - SPEED_MIN_MPS) / 2
    speed = mid_v + amp_v * np.sin(np.outer(t, om_v) + ph_v) @ w_v
    travelled = mid_v * t - amp_v * ((np.cos(np.outer(t, om_v) + ph_v) - np.cos(ph_v)) / om_v) @ w_v
    station = START_STATION_M + travelled
    length = float(station[-1]) + END_MARGIN_M

    # The drift: centreline integrated finely from its azimuth profile.
    width = float(path_rng.uniform(4.5, 6.0))
    origin = np.array([float(path_rng.uniform(2000, 8000)), float(path_rng.uniform(2000, 8000))])
    bp_s, bp_az = _heading_profile(path_rng, length)
    every = round(_WALL_STEP_M / _DENSE_STEP_M)
    # fixed steps from the start (a longer drift extends a shorter one), wall vertices
    # every 0.5 m to the first one at or past the drift's length
    dense_s = _DENSE_STEP_M * np.arange(every * math.ceil(length / _WALL_STEP_M) + 1)
    dense_az = np.interp(dense_s, bp_s, bp_az)
    step = np.diff(dense_s)
    # the midpoint rule on 5 cm steps: exact on straights, within 0.2 µm per metre of
    # the true arc on a bend
    mid_az = 0.5 * (dense_az[1:] + dense_az[:-1])
    dense_xy = origin + np.vstack(
        [
            np.zeros((1, 2)),
            np.cumsum(step[:, None] * np.stack([np.sin(mid_az), np.cos(mid_az)], 1), 0),
        ]
    )
    length = float(dense_s[-1])
    tunnel = Tunnel(dense_xy[::every], width)

    # Beacons in stretches with gaps between, on alternating walls.
    first = START_STATION_M + float(beacon_rng.uniform(0.0, 3.0))
    stations, gaps = _layout(beacon_rng, first, length - 4.0, length)
    placements: list[tuple[str, float, str, BeaconDesign, str]] = []
    side = "left" if design_rng.random() < 0.5 else "right"
    for j, st in enumerate(stations):
        design = DRIFT_CATALOGUE[int(design_rng.integers(len(DRIFT_CATALOGUE)))]
        placements.append((f"D{j + 1:03d}", st, side, design, "beacon"))
        side = "right" if side == "left" else "left"
    rough = Roughness(
        amplitude_m=float(wall_rng.uniform(0.02, 0.05)), wavelength_min_m=0.2, wavelength_max_m=1.5
    )
    wb, beacons = mount_beacons(wall_rng, tunnel, placements, rough)
    left, right = tunnel.walls()
    for a, b in ((left[0], right[0]), (left[-1], right[-1])):  # the faces at both ends
        wb.polyline(roughen(np.array([a, b]), rough, wall_rng), Surface("wall"))
    world = wb.build()

    # The vehicle's path: the centreline, a little wander, heading along the path.
    w_l, om_l, ph_l = _sinusoids(motion_rng, 3, (15.0, 60.0))
    bias = float(motion_rng.uniform(-0.3, 0.3))
    wander = 0.3
    along = station - START_STATION_M
    lateral = bias + wander * np.sin(np.outer(along, om_l) + ph_l) @ w_l
    lateral_rate = wander * (np.cos(np.outer(along, om_l) + ph_l) * om_l) @ w_l
    psi = np.interp(station, bp_s, bp_az)
    piece = np.clip(np.searchsorted(bp_s, station, side="right") - 1, 0, len(bp_s) - 2)
    curvature = (bp_az[piece + 1] - bp_az[piece]) / (bp_s[piece + 1] - bp_s[piece])
    centre = np.stack([np.interp(station, dense_s, dense_xy[:, k]) for k in (0, 1)], 1)
    normal = np.stack([-np.cos(psi), np.sin(psi)], 1)  # left of the direction of travel
    pos = centre + lateral[:, None] * normal
    heading = psi - np.arctan2(lateral_rate, 1.0 + lateral * curvature)
    # Yaw noise: first-order Gauss-Markov, 0.3° standard deviation, 0.3 s correlation.
    rho = math.exp(-1.0 / (rate_hz * 0.3))
    yaw = np.empty(scans)
    yaw[0] = yaw_rng.normal(0.0, math.radians(0.3))
    kicks = yaw_rng.normal(0.0, math.radians(0.3) * math.sqrt(1 - rho**2), scans)
    for i in range(1, scans):
        yaw[i] = rho * yaw[i - 1] + kicks[i]
    azimuth = (heading + yaw) % (2 * math.pi)

    scanner = drive_scanner(rate_hz, noise=noise)
    width_digits = len(str(scans - 1))
    shots = tuple(
        Shot(
            f"t{i:0{width_digits}d}",
            Pose2D(float(pos[i, 0]), float(pos[i, 1]), float(azimuth[i])),
            scanner,
        )
        for i in range(scans)
    )
    stamps = start_ns + np.round(np.arange(scans) * (1e9 / rate_hz)).astype(np.int64)
    lo, hi = float(station[0]), float(station[-1])
    seen_gaps = [(a, b) for a, b in gaps if b > lo and a < hi]
    return DriveScene(
        f"drive-{seed}",
        world,
        Survey(beacons),
        shots,
        description=(
            f"{length:.0f} m drift {width:.1f} m wide, {len(beacons)} beacons in stretches "
            f"with gaps of {GAP_M[0]:g}-{GAP_M[1]:g} m; {scans} scans at {rate_hz:g} Hz "
            f"({scans / rate_hz:.1f} s), {float(speed.min()):.1f}-{float(speed.max()):.1f} m/s, "
            f"{hi - lo:.0f} m driven"
        ),
        seed=seed * 1000 + 700_000,
        params={
            "scans": scans,
            "rate_hz": rate_hz,
            "start_utc": datetime.fromtimestamp(start_ns / 1e9, UTC).isoformat(),
            "drift_length_m": round(length, 3),
            "width_m": round(width, 3),
            "driven_m": round(hi - lo, 3),
            "speed_mps": [round(float(speed.min()), 3), round(float(speed.max()), 3)],
            "beacons": len(beacons),
            "gaps_m": [[round(a, 2), round(b, 2)] for a, b in gaps],
            "gaps_on_the_drive": len(seen_gaps),
            "roughness_m": round(rough.amplitude_m, 4),
        },
        stamps_ns=stamps,
        stations_m=station,
        speeds_mps=speed,
        beacon_stations_m=tuple(stations),
        gaps_m=tuple(gaps),
        length_m=length,
        rate_hz=rate_hz,
    )


def drive_scenario(
    seed: int = 0,
    *,
    noise: bool | None = None,
    scans: int | None = None,
    rate_hz: float | None = None,
) -> list[Scene]:
    """The drive as a one-scene scenario; 12 mm noise unless ``noise`` is False."""
    return [
        drive_scene(
            seed,
            scans=DEFAULT_DRIVE_SCANS if scans is None else scans,
            rate_hz=25.0 if rate_hz is None else rate_hz,
            noise=noise is not False,
        )
    ]
