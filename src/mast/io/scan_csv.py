"""The single-scan file: ``angle_rad,range_m[,intensity]``, one row per beam."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from mast.core.scan import Scan
from mast.errors import InputError
from mast.io._csv import CsvRows, parse_number

__all__ = ["read_scan_csv", "write_scan_csv"]

_NO_RETURN = {"", "nan", "-nan", "inf", "+inf", "-inf", "infinity", "none", "null"}


def read_scan_csv(
    path: str | Path,
    *,
    range_min_m: float = 0.0,
    range_max_m: float = math.inf,
) -> Scan:
    """Read one scan from CSV (DESIGN.md, "Single scan").

    Rows must be in strictly increasing angle order. A beam with no return is
    an empty field, ``nan``, ``inf``, ``0`` or a range outside
    ``[range_min_m, range_max_m]``; a negative range is treated as no return,
    as some drivers write ``-1`` for one.

    Raises
    ------
    InputError
        Naming the file, the line and the problem.
    """
    rows = CsvRows(path, required=("angle_rad", "range_m"), optional=("intensity",))
    p = rows.path
    angles: list[float] = []
    ranges: list[float] = []
    inten: list[float] = []
    prev_line = 0
    for line, f in rows:
        a = parse_number(f["angle_rad"], column="angle_rad", path=p, line=line)
        if angles and not a > angles[-1]:
            raise InputError(
                f"angle_rad {a!r} does not increase (line {prev_line} has {angles[-1]!r}); "
                "beams must be in increasing angle order",
                path=p,
                line=line,
            )
        r_text = f["range_m"].strip()
        if r_text.lower() in _NO_RETURN:
            r = math.nan if r_text.lower() in {"", "nan", "-nan", "none", "null"} else math.inf
        else:
            r = parse_number(r_text, column="range_m", path=p, line=line, finite=False)
        angles.append(a)
        ranges.append(r)
        if rows.has("intensity"):
            t = f["intensity"].strip()
            inten.append(
                math.nan
                if t.lower() in _NO_RETURN
                else parse_number(t, column="intensity", path=p, line=line, finite=False)
            )
        prev_line = line
    if not angles:
        raise InputError("no beams after the header", path=p, line=rows.header_line)
    try:
        return Scan(
            np.array(angles),
            np.array(ranges),
            np.array(inten) if inten else None,
            range_min_m,
            range_max_m,
        )
    except InputError as err:
        raise InputError(err.problem, path=p) from None


def write_scan_csv(path: str | Path, scan: Scan) -> None:
    """Write a scan in the single-scan CSV contract (no return as an empty field)."""
    with Path(path).open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        has_i = scan.intensities is not None
        w.writerow(["angle_rad", "range_m", *(["intensity"] if has_i else [])])
        for i in range(len(scan)):
            r = float(scan.ranges_m[i])
            row = [repr(float(scan.angles_rad[i])), repr(r) if math.isfinite(r) else ""]
            if has_i and scan.intensities is not None:
                v = float(scan.intensities[i])
                row.append(repr(v) if math.isfinite(v) else "")
            w.writerow(row)
