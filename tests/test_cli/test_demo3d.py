"""`mast demo`'s 3D part: one simulated VLP-16 frame fixed in six degrees of freedom and
printed beside its truth, each error within a few of the fix's own sigmas."""

from __future__ import annotations

import re

from mast.cli.demo import run_demo_3d

ROWS = ("Easting m", "Northing m", "Elevation m", "Roll °", "Pitch °", "Azimuth °")


def test_the_demo_fixes_a_simulated_3d_frame_and_shows_it_beside_the_truth() -> None:
    lines: list[str] = []
    assert run_demo_3d(lines.append)
    text = "\n".join(lines)
    assert "3D: one simulated VLP-16 frame" in text
    assert "located in" in text
    for heading in ("Truth", "MAST", "σ", "Error/σ"):
        assert heading in text
    for name in ROWS:
        (row,) = [line for line in text.splitlines() if name in line]
        cells = [c.strip() for c in row.strip("│|").split("│")]
        truth, got, sigma, error, ratio = cells[1:6]
        assert sigma.startswith("±"), row  # the elevation is bracketed: not unobserved
        # the error shown is MAST's less the truth (to the last digit shown; the
        # azimuth's wraps at 360°)
        last = 10.0 ** -len(error.split(".")[1])
        if name != "Azimuth °":
            assert abs(float(got) - float(truth) - float(error)) <= 2 * last, row
        assert abs(float(ratio)) < 5, row
    assert re.search(r"on beacons B\d, B\d", text)
