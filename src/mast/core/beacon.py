"""Surveyed beacons, the templates derived from them, and a beacon survey.

A beacon is three flat vertical panels P1, P2, P3 joined along vertical
edges. In plan it is the polyline ``e1 e2 e3 e4`` (DESIGN.md, "The beacon"):
``e1`` the free end of P1, ``e2`` = P1/P2, ``e3`` = P2/P3, ``e4`` the free end
of P3. Everything the locator needs to recognise a beacon (panel lengths,
deflection angles, centroid distances) is derived from the surveyed edges.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.errors import BeaconError, InputError

__all__ = ["Beacon", "BeaconTemplate", "IdentifiabilityRules", "Survey"]


@dataclass(frozen=True, slots=True)
class IdentifiabilityRules:
    """What makes a beacon's panels tell themselves apart in a scan.

    Attributes
    ----------
    min_panel_m : float
        Shortest panel, metres: shorter ones catch too few beams to fit a line.
    min_length_difference : float
        Any two panel lengths must differ by at least this fraction of the
        longer one (2:3:1 gives 0.33 and 0.5).
    min_deflection_rad, max_deflection_rad : float
        Deflection angles at e2 and e3 must lie, in magnitude, between these:
        a small deflection cannot be told from a straight wall, and one near
        180 degrees folds a panel back on its neighbour.
    """

    min_panel_m: float = 0.05
    min_length_difference: float = 0.10
    min_deflection_rad: float = math.radians(5.0)
    max_deflection_rad: float = math.radians(170.0)


def _signed_angle(u: NDArray[np.float64], v: NDArray[np.float64]) -> float:
    """Counter-clockwise angle from direction ``u`` to direction ``v``, in (-pi, pi]."""
    return math.atan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1])


@dataclass(frozen=True, eq=False)
class BeaconTemplate:
    """Shape of a beacon, derived from its four edges (any frame).

    Attributes
    ----------
    panel_lengths : ndarray, shape (3,)
        ``|e2 - e1|``, ``|e3 - e2|``, ``|e4 - e3|``, metres.
    directions : ndarray, shape (3, 2)
        Unit vector of each panel, from its lower- to its higher-numbered edge.
    normals : ndarray, shape (3, 2)
        Unit normal of each panel, the direction rotated +90 degrees
        (counter-clockwise in a right-handed frame).
    deflections : ndarray, shape (2,)
        Signed turn at e2 (P1 to P2) and at e3 (P2 to P3), radians,
        counter-clockwise positive, walking e1 to e4.
    centroids : ndarray, shape (3, 2)
        Panel mid-points.
    centroid_distances : ndarray, shape (2,)
        Distance between the centroids of P1 and P2, and of P2 and P3 (the
        paper's ``c_j``).
    """

    panel_lengths: NDArray[np.float64]
    directions: NDArray[np.float64]
    normals: NDArray[np.float64]
    deflections: NDArray[np.float64]
    centroids: NDArray[np.float64]
    centroid_distances: NDArray[np.float64]

    @classmethod
    def from_edges(cls, edges: ArrayLike) -> BeaconTemplate:
        e = np.asarray(edges, dtype=float).reshape(4, 2)
        vec = np.diff(e, axis=0)
        lengths = np.hypot(vec[:, 0], vec[:, 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            dirs = vec / lengths[:, None]
        normals = np.stack([-dirs[:, 1], dirs[:, 0]], axis=1)
        defl = np.array([_signed_angle(dirs[0], dirs[1]), _signed_angle(dirs[1], dirs[2])])
        cents = 0.5 * (e[:-1] + e[1:])
        cd = np.hypot(*np.diff(cents, axis=0).T)
        for a in (lengths, dirs, normals, defl, cents, cd):
            a.setflags(write=False)
        return cls(lengths, dirs, normals, defl, cents, cd)


@dataclass(frozen=True, eq=False)
class Beacon:
    """One surveyed beacon.

    Attributes
    ----------
    id : str
        The surveyor's name for it.
    edges : ndarray, shape (4, 2)
        ``e1..e4`` as (Easting, Northing), metres, in polyline order.
    elevations : ndarray, shape (4,), optional
        Surveyed elevation of each edge point, metres (not used in 2D).
    edge_sigmas_m : ndarray, shape (4,), optional
        Standard deviation of each edge's horizontal coordinates, metres, where the
        survey gives it (``sigma_m``; NaN for an edge it leaves out).
    design : str, optional
        The name of the design this beacon is built to (``design``), where given.
    """

    id: str
    edges: NDArray[np.float64]
    elevations: NDArray[np.float64] | None = None
    edge_sigmas_m: NDArray[np.float64] | None = None
    design: str | None = None
    template: BeaconTemplate = field(init=False, repr=False)

    def __post_init__(self) -> None:
        e = np.array(self.edges, dtype=float)
        if e.shape != (4, 2):
            raise BeaconError(f"beacon {self.id!r} needs 4 edges (E, N), got shape {e.shape}")
        if not np.all(np.isfinite(e)):
            raise BeaconError(f"beacon {self.id!r} has an edge coordinate that is not finite")
        e.setflags(write=False)
        object.__setattr__(self, "edges", e)
        if self.elevations is not None:
            z = np.array(self.elevations, dtype=float).reshape(-1)
            if z.shape != (4,):
                raise BeaconError(f"beacon {self.id!r} needs 4 elevations, got {z.size}")
            z.setflags(write=False)
            object.__setattr__(self, "elevations", z)
        if self.edge_sigmas_m is not None:
            s = np.array(self.edge_sigmas_m, dtype=float).reshape(-1)
            if s.shape != (4,):
                raise BeaconError(f"beacon {self.id!r} needs 4 edge sigmas, got {s.size}")
            if np.any(s[~np.isnan(s)] < 0) or np.any(np.isinf(s)):
                raise BeaconError(f"beacon {self.id!r}: an edge sigma is negative or infinite")
            s.setflags(write=False)
            object.__setattr__(self, "edge_sigmas_m", s)
        object.__setattr__(self, "template", BeaconTemplate.from_edges(e))

    def sigmas_or(self, default_m: float) -> NDArray[np.float64]:
        """Each edge's standard deviation, metres: the survey's ``sigma_m`` where it
        gives one, else ``default_m`` (``--survey-sigma``)."""
        if self.edge_sigmas_m is None:
            return np.full(4, float(default_m))
        return np.where(np.isnan(self.edge_sigmas_m), float(default_m), self.edge_sigmas_m)

    def identifiability_problems(
        self, rules: IdentifiabilityRules = IdentifiabilityRules()
    ) -> list[str]:
        """Reasons this beacon could not be told apart in a scan (empty if none)."""
        t = self.template
        p = t.panel_lengths
        problems: list[str] = []
        for i, length in enumerate(p):
            if not length >= rules.min_panel_m:
                problems.append(
                    f"panel P{i + 1} is {length:.3f} m long, shorter than "
                    f"{rules.min_panel_m:.3f} m (edges e{i + 1} and e{i + 2} too close)"
                )
        if problems:
            return problems
        for i, j in ((0, 1), (1, 2), (0, 2)):
            longer = max(p[i], p[j])
            if abs(p[i] - p[j]) < rules.min_length_difference * longer:
                problems.append(
                    f"panels P{i + 1} ({p[i]:.3f} m) and P{j + 1} ({p[j]:.3f} m) differ by less "
                    f"than {100 * rules.min_length_difference:.0f} % and cannot be told apart"
                )
        for k, d in enumerate(t.deflections):
            deg = math.degrees(abs(d))
            if abs(d) < rules.min_deflection_rad:
                problems.append(
                    f"deflection at e{k + 2} is {deg:.2f}°, less than "
                    f"{math.degrees(rules.min_deflection_rad):.1f}° (panels nearly collinear)"
                )
            elif abs(d) > rules.max_deflection_rad:
                problems.append(
                    f"deflection at e{k + 2} is {deg:.2f}°, more than "
                    f"{math.degrees(rules.max_deflection_rad):.1f}° (panel folded back)"
                )
        return problems

    def check_identifiable(self, rules: IdentifiabilityRules = IdentifiabilityRules()) -> None:
        """Raise :class:`BeaconError` naming the beacon and its first problem."""
        problems = self.identifiability_problems(rules)
        if problems:
            raise BeaconError(f"beacon {self.id!r} is not identifiable: " + "; ".join(problems))

    @property
    def centroid(self) -> NDArray[np.float64]:
        """Mean of the four edge points."""
        return np.asarray(self.edges.mean(axis=0))


class Survey:
    """The surveyed beacons of a site, in file order, looked up by id."""

    def __init__(self, beacons: Iterable[Beacon], *, source: str | None = None):
        self._beacons: dict[str, Beacon] = {}
        for b in beacons:
            if b.id in self._beacons:
                raise InputError(f"beacon {b.id!r} appears twice", path=source)
            self._beacons[b.id] = b
        self.source = source

    def __len__(self) -> int:
        return len(self._beacons)

    def __iter__(self) -> Iterator[Beacon]:
        return iter(self._beacons.values())

    def __getitem__(self, beacon_id: str) -> Beacon:
        try:
            return self._beacons[beacon_id]
        except KeyError:
            raise KeyError(f"no beacon {beacon_id!r} in the survey") from None

    def __contains__(self, beacon_id: object) -> bool:
        return beacon_id in self._beacons

    @property
    def ids(self) -> list[str]:
        return list(self._beacons)

    def edge_sigmas(self) -> NDArray[np.float64]:
        """The ``sigma_m`` the survey gives, edge by edge (those it gives only)."""
        given = [b.edge_sigmas_m for b in self if b.edge_sigmas_m is not None]
        every = np.concatenate(given) if given else np.zeros(0)
        return np.asarray(every[~np.isnan(every)])

    def loose_edges(self, default_m: float) -> list[str]:
        """The edges whose ``sigma_m`` is more than three times the survey's median edge
        sigma and above 1 cm, as ``"B07 e3 (0.300 m)"``: tests made before it is known
        which beacon a corner is (the identification, the pose hypotheses) take the
        survey's largest sigma, so one loose edge widens them for every beacon."""
        every = np.concatenate([b.sigmas_or(default_m) for b in self]) if len(self) else np.zeros(0)
        if every.size == 0:
            return []
        limit = max(0.01, 3.0 * float(np.median(every)))
        return [
            f"{b.id} e{k + 1} ({s:.3f} m)"
            for b in self
            for k, s in enumerate(b.sigmas_or(default_m))
            if s > limit
        ]

    def sigma_text(self, default_m: float) -> str:
        """How the survey's edges are weighed, for reports: ``"3.0 mm per edge
        coordinate"``, or the survey's own ``sigma_m`` and the default for the rest."""
        own = self.edge_sigmas()
        if own.size == 0:
            return f"{1000 * default_m:.1f} mm per edge coordinate"
        total = 4 * len(self)
        text = (
            f"the survey's sigma_m on {own.size} of {total} edges "
            f"({1000 * float(own.min()):.1f} to {1000 * float(own.max()):.1f} mm)"
        )
        return text if own.size == total else f"{text}, {1000 * default_m:.1f} mm on the rest"

    def __repr__(self) -> str:
        return f"Survey({len(self)} beacons: {', '.join(self.ids)})"
