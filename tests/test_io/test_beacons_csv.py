import contextlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from mast import Beacon, BeaconError, InputError, Survey
from mast.io import read_survey, write_survey
from mast.sim import paper_design

GOOD = """beacon,edge,easting,northing,elevation
B1,1,100.0,200.0,1.5
B1,2,100.3539,200.2,1.5
B1,3,100.9637,200.2,1.5
B1,4,101.0,200.0,1.5
"""


def test_round_trip_is_exact(tmp_path: Path) -> None:
    d = paper_design(1.0, 0.2)
    survey = Survey(
        [
            d.beacon("west", [512345.678, 7012345.678], [0.0, 1.0], tunnel_side=-1),
            Beacon("east", d.edges_local + [3.0, 4.0], np.array([1.5, 1.5, 1.6, np.nan])),
        ]
    )
    p = tmp_path / "beacons.csv"
    write_survey(p, survey)
    back = read_survey(p)
    assert back.ids == ["west", "east"]
    for a, b in zip(survey, back, strict=True):
        assert_array_equal(a.edges, b.edges)
    assert back["west"].elevations is None
    east = back["east"].elevations
    assert east is not None
    assert_array_equal(east[:3], [1.5, 1.5, 1.6])
    assert np.isnan(east[3])


def test_reads_extra_columns_any_order_and_case(write_text: Callable[..., Path]) -> None:
    text = "Northing , note, EDGE,Easting,Beacon\n" + "\n".join(
        f"{n},x,{k},{e},A"
        for k, (e, n) in enumerate([(0, 0), (0.3539, 0.2), (0.9637, 0.2), (1.0, 0.0)], 1)
    )
    s = read_survey(write_text("b.csv", "\ufeff" + text + "\n\n"))
    assert s["A"].edges[1].tolist() == [0.3539, 0.2]


def test_edges_may_come_in_any_row_order(write_text: Callable[..., Path]) -> None:
    lines = GOOD.splitlines()
    s = read_survey(
        write_text("b.csv", "\n".join([lines[0], lines[3], lines[1], lines[4], lines[2]]))
    )
    assert s["B1"].edges[0].tolist() == [100.0, 200.0]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", r"b\.csv: file is empty; expected a header row"),
        (
            "beacon,edge,easting\nB1,1,0\n",
            r"b\.csv, line 1: header lacks required column\(s\) northing",
        ),
        ("beacon,edge,easting,northing\n", r"line 1: no beacon rows after the header"),
        (GOOD.replace("100.3539", "1O0.35"), r"line 3: column 'easting': '1O0.35' is not a number"),
        (
            GOOD.replace("200.2,1.5\nB1,3", "nan,1.5\nB1,3"),
            r"line 3: column 'northing': 'nan' is not a finite number",
        ),
        (
            GOOD.replace("B1,3,", "B1,5,"),
            r"line 4: column 'edge': '5' is not an edge number 1\.\.4",
        ),
        (GOOD.replace("B1,3,", "B1,2.5,"), r"line 4: column 'edge': '2.5' is not an edge number"),
        (
            GOOD.replace("B1,3,", "B1,2,"),
            r"line 4: beacon 'B1' edge 2 given twice \(first on line 3\)",
        ),
        (
            GOOD.replace("B1,4,101.0,200.0,1.5\n", ""),
            r"line 2: beacon 'B1' has 3 edge\(s\); edge\(s\) 4 missing",
        ),
        (GOOD.replace("B1,2,", ",2,"), r"line 3: column 'beacon' is empty"),
        (
            GOOD.replace("B1,4,101.0,200.0,1.5", "B1,4"),
            r"line 5: row has 2 field\(s\); column\(s\) easting, northing missing",
        ),
        (
            GOOD.replace("B1,2,100.3539,200.2,1.5", "B1,2,100.3539,200.2,high"),
            r"line 3: column 'elevation': 'high' is not a number",
        ),
    ],
)
def test_errors_name_file_line_and_problem(
    write_text: Callable[..., Path], content: str, message: str
) -> None:
    with pytest.raises(InputError, match=message):
        read_survey(write_text("b.csv", content))


def test_unidentifiable_beacon_is_named_with_its_line(write_text: Callable[..., Path]) -> None:
    text = GOOD + "flat,1,0,0\nflat,2,1,0.001\nflat,3,2.5,0\nflat,4,3,0.5\n"
    with pytest.raises(
        BeaconError, match=r"line 6: beacon 'flat' is not identifiable: .*deflection at e2"
    ):
        read_survey(write_text("b.csv", text))
    # ... and can still be read for inspection
    assert "flat" in read_survey(write_text("b2.csv", text), rules=None)


def test_not_utf8_and_missing_file(write_text: Callable[..., Path], tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"line 2: not UTF-8 text \(byte 0xff"):
        read_survey(write_text("b.csv", b"beacon,edge,easting,northing\n\xff\xfe,1,2,3\n"))
    with pytest.raises(InputError, match=r"nope\.csv: file not found"):
        read_survey(tmp_path / "nope.csv")
    with pytest.raises(InputError, match="is a folder"):
        read_survey(tmp_path)
    with pytest.raises(InputError, match="NUL byte"):
        read_survey(write_text("n.csv", "beacon,edge,easting,northing\nB\x00,1,2,3\n"))


@settings(max_examples=1000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.binary(max_size=400))
def test_garbage_bytes_only_raise_input_error(tmp_path: Path, data: bytes) -> None:
    p = tmp_path / "fuzz.csv"
    p.write_bytes(data)
    with contextlib.suppress(InputError):
        read_survey(p)


@settings(max_examples=1000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.lists(
            st.sampled_from(
                ["B1", "1", "2", "3", "4", "0.5", "-1e308", "x", "", "nan", "1e999", '"']
            ),
            max_size=6,
        ),
        max_size=12,
    )
)
def test_garbage_rows_only_raise_input_error(tmp_path: Path, rows: list[list[str]]) -> None:
    p = tmp_path / "fuzz.csv"
    p.write_text(
        "beacon,edge,easting,northing\n" + "\n".join(",".join(r) for r in rows), encoding="utf-8"
    )
    try:
        s = read_survey(p)
    except InputError:
        return
    for b in s:
        assert b.edges.shape == (4, 2)
        assert np.all(np.isfinite(b.edges))


def test_sigma_and_design_round_trip_and_stay_optional(tmp_path: Path) -> None:
    d = paper_design(1.0, 0.2)
    survey = Survey(
        [
            Beacon("A", d.edges_local, None, np.array([0.001, 0.0015, np.nan, 0.002]), "paper"),
            Beacon("B", d.edges_local + [5.0, 0.0]),
        ]
    )
    p = tmp_path / "beacons.csv"
    write_survey(p, survey)
    assert p.read_text().splitlines()[0] == "beacon,edge,easting,northing,sigma_m,design"
    back = read_survey(p)
    a, b = back["A"], back["B"]
    assert a.design == "paper"
    assert a.edge_sigmas_m is not None
    assert_array_equal(a.edge_sigmas_m[[0, 1, 3]], [0.001, 0.0015, 0.002])
    assert np.isnan(a.edge_sigmas_m[2])
    assert b.design is None
    assert b.edge_sigmas_m is None
    # a survey without them is written as before
    write_survey(p, Survey([Beacon("B", d.edges_local)]))
    assert p.read_text().splitlines()[0] == "beacon,edge,easting,northing"


@pytest.mark.parametrize(
    ("rows", "said"),
    [
        (
            ("1,,a", "2,,a", "3,,b", "4,,a"),
            "line 4: beacon 'B1' is of design 'a' on line 2 and 'b'",
        ),
        (("1,-0.001,", "2,,", "3,,", "4,,"), "line 2: column 'sigma_m': -0.001 is negative"),
        (("1,,", "2,3,", "3,,", "4,,"), "line 3: column 'sigma_m': 3 m is beyond ±1 m"),
        (("1,,", "2,,", "3,nan,", "4,,"), "line 4: column 'sigma_m': 'nan' is not a finite"),
    ],
)
def test_a_bad_sigma_or_design_names_the_line(
    tmp_path: Path, rows: tuple[str, ...], said: str
) -> None:
    xy = ("100.0,200.0", "100.3539,200.2", "100.9637,200.2", "101.0,200.0")
    lines = ["beacon,edge,easting,northing,sigma_m,design"]
    for r, p in zip(rows, xy, strict=True):
        edge, *rest = r.split(",")
        lines.append(f"B1,{edge},{p},{','.join(rest)}")
    path = tmp_path / "s.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=said):
        read_survey(path)
