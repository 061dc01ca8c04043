"""One door to every recorded scan: a scan CSV, a folder of them, or a bag."""

from __future__ import annotations

import shutil
from importlib.resources import as_file, files
from pathlib import Path

import numpy as np
import pytest

from mast.errors import InputError
from mast.io import read_scan_csv, write_laserscans
from mast.io.scans import FORMATS, open_scans, scan_format


@pytest.fixture
def example(tmp_path: Path) -> Path:
    with as_file(files("mast").joinpath("data/example/scan.csv")) as path:
        shutil.copy(path, tmp_path / "scan.csv")
    return tmp_path / "scan.csv"


def test_a_csv_is_one_scan_with_the_range_limits_given(example: Path) -> None:
    run = open_scans(example, range_max_m=5.0)
    assert run.format is FORMATS[0]
    assert not run.format.sequence
    assert run.topic is None
    (scan,) = list(run.scans)
    assert scan.range_max_m == 5.0
    expected = read_scan_csv(example, range_max_m=5.0)
    assert np.array_equal(scan.ranges_m, expected.ranges_m, equal_nan=True)
    assert np.array_equal(scan.valid, expected.valid)


def test_a_folder_of_scan_csvs_is_a_run_in_name_order_stamped_at_its_rate(
    example: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "run"
    folder.mkdir()
    for name in ("b.csv", "a.csv", "c.csv"):
        shutil.copy(example, folder / name)
    (folder / "notes.csv").write_text("not,a,scan\n")
    # A header in other case after a blank line, and an upper-case suffix: a scan CSV
    # still, as read_scan_csv reads it.
    text = example.read_text(encoding="utf-8")
    (folder / "d.CSV").write_text("\nAngle_rad,Range_m" + text[len("angle_rad,range_m") :])
    run = open_scans(folder, csv_hz=10.0)
    assert run.format.name == "folder of scan CSVs"
    assert run.format.sequence
    assert [s.stamp_ns for s in run.scans] == [0, 100_000_000, 200_000_000, 300_000_000]


def test_a_bag_is_a_run_with_its_topic(example: Path, tmp_path: Path) -> None:
    scan = read_scan_csv(example)
    bag = tmp_path / "run.bag"
    write_laserscans(bag, [scan, scan], topic="/front/scan")
    run = open_scans(bag, range_min_m=0.5)
    assert run.format.name.startswith("ROS bag")
    assert run.topic == "/front/scan"
    scans = list(run.scans)
    assert len(scans) == 2
    assert all(s.range_min_m == 0.5 for s in scans)


def test_what_no_format_reads_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="run not found"):
        scan_format(tmp_path / "missing", what="run")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match="folder holds no scan CSV"):
        open_scans(empty)
    other = tmp_path / "scan.las"
    other.write_bytes(b"LASF")
    with pytest.raises(InputError, match=str(other)):
        open_scans(other)
