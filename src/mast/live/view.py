"""``mast live --view``: a live view for Foxglove over its WebSocket protocol.

Channels (``foxglove-sdk``'s built-in schemas), in frame ``site``, the mine grid
moved to a round origin near the beacons (float32 graphics jitter at seven-digit
coordinates; the ``mine_grid`` -> ``site`` transform gives the grid back):

* ``/scan`` (``foxglove.LaserScan``): each located scan, in frame ``scanner``;
* ``/tf`` (``foxglove.FrameTransform``): ``mine_grid`` -> ``site`` and, with a fix,
  ``site`` -> ``scanner``, which puts the scan in the mine frame;
* ``/pose`` (``foxglove.PoseInFrame``): the fixed pose;
* ``/beacons`` (``foxglove.SceneUpdate``): the surveyed panels and beacon ids;
* ``/ellipse`` (``foxglove.SceneUpdate``): the 95 % position ellipse, drawn
  ``ELLIPSE_EXAGGERATION`` times its size (millimetres would not show);
* ``/status`` (``foxglove.Log``): the fix, or the no-fix reason and its detail.

The server listens on loopback unless another host is given.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from mast.core.beacon import Survey
from mast.core.frames import yaw_of_azimuth, yaw_quaternion
from mast.core.pose import Pose2D
from mast.core.scan import Scan, split_stamp
from mast.pipeline.locator import Fix

__all__ = ["DEFAULT_VIEW_PORT", "ELLIPSE_EXAGGERATION", "LiveView"]

DEFAULT_VIEW_PORT = 8765
#: The 95 % ellipse is drawn this many times its size.
ELLIPSE_EXAGGERATION = 100.0
#: Seconds between repeats of the beacons (for viewers that join late).
_BEACONS_EVERY_S = 1.0


def _yaw_quaternion(yaw: float) -> Any:
    import foxglove.messages as fm

    return fm.Quaternion(**dict(zip("xyzw", yaw_quaternion(yaw), strict=True)))


def _timestamp(ns: int) -> Any:
    import foxglove.messages as fm

    return fm.Timestamp(*split_stamp(ns))


class LiveView:
    """A Foxglove WebSocket server publishing each scan and fix (see the module)."""

    def __init__(self, survey: Survey, *, host: str = "127.0.0.1", port: int = 8765) -> None:
        import foxglove
        import foxglove.channels as fc

        self.survey = survey
        edges = np.concatenate([b.edges for b in survey]) if len(survey) else np.zeros((0, 2))
        self.origin = np.round(edges.mean(axis=0) / 100.0) * 100.0 if edges.size else np.zeros(2)
        self._context = foxglove.Context()
        self._server = foxglove.start_server(
            name="mast live", host=host, port=port, context=self._context
        )
        self.port: int = self._server.port
        ctx = self._context
        self._scan = fc.LaserScanChannel("/scan", context=ctx)
        self._tf = fc.FrameTransformChannel("/tf", context=ctx)
        self._pose = fc.PoseInFrameChannel("/pose", context=ctx)
        self._beacons = fc.SceneUpdateChannel("/beacons", context=ctx)
        self._ellipse = fc.SceneUpdateChannel("/ellipse", context=ctx)
        self._status = fc.LogChannel("/status", context=ctx)
        self._beacons_at = -math.inf

    def close(self) -> None:
        self._server.stop()

    def scan(self, scan: Scan) -> None:
        """Received scans are shown when located (:meth:`fix`)."""

    def fix(self, scan: Scan, fix: Fix, record: dict[str, Any]) -> None:
        import foxglove.messages as fm

        stamp = _timestamp(scan.stamp_ns)
        now = time.monotonic()
        if now - self._beacons_at > _BEACONS_EVERY_S:
            self._beacons_at = now
            self._publish_beacons(stamp)
            self._tf.log(
                fm.FrameTransform(
                    timestamp=stamp,
                    parent_frame_id="mine_grid",
                    child_frame_id="site",
                    translation=fm.Vector3(x=float(self.origin[0]), y=float(self.origin[1])),
                    rotation=_yaw_quaternion(0.0),
                )
            )
        if self._scan.has_sinks() and len(scan):
            r = np.where(scan.valid, scan.ranges_m, np.inf)
            self._scan.log(
                fm.LaserScan(
                    timestamp=stamp,
                    frame_id=scan.frame_id,
                    pose=fm.Pose(position=fm.Vector3(), orientation=_yaw_quaternion(0.0)),
                    start_angle=float(scan.angles_rad[0]),
                    end_angle=float(scan.angles_rad[-1]),
                    ranges=r.tolist(),
                )
            )
        if fix.ok and fix.pose is not None:
            self._publish_pose(scan, fix.pose, stamp, record)
            text = (
                f"fix E {record['easting']:.3f} N {record['northing']:.3f} "
                f"Az {record['azimuth_dms']}, beacons {' '.join(fix.beacons)}"
            )
            level = fm.LogLevel.Info
        else:
            text = f"no fix: {fix.reason}: {fix.detail}"
            level = fm.LogLevel.Warning
        self._status.log(fm.Log(timestamp=stamp, level=level, message=text, name="mast"))

    def _local(self, e: float, n: float) -> tuple[float, float]:
        return e - float(self.origin[0]), n - float(self.origin[1])

    def _publish_pose(self, scan: Scan, pose: Pose2D, stamp: Any, record: dict[str, Any]) -> None:
        import foxglove.messages as fm

        x, y = self._local(pose.easting, pose.northing)
        yaw = yaw_of_azimuth(pose.azimuth)
        self._tf.log(
            fm.FrameTransform(
                timestamp=stamp,
                parent_frame_id="site",
                child_frame_id=scan.frame_id,
                translation=fm.Vector3(x=x, y=y),
                rotation=_yaw_quaternion(yaw),
            )
        )
        self._pose.log(
            fm.PoseInFrame(
                timestamp=stamp,
                frame_id="site",
                pose=fm.Pose(position=fm.Vector3(x=x, y=y), orientation=_yaw_quaternion(yaw)),
            )
        )
        a = record["ellipse95_semi_major_m"] * ELLIPSE_EXAGGERATION
        b = record["ellipse95_semi_minor_m"] * ELLIPSE_EXAGGERATION
        az = math.radians(record["ellipse95_azimuth_deg"])
        t = np.linspace(0.0, 2 * math.pi, 49)
        pe = x + a * np.cos(t) * math.sin(az) + b * np.sin(t) * math.cos(az)
        pn = y + a * np.cos(t) * math.cos(az) - b * np.sin(t) * math.sin(az)
        self._ellipse.log(
            fm.SceneUpdate(
                entities=[
                    fm.SceneEntity(
                        timestamp=stamp,
                        frame_id="site",
                        id="ellipse95",
                        lines=[
                            fm.LinePrimitive(
                                type=fm.LinePrimitiveLineType.LineStrip,
                                thickness=2.0,
                                scale_invariant=True,
                                points=[
                                    fm.Point3(x=float(u), y=float(v))
                                    for u, v in zip(pe, pn, strict=True)
                                ],
                                color=fm.Color(r=1.0, g=0.6, b=0.0, a=1.0),
                            )
                        ],
                    )
                ]
            )
        )

    def _publish_beacons(self, stamp: Any) -> None:
        import foxglove.messages as fm

        entities = []
        for beacon in self.survey:
            local = beacon.edges - self.origin
            pts = [fm.Point3(x=float(u), y=float(v)) for u, v in local]
            label = fm.Vector3(x=float(local[0, 0]), y=float(local[0, 1]), z=0.5)
            entities.append(
                fm.SceneEntity(
                    timestamp=stamp,
                    frame_id="site",
                    id=f"beacon-{beacon.id}",
                    lines=[
                        fm.LinePrimitive(
                            type=fm.LinePrimitiveLineType.LineStrip,
                            thickness=3.0,
                            scale_invariant=True,
                            points=pts,
                            color=fm.Color(r=0.1, g=0.8, b=0.2, a=1.0),
                        )
                    ],
                    texts=[
                        fm.TextPrimitive(
                            pose=fm.Pose(position=label),
                            billboard=True,
                            font_size=14.0,
                            scale_invariant=True,
                            color=fm.Color(r=1.0, g=1.0, b=1.0, a=1.0),
                            text=beacon.id,
                        )
                    ],
                )
            )
        self._beacons.log(fm.SceneUpdate(entities=entities))
