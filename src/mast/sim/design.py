"""Beacon designs: the shapes the simulator builds and mounts on walls.

Geometry (local design frame, metres): the wall is the x axis, the tunnel
lies at +y. The polyline ``e1 e2 e3 e4`` runs in +x; the beacon stands out
of the wall towards +y. Walking e1 to e4 the panels turn clockwise, so both
deflection angles are negative (counter-clockwise positive, as in
:class:`mast.core.beacon.BeaconTemplate`).

:func:`paper_design` is the paper's three-panel "hat" (Figure 1): panel
lengths in the ratio ``p1:p2:p3`` (default 2:3:1); P1 rises from the wall at
e1 to depth ``h`` at e2; P2 runs parallel to the wall at depth ``h``; P3
returns from e3 to the wall at e4. Hence the deflection at e2 is
``-asin(h / p1)`` and at e3 is ``-asin(h / p3)``: both are functions of the
depth, as the paper says of its theta_2. The overall length given is the
chord ``|e4 - e1|`` along the wall; the panel unit is solved from it. The
paper's beacons (length 0.499-1.996 m, depth 0.100-0.400 m) all fit this
shape with a steep P3.

:func:`polyline_design` builds any shape from three panel lengths and two
deflections; :func:`random_design` draws identifiable shapes for tests.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from mast.core.beacon import Beacon
from mast.errors import InputError

__all__ = ["BeaconDesign", "paper_design", "polyline_design", "random_design"]


@dataclass(frozen=True, eq=False)
class BeaconDesign:
    """A beacon shape in its design frame (wall along +x, tunnel at +y).

    Attributes
    ----------
    name : str
    edges_local : ndarray, shape (4, 2)
        ``e1..e4``; ``e1`` at the origin, ``e4`` on the x axis at ``x = chord``.
        Shapes that are no beacon (look-alikes) may have more or fewer vertices;
        their chord runs from the first to the last.
    """

    name: str
    edges_local: NDArray[np.float64]

    @property
    def chord_m(self) -> float:
        return float(np.hypot(*(self.edges_local[-1] - self.edges_local[0])))

    @property
    def depth_m(self) -> float:
        return float(self.edges_local[:, 1].max() - self.edges_local[:, 1].min())

    def mounted(
        self, wall_point: ArrayLike, wall_direction: ArrayLike, *, tunnel_side: int = 1
    ) -> NDArray[np.float64]:
        """Edges in the mine frame, with the chord centred on ``wall_point``.

        ``wall_direction`` is the wall's unit tangent; ``tunnel_side`` is +1
        when the tunnel lies to its left, -1 when to its right (the beacon
        always stands out into the tunnel). On a wall with the tunnel on the
        right the design is mirrored, so the polyline still runs e1 to e4 in
        the tangent direction.
        """
        t = np.asarray(wall_direction, dtype=float)
        t = t / np.hypot(*t)
        n = np.array([-t[1], t[0]]) * (1 if tunnel_side >= 0 else -1)
        local = self.edges_local - np.array([self.chord_m / 2, 0.0])
        out: NDArray[np.float64] = (
            np.asarray(wall_point, dtype=float) + local[:, :1] * t + local[:, 1:] * n
        )
        return out

    def beacon(
        self,
        beacon_id: str,
        wall_point: ArrayLike,
        wall_direction: ArrayLike,
        *,
        tunnel_side: int = 1,
    ) -> Beacon:
        return Beacon(beacon_id, self.mounted(wall_point, wall_direction, tunnel_side=tunnel_side))


def polyline_design(
    panel_lengths_m: tuple[float, float, float],
    deflections_rad: tuple[float, float],
    *,
    name: str = "custom",
) -> BeaconDesign:
    """A design from panel lengths and the signed deflections at e2 and e3.

    The polyline is rotated so its chord e1-e4 lies on the wall (x axis) and
    shifted so its lowest point touches the wall. Negative (clockwise)
    deflections give a hat standing out towards +y.
    """
    p = [float(v) for v in panel_lengths_m]
    if min(p) <= 0:
        raise InputError(f"beacon design {name!r}: panel lengths must be positive, got {p}")
    heading = 0.0
    pts = [np.zeros(2)]
    for i in range(3):
        pts.append(pts[-1] + p[i] * np.array([math.cos(heading), math.sin(heading)]))
        if i < 2:
            heading += deflections_rad[i]
    e = np.array(pts)
    chord = e[3] - e[0]
    if np.hypot(*chord) < 1e-9:
        raise InputError(f"beacon design {name!r}: e1 and e4 coincide")
    ang = math.atan2(chord[1], chord[0])
    c, s = math.cos(-ang), math.sin(-ang)
    e = e @ np.array([[c, -s], [s, c]]).T
    if e[1:3, 1].mean() < 0:  # stand out towards the tunnel
        e[:, 1] = -e[:, 1]
    e[:, 1] -= e[:, 1].min()
    e[:, 0] -= e[0, 0]
    e.setflags(write=False)
    return BeaconDesign(name, e)


def paper_design(
    chord_m: float = 1.0,
    depth_m: float = 0.2,
    *,
    ratio: tuple[float, float, float] = (2.0, 3.0, 1.0),
) -> BeaconDesign:
    """The paper's hat: panels in ``ratio``, chord ``chord_m`` along the wall, depth ``depth_m``.

    Solves the panel unit ``u`` from ``chord = sum_i p_i cos(a_i)`` with
    ``p = u * ratio``, ``a_1 = asin(h / p_1)``, ``a_2 = 0``, ``a_3 = asin(h / p_3)``.
    """
    r = np.asarray(ratio, dtype=float)
    h = float(depth_m)
    if not (h > 0 and chord_m > 0):
        raise InputError(f"paper beacon: chord {chord_m} m and depth {h} m must be positive")
    u_min = h / min(r[0], r[2])

    def chord_of(u: float) -> float:
        p = u * r
        return float(
            p[0] * math.sqrt(max(0.0, 1 - (h / p[0]) ** 2))
            + p[1]
            + p[2] * math.sqrt(max(0.0, 1 - (h / p[2]) ** 2))
        )

    if chord_of(u_min) > chord_m:
        raise InputError(
            f"paper beacon: chord {chord_m} m is too short for depth {h} m with ratio "
            f"{':'.join(f'{v:g}' for v in r)} (needs at least {chord_of(u_min):.3f} m)"
        )
    u = brentq(lambda v: chord_of(v) - chord_m, u_min, max(2 * u_min, chord_m), xtol=1e-15)
    p = u * r
    a1 = math.asin(min(1.0, h / p[0]))
    e2 = np.array([p[0] * math.cos(a1), h])
    e3 = e2 + np.array([p[1], 0.0])
    e4 = np.array([chord_m, 0.0])
    e = np.array([[0.0, 0.0], e2, e3, e4])
    e.setflags(write=False)
    return BeaconDesign(f"paper-{':'.join(f'{v:g}' for v in r)}-{chord_m:g}x{h:g}", e)


def random_design(
    rng: np.random.Generator,
    *,
    chord_range_m: tuple[float, float] = (0.6, 2.0),
    deflection_range_deg: tuple[float, float] = (20.0, 70.0),
) -> BeaconDesign:
    """An identifiable random hat: distinct panel lengths, clockwise deflections in
    ``deflection_range_deg`` (shallow ones put the outer panels at a shallow angle to the
    wall)."""
    lo, hi = (math.radians(v) for v in deflection_range_deg)
    for _ in range(1000):
        p = rng.uniform(1.0, 3.0, size=3)
        q = np.sort(p)
        if np.any(np.diff(q) < 0.25 * q[1:]):
            continue
        d = -rng.uniform(lo, hi, size=2)
        design = polyline_design((p[0], p[1], p[2]), (d[0], d[1]), name="random")
        scale = rng.uniform(*chord_range_m) / design.chord_m
        e = design.edges_local * scale
        if e[1:3, 1].min() < 0.03:  # both inner edges must stand clear of the wall
            continue
        e.setflags(write=False)
        return BeaconDesign(f"random-{scale * p.sum():.2f}m", e)
    raise RuntimeError("could not draw an identifiable beacon design")  # pragma: no cover
