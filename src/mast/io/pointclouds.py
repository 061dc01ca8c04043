"""``sensor_msgs/PointCloud2`` frames of a 3D lidar in ROS 1 and ROS 2 bags and MCAP files.

A bag is opened, its topic chosen and its messages read one at a time, a damaged one
skipped and named, by the same code as ``LaserScan`` (:mod:`mast.io.bags`); this module
turns each message into a :class:`~mast.core.pose3d.Frame3D` and back.

What a message must hold (anything else is an :class:`InputError` saying what is wrong):

* fields ``x``, ``y`` and ``z``, each ``FLOAT32`` or ``FLOAT64`` (PointField datatypes 7
  and 8), at any offsets inside ``point_step``; rows ``row_step`` apart when the cloud is
  organised (``height`` > 1), bytes in the order ``is_bigendian`` says. A point with a
  coordinate that is not finite is left out: drivers mark "no return" with NaN;
* optionally ``intensity`` (any number type) as :attr:`Frame3D.intensity`; ``ring`` (any
  number type, whole numbers) as :attr:`Frame3D.ring`; and a per-point time, ``t`` or
  else ``time``, as :attr:`Frame3D.time_s` in seconds from the header's stamp. The
  time's unit is told by its datatype, as the drivers write it: an integer is
  nanoseconds (Ouster's ``t``, UINT32), a float is seconds (Velodyne's and Livox's
  ``time``, FLOAT32). A time that is absolute rather than from the stamp (Hesai's
  ``timestamp``, FLOAT64 seconds since 1970) is not read;
* at most :data:`mast.limits.MAX_CLOUD_POINTS` points (width × height), and data at
  least as long as they need.

Fields MAST does not read are ignored whatever they hold (a driver's own extras).
Each field read must hold one number a point (``count`` 0 or 1) and appear once.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from mast import limits
from mast.core.pose3d import Frame3D
from mast.core.scan import split_stamp, stamp_of
from mast.errors import InputError, quoted
from mast.io.bags import (
    BagKind,
    _choose_topic,
    _read_messages,
    _write_messages,
    indexed_count,
    list_topics,
)

__all__ = [
    "POINTCLOUD2",
    "decode_pointcloud",
    "pointcloud_bytes",
    "pointcloud_count",
    "pointcloud_topic",
    "read_pointclouds",
    "write_pointclouds",
]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"

#: PointField's datatypes (sensor_msgs/PointField constants) as numpy type codes.
DATATYPES: dict[int, str] = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
#: Their names, for messages.
DATATYPE_NAMES: dict[int, str] = {
    1: "INT8",
    2: "UINT8",
    3: "INT16",
    4: "UINT16",
    5: "INT32",
    6: "UINT32",
    7: "FLOAT32",
    8: "FLOAT64",
}
#: The coordinates: float fields only (an integer coordinate is a driver's scaled units,
#: which MAST cannot know).
COORDINATES = ("x", "y", "z")
_FLOATS = frozenset({7, 8})
#: Names of a per-point time, in the order looked for.
TIME_FIELDS = ("t", "time")
#: Largest ``t`` a UINT32 holds in nanoseconds, seconds: a frame whose times do not fit is
#: written with a FLOAT32 ``time`` in seconds instead.
_MAX_T_S = (2**32 - 1) * 1e-9
_INT32 = (-(2**31), 2**31 - 1)


def decode_pointcloud(msg: Any) -> Frame3D:
    """A ``sensor_msgs/PointCloud2`` message of any binding (a bag's, a DDS sample's) as a
    :class:`Frame3D`, decoded as the module describes.

    The bytes are read in place through a numpy structured dtype (offsets, ``point_step``
    as its size, rows ``row_step`` apart), so a frame of 65 000 points takes a few
    milliseconds.

    Raises
    ------
    InputError
        Naming the problem (a missing or unreadable field, data too short, too many
        points); without a path: a reader adds the file and the message.
    """
    height = _count(msg.height, "height")
    width = _count(msg.width, "width")
    point_step = _count(msg.point_step, "point_step")
    row_step = _count(msg.row_step, "row_step")
    fields = _fields(msg.fields, point_step)
    n = height * width
    if n > limits.MAX_CLOUD_POINTS:
        raise InputError(
            f"{n} points ({height} x {width}), more than the {limits.MAX_CLOUD_POINTS} MAST "
            "takes in one frame (mast.limits.MAX_CLOUD_POINTS)"
        )
    if height > 1 and row_step < width * point_step:
        raise InputError(
            f"row_step {row_step} is less than width {width} x point_step {point_step}; "
            "the rows would overlap"
        )
    data = _bytes(msg.data)
    need = 0 if n == 0 else (height - 1) * row_step + width * point_step
    if data.size < need:
        rows = f"{height} rows of " if height > 1 else ""
        raise InputError(
            f"data is {data.size} bytes, short of the {need} that {rows}{width} points of "
            f"{point_step} bytes need"
        )
    order = ">" if bool(msg.is_bigendian) else "<"
    dtype = np.dtype(
        {
            "names": list(fields),
            "formats": [order + DATATYPES[datatype] for _, datatype in fields.values()],
            "offsets": [offset for offset, _ in fields.values()],
            "itemsize": max(point_step, 1),
        }
    )
    # Rows row_step apart, points point_step apart, read where they lie (no copy).
    cloud: NDArray[Any] = np.ndarray(
        (height, width),
        dtype=dtype,
        buffer=data,
        strides=(row_step if height > 1 else width * point_step, point_step),
    )
    points = np.empty((n, 3))
    for k, name in enumerate(COORDINATES):
        points[:, k] = cloud[name].reshape(-1)
    keep = np.isfinite(points).all(axis=1)
    whole = bool(keep.all())
    if not whole:
        points = points[keep]

    def column(name: str) -> NDArray[Any] | None:
        if name not in fields:
            return None
        values = cloud[name].reshape(-1)
        return values if whole else values[keep]

    intensity = column("intensity")
    ring = column("ring")
    time_name = next((t for t in TIME_FIELDS if t in fields), None)
    times = None if time_name is None else column(time_name)
    stamp = msg.header.stamp
    return Frame3D(
        points,
        intensity=None if intensity is None else intensity.astype(np.float64),
        ring=None if ring is None else _rings(ring),
        time_s=None if times is None else _seconds(times),
        stamp_ns=stamp_of(stamp.sec, stamp.nanosec),
        frame_id=str(msg.header.frame_id),
    )


def _count(value: Any, name: str) -> int:
    """A message's size field as an int, or an error (a crafted message's may be anything)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InputError(f"{name} {_shown(value)} is not a count")
    return int(value)


def _shown(value: Any) -> str:
    """A message's value for an error: an int as it is, anything else quoted."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    return quoted(value)


def _fields(fields: Any, point_step: int) -> dict[str, tuple[int, int]]:
    """The fields MAST reads, ``name -> (offset, datatype)``, each checked."""
    wanted = {*COORDINATES, "intensity", "ring", *TIME_FIELDS}
    found: dict[str, tuple[int, int]] = {}
    names: list[str] = []
    for f in fields:
        name = str(f.name)
        names.append(name)
        if name not in wanted:
            continue
        if name in found:
            raise InputError(f"field {name!r} appears twice")
        offset = _count(f.offset, f"field {name!r}'s offset")
        datatype = f.datatype
        if isinstance(datatype, bool) or not isinstance(datatype, (int, np.integer)):
            datatype = -1
        datatype = int(datatype)
        if datatype not in DATATYPES:
            raise InputError(
                f"field {name!r} has datatype {_shown(f.datatype)}, not one of PointField's "
                "number types (1-8)"
            )
        if name in COORDINATES and datatype not in _FLOATS:
            raise InputError(
                f"field {name!r} is {DATATYPE_NAMES[datatype]}; a coordinate must be FLOAT32 "
                "or FLOAT64"
            )
        count = _count(f.count, f"field {name!r}'s count")
        if count > 1:
            raise InputError(f"field {name!r} has count {count}; MAST reads one number a point")
        end = offset + np.dtype(DATATYPES[datatype]).itemsize
        if end > point_step:
            raise InputError(
                f"field {name!r} ({DATATYPE_NAMES[datatype]} at offset {offset}) ends at byte "
                f"{end}, past point_step {point_step}"
            )
        found[name] = (offset, datatype)
    missing = [c for c in COORDINATES if c not in found]
    if missing:
        listing = ", ".join(quoted(n, 20) for n in names[:12]) or "none"
        more = f" and {len(names) - 12} more" if len(names) > 12 else ""
        raise InputError(f"no field {missing[0]!r} (its fields: {listing}{more})")
    return found


def _bytes(data: Any) -> NDArray[np.uint8]:
    """A message's ``data`` (a numpy array, bytes, an ``array.array``, a list) as bytes."""
    try:
        return np.frombuffer(memoryview(data).cast("B"), dtype=np.uint8)
    except (TypeError, ValueError):
        try:
            return np.asarray(data, dtype=np.uint8).reshape(-1)
        except (TypeError, ValueError, OverflowError):
            raise InputError("data is not a sequence of bytes") from None


def _rings(values: NDArray[Any]) -> NDArray[np.int32]:
    """Ring numbers as int32: a float ring must hold whole, finite numbers."""
    if values.dtype.kind == "f" and not np.all(values == np.rint(values)):
        # NaN and the infinities fail the comparison too.
        raise InputError("field 'ring' holds a value that is not a whole number")
    if values.size and (values.min() < _INT32[0] or values.max() > _INT32[1]):
        raise InputError(f"field 'ring' holds {values.max():.0f}, beyond any ring number")
    return values.astype(np.int32)


def _seconds(values: NDArray[Any]) -> NDArray[np.float64]:
    """A per-point time in seconds: integers are nanoseconds, floats seconds."""
    if values.dtype.kind in "iu":
        return values.astype(np.float64) * 1e-9
    return values.astype(np.float64)


def _to_frame(msg: Any, _path: Path, _index: int) -> Frame3D:
    return decode_pointcloud(msg)


def read_pointclouds(
    path: str | Path,
    topic: str | None = None,
    *,
    on_skip: Callable[[str], None] | None = None,
) -> Iterator[Frame3D]:
    """Yield the ``PointCloud2`` messages of ``topic`` as frames, in time order, one at
    a time.

    With ``topic=None`` the bag must hold exactly one PointCloud2 topic (a bag with
    LaserScan topics besides is fine). A topic that is missing, or not PointCloud2, is
    an :class:`InputError` listing the bag's topics.

    Without ``on_skip`` a malformed message is an :class:`InputError` naming it
    (``message 7 of /points cannot be decoded: no field 'z' ...``). With it, bags are
    read as they come from the field: such a message is skipped and ``on_skip`` told
    which one and why; a bag cut short gives every frame before the damage (as
    :func:`mast.io.bags.read_laserscans`).
    """
    yield from _read_messages(
        Path(path), POINTCLOUD2, _to_frame, topic=topic, on_skip=on_skip, what="frames"
    )


def pointcloud_topic(path: str | Path, topic: str | None = None) -> str | None:
    """The PointCloud2 topic :func:`read_pointclouds` reads (``topic`` checked, or the
    bag's only one), or None when the bag's index is too damaged to list its topics (the
    tolerant reader may still read it). Errors list the bag's topics."""
    try:
        topics = list_topics(path)
    except InputError:
        return topic
    return _choose_topic([(t.topic, t.msgtype) for t in topics], topic, Path(path), POINTCLOUD2)


def pointcloud_count(path: str | Path, topic: str | None = None) -> int | None:
    """How many PointCloud2 messages the topic read holds, from the bag's index or
    metadata (no message is read); None when that is not known (a damaged bag, no such
    topic). For a progress bar's total, never a limit."""
    return indexed_count(path, topic, pointcloud_topic)


def write_pointclouds(
    path: str | Path,
    frames: Iterable[Frame3D],
    *,
    kind: BagKind = "rosbag1",
    topic: str = "/points",
    compression: Literal["none", "bz2", "lz4"] = "none",
) -> int:
    """Write frames as ``PointCloud2`` messages; returns the number written.

    ``kind`` is ``"rosbag1"`` (a ``.bag`` file), ``"sqlite3"`` or ``"mcap"`` (ROS 2 bag
    folders), written whole or not at all; each frame's ``stamp_ns`` is its bag time.
    The layout is :func:`pointcloud_bytes`'.
    """
    return _write_messages(
        Path(path),
        ((int(f.stamp_ns), f) for f in frames),
        POINTCLOUD2,
        pointcloud_bytes,
        kind=kind,
        topic=topic,
        compression=compression,
    )


def _layout(frame: Frame3D, seq: int) -> list[tuple[str, str]]:
    """The fields a frame is written with, as (name, little-endian numpy type)."""
    layout = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if frame.intensity is not None:
        layout.append(("intensity", "<f4"))
    if frame.ring is not None:
        ring = frame.ring
        if ring.size and (ring.min() < 0 or ring.max() > np.iinfo(np.uint16).max):
            raise InputError(f"frame {seq}: a ring outside 0-65535, which a UINT16 ring holds")
        layout.append(("ring", "<u2"))
    if frame.time_s is not None:
        t = frame.time_s
        ouster = not t.size or (bool(np.all(t >= 0)) and float(t.max()) <= _MAX_T_S)
        layout.append(("t", "<u4") if ouster else ("time", "<f4"))
    return layout


def _offsets(dtype: np.dtype[Any]) -> list[int]:
    """The byte offset of each of a structured dtype's fields, in order."""
    fields = dtype.fields
    assert fields is not None, "a structured dtype"
    return [int(fields[name][1]) for name in fields]


def pointcloud_bytes(store: Any, frame: Frame3D, seq: int, *, ros1: bool) -> bytes:
    """``frame`` as a serialised ``PointCloud2`` (ROS 1, or ROS 2 CDR) of ``store``'s types.

    Unorganised (height 1), little-endian, packed: FLOAT32 ``x``, ``y``, ``z``, then,
    where the frame has them, FLOAT32 ``intensity``, UINT16 ``ring``, and the time as
    Ouster writes it (``t``, UINT32 nanoseconds from the stamp) or, for times a UINT32
    cannot hold (before the stamp, or 4.29 s after it), as Velodyne does (``time``,
    FLOAT32 seconds).
    """
    layout = _layout(frame, seq)
    dtype = np.dtype(layout)
    cloud = np.zeros(len(frame), dtype=dtype)
    for k, name in enumerate(COORDINATES):
        cloud[name] = frame.points[:, k]
    if frame.intensity is not None:
        cloud["intensity"] = frame.intensity
    if frame.ring is not None:
        cloud["ring"] = frame.ring
    if frame.time_s is not None:
        if any(name == "t" for name, _ in layout):
            cloud["t"] = np.rint(frame.time_s * 1e9)
        else:
            cloud["time"] = frame.time_s
    PointCloud2 = store.types[POINTCLOUD2]
    PointField = store.types["sensor_msgs/msg/PointField"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    codes = {code: number for number, code in DATATYPES.items()}
    sec, nanosec = split_stamp(frame.stamp_ns)
    header_kw: dict[str, Any] = {
        "stamp": Time(sec=sec, nanosec=nanosec),
        "frame_id": frame.frame_id,
    }
    if ros1:
        header_kw["seq"] = seq
    msg = PointCloud2(
        header=Header(**header_kw),
        height=1,
        width=len(frame),
        fields=[
            PointField(name=name, offset=offset, datatype=codes[code[1:]], count=1)
            for (name, code), offset in zip(layout, _offsets(dtype), strict=True)
        ],
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * len(frame),
        data=cloud.view(np.uint8).reshape(-1),
        is_dense=True,
    )
    raw = store.serialize_ros1(msg, POINTCLOUD2) if ros1 else store.serialize_cdr(msg, POINTCLOUD2)
    return bytes(raw)
