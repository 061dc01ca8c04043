"""Small drifts for the planning tests."""

from __future__ import annotations

import numpy as np

from mast.core.beacon import Beacon, Survey
from mast.core.walls import Drift, Wall
from mast.sim.design import paper_design, polyline_design
from mast.sim.tunnel import Tunnel

ORIGIN = np.array([52_000.0, 7_340_000.0])  # UTM-sized, as a mine grid may be

DESIGNS = (
    paper_design(1.2, 0.2),
    polyline_design((0.5, 0.35, 0.7), (-0.7, -0.9), name="chevron"),
    paper_design(1.5, 0.25),
)


def straight_drift(
    length_m: float = 40.0, width_m: float = 5.0, azimuth_deg: float = 30.0
) -> tuple[Tunnel, Drift]:
    a = np.radians(azimuth_deg)
    s = np.arange(0.0, length_m + 1e-9, 2.0)
    centre = ORIGIN + s[:, None] * np.array([np.sin(a), np.cos(a)])
    tunnel = Tunnel(centre, width_m)
    left, right = tunnel.walls()
    return tunnel, Drift((Wall("left", left), Wall("right", right)), source="test drift")


def mounted(tunnel: Tunnel, layout: list[tuple[str, float, str, int]]) -> Survey:
    beacons = []
    for bid, station, side, design in layout:
        point, tangent, tunnel_side = tunnel.wall_point(side, station)
        beacons.append(DESIGNS[design].beacon(bid, point, tangent, tunnel_side=tunnel_side))
    return Survey(beacons)


def pair_scene() -> tuple[Tunnel, Drift, Survey]:
    """A 40 m drift with two beacons abeam each other's stretch at 18 and 24 m."""
    tunnel, drift = straight_drift()
    return tunnel, drift, mounted(tunnel, [("A", 18.0, "left", 0), ("B", 24.0, "right", 1)])


__all__ = ["Beacon", "mounted", "pair_scene", "straight_drift"]
