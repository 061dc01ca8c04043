"""An index of a beacon survey's features, so that a scan's evidence looks up
candidates instead of looping over every pair of surveyed beacons.

Whole-mine survey files hold hundreds of beacons, many of them built to a few
designs. The index groups the beacons by design (the same panel lengths and
deflections within a tolerance) so that identification tests each design once,
and keeps, per pair of designs and node edges, the distances between their
surveyed edges sorted, so that a pair of identified nodes finds the surveyed
edge pairs of that length by bisection.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon, Survey

__all__ = ["DesignTolerance", "SurveyIndex"]

#: The edges a node can be: e2 (P1/P2) and e3 (P2/P3).
NODE_EDGES: tuple[int, int] = (2, 3)


@dataclass(frozen=True, slots=True)
class DesignTolerance:
    """When two surveyed beacons count as one design.

    Attributes
    ----------
    length_m : float
        Largest difference of any panel length.
    deflection_rad : float
        Largest difference of either deflection angle.
    max_pair_distance_m : float
        Edge pairs farther apart than this are not indexed (no scan sees both).
    """

    length_m: float = 0.005
    deflection_rad: float = math.radians(0.5)
    max_pair_distance_m: float = 250.0


def _same_design(a: Beacon, b: Beacon, tol: DesignTolerance) -> bool:
    ta, tb = a.template, b.template
    return bool(
        np.all(np.abs(ta.panel_lengths - tb.panel_lengths) <= tol.length_m)
        and np.all(np.abs(ta.deflections - tb.deflections) <= tol.deflection_rad)
    )


@dataclass(frozen=True, eq=False)
class SurveyIndex:
    """Designs and edge-pair distances of a survey.

    Attributes
    ----------
    survey : Survey
    designs : tuple of tuple of str
        Beacon ids grouped by design; the first of each is its representative.
    """

    survey: Survey
    designs: tuple[tuple[str, ...], ...]
    _design_of: dict[str, int] = field(repr=False)
    _pairs: dict[tuple[int, int, int, int], tuple[list[float], NDArray[np.intp]]] = field(
        repr=False
    )
    _row_beacon: NDArray[np.intp] = field(repr=False)
    _row_xy: NDArray[np.float64] = field(repr=False)

    @classmethod
    def from_survey(
        cls, survey: Survey, tolerance: DesignTolerance = DesignTolerance()
    ) -> SurveyIndex:
        designs: list[list[str]] = []
        for beacon in survey:
            for group in designs:
                if _same_design(survey[group[0]], beacon, tolerance):
                    group.append(beacon.id)
                    break
            else:
                designs.append([beacon.id])
        design_of = {b: k for k, group in enumerate(designs) for b in group}
        ids = survey.ids
        # One row per (beacon, node edge); all pairs within reach, sorted by (key, distance).
        n_edges = len(NODE_EDGES)
        row_beacon = np.repeat(np.arange(len(ids), dtype=np.intp), n_edges)
        row_edge = np.tile(np.array(NODE_EDGES, dtype=np.intp), len(ids))
        row_xy = np.array(
            [survey[ids[b]].edges[e - 1] for b, e in zip(row_beacon, row_edge, strict=True)]
        ).reshape(-1, 2)
        row_key = np.array([design_of[ids[b]] for b in row_beacon], dtype=np.intp) * n_edges + (
            row_edge - NODE_EDGES[0]
        )
        n_keys = len(designs) * n_edges
        ii_all: list[NDArray[np.intp]] = []
        jj_all: list[NDArray[np.intp]] = []
        d_all: list[NDArray[np.float64]] = []
        for lo in range(0, row_xy.shape[0], 512):
            diff = row_xy[None, :, :] - row_xy[lo : lo + 512, None, :]
            d = np.hypot(diff[..., 0], diff[..., 1])
            ii, jj = np.nonzero((d <= tolerance.max_pair_distance_m) & (d > 0))
            ii_all.append(ii + lo)
            jj_all.append(jj)
            d_all.append(d[ii, jj])
        ii = np.concatenate(ii_all) if ii_all else np.zeros(0, dtype=np.intp)
        jj = np.concatenate(jj_all) if jj_all else np.zeros(0, dtype=np.intp)
        dist = np.concatenate(d_all) if d_all else np.zeros(0)
        key = row_key[ii] * n_keys + row_key[jj]
        order = np.lexsort((dist, key))
        key, ii, jj, dist = key[order], ii[order], jj[order], dist[order]
        uniq, starts = np.unique(key, return_index=True)
        bounds = [*starts.tolist(), key.size]
        pairs: dict[tuple[int, int, int, int], tuple[list[float], NDArray[np.intp]]] = {}
        for k, lo, hi in zip(uniq.tolist(), bounds[:-1], bounds[1:], strict=True):
            ka, kb = divmod(int(k), n_keys)
            da, ea = divmod(ka, n_edges)
            db, eb = divmod(kb, n_edges)
            pairs[(da, ea + NODE_EDGES[0], db, eb + NODE_EDGES[0])] = (
                dist[lo:hi].tolist(),
                np.stack([ii[lo:hi], jj[lo:hi]], axis=1),
            )
        return cls(survey, tuple(tuple(g) for g in designs), design_of, pairs, row_beacon, row_xy)

    @property
    def representatives(self) -> list[Beacon]:
        """One beacon of each design: identification tests these."""
        return [self.survey[group[0]] for group in self.designs]

    def design_of(self, beacon_id: str) -> int:
        return self._design_of[beacon_id]

    def beacons_like(self, beacon_id: str) -> tuple[str, ...]:
        """Every surveyed beacon of the same design as ``beacon_id`` (itself included)."""
        return self.designs[self._design_of[beacon_id]]

    def edge_pairs(
        self,
        beacon_a: str,
        edge_a: int,
        beacon_b: str,
        edge_b: int,
        distance_m: float,
        tolerance_m: float,
        *,
        same_beacon: bool = True,
    ) -> list[tuple[str, str, NDArray[np.float64], NDArray[np.float64]]]:
        """Surveyed edge pairs of these designs and edges, ``distance_m`` apart (within tolerance).

        Returns ``(beacon a, beacon b, edge a (E, N), edge b (E, N))`` for every
        beacon of ``beacon_a``'s design and of ``beacon_b``'s (the two edges of one
        beacon as well, when ``same_beacon``).
        """
        key = (self.design_of(beacon_a), edge_a, self.design_of(beacon_b), edge_b)
        found = self._pairs.get(key)
        out: list[tuple[str, str, NDArray[np.float64], NDArray[np.float64]]] = []
        if found is None:
            return out
        dist, rows = found
        lo = bisect.bisect_left(dist, distance_m - tolerance_m)
        hi = bisect.bisect_right(dist, distance_m + tolerance_m)
        ids = self.survey.ids
        for i, j in rows[lo:hi]:
            ba, bb = ids[self._row_beacon[i]], ids[self._row_beacon[j]]
            if ba == bb and not same_beacon:
                continue
            out.append((ba, bb, self._row_xy[i], self._row_xy[j]))
        return out
