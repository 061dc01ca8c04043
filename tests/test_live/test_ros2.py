"""``mast ros2`` against a Cyclone DDS publisher and subscriber over loopback, as a ROS 2
robot's driver and its navigation stack would be.

Every wait is on a condition (a match, a sample) with a guard against a hang, never a
measured time: the poses equal ``mast locate``'s on the same scans within 0.1 mm and
1 arc-second, none is lost while the locator keeps up, a subscriber that joins late
gets the next poses, and Ctrl-C or SIGTERM end the node cleanly.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
import pytest

from mast.core.frames import UNOBSERVED_VARIANCE
from mast.core.pose import Pose2D
from mast.core.scan import Scan, stamp_of
from mast.live.ros2_msgs import (
    Header,
    LaserScan,
    PoseWithCovarianceStamped,
    String,
    TFMessage,
    Time,
    dds_topic,
    laserscan_message,
    pose_message,
    tf_message,
)
from mast.live.sources import read_run
from tests._cli import run_mast_text
from tests.test_live.conftest import Drive

cyclonedds = pytest.importorskip("cyclonedds")

from cyclonedds.core import Policy, Qos, ReadCondition, SampleState, WaitSet  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from mast.live.ros2 import LOOPBACK_CONFIG, ScanPublisher  # noqa: E402

#: A guard against a hang, not a measure of speed.
HANG_S = float(os.environ.get("MAST_TEST_HANG_S", "120"))
#: How many of the drive's scans the equality test publishes.
SCANS = 40


def _worker_domains() -> Iterator[int]:
    """DDS domains no other test process uses at the same time: the domains 1-200 shared
    out among the parallel test processes, each cycling through its own (its tests run
    one after the other, each ending its node)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw"))
    block = 200 // max(workers, 1)
    if block < 1:
        raise RuntimeError(f"{workers} test processes: more than the 200 DDS domains")
    return itertools.cycle(range(1 + worker * block, 1 + (worker + 1) * block))


_domains = _worker_domains()


@pytest.fixture
def domain(monkeypatch: pytest.MonkeyPatch) -> int:
    """A DDS domain of its own for each test (tests run in parallel processes)."""
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK_CONFIG)
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    return next(_domains)


class Subscriber:
    """A ROS 2 subscriber's reader: its samples, waited for by condition."""

    def __init__(self, dp: DomainParticipant, topic: str, kind: type, *, keep: bool = True):
        # transient-local: a sample written while the node's writer had not yet matched this
        # reader (discovery is not symmetric in time) still arrives
        qos = Qos(
            Policy.Reliability.Reliable(duration(milliseconds=100)),
            Policy.Durability.TransientLocal if keep else Policy.Durability.Volatile,
            Policy.History.KeepLast(1000),
        )
        self.reader = DataReader(dp, Topic(dp, dds_topic(topic), kind), qos=qos)
        self._waitset = WaitSet(dp)
        self._waitset.attach(ReadCondition(self.reader, SampleState.Any))
        self.samples: list[Any] = []

    def matched(self) -> int:
        return len(self.reader.get_matched_publications())

    def poll(self) -> None:
        """Take what has come."""
        self.samples.extend(self.reader.take(N=100))

    def until(self, done: Callable[[], bool], *, patience: float | None = None) -> bool:
        """Take samples until ``done()``. Without ``patience`` a hang guard fails the
        test; with it, False once that many seconds of waits went by in vain."""
        waited = 0.0
        while not done():
            self._waitset.wait(duration(milliseconds=50))
            self.samples.extend(self.reader.take(N=100))
            waited += 0.05
            if patience is not None and waited >= patience:
                return False
            assert waited < HANG_S, "no sample came"
        return True


def _deliver(publisher: ScanPublisher, fixes: Subscriber, scan: Scan) -> None:
    """Publish ``scan`` until its record comes back: a sample written before the node's
    reader has discovered a new writer is lost (best effort), as a sample may be on any
    network; the stamp is the record's key."""

    def recorded() -> bool:
        return any(json.loads(s.data)["stamp_ns"] == scan.stamp_ns for s in fixes.samples)

    for _ in range(int(HANG_S)):
        publisher.publish(scan)
        if fixes.until(recorded, patience=1.0):
            return
    raise AssertionError("the scan was never located")


def _wait(condition: Callable[[], bool], what: str) -> None:
    event = threading.Event()
    for _ in range(int(HANG_S / 0.02)):
        if condition():
            return
        event.wait(0.02)
    raise AssertionError(f"waited in vain for {what}")


@dataclass
class Node:
    """``mast ros2`` running, its records going to a file (a pipe nobody reads would fill
    and stop it)."""

    proc: subprocess.Popen[bytes]
    records: IO[bytes]
    listening: str = ""
    """Its first line on standard error: it has joined the domain, ready."""

    def finish(self) -> tuple[list[dict[str, Any]], str]:
        """Its records and standard error once it has ended."""
        _, err = self.proc.communicate(timeout=HANG_S)
        self.records.seek(0)
        return [json.loads(line) for line in self.records.read().splitlines()], err.decode()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.communicate(timeout=30)
        self.records.close()


def _start(drive: Drive, domain: int, *args: str) -> Node:
    records = tempfile.TemporaryFile()  # noqa: SIM115 - closed by Node.stop
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mast",
            "ros2",
            "-b",
            str(drive.beacons),
            "--range-sigma",
            "0.012",
            "--domain-id",
            str(domain),
            *args,
        ],
        stdout=records,
        stderr=subprocess.PIPE,
    )
    assert proc.stderr is not None
    # ready (compiled, joined) before the test publishes: a node still compiling would
    # locate the test's first scans late, and drop some
    return Node(proc, records, proc.stderr.readline().decode())


def _scans(drive: Drive, n: int) -> list[Scan]:
    scans = read_run(drive.bag)
    return [scan for _, scan in zip(range(n), scans, strict=False)]


def _azimuth_deg(msg: PoseWithCovarianceStamped) -> float:
    q = msg.pose.pose.orientation
    yaw = 2 * math.atan2(q.z, q.w)
    return math.degrees(math.pi / 2 - yaw) % 360.0


def _stamp(header: Header) -> int:
    return stamp_of(header.stamp.sec, header.stamp.nanosec)


@pytest.fixture
def node(drive: Drive, domain: int) -> Iterator[tuple[DomainParticipant, Node]]:
    dp = DomainParticipant(domain)
    running = _start(drive, domain)
    try:
        assert running.listening.startswith("mast: listening on /scan"), running.listening
        yield dp, running
    finally:
        running.stop()


def test_the_poses_equal_locates_on_the_same_scans_and_none_is_lost(
    node: tuple[DomainParticipant, Node], drive: Drive, tmp_path: Path
) -> None:
    dp, proc = node
    scans = _scans(drive, SCANS)
    publisher = ScanPublisher(dp, "/scan", reliable=True)
    poses = Subscriber(dp, "/mast/pose", PoseWithCovarianceStamped)
    tf = Subscriber(dp, "/tf", TFMessage)
    fixes = Subscriber(dp, "/mast/fix", String)
    _wait(
        lambda: publisher.matched() and poses.matched() and tf.matched() and fixes.matched(),
        "the node to match the test's publisher and subscribers",
    )
    # the first scan until it is located (the node's reader may not know the new writer
    # yet); then a scan at a time, the next once its record is out: the locator keeps up
    _deliver(publisher, fixes, scans[0])
    first = len(fixes.samples)
    for i, scan in enumerate(scans[1:], start=first):
        publisher.publish(scan)
        fixes.until(lambda i=i: len(fixes.samples) > i)
    records = [json.loads(s.data) for s in fixes.samples]
    proc.proc.send_signal(signal.SIGINT)
    printed, err = proc.finish()
    assert proc.proc.returncode == 130, err
    assert printed == records
    n = len(records)
    assert f"{n} scans received, {n} located" in err
    assert "0 dropped" in err
    assert [r["stamp_ns"] for r in records[first - 1 :]] == [s.stamp_ns for s in scans]
    assert [r["dropped"] for r in records] == [0] * n
    fixed = [r for r in records if r["status"] == "fix"]
    assert len(fixed) >= SCANS // 2
    poses.until(lambda: len(poses.samples) >= len(fixed))
    tf.until(lambda: len(tf.samples) >= len(fixed))
    assert len(poses.samples) == len(tf.samples) == len(fixed)

    # the same scans, as a bag, through mast locate
    from mast.io.bags import write_laserscans

    bag = tmp_path / "same.bag"
    by_stamp = {s.stamp_ns: s for s in scans}
    write_laserscans(bag, [by_stamp[r["stamp_ns"]] for r in records])  # as the node saw them
    done = run_mast_text(
        "locate", str(bag), "-b", str(drive.beacons), "--range-sigma", "0.012", "--format", "json"
    )
    assert done.returncode == 0, done.stderr
    ordered = [json.loads(line) for line in done.stdout.splitlines()]
    assert [r["status"] for r in ordered] == [r["status"] for r in records]
    located = {r["stamp_ns"]: r for r in ordered[first - 1 :]}
    for msg, t in zip(poses.samples, tf.samples, strict=True):
        ref = located[_stamp(msg.header)]
        assert msg.header.frame_id == "map"
        p = msg.pose.pose.position
        assert math.hypot(p.x - ref["easting"], p.y - ref["northing"]) < 1e-4
        assert p.z == 0.0
        turn = (_azimuth_deg(msg) - ref["azimuth_deg"] + 180.0) % 360.0 - 180.0
        assert abs(turn) * 3600 < 1.0
        cov = np.reshape(msg.pose.covariance, (6, 6))
        c = np.asarray(ref["covariance"])
        assert cov[0, 0] == pytest.approx(c[0, 0], rel=1e-9)
        assert cov[1, 1] == pytest.approx(c[1, 1], rel=1e-9)
        assert cov[5, 5] == pytest.approx(c[2, 2], rel=1e-9)
        assert cov[0, 5] == pytest.approx(-c[0, 2], rel=1e-9, abs=1e-18)  # yaw turns the other way
        assert cov[2, 2] == cov[3, 3] == cov[4, 4] == UNOBSERVED_VARIANCE
        assert np.allclose(cov, cov.T)
        (ts,) = t.transforms
        assert _stamp(ts.header) == _stamp(msg.header)
        assert (ts.header.frame_id, ts.child_frame_id) == ("map", scans[0].frame_id)
        assert (ts.transform.translation.x, ts.transform.translation.y) == (p.x, p.y)
        assert ts.transform.rotation == msg.pose.pose.orientation


def test_a_subscriber_that_joins_late_gets_the_next_poses_from_a_best_effort_driver(
    node: tuple[DomainParticipant, Node], drive: Drive
) -> None:
    dp, proc = node
    scans = _scans(drive, SCANS)
    publisher = ScanPublisher(dp, "/scan", reliable=False)
    fixes = Subscriber(dp, "/mast/fix", String)
    _wait(lambda: publisher.matched() and fixes.matched(), "the node to match")
    sent = 0

    def send_next() -> None:
        nonlocal sent
        _deliver(publisher, fixes, scans[sent])
        sent += 1

    while sent < SCANS // 2:
        send_next()
    # a volatile subscriber (ROS's default) joins: from its first pose on, it gets every one
    late = Subscriber(dp, "/mast/pose", PoseWithCovarianceStamped, keep=False)
    _wait(late.matched, "the late subscriber to match the node's pose writer")
    joined = sent
    while not late.samples:
        send_next()
        late.poll()
    first = _stamp(late.samples[0].header)
    while sent < SCANS:
        send_next()
    records = [json.loads(s.data) for s in fixes.samples]
    assert first in {r["stamp_ns"] for r in records[joined:]}  # nothing from before it joined
    owed = [r["stamp_ns"] for r in records if r["status"] == "fix" and r["stamp_ns"] >= first]
    assert len(owed) >= SCANS // 4
    late.until(lambda: len(late.samples) >= len(owed))
    assert [_stamp(m.header) for m in late.samples] == owed
    proc.proc.send_signal(signal.SIGINT)
    _, err = proc.finish()
    assert proc.proc.returncode == 130, err


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_or_sigterm_end_the_node_cleanly(
    drive: Drive, domain: int, signum: int, status: int
) -> None:
    node = _start(drive, domain)
    try:
        assert node.listening.startswith(f"mast: listening on /scan in DDS domain {domain}")
        node.proc.send_signal(signum)
        printed, err = node.finish()
    finally:
        node.stop()
    assert node.proc.returncode == status
    assert printed == []
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == "mast: interrupted"


def test_a_malformed_scan_is_skipped_counted_and_named_once(drive: Drive, domain: int) -> None:
    dp = DomainParticipant(domain)
    node = _start(drive, domain, "--crs", "local:Mine Grid A")
    try:
        publisher = ScanPublisher(dp, "/scan", reliable=True)
        fixes = Subscriber(dp, "/mast/fix", String)
        _wait(lambda: publisher.matched() and fixes.matched(), "the node to match")
        first, second = _scans(drive, 2)
        _deliver(publisher, fixes, first)  # the node's reader knows the writer now
        bad = laserscan_message(second)
        bad.angle_max = bad.angle_min + 1.0  # disagrees with the increment: damaged
        for _ in range(3):
            publisher.write(bad)
        n = len(fixes.samples)
        publisher.publish(second)
        fixes.until(lambda: len(fixes.samples) > n)
        node.proc.send_signal(signal.SIGINT)
        printed, text = node.finish()
    finally:
        node.stop()
    assert node.proc.returncode == 130, text
    assert text.count("malformed LaserScan skipped") == 1
    assert "3 malformed skipped" in text
    assert printed[-1]["stamp_ns"] == second.stamp_ns  # and the node went on
    assert {r["crs"]["name"] for r in printed} == {"Mine Grid A"}
    assert json.loads(fixes.samples[0].data)["crs"] == printed[0]["crs"]


def test_a_bag_published_by_mast_emulate_ros2_is_located(drive: Drive, domain: int) -> None:
    node = _start(drive, domain, "--max-scans", "20")
    try:
        assert node.listening.startswith("mast: listening on /scan")
        played = subprocess.run(
            [
                *(sys.executable, "-m", "mast", "emulate", "ros2", "--from", str(drive.bag)),
                *("--domain-id", str(domain), "--hz", "25"),
            ],
            capture_output=True,
            text=True,
            timeout=HANG_S,
            check=False,
        )
        printed, text = node.finish()
    finally:
        node.stop()
    assert played.returncode == 0, played.stderr
    assert played.stderr.strip().splitlines()[-1] == f"mast: published {drive.scans} scans"
    assert node.proc.returncode == 0, text
    assert len(printed) + sum(r["dropped"] for r in printed) == 20
    stamps = {s.stamp_ns for s in read_run(drive.bag)}
    assert {r["stamp_ns"] for r in printed} <= stamps  # stamps as recorded
    assert any(r["status"] == "fix" for r in printed)


def test_a_driver_that_restarts_is_taken_up_again(drive: Drive, domain: int) -> None:
    dp = DomainParticipant(domain)
    node = _start(drive, domain)
    try:
        fixes = Subscriber(dp, "/mast/fix", String)
        first, second = _scans(drive, 2)
        for scan in (first, second):
            driver = DomainParticipant(domain)  # the driver's own process, as on a robot
            publisher = ScanPublisher(driver, "/scan", reliable=True)
            _wait(lambda p=publisher: p.matched() and fixes.matched(), "the node to match")
            _deliver(publisher, fixes, scan)
            del publisher, driver  # the driver leaves: its writer's end reaches the node
        node.proc.send_signal(signal.SIGINT)
        printed, text = node.finish()
    finally:
        node.stop()
    assert node.proc.returncode == 130, text
    assert {r["stamp_ns"] for r in printed} == {first.stamp_ns, second.stamp_ns}
    assert "malformed" not in text
    assert "Traceback" not in text


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--domain-id", "233"), "--domain-id 233: ROS 2 domains are 0-232"),
        (("--scan-topic", "two words"), "topic 'two words': give a ROS 2 topic name"),
        (("--frame", ""), "--frame '': give a frame id such as map"),
        (("--timeout", "0"), "--timeout must be a positive number of seconds"),
    ],
)
def test_bad_options_are_one_line_errors(
    drive: Drive, domain: int, args: tuple[str, ...], message: str
) -> None:
    done = run_mast_text("ros2", "-b", str(drive.beacons), "--domain-id", str(domain), *args)
    assert done.returncode == 2
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert "Traceback" not in done.stderr


@pytest.mark.parametrize("value", ["abc", "300"])
def test_a_ros_domain_id_that_is_no_domain_is_named_not_taken_for_0(
    drive: Drive, value: str
) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "mast", "ros2", "-b", str(drive.beacons)],
        capture_output=True,
        text=True,
        timeout=HANG_S,
        check=False,
        env=dict(os.environ, ROS_DOMAIN_ID=value),
    )
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"mast: error: $ROS_DOMAIN_ID '{value}': ROS 2 domains are 0-232")


@pytest.mark.parametrize("azimuth_deg", [0.0, 30.0, 90.0, 200.0, 359.5])
def test_the_pose_and_transform_put_a_scanner_point_where_the_grid_has_it(
    azimuth_deg: float,
) -> None:
    """Both ways: a point 2 m ahead of the scanner and 1 m to its left lies, in the grid,
    at azimuth + 0° and azimuth - 90° (DESIGN.md's formula); the transform and the pose's
    quaternion must send it there, and back."""
    pose = Pose2D.from_degrees(1000.0, 2000.0, azimuth_deg)
    a = math.radians(azimuth_deg)
    ahead, left = 2.0, 1.0
    grid = np.array(
        [
            1000.0 + ahead * math.sin(a) + left * math.sin(a - math.pi / 2),
            2000.0 + ahead * math.cos(a) + left * math.cos(a - math.pi / 2),
        ]
    )
    msg = pose_message(pose, np.diag([1e-6, 4e-6, 1e-8]), stamp=5, frame="map")
    (ts,) = tf_message(pose, stamp=5, frame="map", child="laser").transforms
    for q, t in ((msg.pose.pose.orientation, msg.pose.pose.position), (ts.transform.rotation,
                 ts.transform.translation)):  # fmt: skip
        yaw = 2 * math.atan2(q.z, q.w)
        R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
        assert R @ [ahead, left] + [t.x, t.y] == pytest.approx(grid, abs=1e-9)
        assert R.T @ (grid - [t.x, t.y]) == pytest.approx([ahead, left], abs=1e-9)
    cov = np.reshape(msg.pose.covariance, (6, 6))
    assert np.diag(cov)[[0, 1, 5]] == pytest.approx([1e-6, 4e-6, 1e-8])
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 5)


def test_a_laserscan_round_trips_through_its_dds_sample(drive: Drive) -> None:
    (scan,) = _scans(drive, 1)
    sample = LaserScan.deserialize(laserscan_message(scan).serialize())
    back = Scan.from_message(sample)
    assert (back.stamp_ns, back.frame_id) == (scan.stamp_ns, scan.frame_id)
    assert np.array_equal(back.ranges_m, scan.ranges_m.astype(np.float32), equal_nan=True)
    assert np.allclose(back.angles_rad, scan.angles_rad, atol=1e-6)
    assert isinstance(sample.header.stamp, Time)
    # plain CDR, little-endian, as every ROS 2 middleware writes it
    assert laserscan_message(scan).serialize()[:2] == b"\x00\x01"


@pytest.mark.parametrize(
    ("name", "dds"), [("/scan", "rt/scan"), ("scan", "rt/scan"), ("/robot1/scan", "rt/robot1/scan")]
)
def test_ros_topic_names_map_to_dds_topics(name: str, dds: str) -> None:
    assert dds_topic(name) == dds
