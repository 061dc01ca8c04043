"""The survey index: the same look-ups as a walk over every pair, in time linear in the pairs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from mast.core.beacon import Beacon, Survey
from mast.core.index import NODE_EDGES, DesignTolerance, SurveyIndex, _same_design
from mast.sim.design import random_design


def _survey(n: int, designs: int, seed: int = 0, spacing_m: float = 12.0) -> Survey:
    rng = np.random.default_rng(seed)
    kinds = [random_design(rng) for _ in range(designs)]
    beacons = []
    for k in range(n):
        turn = rng.uniform(0, 2 * math.pi)
        rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
        at = np.array([(k % 30) * spacing_m, (k // 30) * spacing_m]) + rng.normal(0, 1, 2)
        beacons.append(Beacon(f"B{k}", kinds[k % designs].edges_local @ rot.T + at))
    return Survey(beacons)


def _designs_by_walk(survey: Survey, tol: DesignTolerance) -> list[list[str]]:
    groups: list[list[str]] = []
    for b in survey:
        for g in groups:
            if _same_design(survey[g[0]], b, tol):
                g.append(b.id)
                break
        else:
            groups.append([b.id])
    return groups


def _pairs_by_walk(
    index: SurveyIndex,
    a: str,
    ea: int,
    b: str,
    eb: int,
    d: float,
    tol: float,
    same: bool,
    reach: float = DesignTolerance().max_pair_distance_m,
) -> list[tuple[str, str]]:
    """Every surveyed edge pair of these designs and edges at that distance, sorted as the
    index sorts them: (distance, first row, second row)."""
    survey = index.survey
    ids = survey.ids
    rows = [(i, bid, e) for i, bid in enumerate(ids) for e in NODE_EDGES]
    found = []
    for ri, (_, ba, e1) in enumerate(rows):
        if index.design_of(ba) != index.design_of(a) or e1 != ea:
            continue
        for rj, (_, bb, e2) in enumerate(rows):
            if index.design_of(bb) != index.design_of(b) or e2 != eb:
                continue
            diff = survey[bb].edges[e2 - 1] - survey[ba].edges[e1 - 1]
            dist = float(np.hypot(diff[0], diff[1]))
            if dist == 0 or dist > reach:
                continue
            if abs(dist - d) <= tol and (same or ba != bb):
                found.append((dist, ri, rj, ba, bb))
    return [(x[3], x[4]) for x in sorted(found)]


@pytest.mark.parametrize(("designs", "reach"), [(3, math.inf), (40, math.inf), (3, 25.0)])
def test_look_ups_match_a_walk_over_every_pair(designs: int, reach: float) -> None:
    survey = _survey(120, designs)
    index = SurveyIndex.from_survey(survey, reach_m=reach)
    assert [list(g) for g in index.designs] == _designs_by_walk(survey, DesignTolerance())
    rng = np.random.default_rng(1)
    ids = survey.ids
    for _ in range(60):
        a, b = ids[int(rng.integers(len(ids)))], ids[int(rng.integers(len(ids)))]
        ea, eb = (int(x) for x in rng.choice(NODE_EDGES, 2))
        d = float(rng.uniform(0.2, 60.0))
        tol = float(rng.choice([0.05, 2.0, 10.0]))
        same = bool(rng.integers(2))
        ra, rb = index.pair_rows(a, ea, b, eb, d, tol)
        both = [
            (index.beacon_id(int(i)), index.beacon_id(int(j)))
            for i, j in zip(index.row_beacon(ra), index.row_beacon(rb), strict=True)
        ]
        assert_allclose(np.hypot(*(index.row_xy(rb) - index.row_xy(ra)).T), d, atol=tol)
        got = [(x, y) for x, y in both if same or x != y]
        limit = min(reach, DesignTolerance().max_pair_distance_m)
        assert got == _pairs_by_walk(index, a, ea, b, eb, d, tol, same, limit)


def _random_look_ups(  # type: ignore[no-untyped-def]
    index: SurveyIndex, rng: np.random.Generator, n: int
):
    """``n`` random look-ups: pairs of beacons and of node edges, distances (half of them
    near surveyed ones, so that windows open and close on pairs) and tolerances, and the
    pairs' keys."""
    ids = index.survey.ids
    picks = [(ids[int(rng.integers(len(ids)))], ids[int(rng.integers(len(ids)))]) for _ in range(n)]
    edges = rng.choice(NODE_EDGES, size=(n, 2))
    d = np.where(rng.random(n) < 0.5, rng.uniform(0.2, 60.0, n), 12.0 * rng.integers(1, 5, n))
    tol = rng.choice([0.0, 0.05, 2.0, 10.0], size=n)
    keys_a = np.array(
        [index.node_key(a, int(e)) for (a, _), e in zip(picks, edges[:, 0], strict=True)]
    )
    keys_b = np.array(
        [index.node_key(b, int(e)) for (_, b), e in zip(picks, edges[:, 1], strict=True)]
    )
    return picks, edges, d, tol, keys_a, keys_b


@pytest.mark.parametrize("designs", [1, 3, 40])
def test_pair_counts_are_the_lengths_of_pair_rows(designs: int) -> None:
    index = SurveyIndex.from_survey(_survey(90, designs, seed=designs))
    picks, edges, d, tol, keys_a, keys_b = _random_look_ups(
        index, np.random.default_rng(designs), 400
    )
    got = index.pair_counts(keys_a, keys_b, d, tol)
    want = [
        index.pair_rows(a, int(ea), b, int(eb), float(dk), float(tk))[0].size
        for (a, b), (ea, eb), dk, tk in zip(picks, edges, d, tol, strict=True)
    ]
    assert got.tolist() == want
    assert sum(want) > 0
    assert want.count(0) > 0
    # and the walk over every pair of rows, where no distance is on a window's edge
    clear = [k for k in range(len(picks)) if tol[k] > 0 and d[k] % 12.0 != 0][:120]
    walked = []
    for k in clear:
        (a, b), (ea, eb) = picks[k], edges[k]
        walked.append(len(_pairs_by_walk(index, a, int(ea), b, int(eb), d[k], tol[k], True)))
    assert got[clear].tolist() == walked
    assert sum(walked) > 0


def test_look_ups_of_odd_windows_hold_nothing_or_what_searchsorted_gives() -> None:
    """A negative tolerance holds no pair (not a negative count); a window whose bound is
    not a number is past every distance at that bound, as ``numpy.searchsorted`` has it."""
    index = SurveyIndex.from_survey(_survey(40, 1, seed=3))
    a = index.survey.ids[0]
    key = np.array([index.node_key(a, 2)] * 5, dtype=np.int64)
    d = np.array([12.0, 12.0, math.inf, -math.inf, math.nan])
    tol = np.array([-1.0, 1.0, math.inf, math.inf, 1.0])
    counts = index.pair_counts(key, key, d, tol)
    which, _, _ = index.pairs_rows(key, key, d, tol)
    assert counts[0] == 0
    assert counts[1] > 0
    assert counts[2] == 0  # from NaN (inf - inf) to inf: none
    assert counts[3] == index.pair_counts(key[:1], key[:1], np.array([30.0]), np.array([1e9]))[0]
    assert counts[4] == 0
    assert np.bincount(which, minlength=5).tolist() == counts.tolist()


def test_first_at_least_matches_the_numpy_reference() -> None:
    """The compiled search of many sorted slices gives the numpy one's positions: bounds
    below, inside, above and on values (ties either side), empty slices, NaN bounds."""
    from mast.core.index import _first_at_least, _first_at_least_reference

    rng = np.random.default_rng(4)
    values = np.concatenate([np.sort(rng.uniform(0, 50, size=k)) for k in (0, 1, 7, 200, 33)])
    values = np.concatenate([values, np.repeat([5.0, 6.0], 4)])
    edges = np.concatenate([[0], np.cumsum([0, 1, 7, 200, 33, 8])])
    for _ in range(50):
        slab = rng.integers(0, edges.size - 1, size=300)
        start, stop = edges[slab], edges[slab + 1]
        bound = rng.choice([rng.uniform(-5, 55), 5.0, 6.0, math.nan, -math.inf, math.inf], size=300)
        bound = np.where(rng.random(300) < 0.3, values[np.minimum(start, values.size - 1)], bound)
        for strict in (False, True):
            got = _first_at_least(values, start, stop, bound, strict=strict)
            want = _first_at_least_reference(values, start, stop, bound, strict=strict)
            np.testing.assert_array_equal(got, want)
            # any shape of slices, and one bound for all
            got = _first_at_least(
                values, start.reshape(20, 15), stop.reshape(20, 15), bound[0], strict=strict
            )
            want = _first_at_least_reference(
                values, start.reshape(20, 15), stop.reshape(20, 15), bound[0], strict=strict
            )
            np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("designs", [1, 3, 40])
def test_pairs_to_look_up_match_the_reference_and_a_walk(designs: int) -> None:
    """The compiled pair walk gives the numpy reference's pairs in its order, with and
    without the distance filter; unfiltered, they are every pair ``i < j`` whose keys have
    a bucket; filtered, those whose distance is within the slack of their bucket's span."""
    survey = _survey(90, designs, seed=designs)
    index = SurveyIndex.from_survey(survey)
    rng = np.random.default_rng(designs + 7)
    ids = survey.ids
    n = 60
    keys = np.array(
        [
            index.node_key(ids[int(rng.integers(len(ids)))], int(rng.choice(NODE_EDGES)))
            for _ in range(n)
        ],
        dtype=np.int64,
    )
    places = rng.uniform(0.0, 60.0, size=(n, 2))
    slack = rng.choice([0.0, 0.05, 1.0], size=n)
    everything = np.triu_indices(n, 1)
    wanted = index.have_pairs(keys[everything[0]], keys[everything[1]])
    plain = index.pairs_to_look_up(keys)
    assert [x.tolist() for x in plain] == [
        x.tolist() for x in index._pairs_to_look_up_reference(keys)
    ]
    assert plain[0].tolist() == everything[0][wanted].tolist()
    assert plain[1].tolist() == everything[1][wanted].tolist()
    got = index.pairs_to_look_up(keys, places, slack)
    ref = index._pairs_to_look_up_reference(keys, places, slack)
    assert [x.tolist() for x in got] == [x.tolist() for x in ref]
    low, high = index.key_pairs
    span_lo, span_hi = index.key_pair_spans
    bucket = {(int(a), int(b)): q for q, (a, b) in enumerate(zip(low, high, strict=True))}
    kept = set(zip(got[0].tolist(), got[1].tolist(), strict=True))
    assert kept <= set(zip(plain[0].tolist(), plain[1].tolist(), strict=True))
    for i, j in zip(plain[0].tolist(), plain[1].tolist(), strict=True):
        q = bucket[(min(keys[i], keys[j]), max(keys[i], keys[j]))]
        d = float(np.hypot(*(places[j] - places[i])))
        tol = slack[i] + slack[j]
        inside = span_lo[q] - tol + 1e-6 <= d <= span_hi[q] + tol - 1e-6
        outside = d < span_lo[q] - tol - 1e-6 or d > span_hi[q] + tol + 1e-6
        assert not (inside and (i, j) not in kept)
        assert not (outside and (i, j) in kept)
    assert 0 < len(kept) < plain[0].size


@pytest.mark.parametrize("designs", [1, 3, 40])
def test_pairs_rows_are_each_pairs_rows_in_turn(designs: int) -> None:
    """The look-up of many pairs of keys at once gives each pair's rows (keys either way
    round), in its order, one pair after another."""
    index = SurveyIndex.from_survey(_survey(90, designs, seed=designs))
    picks, edges, d, tol, keys_a, keys_b = _random_look_ups(
        index, np.random.default_rng(designs + 10), 300
    )
    which, rows_a, rows_b = index.pairs_rows(keys_a, keys_b, d, tol)
    want_which, want_a, want_b = [], [], []
    for k, ((a, b), (ea, eb), dk, tk) in enumerate(zip(picks, edges, d, tol, strict=True)):
        ra, rb = index.pair_rows(a, int(ea), b, int(eb), float(dk), float(tk))
        want_which += [k] * ra.size
        want_a += ra.tolist()
        want_b += rb.tolist()
    assert which.tolist() == want_which
    assert rows_a.tolist() == want_a
    assert rows_b.tolist() == want_b
    assert len(set(want_which)) > 10
    # each pair's rows, keys stored the other way round or not, in the walk's order
    checked = {True: 0, False: 0}
    for k in sorted(set(want_which)):
        if tol[k] == 0 or d[k] % 12.0 == 0:
            continue  # a distance on the window's edge may round either way
        here = which == k
        got = [
            (index.beacon_id(int(i)), index.beacon_id(int(j)))
            for i, j in zip(
                index.row_beacon(rows_a[here]), index.row_beacon(rows_b[here]), strict=True
            )
        ]
        (a, b), (ea, eb) = picks[k], edges[k]
        assert got == _pairs_by_walk(
            index, a, int(ea), b, int(eb), float(d[k]), float(tol[k]), True
        )
        checked[bool(keys_a[k] > keys_b[k])] += 1
    assert checked[True] > 0
    assert checked[False] > 0
