"""Hostile scenes: rough rock, people, equipment, look-alike shapes, occlusion,
dropouts, mixed pixels and range bias (``hard``); and a long drift with dozens of
beacons of a few identical designs (``drift``)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon, Survey
from mast.core.pose import Pose2D
from mast.sim.design import BeaconDesign, paper_design, polyline_design, random_design
from mast.sim.scanner import ScannerModel
from mast.sim.scenarios import Scene, Shot
from mast.sim.tunnel import Roughness, Tunnel, project_station, roughen
from mast.sim.world import Surface, WorldBuilder

__all__ = ["drift_scene", "hard_scene"]


def _direction(azimuth_rad: float) -> NDArray[np.float64]:
    return np.array([math.sin(azimuth_rad), math.cos(azimuth_rad)])


def _centreline(
    rng: np.random.Generator, lengths: list[float], max_bend_deg: float
) -> NDArray[np.float64]:
    heading = float(rng.uniform(0, 2 * math.pi))
    pts = [np.array([float(rng.uniform(0, 1e4)), float(rng.uniform(0, 1e4))])]
    for length in lengths:
        pts.append(pts[-1] + length * _direction(heading))
        heading += math.radians(float(rng.uniform(-max_bend_deg, max_bend_deg)))
    return np.array(pts)


def _wall_mount(
    tunnel: Tunnel, station: float, side: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    centre, tangent = tunnel.centre_point(station)
    normal = np.array([-tangent[1], tangent[0]])
    on_wall = centre + (tunnel.width_m / 2) * normal * (1 if side == "left" else -1)
    return on_wall, tangent, (-1 if side == "left" else 1)


def _build(
    rng: np.random.Generator,
    tunnel: Tunnel,
    placements: list[tuple[str, float, str, BeaconDesign, str]],
    roughness: Roughness | None,
) -> tuple[WorldBuilder, list[Beacon]]:
    """Mount beacons and look-alikes ``(id, station, side, design, kind)``, then the walls."""
    left, right = tunnel.walls()
    wb = WorldBuilder()
    smooth: dict[str, list[tuple[float, float]]] = {"left": [], "right": []}
    beacons = []
    for bid, st, side, design, kind in placements:
        on_wall, tangent, tside = _wall_mount(tunnel, st, side)
        edges = design.mounted(on_wall, tangent, tunnel_side=tside)
        if len(edges) == 4:
            wb.panels(edges, bid, kind=kind)
        else:
            wb.polyline(edges, Surface(kind, bid))
        if kind == "beacon":
            beacons.append(Beacon(bid, edges))
        ws = project_station(left if side == "left" else right, on_wall)
        smooth[side].append((ws - design.chord_m / 2, ws + design.chord_m / 2))
    for side, wall in (("left", left), ("right", right)):
        pts = roughen(wall, roughness, rng, smooth_intervals=smooth[side]) if roughness else wall
        wb.polyline(pts, Surface("wall"))
    return wb, beacons


def _poses(
    rng: np.random.Generator,
    tunnel: Tunnel,
    lo: float,
    hi: float,
    count: int,
    model_for: list[ScannerModel],
) -> tuple[Shot, ...]:
    shots = []
    for k in range(count):
        st = float(rng.uniform(lo, hi))
        centre, tangent = tunnel.centre_point(st)
        normal = np.array([-tangent[1], tangent[0]])
        p = (
            centre
            + float(rng.uniform(-(tunnel.width_m / 2 - 1.0), tunnel.width_m / 2 - 1.0)) * normal
        )
        az = math.atan2(tangent[0], tangent[1]) + (math.pi if rng.random() < 0.5 else 0.0)
        az += math.radians(float(rng.normal(0, 15)))
        model = model_for[int(rng.integers(len(model_for)))]
        shots.append(Shot(f"pose{k}", Pose2D(float(p[0]), float(p[1]), az % (2 * math.pi)), model))
    return tuple(shots)


def _hostile_scanner(rng: np.random.Generator, resolution_deg: float) -> ScannerModel:
    bias = float(rng.uniform(-0.005, 0.005))
    return ScannerModel(
        f"hostile-270-{resolution_deg:g}",
        270.0,
        resolution_deg,
        range_max_m=30.0,
        range_sigma_m=0.012,
        range_bias_m=bias,
        dropout_prob=0.03,
        mixed_pixel_prob=0.5,
        beam_divergence_rad=math.radians(0.3),
    )


def _zigzag(rng: np.random.Generator) -> BeaconDesign:
    """A zig-zag that is no beacon: mesh folds, a ventilation-duct bracket, a cable tray."""
    n = int(rng.integers(3, 6))
    lengths = rng.uniform(0.15, 0.8, n)
    turns = rng.choice([-1.0, 1.0], n - 1) * rng.uniform(math.radians(15), math.radians(80), n - 1)
    heading = 0.0
    pts = [np.zeros(2)]
    for i in range(n):
        pts.append(pts[-1] + lengths[i] * np.array([math.cos(heading), math.sin(heading)]))
        if i < n - 1:
            heading += float(turns[i])
    e = np.array(pts)
    e[:, 1] -= e[:, 1].min()
    return BeaconDesign("zigzag", e)


def hard_scene(seed: int, index: int = 0, *, poses: int = 5) -> Scene:
    """A drift at its worst: rough rock (±3-10 cm at 0.2-1 m), 2-4 beacons of practical
    size, people and equipment anywhere (occluding beacons at times), one or two
    look-alikes not in the survey (a copy of a surveyed design, or a zig-zag), and a
    scanner with 12 mm noise, a few mm of bias, 3 % dropouts and mixed pixels."""
    rng = np.random.default_rng([seed, index, 5])
    width = float(rng.uniform(4.0, 6.5))
    tunnel = Tunnel(_centreline(rng, [25.0, 25.0, 25.0], 20.0), width)
    n_beacons = int(rng.integers(2, 5))
    designs = []
    for _ in range(n_beacons):
        if rng.random() < 0.5:
            chord = float(rng.uniform(1.0, 1.8))
            designs.append(paper_design(chord, chord * float(rng.uniform(0.12, 0.2))))
        else:
            designs.append(random_design(rng, chord_range_m=(1.0, 2.0)))
    placements: list[tuple[str, float, str, BeaconDesign, str]] = []
    s = float(rng.uniform(15, 22))
    side = "left" if rng.random() < 0.5 else "right"
    for j, d in enumerate(designs):
        placements.append((f"B{j + 1}", s, side, d, "beacon"))
        s += float(rng.uniform(5, 10))
        side = ("right" if side == "left" else "left") if rng.random() < 0.75 else side
    lo, hi = placements[0][1] - 1.0, placements[-1][1] + 1.0
    for k in range(int(rng.integers(1, 3))):
        fake = designs[int(rng.integers(len(designs)))] if rng.random() < 0.5 else _zigzag(rng)
        st = float(rng.uniform(5, 70))
        if all(abs(st - p[1]) > 2.5 for p in placements):
            placements.append(
                (f"fake{k}", st, "left" if rng.random() < 0.5 else "right", fake, "lookalike")
            )
    rough = Roughness(
        amplitude_m=float(rng.uniform(0.03, 0.10)), wavelength_min_m=0.2, wavelength_max_m=1.0
    )
    wb, beacons = _build(rng, tunnel, placements, rough)
    for _ in range(int(rng.integers(1, 5))):
        centre, tangent = tunnel.centre_point(float(rng.uniform(lo - 3, hi + 3)))
        normal = np.array([-tangent[1], tangent[0]])
        p = centre + float(rng.uniform(-(width / 2 - 0.5), width / 2 - 0.5)) * normal
        wb.box(
            p,
            (float(rng.uniform(0.4, 2.5)), float(rng.uniform(0.3, 1.2))),
            float(rng.uniform(0, math.pi)),
            Surface("clutter"),
        )
    for _ in range(int(rng.integers(0, 4))):
        centre, tangent = tunnel.centre_point(float(rng.uniform(lo - 3, hi + 3)))
        normal = np.array([-tangent[1], tangent[0]])
        p = centre + float(rng.uniform(-(width / 2 - 0.4), width / 2 - 0.4)) * normal
        wb.circle(p, float(rng.uniform(0.18, 0.3)), Surface("person"))
    models = [_hostile_scanner(rng, 0.25), _hostile_scanner(rng, 0.5)]
    shots = _poses(rng, tunnel, lo, hi, poses, models)
    return Scene(
        f"hard-{seed}-{index}",
        wb.build(),
        Survey(beacons),
        shots,
        description=(
            f"hostile drift {width:.1f} m, {n_beacons} beacons, rock ±{rough.amplitude_m:.2f} m"
        ),
        seed=seed * 1000 + index + 500_000,
        params={"width_m": width},
    )


#: A few standard designs, so that many beacons in one drift are identical.
DRIFT_CATALOGUE = (
    paper_design(1.2, 0.2),
    paper_design(1.5, 0.25),
    polyline_design((0.5, 0.35, 0.7), (-0.7, -0.9), name="chevron"),
)


def drift_scene(seed: int, index: int = 0, *, poses: int = 10, length_m: float = 200.0) -> Scene:
    """A long drift with a beacon every 6-10 m on alternating walls (two dozen or more),
    drawn from three standard designs, 12 mm noise and mildly rough walls."""
    rng = np.random.default_rng([seed, index, 9])
    width = float(rng.uniform(4.5, 6.0))
    segs = [length_m / 4] * 4
    tunnel = Tunnel(_centreline(rng, segs, 8.0), width)
    placements: list[tuple[str, float, str, BeaconDesign, str]] = []
    s, side, j = 5.0, "left", 0
    while s < length_m - 5:
        d = DRIFT_CATALOGUE[int(rng.integers(len(DRIFT_CATALOGUE)))]
        j += 1
        placements.append((f"D{j:02d}", s, side, d, "beacon"))
        s += float(rng.uniform(6, 10))
        side = "right" if side == "left" else "left"
    wb, beacons = _build(
        rng, tunnel, placements, Roughness(amplitude_m=float(rng.uniform(0.01, 0.04)))
    )
    models = [
        ScannerModel("drift-270-0.25", 270.0, 0.25, range_max_m=30.0, range_sigma_m=0.012),
        ScannerModel("drift-270-0.5", 270.0, 0.5, range_max_m=30.0, range_sigma_m=0.012),
    ]
    shots = _poses(rng, tunnel, 5.0, length_m - 5.0, poses, models)
    return Scene(
        f"drift-{seed}-{index}",
        wb.build(),
        Survey(beacons),
        shots,
        description=(
            f"{length_m:.0f} m drift, {len(beacons)} beacons of {len(DRIFT_CATALOGUE)} designs"
        ),
        seed=seed * 1000 + index + 900_000,
        params={"width_m": width, "beacons": len(beacons)},
    )
