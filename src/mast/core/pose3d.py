"""A 3D sensor's pose in the mine grid, and one 3D lidar frame.

The convention (docs/3d.md), stated once and used by every 3D module:

* the sensor frame is REP 103's: x forward, y left, z up;
* the grid frame is x = easting, y = northing, z = elevation (metres);
* the sensor-to-grid rotation is ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, with
  ``yaw = 90° - azimuth`` (:func:`mast.core.frames.yaw_of_azimuth`): roll about the
  sensor's x axis, then pitch about y, then yaw about the grid's z;
* a point ``p`` in the sensor frame is at ``R @ p + t`` in the grid, ``t`` being the
  sensor origin's (easting, northing, elevation): the pose's position;
* the azimuth is the heading of the sensor's x axis projected on the horizontal,
  clockwise from grid north, as in 2D. The rotations are right-handed: a positive
  pitch turns x (forward) down, a positive roll turns y (left) up.

A level sensor (roll = pitch = 0) is a 2D scanner's pose at that elevation: the 2D
formula ``E = E0 + r sin(A - phi)``, ``N = N0 + r cos(A - phi)`` holds for a return
at bearing ``phi`` in the xy-plane (tested both ways).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mast.core.frames import azimuth_of_yaw, yaw_of_azimuth
from mast.core.pose import Pose2D
from mast.errors import InputError

__all__ = ["Frame3D", "Pose3D", "rotation_rpy", "rpy_of_rotation"]


def rotation_rpy(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (radians)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def rpy_of_rotation(R: ArrayLike) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``, pitch in
    [-90°, 90°] (at ±90° the roll is taken as 0: the gimbal lock, where only their
    difference is defined)."""
    m = np.asarray(R, dtype=float)
    pitch = math.asin(max(-1.0, min(1.0, -float(m[2, 0]))))
    if abs(m[2, 0]) < 1.0 - 1e-12:
        roll = math.atan2(float(m[2, 1]), float(m[2, 2]))
        yaw = math.atan2(float(m[1, 0]), float(m[0, 0]))
    else:
        roll = 0.0
        yaw = math.atan2(-float(m[0, 1]), float(m[1, 1]))
    return roll, pitch, yaw


@dataclass(frozen=True, slots=True)
class Pose3D:
    """A 3D sensor's pose in the mine grid (see the module).

    Attributes
    ----------
    easting, northing, elevation : float
        The sensor origin, metres.
    azimuth : float
        Heading of the sensor's x axis on the horizontal, radians clockwise from grid
        north.
    pitch, roll : float
        Radians (REP 103 senses; the rotation ``Rz(yaw) Ry(pitch) Rx(roll)``).
    """

    easting: float
    northing: float
    elevation: float
    azimuth: float
    pitch: float = 0.0
    roll: float = 0.0

    @classmethod
    def from_degrees(
        cls,
        easting: float,
        northing: float,
        elevation: float,
        azimuth_deg: float,
        pitch_deg: float = 0.0,
        roll_deg: float = 0.0,
    ) -> Pose3D:
        return cls(
            float(easting),
            float(northing),
            float(elevation),
            math.radians(azimuth_deg),
            math.radians(pitch_deg),
            math.radians(roll_deg),
        )

    @classmethod
    def from_rotation(cls, R: ArrayLike, t: ArrayLike) -> Pose3D:
        """The pose of rotation ``R`` (sensor to grid) and translation ``t``."""
        roll, pitch, yaw = rpy_of_rotation(R)
        e, n, z = (float(v) for v in np.asarray(t, dtype=float).reshape(3))
        return cls(e, n, z, azimuth_of_yaw(yaw), pitch, roll)

    @property
    def yaw(self) -> float:
        return yaw_of_azimuth(self.azimuth)

    @property
    def rotation(self) -> NDArray[np.float64]:
        """Sensor-to-grid rotation, 3×3."""
        return rotation_rpy(self.roll, self.pitch, self.yaw)

    @property
    def position(self) -> NDArray[np.float64]:
        return np.array([self.easting, self.northing, self.elevation])

    @property
    def horizontal(self) -> Pose2D:
        """The 2D pose: position and azimuth, the elevation and tilt left out."""
        return Pose2D(self.easting, self.northing, self.azimuth)

    def minus(self, other: Pose3D) -> NDArray[np.float64]:
        """``self - other`` as (easting, northing, elevation, roll, pitch, azimuth), metres
        and radians (a 3D record's ``covariance_order``), the azimuth's difference
        wrapped to [-pi, pi]."""
        return np.array(
            [
                self.easting - other.easting,
                self.northing - other.northing,
                self.elevation - other.elevation,
                self.roll - other.roll,
                self.pitch - other.pitch,
                math.remainder(self.azimuth - other.azimuth, 2 * math.pi),
            ]
        )

    def sensor_to_grid(self, points: ArrayLike) -> NDArray[np.float64]:
        """(n, 3) points in the sensor frame → the grid."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return np.asarray(p @ self.rotation.T + self.position, dtype=float)

    def grid_to_sensor(self, points: ArrayLike) -> NDArray[np.float64]:
        """(n, 3) points in the grid → the sensor frame."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return np.asarray((p - self.position) @ self.rotation, dtype=float)


@dataclass(frozen=True, slots=True, eq=False)
class Frame3D:
    """One frame of a 3D lidar in its own frame (REP 103: x forward, y left, z up).

    Attributes
    ----------
    points : ndarray, shape (n, 3)
        Returns, metres; every one finite (a frame read with NaNs for no return has
        them left out).
    intensity : ndarray, shape (n,), optional
    ring : ndarray of int, shape (n,), optional
        The laser (ring) of each return, where the driver gives it.
    time_s : ndarray, shape (n,), optional
        Each return's time from the frame's stamp, seconds, where given.
    stamp_ns : int
    frame_id : str
    """

    points: NDArray[np.float64]
    intensity: NDArray[np.float64] | None = None
    ring: NDArray[np.int32] | None = None
    time_s: NDArray[np.float64] | None = None
    stamp_ns: int = 0
    frame_id: str = "lidar"

    def __post_init__(self) -> None:
        p = np.array(self.points, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(p)):
            raise InputError("a 3D frame holds a point that is not finite")
        p.setflags(write=False)
        object.__setattr__(self, "points", p)
        for name, kind in (("intensity", np.float64), ("ring", np.int32), ("time_s", np.float64)):
            value = getattr(self, name)
            if value is None:
                continue
            a = np.array(value, dtype=kind).reshape(-1)
            if a.size != len(p):
                raise InputError(f"a 3D frame has {len(p)} points but {a.size} {name} values")
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.points.shape[0])
