"""Settings files: read onto the configuration dataclasses, written back to the same
floats, and every mistake one line naming the file, the line and the key."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import pytest

from mast.core.pose import Pose2D
from mast.errors import InputError
from mast.io.settings import fingerprint, from_table, read_settings, settings_text
from mast.pipeline.locator import LocatorConfig, SequenceConfig
from mast.pipeline.tracking import Prior
from mast.runs.track import TrackConfig


def _read(tmp_path: Path, text: str, cls: type = LocatorConfig, where: str = "locator") -> object:
    path = tmp_path / "s.toml"
    path.write_text(text, encoding="utf-8")
    data, raw = read_settings(path)
    return from_table(cls, data.get(where, {}), path=path, text=raw, where=where)


@pytest.mark.parametrize(
    ("name", "obj"),
    [
        ("locator", LocatorConfig()),
        ("sequence", SequenceConfig()),
        ("track", TrackConfig()),
        ("locator", LocatorConfig(range_sigma_m=0.0123, ambiguity_log_ratio=math.log(7.0))),
    ],
)
def test_written_settings_read_back_to_the_same_floats(
    name: str, obj: object, tmp_path: Path
) -> None:
    text = settings_text({name: obj})
    back = _read(tmp_path, text, type(obj), name)
    assert settings_text({name: back}) == text
    assert fingerprint(settings_text({name: back})) == fingerprint(text)


def test_a_table_left_out_keeps_the_defaults_and_a_key_given_changes_only_itself(
    tmp_path: Path,
) -> None:
    cfg = _read(
        tmp_path, "[locator]\nrange_sigma_m = 0.015\n[locator.verification]\ngate_sigmas = 3\n"
    )
    assert isinstance(cfg, LocatorConfig)
    assert cfg.range_sigma_m == 0.015
    assert cfg.verification.gate_sigmas == 3.0
    assert isinstance(cfg.verification.gate_sigmas, float)
    expected = replace(
        LocatorConfig(range_sigma_m=0.015),
        verification=replace(LocatorConfig().verification, gate_sigmas=3.0),
    )
    assert settings_text({"locator": cfg}) == settings_text({"locator": expected})


def test_a_prior_is_an_input_not_a_setting(tmp_path: Path) -> None:
    with_prior = LocatorConfig(prior=Prior(Pose2D(1.0, 2.0, 0.3), 0.5, 0.1))
    assert "prior" not in settings_text({"locator": with_prior}).replace("prior_margin", "")
    with pytest.raises(InputError, match=r"s\.toml, line 2: \[locator\] has no setting 'prior'"):
        _read(tmp_path, "[locator]\nprior = 1.0\n")


#: A mistake, and what the error says after "<file>, ".
MISTAKES = [
    ("[locator]\nrange_sigma_m = 0.01\ngate_sigma = 3\n", "line 3: [locator] has no setting 'gate"),
    ("[locator]\nrange_sigma_m = 'ten'\n", "line 2: [locator] range_sigma_m must be a number"),
    ("[locator]\nmin_beacons = 2.5\n", "line 2: [locator] min_beacons must be a whole number"),
    ("[locator]\nmin_beacons = true\n", "line 2: [locator] min_beacons must be a whole number"),
    ("[locator]\nmin_beacons = -2\n", "line 2: [locator] min_beacons must be a whole number, 0 or"),
    ("[locator]\nsurvey_sigma_m = -0.003\n", "line 2: [locator] survey_sigma_m must be a number"),
    ("[locator.verification]\ngate_sigmas = nan\n", "line 2: [locator.verification] gate_sigmas"),
    ("[locator.verification]\nplaced_support = 1\n", "line 2: [locator.verification] placed"),
    ("[locator.verification]\ncoarse_gates_m = 0.5\n", "line 2: [locator.verification] coarse"),
    ("[locator]\nverification = 3\n", "line 2: [locator] verification must be a table"),
    ("[locator]\nrange_sigma_m = \n", "line 2: not a TOML settings file"),
    ("[locator.tracking]\nstep_m = 0.033\n", "line 2: [locator.tracking] step_m (0.033) must be"),
]  # fmt: skip


@pytest.mark.parametrize(("text", "message"), MISTAKES)
def test_every_mistake_names_the_file_the_line_and_the_key(
    text: str, message: str, tmp_path: Path
) -> None:
    with pytest.raises(InputError, match=re.escape("s.toml, " + message)):
        _read(tmp_path, text)


def test_a_binary_or_huge_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_bytes(b"[locator]\n\xff\xfe\n")
    with pytest.raises(InputError, match="line 2: not UTF-8"):
        read_settings(path)
    path.write_bytes(b"# " + b"x" * (2 * 1024 * 1024) + b"\n")
    with pytest.raises(InputError, match="MAX_METADATA_BYTES"):
        read_settings(path)
