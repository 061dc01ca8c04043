"""The command line's surface, through the ``mast`` process: one meaning per option name
(the old names kept a release, hidden, with a warning), angles in degrees, an example in
every command's help, progress only on a terminal, the scanner models."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer.main
from typer.testing import CliRunner

from mast.io.scans import scan_count
from mast.program import app
from tests._cli import run_mast_text

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "examples"
SCAN = str(EXAMPLES / "scan.csv")
SURVEY = str(EXAMPLES / "beacons.csv")
WALLS = str(EXAMPLES / "plan" / "drift.csv")
PLAN_SURVEY = str(EXAMPLES / "plan" / "beacons.csv")

runner = CliRunner()


def _commands() -> Iterator[list[str]]:
    """Every command's words (``locate``, ``bench accuracy`` ...), walked from the app."""

    def walk(command: object, path: list[str]) -> Iterator[list[str]]:
        subs = getattr(command, "commands", None)
        if subs:
            for name, sub in sorted(subs.items()):
                yield from walk(sub, [*path, name])
        else:
            yield path

    yield from walk(typer.main.get_command(app), [])


COMMANDS = list(_commands())


def test_the_walk_finds_every_command() -> None:
    names = {" ".join(c) for c in COMMANDS}
    assert {"locate", "track", "scanners", "bench accuracy", "reproduce paper"} <= names
    assert len(names) >= 25


@pytest.mark.parametrize("words", COMMANDS, ids=" ".join)
def test_every_command_help_has_an_example(words: list[str]) -> None:
    r = runner.invoke(app, [*words, "--help"])
    assert r.exit_code == 0, r.output
    assert "Example: mast " in r.output


def _warnings(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("mast: warning:")]


def _shows(option: str, help_text: str) -> bool:
    """Whether ``help_text`` lists ``option`` itself (not a longer name it begins)."""
    return re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", help_text) is not None


@pytest.mark.parametrize(
    ("command", "old"),
    [
        (["plan"], ["--drift", "--check", "--angle-sigma"]),
        (["simulate"], ["--format", "--noise", "--no-noise"]),
        (["locate"], ["--angle-sigma"]),
        (["track"], ["--angle-sigma"]),
        (["live"], ["--angle-sigma"]),
        (["bench", "robustness"], ["--hard", "--drift"]),
        (["bench", "survey"], ["--beacons"]),
        (["bench", "speed"], ["--beacons"]),
        (["bench", "clutter"], ["--beacons"]),
        (["bench", "reallog"], ["--beacons"]),
    ],
)
def test_help_hides_the_old_names(command: list[str], old: list[str]) -> None:
    r = runner.invoke(app, [*command, "--help"], terminal_width=200)
    assert r.exit_code == 0
    for name in old:
        assert not _shows(name, r.output), name


def test_plan_walls_and_dry_run_and_their_old_names(tmp_path: Path) -> None:
    new = run_mast_text("plan", "--walls", WALLS, "-b", PLAN_SURVEY, "--out", str(tmp_path / "p"),
                        "--scanner", "lms1xx-0.5", "--dry-run")  # fmt: skip
    assert new.returncode == 0, new.stderr
    assert "5 beacons" in new.stdout
    assert new.stderr == ""
    old = run_mast_text("plan", "--drift", WALLS, "-b", PLAN_SURVEY, "--out", str(tmp_path / "p"),
                        "--scanner", "lms1xx-0.5", "--check")  # fmt: skip
    assert old.returncode == 0, old.stderr
    assert old.stdout == new.stdout
    assert _warnings(old.stderr) == [
        "mast: warning: --drift is now --walls here; the old name goes in the next release",
        "mast: warning: --check is now --dry-run here; the old name goes in the next release",
    ]
    assert not (tmp_path / "p").exists()
    both = run_mast_text("plan", "--walls", WALLS, "--drift", WALLS, "-b", PLAN_SURVEY,
                         "--out", str(tmp_path / "p"), "--dry-run")  # fmt: skip
    assert both.returncode == 2
    assert both.stderr.strip().splitlines() == [
        "mast: error: --drift is the old name of --walls here: give --walls only"
    ]
    none = run_mast_text("plan", "-b", PLAN_SURVEY, "--out", str(tmp_path / "p"), "--dry-run")
    assert none.returncode == 2
    assert "--walls" in none.stderr
    assert len(none.stderr.strip().splitlines()) == 1


def test_simulate_scan_format_and_noisy_and_their_old_names(tmp_path: Path) -> None:
    new = run_mast_text("simulate", "--scan-format", "bag", "--noisy", "--out", str(tmp_path / "a"))
    assert new.returncode == 0, new.stderr
    assert new.stderr == ""
    assert (tmp_path / "a" / "paper-parallel" / "scans.bag").is_file()
    old = run_mast_text("simulate", "--format", "bag", "--noise", "--out", str(tmp_path / "b"))
    assert old.returncode == 0, old.stderr
    assert (tmp_path / "b" / "paper-parallel" / "scans.bag").read_bytes() == (
        tmp_path / "a" / "paper-parallel" / "scans.bag"
    ).read_bytes()
    assert _warnings(old.stderr) == [
        "mast: warning: --format is now --scan-format here; the old name goes in the next release",
        "mast: warning: --noise/--no-noise is now --noisy/--noise-free here; the old name goes "
        "in the next release",
    ]
    both = run_mast_text("simulate", "--scan-format", "mcap", "--format", "bag", "--out",
                         str(tmp_path / "c"))  # fmt: skip
    assert both.returncode == 2
    assert "--format is the old name of --scan-format" in both.stderr
    assert not (tmp_path / "c").exists()


def test_a_bench_count_keeps_its_old_name_for_a_release() -> None:
    new = run_mast_text("bench", "survey", "--beacon-count", "30")
    assert new.returncode == 0, new.stderr
    assert _warnings(new.stderr) == []
    old = run_mast_text("bench", "survey", "--beacons", "30")
    assert old.returncode == 0, old.stderr
    assert _warnings(old.stderr) == [
        "mast: warning: --beacons is now --beacon-count here; the old name goes in the next release"
    ]


def _json_angle_sigma(stdout: str) -> float:
    import json

    return float(json.loads(stdout.splitlines()[0])["angle_sigma_rad"])


def test_the_angle_sigma_is_in_degrees_and_the_radians_name_is_kept_a_release() -> None:
    base = ("locate", SCAN, "-b", SURVEY, "--range-sigma", "0.012", "--format", "json")
    new = run_mast_text(*base, "--angle-sigma-deg", "0.01")
    assert new.returncode == 0, new.stderr
    assert _warnings(new.stderr) == []
    assert _json_angle_sigma(new.stdout) == pytest.approx(0.01 * 3.141592653589793 / 180)
    old = run_mast_text(*base, "--angle-sigma", "0.0001745329")
    assert old.returncode == 0, old.stderr
    assert _json_angle_sigma(old.stdout) == pytest.approx(0.0001745329)
    assert _warnings(old.stderr) == [
        "mast: warning: --angle-sigma (radians) is now --angle-sigma-deg (degrees): "
        "--angle-sigma 0.000174533 is --angle-sigma-deg 0.01; the old name goes in the next "
        "release"
    ]
    both = run_mast_text(*base, "--angle-sigma-deg", "0.01", "--angle-sigma", "0.0002")
    assert both.returncode == 2
    assert both.stderr.strip().splitlines() == [
        "mast: error: --angle-sigma is the old name of --angle-sigma-deg (in radians): give "
        "--angle-sigma-deg only"
    ]


@pytest.mark.parametrize("words", COMMANDS, ids=" ".join)
def test_every_angle_option_says_degrees(words: list[str]) -> None:
    command = typer.main.get_command(app)
    for w in words:
        command = command.commands[w]  # type: ignore[attr-defined]
    for param in command.params:
        opts = " ".join(getattr(param, "opts", []))
        if getattr(param, "hidden", False) or not re.search(r"angle|azimuth|fov|resolution", opts):
            continue
        assert "degree" in (getattr(param, "help", "") or ""), opts


def test_track_takes_a_folder_of_scan_csvs(tmp_path: Path) -> None:
    r = run_mast_text("track", str(EXAMPLES / "scans"), "-b", SURVEY, "--scanner", "lms1xx-0.25",
                      "--out", str(tmp_path / "run"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "8 scans, 8 fixed, 8 placed" in r.stdout
    rows = (tmp_path / "run" / "trajectory.csv").read_text().splitlines()
    assert len(rows) == 9


def test_no_progress_goes_into_a_pipe(tmp_path: Path) -> None:
    # The tests' stderr is a pipe, as a log file or a vehicle's journal is: a run, a bag
    # located and a folder of scans print their summary and nothing of a progress bar.
    for args in (
        ("track", str(EXAMPLES / "run.bag"), "-b", SURVEY, "--out", str(tmp_path / "t")),
        ("locate", str(EXAMPLES / "run.bag"), "-b", SURVEY, "--format", "json"),
        ("locate", str(EXAMPLES / "scans"), "-b", SURVEY, "--format", "json"),
    ):
        r = run_mast_text(*args, "--scanner", "lms1xx-0.25")
        assert r.returncode == 0, r.stderr
        assert r.stderr == "", args
        assert "\r" not in r.stdout
        assert "\x1b" not in r.stdout


def test_a_progress_total_comes_from_the_bag_index_and_the_folder() -> None:
    assert scan_count(EXAMPLES / "run.bag") == 80
    assert scan_count(EXAMPLES / "log.bag") == 24
    assert scan_count(EXAMPLES / "scans") == 8
    assert scan_count(EXAMPLES / "scan.csv") == 1


def test_the_progress_bar_gets_the_total_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    import io
    import sys

    from mast.cli.options import run_progress, work_progress

    with work_progress("x") as bar:
        assert bar is None  # the tests' stderr is no terminal

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    screen = Tty()
    monkeypatch.setattr(sys, "stderr", screen)
    with run_progress("tracking run.bag") as update:
        assert update is not None
        for k in range(1, 41):
            update(k, k // 2, 80)
    shown = screen.getvalue()
    assert "40/80" in shown or "80" in shown


def test_the_scanner_models_name_their_live_protocol() -> None:
    r = run_mast_text("scanners")
    assert r.returncode == 0
    lines = {line.split()[0]: line for line in r.stdout.splitlines()}
    for name in ("tim551", "tim561", "tim571", "tim781"):
        assert "270°" in lines[name]
        assert "σ 20 mm" in lines[name]
        assert lines[name].endswith("live sick://")
    for name, reach in (("ust-10lx", "0.06–10 m"), ("ust-20lx", "0.06–20 m")):
        assert "270° at 0.25°" in lines[name]
        assert reach in lines[name]
        assert lines[name].endswith("live hokuyo://")
    assert lines["lms1xx-0.25"].endswith("live sick://")
    assert lines["lms2xx-0.1667"].endswith("live -")


def test_locate_takes_a_tim571() -> None:
    r = run_mast_text("locate", SCAN, "-b", SURVEY, "--scanner", "tim571")
    assert r.returncode == 0, r.stderr
    assert "Range σ       20.0 mm (from tim571)" in r.stdout
    assert "Result        FIX" in r.stdout
