"""Hostile scenes: rough rock, people, equipment, look-alike shapes, occlusion,
dropouts, mixed pixels and range bias (``hard``); a long drift with dozens of
beacons of a few identical designs (``drift``); and scenes drawn as widely as the field
(``field``): beacons of any identifiable shape and size bolted askew onto rough rock, five
scanner models from 8 to 20 mm, and in their hostile half clutter that looks like panels."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mast.core.beacon import Survey
from mast.core.pose import Pose2D
from mast.sim.design import BeaconDesign, paper_design, random_design
from mast.sim.mounting import (
    DRIFT_CATALOGUE,
    direction,
    mount_beacons,
    random_centreline,
)
from mast.sim.scanner import ScannerModel
from mast.sim.scene import Scene, Shot
from mast.sim.tunnel import Roughness, Tunnel
from mast.sim.world import Surface, WorldBuilder

__all__ = ["FIELD_SCANNERS", "drift_scene", "field_scene", "hard_scene"]


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


def _equipment_and_people(
    rng: np.random.Generator,
    wb: WorldBuilder,
    tunnel: Tunnel,
    box_stations: tuple[float, float],
    person_stations: tuple[float, float],
    least_box: tuple[float, float],
    person_radius: tuple[float, float],
) -> None:
    """One to four boxes (equipment, up to 2.5 x 1.2 m, at least ``least_box``) and up
    to three people (circles) anywhere across the drift between the stations given."""
    width = tunnel.width_m
    for _ in range(int(rng.integers(1, 5))):
        centre, tangent = tunnel.centre_point(float(rng.uniform(*box_stations)))
        normal = np.array([-tangent[1], tangent[0]])
        p = centre + float(rng.uniform(-(width / 2 - 0.5), width / 2 - 0.5)) * normal
        wb.box(
            p,
            (float(rng.uniform(least_box[0], 2.5)), float(rng.uniform(least_box[1], 1.2))),
            float(rng.uniform(0, math.pi)),
            Surface("clutter"),
        )
    for _ in range(int(rng.integers(0, 4))):
        centre, tangent = tunnel.centre_point(float(rng.uniform(*person_stations)))
        normal = np.array([-tangent[1], tangent[0]])
        p = centre + float(rng.uniform(-(width / 2 - 0.4), width / 2 - 0.4)) * normal
        wb.circle(p, float(rng.uniform(*person_radius)), Surface("person"))


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
    tunnel = Tunnel(random_centreline(rng, [25.0, 25.0, 25.0], 20.0), width)
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
    wb, beacons = mount_beacons(rng, tunnel, placements, rough)
    _equipment_and_people(
        rng, wb, tunnel, (lo - 3, hi + 3), (lo - 3, hi + 3), (0.4, 0.3), (0.18, 0.3)
    )
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


def drift_scene(seed: int, index: int = 0, *, poses: int = 10, length_m: float = 200.0) -> Scene:
    """A long drift with a beacon every 6-10 m on alternating walls (two dozen or more),
    drawn from three standard designs, 12 mm noise and mildly rough walls."""
    rng = np.random.default_rng([seed, index, 9])
    width = float(rng.uniform(4.5, 6.0))
    segs = [length_m / 4] * 4
    tunnel = Tunnel(random_centreline(rng, segs, 8.0), width)
    placements: list[tuple[str, float, str, BeaconDesign, str]] = []
    s, side, j = 5.0, "left", 0
    while s < length_m - 5:
        d = DRIFT_CATALOGUE[int(rng.integers(len(DRIFT_CATALOGUE)))]
        j += 1
        placements.append((f"D{j:02d}", s, side, d, "beacon"))
        s += float(rng.uniform(6, 10))
        side = "right" if side == "left" else "left"
    wb, beacons = mount_beacons(
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


#: The field's scanners: the five classes the independent scenes are drawn with
#: (SICK LMS111 and LMS151, LMS511, Hokuyo UTM-30LX, a 360-degree spinning scanner).
FIELD_SCANNERS: tuple[ScannerModel, ...] = (
    ScannerModel("lms111-0.5", 270.0, 0.5, range_max_m=20.0, range_sigma_m=0.012),
    ScannerModel("lms151-0.25", 270.0, 0.25, range_max_m=50.0, range_sigma_m=0.012),
    ScannerModel("lms511-0.1667", 190.0, 1.0 / 6.0, range_max_m=80.0, range_sigma_m=0.008),
    ScannerModel("utm30-0.25", 270.0, 0.25, range_max_m=30.0, range_sigma_m=0.015),
    ScannerModel("spin360-0.2", 360.0, 0.2, range_max_m=100.0, range_sigma_m=0.020),
)


def _field_design(rng: np.random.Generator) -> BeaconDesign:
    """Half the paper's 2:3:1 hat, half a random identifiable hat; chords 0.45-2.0 m."""
    if rng.random() < 0.5:
        chord = float(rng.uniform(0.45, 2.0))
        return paper_design(chord, chord * float(rng.uniform(0.12, 0.2)))
    return random_design(rng, chord_range_m=(0.45, 2.0))


def _panel_lookalike(rng: np.random.Generator) -> BeaconDesign:
    """Clutter that looks like panels: a bracket, a board on stand-offs, a folded plate."""
    a, b = rng.uniform(0.15, 0.9, 2)
    turn = float(rng.uniform(math.radians(20), math.radians(110)))
    if rng.random() < 0.5:  # an L or V: two faces meeting in a corner
        pts = [np.zeros(2), np.array([a, 0.0]), np.array([a, 0.0]) + b * direction(turn)]
    else:  # a board standing off the wall: three faces, square-ish ends
        d = float(rng.uniform(0.05, 0.25))
        pts = [np.zeros(2), np.array([0.0, d]), np.array([a + b, d]), np.array([a + b, 0.0])]
    e = np.array(pts, dtype=float)
    e[:, 1] -= e[:, 1].min()
    return BeaconDesign("panel-lookalike", e)


def field_scene(seed: int, index: int = 0, *, hostile: bool = False, poses: int = 4) -> Scene:
    """A drift drawn as widely as the field: 4-10 m wide with gentle bends, rough rock
    (±2-8 cm at 0.2-1 m) right up to the beacons, two beacons 4-10 m apart of any
    identifiable shape and size (half the paper's hat, chords 0.45-2 m) bolted up to
    10 degrees off the wall's line, and shots between them by one of the five
    :data:`FIELD_SCANNERS`. ``hostile`` adds equipment, people, look-alikes of the
    surveyed designs and clutter shaped like panels near the beacons, mixed pixels at
    every range jump and dropouts."""
    rng = np.random.default_rng([seed, index, 31 if hostile else 30])
    width = float(rng.uniform(4.0, 10.0))
    tunnel = Tunnel(random_centreline(rng, [22.0, 22.0, 22.0], 12.0), width)
    s1 = float(rng.uniform(24.0, 30.0))
    s2 = s1 + float(rng.uniform(4.0, 10.0))
    side1 = "left" if rng.random() < 0.5 else "right"
    side2 = ("right" if side1 == "left" else "left") if rng.random() < 0.6 else side1
    designs = [_field_design(rng), _field_design(rng)]
    placements: list[tuple[str, float, str, BeaconDesign, str]] = [
        ("B1", s1, side1, designs[0], "beacon"),
        ("B2", s2, side2, designs[1], "beacon"),
    ]
    tilts = {bid: math.radians(float(rng.uniform(-10.0, 10.0))) for bid in ("B1", "B2")}
    if hostile:
        for k in range(int(rng.integers(1, 4))):
            st = float(rng.uniform(s1 - 8.0, s2 + 8.0))
            if all(abs(st - p[1]) > 2.2 for p in placements):
                r = rng.random()
                fake = (
                    designs[int(rng.integers(2))]
                    if r < 0.3
                    else _panel_lookalike(rng)
                    if r < 0.8
                    else _zigzag(rng)
                )
                side = "left" if rng.random() < 0.5 else "right"
                placements.append((f"fake{k}", st, side, fake, "lookalike"))
                tilts[f"fake{k}"] = math.radians(float(rng.uniform(-15.0, 15.0)))
    rough = Roughness(
        amplitude_m=float(rng.uniform(0.02, 0.08)),
        wavelength_min_m=0.2,
        wavelength_max_m=1.0,
        beacon_margin_m=0.03,
    )
    wb, beacons = mount_beacons(rng, tunnel, placements, rough, tilts)
    if hostile:
        _equipment_and_people(
            rng, wb, tunnel, (s1 - 6.0, s2 + 6.0), (s1 - 4.0, s2 + 4.0), (0.3, 0.2), (0.15, 0.3)
        )
    models = [
        replace(
            m,
            dropout_prob=0.02,
            mixed_pixel_prob=0.5,
            beam_divergence_rad=math.radians(float(rng.uniform(0.2, 0.6))),
        )
        if hostile
        else m
        for m in FIELD_SCANNERS
    ]
    shots = _poses(rng, tunnel, s1 - 1.0, s2 + 1.0, poses, models)
    family = "hostile" if hostile else "noisy"
    return Scene(
        f"field-{family}-{seed}-{index}",
        wb.build(),
        Survey(beacons),
        shots,
        description=(
            f"{family} field drift {width:.1f} m, beacons {designs[0].chord_m:.2f} m and "
            f"{designs[1].chord_m:.2f} m askew {math.degrees(tilts['B1']):+.0f}° and "
            f"{math.degrees(tilts['B2']):+.0f}°, rock ±{rough.amplitude_m:.2f} m"
        ),
        seed=seed * 1000 + index + (700_000 if hostile else 600_000),
        params={
            "width_m": width,
            "family": family,
            "tilts_deg": {b: math.degrees(tilts[b]) for b in ("B1", "B2")},
        },
    )
