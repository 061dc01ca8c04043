"""The 3D convention of docs/3d.md, tested both ways: a level sensor is the 2D scanner
of DESIGN.md's formula, the rotations turn the way REP 103 says, and every pose and
rotation goes there and back."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mast.core.pose3d import Frame3D, Pose3D, rotation_rpy, rpy_of_rotation
from mast.errors import InputError


@pytest.mark.parametrize("azimuth_deg", [0.0, 30.0, 90.0, 181.0, 359.0])
@pytest.mark.parametrize("phi_deg", [0.0, 45.0, -120.0])
def test_a_level_sensor_is_the_2d_scanner_of_the_design(azimuth_deg: float, phi_deg: float) -> None:
    """DESIGN.md: a return at bearing phi (counter-clockwise from x) and range r lies at
    E = E0 + r sin(A - phi), N = N0 + r cos(A - phi); and back."""
    pose = Pose3D.from_degrees(1000.0, 2000.0, 50.0, azimuth_deg)
    r, phi, a = 7.0, math.radians(phi_deg), math.radians(azimuth_deg)
    sensor = np.array([[r * math.cos(phi), r * math.sin(phi), 0.0]])
    grid = pose.sensor_to_grid(sensor)[0]
    assert grid == pytest.approx(
        [1000.0 + r * math.sin(a - phi), 2000.0 + r * math.cos(a - phi), 50.0], abs=1e-9
    )
    assert pose.grid_to_sensor(grid)[0] == pytest.approx(sensor[0], abs=1e-9)
    flat = pose.horizontal.scanner_to_mine(sensor[:, :2])[0]
    assert flat == pytest.approx(grid[:2], abs=1e-9)


def test_positive_pitch_turns_forward_down_and_positive_roll_turns_left_up() -> None:
    pitched = Pose3D.from_degrees(0.0, 0.0, 0.0, 90.0, pitch_deg=10.0)  # facing east
    ahead = pitched.sensor_to_grid([[1.0, 0.0, 0.0]])[0]
    assert ahead[2] == pytest.approx(-math.sin(math.radians(10.0)))
    assert ahead[0] > 0  # still east
    rolled = Pose3D.from_degrees(0.0, 0.0, 0.0, 90.0, roll_deg=10.0)
    left = rolled.sensor_to_grid([[0.0, 1.0, 0.0]])[0]
    assert left[2] == pytest.approx(math.sin(math.radians(10.0)))
    assert left[1] > 0  # the left of a sensor facing east is north


def test_the_azimuth_is_the_heading_of_x_on_the_horizontal_whatever_the_tilt() -> None:
    pose = Pose3D.from_degrees(0.0, 0.0, 0.0, 30.0, pitch_deg=8.0, roll_deg=-6.0)
    x = pose.rotation[:, 0]
    heading = math.degrees(math.atan2(x[0], x[1])) % 360.0  # clockwise from north
    assert heading == pytest.approx(30.0, abs=1e-9)


angles = st.floats(min_value=-math.pi, max_value=math.pi, allow_nan=False)
tilts = st.floats(min_value=-1.5, max_value=1.5, allow_nan=False)


@given(angles, tilts, angles)
def test_a_rotation_goes_to_roll_pitch_yaw_and_back(roll: float, pitch: float, yaw: float) -> None:
    R = rotation_rpy(roll, pitch, yaw)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert rotation_rpy(*rpy_of_rotation(R)) == pytest.approx(R, abs=1e-9)


@given(angles, tilts, angles)
def test_a_pose_goes_to_its_rotation_and_back(azimuth: float, pitch: float, roll: float) -> None:
    pose = Pose3D(1.0, 2.0, 3.0, azimuth % (2 * math.pi), pitch, roll)
    back = Pose3D.from_rotation(pose.rotation, pose.position)
    assert back.rotation == pytest.approx(pose.rotation, abs=1e-9)
    assert back.position == pytest.approx(pose.position)


def test_a_frame_refuses_what_is_not_a_frame() -> None:
    with pytest.raises(InputError, match="not finite"):
        Frame3D(np.array([[0.0, 0.0, math.nan]]))
    with pytest.raises(InputError, match="2 points but 1 ring"):
        Frame3D(np.zeros((2, 3)), ring=[0])
    frame = Frame3D(np.zeros((2, 3)), ring=[0, 1], stamp_ns=5)
    assert len(frame) == 2
    assert frame.ring is not None
    assert frame.ring.dtype == np.int32


def test_a_pose_minus_another_is_in_record_order_with_the_azimuth_wrapped() -> None:
    a = Pose3D.from_degrees(10.0, 20.0, 3.0, 359.0, 2.0, -1.0)
    b = Pose3D.from_degrees(9.0, 22.0, 2.5, 1.0, 1.0, 1.0)
    d = a.minus(b)
    assert d[:3] == pytest.approx([1.0, -2.0, 0.5])
    # roll, pitch, then the azimuth across north: -2 deg, not 358
    assert np.degrees(d[3:]) == pytest.approx([-2.0, 1.0, -2.0])
    assert np.degrees(b.minus(a)[5]) == pytest.approx(2.0)
