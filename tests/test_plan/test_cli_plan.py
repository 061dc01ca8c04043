"""mast plan from the command line, on the shipped example drift."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from mast.plan.outputs import PLAN_COLUMNS
from tests._cli import run_mast_text

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "plan"
CONTRACT = (
    "easting,northing,heading_deg,beacons_in_view,owed,fix_rate,"
    "sigma_easting_m,sigma_northing_m,sigma_azimuth_deg"
)


def test_plan_writes_the_four_outputs_and_suggests(tmp_path: Path) -> None:
    out = tmp_path / "plan"
    done = run_mast_text(
        "plan", "--walls", str(EXAMPLE / "drift.csv"), "-b", str(EXAMPLE / "beacons.csv"),
        "--scanner", "lms1xx-0.25", "--out", str(out), "--step", "6", "--across", "2",
        "--scans-per-cell", "1", "--suggest", "2", "--target-sigma", "0.02",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "covered" in done.stdout
    for name in ("plan.csv", "plan.png", "plan.dxf", "summary.json", "proposed_beacons.csv"):
        assert (out / name).is_file(), name
        assert (out / name).stat().st_size > 0, name
    header = (out / "plan.csv").read_text().splitlines()[0]
    assert header.startswith(CONTRACT)
    assert tuple(header.split(",")) == PLAN_COLUMNS
    rows = list(csv.DictReader((out / "plan.csv").open()))
    assert rows
    assert len(rows) % 2 == 0
    assert {r["owed"] for r in rows} <= {"0", "1"}
    assert all(0.0 <= float(r["fix_rate"]) <= 1.0 for r in rows)
    summary = json.loads((out / "summary.json").read_text())
    for key in ("covered_share", "worst_sigma_m", "longest_gap_m"):
        assert key in summary
    assert summary["covered_share"] > summary["before"]["covered_share"]
    assert summary["proposed_beacons"]
    assert summary["wrong_fixes"] == 0
    # the proposal is a survey: mast plan and mast locate take it
    again = run_mast_text(
        "plan", "--walls", str(EXAMPLE / "drift.dxf"), "-b", str(out / "proposed_beacons.csv"),
        "--scanner", "lms1xx-0.25", "--out", str(tmp_path / "again"), "--step", "6",
        "--scans-per-cell", "1", "--target-sigma", "0.02", "--crs", "EPSG:32735",
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    redone = json.loads((tmp_path / "again" / "summary.json").read_text())
    assert "crs" not in summary
    assert redone["crs"]["epsg"] == 32735
    assert redone["covered_share"] == pytest.approx(summary["covered_share"], abs=0.1)

    import ezdxf

    doc = ezdxf.readfile(out / "plan.dxf")
    layers = {e.dxf.layer for e in doc.modelspace()}
    assert {"MAST_WALLS", "MAST_BEACONS", "MAST_PROPOSED", "MAST_CENTRELINE"} <= layers
    assert any(name.startswith("MAST_NO_FIX") for name in layers)
    assert any(name.startswith("MAST_SIGMA_") for name in layers)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--fov", "270"], "--resolution"),
        (["--scanner", "nope"], "unknown scanner"),
        (["--scanner", "lms1xx-0.5", "--step", "0"], "--step"),
        (["--scanner", "lms1xx-0.5", "--min-fix-rate", "2"], "--min-fix-rate"),
    ],
)
def test_plan_bad_options_are_one_line_errors(tmp_path: Path, args: list[str], words: str) -> None:
    done = run_mast_text(
        "plan", "--walls", str(EXAMPLE / "drift.csv"), "-b", str(EXAMPLE / "beacons.csv"),
        "--out", str(tmp_path / "o"), *args,
    )  # fmt: skip
    assert done.returncode == 2
    assert words in done.stderr
    assert "Traceback" not in done.stderr


def test_plan_bad_drift_names_file_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "drift.csv"
    bad.write_text("wall,vertex,easting,northing\nw,1,0,0\nw,2,oops,0\n")
    done = run_mast_text(
        "plan", "--walls", str(bad), "-b", str(EXAMPLE / "beacons.csv"),
        "--scanner", "lms1xx-0.5", "--out", str(tmp_path / "o"),
    )  # fmt: skip
    assert done.returncode == 2
    assert f"{bad}, line 3" in done.stderr
    assert done.stderr.count("\n") == 1
