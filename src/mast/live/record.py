"""``mast live --record run.mcap``: the received scans and the poses, as a ROS 2 MCAP file.

Topics (ROS 2 Humble types, CDR):

* ``/scan``, ``sensor_msgs/msg/LaserScan``: every scan received (dropped ones
  too), stamped as received, in the scanner's frame;
* ``/mast/pose``, ``geometry_msgs/msg/PoseWithCovarianceStamped``: each fix in
  frame ``mine_grid`` (x easting, y northing, z 0; yaw counter-clockwise from
  east, ``90° - azimuth``), its covariance in ROS order (x, y, z, roll, pitch,
  yaw; 1e6 on the axes a 2D fix does not observe, z, roll and pitch);
* ``/mast/fix``, ``std_msgs/msg/String``: every record written to standard
  output (fix or no fix), as its JSON.

The file is written under a temporary name beside the target and renamed when
closed (on the stream's end, a closed pipe or Ctrl-C), so that ``run.mcap`` is
only ever a complete file; ``mast locate`` and ``mast track`` read it back.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

from mast.core.frames import ros_pose_covariance, yaw_of_azimuth, yaw_quaternion
from mast.core.scan import Scan, split_stamp
from mast.io.atomic import commit, discard, part_path
from mast.io.bags import LASERSCAN, laserscan_bytes
from mast.pipeline.locator import Fix

__all__ = ["MINE_FRAME", "McapRecorder"]

#: Frame of the recorded poses.
MINE_FRAME = "mine_grid"
_POSE = "geometry_msgs/msg/PoseWithCovarianceStamped"
_STRING = "std_msgs/msg/String"


class McapRecorder:
    """Write scans and fixes to ``path`` as they come (thread-safe); :meth:`close` once."""

    def __init__(self, path: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        self.path = path
        self._stage = part_path(path)
        discard(self._stage)
        self._stage.mkdir(parents=True)
        self._store: Any = get_typestore(Stores.ROS2_HUMBLE)
        self._writer: Any = Writer(
            self._stage / "run", version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP
        )
        self._writer.open()
        w, st = self._writer, self._store
        self._scan = w.add_connection("/scan", LASERSCAN, typestore=st)
        self._pose = w.add_connection("/mast/pose", _POSE, typestore=st)
        self._fix = w.add_connection("/mast/fix", _STRING, typestore=st)
        self._lock = threading.Lock()
        self._seq = 0
        self.scans = 0
        self.closed = False

    def scan(self, scan: Scan) -> None:
        raw = laserscan_bytes(self._store, scan, self._seq, ros1=False)
        with self._lock:
            if self.closed:
                return
            self._writer.write(self._scan, int(scan.stamp_ns), raw)
            self._seq += 1
            self.scans += 1

    def fix(self, scan: Scan, fix: Fix, record: dict[str, Any]) -> None:
        """The record of ``scan`` (always) and its pose (when fixed)."""
        t = self._store.types
        text = self._store.serialize_cdr(t[_STRING](data=json.dumps(record)), _STRING)
        pose = None
        if fix.ok and fix.pose is not None and fix.adjustment is not None:
            pose = self._store.serialize_cdr(self._pose_message(scan, fix), _POSE)
        with self._lock:
            if self.closed:
                return
            self._writer.write(self._fix, int(scan.stamp_ns), bytes(text))
            if pose is not None:
                self._writer.write(self._pose, int(scan.stamp_ns), bytes(pose))

    def _pose_message(self, scan: Scan, fix: Fix) -> Any:
        assert fix.pose is not None
        assert fix.adjustment is not None
        t = self._store.types
        sec, nsec = split_stamp(scan.stamp_ns)
        yaw = yaw_of_azimuth(fix.pose.azimuth)
        cov = ros_pose_covariance(fix.adjustment.covariance)
        return t[_POSE](
            header=t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=MINE_FRAME
            ),
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](
                        x=fix.pose.easting, y=fix.pose.northing, z=0.0
                    ),
                    orientation=t["geometry_msgs/msg/Quaternion"](
                        **dict(zip("xyzw", yaw_quaternion(yaw), strict=True))
                    ),
                ),
                covariance=cov.ravel(),
            ),
        )

    def close(self) -> None:
        """Finish the file and give it its name (a second call does nothing)."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
            try:
                self._writer.close()
                commit(self._stage / "run" / "run.mcap", self.path)
            finally:
                discard(self._stage)
