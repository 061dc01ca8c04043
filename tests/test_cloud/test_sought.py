"""A surveyed beacon looked for where the transformation puts it: found with rock
running on above it in its panels' planes, its edges and top where it is; nothing
found where it is not."""

from __future__ import annotations

import itertools
import math

import numpy as np

from mast.cloud.detect import DetectConfig
from mast.cloud.sought import seek_beacon
from mast.core.quantiles import chi2_isf

#: A hat with short outer panels at 25-30 degrees to the wall (the hard clouds' misses).
SHAPE = np.array([[0.0, 0.0], [0.3, 0.16], [0.9, 0.16], [1.08, 0.06]])
BOTTOM, TOP = 1.4, 2.0
NOISE = 0.01


def _turned(points: np.ndarray, theta: float, at: np.ndarray) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.asarray(points @ np.array([[c, -s], [s, c]]).T + at)


def _scene(
    rng: np.random.Generator, theta: float, at: np.ndarray, beacon: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate points of a beacon (its design turned by ``theta`` and put at ``at``) on
    rough rock, and its true edges. The rock behind it runs from the floor to the roof,
    and above the beacon it bulges into the outer panels' planes for half a metre
    (points scattered 5 cm either side of their lines), as detection's pieces met it."""
    parts = []
    if beacon:
        for a, b in itertools.pairwise(SHAPE):
            n = int(2000 * math.dist(a, b) * (TOP - BOTTOM))
            t = rng.uniform(0, 1, n)
            d = (b - a) / math.dist(a, b)
            xy = a + t[:, None] * (b - a) + rng.normal(0, NOISE, n)[:, None] * [-d[1], d[0]]
            parts.append(np.column_stack([xy, rng.uniform(BOTTOM, TOP, n)]))
    for a, b in (SHAPE[0:2], SHAPE[2:4]):
        n = 300
        d = (b - a) / math.dist(a, b)
        xy = (
            a
            + rng.uniform(0, 1, n)[:, None] * (b - a)
            + rng.uniform(-0.05, 0.05, (n, 1))
            * [
                -d[1],
                d[0],
            ]
        )
        parts.append(np.column_stack([xy, rng.uniform(TOP, TOP + 0.5, n)]))
    wall = np.column_stack([rng.uniform(-0.6, 1.7, 6000), rng.normal(-0.05, 0.03, 6000)])
    parts.append(np.column_stack([wall, rng.uniform(0.5, 3.0, 6000)]))
    xyz = np.vstack(parts)
    xyz[:, :2] = _turned(xyz[:, :2], theta, at)
    return xyz, _turned(SHAPE, theta, at)


def _seek(xyz: np.ndarray, predicted: np.ndarray, shape: np.ndarray = SHAPE):  # type: ignore[no-untyped-def]
    return seek_beacon(xyz, None, shape + 500.0, predicted, NOISE, 0.003, DetectConfig())


def test_a_beacon_is_found_where_predicted_and_its_edges_and_top_cover_the_truth() -> None:
    rng = np.random.default_rng(7)
    at = np.array([452_310.0, 7_101_220.0])
    limit = chi2_isf(0.05, 4)
    inside = 0
    tops = []
    draws = 60
    for _ in range(draws):
        xyz, truth = _scene(rng, rng.uniform(-math.pi, math.pi), at)
        # the transformation's prediction: millimetres off
        found = _seek(xyz, truth + rng.normal(0, 0.005, 2))
        assert found is not None
        assert np.max(np.hypot(*(found.fit.edges - truth).T)) < 0.02
        d = (found.fit.edges[1:3] - truth[1:3]).reshape(-1)
        inside += float(d @ np.linalg.solve(found.fit.edge_covariance((2, 3)), d)) <= limit
        # the rock above in the outer panels' planes is not taken for panel
        tops.append((found.top - TOP) / found.sigma_top)
        assert abs(found.top - TOP) < 4 * found.sigma_top < 0.06
    assert inside / draws >= 0.88, inside / draws
    assert float(np.sqrt(np.mean(np.square(tops)))) < 1.5, tops


def test_nothing_is_found_where_the_beacon_is_not() -> None:
    rng = np.random.default_rng(8)
    at = np.array([1000.0, 2000.0])
    for k in range(20):
        theta = rng.uniform(-math.pi, math.pi)
        xyz, truth = _scene(rng, theta, at, beacon=False)
        assert _seek(xyz, truth) is None, k
        # the beacon there, looked for a metre along the wall from it
        xyz, truth = _scene(rng, theta, at)
        along = (truth[3] - truth[0]) / math.dist(truth[3], truth[0])
        assert _seek(xyz, truth + along) is None, k
        assert _seek(xyz, truth - along) is None, k


def test_a_design_other_than_the_one_there_is_not_confirmed() -> None:
    rng = np.random.default_rng(9)
    at = np.array([1000.0, 2000.0])
    # the paper's hat: outer panels at 45 degrees, a middle panel 0.1 m longer
    other = np.array([[0.0, 0.0], [0.2, 0.2], [0.9, 0.2], [1.1, 0.0]])
    for k in range(20):
        xyz, truth = _scene(rng, rng.uniform(-math.pi, math.pi), at)
        predicted = truth[0] + (other - other[0]) @ np.eye(2)
        u, v = other[3] - other[0], truth[3] - truth[0]
        theta = math.atan2(v[1], v[0]) - math.atan2(u[1], u[0])
        predicted = _turned(other - other[0], theta, truth[0])
        assert _seek(xyz, predicted, other) is None, k


def test_the_top_step_is_unbiased_and_its_sigma_honest_with_rock_running_on_above() -> None:
    from mast.cloud.sought import _top_step

    rng = np.random.default_rng(10)
    scores = []
    for k in range(300):
        # a panel's points per height (1000-3000 per metre), the rock above in its plane
        # at none to a quarter of that, heights spread by 1-1.5 cm (at half the density
        # and 2 cm the step is faint and its sigma optimistic: 1.9 times)
        dense = rng.uniform(1000, 3000)
        blur = rng.uniform(0.01, 0.015)
        panel = rng.uniform(TOP - 0.6, TOP, rng.poisson(0.6 * dense))
        rock = rng.uniform(TOP, TOP + 0.5, rng.poisson(0.5 * dense * rng.uniform(0, 0.25)))
        z = np.concatenate([panel, rock]) + rng.normal(0, blur, panel.size + rock.size)
        # the run of heights ends within a bin of the top
        got = _top_step(z, TOP + rng.uniform(-0.05, 0.05), 0.01)
        assert got is not None, k
        scores.append((got[0] - TOP) / got[1])
    rms = float(np.sqrt(np.mean(np.square(scores))))
    assert 0.8 < rms < 1.25, rms
    assert abs(float(np.mean(scores))) < 0.2


def test_noisy_clouds_and_loose_predictions_are_no_error() -> None:
    from mast.cloud.sought import _top_step

    rng = np.random.default_rng(11)
    # a noise as wide as the step's window leaves no step to place, not a crash
    z = rng.uniform(TOP - 0.6, TOP, 3000) + rng.normal(0, 0.03, 3000)
    for noise in (0.03, 0.04, 0.1):
        got = _top_step(z, TOP, noise)
        assert got is None or abs(got[0] - TOP) < 0.05
    # a survey sigma of 0.2 m: the snap stays within 15 cm, the beacon is found
    xyz, truth = _scene(rng, 0.3, np.array([10.0, 20.0]))
    found = seek_beacon(xyz, None, SHAPE, truth + 0.05, NOISE, 0.2, DetectConfig())
    assert found is not None
    assert np.max(np.hypot(*(found.fit.edges - truth).T)) < 0.02


def test_the_points_about_the_beacons_sought_are_every_point_there_in_one_pass() -> None:
    """:func:`points_near` keeps every point within each place's own square, in chunks as
    a file is read, and nothing far from them."""
    from collections.abc import Iterator
    from pathlib import Path

    from mast.cloud.detect import points_near
    from mast.cloud.io import Chunk, Cloud

    rng = np.random.default_rng(9)
    n = 200_000
    # grid coordinates 70 km from the origin, x unique: a point is known by it
    xyz = np.column_stack(
        [rng.uniform(-50.0, 50.0, (n, 2)) + [70_000.0, -4_000_000.0], rng.uniform(0, 4, n)]
    )

    class Memory(Cloud):
        path, count, time_field = Path("memory.las"), n, None

        def chunks(self, size: int = 2_000_000) -> Iterator[Chunk]:
            for k in range(0, n, 30_000):
                yield Chunk(xyz[k : k + 30_000], None)

    centres = np.array([[3.3, -7.1], [-20.05, 41.6], [3.6, -6.9]]) + [70_000.0, -4_000_000.0]
    half = np.array([0.8, 2.0, 0.3])
    near = points_near(Memory(), centres, half)
    inside = np.any(np.max(np.abs(xyz[:, None, :2] - centres[None]), axis=2) < half, axis=1)
    kept = np.isin(xyz[:, 0], near[:, 0])
    assert np.all(kept[inside])
    assert np.array_equal(np.sort(xyz[kept, 0]), np.sort(near[:, 0]))
    # a few more than the squares hold (the cells they touch), never beyond those cells
    beyond = np.max(np.abs(near[:, None, :2] - centres[None]), axis=2) - half
    assert np.all(np.min(beyond, axis=1) < 0.25)
    assert kept.sum() < 2 * inside.sum()
