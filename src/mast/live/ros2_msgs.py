"""The ROS 2 messages ``mast ros2`` speaks, as DDS types, and the conversions to and from them.

ROS 2 puts a message on the wire as an XCDR1 (plain CDR) sample of a final struct whose
type is named ``<package>::msg::dds_::<Name>_`` on the topic ``rt<topic name>``, whatever
its middleware (rmw_cyclonedds, rmw_fastrtps, rmw_connextdds). The structs below are those
of the message definitions (``sensor_msgs/LaserScan``, ``geometry_msgs/PoseWithCovarianceStamped``,
``tf2_msgs/TFMessage``, ``std_msgs/String``), field for field, so that Eclipse Cyclone DDS's
Python binding exchanges them with any ROS 2 node without a ROS installation.

The pose in the grid is REP 103's ENU: x = easting, y = northing, z up; the heading is the
yaw about z, counter-clockwise from x (east), so ``yaw = 90° - azimuth``
(:func:`pose_message`).
"""

# No "from __future__ import annotations": the binding reads the field types at run time.
from dataclasses import dataclass

import numpy as np
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint32
from numpy.typing import NDArray

from mast.core.frames import ros_pose_covariance, yaw_of_azimuth, yaw_quaternion
from mast.core.pose import Pose2D
from mast.core.scan import Scan, split_stamp
from mast.errors import InputError

__all__ = [
    "Header",
    "LaserScan",
    "PoseWithCovarianceStamped",
    "String",
    "TFMessage",
    "dds_topic",
    "laserscan_message",
    "pose_message",
    "tf_message",
]


@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@final
@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@final
@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header
    angle_min: float32
    angle_max: float32
    angle_increment: float32
    time_increment: float32
    scan_time: float32
    range_min: float32
    range_max: float32
    ranges: sequence[float32]  # type: ignore[type-arg]
    intensities: sequence[float32]  # type: ignore[type-arg]


@final
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@final
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@final
@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@final
@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@final
@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]  # type: ignore[type-arg,valid-type]


@final
@dataclass
class PoseWithCovarianceStamped(
    IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovarianceStamped_"
):
    header: Header
    pose: PoseWithCovariance


@final
@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@final
@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@final
@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]  # type: ignore[type-arg]


@final
@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


def dds_topic(name: str) -> str:
    """The DDS topic of a ROS 2 topic name: ``/scan`` → ``rt/scan`` (a relative name is
    taken from the root namespace, as a node without one does)."""
    text = name.strip()
    if not text or text == "/" or any(c.isspace() for c in text) or "//" in text:
        raise InputError(f"topic {name!r}: give a ROS 2 topic name such as /scan")
    return "rt/" + text.lstrip("/")


def _time(ns: int) -> Time:
    return Time(*split_stamp(ns))


def laserscan_message(scan: Scan) -> LaserScan:
    """A scan as the LaserScan a ROS 2 driver publishes (float32 fields, as a bag holds
    them: :meth:`~mast.core.scan.Scan.message_fields`)."""
    f = scan.message_fields()
    sec, nanosec = f.pop("stamp")
    header = Header(Time(sec, nanosec), f.pop("frame_id"))
    f["ranges"], f["intensities"] = f["ranges"].tolist(), f["intensities"].tolist()
    return LaserScan(header=header, **f)


def _yaw_quaternion(azimuth: float) -> Quaternion:
    return Quaternion(*yaw_quaternion(yaw_of_azimuth(azimuth)))


def pose_message(
    pose: Pose2D, covariance: NDArray[np.float64], *, stamp: int, frame: str
) -> PoseWithCovarianceStamped:
    """A fix as ``geometry_msgs/PoseWithCovarianceStamped`` in ENU (see the module), its
    covariance as :func:`~mast.core.frames.ros_pose_covariance` gives it."""
    return PoseWithCovarianceStamped(
        header=Header(_time(stamp), frame),
        pose=PoseWithCovariance(
            pose=Pose(
                position=Point(float(pose.easting), float(pose.northing), 0.0),
                orientation=_yaw_quaternion(pose.azimuth),
            ),
            covariance=ros_pose_covariance(covariance).ravel().tolist(),  # type: ignore[arg-type]
        ),
    )


def tf_message(pose: Pose2D, *, stamp: int, frame: str, child: str) -> TFMessage:
    """The transform from ``frame`` (the grid) to ``child`` (the scanner) at a fix."""
    return TFMessage(
        transforms=[  # type: ignore[arg-type]
            TransformStamped(
                header=Header(_time(stamp), frame),
                child_frame_id=child,
                transform=Transform(
                    Vector3(float(pose.easting), float(pose.northing), 0.0),
                    _yaw_quaternion(pose.azimuth),
                ),
            )
        ]
    )
