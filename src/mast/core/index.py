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


def _designs(survey: Survey, tol: DesignTolerance) -> list[list[str]]:
    """Beacon ids grouped by design, in survey order: each beacon joins the first group
    whose first beacon it matches (:func:`_same_design`), or starts a new one.

    The groups' first beacons are hashed on a grid of their first two panel
    lengths (cells of the length tolerance), so a beacon is compared only with
    those in the neighbouring cells: a whole mine's survey groups in a fraction
    of a second whether it holds a few designs or thousands.
    """
    beacons = list(survey)
    feats = np.array(
        [np.concatenate([b.template.panel_lengths, b.template.deflections]) for b in beacons]
    ).reshape(-1, 5)
    limit = np.array([tol.length_m] * 3 + [tol.deflection_rad] * 2)
    cell_m = max(tol.length_m, 1e-9)
    with np.errstate(invalid="ignore"):
        cells = np.floor(feats[:, :2] / cell_m)
    cells = np.where(np.isfinite(cells), cells, 2.0**62).astype(np.int64)
    grid: dict[tuple[int, int], list[int]] = {}
    reps: list[NDArray[np.float64]] = []
    designs: list[list[str]] = []
    for beacon, f, (cx, cy) in zip(beacons, feats, cells.tolist(), strict=True):
        near = [
            k
            for dx in (-1, 0, 1)
            for dy in (-1, 0, 1)
            for k in grid.get((cx + dx, cy + dy), ())
            if np.all(np.abs(reps[k] - f) <= limit)
        ]
        if near:
            designs[min(near)].append(beacon.id)
            continue
        grid.setdefault((cx, cy), []).append(len(designs))
        reps.append(f)
        designs.append([beacon.id])
    return designs


def _pairs_within(
    xy: NDArray[np.float64], reach_m: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Every pair of distinct rows of ``xy`` (``i < j``) at most ``reach_m`` apart and
    not coincident, with its distance: a k-d tree, so a whole mine's survey costs
    time in proportion to the pairs within reach, not to the square of its size."""
    from scipy.spatial import cKDTree

    if xy.shape[0] < 2:
        empty = np.zeros(0, dtype=np.intp)
        return empty, empty, np.zeros(0)
    found = cKDTree(xy).query_pairs(reach_m * (1 + 1e-9) + 1e-9, output_type="ndarray")
    ii = found[:, 0].astype(np.intp)
    jj = found[:, 1].astype(np.intp)
    diff = xy[jj] - xy[ii]
    d = np.hypot(diff[:, 0], diff[:, 1])
    keep = (d <= reach_m) & (d > 0)
    return ii[keep], jj[keep], d[keep]


@dataclass(frozen=True, slots=True)
class _Bucket:
    """The surveyed edge pairs of one (design, edge) key pair, sorted by (distance,
    first row, second row)."""

    dist: NDArray[np.float64]
    first: NDArray[np.intp]
    second: NDArray[np.intp]


@dataclass(frozen=True, eq=False)
class SurveyIndex:
    """Designs and edge-pair distances of a survey.

    Every pair of surveyed node edges within
    :attr:`DesignTolerance.max_pair_distance_m` is kept once, under the ordered
    pair of its (design, edge) keys; a key pair's edge pairs are sorted by
    distance the first time a scan asks for them, so building the index costs
    one k-d tree search and one sort of the pairs by key, whatever the number
    of designs.

    Attributes
    ----------
    survey : Survey
    designs : tuple of tuple of str
        Beacon ids grouped by design; the first of each is its representative.
    """

    survey: Survey
    designs: tuple[tuple[str, ...], ...]
    _design_of: dict[str, int] = field(repr=False)
    _row_beacon: NDArray[np.intp] = field(repr=False)
    _row_xy: NDArray[np.float64] = field(repr=False)
    _row_key: NDArray[np.int64] = field(repr=False)
    _ids: tuple[str, ...] = field(repr=False)
    #: Pairs grouped by key pair: rows ``i`` (key <= key of ``j``), ``j``, distance.
    _pair_i: NDArray[np.intp] = field(repr=False)
    _pair_j: NDArray[np.intp] = field(repr=False)
    _pair_d: NDArray[np.float64] = field(repr=False)
    #: Key-pair codes present (sorted) and where each one's pairs start in the arrays.
    _codes: NDArray[np.int64] = field(repr=False)
    _starts: NDArray[np.intp] = field(repr=False)
    _sorted_buckets: dict[int, _Bucket] = field(repr=False, default_factory=dict)

    @classmethod
    def from_survey(
        cls, survey: Survey, tolerance: DesignTolerance = DesignTolerance()
    ) -> SurveyIndex:
        designs = _designs(survey, tolerance)
        design_of = {b: k for k, group in enumerate(designs) for b in group}
        ids = survey.ids
        # One row per (beacon, node edge); its key is (design, edge).
        n_edges = len(NODE_EDGES)
        row_beacon = np.repeat(np.arange(len(ids), dtype=np.intp), n_edges)
        row_edge = np.tile(np.array(NODE_EDGES, dtype=np.intp), len(ids))
        row_xy = np.array(
            [survey[ids[b]].edges[e - 1] for b, e in zip(row_beacon, row_edge, strict=True)]
        ).reshape(-1, 2)
        row_key = np.array([design_of[ids[b]] for b in row_beacon], dtype=np.int64) * n_edges + (
            row_edge - NODE_EDGES[0]
        )
        ii, jj, dist = _pairs_within(row_xy, tolerance.max_pair_distance_m)
        # Each pair once, its lower key first.
        swap = row_key[ii] > row_key[jj]
        ii, jj = np.where(swap, jj, ii), np.where(swap, ii, jj)
        n_keys = max(len(designs) * n_edges, 1)
        code = row_key[ii] * n_keys + row_key[jj]
        order = np.argsort(code, kind="stable")
        code, ii, jj, dist = code[order], ii[order], jj[order], dist[order]
        uniq, starts = np.unique(code, return_index=True)
        starts = np.append(starts, code.size).astype(np.intp)
        return cls(
            survey,
            tuple(tuple(g) for g in designs),
            design_of,
            row_beacon,
            row_xy,
            row_key,
            tuple(ids),
            ii,
            jj,
            dist,
            uniq.astype(np.int64),
            starts,
        )

    @property
    def representatives(self) -> list[Beacon]:
        """One beacon of each design: identification tests these."""
        return [self.survey[group[0]] for group in self.designs]

    def design_of(self, beacon_id: str) -> int:
        return self._design_of[beacon_id]

    def beacons_like(self, beacon_id: str) -> tuple[str, ...]:
        """Every surveyed beacon of the same design as ``beacon_id`` (itself included)."""
        return self.designs[self._design_of[beacon_id]]

    def _bucket(self, ka: int, kb: int) -> _Bucket | None:
        """The pairs of keys ``ka <= kb``, sorted by distance on first use; None if none."""
        n_keys = max(len(self.designs) * len(NODE_EDGES), 1)
        code = ka * n_keys + kb
        at = int(np.searchsorted(self._codes, code))
        if at == self._codes.size or int(self._codes[at]) != code:
            return None
        found = self._sorted_buckets.get(at)
        if found is None:
            lo, hi = int(self._starts[at]), int(self._starts[at + 1])
            i, j, d = self._pair_i[lo:hi], self._pair_j[lo:hi], self._pair_d[lo:hi]
            if ka == kb:  # one key: each pair is looked up either way round
                i, j, d = np.concatenate([i, j]), np.concatenate([j, i]), np.concatenate([d, d])
            order = np.lexsort((j, i, d))
            found = _Bucket(d[order], i[order], j[order])
            self._sorted_buckets[at] = found
        return found

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
        beacon as well, when ``same_beacon``), nearest ``distance_m`` in
        distance order (ties by survey order).
        """
        n_edges = len(NODE_EDGES)
        ka = self.design_of(beacon_a) * n_edges + edge_a - NODE_EDGES[0]
        kb = self.design_of(beacon_b) * n_edges + edge_b - NODE_EDGES[0]
        flip = ka > kb
        b = self._bucket(kb, ka) if flip else self._bucket(ka, kb)
        out: list[tuple[str, str, NDArray[np.float64], NDArray[np.float64]]] = []
        if b is None:
            return out
        lo = int(np.searchsorted(b.dist, distance_m - tolerance_m, side="left"))
        hi = int(np.searchsorted(b.dist, distance_m + tolerance_m, side="right"))
        rows = list(
            zip(
                b.dist[lo:hi].tolist(),
                b.first[lo:hi].tolist(),
                b.second[lo:hi].tolist(),
                strict=True,
            )
        )
        if flip:  # stored the other way round: swap, and restore the (distance, a, b) order
            rows = sorted((d, j, i) for d, i, j in rows)
        ids = self._ids
        for _, i, j in rows:
            ba, bb = ids[self._row_beacon[i]], ids[self._row_beacon[j]]
            if ba == bb and not same_beacon:
                continue
            out.append((ba, bb, self._row_xy[i], self._row_xy[j]))
        return out
