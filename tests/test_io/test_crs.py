"""The grid's coordinate reference system (issue 35): --crs read and checked, a local grid
kept local, the CRS in a LAS header, GeoJSON and the point list's D°M'S azimuths."""

from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path
from typing import Any

import jsonschema
import laspy
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pyproj import CRS

from mast.core.pose import parse_azimuth
from mast.errors import InputError
from mast.io.crs import GridCrs, local_grid, parse_crs
from mast.io.geojson import FeatureCollectionWriter, line_string, point
from mast.io.las import LasWriter, new_las_header
from mast.io.point_list import POINT_LIST_COLUMNS, PointListWriter

#: A structural GeoJSON schema (RFC 7946 geometries, with the 2008 ``crs`` member MAST
#: writes for a grid): every position two finite numbers, a LineString two or more.
POSITION = {"type": "array", "minItems": 2, "maxItems": 3, "items": {"type": "number"}}
GEOJSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "required": ["type", "features"],
    "properties": {
        "type": {"const": "FeatureCollection"},
        "name": {"type": "string"},
        "crs": {
            "type": "object",
            "required": ["type", "properties"],
            "properties": {
                "type": {"const": "name"},
                "properties": {
                    "type": "object",
                    "required": ["name"],
                    "properties": {"name": {"type": "string", "minLength": 1}},
                },
            },
        },
        "features": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["type", "geometry", "properties"],
                "properties": {
                    "type": {"const": "Feature"},
                    "properties": {"type": ["object", "null"]},
                    "geometry": {
                        "oneOf": [
                            {
                                "type": "object",
                                "required": ["type", "coordinates"],
                                "properties": {
                                    "type": {"const": "Point"},
                                    "coordinates": POSITION,
                                },
                            },
                            {
                                "type": "object",
                                "required": ["type", "coordinates"],
                                "properties": {
                                    "type": {"const": "LineString"},
                                    "coordinates": {
                                        "type": "array",
                                        "minItems": 2,
                                        "items": POSITION,
                                    },
                                },
                            },
                        ]
                    },
                },
            },
        },
    },
}


def check_geojson(path: Path) -> dict[str, Any]:
    """The GeoJSON at ``path``, after checking it against :data:`GEOJSON_SCHEMA` and that
    every coordinate is finite (JSON itself has no NaN; Python's parser would take one)."""
    data: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"), parse_constant=_refuse)
    errors = list(jsonschema.Draft202012Validator(GEOJSON_SCHEMA).iter_errors(data))
    assert not errors, errors[0].message
    for f in data["features"]:
        xy = np.asarray(f["geometry"]["coordinates"], dtype=float)
        assert np.all(np.isfinite(xy))
    return data


def _refuse(name: str) -> None:
    raise AssertionError(f"{name} in a GeoJSON file")


# --------------------------------------------------------------------------- --crs


@pytest.mark.parametrize("text", ["EPSG:32735", "32735", "epsg:32735", " EPSG:32735 "])
def test_an_epsg_code_is_taken_with_or_without_its_authority(text: str) -> None:
    crs = parse_crs(text)
    assert crs.epsg == 32735
    assert crs.name == "WGS 84 / UTM zone 35S"
    assert crs.pyproj().equals(CRS.from_epsg(32735))
    assert crs.record() == {"name": crs.name, "wkt": crs.wkt, "epsg": 32735}
    assert crs.line() == "WGS 84 / UTM zone 35S (EPSG:32735)"
    assert crs.geojson_member()["properties"]["name"] == "urn:ogc:def:crs:EPSG::32735"


def test_a_local_grid_stays_an_engineering_crs_with_its_name() -> None:
    crs = parse_crs("local:Mine Grid A")
    back = CRS.from_wkt(crs.wkt)
    assert back.is_engineering
    assert not back.is_geographic
    assert back.name == "Mine Grid A"
    assert [a.direction for a in back.axis_info] == ["east", "north"]
    assert {a.unit_name for a in back.axis_info} == {"metre"}
    assert crs.local
    assert crs.epsg is None
    assert "epsg" not in crs.record()
    assert crs.line() == "Mine Grid A (local grid)"
    assert crs.geojson_member() == {"type": "name", "properties": {"name": "Mine Grid A"}}
    # its WKT1 for LAS is a LOCAL_CS of the same name, read back as the same CRS
    las = CRS.from_wkt(crs.las_wkt())
    assert las.is_engineering
    assert las.equals(back)


def test_a_wkt_file_and_a_wkt_string_give_the_same_crs(tmp_path: Path) -> None:
    wkt = CRS.from_epsg(32735).to_wkt("WKT1_ESRI")
    path = tmp_path / "grid.prj"
    path.write_text(wkt + "\n", encoding="utf-8")
    from_file = parse_crs(str(path))
    assert from_file.pyproj().equals(CRS.from_epsg(32735), ignore_axis_order=True)
    assert parse_crs(wkt).wkt == from_file.wkt
    # a local grid given as WKT (an ENGCRS) keeps its name and stays local
    path.write_text(local_grid("Pit 3").wkt, encoding="utf-8")
    assert parse_crs(str(path)).local
    assert parse_crs(str(path)).name == "Pit 3"


def test_a_compound_crs_keeps_its_projected_part_for_geojson() -> None:
    crs = parse_crs("EPSG:32735+5773")
    assert crs.epsg is None
    assert crs.horizontal_epsg == 32735
    assert crs.geojson_member()["properties"]["name"] == "urn:ogc:def:crs:EPSG::32735"
    assert CRS.from_wkt(crs.las_wkt()).equals(crs.pyproj())


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("EPSG:4326", r"WGS 84 is a geographic \(degrees\) CRS; MAST's grid is metres"),
        ("+proj=longlat +datum=WGS84", "geographic"),
        ("EPSG:4978", "geocentric CRS"),
        ("EPSG:5773", "vertical CRS"),
        ("EPSG:2229", "is in US survey foot; MAST's grid coordinates are metres"),
        ("EPSG:2048", "axes pointing west and south"),
        ("EPSG:99999", "not a coordinate reference system pyproj knows"),
        ("nonsense", "not a coordinate reference system pyproj knows"),
        ("", "empty; give an EPSG code"),
        ("local:", r"a local grid needs a name \(local:NAME\)"),
        ('local:Grid "A"', "without a double quote"),
        ("local:" + "x" * 81, "at most 80 printable characters"),
    ],
)
def test_a_crs_that_is_not_a_metric_east_north_grid_is_refused(text: str, words: str) -> None:
    with pytest.raises(InputError, match=words) as err:
        parse_crs(text)
    assert "--crs" in str(err.value)
    assert "\n" not in str(err.value)


def test_a_wkt_file_that_is_missing_or_not_text_is_refused_naming_it(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="--crs: file not found") as err:
        parse_crs(str(tmp_path / "none.wkt"))
    assert err.value.path == str(tmp_path / "none.wkt")
    binary = tmp_path / "grid.wkt"
    binary.write_bytes(b"\xff\xfe\x00PROJCS")
    with pytest.raises(InputError, match="NUL byte"):
        parse_crs(str(binary))
    with pytest.raises(InputError, match="is a folder"):
        parse_crs(str(tmp_path))


# --------------------------------------------------------------------------- LAS


@pytest.mark.parametrize(("version", "point_format"), [("1.4", 6), ("1.2", 3)])
def test_a_las_header_given_a_crs_carries_it_as_wkt_in_las_1_4(
    tmp_path: Path, version: str, point_format: int
) -> None:
    crs = parse_crs("EPSG:32735")
    header = new_las_header(
        offsets=[0.0, 0.0, 0.0],
        software="test",
        version=version,
        point_format=point_format,
        crs=crs,
    )
    path = tmp_path / "c.laz"
    with LasWriter(path, header) as las:
        rec = las.zeros(3)
        rec.X = np.arange(3, dtype=np.int32)
        las.write(rec)
    back = laspy.read(path)
    assert str(back.header.version) == "1.4"  # the WKT bit is 1.4's
    assert back.header.global_encoding.wkt
    assert back.header.point_format.id == point_format
    parsed = back.header.parse_crs()
    assert parsed is not None
    assert parsed.equals(crs.pyproj())
    assert sum(v.record_id == 2112 for v in back.header.vlrs) == 1


@pytest.mark.parametrize("code", [2193, 31467])
def test_a_northing_first_crs_is_written_easting_first_as_gis_reads_it(
    tmp_path: Path, code: int
) -> None:
    """NZTM 2000 and Gauss-Kruger zone 3 list northing first. MAST's coordinates are
    easting first, as LAS, GeoJSON and every GIS take x and y: the LAS carries the CRS
    in that order (GDAL's WKT1), which reads back as the same EPSG entry."""
    crs = parse_crs(f"EPSG:{code}")
    assert crs.epsg == code
    header = new_las_header(
        offsets=[0.0, 0.0, 0.0], software="test", version="1.4", point_format=6, crs=crs
    )
    path = tmp_path / "c.las"
    with LasWriter(path, header) as las:
        las.write(las.zeros(1))
    parsed = laspy.read(path).header.parse_crs()
    assert parsed is not None
    assert parsed.name == crs.name  # (pyproj may name the entry of its easting-first twin)
    assert [a.direction for a in parsed.axis_info[:2]] == ["east", "north"]
    assert parsed.geodetic_crs.equals(crs.pyproj().geodetic_crs, ignore_axis_order=True)
    assert parsed.coordinate_operation == crs.pyproj().coordinate_operation


def test_a_las_header_without_a_crs_records_none(tmp_path: Path) -> None:
    header = new_las_header(offsets=[0.0, 0.0, 0.0], software="test", version="1.2", point_format=3)
    path = tmp_path / "c.las"
    with LasWriter(path, header) as las:
        las.write(las.zeros(1))
    back = laspy.read(path)
    assert str(back.header.version) == "1.2"
    assert back.header.parse_crs() is None


# --------------------------------------------------------------------------- GeoJSON


@pytest.mark.parametrize("crs", [None, parse_crs("EPSG:32735"), local_grid("Mine Grid A")])
def test_a_feature_collection_validates_with_its_crs_member(
    tmp_path: Path, crs: GridCrs | None
) -> None:
    path = tmp_path / "f.geojson"
    with path.open("w", encoding="utf-8") as fh:
        w = FeatureCollectionWriter(fh, crs=crs, name="fixes")
        w.add(point(512345.12345, 7012345.6), {"name": "F1", "azimuth_dms": "1°00'00.0\""})
        w.add(line_string([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]]), {"scans": 3})
        assert w.close() == 2
    data = check_geojson(path)
    assert data["name"] == "fixes"
    assert data["features"][0]["geometry"]["coordinates"] == [512345.1235, 7012345.6]
    if crs is None:
        assert "crs" not in data
    else:
        assert data["crs"] == crs.geojson_member()


def test_an_empty_collection_is_valid_and_bad_geometries_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "empty.geojson"
    with path.open("w", encoding="utf-8") as fh:
        assert FeatureCollectionWriter(fh).close() == 0
    assert check_geojson(path)["features"] == []
    with pytest.raises(ValueError, match="at least two positions"):
        line_string([[1.0, 2.0]])
    with pytest.raises(ValueError, match="not finite"):
        point(math.nan, 1.0)
    with pytest.raises(ValueError, match="not finite"):
        line_string([[1.0, 2.0], [math.inf, 1.0]])


# --------------------------------------------------------------------------- point list


def _point_row(azimuth_deg: float) -> dict[str, str]:
    fh = io.StringIO(newline="")
    PointListWriter(fh).add("F1", 1.0, 2.0, None, azimuth_deg, 0.001, 0.002, 1 / 3600)
    fh.seek(0)
    rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == POINT_LIST_COLUMNS
    return rows[0]


def test_the_point_list_writes_dms_and_arc_seconds() -> None:
    row = _point_row(123 + 4 / 60 + 5.6 / 3600)
    assert row == {
        "name": "F1",
        "easting": "1.0000",
        "northing": "2.0000",
        "elevation": "",
        "azimuth": "123°04'05.6\"",
        "azimuth_ddd_mmss": "123.04056",
        "sigma_easting_m": "0.0010",
        "sigma_northing_m": "0.0020",
        "sigma_azimuth_arcsec": "1.0",
    }


@pytest.mark.parametrize(
    ("azimuth_deg", "dms"),
    [
        (359 + 59 / 60 + 59.95 / 3600, "0°00'00.0\""),
        (359 + 59 / 60 + 59.94 / 3600, "359°59'59.9\""),
        (10 + 59 / 60 + 59.96 / 3600, "11°00'00.0\""),
        (-0.5 / 3600, "359°59'59.5\""),
        (360.0, "0°00'00.0\""),
    ],
)
def test_rounding_carries_into_minutes_and_degrees_never_60(azimuth_deg: float, dms: str) -> None:
    row = _point_row(azimuth_deg)
    assert row["azimuth"] == dms
    d, m, sec = re.match(r"(\d+)°(\d\d)'(\d\d\.\d)\"", dms).groups()  # type: ignore[union-attr]
    assert row["azimuth_ddd_mmss"] == f"{d}.{m}{sec.replace('.', '')}"


@given(st.floats(min_value=-720.0, max_value=720.0, allow_nan=False))
def test_every_azimuth_round_trips_through_the_point_list(azimuth_deg: float) -> None:
    text = _point_row(azimuth_deg)["azimuth"]
    deg, rest = text.split("°")
    minutes, seconds = rest.rstrip('"').split("'")
    assert 0 <= int(deg) < 360
    assert 0 <= int(minutes) < 60
    assert 0.0 <= float(seconds) < 60.0
    back = parse_azimuth(text)
    # within the 0.05" of the rounding, across north
    diff = (back - azimuth_deg + 180.0) % 360.0 - 180.0
    assert abs(diff) * 3600.0 <= 0.05 + 1e-6
