"""The published record (docs/fix.schema.json), the signed-off report, output paths
that never end in a traceback, and the command-line conventions (issue 9)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from typer.testing import CliRunner

from mast.core.beacon import Beacon, Survey
from mast.pipeline import LocatorConfig, locate
from mast.program import app
from mast.report.record import fix_record, fix_text
from mast.sim import paper_scene, random_scene, write_scenario
from tests._cli import run_mast

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "docs" / "fix.schema.json"
runner = CliRunner()


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(
        schema, format_checker=jsonschema.Draft202012Validator.FORMAT_CHECKER
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("records")
    write_scenario([paper_scene("parallel", range_sigma_m=0.012, seed=2)], out, fmt="csv")
    write_scenario([paper_scene("divergent")], out / "bag", fmt="bag")
    return out


_mast = run_mast


def _locate_paper(files: Path, scan: str, *options: str) -> Any:
    """``mast locate`` in-process on a scan of the noisy parallel-wall scene."""
    folder = files / "paper-parallel"
    return runner.invoke(
        app, ["locate", str(folder / scan), "-b", str(folder / "beacons.csv"), *options]
    )


def _records(stdout: bytes) -> list[dict[str, Any]]:
    return [json.loads(line) for line in stdout.decode().splitlines() if line.strip()]


def _valid(validator: jsonschema.Draft202012Validator, rec: dict[str, Any]) -> None:
    errors = sorted(validator.iter_errors(rec), key=str)
    assert not errors, [f"{list(e.absolute_path)}: {e.message}" for e in errors]


# --- the published record -------------------------------------------------------------


def test_records_of_csv_scans_stdin_and_no_fix_follow_the_schema(
    files: Path, validator: jsonschema.Draft202012Validator
) -> None:
    folder = files / "paper-parallel"
    beacons = str(folder / "beacons.csv")
    one = folder / "one_beacon.csv"
    one.write_text(
        "\n".join(
            line for line in (folder / "beacons.csv").read_text().splitlines() if "B2" not in line
        )
        + "\n"
    )
    r = _mast(
        "locate",
        str(folder / "scan_001.csv"),
        "-",
        str(folder / "scan_003.csv"),
        "-b",
        beacons,
        "--format",
        "json",
        "--range-sigma",
        "0.012",
        stdin=(folder / "scan_002.csv").read_bytes(),
    )
    assert r.returncode == 0, r.stderr
    recs = _records(r.stdout)
    assert [rec["source"] for rec in recs] == [
        str(folder / "scan_001.csv"),
        "<stdin>",
        str(folder / "scan_003.csv"),
    ]
    for rec in recs:
        _valid(validator, rec)
        assert rec["status"] == "fix"
        assert rec["chi2_test"] in ("pass", "too_small", "too_large")
        assert rec["inputs"]["defaults"] == ["angle_sigma_rad", "survey_sigma_m"]
        assert rec["range_sigma_m"] == 0.012
        assert rec["inputs"]["beams"] >= rec["inputs"]["valid_beams"] > rec["points_used"]
        assert rec["software"].startswith("mast ")
    r = _mast("locate", str(folder / "scan_001.csv"), "-b", str(one), "--format", "json")
    assert r.returncode == 3
    (rec,) = _records(r.stdout)
    _valid(validator, rec)
    assert rec["reason"] == "one_beacon"
    assert rec["easting"] is None
    assert rec["reason_text"]


def test_bag_records_follow_the_schema_with_stamp_topic_and_frame(
    files: Path, validator: jsonschema.Draft202012Validator
) -> None:
    folder = files / "bag" / "paper-divergent"
    r = _mast(
        "locate", str(folder / "scans.bag"), "-b", str(folder / "beacons.csv"), "--format", "json"
    )
    assert r.returncode == 0, r.stderr
    recs = _records(r.stdout)
    assert [rec["scan"] for rec in recs] == list(range(len(recs)))
    stamps = [rec["stamp_ns"] for rec in recs]
    assert stamps == sorted(stamps)
    assert len(set(stamps)) == len(stamps)
    last_fixed = None
    for rec in recs:
        _valid(validator, rec)
        assert rec["topic"] == "/scan"
        assert rec["frame_id"]
        # A run is located in sequence: each record says whether the last fix, if no
        # more than 0.5 s before, was tried as the scan's prior, and whether it failed.
        near = last_fixed is not None and rec["stamp_ns"] - last_fixed <= 500_000_000
        assert rec["tracking"] is near
        assert not rec["track_lost"] or near
        if near and rec["status"] != "fix":
            assert rec["track_lost"]
        if rec["status"] == "fix":
            last_fixed = rec["stamp_ns"]


def test_the_covariance_states_its_order_and_units(files: Path) -> None:
    r = _locate_paper(files, "scan_004.csv", "--format", "json", "--range-sigma", "0.012")
    rec = json.loads(r.output)
    assert rec["covariance_order"] == ["easting_m", "northing_m", "azimuth_rad"]
    cov = np.array(rec["covariance"])
    assert np.allclose(cov, cov.T)
    # The sigmas are printed to 7 decimals of a metre and 8 of a degree: equal to that.
    assert math.isclose(math.sqrt(cov[0, 0]), rec["sigma_easting_m"], abs_tol=5.1e-8)
    assert math.isclose(math.sqrt(cov[1, 1]), rec["sigma_northing_m"], abs_tol=5.1e-8)
    assert math.isclose(
        math.degrees(math.sqrt(cov[2, 2])), rec["sigma_azimuth_deg"], abs_tol=5.1e-9
    )
    schema = json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))
    assert "m²" in schema["properties"]["covariance"]["description"]
    assert "rad²" in schema["properties"]["covariance"]["description"]


def _moved_b1() -> tuple[Any, Survey]:
    scene = random_scene(2, 1, noise=True)
    sim = scene.simulate_all()[1]
    moved = Survey(
        [
            Beacon(b.id, b.edges + (np.array([0.05, 0.0]) if b.id == "B1" else 0.0))
            for b in scene.survey
        ]
    )
    return sim, moved


def test_an_inconsistent_answer_gives_every_beacons_test(
    validator: jsonschema.Draft202012Validator,
) -> None:
    # B1 of three beacons surveyed 5 cm off: the answer shows which beacon disagrees most.
    sim, moved = _moved_b1()
    fix = locate(sim.scan, moved, config=LocatorConfig(range_sigma_m=0.012))
    assert fix.reason == "inconsistent"
    rec = fix_record(fix, scan=sim.scan)
    _valid(validator, rec)
    tests = {b: v["test"] for b, v in rec["residuals"]["per_beacon"].items()}
    assert set(tests) == {"B1", "B2", "B3"}
    worst = max(tests, key=lambda b: tests[b]["statistic"] / tests[b]["critical"])
    assert worst == "B1"
    assert not tests["B1"]["passed"]
    assert "B1 2." in fix.detail  # "B1 2.16" times its critical value, listed first
    text = fix_text(fix, scan=sim.scan)
    assert "Beacon tests" in text
    assert "FAIL: moved or mis-surveyed?" in text


# --- the signed-off report --------------------------------------------------------------


def test_the_text_report_lists_inputs_residuals_and_conventions(files: Path) -> None:
    scan = str(files / "paper-parallel" / "scan_001.csv")
    r = _locate_paper(files, "scan_001.csv", "--range-sigma", "0.012")
    assert r.exit_code == 0, r.output
    out = r.output
    for expected in (
        f"Scan file     {scan}",
        "Survey file",
        "Beams         1081 read,",
        "Range σ       12.0 mm\n",
        "Angle σ       0° (0 rad) (default)",
        "Survey σ      3.0 mm per edge coordinate (default)",
        "clockwise from grid north",
        "chi-square test at 5 %",
        "Residuals (measured minus computed range",
        "against the critical",
        "Beacon tests",
        "mast ",
        " UTC",
    ):
        assert expected in out, expected
    assert "similarity scale" not in out
    assert "ICP" not in out
    rows = [line.split() for line in out.splitlines() if line.startswith("  B1 ")]
    assert {row[1] for row in rows if row[1] != "statistic"} >= {"1", "2", "all"}
    lines = [line for line in out.splitlines() if line.strip()]
    assert len(lines) == len(set(lines)), "a line is repeated"


def test_a_scanner_model_is_named_as_the_source_of_the_precisions(files: Path) -> None:
    r = _locate_paper(files, "scan_001.csv", "--scanner", "lms1xx-0.25")
    assert "Scanner       lms1xx-0.25" in r.output
    assert "(from lms1xx-0.25)" in r.output


# --- output paths: checked first, never a traceback -------------------------------------


@pytest.mark.parametrize(
    ("make_args", "status", "message"),
    [
        (
            lambda d, f: ["locate", f["scan"], "-b", f["beacons"], "--plot", str(d / "x.xyz")],
            2,
            "unknown file type '.xyz'",
        ),
        (
            lambda d, f: ["locate", f["scan"], "-b", f["beacons"], "--plot", str(d)],
            2,
            "not a folder",
        ),
        (
            lambda d, f: ["locate", f["scan"], "-b", f["beacons"], "--plot", f["scan_png"]],
            2,
            "overwrite an input",
        ),
        (lambda d, f: ["simulate", "--out", f["scan"]], 2, "must be a folder"),
        (lambda d, f: ["demo", "--out", f["scan"]], 2, "must be a folder"),
        (lambda d, f: ["bench", "accuracy", "--out", f["scan"]], 2, "must be a folder"),
        (lambda d, f: ["bench", "robustness", "--out", f["scan"]], 2, "must be a folder"),
        (lambda d, f: ["reproduce", "paper", "--out", f["scan"]], 2, "must be a folder"),
        (
            lambda d, f: ["simulate", "--out", str(Path(f["scan"]) / "sub")],
            4,
            "cannot create the folder",
        ),
    ],
)
def test_bad_output_paths_are_one_line_before_any_work(
    tmp_path: Path, files: Path, make_args: Any, status: int, message: str
) -> None:
    folder = files / "paper-parallel"
    png = tmp_path / "scan.png"
    png.write_bytes(b"not really")
    f = {
        "scan": str(folder / "scan_001.csv"),
        "beacons": str(folder / "beacons.csv"),
        "scan_png": str(png),
    }
    if "overwrite" in message:
        f["scan"] = f["scan_png"]  # the plot would land on the scan itself
    r = _mast(*make_args(tmp_path, f))
    err = r.stderr.decode()
    assert r.returncode == status, err
    assert message in err
    assert len(err.strip().splitlines()) == 1
    assert "Traceback" not in err
    assert r.stdout == b""  # nothing was done before the check


def test_a_plot_into_a_missing_folder_creates_it(tmp_path: Path, files: Path) -> None:
    target = tmp_path / "new" / "deeper" / "fix.png"
    r = _locate_paper(files, "scan_001.csv", "--plot", str(target), "--range-sigma", "0.012")
    assert r.exit_code == 0, r.output
    assert target.read_bytes().startswith(b"\x89PNG")


def test_a_full_standard_output_is_exit_4_with_one_line(files: Path) -> None:
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    folder = files / "paper-parallel"
    with open("/dev/full", "wb") as full:
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "mast",
                "locate",
                str(folder / "scan_001.csv"),
                "-b",
                str(folder / "beacons.csv"),
            ],
            stdout=full,
            stderr=subprocess.PIPE,
            timeout=120,
            check=False,
        )
    err = r.stderr.decode()
    assert r.returncode == 4, err
    assert "cannot write" in err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_an_internal_error_is_one_line_with_status_70(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import mast.cli.root as cli

    def broken(**_: object) -> None:
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(cli, "app", broken)
    monkeypatch.delenv("MAST_DEBUG", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        cli.main()
    assert exit_info.value.code == 70
    err = capsys.readouterr().err
    assert err.startswith("mast: internal error: ZeroDivisionError: a bug")
    assert len(err.strip().splitlines()) == 1


# --- command-line conventions -----------------------------------------------------------


def test_short_help_and_defaults_in_help() -> None:
    r = runner.invoke(app, ["-h"])
    assert r.exit_code == 0
    assert "locate" in r.output
    r = runner.invoke(app, ["locate", "-h"], terminal_width=200)
    assert r.exit_code == 0
    text = " ".join(r.output.split())
    assert "[default: 0.01, or the --scanner's]" in text
    assert "[default: 0.003]" in text
    assert "standard input" in text


def test_readme_and_docs_links_resolve_inside_the_repository() -> None:
    import re

    root = SCHEMA_PATH.parents[1]
    pages = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    for page in pages:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target):
                continue  # a web address
            resolved = (page.parent / target).resolve()
            assert resolved.exists(), f"{page.name}: link {target} does not resolve"
            assert root.resolve() in resolved.parents, f"{page.name}: {target} leaves the clone"
    assert "fix.schema.json" in (root / "README.md").read_text(encoding="utf-8")


def test_a_tracked_fix_says_its_first_pose_came_from_the_prior(files: Path) -> None:
    rec = json.loads(
        _locate_paper(files, "scan_001.csv", "--range-sigma", "0.012", "--format", "json").output
    )
    near = f"{rec['easting'] + 0.1},{rec['northing'] - 0.1},{rec['azimuth_deg'] + 1}"
    r = _locate_paper(
        files,
        "scan_001.csv",
        "--range-sigma",
        "0.012",
        "--near",
        near,
        "--radius",
        "0.5",
        "--azimuth-tolerance",
        "5",
    )
    assert r.exit_code == 0, r.output
    assert "First pose from a search of the prior's window (0.5 m around" in r.output
    assert "matched corners" not in r.output
