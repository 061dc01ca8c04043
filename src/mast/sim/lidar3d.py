"""Frames of a spinning 3D lidar in a mine drift with beacons, and their truth.

A frame is simulated by ray casting every (ring, column) beam of a
:class:`Lidar3DModel` from a known :class:`~mast.core.pose3d.Pose3D` into a
:class:`~mast.sim.drift3d.Drift3D`; it comes back as a
:class:`~mast.core.pose3d.Frame3D` in the sensor frame (REP 103: x forward, y left,
z up; the convention of :mod:`mast.core.pose3d`), with each return's ring and time,
and with what each return hit, the true pose and whether the frame is owed a fix
(:class:`OwedRule3D`).

A beam of ring elevation ``eps`` and column angle ``phi`` (counter-clockwise from x)
points along ``(cos eps cos phi, cos eps sin phi, sin eps)`` in the sensor frame and
along ``R`` times that in the grid. Columns are fired clockwise seen from above,
starting behind the sensor (``phi = pi``), as Velodyne and Ouster sensors spin; a
return's time is its column's time within the frame (``column / columns / rate``). The
vehicle stands still during a frame (no motion distortion). Ring numbers follow each
vendor's driver: a VLP-16's ring 0 is its lowest laser, an OS1's its highest.

:func:`random_drift_scene` draws a whole site from a seed (drift, grade, beacons on both
walls, poses along the drift); :meth:`DriftScene3D.frames` and :func:`simulate_frames`
give its frames one at a time, deterministic per seed.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon, Survey
from mast.core.pose3d import Frame3D, Pose3D
from mast.errors import InputError
from mast.sim.design import BeaconDesign, paper_design, random_design
from mast.sim.drift3d import Drift3D, Plate, beacon_plates
from mast.sim.hard import _panel_lookalike
from mast.sim.mounting import DRIFT_CATALOGUE, direction, random_centreline, wall_mount
from mast.sim.tunnel import Roughness, Tunnel
from mast.sim.world import Surface

__all__ = [
    "LIDARS",
    "OWED_3D",
    "DriftScene3D",
    "Lidar3DModel",
    "OwedRule3D",
    "SimulatedFrame3D",
    "lidar_model",
    "random_drift_scene",
    "simulate_frame",
    "simulate_frames",
]


@dataclass(frozen=True, slots=True)
class Lidar3DModel:
    """A spinning lidar: its rings, columns, range limits and error model.

    Attributes
    ----------
    name : str
    ring_elevations_deg : tuple of float
        Each ring's elevation angle in the sensor frame, degrees, by ring number.
    columns : int
        Firings per revolution (one beam per ring each).
    rate_hz : float
        Revolutions per second: a frame lasts ``1 / rate_hz``.
    range_min_m, range_max_m : float
        Returns outside these limits are no return.
    range_sigma_m : float
        Standard deviation of Gaussian range noise.
    dropout_prob : float
        Probability that a beam returns nothing.
    """

    name: str
    ring_elevations_deg: tuple[float, ...]
    columns: int
    rate_hz: float = 10.0
    range_min_m: float = 0.5
    range_max_m: float = 100.0
    range_sigma_m: float = 0.02
    dropout_prob: float = 0.0

    def __post_init__(self) -> None:
        if not self.ring_elevations_deg or any(abs(e) >= 90 for e in self.ring_elevations_deg):
            raise InputError(f"lidar {self.name!r}: ring elevations must be in (-90°, 90°)")
        if self.columns < 1 or not self.rate_hz > 0:
            raise InputError(f"lidar {self.name!r}: columns and rate must be positive")
        if not 0 <= self.range_min_m < self.range_max_m:
            raise InputError(f"lidar {self.name!r}: range limits are invalid")
        if self.range_sigma_m < 0 or not 0 <= self.dropout_prob <= 1:
            raise InputError(f"lidar {self.name!r}: noise figures are invalid")

    @property
    def rings(self) -> int:
        return len(self.ring_elevations_deg)

    @property
    def beams(self) -> int:
        """Beams a frame (rings × columns)."""
        return self.rings * self.columns

    def column_angles(self) -> NDArray[np.float64]:
        """Each column's angle, radians counter-clockwise from x: clockwise from ``pi``."""
        return np.asarray(math.pi - 2 * math.pi * np.arange(self.columns) / self.columns)

    def beam_table(self) -> tuple[NDArray[np.float64], NDArray[np.int32], NDArray[np.intp]]:
        """Every beam in firing order (column by column, rings in order within one):
        unit directions in the sensor frame ``(beams, 3)``, ring and column numbers."""
        eps = np.radians(np.asarray(self.ring_elevations_deg, dtype=float))
        phi = self.column_angles()
        ce, se = np.cos(eps)[None, :], np.sin(eps)[None, :]
        d = np.empty((self.columns, self.rings, 3))
        d[..., 0] = ce * np.cos(phi)[:, None]
        d[..., 1] = ce * np.sin(phi)[:, None]
        d[..., 2] = np.broadcast_to(se, (self.columns, self.rings))
        ring = np.tile(np.arange(self.rings, dtype=np.int32), self.columns)
        column = np.repeat(np.arange(self.columns, dtype=np.intp), self.rings)
        return d.reshape(-1, 3), ring, column


#: Named lidars. A Velodyne VLP-16 (16 lasers, -15° to +15° every 2°, ring 0 the lowest
#: in the ROS driver; 0.2° azimuth steps at 10 Hz; up to 100 m, "±3 cm typical" range
#: accuracy) and an Ouster OS1-64 (64 channels over a 33.2° vertical field, channel 0
#: the highest; 1024 columns at 10 Hz; 0.8-120 m). Range sigma 2 cm for both: pass
#: another with :func:`lidar_model`.
LIDARS: dict[str, Lidar3DModel] = {
    m.name: m
    for m in (
        Lidar3DModel(
            "vlp16",
            tuple(float(e) for e in range(-15, 16, 2)),
            1800,
            range_min_m=0.5,
            range_max_m=100.0,
            dropout_prob=0.01,
        ),
        Lidar3DModel(
            "os1-64",
            tuple(float(e) for e in np.linspace(16.6, -16.6, 64)),
            1024,
            range_min_m=0.8,
            range_max_m=120.0,
            dropout_prob=0.01,
        ),
    )
}


def lidar_model(name: str, *, range_sigma_m: float | None = None) -> Lidar3DModel:
    """A named lidar (:data:`LIDARS`), with another range sigma where given."""
    try:
        model = LIDARS[name]
    except KeyError:
        raise InputError(f"unknown lidar {name!r}; known: {', '.join(LIDARS)}") from None
    return model if range_sigma_m is None else replace(model, range_sigma_m=range_sigma_m)


@dataclass(frozen=True, slots=True)
class OwedRule3D:
    """When a 3D frame is owed a fix.

    A panel is *shown* when at least ``min_rings`` rings each put at least
    ``min_points_per_ring`` returns on it (each ring's returns draw a line across the
    panel, as three returns do in 2D, and two lines at different heights span its
    plane) and the beams meet it at least ``min_incidence_deg`` off grazing (the angle
    between the beam to its returns' centroid and the panel's plane). A beacon is shown
    when at least ``min_panels`` of its panels are (two panels and their bend tell its
    shape, as in 2D); a frame is owed a fix when at least ``min_beacons`` beacons are.
    """

    min_points_per_ring: int = 3
    min_rings: int = 2
    min_panels: int = 2
    min_beacons: int = 2
    min_incidence_deg: float = 10.0


#: The rule issue 36's targets are counted by: two beacons, each with two panels hit by
#: two rings of three returns or more, ten degrees off grazing.
OWED_3D = OwedRule3D()


@dataclass(frozen=True, eq=False)
class SimulatedFrame3D:
    """A simulated frame with its truth.

    Attributes
    ----------
    frame : Frame3D
        What the lidar reports (sensor frame; returns only).
    pose : Pose3D
        The true pose it was taken from.
    owed : bool
        Whether it is owed a fix by the rule it was simulated with.
    lidar : Lidar3DModel
    surface_index : ndarray of int, shape (n,)
        Index into ``drift.surfaces`` of what each return hit.
    true_range_m : ndarray, shape (n,)
        Each return's noise-free range.
    drift : Drift3D
        The world it was cast in.
    """

    frame: Frame3D
    pose: Pose3D
    owed: bool
    lidar: Lidar3DModel
    surface_index: NDArray[np.intp]
    true_range_m: NDArray[np.float64]
    drift: Drift3D = field(repr=False)

    def points_grid(self) -> NDArray[np.float64]:
        """The returns in the grid, through the true pose."""
        return self.pose.sensor_to_grid(self.frame.points)

    def panel_rings(self, rule: OwedRule3D = OWED_3D) -> dict[tuple[str, int], int]:
        """Per (beacon id, panel 1..3) hit: how many rings put at least
        ``rule.min_points_per_ring`` returns on it."""
        out: dict[tuple[str, int], int] = {}
        ring = self.frame.ring
        assert ring is not None
        for k, surface in enumerate(self.drift.surfaces):
            if surface.kind != "beacon":
                continue
            on = self.surface_index == k
            if not np.any(on):
                continue
            _, counts = np.unique(ring[on], return_counts=True)
            out[(surface.beacon, surface.panel)] = int(np.sum(counts >= rule.min_points_per_ring))
        return out

    def panels_seen(self, rule: OwedRule3D = OWED_3D) -> dict[str, list[int]]:
        """The panels ``rule`` counts as shown, per beacon id (see :class:`OwedRule3D`)."""
        out: dict[str, list[int]] = {}
        grid = self.points_grid()
        for (b, p), rings in sorted(self.panel_rings(rule).items()):
            if rings < rule.min_rings:
                continue
            k = self.drift.surfaces.index(Surface("beacon", b, p))
            beam = grid[self.surface_index == k].mean(axis=0) - self.pose.position
            normal = self.drift.plate_normal(k)
            sin_inc = abs(float(beam[:2] @ normal)) / float(np.linalg.norm(beam))
            if math.degrees(math.asin(min(1.0, sin_inc))) >= rule.min_incidence_deg:
                out.setdefault(b, []).append(p)
        return out

    def owes_fix(self, rule: OwedRule3D = OWED_3D) -> bool:
        """Whether ``rule`` owes this frame a fix."""
        seen = self.panels_seen(rule)
        return sum(len(p) >= rule.min_panels for p in seen.values()) >= rule.min_beacons


def simulate_frame(
    drift: Drift3D,
    pose: Pose3D,
    lidar: Lidar3DModel,
    *,
    rng: np.random.Generator | None = None,
    rule: OwedRule3D = OWED_3D,
    stamp_ns: int = 0,
    frame_id: str = "lidar",
) -> SimulatedFrame3D:
    """Ray-cast one frame of ``lidar`` from ``pose`` (vectorised over beams).

    Each beam's range gets Gaussian noise (``lidar.range_sigma_m``) along the beam;
    beams dropped (``lidar.dropout_prob``) or out of the range limits are left out of
    the frame. Intensities are the surfaces' reflectivities with 5 % noise.
    """
    if rng is None:
        rng = np.random.default_rng(0)
    d_sensor, ring, column = lidar.beam_table()
    n = len(d_sensor)
    d_grid = d_sensor @ pose.rotation.T
    true_r, surf = drift.raycast(pose.position, d_grid)
    r = true_r + rng.normal(0.0, lidar.range_sigma_m, n) if lidar.range_sigma_m > 0 else true_r
    keep = np.isfinite(r) & (r >= lidar.range_min_m) & (r <= lidar.range_max_m)
    if lidar.dropout_prob > 0:
        keep &= rng.random(n) >= lidar.dropout_prob
    refl = drift.reflectivity(surf[keep])
    intensity = np.maximum(refl * (1 + 0.05 * rng.normal(size=int(keep.sum()))), 0.0)
    frame = Frame3D(
        d_sensor[keep] * r[keep, None],
        intensity=intensity,
        ring=ring[keep],
        time_s=column[keep] / (lidar.columns * lidar.rate_hz),
        stamp_ns=stamp_ns,
        frame_id=frame_id,
    )
    sim = SimulatedFrame3D(frame, pose, False, lidar, surf[keep], true_r[keep], drift)
    return replace(sim, owed=sim.owes_fix(rule))


@dataclass(frozen=True, eq=False)
class DriftScene3D:
    """A simulated drift, its beacon survey (with top-edge elevations) and the poses a
    lidar takes frames from."""

    name: str
    drift: Drift3D
    survey: Survey
    poses: tuple[Pose3D, ...]
    lidar: Lidar3DModel
    seed: int = 0
    rule: OwedRule3D = OWED_3D
    description: str = ""
    params: dict[str, object] = field(default_factory=dict)

    def simulate(self, index: int) -> SimulatedFrame3D:
        """Frame ``index``, its noise drawn from a generator seeded by the scene's seed
        and the index (so any one frame is reproduced alone); stamps 0.1 s apart."""
        rng = np.random.default_rng([self.seed, index])
        return simulate_frame(
            self.drift,
            self.poses[index],
            self.lidar,
            rng=rng,
            rule=self.rule,
            stamp_ns=index * 100_000_000,
        )

    def frames(self) -> Iterator[SimulatedFrame3D]:
        """Every pose's frame in order, one at a time."""
        for i in range(len(self.poses)):
            yield self.simulate(i)


#: A drift's grade at most: 1 in 7 (about 8.1°).
MAX_GRADE = 1.0 / 7.0
#: Vehicle roll and pitch on top of the floor's slope, at most, degrees.
MAX_TILT_DEG = 10.0
#: Sensor height above the floor, metres; panel heights; top edges above the floor.
SENSOR_HEIGHT_M = (1.5, 2.5)
PANEL_HEIGHT_M = (0.5, 1.2)
TOP_EDGE_M = (1.5, 2.5)
#: A beacon or look-alike is kept this far, metres, from a bend's vertex.
BEND_CLEARANCE_M = 4.0
#: A look-alike keeps this far, in plan, from every beacon and look-alike before it: two
#: plates cannot pass through each other (one drawn across a beacon's panels had
#: replaced half their returns with its own), metres; and so many places are drawn for
#: it before it is left out.
LOOKALIKE_CLEARANCE_M = 0.3
LOOKALIKE_PLACES = 20


def _design(rng: np.random.Generator) -> BeaconDesign:
    u = rng.random()
    if u < 0.5:
        return random_design(rng)
    if u < 0.8:
        chord = float(rng.uniform(0.7, 1.8))
        return paper_design(chord, chord * float(rng.uniform(0.1, 0.2)))
    return DRIFT_CATALOGUE[int(rng.integers(len(DRIFT_CATALOGUE)))]


def _gap(a: NDArray[np.float64], b: NDArray[np.float64], step_m: float = 0.01) -> float:
    """The least distance in plan between two polylines (their corners, (n, 2)), to
    about ``step_m``: each sampled that finely."""

    def sampled(p: NDArray[np.float64]) -> NDArray[np.float64]:
        parts = [
            p[k]
            + np.linspace(0.0, 1.0, max(2, int(np.hypot(*(p[k + 1] - p[k])) / step_m) + 1))[:, None]
            * (p[k + 1] - p[k])
            for k in range(len(p) - 1)
        ]
        return np.concatenate(parts)

    pa, pb = sampled(a), sampled(b)
    return float(np.sqrt(((pa[:, None, :] - pb[None, :, :]) ** 2).sum(axis=2).min()))


def _mount(tunnel: Tunnel, station: float, side: str, design: BeaconDesign) -> NDArray[np.float64]:
    on_wall, tangent, tside = wall_mount(tunnel, station, side, 0.0, design.chord_m)
    return design.mounted(on_wall, tangent, tunnel_side=tside)


def _vehicle_pose(
    rng: np.random.Generator, tunnel: Tunnel, drift: Drift3D, station: float
) -> Pose3D:
    centre, tangent = tunnel.centre_point(station)
    normal = np.array([-tangent[1], tangent[0]])
    p = centre + float(rng.uniform(-1, 1)) * (tunnel.width_m / 2 - 1.2) * normal
    heading = math.atan2(tangent[0], tangent[1]) + (math.pi if rng.random() < 0.5 else 0.0)
    heading += math.radians(float(rng.normal(0.0, 10.0)))
    ahead = direction(heading)
    left = np.array([-ahead[1], ahead[0]])
    # The floor's slope along the vehicle's heading and to its left: nose up (a negative
    # pitch) uphill, left side up (a positive roll) where the floor rises to the left.
    pitch = -math.atan(drift.grade * float(ahead @ drift.grade_direction))
    roll = math.atan(drift.grade * float(left @ drift.grade_direction))
    pitch += math.radians(float(rng.uniform(-MAX_TILT_DEG, MAX_TILT_DEG)))
    roll += math.radians(float(rng.uniform(-MAX_TILT_DEG, MAX_TILT_DEG)))
    z = float(drift.floor_at(p)[0]) + float(rng.uniform(*SENSOR_HEIGHT_M))
    return Pose3D(float(p[0]), float(p[1]), z, heading % (2 * math.pi), pitch, roll)


def random_drift_scene(
    seed: int,
    index: int = 0,
    *,
    frames: int = 10,
    lidar: str | Lidar3DModel = "vlp16",
    range_sigma_m: float | None = None,
    rough: bool = True,
    lookalikes: bool = False,
    rule: OwedRule3D = OWED_3D,
) -> DriftScene3D:
    """A seeded random drift and ``frames`` poses in it.

    The drift is 4-7 m wide and 4-5 m high, 80 m long, straight or bent once by
    10-30°, on a grade of up to 1 in 7 either way (along its chord), somewhere in the
    grid; its rock is rough by 1-5 cm (wavelengths 0.2-1 m). Three to five beacons
    (random hats, the paper's 2:3:1 hat or the drift catalogue's designs) stand 5-12 m
    apart, mostly on alternate walls, panels 0.5-1.2 m tall with top edges 1.5-2.5 m
    above the floor; the survey gives each edge's top elevation. ``lookalikes`` adds one
    or two brackets and boards on stand-offs (:mod:`mast.sim.hard`'s look-alikes)
    mounted as plates ``Surface("lookalike", "L1", k)``, each 0.3 m clear in plan of the
    beacons and of the look-alike before it (:data:`LOOKALIKE_CLEARANCE_M`; one with no
    clear place in :data:`LOOKALIKE_PLACES` draws is left out).
    The poses are along the beacons' stretch, at least 1.2 m from the walls, facing
    either way along the drift (±10°), the sensor 1.5-2.5 m above the floor and the
    vehicle rolled and pitched by up to ±10° on top of the floor's slope.

    Parameters
    ----------
    seed, index : int
        The scene is a function of these alone (and the options).
    frames : int
        Poses to draw.
    lidar : str or Lidar3DModel
        A name in :data:`LIDARS` or a model.
    range_sigma_m : float, optional
        Replaces the lidar's range sigma.
    """
    rng = np.random.default_rng([seed, index, 36])
    model = lidar if isinstance(lidar, Lidar3DModel) else lidar_model(lidar)
    if range_sigma_m is not None:
        model = replace(model, range_sigma_m=range_sigma_m)
    width = float(rng.uniform(4.0, 7.0))
    height = float(rng.uniform(4.0, 5.0))
    grade = float(rng.uniform(-MAX_GRADE, MAX_GRADE))
    bent = bool(rng.random() < 0.5)
    length = 80.0
    centre = random_centreline(rng, [length / 2, length / 2] if bent else [length], 0.0)
    bend_deg = 0.0
    if bent:
        bend_deg = float(rng.choice([-1, 1]) * rng.uniform(10.0, 30.0))
        heading = math.atan2(*(centre[1] - centre[0]))
        centre[2] = centre[1] + (length / 2) * direction(heading + math.radians(bend_deg))
    tunnel = Tunnel(centre, width)
    floor0 = float(rng.uniform(-800.0, 400.0))
    bare = Drift3D(tunnel, height, grade=grade, floor_elevation_m=floor0)

    def clear(station: float) -> float:
        if bent and abs(station - length / 2) < BEND_CLEARANCE_M:
            return length / 2 + BEND_CLEARANCE_M
        return station

    beacons: list[Beacon] = []
    plates: list[Plate] = []
    designs: list[str] = []
    side = "left" if rng.random() < 0.5 else "right"
    s = float(rng.uniform(22.0, 30.0))
    for j in range(int(rng.integers(3, 6))):
        s = clear(s)
        design = _design(rng)
        edges = _mount(tunnel, s, side, design)
        top = float(bare.floor_at(edges.mean(axis=0))[0]) + float(rng.uniform(*TOP_EDGE_M))
        beacon = Beacon(f"B{j + 1}", edges, elevations=np.full(4, top), design=design.name)
        beacons.append(beacon)
        designs.append(design.name)
        plates += beacon_plates(beacon, float(rng.uniform(*PANEL_HEIGHT_M)))
        s += float(rng.uniform(5.0, 12.0))
        if rng.random() < 0.75:
            side = "right" if side == "left" else "left"
    stretch = (float(rng.uniform(22.0, 30.0)) - 4.0, s - 1.0)
    if lookalikes:
        taken = [b.edges for b in beacons]
        for _ in range(int(rng.integers(1, 3))):
            for _place in range(LOOKALIKE_PLACES):
                st = clear(float(rng.uniform(*stretch)))
                shape = _panel_lookalike(rng)
                edges = _mount(tunnel, st, "left" if rng.random() < 0.5 else "right", shape)
                if all(_gap(edges, other) >= LOOKALIKE_CLEARANCE_M for other in taken):
                    break
            else:
                continue  # no place clear of the others along the stretch
            taken.append(edges)
            top = float(bare.floor_at(edges.mean(axis=0))[0]) + float(rng.uniform(*TOP_EDGE_M))
            tall = float(rng.uniform(*PANEL_HEIGHT_M))
            for k in range(len(edges) - 1):
                a, b = edges[k], edges[k + 1]
                if np.hypot(*(b - a)) > 1e-6:
                    plates.append(
                        Plate(
                            (float(a[0]), float(a[1])),
                            (float(b[0]), float(b[1])),
                            top - tall,
                            top,
                            Surface("lookalike", f"L{len(taken) - len(beacons)}", k + 1),
                            float(rng.uniform(60.0, 220.0)),
                        )
                    )
    rock = Roughness(amplitude_m=float(rng.uniform(0.01, 0.05))) if rough else None
    drift = Drift3D(
        tunnel,
        height,
        grade=grade,
        floor_elevation_m=floor0,
        rock=rock,
        plates=plates,
        seed=int(rng.integers(2**31)),
    )
    poses = tuple(
        _vehicle_pose(rng, tunnel, drift, clear(float(rng.uniform(*stretch))))
        for _ in range(frames)
    )
    return DriftScene3D(
        f"drift3d-{seed}-{index}",
        drift,
        Survey(beacons),
        poses,
        model,
        seed=seed * 1000 + index,
        rule=rule,
        description=(
            f"{length:.0f} m drift {width:.2f} m wide, {height:.2f} m high, grade "
            f"{grade:+.3f}, "
            + (f"bent {bend_deg:+.1f}°, " if bent else "straight, ")
            + f"{len(beacons)} beacons ({', '.join(designs)}), "
            + (f"rock ±{rock.amplitude_m:.3f} m" if rock else "smooth rock")
            + f"; {model.name}, range sigma {model.range_sigma_m:.3f} m"
        ),
        params={
            "width_m": width,
            "height_m": height,
            "grade": grade,
            "bend_deg": bend_deg,
            "beacons": len(beacons),
            "lidar": model.name,
            "range_sigma_m": model.range_sigma_m,
        },
    )


def simulate_frames(
    seed: int,
    n: int,
    *,
    lidar: str | Lidar3DModel = "vlp16",
    range_sigma_m: float | None = None,
    frames_per_scene: int = 10,
    lookalikes: bool = False,
    rule: OwedRule3D = OWED_3D,
) -> Iterator[tuple[DriftScene3D, SimulatedFrame3D]]:
    """``n`` frames from random drifts (:func:`random_drift_scene` with indices 0, 1,
    ... of ``seed``, ``frames_per_scene`` poses each), one at a time with their scene
    (its survey is what a locator is given). Deterministic per seed."""
    index = 0
    left = n
    while left > 0:
        scene = random_drift_scene(
            seed,
            index,
            frames=min(frames_per_scene, left),
            lidar=lidar,
            range_sigma_m=range_sigma_m,
            lookalikes=lookalikes,
            rule=rule,
        )
        for sim in scene.frames():
            yield scene, sim
        left -= len(scene.poses)
        index += 1
