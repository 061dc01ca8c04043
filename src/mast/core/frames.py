"""The mine grid's azimuth and the robotics yaw, and their covariances, converted once.

MAST speaks azimuth: clockwise from grid north (docs/design.md, "Frames and units").
ROS, GTSAM, TUM files and Foxglove speak yaw: counter-clockwise from +x (east, in the
mine grid). So ``yaw = pi/2 - azimuth``; positions are the same (x = easting,
y = northing); a covariance over (E, N, A) becomes one over (x, y, yaw) with the signs
of its azimuth row and column flipped. Every conversion in MAST is one of these.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mast.core.pose import normalize_azimuth

__all__ = [
    "UNOBSERVED_VARIANCE",
    "azimuth_of_yaw",
    "body_jacobian",
    "ena_to_xy_yaw_covariance",
    "ros_pose_covariance",
    "yaw_of_azimuth",
    "yaw_quaternion",
]

#: d(x, y, yaw) / d(E, N, A): the azimuth turns the other way.
_AZIMUTH_TO_YAW_SIGN = np.array([1.0, 1.0, -1.0])


def yaw_of_azimuth(azimuth_rad: float) -> float:
    """The yaw (counter-clockwise from +E) of an azimuth (clockwise from grid north)."""
    return math.pi / 2 - azimuth_rad


def azimuth_of_yaw(yaw_rad: float) -> float:
    """The azimuth in [0, 2 pi) of a yaw: :func:`yaw_of_azimuth` inverted."""
    return normalize_azimuth(math.pi / 2 - yaw_rad)


def yaw_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` of a rotation about z by ``yaw_rad``."""
    return 0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2)


def ena_to_xy_yaw_covariance(covariance: NDArray[np.float64]) -> NDArray[np.float64]:
    """A (3, 3) covariance over (E, N, A) as one over (x, y, yaw)."""
    return np.asarray(
        covariance * np.outer(_AZIMUTH_TO_YAW_SIGN, _AZIMUTH_TO_YAW_SIGN), dtype=float
    )


#: Variance ROS messages give the axes a 2D fix does not observe (z, roll and pitch):
#: large, ROS's convention for "ignore this axis" (m² and rad²).
UNOBSERVED_VARIANCE = 1e6


def ros_pose_covariance(covariance: NDArray[np.float64]) -> NDArray[np.float64]:
    """A (3, 3) covariance over (E, N, A) as ROS's (6, 6) over (x, y, z, roll, pitch,
    yaw) of a ``geometry_msgs/PoseWithCovariance``: the axes a 2D fix leaves unobserved
    get :data:`UNOBSERVED_VARIANCE`."""
    c = np.asarray(covariance, dtype=float)
    full = np.diag([0.0, 0.0, UNOBSERVED_VARIANCE, UNOBSERVED_VARIANCE, UNOBSERVED_VARIANCE, 0.0])
    full[np.ix_([0, 1, 5], [0, 1, 5])] = ena_to_xy_yaw_covariance((c + c.T) / 2)
    return full


def body_jacobian(yaw_rad: float) -> NDArray[np.float64]:
    """d(E, N, A) / d(body x, body y, yaw) at a pose of heading ``yaw_rad``: a step in the
    body's own frame turned into the grid, and the yaw's sense reversed."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, -1.0]])
