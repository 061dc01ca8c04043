"""``--config``: the settings file every locating command reads, ``mast config`` that
prints one, and the fingerprint every record names its configuration by."""

from __future__ import annotations

import json
import re
from importlib.resources import files
from pathlib import Path

import pytest
from typer.testing import CliRunner

from mast.program import app
from tests._cli import run_mast_text

runner = CliRunner()
EXAMPLE = files("mast").joinpath("data/example")
SCAN, SURVEY = str(EXAMPLE.joinpath("scan.csv")), str(EXAMPLE.joinpath("beacons.csv"))


def _sha(text: str) -> str:
    found = re.search(r"SHA-256 of the settings below: ([0-9a-f]{64})", text)
    assert found, text[:300]
    return found.group(1)


def _locate(*options: str) -> dict[str, object]:
    r = runner.invoke(app, ["locate", SCAN, "-b", SURVEY, "--format", "json", *options])
    assert r.exit_code == 0, r.output
    record: dict[str, object] = json.loads(r.stdout)
    return record


@pytest.mark.parametrize("command", ["locate", "track", "live"])
def test_mast_config_prints_every_setting_and_reads_back_the_same(
    command: str, tmp_path: Path
) -> None:
    r = runner.invoke(app, ["config", "--for", command])
    assert r.exit_code == 0, r.output
    assert "[locator.verification]" in r.stdout
    assert ("[track]" in r.stdout) == (command == "track")
    path = tmp_path / "c.toml"
    path.write_text(r.stdout, encoding="utf-8")
    again = runner.invoke(app, ["config", "--for", command, "--config", str(path)])
    assert again.exit_code == 0, again.output
    assert again.stdout == r.stdout


def test_a_record_names_its_settings_and_the_defaults_file_is_the_defaults(
    tmp_path: Path,
) -> None:
    defaults = runner.invoke(app, ["config", "--for", "locate", "--out", str(tmp_path / "d.toml")])
    assert defaults.exit_code == 0, defaults.output
    text = (tmp_path / "d.toml").read_text(encoding="utf-8")
    plain = _locate()
    inputs = plain["inputs"]
    assert isinstance(inputs, dict)
    assert inputs["config_file"] is None
    assert inputs["config_sha256"] == _sha(text)
    from_file = _locate("--config", str(tmp_path / "d.toml"))
    assert from_file["inputs"]["config_sha256"] == inputs["config_sha256"]  # type: ignore[index]
    for key in ("easting", "northing", "azimuth_deg", "sigma_easting_m"):
        assert from_file[key] == plain[key]


def test_a_file_sets_what_it_names_and_the_options_override_it(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[locator]\nrange_sigma_m = 0.012\n", encoding="utf-8")
    record = _locate("--config", str(path))
    assert record["range_sigma_m"] == 0.012
    assert "range_sigma_m" not in record["inputs"]["defaults"]  # type: ignore[index]
    assert record["inputs"]["config_file"] == str(path)  # type: ignore[index]
    assert _locate("--config", str(path), "--range-sigma", "0.015")["range_sigma_m"] == 0.015
    differs = _locate("--config", str(path))["inputs"]["config_sha256"]  # type: ignore[index]
    assert differs != _locate()["inputs"]["config_sha256"]  # type: ignore[index]


def test_a_mistake_in_the_file_is_one_line_and_bad_input(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[locator]\nrange_sigma_m = 0.012\ngate_sigma = 3\n", encoding="utf-8")
    r = run_mast_text("locate", SCAN, "-b", SURVEY, "--config", str(path))
    assert r.returncode == 2
    assert r.stdout == ""
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith(f"mast: error: {path}, line 3: [locator] has no setting 'gate_sigma'")


@pytest.mark.parametrize("value", ["0", "inf", "-0.01", "nan"])
def test_a_range_sigma_no_scanner_has_is_refused_from_a_file(value: str, tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text(f"[locator]\nrange_sigma_m = {value}\n", encoding="utf-8")
    r = run_mast_text("locate", SCAN, "-b", SURVEY, "--config", str(path))
    assert r.returncode == 2, r.stderr
    assert f"{path}, line 2: [locator] range_sigma_m must be" in r.stderr


@pytest.mark.parametrize("key", ["angle_sigma_rad", "survey_sigma_m"])
def test_an_endless_precision_is_refused_from_a_file_on_its_line(key: str, tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text(f"[locator]\nrange_sigma_m = 0.01\n{key} = inf\n", encoding="utf-8")
    r = run_mast_text("locate", SCAN, "-b", SURVEY, "--config", str(path))
    assert r.returncode == 2, r.stderr
    assert f"{path}, line 3: [locator] {key} must be a non-negative number" in r.stderr


def test_a_refused_track_run_leaves_its_folder_empty(tmp_path: Path) -> None:
    out = tmp_path / "out"
    r = run_mast_text("track", SCAN, "-b", str(tmp_path / "missing.csv"), "--out", str(out))
    assert r.returncode == 2
    assert list(out.iterdir()) == []


def test_a_mistake_in_a_table_the_command_does_not_use_is_still_found(tmp_path: Path) -> None:
    path = tmp_path / "c.toml"
    path.write_text("[locator]\nrange_sigma_m = 0.012\n[track]\nmax_gap = 1\n", encoding="utf-8")
    r = run_mast_text("locate", SCAN, "-b", SURVEY, "--config", str(path))
    assert r.returncode == 2
    assert f"{path}, line 4: [track] has no setting 'max_gap'" in r.stderr
