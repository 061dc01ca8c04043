"""Fixed-lag smoothing in windows against the whole run's pose graph."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.core.pose import Pose2D
from mast.runs.odometry import Motion
from mast.runs.track import Node, Smoother, smooth

FIX_COV = np.diag([0.002**2, 0.002**2, math.radians(0.005) ** 2])
STEP_COV = np.diag([0.004**2, 0.002**2, math.radians(0.01) ** 2])


def _relative(a: Pose2D, b: Pose2D) -> tuple[float, float, float]:
    """``b`` in the scanner frame of ``a`` (x forward, y left, angle counter-clockwise)."""
    th = math.pi / 2 - a.azimuth
    de, dn = b.easting - a.easting, b.northing - a.northing
    c, s = math.cos(th), math.sin(th)
    return c * de + s * dn, -s * de + c * dn, (a.azimuth - b.azimuth + math.pi) % math.tau - math.pi


def _run(
    n: int, fixed: list[tuple[int, int]], seed: int = 0, key_every: int = 10
) -> tuple[list[Node], list[Pose2D]]:
    """A drive along a gentle curve at 4 cm a scan: fixes in the ``fixed`` index ranges,
    each scan's motion measured (with noise of its covariance) from its keyframe."""
    rng = np.random.default_rng(seed)
    truth = []
    for i in range(n):
        s = 0.04 * i
        az = math.radians(60.0 + 20.0 * math.sin(s / 25.0))
        truth.append(Pose2D(1000.0 + 0.9 * s, 5000.0 + 0.4 * s + 3 * math.sin(s / 40), az))
    nodes: list[Node] = []
    key = None
    chol_f, chol_m = np.linalg.cholesky(FIX_COV), np.linalg.cholesky(STEP_COV)
    for i, t in enumerate(truth):
        fix = None
        if any(a <= i < b for a, b in fixed):
            e = chol_f @ rng.standard_normal(3)
            fix = (Pose2D(t.easting + e[0], t.northing + e[1], t.azimuth + e[2]), FIX_COV)
        motion = None
        if key is not None:
            dx, dy, dth = _relative(truth[key], t)
            e = chol_m @ rng.standard_normal(3)
            motion = Motion(dx + e[0], dy + e[1], dth + e[2], STEP_COV, 100, 0.01)
        nodes.append(Node(i, i * 40_000_000, fix, motion, key))
        if key is None or fix is not None or i - key >= key_every:
            key = i
    return nodes, truth


def _whole(nodes: list[Node]) -> dict[int, tuple[Pose2D, np.ndarray]]:
    smoother = Smoother(margin=10**6, batch=10**6, max_nodes=10**9)
    placed = [p for n in nodes for p in smoother.push(n)] + smoother.finish()
    return {p.scan: (p.pose, p.covariance) for p in placed}


def _deviation(a: Pose2D, b: Pose2D, cov: np.ndarray) -> np.ndarray:
    d = np.array(
        [
            a.easting - b.easting,
            a.northing - b.northing,
            (a.azimuth - b.azimuth + math.pi) % math.tau - math.pi,
        ]
    )
    return np.abs(d) / np.sqrt(np.diag(cov))


def test_windows_agree_with_the_whole_graph() -> None:
    fixed = [(0, 60), (400, 470), (1500, 1530), (1600, 1700), (2500, 2600)]
    nodes, _ = _run(2600, fixed)
    whole = _whole(nodes)
    smoother = Smoother(margin=10, batch=100, max_nodes=2000)
    placed = [p for n in nodes for p in smoother.push(n)] + smoother.finish()
    assert [p.scan for p in placed] == list(range(2600))
    assert smoother.dropped == 0
    worst = 0.0
    for p in placed:
        pose, cov = whole[p.scan]
        worst = max(worst, float(np.max(_deviation(p.pose, pose, cov))))
        np.testing.assert_allclose(np.sqrt(np.diag(p.covariance)), np.sqrt(np.diag(cov)), rtol=0.05)
    assert worst < 0.05, worst
    # The sources are the scans' own: a fix is a fix, the rest odometry.
    assert {p.scan for p in placed if p.source == "fix"} == {n.scan for n in nodes if n.fix}


def test_memory_is_bounded_by_the_window() -> None:
    fixed = [(i, i + 20) for i in range(0, 6000, 300)]
    nodes, _ = _run(6000, fixed)
    smoother = Smoother(margin=10, batch=100, max_nodes=1000)
    longest = 0
    count = 0
    for n in nodes:
        count += len(smoother.push(n))
        longest = max(longest, len(smoother._buf))
    count += len(smoother.finish())
    assert count == 6000
    # A window holds a gap (280 scans) and the fixes around it, never the run.
    assert longest < 800


def test_a_gap_longer_than_the_window_is_placed_from_its_past() -> None:
    fixed = [(0, 50), (3000, 3050)]
    nodes, truth = _run(3050, fixed, seed=3)
    whole = _whole(nodes)
    smoother = Smoother(margin=10, batch=100, max_nodes=1000)
    placed = {p.scan: p for n in nodes for p in smoother.push(n)}
    placed.update({p.scan: p for p in smoother.finish()})
    assert sorted(placed) == list(range(3050))
    # Cut before the next fix was seen: less known, and honestly so.
    for i in (600, 1200, 1800):
        p = placed[i]
        _, cov = whole[i]
        assert np.all(np.diag(p.covariance) >= np.diag(cov) * 0.999)
        assert np.all(_deviation(p.pose, truth[i], p.covariance) < 4.5)
    # Near the second fixes the cut does not matter.
    pose, cov = whole[3049]
    assert np.max(_deviation(placed[3049].pose, pose, cov)) < 0.1


def test_scans_before_the_first_fix_wait_for_it_and_a_chain_without_one_is_dropped() -> None:
    nodes, _ = _run(300, [(200, 220)])
    placed = smooth(nodes)
    assert [p.scan for p in placed] == list(range(300))
    # A broken chain (no motion) without a fix is not placed.
    orphan = [Node(1000 + i, 0, None, None, None) for i in range(3)]
    assert smooth(orphan) == []
    smoother = Smoother(margin=5, batch=10, max_nodes=20)
    nodes, _ = _run(60, [])
    for n in nodes:
        assert smoother.push(n) == []
    assert smoother.finish() == []
    assert smoother.dropped > 0


def test_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="margin and batch must be positive"):
        Smoother(margin=0)
    with pytest.raises(ValueError, match="max_nodes >= 2"):
        Smoother(batch=100, max_nodes=150)
