"""Beacons bolted onto a simulated tunnel's walls: where a design's chord goes on a wall
(straight or askew), the tunnel's rough walls kept smooth behind each beacon, and the
catalogue of standard designs a long drift repeats. Shared by the hostile scenes
(:mod:`mast.sim.hard`) and the drives (:mod:`mast.sim.drive`)."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon
from mast.sim.design import BeaconDesign, paper_design, polyline_design
from mast.sim.tunnel import Roughness, Tunnel, project_station, roughen
from mast.sim.world import Surface, WorldBuilder

__all__ = ["DRIFT_CATALOGUE", "direction", "mount_beacons", "random_centreline", "wall_mount"]


#: A few standard designs, so that many beacons in one drift are identical.
DRIFT_CATALOGUE = (
    paper_design(1.2, 0.2),
    paper_design(1.5, 0.25),
    polyline_design((0.5, 0.35, 0.7), (-0.7, -0.9), name="chevron"),
)


def direction(azimuth_rad: float) -> NDArray[np.float64]:
    """The unit vector (E, N) of an azimuth (clockwise from grid north)."""
    return np.array([math.sin(azimuth_rad), math.cos(azimuth_rad)])


def random_centreline(
    rng: np.random.Generator, lengths: list[float], max_bend_deg: float
) -> NDArray[np.float64]:
    """A tunnel's centreline somewhere in a 10 km square: legs of ``lengths`` in a random
    heading, each bending by up to ``max_bend_deg`` from the last."""
    heading = float(rng.uniform(0, 2 * math.pi))
    pts = [np.array([float(rng.uniform(0, 1e4)), float(rng.uniform(0, 1e4))])]
    for length in lengths:
        pts.append(pts[-1] + length * direction(heading))
        heading += math.radians(float(rng.uniform(-max_bend_deg, max_bend_deg)))
    return np.array(pts)


def wall_mount(
    tunnel: Tunnel, station: float, side: str, tilt_rad: float = 0.0, chord_m: float = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64], int]:
    """Where a design's chord centre goes, the chord's direction and the tunnel's side.

    A beacon bolted askew (``tilt_rad`` off the wall's line) stands out from the
    wall so that its nearer base end touches the wall's line: one end on the
    rock, the other clear of it (divergent or convergent to the wall).
    """
    centre, tangent = tunnel.centre_point(station)
    normal = np.array([-tangent[1], tangent[0]])
    inward = -normal if side == "left" else normal
    on_wall = centre - (tunnel.width_m / 2) * inward
    on_wall = on_wall + (chord_m / 2) * abs(math.sin(tilt_rad)) * inward
    c, s = math.cos(tilt_rad), math.sin(tilt_rad)
    chord_dir = np.array([c * tangent[0] - s * tangent[1], s * tangent[0] + c * tangent[1]])
    return on_wall, chord_dir, (-1 if side == "left" else 1)


def mount_beacons(
    rng: np.random.Generator,
    tunnel: Tunnel,
    placements: list[tuple[str, float, str, BeaconDesign, str]],
    roughness: Roughness | None,
    tilts_rad: dict[str, float] | None = None,
) -> tuple[WorldBuilder, list[Beacon]]:
    """Mount beacons and look-alikes ``(id, station, side, design, kind)``, each
    ``tilts_rad[id]`` off its wall's line (0 when not given), then the walls."""
    left, right = tunnel.walls()
    wb = WorldBuilder()
    smooth: dict[str, list[tuple[float, float]]] = {"left": [], "right": []}
    beacons = []
    for bid, st, side, design, kind in placements:
        tilt = (tilts_rad or {}).get(bid, 0.0)
        on_wall, tangent, tside = wall_mount(tunnel, st, side, tilt, design.chord_m)
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
