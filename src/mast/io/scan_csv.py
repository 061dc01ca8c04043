"""The single-scan file: ``angle_rad,range_m[,intensity]``, one row per beam."""

from __future__ import annotations

import csv
import math
from array import array
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast import limits
from mast.core.scan import Scan
from mast.errors import InputError
from mast.io._csv import CsvRows, CsvStream, IrregularError, parse_number
from mast.io.atomic import atomic_open

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

    The file is streamed into arrays (memory a few tens of bytes per beam, any
    size of file); anything irregular is read again as a whole, which names
    the problem.

    Raises
    ------
    InputError
        Naming the file, the line and the problem.
    """
    try:
        p, angles, ranges, inten = _stream(path)
    except (IrregularError, InputError, OSError, UnicodeDecodeError, csv.Error):
        p, angles, ranges, inten = _read_whole(path)
    try:
        return Scan(angles, ranges, inten, range_min_m, range_max_m)
    except InputError as err:
        raise InputError(err.problem, path=p) from None


_Columns = tuple[Path, NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]


def _range_value(text: str, path: Path, line: int) -> float:
    """One ``range_m`` field: the no-return spellings, else a number (``inf`` allowed)."""
    r_text = text.strip()
    if r_text.lower() in _NO_RETURN:
        return math.nan if r_text.lower() in {"", "nan", "-nan", "none", "null"} else math.inf
    return parse_number(r_text, column="range_m", path=path, line=line, finite=False)


def _intensity_value(text: str, path: Path, line: int) -> float:
    """One ``intensity`` field: nan for the no-return spellings, else a number."""
    t = text.strip()
    if t.lower() in _NO_RETURN:
        return math.nan
    return parse_number(t, column="intensity", path=path, line=line, finite=False)


def _stream(path: str | Path) -> _Columns:
    """Plain, valid files row by row into arrays; :class:`IrregularError` for anything else.

    Reads every value as :func:`_read_whole` does (the fast ``float`` of a
    field is taken only where it equals what the whole-file reader makes of
    it); an error of any kind is left to :func:`_read_whole` to name.
    """
    fl = float
    angles, ranges, inten = array("d"), array("d"), array("d")
    with CsvStream(path, required=("angle_rad", "range_m"), optional=("intensity",)) as rows:
        p = rows.path
        ia, ir = rows.columns["angle_rad"], rows.columns["range_m"]
        ii = rows.columns.get("intensity")
        prev = -math.inf
        for row in rows.reader:
            try:
                a = fl(row[ia])
                r_text = row[ir]
            except (ValueError, IndexError):
                if any(cell.strip() for cell in row):
                    raise IrregularError("row") from None
                continue  # a blank line
            if not (a > prev and a - a == 0.0):  # not increasing, or not finite
                raise IrregularError("angle")
            prev = a
            try:
                r = fl(r_text)
            except ValueError:
                r = _range_value(r_text, p, 0)
            else:
                if r - r != 0.0:  # nan or infinite: as the no-return spellings read
                    r = _range_value(r_text, p, 0)
            angles.append(a)
            ranges.append(r)
            if len(angles) > limits.MAX_BEAMS:
                raise IrregularError("too many beams")
            if ii is not None:
                t = row[ii] if ii < len(row) else ""
                try:
                    v = fl(t)
                except ValueError:
                    v = _intensity_value(t, p, 0)
                else:
                    if v - v != 0.0:
                        v = _intensity_value(t, p, 0)
                inten.append(v)
    if not angles:
        raise IrregularError("no beams")
    return (
        p,
        np.frombuffer(angles, dtype=np.float64),
        np.frombuffer(ranges, dtype=np.float64),
        np.frombuffer(inten, dtype=np.float64) if ii is not None else None,
    )


def _read_whole(path: str | Path) -> _Columns:
    """The whole file at once, row by row: every error named with its file and line."""
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
        angles.append(a)
        if len(angles) > limits.MAX_BEAMS:
            raise InputError(
                f"more than {limits.MAX_BEAMS} beams, the most MAST takes in one scan "
                "(mast.limits.MAX_BEAMS)",
                path=p,
                line=line,
            )
        ranges.append(_range_value(f["range_m"], p, line))
        if rows.has("intensity"):
            inten.append(_intensity_value(f["intensity"], p, line))
        prev_line = line
    if not angles:
        raise InputError("no beams after the header", path=p, line=rows.header_line)
    return p, np.array(angles), np.array(ranges), np.array(inten) if inten else None


def write_scan_csv(path: str | Path, scan: Scan) -> None:
    """Write a scan in the single-scan CSV contract (no return as an empty field)."""
    with atomic_open(path, "w", newline="", encoding="utf-8") as fh:
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
