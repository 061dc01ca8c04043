"""The grid's nearest neighbours within a gate are the k-d tree's."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from mast.core.neighbours import BearingIndex, PointGrid


def _check(points: np.ndarray, query: np.ndarray, cell: float, gate: float) -> None:
    dist, idx = PointGrid.build(points, cell).query(query, gate)
    ref_d, ref_i = cKDTree(points).query(query, distance_upper_bound=gate)
    np.testing.assert_array_equal(np.isfinite(dist), np.isfinite(ref_d))
    ok = np.isfinite(ref_d)
    np.testing.assert_allclose(dist[ok], ref_d[ok], rtol=0, atol=1e-12)
    assert np.all(idx[~ok] == len(points))
    # the same neighbour, or one exactly as near (a tie)
    same = idx[ok] == ref_i[ok]
    tie = np.hypot(*(points[idx[ok]] - query[ok]).T) == ref_d[ok]
    assert np.all(same | tie)


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(0, 400),
    m=st.integers(0, 300),
    seed=st.integers(0, 2**32 - 1),
    spread=st.sampled_from([0.5, 10.0, 300.0]),
    gate=st.sampled_from([0.01, 0.06, 0.3, 2.0]),
    cell=st.sampled_from([0.05, 0.3, 1.0]),
)
def test_grid_matches_the_kd_tree(
    n: int, m: int, seed: int, spread: float, gate: float, cell: float
) -> None:
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-5e5, 5e5, 2)  # mine-grid coordinates, far from the origin
    points = centre + rng.uniform(-spread, spread, (n, 2))
    query = centre + rng.uniform(-1.2 * spread, 1.2 * spread, (m, 2))
    if n:  # queries on and next to the points themselves
        pick = points[rng.integers(0, n, min(n, 50))]
        query = np.vstack([query, pick, pick + rng.normal(0, gate, pick.shape)])
    _check(points, query, cell, gate)


def test_far_and_non_finite_queries_find_nothing() -> None:
    points = np.array([[0.0, 0.0], [1.0, 0.0]])
    query = np.array([[1e300, 0.0], [-1e300, 5.0], [np.nan, 0.0], [np.inf, 1.0], [0.05, 0.0]])
    dist, idx = PointGrid.build(points, 0.3).query(query, 0.3)
    assert np.all(np.isinf(dist[:4]))
    assert np.all(idx[:4] == 2)
    assert idx[4] == 0
    assert dist[4] == pytest.approx(0.05)


def test_a_wide_extent_keeps_the_grid_small() -> None:
    points = np.array([[0.0, 0.0], [1e5, 1e5]])
    grid = PointGrid.build(points, 0.01)
    assert grid.nx * grid.ny <= 2 * (1 << 20)
    _check(points, points + 0.004, 0.01, 0.01)


def test_an_empty_grid_finds_nothing() -> None:
    dist, idx = PointGrid.build(np.zeros((0, 2)), 0.3).query(np.ones((3, 2)), 0.3)
    assert np.all(np.isinf(dist))
    assert np.all(idx == 0)


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(0, 400),
    m=st.integers(0, 300),
    seed=st.integers(0, 2**32 - 1),
    spread=st.sampled_from([0.5, 10.0, 300.0]),
    gate=st.sampled_from([0.01, 0.06, 0.3, 2.0]),
    offset=st.sampled_from([0.0, 3.0, 50.0]),
)
def test_bearing_index_matches_the_grid_and_the_kd_tree(
    n: int, m: int, seed: int, spread: float, gate: float, offset: float
) -> None:
    # Scan-like sets round the origin (a scanner's returns), some across the -pi / pi
    # cut behind it, some off to one side; queries on and next to the points too.
    rng = np.random.default_rng(seed)
    centre = np.array([offset, rng.uniform(-offset, offset)])
    points = centre + rng.uniform(-spread, spread, (n, 2))
    query = centre + rng.uniform(-1.2 * spread, 1.2 * spread, (m, 2))
    if n:
        pick = points[rng.integers(0, n, min(n, 50))]
        query = np.vstack([query, pick, pick + rng.normal(0, gate, pick.shape), [[0.0, 0.0]]])
    by_bearing = BearingIndex.build(points).query(query, gate)
    by_grid = PointGrid.build(points, max(gate, 0.05)).query(query, gate)
    np.testing.assert_array_equal(by_bearing[0], by_grid[0])
    np.testing.assert_array_equal(by_bearing[1], by_grid[1])
    if n:
        ref_d, _ = cKDTree(points).query(query, distance_upper_bound=gate)
        np.testing.assert_array_equal(np.isfinite(by_bearing[0]), np.isfinite(ref_d))
    else:
        assert np.all(np.isinf(by_bearing[0]))


def test_bearing_index_searches_across_the_cut_behind_the_scanner() -> None:
    # Points just either side of bearing pi (behind the scanner), queried from both sides.
    ang = np.array([np.pi - 1e-4, -np.pi + 1e-4, np.pi, 0.5])
    points = 10.0 * np.column_stack([np.cos(ang), np.sin(ang)])
    query = np.array([[-10.0, 0.001], [-10.0, -0.001], [-10.0, 0.0], [-9.99, 0.0]])
    by_bearing = BearingIndex.build(points).query(query, 0.06)
    by_grid = PointGrid.build(points, 0.3).query(query, 0.06)
    np.testing.assert_array_equal(by_bearing[0], by_grid[0])
    np.testing.assert_array_equal(by_bearing[1], by_grid[1])
    assert np.all(np.isfinite(by_bearing[0]))


def test_a_known_bound_on_the_nearest_gives_the_same_answers() -> None:
    from mast.core._kernels import nearest_by_bearing

    rng = np.random.default_rng(7)
    ang = np.sort(rng.uniform(-2.3, 2.3, 800))
    points = rng.uniform(2.0, 20.0, 800)[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    query = points + rng.normal(0.0, 0.05, points.shape)
    index = BearingIndex.build(points)
    for gate in (0.06, 0.3):
        dist, idx = index.query(query, gate)
        assert np.isfinite(dist).sum() > 100
        # a bound at or above the nearest's distance (inf: nothing known), or the gate
        bound = np.where(np.isfinite(dist), dist + rng.uniform(0.0, 0.1, dist.size), np.inf)
        got = nearest_by_bearing(query, index.points, index.bearing, index.order, gate, bound)
        np.testing.assert_array_equal(got[0], dist)
        np.testing.assert_array_equal(got[1], idx)
