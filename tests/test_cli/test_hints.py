"""The newcomer's stumbles of issue 35, each run again through the ``mast`` process: it
ends with a one-line hint on standard error and the documented exit status.

The shipped examples are a drive's scans with 12 mm range noise; the default range
sigma is 10 mm.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

from tests._cli import run_mast_text

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "examples"


def _hints(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("mast: hint: ")]


def test_a_range_sigma_below_the_scatter_ends_locate_with_the_sigma_that_fixes() -> None:
    scans = str(EXAMPLES / "scans")
    beacons = str(EXAMPLES / "beacons.csv")
    done = run_mast_text("locate", scans, "-b", beacons, "--format", "json")
    assert done.returncode == 0, done.stderr  # some scans fixed
    (hint,) = _hints(done.stderr)
    m = re.search(r"with --range-sigma (\S+) (all \d+|\d+ of the \d+) fix", hint)
    assert m is not None, hint
    assert "--scanner" in hint
    # the sigma it names, given: no scan refused, no hint
    again = run_mast_text("locate", scans, "-b", beacons, "--format", "json", "--range-sigma", m[1])
    assert again.returncode == 0, again.stderr
    assert _hints(again.stderr) == []
    assert '"reason": "rejected"' not in again.stdout


def test_a_range_sigma_below_the_scatter_ends_track_with_the_hint(tmp_path: Path) -> None:
    done = run_mast_text(
        "track", str(EXAMPLES / "scans"), "-b", str(EXAMPLES / "beacons.csv"),
        "--out", str(tmp_path / "run"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    (hint,) = _hints(done.stderr)
    assert "refused by the global test" in hint
    assert "--range-sigma 0.01" in hint


def test_a_survey_with_easting_and_northing_exchanged_is_named(tmp_path: Path) -> None:
    swapped = tmp_path / "beacons.csv"
    with (EXAMPLES / "beacons.csv").open(newline="") as src, swapped.open("w", newline="") as dst:
        rows = csv.reader(src)
        out = csv.writer(dst)
        out.writerow(next(rows))
        for row in rows:
            row[2], row[3] = row[3], row[2]
            out.writerow(row)
    done = run_mast_text(
        "locate", str(EXAMPLES / "scans"), "-b", str(swapped), "--scanner", "lms1xx-0.25"
    )
    assert done.returncode == 3  # no fix
    (hint,) = _hints(done.stderr)
    assert hint.startswith(
        f"mast: hint: no scan fixed, but with easting and northing exchanged {swapped} fixes"
    )
    assert hint.endswith("are its columns beacon,edge,easting,northing (easting first)?")


def test_a_survey_in_millimetres_is_named(tmp_path: Path) -> None:
    mm = tmp_path / "beacons.csv"
    with (EXAMPLES / "beacons.csv").open(newline="") as src, mm.open("w", newline="") as dst:
        rows = csv.reader(src)
        out = csv.writer(dst)
        out.writerow(next(rows))
        for row in rows:
            out.writerow([*row[:2], *(f"{1000 * float(v):.1f}" for v in row[2:4]), *row[4:]])
    done = run_mast_text("locate", str(EXAMPLES / "scan.csv"), "-b", str(mm))
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"mast: error: {mm}, line ")
    assert "is the survey in millimetres?" in line
