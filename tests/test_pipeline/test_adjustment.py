import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from mast import Pose2D
from mast.core.geometry import PanelSet
from mast.core.noise import NoiseModel
from mast.pipeline.adjustment import adjust_pose, range_model
from mast.sim import paper_scene


def _observations(sigma: float = 0.0, seed: int = 0):  # type: ignore[no-untyped-def]
    scene = paper_scene("parallel", range_sigma_m=sigma, seed=seed)
    shot = scene.shots[1]
    sim = scene.simulate(shot, rng=np.random.default_rng(seed))
    panels = PanelSet.from_survey(scene.survey)
    beams = np.flatnonzero(sim.beacon_mask())
    surf = [sim.surfaces[i] for i in sim.surface_index[beams]]
    k = np.array([scene.survey.ids.index(s.beacon) * 3 + s.panel - 1 for s in surf])
    nrm = panels.normal[k]
    off = np.einsum("ij,ij->i", nrm, panels.a[k])
    return shot.pose, sim.scan.angles_rad[beams], sim.scan.ranges_m[beams], nrm, off


def test_jacobian_matches_finite_differences() -> None:
    pose, ang, _r, nrm, off = _observations()
    rho, jac, d_phi = range_model(pose, ang, nrm, off)
    h = 1e-6
    for j, dp in enumerate(([h, 0, 0], [0, h, 0], [0, 0, h])):
        up = Pose2D(pose.easting + dp[0], pose.northing + dp[1], pose.azimuth + dp[2])
        down = Pose2D(pose.easting - dp[0], pose.northing - dp[1], pose.azimuth - dp[2])
        fd = (range_model(up, ang, nrm, off)[0] - range_model(down, ang, nrm, off)[0]) / (2 * h)
        assert_allclose(jac[:, j], fd, rtol=1e-6, atol=1e-8)
    fd_phi = (range_model(pose, ang + h, nrm, off)[0] - range_model(pose, ang - h, nrm, off)[0]) / (
        2 * h
    )
    assert_allclose(d_phi, fd_phi, rtol=1e-6, atol=1e-8)
    assert rho.shape == ang.shape


def test_noise_free_ranges_give_the_pose_exactly() -> None:
    pose, ang, r, nrm, off = _observations()
    start = Pose2D(pose.easting + 0.02, pose.northing - 0.01, pose.azimuth + 0.003)
    adj = adjust_pose(start, ang, r, nrm, off, noise=NoiseModel(0.01, 0.0, 0.0))
    assert adj.pose.easting == pytest.approx(pose.easting, abs=1e-12)
    assert adj.pose.northing == pytest.approx(pose.northing, abs=1e-12)
    assert math.remainder(adj.pose.azimuth - pose.azimuth, 2 * math.pi) == pytest.approx(
        0.0, abs=1e-13
    )
    assert adj.reference_variance < 1e-12
    assert adj.test_verdict.startswith("too small")


def test_intervals_cover_the_truth_about_95_percent() -> None:
    hits = np.zeros(3)
    s0 = []
    n = 300
    for seed in range(n):
        pose, ang, r, nrm, off = _observations(0.012, seed)
        adj = adjust_pose(pose, ang, r, nrm, off, noise=NoiseModel(0.012, 0.0, 0.0))
        err = np.array(
            [
                adj.pose.easting - pose.easting,
                adj.pose.northing - pose.northing,
                math.remainder(adj.pose.azimuth - pose.azimuth, 2 * math.pi),
            ]
        )
        hits += np.abs(err) <= adj.interval95()
        s0.append(adj.reference_variance)
    cover = hits / n
    assert np.all((cover > 0.91) & (cover < 0.99)), cover
    assert np.mean(s0) == pytest.approx(1.0, abs=0.05)


def test_ellipse_axes_match_the_covariance() -> None:
    pose, ang, r, nrm, off = _observations()
    adj = adjust_pose(
        pose, ang, r + 1e-4 * np.sin(np.arange(r.size)), nrm, off, noise=NoiseModel(0.01, 0.0, 0.0)
    )
    ell = adj.ellipse()
    c = adj.covariance[:2, :2]
    k2 = -2 * math.log(0.05)  # chi-square(2) 95 %
    assert ell.semi_major_m**2 + ell.semi_minor_m**2 == pytest.approx(k2 * np.trace(c), rel=1e-9)
    assert 0 <= ell.azimuth_rad < math.pi
