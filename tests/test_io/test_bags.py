import math
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from mast import InputError, Scan
from mast.io import bag_kind, list_topics, read_laserscans, write_laserscans
from mast.io.scan_csv import write_scan_csv
from tests._paths import SHARED_DATA


def _scans(n: int = 3) -> list[Scan]:
    rng = np.random.default_rng(7)
    out = []
    for i in range(n):
        r = rng.uniform(0.5, 25, 541)
        r[::50] = np.nan
        out.append(
            Scan.from_laserscan(
                angle_min=-math.radians(135),
                angle_increment=math.radians(0.5),
                ranges=r,
                range_min=0.05,
                range_max=30.0,
                stamp_ns=1_700_000_000_000_000_000 + i * 100_000_000,
                frame_id="laser",
            )
        )
    return out


@pytest.mark.parametrize(
    ("kind", "name", "detected"),
    [
        ("rosbag1", "scans.bag", "rosbag1"),
        ("sqlite3", "scans_db3", "rosbag2"),
        ("mcap", "scans_mcap", "rosbag2"),
    ],
)
def test_round_trip_every_bag_kind(tmp_path: Path, kind: str, name: str, detected: str) -> None:
    scans = _scans()
    p = tmp_path / name
    assert write_laserscans(p, scans, kind=kind) == 3  # type: ignore[arg-type]
    assert bag_kind(p) == detected
    assert [(t.topic, t.msgtype, t.count) for t in list_topics(p)] == [
        ("/scan", "sensor_msgs/msg/LaserScan", 3)
    ]
    back = list(read_laserscans(p))
    assert len(back) == 3
    for a, b in zip(scans, back, strict=True):
        # LaserScan carries float32: equal to float32 rounding.
        assert_allclose(b.ranges_m[a.valid], a.ranges_m[a.valid], rtol=1e-7)
        assert_array_equal(b.valid, a.valid)
        assert_allclose(b.angles_rad, a.angles_rad, atol=1e-6)
        assert b.stamp_ns == a.stamp_ns
        assert b.range_max_m == 30.0
        assert b.frame_id == "laser"


def test_ros1_bag_found_by_magic_not_name(tmp_path: Path) -> None:
    p = tmp_path / "recording.bag"
    write_laserscans(p, _scans(1))
    q = tmp_path / "recording.data"
    q.write_bytes(p.read_bytes())
    assert bag_kind(q) == "rosbag1"
    assert len(list(read_laserscans(q))) == 1


def test_missing_topic_lists_the_topics(tmp_path: Path) -> None:
    p = tmp_path / "s.bag"
    write_laserscans(p, _scans(1), topic="/front/scan")
    with pytest.raises(
        InputError,
        match=r"s\.bag: bag has no topic '/scan'\. Topics: /front/scan \(sensor_msgs/msg/LaserS",
    ):
        list(read_laserscans(p, topic="/scan"))
    assert len(list(read_laserscans(p, topic="/front/scan"))) == 1


def test_two_laserscan_topics_need_a_choice(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    p = tmp_path / "two.bag"
    store = get_typestore(Stores.ROS1_NOETIC)
    with Writer(p) as w:
        w.add_connection("/a", "sensor_msgs/msg/LaserScan", typestore=store)
        w.add_connection("/b", "sensor_msgs/msg/LaserScan", typestore=store)
    with pytest.raises(
        InputError, match=r"several LaserScan topics; choose one with --topic\. Topics: /a .*, /b"
    ):
        list(read_laserscans(p))


def test_non_laserscan_topic_is_refused(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    p = tmp_path / "imu.bag"
    store = get_typestore(Stores.ROS1_NOETIC)
    with Writer(p) as w:
        w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=store)
    with pytest.raises(
        InputError, match=r"bag has no LaserScan topic.*/imu \(sensor_msgs/msg/Imu\)"
    ):
        list(read_laserscans(p))
    with pytest.raises(
        InputError, match=r"topic '/imu' carries sensor_msgs/msg/Imu, not sensor_msgs/msg/LaserScan"
    ):
        list(read_laserscans(p, topic="/imu"))


def test_truncated_and_foreign_files(tmp_path: Path) -> None:
    p = tmp_path / "s.bag"
    write_laserscans(p, _scans(3))
    cut = tmp_path / "cut.bag"
    cut.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2])
    with pytest.raises(InputError, match=r"cut\.bag: unreadable bag"):
        list(read_laserscans(cut))
    csv = tmp_path / "scan.csv"
    write_scan_csv(csv, _scans(1)[0])
    with pytest.raises(InputError, match=r"not a ROS 1 bag .* nor a ROS 2 bag folder"):
        list(read_laserscans(csv))
    with pytest.raises(InputError, match=r"no metadata\.yaml"):
        list(read_laserscans(tmp_path))
    with pytest.raises(InputError, match="bag not found"):
        list(read_laserscans(tmp_path / "none.bag"))


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    p = tmp_path / "s.bag"
    write_laserscans(p, _scans(1))
    with pytest.raises(InputError, match="exists already"):
        write_laserscans(p, _scans(1))


def test_uneven_beams_cannot_be_a_laserscan(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not evenly spaced"):
        write_laserscans(tmp_path / "u.bag", [Scan([0.0, 0.1, 0.3], [1.0, 1.0, 1.0])])


@pytest.mark.skipif(
    not (SHARED_DATA / "ccny_hokuyo_rosbag").is_dir(), reason="shared data not present"
)
def test_real_bag_with_damaged_index_is_read_by_walking_its_records() -> None:
    # rosbags refuses this bag (its IndexData lengths are wrong); the messages are intact.
    scans = list(read_laserscans(SHARED_DATA / "ccny_hokuyo_rosbag" / "demo.bag"))
    assert len(scans) == 360
    assert all(len(s) == 681 for s in scans)
    assert scans[0].angles_rad[0] == pytest.approx(-2.0862138, abs=1e-6)
    assert scans[0].range_max_m == pytest.approx(5.6, abs=1e-6)
    assert [s.stamp_ns for s in scans] == sorted(s.stamp_ns for s in scans)
    with pytest.raises(InputError, match=r"bag has no topic '/nope'\. Topics: /scan"):
        list(read_laserscans(SHARED_DATA / "ccny_hokuyo_rosbag" / "demo.bag", topic="/nope"))
