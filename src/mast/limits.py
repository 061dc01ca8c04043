"""Named limits on what MAST takes from a file, and reading that keeps to them.

Files reach MAST from vehicles, contractors and other software; some are
damaged, a few may be crafted. Every reader keeps to these limits, so that
no input can make MAST hold more memory than a few times the limit, or work
for longer than in proportion to the bytes it was given (``docs/security.md``
lists what each reader guarantees). Going over a limit is bad input (exit 2)
naming the file, the line where there is one, the limit and its name here.

The defaults are far above anything a scanner, a survey or a drawing
produces; a caller with a real need may change them (``mast.limits.X = ...``)
before reading.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO, Protocol

import numpy as np

from mast.errors import InputError

__all__ = [
    "MAX_BAG_CHUNK_BYTES",
    "MAX_BEACONS",
    "MAX_BEAMS",
    "MAX_CLOUD_POINTS",
    "MAX_COORDINATE_M",
    "MAX_CRS_BYTES",
    "MAX_ELEVATION_M",
    "MAX_LINE_BYTES",
    "MAX_METADATA_BYTES",
    "MAX_SURVEY_SIGMA_M",
    "MAX_TEXT_BYTES",
    "MAX_WALL_LENGTH_M",
    "check_lines",
    "line_too_long",
    "read_bounded",
    "read_line",
    "read_stream",
    "size_text",
]

#: A text file read whole (CSV survey, scan, drift; stdin): 64 MiB (a scan of a
#: million beams is ~40 MB, a survey of 10 000 beacons ~3 MB).
MAX_TEXT_BYTES = 64 * 1024 * 1024
#: One line of a CSV file or of a log (a scan of 10 000 beams is ~300 KB): 4 MiB.
MAX_LINE_BYTES = 4 * 1024 * 1024
#: One ROS 1 bag chunk or MCAP chunk, decompressed (rosbag record writes 768 KiB):
#: 128 MiB; a chunk is besides never decompressed beyond the size its header declares.
MAX_BAG_CHUNK_BYTES = 128 * 1024 * 1024
#: A ROS 2 bag's ``metadata.yaml`` (a few KB in practice): 1 MiB.
MAX_METADATA_BYTES = 1024 * 1024
#: A WKT file given to ``--crs`` (a projected CRS's WKT is 1-2 KB): 1 MiB.
MAX_CRS_BYTES = 1024 * 1024
#: Beams in one scan (a 360-degree scan at 0.01 degrees is 36 000): 1 000 000.
MAX_BEAMS = 1_000_000
#: Points in one 3D lidar frame, NaNs for no return counted (a 128-ring lidar at 2048
#: columns gives 262 144): 4 000 000.
MAX_CLOUD_POINTS = 4_000_000
#: Beacons in one survey (a whole mine holds thousands): 100 000.
MAX_BEACONS = 100_000
#: Largest easting or northing, metres: any projected grid (UTM northings reach 1e7 m).
MAX_COORDINATE_M = 1e8
#: Total length of a drift's walls ``mast plan`` takes (a drift of 50 km): 100 km.
MAX_WALL_LENGTH_M = 100_000.0
#: Largest elevation in magnitude, metres (the deepest mine is ~4 km below the surface).
MAX_ELEVATION_M = 1e5
#: Largest standard deviation of a surveyed edge coordinate, metres: a survey a metre out
#: is no survey (and millimetres typed as metres are caught).
MAX_SURVEY_SIGMA_M = 1.0

_CHUNK = 1 << 20


def size_text(n: float) -> str:
    """``n`` bytes for a message: ``512 MiB``, ``1.5 KiB``, ``12 bytes``."""
    for unit, scale in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{int(n)} bytes"


def _stat(path: Path) -> os.stat_result:
    try:
        return path.stat()
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except OSError as err:
        raise InputError(f"cannot read: {err.strerror or err}", path=path) from None


def line_too_long(path: str | Path, line: int) -> InputError:
    """The error for a line longer than :data:`MAX_LINE_BYTES`, naming the file and line."""
    return InputError(
        f"line longer than {size_text(MAX_LINE_BYTES)} (mast.limits.MAX_LINE_BYTES)",
        path=path,
        line=line,
    )


class _Lines(Protocol):
    def readline(self, size: int = -1, /) -> bytes: ...


def read_line(fh: _Lines, path: str | Path, line: int) -> bytes:
    """The next line of ``fh`` (empty at the end), refused past :data:`MAX_LINE_BYTES`;
    ``line`` is its number, for the error."""
    raw = fh.readline(MAX_LINE_BYTES + 1)
    if len(raw) > MAX_LINE_BYTES:
        raise line_too_long(path, line)
    return raw


def read_stream(
    fh: BinaryIO,
    path: str | Path,
    *,
    limit: int | None = None,
    text: bool = True,
    name: str = "MAX_TEXT_BYTES",
) -> bytes:
    """Read ``fh`` to its end, a chunk at a time, refusing more than ``limit`` bytes.

    With ``text``, a NUL byte or a line longer than :data:`MAX_LINE_BYTES` ends
    the reading as soon as it arrives (an endless device fails at once).
    """
    limit = MAX_TEXT_BYTES if limit is None else limit
    parts: list[bytes] = []
    total = 0
    line = 1
    since_newline = 0
    while True:
        chunk = fh.read(_CHUNK)
        if not chunk:
            break
        total += len(chunk)
        if total > limit:
            raise InputError(
                f"more than {size_text(limit)}: larger than MAST reads (mast.limits.{name})",
                path=path,
            )
        if text:
            nul = chunk.find(b"\x00")
            if nul >= 0:
                at = line + chunk.count(b"\n", 0, nul)
                raise InputError("contains a NUL byte; not a text file", path=path, line=at)
            last = chunk.rfind(b"\n")
            if last < 0:
                since_newline += len(chunk)
            else:
                check_lines(chunk, path, first_line=line, carried=since_newline)
                since_newline = len(chunk) - last - 1
            if since_newline > MAX_LINE_BYTES:
                raise line_too_long(path, line + chunk.count(b"\n"))
            line += chunk.count(b"\n")
        parts.append(chunk)
    return b"".join(parts)


def read_bounded(
    path: str | Path,
    *,
    limit: int | None = None,
    text: bool = True,
    what: str = "file",
    name: str = "MAX_TEXT_BYTES",
) -> bytes:
    """The bytes of the file at ``path``, at most ``limit`` of them.

    A regular file larger than ``limit`` is refused before it is read; a pipe
    or a device (``/dev/zero``, a FIFO) is read a chunk at a time and refused
    as soon as it passes the limit. With ``text``, every line must be at most
    :data:`MAX_LINE_BYTES` long and no byte may be NUL. Errors are
    :class:`InputError` naming the file (and the line).
    """
    limit = MAX_TEXT_BYTES if limit is None else limit
    p = Path(path)
    st = _stat(p)
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"is a folder, not a {what}", path=p)
    regular = stat.S_ISREG(st.st_mode)
    if regular and st.st_size > limit:
        raise InputError(
            f"{size_text(st.st_size)}: larger than the {size_text(limit)} MAST reads "
            f"(mast.limits.{name})",
            path=p,
        )
    try:
        with p.open("rb") as fh:
            return read_stream(fh, p, limit=limit, text=text, name=name)
    except OSError as err:
        raise InputError(f"cannot read: {err.strerror or err}", path=p) from None


def check_lines(data: bytes, path: str | Path, *, first_line: int = 1, carried: int = 0) -> None:
    """Refuse (:class:`InputError`, naming the line) a line of ``data`` longer than
    :data:`MAX_LINE_BYTES`; ``carried`` bytes of the first line came before ``data``."""
    if carried + len(data) <= MAX_LINE_BYTES:
        return
    nl = np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == 10)
    ends = np.append(nl, len(data))
    starts = np.concatenate([[-1], nl]) + 1
    lengths = ends - starts
    lengths[0] += carried
    # The last piece is a line only if the data ends without a newline; callers of a
    # stream count it with what follows, so it is judged here only when it is too long.
    long = np.flatnonzero(lengths > MAX_LINE_BYTES)
    if long.size:
        raise line_too_long(path, first_line + int(long[0]))
