"""Returns at a beacon's silhouette (possibly mixed pixels) weigh less in the fit."""

import math

import numpy as np
import pytest

from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.pipeline.adjustment import adjust_pose
from mast.pipeline.edges import JUMP_MIN_M, at_silhouette, jump_m


def test_a_jump_is_four_sigmas_of_a_step_and_at_least_three_centimetres() -> None:
    assert jump_m(0.012) == pytest.approx(4 * math.sqrt(2) * 0.012)
    assert jump_m(0.001) == JUMP_MIN_M


def test_the_beam_beside_a_jump_to_what_lies_behind_is_at_the_silhouette() -> None:
    # Beams 0-9: 2 and 3 on beacon 0 (predicted at 5 m), 4 misses it and returns from the
    # rock 0.3 m behind; 6 and 7 on beacon 1, 8 misses it but returns from nearer (an
    # occluder in front is no silhouette of beacon 1); 1 misses beacon 0 and returns
    # 1 cm behind (no jump: the wall the beacon stands on).
    ranges = np.array([5.0, 5.01, 5.0, 5.0, 5.3, 6.0, 6.0, 6.0, 5.5, np.nan])
    valid = np.isfinite(ranges)
    ray_owner = np.array([-1, -1, 0, 0, -1, -1, 1, 1, -1, -1])
    beams = np.array([2, 3, 6, 7])
    owner = ray_owner[beams]
    predicted = np.array([5.0, 5.0, 6.0, 6.0])
    edge = at_silhouette(ranges, valid, beams, predicted, owner, ray_owner, jump_m(0.012))
    assert edge.tolist() == [False, True, False, False]
    # Its own range does not decide it: the same beam returning 5 cm short is still at it.
    ranges[3] = 4.95
    edge = at_silhouette(ranges, valid, beams, predicted, owner, ray_owner, jump_m(0.012))
    assert edge.tolist() == [False, True, False, False]
    # A neighbour with no return cannot show a jump.
    ranges[4] = np.nan
    edge = at_silhouette(ranges, np.isfinite(ranges), beams, predicted, owner, ray_owner, 0.07)
    assert not edge.any()


def test_a_return_with_four_times_the_variance_has_twice_the_sigma() -> None:
    # Four returns on two perpendicular lines through the scanner's surroundings.
    pose = Pose2D(0.0, 0.0, 0.0)
    angles = np.array([0.0, 0.3, math.pi / 2, math.pi / 2 + 0.3, -0.4])
    normals = np.array([[0.0, 1.0], [0.0, 1.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    offsets = np.array([3.0, 3.0, 4.0, 4.0, 3.0])
    # azimuth 0 looks north: beam angle phi points along bearing -phi
    dirs = pose.beam_directions(angles)
    ranges = offsets / np.einsum("ij,ij->i", normals, dirs)
    noise = NoiseModel(0.01, 0.0, 0.0)
    plain = adjust_pose(pose, angles, ranges, normals, offsets, noise=noise)
    scale = np.array([1.0, 1.0, 1.0, 4.0, 1.0])
    weighted = adjust_pose(
        pose, angles, ranges, normals, offsets, noise=noise, variance_scale=scale
    )
    assert weighted.sigmas_m[3] == pytest.approx(2 * plain.sigmas_m[3])
    np.testing.assert_allclose(weighted.sigmas_m[[0, 1, 2, 4]], plain.sigmas_m[[0, 1, 2, 4]])
    # A return weighing less leaves the pose less certain.
    assert np.all(np.diag(weighted.cofactor) >= np.diag(plain.cofactor) - 1e-15)
    assert np.trace(weighted.cofactor) > np.trace(plain.cofactor)
