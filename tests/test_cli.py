import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mast import __version__
from mast.cli import app

runner = CliRunner()


def _mast(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mast", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


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
    r = runner.invoke(app, ["simulate", "--format", "bag", "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "paper-parallel" / "scans.bag").is_file()


def test_demo_runs() -> None:
    r = runner.invoke(app, ["demo"])
    assert r.exit_code == 0, r.output
    assert "paper-parallel" in r.output
    assert "P7@0.25deg" in r.output


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["simulate", "--scenario", "mars", "--out", "{tmp}"],
            "mast: error: unknown scenario 'mars'; known: paper, random",
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
