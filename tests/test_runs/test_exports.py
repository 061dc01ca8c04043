"""mast track and mast locate with --crs (issue 35), through the ``mast`` process: the CRS in
the map, the records and the report; the GeoJSON and the point list of the fixes."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import jsonschema
import laspy
import pytest
from pyproj import CRS

from mast.sim import drive_scene, write_scenario
from tests._cli import run_mast_text
from tests.test_io.test_crs import check_geojson

SCHEMA = Path(__file__).resolve().parents[2] / "docs" / "fix.schema.json"
UTM_35S = "EPSG:32735"
LOCAL = "local:Mine Grid A"


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 60-scan drive past beacons, as a ROS 1 bag."""
    out = tmp_path_factory.mktemp("drive")
    (w,) = write_scenario([drive_scene(1, scans=60)], out, fmt="bag", scenario="drive")
    return w.folder


def _track(drive: Path, out: Path, *args: str) -> Path:
    done = run_mast_text(
        "track", str(drive / "scans.bag"), "-b", str(drive / "beacons.csv"),
        "--out", str(out), "--range-sigma", "0.012", *args,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def utm_run(drive: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _track(drive, tmp_path_factory.mktemp("utm"), "--crs", UTM_35S)


@pytest.fixture(scope="module")
def local_run(drive: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _track(drive, tmp_path_factory.mktemp("local"), "--crs", LOCAL)


def _records(run: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in (run / "fixes.jsonl").read_text().splitlines()]


def test_the_map_carries_the_crs_given(utm_run: Path) -> None:
    header = laspy.read(utm_run / "map.las").header
    assert str(header.version) == "1.4"
    assert header.global_encoding.wkt
    crs = header.parse_crs()
    assert crs is not None
    assert crs.equals(CRS.from_user_input(UTM_35S))


def test_every_record_carries_the_crs_and_validates(utm_run: Path) -> None:
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA.read_text()))
    records = _records(utm_run)
    assert records
    for r in records:
        assert not list(validator.iter_errors(r))
        crs = r["crs"]
        assert isinstance(crs, dict)
        assert crs["epsg"] == 32735
        assert crs["name"] == "WGS 84 / UTM zone 35S"
        assert "wkt" not in crs  # the code names it whole: not 1.5 kB on every record
    report = (utm_run / "report.html").read_text(encoding="utf-8")
    assert "WGS 84 / UTM zone 35S (EPSG:32735)" in report


def test_a_local_grid_stays_an_engineering_crs_with_its_name(local_run: Path) -> None:
    crs = laspy.read(local_run / "map.las").header.parse_crs()
    assert crs is not None
    assert crs.is_engineering
    assert not crs.is_geographic
    assert crs.name == "Mine Grid A"
    (record, *_) = _records(local_run)
    assert isinstance(record["crs"], dict)
    assert CRS.from_wkt(record["crs"]["wkt"]).is_engineering
    assert "epsg" not in record["crs"]
    for name in ("fixes.geojson", "trajectory.geojson"):
        data = check_geojson(local_run / name)
        assert data["crs"]["properties"]["name"] == "Mine Grid A"


def test_the_geojson_and_the_point_list_hold_every_fix(utm_run: Path) -> None:
    fixes = [r for r in _records(utm_run) if r["status"] == "fix"]
    assert fixes
    data = check_geojson(utm_run / "fixes.geojson")
    assert data["crs"]["properties"]["name"] == "urn:ogc:def:crs:EPSG::32735"
    points = data["features"]
    assert len(points) == len(fixes)
    for f, r in zip(points, fixes, strict=True):
        assert f["geometry"]["type"] == "Point"
        position = [r["easting"], r["northing"]]
        assert f["geometry"]["coordinates"] == pytest.approx(position, abs=1e-4)
        assert f["properties"]["scan"] == r["scan"]
        assert f["properties"]["stamp_ns"] == r["stamp_ns"]
        assert f["properties"]["azimuth_dms"] == r["azimuth_dms"]
    with (utm_run / "fixes_points.csv").open(encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [row["name"] for row in rows] == [f["properties"]["name"] for f in points]
    assert [row["azimuth"] for row in rows] == [r["azimuth_dms"] for r in fixes]
    assert all(row["elevation"] == "" for row in rows)
    first = fixes[0]
    assert isinstance(first["sigma_azimuth_deg"], float)
    assert float(rows[0]["sigma_azimuth_arcsec"]) == pytest.approx(
        3600 * first["sigma_azimuth_deg"], abs=0.05
    )
    lines = check_geojson(utm_run / "trajectory.geojson")["features"]
    assert lines
    with (utm_run / "trajectory.csv").open(encoding="utf-8", newline="") as fh:
        placed = list(csv.DictReader(fh))
    assert sum(f["properties"]["scans"] for f in lines) <= len(placed)
    assert all(len(f["geometry"]["coordinates"]) >= 2 for f in lines)


def test_without_crs_nothing_names_one(drive: Path, tmp_path: Path) -> None:
    run = _track(drive, tmp_path / "plain")
    assert laspy.read(run / "map.las").header.parse_crs() is None
    assert all("crs" not in r for r in _records(run))
    assert "crs" not in check_geojson(run / "fixes.geojson")
    assert "Grid CRS" not in (run / "report.html").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("crs", "words"),
    [
        ("EPSG:4326", "geographic (degrees) CRS"),
        ("EPSG:99999", "not a coordinate reference system pyproj knows"),
        ("local:", "a local grid needs a name"),
    ],
)
def test_a_bad_crs_is_a_one_line_error_exit_2_before_any_work(
    drive: Path, tmp_path: Path, crs: str, words: str
) -> None:
    out = tmp_path / "run"
    done = run_mast_text(
        "track", str(drive / "scans.bag"), "-b", str(drive / "beacons.csv"),
        "--out", str(out), "--crs", crs,
    )  # fmt: skip
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("mast: error: --crs")
    assert words in line
    assert "Traceback" not in done.stderr
    assert not out.exists() or not any(out.iterdir())


def test_locate_json_records_and_report_name_the_crs(drive: Path) -> None:
    bag = str(drive / "scans.bag")
    beacons = str(drive / "beacons.csv")
    done = run_mast_text(
        "locate", bag, "-b", beacons, "--format", "json", "--range-sigma", "0.012",
        "--crs", UTM_35S,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA.read_text()))
    records = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(records) == 60
    for r in records:
        assert not list(validator.iter_errors(r))
        assert r["crs"]["epsg"] == 32735
    text = run_mast_text("locate", bag, "-b", beacons, "--range-sigma", "0.012", "--crs", LOCAL)
    assert text.returncode == 0, text.stderr
    assert "Grid CRS      Mine Grid A (local grid)" in text.stdout
    bad = run_mast_text("locate", bag, "-b", beacons, "--crs", "4326")
    assert bad.returncode == 2
    (line,) = bad.stderr.strip().splitlines()
    assert "geographic (degrees)" in line
