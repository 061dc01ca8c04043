import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mast import __version__
from mast.program import app
from tests._cli import run_mast_text

runner = CliRunner()


_mast = run_mast_text


def test_version_and_help() -> None:
    r = runner.invoke(app, ["--version"])
    assert r.exit_code == 0
    assert r.output.strip() == f"mast {__version__}"
    r = runner.invoke(app, ["--help"])
    assert r.exit_code == 0
    assert "simulate" in r.output
    assert "demo" in r.output


def test_simulate_writes_survey_scans_and_truth(tmp_path: Path) -> None:
    r = runner.invoke(
        app, ["simulate", "--scenario", "random", "--seed", "3", "--out", str(tmp_path)]
    )
    assert r.exit_code == 0, r.output
    folders = sorted(p for p in tmp_path.iterdir() if p.is_dir())
    assert len(folders) == 4
    for f in folders:
        assert (f / "beacons.csv").is_file()
        assert (f / "truth.csv").is_file()
        assert len(list(f.glob("scan_*.csv"))) == 5
    assert (tmp_path / "scenario.json").is_file()


def test_simulate_bag(tmp_path: Path) -> None:
    r = runner.invoke(app, ["simulate", "--scan-format", "bag", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "paper-parallel" / "scans.bag").is_file()


def test_demo_prints_the_table2_comparison() -> None:
    r = runner.invoke(app, ["demo"])
    assert r.exit_code == 0, r.output
    assert "noise-free, as in the paper" in r.output
    assert "12 mm range noise" in r.output
    for pos in ("P1", "P2", "P3", "P4", "P5", "P6", "P7"):
        assert pos in r.output
    assert "3D: one simulated VLP-16 frame" in r.output  # tests/test_cli/test_demo3d.py


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["simulate", "--scenario", "mars", "--out", "{tmp}"],
            "mast: error: unknown scenario 'mars'; known: paper, random, drive",
        ),
    ],
)
def test_errors_are_one_line_with_status_2(tmp_path: Path, args: list[str], message: str) -> None:
    r = _mast(*[a.format(tmp=tmp_path) for a in args])
    assert r.returncode == 2
    assert r.stderr.strip() == message
    assert "Traceback" not in r.stderr


def test_usage_error_is_status_2() -> None:
    r = _mast("simulate")
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "--out" in r.stderr


@pytest.fixture(scope="module")
def paper_files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from mast.sim import paper_scene, write_scenario

    out = tmp_path_factory.mktemp("paper")
    write_scenario([paper_scene("parallel")], out, fmt="csv")
    write_scenario([paper_scene("divergent")], out / "bag", fmt="bag")
    return out


def test_locate_text_report(paper_files: Path) -> None:
    folder = paper_files / "paper-parallel"
    r = runner.invoke(
        app, ["locate", str(folder / "scan_001.csv"), "--beacons", str(folder / "beacons.csv")]
    )
    assert r.exit_code == 0, r.output
    assert "Easting" in r.output
    assert "11.0000 m" in r.output
    assert "Azimuth" in r.output
    assert "0°00'00.0\"" in r.output
    assert "Table 1 option" in r.output


def test_locate_json_contract(paper_files: Path) -> None:
    import json

    folder = paper_files / "paper-parallel"
    r = runner.invoke(
        app,
        [
            "locate",
            str(folder / "scan_002.csv"),
            "-b",
            str(folder / "beacons.csv"),
            "--format",
            "json",
            "--range-sigma",
            "0.005",
        ],
    )
    assert r.exit_code == 0, r.output
    rec = json.loads(r.output)
    assert rec["status"] == "fix"
    assert rec["easting"] == pytest.approx(15.0, abs=1e-6)
    assert rec["northing"] == pytest.approx(7.0, abs=1e-6)
    assert rec["beacons"] == ["B1", "B2"]
    assert rec["sigma_easting_m"] > 0


def test_locate_bag_gives_json_lines(paper_files: Path) -> None:
    import json

    folder = paper_files / "bag" / "paper-divergent"
    r = runner.invoke(
        app,
        [
            "locate",
            str(folder / "scans.bag"),
            "-b",
            str(folder / "beacons.csv"),
            "--format",
            "json",
        ],
    )
    assert r.exit_code == 0, r.output
    recs = [json.loads(line) for line in r.output.splitlines()]
    assert len(recs) == 6
    assert [x["scan"] for x in recs] == list(range(6))
    assert all(x["status"] == "fix" for x in recs)


def test_locate_no_fix_is_status_3(paper_files: Path, tmp_path: Path) -> None:
    folder = paper_files / "paper-parallel"
    one = tmp_path / "one.csv"
    lines = (folder / "beacons.csv").read_text().splitlines()
    one.write_text("\n".join([lines[0]] + [x for x in lines[1:] if x.startswith("B1,")]) + "\n")
    r = _mast("locate", str(folder / "scan_001.csv"), "--beacons", str(one), "--format", "json")
    assert r.returncode == 3
    assert '"reason": "one_beacon"' in r.stdout
    assert "Traceback" not in r.stderr


def test_locate_bad_input_is_status_2(paper_files: Path, tmp_path: Path) -> None:
    folder = paper_files / "paper-parallel"
    bad = tmp_path / "bad.csv"
    bad.write_text("beacon,edge,easting,northing\nB1,1,0,0\n")
    r = _mast("locate", str(folder / "scan_001.csv"), "--beacons", str(bad))
    assert r.returncode == 2
    assert r.stderr.strip().startswith("mast: error: ")
    assert "bad.csv, line 2: beacon 'B1' has 1 edge(s)" in r.stderr
    r = _mast("locate", str(tmp_path / "none.csv"), "--beacons", str(folder / "beacons.csv"))
    assert r.returncode == 2
    assert "not" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = _mast(
        "locate",
        str(folder / "scan_001.csv"),
        "--beacons",
        str(folder / "beacons.csv"),
        "--range-sigma",
        "-1",
    )
    assert r.returncode == 2
    assert "--range-sigma must be a positive number of metres (10 mm is 0.01), got -1" in r.stderr
    for option, value, said in (
        ("--range-sigma", "0", "--range-sigma must be a positive number"),
        ("--angle-sigma-deg", "nan", "--angle-sigma-deg must be a non-negative number of degrees"),
        ("--survey-sigma", "-0.003", "--survey-sigma must be a non-negative number of metres"),
    ):
        r = _mast("locate", str(folder / "scan_001.csv"), "-b", str(folder / "beacons.csv"),
                  option, value)  # fmt: skip
        assert r.returncode == 2
        assert said in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1


def test_locate_plot_writes_a_png(paper_files: Path, tmp_path: Path) -> None:
    folder = paper_files / "paper-parallel"
    png = tmp_path / "fig.png"
    r = runner.invoke(
        app,
        [
            "locate",
            str(folder / "scan_000.csv"),
            "-b",
            str(folder / "beacons.csv"),
            "--plot",
            str(png),
        ],
    )
    assert r.exit_code == 0, r.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_scanners_lists_models() -> None:
    r = runner.invoke(app, ["scanners"])
    assert r.exit_code == 0
    assert "lms1xx-0.5" in r.output


def test_bench_accuracy_small_run_writes_csv(tmp_path: Path) -> None:
    import csv

    r = runner.invoke(
        app, ["bench", "accuracy", "--poses", "2", "--draws", "3", "--out", str(tmp_path)]
    )
    assert r.exit_code == 0, r.output
    assert "RMS/CRB" in r.output
    with (tmp_path / "accuracy_summary.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [x["config"] for x in rows] == [
        "270deg-0.5deg-12mm",
        "270deg-0.25deg-12mm",
        "190deg-0.1667deg-8mm",
        "360deg-0.2deg-20mm",
    ]
    for x in rows:
        assert 0.0 <= float(x["fix_rate"]) <= 1.0
        assert int(x["draws"]) == 6
        assert x["wrong"] == "0"
    assert "WRONG 0" in r.output


def test_reproduce_paper_writes_report_and_figures(tmp_path: Path) -> None:
    r = runner.invoke(app, ["reproduce", "paper", "--out", str(tmp_path), "--draws", "1"])
    assert r.exit_code == 0, r.output
    report = (tmp_path / "report.md").read_text()
    assert "ours beside the paper's" in report
    assert "conclusions, checked" in report
    for png in ("figure3_P1.png", "figure3_P4.png", "errors_by_position.png", "errors_by_size.png"):
        assert (tmp_path / png).read_bytes()[:4] == b"\x89PNG"


def test_locate_near_option_errors(paper_files: Path) -> None:
    folder = paper_files / "paper-parallel"
    args = ["locate", str(folder / "scan_001.csv"), "--beacons", str(folder / "beacons.csv")]
    r = runner.invoke(app, [*args, "--near", "11,7,0", "--radius", "2"])
    assert r.exit_code == 0, r.output
    r = _mast(*args, "--near", "11;7")
    assert r.returncode == 2
    assert "--near '11;7': expected E,N or E,N,AZ" in r.stderr
    r = _mast(*args, "--near", "500,500")
    assert r.returncode == 3


def _rewritten_scan(paper_files: Path, tmp_path: Path, angle: float, rng: float) -> Path:
    """The paper's first scan with its angles and ranges multiplied (a unit mistake)."""
    from mast.io import read_scan_csv

    scan = read_scan_csv(paper_files / "paper-parallel" / "scan_001.csv")
    out = tmp_path / "scan.csv"
    lines = ["angle_rad,range_m"]
    lines += [
        f"{float(a * angle)!r},{float(r * rng)!r}" if np.isfinite(r) else f"{float(a * angle)!r},"
        for a, r in zip(scan.angles_rad, scan.ranges_m, strict=True)
    ]
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.parametrize(
    ("angle", "rng", "hint"),
    [
        (180 / np.pi, 1.0, "more than a full turn: they look like degrees"),
        (1.0, 1000.0, "the ranges look like millimetres"),
    ],
)
def test_unit_mistakes_in_a_scan_are_bad_input_with_a_hint(
    paper_files: Path, tmp_path: Path, angle: float, rng: float, hint: str
) -> None:
    scan = _rewritten_scan(paper_files, tmp_path, angle, rng)
    beacons = paper_files / "paper-parallel" / "beacons.csv"
    r = _mast("locate", str(scan), "--beacons", str(beacons))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert str(scan) in r.stderr
    assert hint in r.stderr


@pytest.mark.parametrize(
    ("option", "value", "unit"),
    [
        ("--range-sigma", "10", "it is in metres (10 mm is 0.01)"),
        ("--survey-sigma", "3", "it is in metres (3 mm is 0.003)"),
        ("--angle-sigma-deg", "5", "it is in degrees"),
    ],
)
def test_a_sigma_no_scanner_has_warns_with_its_unit(
    paper_files: Path, option: str, value: str, unit: str
) -> None:
    folder = paper_files / "paper-parallel"
    r = _mast(
        "locate",
        str(folder / "scan_001.csv"),
        "--beacons",
        str(folder / "beacons.csv"),
        option,
        value,
    )
    assert "Traceback" not in r.stderr
    warning = [line for line in r.stderr.splitlines() if "warning" in line]
    assert len(warning) == 1
    assert option in warning[0]
    assert unit in warning[0]


def test_the_command_starts_without_the_heavy_libraries() -> None:
    # `mast --help` must start fast: matplotlib, scipy, GTSAM and the pipeline are
    # imported inside the commands that need them.
    code = (
        "import sys, mast.program; "
        "print(sorted(m for m in ('matplotlib', 'scipy', 'gtsam', 'mast.pipeline.locator', "
        "'dask', 'laspy', 'ezdxf', 'rosbags', 'rich') if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert done.stdout.strip() == "[]"


def test_bench_field_small_run_writes_csv(tmp_path: Path) -> None:
    import csv

    r = runner.invoke(
        app, ["bench", "field", "--scenes", "2", "--poses", "2", "--out", str(tmp_path)]
    )
    assert r.exit_code == 0, r.output
    assert "RMS/CRB" in r.output
    assert "95 % coverage" in r.output
    assert "with a good prior" in r.output
    for family in ("noisy", "hostile"):
        with (tmp_path / f"field_{family}.csv").open() as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == 4
        assert {x["status"] for x in rows} <= {"fix", "no_fix"}
        assert all(x["wrong"] == "0" for x in rows)
        # Only the owed scans are located again with a prior.
        assert all((x["prior_status"] != "") == (x["owed"] == "1") for x in rows)


def test_track_and_locate_read_a_folder_of_scan_csvs(tmp_path: Path) -> None:
    # The same scan readers for every command: a folder of scan CSVs is a run to
    # `mast track` as it is to `mast live` and `mast emulate`.
    import shutil
    from importlib.resources import as_file, files

    run = tmp_path / "run"
    run.mkdir()
    example = files("mast").joinpath("data/example")
    with as_file(example.joinpath("scan.csv")) as scan:
        for k in range(3):
            shutil.copy(scan, run / f"scan_{k:03d}.csv")
    with as_file(example.joinpath("beacons.csv")) as beacons:
        shutil.copy(beacons, tmp_path / "beacons.csv")
    r = runner.invoke(
        app, ["track", str(run), "-b", str(tmp_path / "beacons.csv"), "--out", str(tmp_path / "o")]
    )
    assert r.exit_code == 0, r.output
    assert "3 scans, 3 fixed" in r.output
    rows = (tmp_path / "o" / "trajectory.csv").read_text().splitlines()
    assert len(rows) == 4
    r = runner.invoke(
        app, ["locate", str(run), "-b", str(tmp_path / "beacons.csv"), "--format", "json"]
    )
    assert r.exit_code == 0, r.output
    assert len(r.stdout.splitlines()) == 3
