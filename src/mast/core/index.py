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

import functools
import math
from dataclasses import dataclass, field
from typing import Any

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


def _key_width(designs: int) -> int:
    """How many (design, edge) keys there are: the base of :func:`_key_pair_code`."""
    return max(designs * len(NODE_EDGES), 1)


def _no_pairs() -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    empty = np.zeros(0, dtype=np.intp)
    return empty, empty


def _in_triu_order(
    a: NDArray[np.intp], b: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Node pairs ``(a, b)`` as ``(i, j)``, ``i < j``, in the order of ``numpy.triu_indices``."""
    i, j = np.minimum(a, b), np.maximum(a, b)
    at = np.lexsort((j, i))
    return i[at].astype(np.intp), j[at].astype(np.intp)


def _key_pair_code(ka: Any, kb: Any, designs: int) -> Any:
    """One number for the ordered pair of (design, edge) keys ``(ka, kb)`` (ints or arrays)."""
    return ka * _key_width(designs) + kb


def _first_at_least(
    values: NDArray[np.float64],
    start: NDArray[np.intp],
    stop: NDArray[np.intp],
    bound: NDArray[np.float64],
    *,
    strict: bool,
) -> NDArray[np.intp]:
    """In each sorted slice ``values[start:stop]``, the position of the first value at
    least ``bound`` (above it, if ``strict``), or ``stop``: ``start +
    searchsorted(values[start:stop], bound, side="right" if strict else "left")`` for
    every slice (compiled: :func:`mast.core._kernels.first_at_least`;
    :func:`_first_at_least_reference` in numpy, the tests compare the two)."""
    from mast.core._kernels import first_at_least

    shape = np.shape(start)
    found: NDArray[np.intp] = first_at_least(
        np.ascontiguousarray(values, dtype=float),
        np.ascontiguousarray(start, dtype=np.intp).ravel(),
        np.ascontiguousarray(stop, dtype=np.intp).ravel(),
        np.ascontiguousarray(np.broadcast_to(bound, shape), dtype=float).ravel(),
        strict,
    )
    return found.reshape(shape)


def _first_at_least_reference(
    values: NDArray[np.float64],
    start: NDArray[np.intp],
    stop: NDArray[np.intp],
    bound: NDArray[np.float64],
    *,
    strict: bool,
) -> NDArray[np.intp]:
    """:func:`_first_at_least` for every slice at once in numpy."""
    lo, hi = start.astype(np.intp), stop.astype(np.intp)
    last = max(values.size - 1, 0)
    while True:
        open_ = lo < hi
        if not np.any(open_):
            return lo
        mid = (lo + hi) // 2
        v = values[np.minimum(mid, last)]
        below = (v <= bound) if strict else (v < bound)
        lo = np.where(open_ & below, mid + 1, lo)
        hi = np.where(open_ & ~below, mid, hi)


@dataclass(frozen=True, eq=False)
class SurveyIndex:
    """Designs and edge-pair distances of a survey.

    Every pair of surveyed node edges within reach (twice the scanner's range,
    at most :attr:`DesignTolerance.max_pair_distance_m`) is kept once, under
    the ordered pair of its (design, edge) keys (both ways round when the keys
    are one), sorted by key pair, distance and rows: building the index costs
    one k-d tree search and two sorts of the pairs, whatever the number of
    designs, and a scan's look-up is a bisection.

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
    _number: dict[str, int] = field(repr=False)
    #: Mine-frame angle of each beacon's panels P1-P3 (from the lower- to the higher-numbered edge).
    _panel_angle: NDArray[np.float64] = field(repr=False)
    #: Pairs sorted by key pair and distance: rows ``i`` (key <= key of ``j``), ``j``, distance.
    _pair_i: NDArray[np.intp] = field(repr=False)
    _pair_j: NDArray[np.intp] = field(repr=False)
    _pair_d: NDArray[np.float64] = field(repr=False)
    #: Key-pair codes present (sorted) and where each one's pairs start in the arrays.
    _codes: NDArray[np.int64] = field(repr=False)
    _starts: NDArray[np.intp] = field(repr=False)

    @classmethod
    def from_survey(
        cls,
        survey: Survey,
        tolerance: DesignTolerance = DesignTolerance(),
        *,
        reach_m: float = math.inf,
    ) -> SurveyIndex:
        """Index ``survey``; edge pairs farther apart than ``reach_m`` (twice the
        scanner's longest range: no scan sees both) or than the tolerance's
        ``max_pair_distance_m`` are left out."""
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
        ii, jj, dist = _pairs_within(row_xy, min(reach_m, tolerance.max_pair_distance_m))
        # Each pair once, its lower key first; a pair of one key both ways round.
        swap = row_key[ii] > row_key[jj]
        ii, jj = np.where(swap, jj, ii), np.where(swap, ii, jj)
        one = row_key[ii] == row_key[jj]
        ii, jj = np.concatenate([ii, jj[one]]), np.concatenate([jj, ii[one]])
        dist = np.concatenate([dist, dist[one]])
        code = _key_pair_code(row_key[ii], row_key[jj], len(designs))
        # By key pair, then distance, then rows: the rows sort only the pairs at one
        # distance to the last bit (look-alikes' own two edges, symmetric layouts).
        order = np.argsort(dist, kind="stable")
        order = order[np.argsort(code[order], kind="stable")]
        c, d = code[order], dist[order]
        same = (c[1:] == c[:-1]) & (d[1:] == d[:-1])
        tied = np.flatnonzero(np.concatenate([same, [False]]) | np.concatenate([[False], same]))
        if tied.size:
            sub = order[tied]
            order[tied] = sub[np.lexsort((jj[sub], ii[sub], dist[sub], code[sub]))]
        code, ii, jj, dist = code[order], ii[order], jj[order], dist[order]
        uniq, starts = np.unique(code, return_index=True)
        starts = np.append(starts, code.size).astype(np.intp)
        edges = np.array([b.edges for b in survey]).reshape(-1, 4, 2)
        steps = np.diff(edges, axis=1)
        panel_angle = np.arctan2(steps[..., 1], steps[..., 0])
        return cls(
            survey,
            tuple(tuple(g) for g in designs),
            design_of,
            row_beacon,
            row_xy,
            row_key,
            tuple(ids),
            {bid: k for k, bid in enumerate(ids)},
            panel_angle,
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

    @functools.cached_property
    def middle_panels(self) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """Per design (by position in :attr:`designs`), its middle panel's length (edge 2
        to edge 3 of its representative) and the key of its edge 2 (:meth:`node_key`)."""
        reps = self.representatives
        lengths = np.array([float(np.hypot(*(b.edges[2] - b.edges[1]))) for b in reps])
        keys = np.array([self.node_key(b.id, 2) for b in reps], dtype=np.int64)
        lengths.flags.writeable = False
        keys.flags.writeable = False
        return lengths, keys

    def design_of(self, beacon_id: str) -> int:
        return self._design_of[beacon_id]

    def beacons_like(self, beacon_id: str) -> tuple[str, ...]:
        """Every surveyed beacon of the same design as ``beacon_id`` (itself included)."""
        return self.designs[self._design_of[beacon_id]]

    def node_key(self, beacon_id: str, edge: int) -> int:
        """Key of a node edge (2 or 3) of a beacon of ``beacon_id``'s design."""
        return self.design_of(beacon_id) * len(NODE_EDGES) + edge - NODE_EDGES[0]

    def _buckets_of(
        self, keys_a: NDArray[np.int64], keys_b: NDArray[np.int64]
    ) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """For each pair of keys (either order), the position of its bucket in
        ``_codes`` (or of a neighbour) and whether it has one. The index must hold a
        pair."""
        code = _key_pair_code(
            np.minimum(keys_a, keys_b), np.maximum(keys_a, keys_b), len(self.designs)
        )
        at = np.minimum(np.searchsorted(self._codes, code), self._codes.size - 1)
        return at, np.asarray(self._codes[at] == code)

    def have_pairs(self, keys_a: NDArray[np.int64], keys_b: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Whether any surveyed edge pair within reach has each pair of keys (either order):
        a scan's node pairs of designs never surveyed near each other need no look-up."""
        if self._codes.size == 0:
            return np.zeros(np.broadcast(keys_a, keys_b).shape, dtype=bool)
        return self._buckets_of(keys_a, keys_b)[1]

    @functools.cached_property
    def key_pairs(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """The pairs of keys ``(low, high)``, ``low <= high``, that have a bucket: the
        (design, edge) pairs surveyed within reach of each other."""
        width = _key_width(len(self.designs))
        low, high = np.divmod(self._codes, width)
        return low.astype(np.int64), high.astype(np.int64)

    @functools.cached_property
    def key_pair_spans(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per pair of keys of :attr:`key_pairs`, the shortest and the longest distance
        of its surveyed edge pairs."""
        if self._codes.size == 0:
            return np.zeros(0), np.zeros(0)
        starts = self._starts
        return self._pair_d[starts[:-1]], self._pair_d[starts[1:] - 1]

    def pairs_to_look_up(
        self,
        keys: NDArray[np.int64],
        places: NDArray[np.float64] | None = None,
        slack_m: NDArray[np.float64] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """The pairs ``i < j`` of ``keys`` (a scan's node keys) whose keys have a bucket
        (:meth:`have_pairs`), in the order of ``numpy.triu_indices``: found from the
        buckets of the keys present, so that a survey of many designs, whose every corner
        is read as a node of many of them, costs the pairs that can be looked up, not
        every pair of nodes.

        With ``places`` (each node's, shape (n, 2)) and ``slack_m`` (each node's share of
        a tolerance), only the pairs ``places`` apart within ``slack_m[i] + slack_m[j]``
        (a hair more) of some distance their bucket's surveyed pairs span."""
        from mast.core._kernels import key_pair_nodes

        keys = np.asarray(keys, dtype=np.int64)
        grouped = self._keys_present(keys)
        if grouped is None:
            return _no_pairs()
        order, first, both = grouped
        low, high = (k[both] for k in self.key_pairs)
        if places is not None and slack_m is not None:
            span_lo, span_hi = (np.ascontiguousarray(span[both]) for span in self.key_pair_spans)
            xy = np.ascontiguousarray(places, dtype=float).reshape(-1, 2)
            slack = np.ascontiguousarray(slack_m, dtype=float)
        else:
            span_lo = span_hi = np.zeros(low.size)
            xy, slack = np.zeros((keys.size, 2)), np.full(keys.size, np.inf)
        return _in_triu_order(*key_pair_nodes(order, first, low, high, xy, slack, span_lo, span_hi))

    def _keys_present(
        self, keys: NDArray[np.int64]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]] | None:
        """The nodes grouped by key (``order[first[k]:first[k + 1]]`` hold key ``k``) and
        which of :attr:`key_pairs` have both keys among ``keys``; None when no pair can."""
        if self._codes.size == 0 or keys.size < 2:
            return None
        width = _key_width(len(self.designs))
        low, high = self.key_pairs
        present = np.zeros(width, dtype=bool)
        present[keys] = True
        order = np.argsort(keys, kind="stable").astype(np.intp)
        first = np.searchsorted(keys[order], np.arange(width + 1)).astype(np.intp)
        return order, first, present[low] & present[high]

    def _pairs_to_look_up_reference(
        self,
        keys: NDArray[np.int64],
        places: NDArray[np.float64] | None = None,
        slack_m: NDArray[np.float64] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """:meth:`pairs_to_look_up` in numpy (the tests compare the two)."""
        keys = np.asarray(keys, dtype=np.int64)
        grouped = self._keys_present(keys)
        if grouped is None:
            return _no_pairs()
        order, first, both = grouped
        low, high = (k[both] for k in self.key_pairs)
        size_a = first[low + 1] - first[low]
        size_b = first[high + 1] - first[high]
        # Every node of the low key with every node of the high key, bucket by bucket.
        per = size_a * size_b
        bucket = np.repeat(np.arange(low.size), per)
        offset = np.arange(bucket.size) - np.repeat(np.cumsum(per) - per, per)
        a = order[first[low[bucket]] + offset // size_b[bucket]]
        b = order[first[high[bucket]] + offset % size_b[bucket]]
        keep = (low[bucket] != high[bucket]) | (a < b)
        if places is not None and slack_m is not None:
            span_lo, span_hi = (span[both] for span in self.key_pair_spans)
            d = np.hypot(places[b, 0] - places[a, 0], places[b, 1] - places[a, 1])
            tol = (slack_m[a] + slack_m[b]) * (1.0 + 1e-9) + 1e-9
            keep &= (d + tol >= span_lo[bucket]) & (d - tol <= span_hi[bucket])
        return _in_triu_order(a[keep], b[keep])

    def pair_counts(
        self,
        keys_a: NDArray[np.int64],
        keys_b: NDArray[np.int64],
        distance_m: NDArray[np.float64],
        tolerance_m: NDArray[np.float64],
    ) -> NDArray[np.intp]:
        """For each pair of keys (either order), how many surveyed edge pairs lie
        ``distance_m`` apart within ``tolerance_m``: the length of what :meth:`pair_rows`
        returns, for many at once (a binary search in every bucket side by side)."""
        lo, hi = self._spans(keys_a, keys_b, distance_m, tolerance_m)
        return hi - lo

    def _spans(
        self,
        keys_a: NDArray[np.int64],
        keys_b: NDArray[np.int64],
        distance_m: NDArray[np.float64],
        tolerance_m: NDArray[np.float64],
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """For each pair of keys (either order), where the surveyed edge pairs
        ``distance_m`` apart within ``tolerance_m`` start and stop in the sorted pairs
        (the same place where there are none: a negative tolerance holds none). A bound
        that is not a number is past every distance, as ``numpy.searchsorted`` has it."""
        shape = np.shape(keys_a)
        if self._codes.size == 0 or math.prod(shape) == 0:
            return np.zeros(shape, dtype=np.intp), np.zeros(shape, dtype=np.intp)
        at, found = self._buckets_of(keys_a, keys_b)
        start, stop = self._starts[at], np.where(found, self._starts[at + 1], self._starts[at])
        with np.errstate(invalid="ignore"):  # inf - inf: a bound that is not a number
            bounds = (distance_m - tolerance_m, distance_m + tolerance_m)
        below, above = (np.where(np.isnan(bound), math.inf, bound) for bound in bounds)
        lo = _first_at_least(self._pair_d, start, stop, below, strict=False)
        hi = _first_at_least(self._pair_d, start, stop, above, strict=True)
        return lo, np.maximum(hi, lo)

    def pair_rows(
        self,
        beacon_a: str,
        edge_a: int,
        beacon_b: str,
        edge_b: int,
        distance_m: float,
        tolerance_m: float,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Rows (see :meth:`row_xy`) of the surveyed edge pairs of these designs and edges,
        ``distance_m`` apart within ``tolerance_m``, in (distance, first row, second row)
        order; the two edges of one beacon are among them (:meth:`pairs_rows` for one)."""
        keys = np.array([self.node_key(beacon_a, edge_a)], dtype=np.int64)
        _, rows_a, rows_b = self.pairs_rows(
            keys,
            np.array([self.node_key(beacon_b, edge_b)], dtype=np.int64),
            np.array([distance_m]),
            np.array([tolerance_m]),
        )
        return rows_a, rows_b

    def pairs_rows(
        self,
        keys_a: NDArray[np.int64],
        keys_b: NDArray[np.int64],
        distance_m: NDArray[np.float64],
        tolerance_m: NDArray[np.float64],
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
        """:meth:`pair_rows` for many pairs of keys (:meth:`node_key`) at once:
        ``(which, rows_a, rows_b)``, one entry per surveyed edge pair found, by pair
        (``which``, its place in the arguments), then by (distance, first row, second
        row); a binary search in every bucket side by side."""
        keys_a = np.asarray(keys_a, dtype=np.int64).ravel()
        keys_b = np.asarray(keys_b, dtype=np.int64).ravel()
        lo, hi = self._spans(keys_a, keys_b, distance_m, tolerance_m)
        count = hi - lo
        which = np.repeat(np.arange(keys_a.size, dtype=np.intp), count)
        pos = lo[which] + (np.arange(which.size) - np.repeat(np.cumsum(count) - count, count))
        first, second = self._pair_i[pos], self._pair_j[pos]
        flip = (keys_a > keys_b)[which]
        if not flip.any():
            return which, first, second
        # stored the other way round: swap, and restore the (distance, a, b) order
        rows_a, rows_b = np.where(flip, second, first), np.where(flip, first, second)
        order = np.lexsort((rows_b, rows_a, self._pair_d[pos], which))
        return which, rows_a[order], rows_b[order]

    def row_xy(self, rows: NDArray[np.intp]) -> NDArray[np.float64]:
        """(E, N) of the node edges at ``rows``."""
        return self._row_xy[rows]

    def edge_xy(self, numbers: NDArray[np.intp], edges: NDArray[np.intp]) -> NDArray[np.float64]:
        """(E, N) of node edge ``edges[k]`` (2 or 3) of the beacon at survey position
        ``numbers[k]``."""
        rows = np.asarray(numbers) * len(NODE_EDGES) + np.asarray(edges) - NODE_EDGES[0]
        return self._row_xy[rows]

    def row_beacon(self, rows: NDArray[np.intp]) -> NDArray[np.intp]:
        """Survey position of the beacon of each of ``rows``."""
        return self._row_beacon[rows]

    def number(self, beacon_id: str) -> int:
        """Survey position (from 0) of the beacon ``beacon_id``."""
        return self._number[beacon_id]

    def beacon_id(self, number: int) -> str:
        """Id of the survey's ``number``-th beacon (from 0)."""
        return self._ids[number]

    def panel_angles(self, numbers: NDArray[np.intp]) -> NDArray[np.float64]:
        """(k, 3) mine-frame angles of panels P1-P3 of the beacons at these survey positions."""
        return self._panel_angle[numbers]
