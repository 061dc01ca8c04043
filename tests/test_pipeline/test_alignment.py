import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from mast import Pose2D
from mast.core.geometry import PanelSet
from mast.pipeline.alignment import icp_point_to_line, similarity_transform
from mast.sim import paper_scene


@given(
    st.floats(0.5, 2.0),
    st.floats(-math.pi, math.pi),
    st.floats(-1e6, 1e6),
    st.floats(-1e6, 1e7),
)
def test_similarity_recovers_a_known_transform(
    scale: float, rot: float, tx: float, ty: float
) -> None:
    rng = np.random.default_rng(0)
    p = rng.uniform(-10, 10, (5, 2))
    c, s = math.cos(rot), math.sin(rot)
    q = scale * p @ np.array([[c, -s], [s, c]]).T + [tx, ty]
    sim = similarity_transform(p, q)
    assert sim.scale == pytest.approx(scale, rel=1e-9)
    assert math.remainder(sim.rotation_rad - rot, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert_allclose(sim.translation, [tx, ty], atol=1e-8 * (1 + abs(tx) + abs(ty)))


def test_similarity_pose_matches_design_convention() -> None:
    pose = Pose2D.from_degrees(500.0, 700.0, 123.0)
    p = np.array([[1.0, 0.0], [0.0, 2.0], [3.0, -1.0]])
    sim = similarity_transform(p, pose.scanner_to_mine(p))
    got = sim.pose()
    assert got.easting == pytest.approx(500.0)
    assert got.azimuth_deg == pytest.approx(123.0)


def test_similarity_needs_two_points() -> None:
    with pytest.raises(ValueError, match="at least two points"):
        similarity_transform(np.zeros((1, 2)), np.zeros((1, 2)))


@pytest.mark.parametrize(("de", "dn", "da_deg"), [(0.05, -0.03, 0.5), (-0.08, 0.02, -1.0)])
def test_icp_converges_to_the_true_pose(de: float, dn: float, da_deg: float) -> None:
    scene = paper_scene("divergent")
    shot, sim = scene.shots[1], scene.simulate_all()[1]
    beacon_beams = sim.beacon_mask()
    ang, r = sim.scan.angles_rad[beacon_beams], sim.scan.ranges_m[beacon_beams]
    pts = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
    start = Pose2D(
        shot.pose.easting + de, shot.pose.northing + dn, shot.pose.azimuth + math.radians(da_deg)
    )
    res = icp_point_to_line(
        pts, start, PanelSet.from_survey(scene.survey), gates_m=(0.3, 0.05, 0.01)
    )
    assert res.converged
    assert res.pose.easting == pytest.approx(shot.pose.easting, abs=1e-9)
    assert res.pose.northing == pytest.approx(shot.pose.northing, abs=1e-9)
    assert math.remainder(res.pose.azimuth - shot.pose.azimuth, 2 * math.pi) == pytest.approx(
        0.0, abs=1e-11
    )
    assert res.inliers == int(beacon_beams.sum())


def test_similarity_is_the_least_squares_solution() -> None:
    """The closed form (diagonal normal equations once centred) is lstsq's answer."""
    rng = np.random.default_rng(11)
    for n in (2, 3, 7):
        p = rng.uniform(-20, 20, size=(n, 2))
        q = rng.uniform(1000, 1040, size=(n, 2))  # not a similarity: residuals remain
        sim = similarity_transform(p, q)
        pc, qc = p.mean(axis=0), q.mean(axis=0)
        x, y = (p - pc).T
        design = np.zeros((2 * n, 2))
        design[0::2, 0], design[0::2, 1] = x, -y
        design[1::2, 0], design[1::2, 1] = y, x
        (a, b), *_ = np.linalg.lstsq(design, (q - qc).reshape(-1), rcond=None)
        assert sim.scale == pytest.approx(math.hypot(a, b), rel=1e-12)
        assert sim.rotation_rad == pytest.approx(math.atan2(b, a), abs=1e-12)
    same = similarity_transform(np.ones((2, 2)), np.zeros((2, 2)))
    assert same.scale == 0.0  # coincident points: lstsq's minimum-norm answer


def test_similarity_refuses_unpaired_points_and_keeps_tiny_ones_exact() -> None:
    with pytest.raises(ValueError, match="3 scanner points but 1 mine points"):
        similarity_transform(np.zeros((3, 2)), np.zeros((1, 2)))
    # a sum of squares below the smallest normal double: lstsq's answer, not a rounded one
    sim = similarity_transform(
        np.array([[0.0, 0.0], [1e-160, 0.0]]), np.array([[0.0, 0.0], [1.0, 0.0]])
    )
    assert sim.scale == pytest.approx(1e160, rel=1e-12)


def test_similarities_at_once_are_each_set_in_turn() -> None:
    """Many sets of point pairs at once give each set's transformation, a degenerate set
    (coincident scanner points: lstsq's minimum-norm answer) among them; none gives none,
    and sets of one point, or of unpaired points, are refused."""
    from mast.pipeline.alignment import similarity_transforms

    rng = np.random.default_rng(4)
    p = rng.uniform(-30.0, 30.0, (40, 3, 2))
    q = rng.uniform(5.0e5, 5.1e5, (40, 3, 2))
    p[7] = p[7, 0]  # coincident
    got = similarity_transforms(p, q)
    for k, sim in enumerate(got):
        pc, qc = p[k].mean(axis=0), q[k].mean(axis=0)
        design = np.zeros((6, 2))
        x, y = (p[k] - pc).T
        design[0::2, 0], design[0::2, 1] = x, -y
        design[1::2, 0], design[1::2, 1] = y, x
        (a, b), *_ = np.linalg.lstsq(design, (q[k] - qc).reshape(-1), rcond=None)
        R = np.array([[a, -b], [b, a]])
        t = qc - R @ pc
        assert sim.scale == pytest.approx(math.hypot(a, b), rel=1e-12, abs=1e-15)
        assert sim.rotation_rad == pytest.approx(math.atan2(b, a), abs=1e-12)
        np.testing.assert_allclose(sim.translation, t, rtol=0, atol=1e-9)
        resid = q[k] - (p[k] @ R.T + t)
        assert sim.rms_m == pytest.approx(math.sqrt(np.mean(np.sum(resid**2, axis=1))), rel=1e-9)
    assert got[7].scale == 0.0
    assert similarity_transforms(np.zeros((0, 2, 2)), np.zeros((0, 2, 2))) == []
    with pytest.raises(ValueError, match="two points"):
        similarity_transforms(np.zeros((3, 1, 2)), np.zeros((3, 1, 2)))
    with pytest.raises(ValueError, match="shapes"):
        similarity_transforms(p, q[:, :2])
