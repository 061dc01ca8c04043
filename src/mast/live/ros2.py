"""A ROS 2 participant over DDS, without a ROS installation: scans in, poses out.

``mast ros2`` joins a DDS domain through Eclipse Cyclone DDS's Python binding and
speaks ROS 2's wire format (:mod:`mast.live.ros2_msgs`), so any ROS 2 node of any
middleware that speaks RTPS sees it as one of its own:

* :class:`Ros2Source` subscribes to a ``sensor_msgs/LaserScan`` topic, best effort
  (it takes reliable and best-effort publishers alike), and yields each scan as it
  arrives; the live loop (:func:`mast.live.session.run_live`) locates the newest one
  first, exactly as for a scanner on TCP.
* :class:`Ros2Publisher` publishes each fix as ``geometry_msgs/PoseWithCovarianceStamped``
  on ``/mast/pose`` and the grid-to-scanner transform on ``/tf``, and every located
  scan's JSON record as ``std_msgs/String`` on ``/mast/fix``: reliable, keeping the last
  10 for a transient-local subscriber that joins late (a volatile one, ROS's default,
  gets the poses from then on).
* :class:`ScanPublisher` publishes scans as a ROS 2 driver does (the tests, the
  benchmark and ``mast emulate ros2``).

The DDS domain is ``--domain-id`` (ROS_DOMAIN_ID's meaning); Cyclone DDS reads its
network configuration from ``CYCLONEDDS_URI`` as usual.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from cyclonedds.core import Policy, Qos, ReadCondition, SampleState, WaitSet
from cyclonedds.domain import DomainParticipant
from cyclonedds.internal import InvalidSample
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.ros2_msgs import (
    LaserScan,
    PoseWithCovarianceStamped,
    String,
    TFMessage,
    dds_topic,
    laserscan_message,
    pose_message,
    tf_message,
)
from mast.live.sources import paced
from mast.live.stream import Received, Source, SourceOptions
from mast.pipeline.locator import Fix

__all__ = [
    "LOOPBACK_CONFIG",
    "Ros2Publisher",
    "Ros2Source",
    "ScanPublisher",
    "leave",
    "participant",
    "play",
    "ros2_domain",
]

#: ROS 2's domain ids: 0-232 (the port mapping of RTPS leaves no room above).
MAX_DOMAIN_ID = 232

#: A Cyclone DDS configuration (for ``CYCLONEDDS_URI``) that keeps a participant on
#: loopback, discovering its peers by unicast: the tests and the benchmark see no other
#: host's traffic and need no multicast route.
LOOPBACK_CONFIG = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30"
    '</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery>'
    "</Domain></CycloneDDS>"
)

#: Samples taken in one wake-up at most, so that a flood cannot starve the stop check.
_TAKE_AT_MOST = 256

# Writers use plain CDR (XCDR1), as every ROS 2 middleware does; readers take either.
_XCDR1 = Policy.DataRepresentation(use_cdrv0_representation=True)
_EITHER = Policy.DataRepresentation(use_cdrv0_representation=True, use_xcdrv2_representation=True)


def ros2_domain() -> int:
    """The ROS 2 domain of this shell: ``$ROS_DOMAIN_ID``, else 0; one that is not a
    domain is an InputError naming the variable (not someone else's domain 0)."""
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    if not text.isdigit() or int(text) > MAX_DOMAIN_ID:
        raise InputError(
            f"$ROS_DOMAIN_ID {text!r}: ROS 2 domains are 0-{MAX_DOMAIN_ID} (or give --domain-id)"
        )
    return int(text)


def leave(dp: DomainParticipant) -> None:
    """Leave the DDS domain now, not whenever the collector gets to it: the participant
    and everything it made are deleted (Cyclone DDS first lets a reliable writer's last
    samples be acknowledged) and the others see it go at once, not at its lease's end."""
    dp.__del__()  # the binding's delete; it also forgets the entity, so it runs once


def participant(domain_id: int) -> DomainParticipant:
    """A DDS participant in ROS 2 domain ``domain_id``; a domain that cannot be joined
    (a bad ``CYCLONEDDS_URI``, no usable network interface) is an InputError."""
    if not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise InputError(f"--domain-id {domain_id}: ROS 2 domains are 0-{MAX_DOMAIN_ID}")
    try:
        return DomainParticipant(domain_id)
    except Exception as err:  # the binding raises DDSException with the C library's code
        raise InputError(
            f"cannot join DDS domain {domain_id}: {err} (check CYCLONEDDS_URI)"
        ) from None


def _reliable(depth: int, *, keep: bool = False) -> Qos:
    """Reliable, and with ``keep`` transient-local: a reader that asks for it gets the last
    ``depth`` samples on joining (one that matched a moment after a sample was written
    too); a volatile reader, ROS's default, gets the next ones. Either matches."""
    return Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.TransientLocal if keep else Policy.Durability.Volatile,
        Policy.History.KeepLast(depth),
        _XCDR1,
    )


class Ros2Source(Source):
    """LaserScans from a ROS 2 topic as they arrive (see the module).

    The run goes on until stopped: no scan for ``options.timeout_s`` is said once (with
    how many publishers the topic has), and no scan for ``options.give_up_s`` ends it
    when that is finite.
    """

    def __init__(
        self, dp: DomainParticipant, topic: str, options: SourceOptions, *, url: str
    ) -> None:
        super().__init__(url, options)
        self.topic = topic
        self._dp = dp
        self._reader = DataReader(
            dp,
            Topic(dp, dds_topic(topic), LaserScan),
            qos=Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(8), _EITHER),
        )

    def scans(self, stop: threading.Event, warn: Callable[[str], None]) -> Iterator[Received]:
        o = self.options
        waitset = WaitSet(self._dp)
        waitset.attach(ReadCondition(self._reader, SampleState.NotRead))
        last = time.perf_counter()
        gap: float | None = None
        said_quiet = False

        def malformed(problem: str) -> None:
            self.stats.malformed += 1
            if not self.stats.first_malformed:  # named once, counted always
                self.stats.first_malformed = problem
                warn(f"{self.topic}: malformed LaserScan skipped: {problem}")

        while not stop.is_set():
            waitset.wait(duration(milliseconds=100))
            for msg in self._take():
                if isinstance(msg, str):
                    malformed(msg)
                    continue
                try:
                    scan = Scan.from_message(msg)
                except InputError as err:
                    malformed(err.problem)
                    continue
                if o.range_min_m is not None or o.range_max_m is not None:
                    scan = scan.with_range_limits(o.range_min_m, o.range_max_m)
                now = time.perf_counter()
                self.stats.scans += 1
                yield Received(scan, time.time_ns(), now, gap)
                last, gap, said_quiet = now, None, False
            quiet = time.perf_counter() - last
            if quiet > o.timeout_s and not said_quiet:
                n = len(self._reader.get_matched_publications())
                warn(
                    f"no scan on {self.topic} for {quiet:.1f} s "
                    f"({n} publisher{'s' if n != 1 else ''} of sensor_msgs/LaserScan matched)"
                )
                said_quiet = True
                gap = quiet
            if quiet > o.give_up_s:
                return
            if gap is not None:
                gap = quiet

    def _take(self) -> Iterator[LaserScan | str]:
        """The scans waiting, one at a time (one the binding cannot decode costs only
        itself): a LaserScan, or what was wrong with one. A publisher that leaves (a
        driver restarted) shows as a sample without data: not a scan."""
        for _ in range(_TAKE_AT_MOST):
            try:
                samples = self._reader.take(N=1)
            except Exception as err:  # a sample the binding cannot decode
                yield f"the sample could not be decoded ({type(err).__name__}: {err})"
                continue
            if not samples:
                return
            (sample,) = samples
            if not isinstance(sample, InvalidSample):
                yield sample


class Ros2Publisher:
    """Each record published: the pose and the transform of a fix, the JSON of every one
    (a :class:`~mast.live.session.Sink` of the live loop)."""

    def __init__(self, dp: DomainParticipant, *, frame: str, tf: bool = True) -> None:
        if not frame.strip() or any(c.isspace() for c in frame):
            raise InputError(f"--frame {frame!r}: give a frame id such as map")
        self.frame = frame

        def writer(topic: str, kind: type) -> DataWriter[Any]:
            return DataWriter(dp, Topic(dp, dds_topic(topic), kind), qos=_reliable(10, keep=True))

        self._pose = writer("/mast/pose", PoseWithCovarianceStamped)
        self._fix = writer("/mast/fix", String)
        self._tf = writer("/tf", TFMessage) if tf else None

    def scan(self, scan: Scan) -> None:
        """Scans are the robot's own: not published again."""

    def fix(self, scan: Scan, fix: Fix, record: dict[str, Any]) -> None:
        """``fix`` of ``scan`` (stamped as the scan) and its ``record``."""
        if fix.ok and fix.pose is not None and fix.adjustment is not None:
            cov = fix.adjustment.covariance
            self._pose.write(pose_message(fix.pose, cov, stamp=scan.stamp_ns, frame=self.frame))
            child = scan.frame_id or "laser"
            if self._tf is not None and child != self.frame:  # no frame is its own child
                self._tf.write(
                    tf_message(fix.pose, stamp=scan.stamp_ns, frame=self.frame, child=child)
                )
        self._fix.write(String(json.dumps(record)))


def play(
    scans: Iterable[Scan],
    publisher: ScanPublisher,
    *,
    stop: threading.Event,
    hz: float | None = None,
) -> int:
    """Publish ``scans`` as a driver would: at their recorded spacing, or ``hz`` a
    second (:func:`mast.live.sources.paced`), stamps as recorded, until they end or
    ``stop`` is set; how many were sent."""
    sent = 0
    for scan in paced(scans, stop, hz=hz):
        publisher.publish(scan)
        sent += 1
    return sent


class ScanPublisher:
    """Scans published on a ROS 2 topic as a driver does (reliable or best effort)."""

    def __init__(self, dp: DomainParticipant, topic: str = "/scan", *, reliable: bool = False):
        qos = (
            _reliable(10)
            if reliable
            else Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(10), _XCDR1)
        )
        self._writer = DataWriter(dp, Topic(dp, dds_topic(topic), LaserScan), qos=qos)

    def matched(self) -> int:
        """Subscribers matched now."""
        return len(self._writer.get_matched_subscriptions())

    def publish(self, scan: Scan) -> None:
        self._writer.write(laserscan_message(scan))

    def write(self, message: Any) -> None:
        """Any sample of the topic's type (a test's malformed message)."""
        self._writer.write(message)
