"""A beacon fitted whole: placed by its design, its lines fitted to every point on its
panels, its edges' joint covariance honest over many draws."""

from __future__ import annotations

import itertools
import math

import numpy as np

from mast.cloud.beacon_fit import edges_covariance, edges_from_lines, fit_beacon
from mast.core.quantiles import chi2_isf

#: A design with a short outer panel at a shallow angle (the georef benchmark's misses).
SHAPE = np.array([[0.0, 0.0], [0.35, 0.18], [0.95, 0.2], [1.12, 0.02]])
HEIGHTS = (1.0, 1.5)


def _cloud(rng: np.random.Generator, edges: np.ndarray, noise: float, density: float) -> np.ndarray:
    """Points on the three panels (vertical, between ``HEIGHTS``) and rough rock behind
    them, in a drift's grid 70 km from the origin."""
    out = []
    for a, b in itertools.pairwise(edges):
        length = math.dist(a, b)
        n = int(density * length * (HEIGHTS[1] - HEIGHTS[0]))
        t = rng.uniform(0, 1, n)
        z = rng.uniform(*HEIGHTS, n)
        d = (b - a) / length
        xy = a + t[:, None] * (b - a) + rng.normal(0, noise, n)[:, None] * np.array([-d[1], d[0]])
        out.append(np.column_stack([xy, z]))
    # rough rock behind the beacon, its free ends on brackets off it, in the design's
    # frame and turned with the beacon
    wall = np.column_stack([rng.uniform(-0.5, 1.6, 4000), rng.normal(-0.06, 0.02, 4000)])
    u, v = SHAPE[3] - SHAPE[0], edges[3] - edges[0]
    theta = math.atan2(v[1], v[0]) - math.atan2(u[1], u[0])
    c, s = math.cos(theta), math.sin(theta)
    wall = (wall - SHAPE[0]) @ np.array([[c, -s], [s, c]]).T + edges[0]
    wall = np.column_stack([wall, rng.uniform(0.5, 2.0, 4000)])
    return np.vstack([*out, wall])


def _placed(theta: float, at: np.ndarray) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.asarray(SHAPE @ np.array([[c, -s], [s, c]]).T + at)


def test_the_edges_are_where_the_beacon_is_and_their_covariance_covers() -> None:
    rng = np.random.default_rng(4)
    at = np.array([452_310.0, 7_101_220.0])
    limit = chi2_isf(0.05, 4)
    inside = 0
    draws = 150
    for _ in range(draws):
        truth = _placed(rng.uniform(-math.pi, math.pi), at)
        xyz = _cloud(rng, truth, 0.01, 2000.0)
        # a start a few centimetres and a degree or two off, as a detection gives it
        c, s = math.cos(0.03), math.sin(0.03)
        start = (
            (truth - truth.mean(axis=0)) @ np.array([[c, -s], [s, c]]).T
            + truth.mean(axis=0)
            + rng.normal(0, 0.02, 2)
        )
        fit = fit_beacon(xyz, SHAPE + 1000.0, start, HEIGHTS, 0.01)
        assert fit is not None
        assert np.max(np.hypot(*(fit.edges - truth).T)) < 0.02
        d = (fit.edges[1:3] - truth[1:3]).reshape(-1)
        cov = fit.edge_covariance((2, 3))
        inside += float(d @ np.linalg.solve(cov, d)) <= limit
        # e2 and e3 share the middle panel: their covariance is not block diagonal
        assert np.max(np.abs(cov[:2, 2:])) > 1e-3 * math.sqrt(cov[0, 0] * cov[2, 2])
    assert abs(inside / draws - 0.95) < 0.05, inside / draws


def test_a_beacon_with_a_panel_unseen_is_not_fitted() -> None:
    rng = np.random.default_rng(5)
    truth = _placed(0.4, np.array([100.0, 200.0]))
    xyz = _cloud(rng, truth, 0.01, 2000.0)
    # P3's points gone (occluded): no line to place e3 on
    d = (truth[3] - truth[2]) / math.dist(truth[3], truth[2])
    along = (xyz[:, :2] - truth[2]) @ d
    across = (xyz[:, :2] - truth[2]) @ np.array([-d[1], d[0]])
    gone = (along > 0) & (np.abs(across) < 0.05) & (xyz[:, 2] > 0.9)
    assert fit_beacon(xyz[~gone], SHAPE, truth, HEIGHTS, 0.01) is None
    assert fit_beacon(xyz, SHAPE, truth, HEIGHTS, 0.01) is not None


def test_the_edges_covariance_is_the_lines_propagated() -> None:
    """Against a Monte Carlo of the lines themselves."""
    rng = np.random.default_rng(6)
    lines = np.array([[0.3, 0.1], [1.4, 0.25], [2.3, -0.05]])
    covs = [np.diag([1e-4, 1e-6]), np.diag([4e-5, 2e-6]), np.diag([2e-4, 1e-6])]
    lengths = np.array([0.4, 0.6, 0.2])
    outward = np.array([[1.0, 0.0], [0.0, 1.0]])
    cov = edges_covariance(lines, covs, lengths, outward)
    draws = np.array(
        [
            edges_from_lines(
                lines + np.array([rng.multivariate_normal(np.zeros(2), c) for c in covs]),
                lengths,
                outward,
            )
            for _ in range(4000)
        ]
    )
    # in units of the two coordinates' standard deviations (correlations to 0.1)
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    np.testing.assert_allclose(np.cov(draws.T) / scale, cov / scale, rtol=0, atol=0.1)


def test_a_placement_that_slides_away_from_its_start_is_refused() -> None:
    """Started 30 cm along the wall from the beacon, the shape would have to slide onto
    it (or onto rock): refused, not taken for the beacon."""
    rng = np.random.default_rng(8)
    truth = _placed(0.2, np.array([10.0, 20.0]))
    xyz = _cloud(rng, truth, 0.01, 2000.0)
    assert fit_beacon(xyz, SHAPE, truth + np.array([0.03, -0.02]), HEIGHTS, 0.01) is not None
    away = truth + 0.3 * (truth[3] - truth[0]) / math.dist(truth[3], truth[0])
    assert fit_beacon(xyz, SHAPE, away, HEIGHTS, 0.01) is None
