"""The BreezySLAM/CoreSLAM "Mines" rover log: one URG-04LX scan per line.

Format (``../shared/data/breezyslam_urg04lx/SOURCE.txt``): whitespace-separated
tokens; token 0 the time stamp in microseconds, tokens 24..705 the 682 ranges
in millimetres (0 = no return), the rest rover telemetry. The 682 beams span
about 240 degrees at the URG's native step of 360/1024 degrees, centred on the
forward axis. The log does not state the rotation direction; beams are taken
as counter-clockwise (the URG's own convention, and REP 103's).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mast import limits
from mast.core.scan import Scan
from mast.errors import InputError

__all__ = ["URG04LX_BEAMS", "read_urg_log"]

URG04LX_BEAMS = 682
_FIRST, _STEP_RAD = 24, math.radians(360.0 / 1024.0)


def read_urg_log(
    path: str | Path, *, range_min_m: float = 0.02, range_max_m: float = 5.6
) -> Iterator[Scan]:
    """Yield one :class:`Scan` per line; a malformed line is an :class:`InputError` naming it."""
    p = Path(path)
    try:
        fh = p.open("rb")
    except OSError as err:
        raise InputError(f"cannot read: {err.strerror}", path=p) from None
    angle_min = -_STEP_RAD * (URG04LX_BEAMS - 1) / 2
    with fh:
        line_no = 0
        while raw := limits.read_line(fh, p, line_no + 1):
            line_no += 1
            tokens = raw.split()
            if not tokens:
                continue
            if len(tokens) < _FIRST + URG04LX_BEAMS:
                raise InputError(
                    f"{len(tokens)} fields; a URG-04LX log line needs "
                    f"at least {_FIRST + URG04LX_BEAMS}",
                    path=p,
                    line=line_no,
                )
            try:
                stamp_us = int(tokens[0])
                ranges_mm = np.array([float(t) for t in tokens[_FIRST : _FIRST + URG04LX_BEAMS]])
            except ValueError:
                raise InputError("a field is not a number", path=p, line=line_no) from None
            yield Scan.from_laserscan(
                angle_min=angle_min,
                angle_increment=_STEP_RAD,
                ranges=ranges_mm / 1000.0,
                range_min=range_min_m,
                range_max=range_max_m,
                stamp_ns=stamp_us * 1000,
                frame_id="urg04lx",
            )
