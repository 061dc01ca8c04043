"""Damage done to a seed: flipped bits, cuts, splices, values no survey holds, bombs."""

from __future__ import annotations

import bz2
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["bz2_bomb_bag", "metadata_attack", "mutate"]


_BAD_NUMBERS = (
    "1e300", "-1e300", "nan", "inf", "-inf", "", "1e-320", "9" * 400, "0x10", "1,5", "--1",
    "١٢٣", "1e8", "-0", "   ", "NaN", "+inf", "1_000",
)  # fmt: skip


def _bitflip(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    if not data:
        return "bitflip", data
    b = bytearray(data)
    k = int(rng.integers(1, 9))
    for _ in range(k):
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
    return f"bitflip x{k}", bytes(b)


def _truncate(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    n = int(rng.integers(0, max(len(data), 1)))
    return f"truncate at {n}", data[:n]


def _random(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    n = int(rng.integers(0, 4096))
    return f"random {n} bytes", rng.bytes(n)


def _splice(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    if len(data) < 2:
        return "splice", data
    i, j = sorted(int(x) for x in rng.integers(0, len(data), size=2))
    kind = int(rng.integers(0, 3))
    if kind == 0:
        return f"delete {i}:{j}", data[:i] + data[j:]
    if kind == 1:
        return f"repeat {i}:{j}", data[:j] + data[i:j] + data[j:]
    return f"insert {j - i} random at {i}", data[:i] + rng.bytes(j - i) + data[i:]


def _text_value(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """A number of a CSV swapped for one no file should hold."""
    lines = data.split(b"\n")
    body = [k for k in range(1, len(lines)) if b"," in lines[k]]
    if not body:
        return "value", data
    k = body[int(rng.integers(0, len(body)))]
    cells = lines[k].split(b",")
    c = int(rng.integers(0, len(cells)))
    bad = _BAD_NUMBERS[int(rng.integers(0, len(_BAD_NUMBERS)))]
    cells[c] = bad.encode()
    lines[k] = b",".join(cells)
    return f"line {k + 1} field {c + 1} = {bad[:12]!r}", b"\n".join(lines)


def _text_lines(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """Lines of a CSV repeated, swapped, dropped or blown up."""
    lines = data.split(b"\n")
    if len(lines) < 3:
        return "lines", data
    k = int(rng.integers(1, len(lines) - 1))
    kind = int(rng.integers(0, 6))
    if kind == 0:
        return f"repeat lines from {k + 1}", b"\n".join(lines + lines[k:])
    if kind == 1:
        j = int(rng.integers(1, len(lines) - 1))
        lines[k], lines[j] = lines[j], lines[k]
        return f"swap lines {k + 1} and {j + 1}", b"\n".join(lines)
    if kind == 2:
        return f"drop line {k + 1}", b"\n".join(lines[:k] + lines[k + 1 :])
    if kind == 3:
        return "a 6 MB line", b"\n".join([*lines[:k], b"1," * 3_000_000, *lines[k:]])
    if kind == 4:
        return "NUL bytes", data[:k] + b"\x00" * 16 + data[k:]
    return "header only", lines[0] + b"\n"


def _lying_chunk(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """A ROS 1 chunk header's decompressed ``size`` changed (smaller or larger)."""
    at = data.find(b"size=", 13)
    if at < 0:
        return "lying size", data
    new = int(rng.choice([0, 1, 64, 2**31, 2**32 - 1]))
    return f"chunk size = {new}", data[: at + 5] + struct.pack("<I", new) + data[at + 9 :]


def mutate(
    data: bytes, rng: np.random.Generator, *, text: bool, bag1: bool = False
) -> tuple[str, bytes]:
    ops: list[Callable[[bytes, np.random.Generator], tuple[str, bytes]]] = [
        _bitflip,
        _bitflip,
        _truncate,
        _random,
        _splice,
    ]
    if text:
        ops += [_text_value, _text_value, _text_value, _text_lines, _text_lines]
    if bag1:
        ops += [_lying_chunk, _lying_chunk]
    return ops[int(rng.integers(0, len(ops)))](data, rng)


def bz2_bomb_bag(path: Path, inflated: int) -> None:
    """A ROS 1 bag of one bz2 chunk that declares 1 KiB and inflates to ``inflated`` bytes."""

    def record(fields: dict[str, bytes], data: bytes) -> bytes:
        head = b"".join(
            struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v
            for k, v in fields.items()
        )
        return struct.pack("<I", len(head)) + head + struct.pack("<I", len(data)) + data

    bomb = bz2.compress(b"\x00" * inflated, 9)
    header = record(
        {
            "op": b"\x03",
            "index_pos": struct.pack("<Q", 0),
            "conn_count": struct.pack("<I", 0),
            "chunk_count": struct.pack("<I", 1),
        },
        b" " * 4000,
    )
    chunk = record({"op": b"\x05", "compression": b"bz2", "size": struct.pack("<I", 1024)}, bomb)
    path.write_bytes(b"#ROSBAG V2.0\n" + header + chunk)


_YAML_BOMB = (
    'a: &a ["x","x","x","x","x","x","x","x","x"]\n'
    + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},"
        f"*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},"
        f"*{chr(97 + i)}]\n"
        for i in range(8)
    )
    + "rosbag2_bagfile_information: *i\n"
)


def metadata_attack(text: str, rng: np.random.Generator) -> tuple[str, str]:
    kind = int(rng.integers(0, 5))
    if kind == 0:
        return "YAML alias bomb", _YAML_BOMB
    if kind == 1:
        return "storage name ../../etc", text.replace("- run_", "- ../../../etc/run_", 1)
    if kind == 2:
        return "storage name absolute", text.replace("- run_", "- /tmp/run_", 1)
    if kind == 3:
        return "2 MB metadata", text + "# " + "x" * 2_000_000 + "\n"
    return "metadata not YAML", "{{{{ [[[ :\n\t- !!python/object/apply:os.system ['true']\n"
