"""The scan CSV is streamed into arrays; anything irregular is read again as a whole.

The streaming reader must read every file exactly as the whole-file reader
does, and leave every error to it, so that messages (file, line, problem) and
their precedence are those of the whole-file reader.
"""

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mast import InputError, Scan
from mast.io import read_scan_csv, scan_csv, write_scan_csv
from mast.io._csv import STREAM_CHUNK_BYTES, IrregularError

_TOKENS = [
    "", " ", "nan", "-nan", "NaN", "inf", "-inf", "+inf", "Infinity", "none", "NULL",
    "0", "-1", "1e999", "-1e999", "1_0", " 2.5 ", "abc", "3", '"4"',
]  # fmt: skip


def test_a_plain_file_is_streamed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    r = np.linspace(1.0, 5.0, 2000)
    r[::7] = np.nan
    scan = Scan.from_laserscan(angle_min=-1.0, angle_increment=0.001, ranges=r, intensities=r)
    p = tmp_path / "s.csv"
    write_scan_csv(p, scan)

    def whole(path: object) -> object:
        raise AssertionError("a plain file must not be read as a whole")

    monkeypatch.setattr(scan_csv, "_read_whole", whole)
    back = read_scan_csv(p)
    assert np.array_equal(back.ranges_m, scan.ranges_m, equal_nan=True)
    assert back.intensities is not None
    assert np.array_equal(back.intensities, r, equal_nan=True)


@settings(max_examples=400, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.tuples(st.sampled_from(_TOKENS), st.sampled_from(_TOKENS), st.booleans()),
        min_size=1,
        max_size=8,
    ),
    st.booleans(),
    st.sampled_from(["\n", "\r\n", "\r"]),
)
def test_streaming_reads_what_the_whole_file_reader_reads(
    tmp_path: Path, rows: list[tuple[str, str, bool]], intensity: bool, newline: str
) -> None:
    lines = ["angle_rad,range_m" + (",intensity" if intensity else "")]
    for k, (r, i, blank) in enumerate(rows):
        if blank:
            lines.append(" , ")
        lines.append(f"{0.1 * k!r},{r}" + (f",{i}" if intensity else ""))
    p = tmp_path / "f.csv"
    p.write_text(newline.join(lines) + newline, encoding="utf-8", newline="")
    try:
        whole = scan_csv._read_whole(p)
    except InputError:
        whole = None
    try:
        streamed = scan_csv._stream(p)
    except (IrregularError, InputError):
        return  # left to the whole-file reader
    assert whole is not None
    for a, b in zip(whole[1:], streamed[1:], strict=True):
        assert (a is None) == (b is None)
        if a is not None and b is not None:
            assert a.tobytes() == b.tobytes()  # the same bits, nan and signs included


def _rows(n: int) -> str:
    return "".join(f"{0.001 * k!r},{1.0 + 0.001 * k!r}\n" for k in range(n))


def test_a_late_bad_byte_is_named_as_before(tmp_path: Path) -> None:
    head = ("angle_rad,range_m\n" + _rows(20_000)).encode()
    assert len(head) > 4 * STREAM_CHUNK_BYTES
    p = tmp_path / "s.csv"
    p.write_bytes(head + b"99.0,\xff\n")
    with pytest.raises(
        InputError, match=rf"line 20002: not UTF-8 text \(byte 0xff at offset {len(head) + 5}\)"
    ):
        read_scan_csv(p)


def test_a_nul_byte_takes_precedence_over_an_earlier_bad_number(tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    p.write_bytes(b"angle_rad,range_m\n0.1,abc\n" + _rows(3000).encode() + b"9.0,1\x00\n")
    with pytest.raises(InputError, match=r"line 3003: contains a NUL byte"):
        read_scan_csv(p)


def test_quoted_fields_and_extra_columns_are_read(tmp_path: Path) -> None:
    p = tmp_path / "s.csv"
    with p.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, quoting=csv.QUOTE_ALL)
        w.writerow(["note", "Range_M ", " ANGLE_RAD", "intensity"])
        w.writerow(["a,b", "1.5", "0.1", ""])
        w.writerow(["line\nbreak", "", "0.2", "7"])
    scan = read_scan_csv(p)
    assert scan.angles_rad.tolist() == [0.1, 0.2]
    assert scan.ranges_m[0] == 1.5
    assert math.isnan(scan.ranges_m[1])
    assert scan.intensities is not None
    assert scan.intensities[1] == 7.0
