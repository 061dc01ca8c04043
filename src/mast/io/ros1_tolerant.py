"""A tolerant walk over a ROS 1 bag's records, for bags whose index is damaged.

Strict readers (rosbags among them) refuse a bag whose index records are
inconsistent even when every message is intact; ``../shared/data``'s real bag
is one (its IndexData records declare a data length that disagrees with their
count). This walks the records in file order — bag header, uncompressed
chunks with their connection and message records, index records skipped by
their *count* — and returns the raw messages; rosbags still decodes them.
Format: http://wiki.ros.org/Bags/Format/2.0.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

__all__ = ["RawMessage", "walk_ros1_bag"]

_MAGIC = b"#ROSBAG V2.0\n"


@dataclass(frozen=True, slots=True)
class RawMessage:
    topic: str
    msgtype: str
    time_ns: int
    data: bytes


class BagFormatError(Exception):
    """The bag's records cannot be walked."""


def _record(buf: bytes, pos: int) -> tuple[dict[str, bytes], int, int, int]:
    """Header fields, data start, data length and the header length of the record at pos."""
    if pos + 4 > len(buf):
        raise BagFormatError(f"truncated record header at byte {pos}")
    (hlen,) = struct.unpack_from("<I", buf, pos)
    hstart, hend = pos + 4, pos + 4 + hlen
    if hend + 4 > len(buf):
        raise BagFormatError(f"truncated record at byte {pos}")
    fields: dict[str, bytes] = {}
    p = hstart
    while p < hend:
        (flen,) = struct.unpack_from("<I", buf, p)
        field = buf[p + 4 : p + 4 + flen]
        if b"=" not in field or p + 4 + flen > hend:
            raise BagFormatError(f"malformed header field at byte {p}")
        name, value = field.split(b"=", 1)
        fields[name.decode("ascii", "replace")] = value
        p += 4 + flen
    (dlen,) = struct.unpack_from("<I", buf, hend)
    return fields, hend + 4, dlen, hlen


def _conn_header(data: bytes) -> dict[str, str]:
    out, p = {}, 0
    while p + 4 <= len(data):
        (flen,) = struct.unpack_from("<I", data, p)
        field = data[p + 4 : p + 4 + flen]
        if b"=" in field:
            k, v = field.split(b"=", 1)
            out[k.decode("ascii", "replace")] = v.decode("utf-8", "replace")
        p += 4 + flen
    return out


def _time_ns(value: bytes) -> int:
    sec, nsec = struct.unpack("<II", value[:8])
    return int(sec) * 1_000_000_000 + int(nsec)


def walk_ros1_bag(path: str | Path) -> list[RawMessage]:
    """Every message of an uncompressed ROS 1 bag, in file order."""
    buf = Path(path).read_bytes()
    if not buf.startswith(_MAGIC):
        raise BagFormatError("not a ROS 1 bag (no '#ROSBAG V2.0' header)")
    conns: dict[int, tuple[str, str]] = {}
    pending: list[tuple[int, int, bytes]] = []
    pos = len(_MAGIC)

    def handle(fields: dict[str, bytes], data: bytes) -> None:
        op = fields.get("op", b"\x00")[0]
        if op == 0x07:
            (cid,) = struct.unpack("<I", fields["conn"][:4])
            hdr = _conn_header(data)
            topic = fields.get("topic", hdr.get("topic", "").encode()).decode("utf-8", "replace")
            conns[cid] = (topic, hdr.get("type", "?"))
        elif op == 0x02:
            (cid,) = struct.unpack("<I", fields["conn"][:4])
            pending.append((cid, _time_ns(fields["time"]), data))

    while pos < len(buf):
        fields, dstart, dlen, _ = _record(buf, pos)
        op = fields.get("op", b"\x00")[0]
        if op == 0x04:
            (count,) = struct.unpack("<I", fields["count"][:4])
            pos = dstart + 12 * count  # the count, not the (damaged) data length
            continue
        if dstart + dlen > len(buf):
            raise BagFormatError(f"record at byte {pos} runs past the end of the file")
        data = buf[dstart : dstart + dlen]
        if op == 0x05:
            if fields.get("compression", b"none") != b"none":
                raise BagFormatError("compressed chunks are not supported by the tolerant reader")
            p = 0
            while p < len(data):
                f2, d2, l2, _ = _record(data, p)
                handle(f2, data[d2 : d2 + l2])
                p = d2 + l2
        else:
            handle(fields, data)
        pos = dstart + dlen
    out = []
    for cid, t, data in pending:
        topic, msgtype = conns.get(cid, ("?", "?"))
        out.append(RawMessage(topic, msgtype, t, data))
    return out
