"""Azimuth and yaw, both ways, and a covariance across the two conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mast.core.frames import (
    azimuth_of_yaw,
    body_jacobian,
    ena_to_xy_yaw_covariance,
    yaw_of_azimuth,
    yaw_quaternion,
)
from mast.core.pose import Pose2D


@pytest.mark.parametrize(
    ("azimuth_deg", "yaw_deg"),
    [(0.0, 90.0), (90.0, 0.0), (180.0, -90.0), (270.0, -180.0), (45.0, 45.0), (135.0, -45.0)],
)
def test_north_is_a_quarter_turn_counter_clockwise_from_east(
    azimuth_deg: float, yaw_deg: float
) -> None:
    # Grid north (azimuth 0) is yaw 90 deg; east (azimuth 90) is yaw 0; and back.
    assert math.degrees(yaw_of_azimuth(math.radians(azimuth_deg))) == pytest.approx(yaw_deg)
    assert math.degrees(azimuth_of_yaw(math.radians(yaw_deg))) == pytest.approx(azimuth_deg % 360.0)


@given(st.floats(-20.0, 20.0, allow_nan=False))
def test_azimuth_of_yaw_is_in_one_turn_and_inverts_yaw_of_azimuth(yaw: float) -> None:
    az = azimuth_of_yaw(yaw)
    assert 0.0 <= az < math.tau
    assert math.remainder(yaw_of_azimuth(az) - yaw, math.tau) == pytest.approx(0.0, abs=1e-12)


def test_a_yaw_heading_points_where_the_azimuth_does() -> None:
    # A scanner facing azimuth A looks along (sin A, cos A) in (E, N); the yaw's
    # (cos yaw, sin yaw) is the same direction.
    for az in np.radians([0.0, 30.0, 100.0, 200.0, 359.0]):
        yaw = yaw_of_azimuth(float(az))
        forward = Pose2D(0.0, 0.0, float(az)).scanner_to_mine(np.array([[1.0, 0.0]]))[0]
        assert forward == pytest.approx([math.cos(yaw), math.sin(yaw)])
        assert forward == pytest.approx([math.sin(az), math.cos(az)])


def test_the_quaternion_turns_about_z_by_the_yaw() -> None:
    qx, qy, qz, qw = yaw_quaternion(math.radians(90.0))
    assert (qx, qy) == (0.0, 0.0)
    assert 2 * math.atan2(qz, qw) == pytest.approx(math.radians(90.0))
    assert math.hypot(qz, qw) == pytest.approx(1.0)


def test_a_covariance_keeps_its_variances_and_flips_the_azimuth_correlations() -> None:
    cov = np.array([[4.0, 1.0, 0.3], [1.0, 9.0, -0.2], [0.3, -0.2, 0.01]])
    out = ena_to_xy_yaw_covariance(cov)
    assert np.diag(out) == pytest.approx(np.diag(cov))
    assert out[0, 1] == cov[0, 1]
    assert out[0, 2] == -cov[0, 2]
    assert out[2, 1] == -cov[2, 1]
    # The same as propagating through the Jacobian of (x, y, yaw) = (E, N, pi/2 - A).
    j = np.diag([1.0, 1.0, -1.0])
    assert out == pytest.approx(j @ cov @ j.T)


def test_a_body_step_lands_in_the_grid_by_the_heading() -> None:
    # A metre forward at yaw 90 deg (facing north) moves +1 m in N; turning left
    # (yaw up) turns the azimuth down.
    j = body_jacobian(math.radians(90.0))
    assert j @ np.array([1.0, 0.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0])
    assert j @ np.array([0.0, 0.0, 0.1]) == pytest.approx([0.0, 0.0, -0.1])
