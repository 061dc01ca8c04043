"""PointCloud2 frames in and out of bags (issue 36): every bag kind, the layouts drivers
write, and every malformed message a one-line error naming it."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from mast import InputError, Scan, limits
from mast.core.pose3d import Frame3D
from mast.io import bag_kind, list_topics, read_laserscans, read_pointclouds, write_pointclouds
from mast.io.bags import laserscan_bytes
from mast.io.pointclouds import (
    POINTCLOUD2,
    decode_pointcloud,
    pointcloud_bytes,
    pointcloud_count,
    pointcloud_topic,
)

STAMP = 1_700_000_000_123_456_789
FLOAT32, FLOAT64, UINT8, UINT16, UINT32, INT16 = 7, 8, 2, 4, 6, 3


def _frames(n: int = 3, points: int = 500) -> list[Frame3D]:
    rng = np.random.default_rng(36)
    return [
        Frame3D(
            rng.uniform(-40, 40, (points, 3)),
            intensity=rng.uniform(0, 255, points),
            ring=rng.integers(0, 16, points),
            time_s=rng.uniform(0, 0.1, points),
            stamp_ns=STAMP + i * 100_000_000,
            frame_id="os_sensor",
        )
        for i in range(n)
    ]


def _store(ros1: bool = False) -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


def _cloud(
    fields: list[tuple[str, int, int]],
    records: np.ndarray[Any, Any],
    *,
    height: int = 1,
    row_step: int | None = None,
    data: bytes | None = None,
    bigendian: bool = False,
    ros1: bool = False,
    count: int = 1,
) -> Any:
    """A PointCloud2 of the store's types: ``fields`` as (name, offset, datatype), the
    points' bytes from ``records`` (a structured array) unless ``data`` is given."""
    store = _store(ros1)
    T = store.types
    point_step = records.dtype.itemsize
    width = records.size // height
    raw = records.tobytes() if data is None else data
    header: dict[str, Any] = {
        "stamp": T["builtin_interfaces/msg/Time"](sec=STAMP // 10**9, nanosec=STAMP % 10**9),
        "frame_id": "lidar",
    }
    if ros1:
        header["seq"] = 0
    return T[POINTCLOUD2](
        header=T["std_msgs/msg/Header"](**header),
        height=height,
        width=width,
        fields=[
            T["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=count)
            for n, o, d in fields
        ],
        is_bigendian=bigendian,
        point_step=point_step,
        row_step=width * point_step if row_step is None else row_step,
        data=np.frombuffer(raw, dtype=np.uint8),
        is_dense=False,
    )


def _records(
    layout: dict[str, tuple[str, int]], itemsize: int, n: int, **values: Any
) -> np.ndarray[Any, Any]:
    """``n`` points in a structured array of ``layout`` (name -> (numpy type, offset)),
    its fields set from ``values``."""
    dtype = np.dtype(
        {
            "names": list(layout),
            "formats": [t for t, _ in layout.values()],
            "offsets": [o for _, o in layout.values()],
            "itemsize": itemsize,
        }
    )
    out = np.zeros(n, dtype=dtype)
    for name, v in values.items():
        out[name] = v
    return out


def _xyz(n: int, seed: int = 0) -> np.ndarray[Any, Any]:
    return np.random.default_rng(seed).uniform(-30, 30, (n, 3))


def _write_bag(path: Path, kind: str, messages: list[tuple[str, str, int, Any]]) -> None:
    """``(topic, msgtype, stamp_ns, message)`` into a bag of ``kind``, as a recorder does."""
    ros1 = kind == "rosbag1"
    store = _store(ros1)
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(path)
    else:
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=Writer2.VERSION_LATEST, storage_plugin=plugin)
    with writer:
        conns: dict[str, Any] = {}
        for topic, msgtype, stamp, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            raw = store.serialize_ros1(msg, msgtype) if ros1 else store.serialize_cdr(msg, msgtype)
            writer.write(conns[topic], stamp, bytes(raw))


# --- round trips -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "name", "detected"),
    [
        ("rosbag1", "clouds.bag", "rosbag1"),
        ("sqlite3", "clouds_db3", "rosbag2"),
        ("mcap", "clouds_mcap", "rosbag2"),
    ],
)
def test_round_trip_every_bag_kind(tmp_path: Path, kind: str, name: str, detected: str) -> None:
    frames = _frames()
    p = tmp_path / name
    assert write_pointclouds(p, frames, kind=kind) == 3  # type: ignore[arg-type]
    assert bag_kind(p) == detected
    assert [(t.topic, t.msgtype, t.count) for t in list_topics(p)] == [("/points", POINTCLOUD2, 3)]
    assert pointcloud_topic(p) == "/points"
    assert pointcloud_count(p) == 3
    back = list(read_pointclouds(p))
    assert len(back) == 3
    for a, b in zip(frames, back, strict=True):
        # x, y, z and intensity are written as float32: equal to its rounding.
        assert_allclose(b.points, a.points, rtol=1e-7, atol=1e-5)
        assert b.intensity is not None
        assert a.intensity is not None
        assert_allclose(b.intensity, a.intensity, rtol=1e-7)
        assert_array_equal(b.ring, a.ring)  # type: ignore[arg-type]
        assert b.time_s is not None
        assert a.time_s is not None
        assert_allclose(b.time_s, a.time_s, atol=0.6e-9)  # whole nanoseconds
        assert b.stamp_ns == a.stamp_ns
        assert b.frame_id == "os_sensor"


def test_a_bare_mcap_file_is_read(tmp_path: Path) -> None:
    folder = tmp_path / "run"
    write_pointclouds(folder, _frames(2), kind="mcap")
    (inner,) = folder.glob("*.mcap")
    bare = tmp_path / "recording.mcap"
    shutil.copy(inner, bare)
    assert len(list(read_pointclouds(bare))) == 2
    assert pointcloud_count(bare) == 2


def test_a_frame_of_points_only_round_trips_without_the_optional_fields(tmp_path: Path) -> None:
    frame = Frame3D(_xyz(100), stamp_ns=STAMP)
    p = tmp_path / "xyz.bag"
    write_pointclouds(p, [frame])
    (back,) = read_pointclouds(p)
    assert (back.intensity, back.ring, back.time_s) == (None, None, None)
    assert_allclose(back.points, frame.points, atol=1e-5)


def test_times_a_uint32_t_cannot_hold_are_written_as_velodyne_time(tmp_path: Path) -> None:
    n = 50
    times = np.linspace(-0.05, 0.05, n)  # the stamp mid-sweep: half the times before it
    frame = Frame3D(_xyz(n), time_s=times, stamp_ns=STAMP)
    store = _store()
    msg = store.deserialize_cdr(pointcloud_bytes(store, frame, 0, ros1=False), POINTCLOUD2)
    assert [f.name for f in msg.fields] == ["x", "y", "z", "time"]
    assert msg.fields[3].datatype == FLOAT32
    assert_allclose(decode_pointcloud(msg).time_s, times, atol=1e-8)  # type: ignore[arg-type]


def test_the_writer_refuses_a_ring_a_uint16_cannot_hold_and_an_existing_bag(
    tmp_path: Path,
) -> None:
    frame = Frame3D(_xyz(3), ring=[0, 1, 70_000])
    with pytest.raises(InputError, match=r"frame 0: a ring outside 0-65535"):
        write_pointclouds(tmp_path / "r.bag", [frame])
    p = tmp_path / "ok.bag"
    write_pointclouds(p, _frames(1))
    with pytest.raises(InputError, match="exists already; not overwriting a bag"):
        write_pointclouds(p, _frames(1))


# --- the layouts drivers write -----------------------------------------------------------


XYZ_F64 = {"x": ("f8", 0), "y": ("f8", 8), "z": ("f8", 16)}


def test_float64_coordinates() -> None:
    xyz = _xyz(40)
    rec = _records(XYZ_F64, 24, 40, x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2])
    frame = decode_pointcloud(
        _cloud([("x", 0, FLOAT64), ("y", 8, FLOAT64), ("z", 16, FLOAT64)], rec)
    )
    assert_array_equal(frame.points, xyz)  # float64 kept exactly
    assert frame.stamp_ns == STAMP
    assert frame.frame_id == "lidar"


def test_big_endian_data() -> None:
    xyz = _xyz(30)
    layout = {"x": (">f4", 0), "y": (">f4", 4), "z": (">f4", 8), "intensity": (">u2", 12)}
    rec = _records(layout, 14, 30, x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], intensity=np.arange(30))
    fields = [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("intensity", 12, UINT16)]
    frame = decode_pointcloud(_cloud(fields, rec, bigendian=True))
    assert_allclose(frame.points, xyz, rtol=1e-7)
    assert_array_equal(frame.intensity, np.arange(30))  # type: ignore[arg-type]


def test_padding_between_fields_and_the_ouster_t_in_nanoseconds() -> None:
    # Ouster's ROS layout: x y z, 4 bytes of padding, intensity, t (UINT32 ns from the
    # stamp), reflectivity, ring, ambient, range; point_step 48.
    layout = {
        "x": ("<f4", 0),
        "y": ("<f4", 4),
        "z": ("<f4", 8),
        "intensity": ("<f4", 16),
        "t": ("<u4", 20),
        "reflectivity": ("<u2", 24),
        "ring": ("<u2", 26),
        "ambient": ("<u2", 28),
        "range": ("<u4", 32),
    }
    n = 64
    xyz = _xyz(n)
    t_ns = np.arange(n, dtype=np.uint32) * 1_562_500  # 1024 columns at 10 Hz... spread out
    rec = _records(
        layout, 48, n, x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], t=t_ns, ring=np.arange(n) % 16
    )
    rec["reflectivity"] = 0xFFFF  # bytes between the fields MAST reads, all set
    fields = [(name, off, {"<f4": 7, "<u4": 6, "<u2": 4}[t]) for name, (t, off) in layout.items()]
    frame = decode_pointcloud(_cloud(fields, rec))
    assert_allclose(frame.points, xyz, rtol=1e-7)
    assert_allclose(frame.time_s, t_ns * 1e-9)  # type: ignore[arg-type]
    assert_array_equal(frame.ring, np.arange(n) % 16)  # type: ignore[arg-type]


def test_velodyne_time_in_float_seconds_at_unaligned_offsets() -> None:
    # velodyne_pointcloud's XYZIRT packed: x y z intensity (FLOAT32), ring (UINT16) at 16,
    # time (FLOAT32 seconds from the stamp) at 18: unaligned.
    layout = {
        "x": ("<f4", 0),
        "y": ("<f4", 4),
        "z": ("<f4", 8),
        "intensity": ("<f4", 12),
        "ring": ("<u2", 16),
        "time": ("<f4", 18),
    }
    n = 32
    xyz = _xyz(n)
    times = np.linspace(0, 0.099, n).astype(np.float32)
    rec = _records(layout, 22, n, x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], time=times, ring=7)
    fields = [(name, off, 4 if name == "ring" else 7) for name, (_, off) in layout.items()]
    frame = decode_pointcloud(_cloud(fields, rec))
    assert_allclose(frame.time_s, times)  # type: ignore[arg-type]
    assert_array_equal(frame.ring, np.full(n, 7))  # type: ignore[arg-type]
    assert_allclose(frame.points, xyz, rtol=1e-7)


def test_an_organised_cloud_with_nan_holes_and_padded_rows() -> None:
    height, width, step = 4, 6, 16
    xyz = _xyz(height * width)
    xyz[[1, 7, 20]] = np.nan  # no return
    xyz[13, 2] = np.inf
    layout = {"x": ("<f4", 0), "y": ("<f4", 4), "z": ("<f4", 8), "ring": ("<u1", 12)}
    rings = np.repeat(np.arange(height), width)
    rec = _records(layout, step, height * width, x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], ring=rings)
    # Each row followed by 8 bytes of padding: row_step 104, not 96.
    rows = rec.tobytes()
    row_step = width * step + 8
    data = b"".join(rows[r * width * step : (r + 1) * width * step] + b"\xee" * 8 for r in range(4))
    fields = [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("ring", 12, UINT8)]
    frame = decode_pointcloud(_cloud(fields, rec, height=height, row_step=row_step, data=data))
    keep = np.isfinite(xyz).all(axis=1)
    assert len(frame) == height * width - 4
    assert_allclose(frame.points, xyz[keep], rtol=1e-7)
    assert_array_equal(frame.ring, rings[keep])  # type: ignore[arg-type]


def test_an_empty_cloud_is_a_frame_of_no_points() -> None:
    rec = _records({"x": ("<f4", 0), "y": ("<f4", 4), "z": ("<f4", 8)}, 12, 0)
    frame = decode_pointcloud(_cloud([("x", 0, 7), ("y", 4, 7), ("z", 8, 7)], rec))
    assert len(frame) == 0


def test_a_ros1_message_and_an_rclpy_like_one_with_bytes() -> None:
    rec = _records({"x": ("<f4", 0), "y": ("<f4", 4), "z": ("<f4", 8)}, 12, 5, x=1.0, y=2, z=3)
    fields = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7)]
    assert_array_equal(decode_pointcloud(_cloud(fields, rec, ros1=True)).points[0], [1, 2, 3])
    msg = _cloud(fields, rec)
    like = SimpleNamespace(**{k: getattr(msg, k) for k in msg.__dataclass_fields__})
    like.data = rec.tobytes()  # rclpy gives bytes or an array.array
    assert len(decode_pointcloud(like)) == 5


# --- malformed messages ------------------------------------------------------------------

XYZ = [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32)]
REC = _records({"x": ("<f4", 0), "y": ("<f4", 4), "z": ("<f4", 8)}, 16, 10, x=1.0, y=2.0, z=3.0)


@pytest.mark.parametrize(
    ("fields", "kw", "message"),
    [
        (
            XYZ[:2] + [("intensity", 12, FLOAT32)],
            {},
            r"no field 'z' \(its fields: 'x', 'y', 'intens",
        ),
        ([], {}, r"no field 'x' \(its fields: none\)"),
        (XYZ, {"data": b"\x00" * 150}, r"data is 150 bytes, short of the 160 that 10 points of 16"),
        (
            XYZ,
            {"height": 2, "data": b"\x00" * 150},
            r"data is 150 bytes, short of the 160 that 2 rows of 5 points of 16 bytes need",
        ),
        (
            XYZ,
            {"height": 2, "row_step": 60},
            r"row_step 60 is less than width 5 x point_step 16; the rows would overlap",
        ),
        (
            [*XYZ[:2], ("z", 12, FLOAT64)],
            {},
            r"field 'z' \(FLOAT64 at offset 12\) ends at byte 20, past point_step 16",
        ),
        (
            [*XYZ, ("t", 14, UINT32)],
            {},
            r"field 't' \(UINT32 at offset 14\) ends at byte 18, past point_step 16",
        ),
        ([*XYZ[:2], ("z", 8, 0)], {}, r"field 'z' has datatype 0, not one of PointField's number"),
        ([*XYZ, ("ring", 12, 9)], {}, r"field 'ring' has datatype 9, not one of PointField's"),
        ([*XYZ[:2], ("z", 8, INT16)], {}, r"field 'z' is INT16; a coordinate must be FLOAT32 or"),
        ([*XYZ, ("x", 12, FLOAT32)], {}, r"field 'x' appears twice"),
        (XYZ, {"count": 3}, r"field 'x' has count 3; MAST reads one number a point"),
    ],
)
def test_a_malformed_message_is_a_one_line_error(
    fields: list[tuple[str, int, int]], kw: dict[str, Any], message: str
) -> None:
    with pytest.raises(InputError, match=message) as err:
        decode_pointcloud(_cloud(fields, REC, **kw))
    assert "\n" not in str(err.value)


def test_more_points_than_the_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(limits, "MAX_CLOUD_POINTS", 9)
    with pytest.raises(
        InputError,
        match=r"10 points \(1 x 10\), more than the 9 MAST takes in one frame "
        r"\(mast.limits.MAX_CLOUD_POINTS\)",
    ):
        decode_pointcloud(_cloud(XYZ, REC))


def test_a_ring_that_is_no_ring_number() -> None:
    rec = _records({"x": ("<f4", 0), "y": ("<f4", 4), "z": ("<f4", 8), "ring": ("<u4", 12)}, 16, 2)
    rec["ring"] = [1, 2**31]
    with pytest.raises(InputError, match=r"field 'ring' holds 2147483648, beyond any ring"):
        decode_pointcloud(_cloud([*XYZ, ("ring", 12, UINT32)], rec))
    rec = _records({"x": ("<f4", 0), "y": ("<f4", 4), "z": ("<f4", 8), "ring": ("<f4", 12)}, 16, 2)
    rec["ring"] = [1, 2.5]
    with pytest.raises(InputError, match=r"field 'ring' holds a value that is not a whole"):
        decode_pointcloud(_cloud([*XYZ, ("ring", 12, FLOAT32)], rec))
    rec["ring"] = [1, 3]  # a float ring of whole numbers is read
    assert_array_equal(decode_pointcloud(_cloud([*XYZ, ("ring", 12, FLOAT32)], rec)).ring, [1, 3])  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", ["rosbag1", "sqlite3", "mcap"])
def test_a_malformed_message_in_a_bag_is_named_skipped_and_counted(
    tmp_path: Path, kind: str
) -> None:
    ros1 = kind == "rosbag1"
    good = _cloud(XYZ, REC, ros1=ros1)
    bad = _cloud(XYZ[:2], REC, ros1=ros1)
    short = _cloud(XYZ, REC, ros1=ros1, data=b"\x00" * 8)
    msgs = [good, bad, good, short, good]
    p = tmp_path / f"run_{kind}"
    _write_bag(p, kind, [("/points", POINTCLOUD2, STAMP + k, m) for k, m in enumerate(msgs)])
    with pytest.raises(
        InputError,
        match=r"run_\w+: message 2 of /points cannot be decoded: no field 'z' \(its fields: 'x',",
    ) as err:
        list(read_pointclouds(p))
    assert "\n" not in str(err.value)
    told: list[str] = []
    got = list(read_pointclouds(p, on_skip=told.append))
    assert len(got) == 3
    assert len(told) == 2
    assert "message 2 of /points cannot be decoded: no field 'z'" in told[0]
    assert "message 4 of /points cannot be decoded: data is 8 bytes, short of the 160" in told[1]
    assert all(t.endswith("; skipped") for t in told)


def test_a_ros1_bag_cut_short_gives_the_frames_before_the_damage(tmp_path: Path) -> None:
    whole = tmp_path / "run.bag"
    frames = _frames(12, points=20_000)  # 18 bytes a point: about 3 chunks of 768 KiB
    write_pointclouds(whole, frames)
    cut = tmp_path / "cut.bag"
    cut.write_bytes(whole.read_bytes()[: int(whole.stat().st_size * 0.8)])
    told: list[str] = []
    got = list(read_pointclouds(cut, on_skip=told.append))
    assert 0 < len(got) < 12
    assert [f.stamp_ns for f in got] == [f.stamp_ns for f in frames[: len(got)]]
    assert len(told) == 1
    assert f"the {len(got)} message(s) of /points before it are kept" in told[0]


# --- choosing the topic --------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["rosbag1", "mcap"])
def test_a_bag_with_laserscan_and_pointcloud2_topics_chooses_each(
    tmp_path: Path, kind: str
) -> None:
    ros1 = kind == "rosbag1"
    store = _store(ros1)
    scan = Scan.from_laserscan(
        angle_min=-1.0, angle_increment=0.01, ranges=np.full(201, 5.0), stamp_ns=STAMP
    )
    laser = store.deserialize_ros1 if ros1 else store.deserialize_cdr
    scan_msg = laser(laserscan_bytes(store, scan, 0, ros1=ros1), "sensor_msgs/msg/LaserScan")
    cloud = _cloud(XYZ, REC, ros1=ros1)
    p = tmp_path / f"both_{kind}"
    messages = []
    for k in range(4):
        messages.append(("/scan", "sensor_msgs/msg/LaserScan", STAMP + 2 * k, scan_msg))
        messages.append(("/ouster/points", POINTCLOUD2, STAMP + 2 * k + 1, cloud))
    _write_bag(p, kind, messages)
    assert pointcloud_topic(p) == "/ouster/points"
    assert pointcloud_count(p) == 4
    assert len(list(read_pointclouds(p))) == 4
    assert len(list(read_laserscans(p))) == 4
    with pytest.raises(
        InputError,
        match=r"topic '/scan' carries sensor_msgs/msg/LaserScan, not sensor_msgs/msg/PointCloud2",
    ):
        pointcloud_topic(p, "/scan")
    with pytest.raises(InputError, match=r"topic '/scan' carries sensor_msgs/msg/LaserScan, not"):
        list(read_pointclouds(p, topic="/scan"))
    assert pointcloud_count(p, "/scan") is None


def test_no_pointcloud2_topic_or_several_or_a_missing_one_list_the_topics(tmp_path: Path) -> None:
    only_scans = tmp_path / "scans.bag"
    store = _store(True)
    scan = Scan.from_laserscan(
        angle_min=-1.0, angle_increment=0.01, ranges=np.full(201, 5.0), stamp_ns=STAMP
    )
    scan_msg = store.deserialize_ros1(
        laserscan_bytes(store, scan, 0, ros1=True), "sensor_msgs/msg/LaserScan"
    )
    _write_bag(only_scans, "rosbag1", [("/scan", "sensor_msgs/msg/LaserScan", STAMP, scan_msg)])
    with pytest.raises(
        InputError,
        match=r"scans\.bag: bag has no PointCloud2 topic; choose one with --topic\. "
        r"Topics: /scan \(sensor_msgs/msg/LaserScan\)$",
    ):
        pointcloud_topic(only_scans)
    two = tmp_path / "two.bag"
    cloud = _cloud(XYZ, REC, ros1=True)
    _write_bag(
        two, "rosbag1", [("/a", POINTCLOUD2, STAMP, cloud), ("/b", POINTCLOUD2, STAMP, cloud)]
    )
    with pytest.raises(InputError, match=r"bag has several PointCloud2 topics; choose one with"):
        list(read_pointclouds(two))
    with pytest.raises(
        InputError, match=r"bag has no topic '/c'\. Topics: /a \(sensor_msgs/msg/Po"
    ):
        pointcloud_topic(two, "/c")
    assert len(list(read_pointclouds(two, "/b"))) == 1


# --- fuzzing ---------------------------------------------------------------------------------

_NAMES = st.sampled_from(["x", "y", "z", "intensity", "ring", "t", "time", "rgb", ""])
_FIELD = st.builds(
    SimpleNamespace,
    name=_NAMES,
    offset=st.integers(-2, 40),
    datatype=st.integers(0, 10),
    count=st.integers(0, 2),
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    fields=st.lists(_FIELD, max_size=8),
    height=st.integers(-1, 4),
    width=st.integers(0, 12),
    point_step=st.integers(0, 40),
    row_step=st.integers(0, 200),
    data=st.binary(max_size=600),
    bigendian=st.booleans(),
)
def test_the_decoder_raises_nothing_but_input_error(
    fields: list[SimpleNamespace],
    height: int,
    width: int,
    point_step: int,
    row_step: int,
    data: bytes,
    bigendian: bool,
) -> None:
    msg = SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=1, nanosec=2), frame_id="f"),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=bigendian,
        point_step=point_step,
        row_step=row_step,
        data=data,
        is_dense=False,
    )
    try:
        frame = decode_pointcloud(msg)
    except InputError as err:
        problem = str(err)
    else:
        problem = ""
        assert len(frame) <= height * width
        assert np.all(np.isfinite(frame.points))
    assert "\n" not in problem


@settings(max_examples=200, deadline=None)
@given(raw=st.binary(max_size=300))
def test_random_message_bytes_in_a_bag_are_named_not_raised(raw: bytes) -> None:
    from mast.io.bags import _decode
    from mast.io.pointclouds import _to_frame

    store = _store()
    told: list[str] = []
    got = _decode(store, False, POINTCLOUD2, raw, Path("b"), "/p", 1, told.append, _to_frame)
    assert (got is None) == bool(told)
