"""CARMEN laser logs with corrected poses (``../shared/data/carmen_corrected``).

Format (``SOURCE.txt`` beside the logs; CARMEN's own ``FLASER`` message), one
message a line, gzip-compressed or plain text::

    FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp

Beam ``i`` (1-based) is at ``-pi/2 + (i - 1) pi / (n - 1)``, counter-clockwise
from the laser's forward axis (REP 103, like MAST's scanner frame); ranges of
50 m or more mean no return. ``x y theta`` is the corrected pose of the laser
in the log's world frame (metres; ``theta`` radians counter-clockwise from
world +x). ``ODOM``, ``NEFF``, ``PARAM`` messages and ``#`` comments are
skipped, but a ``PARAM robot_front_laser_max`` lowers the range limit.

The world frame becomes a mine frame by Easting = world x and Northing =
world y; the heading ``theta`` (counter-clockwise from +x, i.e. from east)
becomes the azimuth ``pi/2 - theta`` (clockwise from north), so that MAST's
scanner-to-mine rotation, counter-clockwise by ``pi/2 - A``, is the log's
rotation by ``theta``.
"""

from __future__ import annotations

import gzip
import io
import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mast import limits
from mast.core.frames import azimuth_of_yaw
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.errors import InputError

__all__ = ["CARMEN_NO_RETURN_M", "read_carmen_log"]

#: Ranges of this or more are CARMEN's "no return".
CARMEN_NO_RETURN_M = 50.0
#: The scan's stated range limit sits just under the no-return value.
_RANGE_MAX_M = CARMEN_NO_RETURN_M - 0.1
#: After the ranges: x y theta odom_x odom_y odom_theta ipc_timestamp hostname logger_timestamp.
_TAIL_FIELDS = 9
_MAX_RANGE_PARAM = b"robot_front_laser_max"


def _open(path: Path) -> gzip.GzipFile | io.BufferedReader:
    with path.open("rb") as probe:
        gzipped = probe.read(2) == b"\x1f\x8b"
    return gzip.open(path, "rb") if gzipped else path.open("rb")


def read_carmen_log(
    path: str | Path, *, frame_id: str = "frontlaser"
) -> Iterator[tuple[Scan, Pose2D]]:
    """Yield each ``FLASER`` scan with its corrected pose in the mine frame.

    Parameters
    ----------
    path : str or Path
        A CARMEN log, gzip-compressed or plain text; read line by line.
    frame_id : str
        Frame name given to the scans.

    Yields
    ------
    scan : Scan
        Beams from ``-pi/2`` to ``pi/2`` counter-clockwise; no-return ranges
        (50 m or more) are invalid (``range_max_m`` just under 50 m, or the
        log's ``robot_front_laser_max`` if smaller). ``stamp_ns`` is the IPC
        time stamp.
    pose : Pose2D
        Corrected laser pose: Easting = world x, Northing = world y,
        azimuth ``pi/2 - theta``.

    Raises
    ------
    InputError
        The file cannot be read or is not gzip/text, or a ``FLASER`` line is
        malformed (named by its line number).
    """
    p = Path(path)
    try:
        fh = _open(p)
    except OSError as err:
        raise InputError(f"cannot read: {err.strerror or err}", path=p) from None
    range_max = _RANGE_MAX_M
    with fh:
        line_no = 0
        while True:
            try:
                raw = limits.read_line(fh, p, line_no + 1)
            except (OSError, EOFError) as err:
                raise InputError(f"cannot read: {err}", path=p, line=line_no + 1) from None
            if not raw:
                return
            line_no += 1
            tokens = raw.split()
            if not tokens:
                continue
            if tokens[0] == b"PARAM" and len(tokens) >= 3 and tokens[1] == _MAX_RANGE_PARAM:
                try:
                    range_max = min(_RANGE_MAX_M, float(tokens[2]))
                except ValueError:
                    raise InputError(
                        f"PARAM {_MAX_RANGE_PARAM.decode()} is not a number", path=p, line=line_no
                    ) from None
                continue
            if tokens[0] != b"FLASER":
                continue
            yield _flaser(tokens, range_max, frame_id, p, line_no)


def _flaser(
    tokens: list[bytes], range_max: float, frame_id: str, path: Path, line_no: int
) -> tuple[Scan, Pose2D]:
    try:
        n = int(tokens[1]) if len(tokens) > 1 else -1
    except ValueError:
        raise InputError("FLASER beam count is not an integer", path=path, line=line_no) from None
    if n < 2:
        raise InputError(
            "FLASER needs a beam count of at least 2 after the message name",
            path=path,
            line=line_no,
        )
    if len(tokens) != 2 + n + _TAIL_FIELDS:
        raise InputError(
            f"FLASER with {n} beams needs {2 + n + _TAIL_FIELDS} fields, got {len(tokens)}",
            path=path,
            line=line_no,
        )
    try:
        ranges = np.array([float(t) for t in tokens[2 : 2 + n]])
        x, y, theta = (float(t) for t in tokens[2 + n : 5 + n])
        stamp_s = float(tokens[8 + n])
    except ValueError:
        raise InputError("a FLASER field is not a number", path=path, line=line_no) from None
    if not all(math.isfinite(v) for v in (x, y, theta, stamp_s)):
        raise InputError("FLASER pose or time stamp is not finite", path=path, line=line_no)
    scan = Scan.from_laserscan(
        angle_min=-math.pi / 2,
        angle_increment=math.pi / (n - 1),
        ranges=ranges,
        range_min=0.0,
        range_max=range_max,
        stamp_ns=round(stamp_s * 1e9),
        frame_id=frame_id,
    )
    return scan, Pose2D(x, y, azimuth_of_yaw(theta))
