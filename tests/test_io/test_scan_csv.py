import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from mast import InputError, Scan
from mast.io import read_scan_csv, write_scan_csv


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    r = rng.uniform(0.1, 30, 541)
    r[[3, 10, 20]] = np.nan
    scan = Scan.from_laserscan(
        angle_min=-2.356194490192345,
        angle_increment=math.radians(0.5),
        ranges=r,
        intensities=rng.uniform(0, 100, 541),
    )
    p = tmp_path / "s.csv"
    write_scan_csv(p, scan)
    back = read_scan_csv(p)
    assert_array_equal(back.angles_rad, scan.angles_rad)
    assert_array_equal(back.ranges_m, scan.ranges_m)
    assert back.intensities is not None
    assert scan.intensities is not None
    assert_array_equal(back.intensities, scan.intensities)
    assert_array_equal(back.valid, scan.valid)


def test_no_return_spellings(write_text: Callable[..., Path]) -> None:
    text = "angle_rad,range_m\n0.0,\n0.1,nan\n0.2,inf\n0.3,0\n0.4,-1\n0.5,99\n0.6,2.5\n"
    scan = read_scan_csv(write_text("s.csv", text), range_max_m=30.0)
    assert scan.valid.tolist() == [False] * 6 + [True]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", r"s\.csv: file is empty"),
        ("angle,range_m\n0,1\n", r"s\.csv, line 1: header lacks required column\(s\) angle_rad"),
        ("angle_rad,range_m\n", r"line 1: no beams after the header"),
        (
            "angle_rad,range_m\n0.1,1\n0.1,2\n",
            r"line 3: angle_rad 0\.1 does not increase \(line 2 has 0\.1\)",
        ),
        (
            "angle_rad,range_m\n0.2,1\n\n0.1,2\n",
            r"line 4: angle_rad 0\.1 does not increase \(line 2",
        ),
        ("angle_rad,range_m\n0.1,1\nabc,2\n", r"line 3: column 'angle_rad': 'abc' is not a number"),
        (
            "angle_rad,range_m\n0.1,1\ninf,2\n",
            r"line 3: column 'angle_rad': 'inf' is not a finite number",
        ),
        ("angle_rad,range_m\n0.1,1\n0.2,2m\n", r"line 3: column 'range_m': '2m' is not a number"),
        ("angle_rad,range_m\n0.1\n", r"line 2: row has 1 field\(s\); column\(s\) range_m missing"),
        (
            "angle_rad,range_m,intensity\n0.1,1,bright\n",
            r"line 2: column 'intensity': 'bright' is not a number",
        ),
    ],
)
def test_errors_name_file_line_and_problem(
    write_text: Callable[..., Path], content: str, message: str
) -> None:
    with pytest.raises(InputError, match=message):
        read_scan_csv(write_text("s.csv", content))


@settings(max_examples=1000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=300))
def test_garbage_bytes_only_raise_input_error(tmp_path: Path, data: bytes) -> None:
    p = tmp_path / "fuzz.csv"
    p.write_bytes(b"angle_rad,range_m\n" + data)
    try:
        scan = read_scan_csv(p)
    except InputError:
        return
    assert np.all(np.diff(scan.angles_rad) > 0)


@settings(max_examples=1000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.tuples(
            st.one_of(st.floats(), st.text(max_size=4)), st.one_of(st.floats(), st.text(max_size=4))
        ),
        max_size=20,
    )
)
def test_garbage_values_only_raise_input_error(
    tmp_path: Path, rows: list[tuple[object, object]]
) -> None:
    p = tmp_path / "fuzz.csv"
    with p.open("w", encoding="utf-8", newline="") as fh:
        import csv

        w = csv.writer(fh)
        w.writerow(["angle_rad", "range_m"])
        for a, r in rows:
            w.writerow([a, r])
    try:
        scan = read_scan_csv(p)
    except InputError:
        return
    assert np.all(np.isfinite(scan.angles_rad))
    assert np.all(np.isfinite(scan.ranges_m[scan.valid]))
