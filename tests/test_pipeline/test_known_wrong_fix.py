"""A wrong fix found by the live benchmark (issue 15), refused since issue 31.

Scan 16 648 of the 40 Hz benchmark drive (``drive_scene(0, scans=30000, rate_hz=40)``,
0.5°, 12 mm noise), ranges rounded to the millimetre as the Hokuyo protocol sends
them. The truth: the scanner at E 7798.683, N 6452.761, Az 191°27'45", showing two
panels of one beacon (D049). ``locate`` fixed it 523 m away, on D015 and D016, with
1.3 cm sigmas: D049's two panels read as D015's, and rock with a corner where D016
should be as D016 (6 returns, 3 hits of 6 predicted beams and 3 through the panels:
beams that favour clutter over the beacon, a negative log-likelihood ratio). A
supporting beacon's beams must now favour it (``verification._beams_favour``).
"""

from __future__ import annotations

import math
from pathlib import Path

from mast.io import read_scan_csv, read_survey
from mast.pipeline.locator import LocatorConfig, locate

DATA = Path(__file__).resolve().parents[1] / "data" / "regressions"
TRUTH_E, TRUTH_N = 7798.6825, 6452.7610


def test_a_rock_look_alike_of_a_beacon_pair_gives_no_fix() -> None:
    scan = read_scan_csv(DATA / "drive40_scan16648_mm.csv", range_min_m=0.05, range_max_m=30.0)
    fix = locate(
        scan, read_survey(DATA / "drive40_beacons.csv"), config=LocatorConfig(range_sigma_m=0.012)
    )
    # One beacon is in view: no fix is owed, and any fix would be far from the truth.
    assert not fix.ok, (fix.pose, fix.beacons)
    for v in fix.verified:
        if len(v.supported) >= 2:
            assert math.hypot(v.pose.easting - TRUTH_E, v.pose.northing - TRUTH_N) < 0.1


def test_beams_that_favour_clutter_do_not_support_a_beacon() -> None:
    from mast.pipeline.verification import BeamCheck, VerificationConfig, _beams_favour

    cfg = VerificationConfig()
    # the D016 of the scan above: half the predicted beams hit, at the edge of their gate
    assert not _beams_favour(BeamCheck(hit=3, occluded=2, through=3, log_likelihood=-8.95), cfg)
    assert _beams_favour(BeamCheck(hit=3, occluded=2, through=3, log_likelihood=4.0), cfg)
    assert not _beams_favour(BeamCheck(hit=2, through=3, log_likelihood=20.0), cfg)
