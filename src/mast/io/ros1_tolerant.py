"""A tolerant walk over a ROS 1 bag's records, for bags whose index is damaged or missing.

Strict readers (rosbags among them) refuse a bag whose index records are
inconsistent even when every message is intact (``../shared/data``'s real bag
is one: its IndexData records declare a data length that disagrees with their
count), and a bag cut short, which has no index at all. This walks the
records in file order — bag header, chunks (uncompressed, bz2 or lz4) with
their connection and message records, index records skipped by their
*count* — one chunk in memory at a time, and yields the raw messages;
rosbags still decodes them. A record cut short ends the walk after every
message before it, and says so. Format: http://wiki.ros.org/Bags/Format/2.0.
"""

from __future__ import annotations

import bz2
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from mast import limits
from mast.core.scan import stamp_of

__all__ = [
    "BagFormatError",
    "RawMessage",
    "chunk_fields",
    "decompress_chunk",
    "inflate",
    "iter_ros1_bag",
    "walk_ros1_bag",
]

_MAGIC = b"#ROSBAG V2.0\n"


@dataclass(frozen=True, slots=True)
class RawMessage:
    topic: str
    msgtype: str
    time_ns: int
    data: bytes


class BagFormatError(Exception):
    """The bag's records cannot be walked."""


def _fields(header: bytes, pos: int) -> dict[str, bytes]:
    fields: dict[str, bytes] = {}
    p = 0
    while p < len(header):
        if p + 4 > len(header):
            raise BagFormatError(f"malformed header field at byte {pos + p}")
        (flen,) = struct.unpack_from("<I", header, p)
        field = header[p + 4 : p + 4 + flen]
        if b"=" not in field or p + 4 + flen > len(header):
            raise BagFormatError(f"malformed header field at byte {pos + p}")
        name, value = field.split(b"=", 1)
        fields[name.decode("ascii", "replace")] = value
        p += 4 + flen
    return fields


def _record(buf: bytes, pos: int) -> tuple[dict[str, bytes], int, int]:
    """Header fields, data start and data length of the record at ``pos`` of a buffer."""
    if pos + 4 > len(buf):
        raise BagFormatError(f"truncated record header at byte {pos}")
    (hlen,) = struct.unpack_from("<I", buf, pos)
    hend = pos + 4 + hlen
    if hend + 4 > len(buf):
        raise BagFormatError(f"truncated record at byte {pos}")
    fields = _fields(buf[pos + 4 : hend], pos + 4)
    (dlen,) = struct.unpack_from("<I", buf, hend)
    return fields, hend + 4, dlen


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
    return stamp_of(sec, nsec)


def _read(fh: BinaryIO, n: int, pos: int, what: str) -> bytes:
    data = fh.read(n)
    if len(data) != n:
        raise BagFormatError(f"{what} at byte {pos} is cut short (the file ends)")
    return data


def chunk_fields(fh: BinaryIO, pos: int) -> dict[str, bytes]:
    """The header fields of the record at byte ``pos`` of an open bag."""
    fh.seek(pos)
    (hlen,) = struct.unpack("<I", _read(fh, 4, pos, "record"))
    if hlen > limits.MAX_BAG_CHUNK_BYTES:
        raise BagFormatError(f"record header at byte {pos} is implausibly long")
    return _fields(_read(fh, hlen, pos, "record header"), pos + 4)


def decompress_chunk(fields: dict[str, bytes], data: bytes, *, pos: int) -> bytes:
    """A ROS 1 chunk's data decompressed (see :func:`inflate`), by its header ``fields``."""
    kind = fields.get("compression", b"none").decode("ascii", "replace")
    size = struct.unpack("<I", fields["size"][:4])[0] if "size" in fields else None
    return inflate(kind, data, size, f"chunk at byte {pos}")


def inflate(kind: str, data: bytes, declared: int | None, where: str) -> bytes:
    """``data`` decompressed (``none``, ``bz2``, ``lz4`` frames, ``zstd``), never past the
    size its header ``declared`` nor :data:`mast.limits.MAX_BAG_CHUNK_BYTES`: a chunk
    that would grow further is a :class:`BagFormatError` as soon as it passes, so a
    decompression bomb costs at most the limit. ROS 1 and MCAP chunks alike."""
    limit = limits.MAX_BAG_CHUNK_BYTES
    if declared is not None and declared > limit:
        raise BagFormatError(f"{where} declares {declared} bytes, beyond the limit")
    if declared is not None:
        limit = max(declared, 0)
    try:
        if kind in ("none", ""):
            return data
        if kind == "bz2":
            out = bz2.BZ2Decompressor().decompress(data, max_length=limit + 1)
        elif kind == "lz4":
            import lz4.frame  # type: ignore[import-untyped]

            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1)
        elif kind == "zstd":
            from backports import zstd

            try:
                out = zstd.ZstdDecompressor().decompress(data, max_length=limit + 1)
            except zstd.ZstdError as err:
                raise ValueError(str(err)) from None
        else:
            raise BagFormatError(f"{where}: unknown compression {kind!r}")
    except (OSError, ValueError, RuntimeError, EOFError) as err:
        raise BagFormatError(f"{where} cannot be decompressed ({err})") from None
    if len(out) > limit:
        raise BagFormatError(f"{where} decompresses beyond its declared size")
    return bytes(out)


def iter_ros1_bag(
    path: str | Path, *, on_damage: Callable[[str], None] | None = None
) -> Iterator[RawMessage]:
    """Every message of a ROS 1 bag in file order, one chunk in memory at a time.

    A record that is cut short or cannot be read ends the walk: every message
    before it has been yielded; ``on_damage`` is told why (without it, the
    walk raises :class:`BagFormatError`).
    """
    conns: dict[int, tuple[str, str]] = {}
    p = Path(path)
    with p.open("rb") as fh:
        if fh.read(len(_MAGIC)) != _MAGIC:
            raise BagFormatError("not a ROS 1 bag (no '#ROSBAG V2.0' header)")
        pos = len(_MAGIC)
        try:
            while True:
                head = fh.read(4)
                if not head:
                    return
                if len(head) < 4:
                    raise BagFormatError(f"record at byte {pos} is cut short (the file ends)")
                (hlen,) = struct.unpack("<I", head)
                if hlen > limits.MAX_BAG_CHUNK_BYTES:
                    raise BagFormatError(f"record header at byte {pos} is implausibly long")
                fields = _fields(_read(fh, hlen, pos, "record header"), pos + 4)
                (dlen,) = struct.unpack("<I", _read(fh, 4, pos, "record"))
                op = fields.get("op", b"\x00")[0]
                if op == 0x04:  # index data: skip by its count, not its (damaged) length
                    (count,) = struct.unpack("<I", fields["count"][:4])
                    fh.seek(12 * count, 1)
                    pos = fh.tell()
                    continue
                if dlen > limits.MAX_BAG_CHUNK_BYTES:
                    raise BagFormatError(f"record at byte {pos} declares {dlen} bytes")
                if op in (0x05, 0x07, 0x02):
                    data = _read(fh, dlen, pos, "record")
                else:
                    fh.seek(dlen, 1)
                    data = b""
                if op == 0x05:
                    chunk = decompress_chunk(fields, data, pos=pos)
                    q = 0
                    while q < len(chunk):
                        f2, d2, l2 = _record(chunk, q)
                        if d2 + l2 > len(chunk):
                            raise BagFormatError(f"chunk at byte {pos} holds a record cut short")
                        msg = _handle(conns, f2, chunk[d2 : d2 + l2])
                        if msg is not None:
                            yield msg
                        q = d2 + l2
                else:
                    msg = _handle(conns, fields, data)
                    if msg is not None:
                        yield msg
                pos = fh.tell()
        except (BagFormatError, struct.error, KeyError, IndexError) as err:
            if on_damage is None:
                raise BagFormatError(str(err)) from None
            on_damage(str(err))


def _handle(
    conns: dict[int, tuple[str, str]], fields: dict[str, bytes], data: bytes
) -> RawMessage | None:
    op = fields.get("op", b"\x00")[0]
    if op == 0x07:
        (cid,) = struct.unpack("<I", fields["conn"][:4])
        hdr = _conn_header(data)
        topic = fields.get("topic", hdr.get("topic", "").encode()).decode("utf-8", "replace")
        conns[cid] = (topic, hdr.get("type", "?"))
    elif op == 0x02:
        (cid,) = struct.unpack("<I", fields["conn"][:4])
        topic, msgtype = conns.get(cid, ("?", "?"))
        return RawMessage(topic, msgtype, _time_ns(fields["time"]), data)
    return None


def walk_ros1_bag(path: str | Path) -> list[RawMessage]:
    """Every message of a ROS 1 bag, in file order (raises if any record is damaged)."""
    return list(iter_ros1_bag(path))
