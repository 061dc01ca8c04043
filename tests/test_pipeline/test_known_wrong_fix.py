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

import pytest

from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.io import read_scan_csv, read_survey
from mast.pipeline.locator import LocatorConfig, SequenceLocator, locate

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


# Wrong fixes found by `mast bench longdrive` (issue 31), each scan sent as its
# protocol sends it (whole millimetres). Scenes: drive_scene(seed, scans=10000,
# rate_hz=...), 0.5 deg, 12 mm; located with lms1xx-0.5's precisions.
LONG_CONFIG = LocatorConfig(range_sigma_m=0.012, angle_sigma_rad=0.0)


def _long_scan(name: str, range_max_m: float = 30.0) -> Scan:
    return read_scan_csv(DATA / name, range_min_m=0.05, range_max_m=range_max_m)


@pytest.mark.parametrize(
    "scan",
    [
        # one panel of D022 in view: fixed 292 m away on D001 and D002
        "drive40s2_scan5907_mm.csv",
        # D023 in view: fixed 82 m away on its look-alike D019, rock read as D018
        "drive40s2_scan7086_mm.csv",
        # D026 in view: fixed 117 m away on its look-alike D018, rock read as D019
        "drive40s2_scan7715_mm.csv",
    ],
)
def test_a_look_alike_pair_read_into_one_beacon_and_rock_is_no_fix(scan: str) -> None:
    """The wrong pose rested on one identified corner and a second beacon confirmed by
    a few returns of rock; the true reading, one beacon identified by its corner,
    explained the scan within the ambiguity margin (7-27 log-units behind)."""
    fix = locate(_long_scan(scan), read_survey(DATA / "drive40s2_beacons.csv"), config=LONG_CONFIG)
    assert not fix.ok, (fix.pose, fix.beacons)


def test_rock_right_in_front_of_a_look_alikes_panels_does_not_confirm_it() -> None:
    """Scan 7724 of the same drive, a few scans after 7715: D026 in view with 4 returns on
    D027; fixed 117 m away on D018 with D019 confirmed by rock (12 hits on two panels),
    and the scan's returns 10-30 cm short of D019's first panel on 7 more beams. Rock
    read as a panel has rock right in front of it; a panel seldom does."""
    scan = _long_scan("drive40s2_scan7724_mm.csv")
    fix = locate(scan, read_survey(DATA / "drive40s2_beacons.csv"), config=LONG_CONFIG)
    assert not fix.ok, (fix.pose, fix.beacons)
    for v in fix.verified:
        if "D019" in v.checks and v.checks["D019"].hit >= 10:
            assert v.checks["D019"].near >= 5  # what refused it
            assert "D019" not in v.supported


def test_a_corner_of_rock_beside_one_panel_does_not_name_a_beacon() -> None:
    """Seed 0 at 50 Hz, scan 6276 (CoLa-A: no range limit sent), D015 in view: fixed
    64 m away on its look-alike D019 and 'D020', whose 'corner' was rock beside one
    panel (returns 4, 1 and 1 on its three panels)."""
    fix = locate(
        _long_scan("drive50s0_scan6276_mm.csv", math.inf),
        read_survey(DATA / "drive50s0_beacons.csv"),
        config=LONG_CONFIG,
    )
    assert not fix.ok, (fix.pose, fix.beacons)


@pytest.mark.parametrize(
    ("scan", "last", "gap_ns", "truth"),
    [
        # one panel of D003 in view (and a return on the next): tracked 8 cm off
        (
            "drive40s0_scan458_mm.csv",
            Pose2D(7284.6742131524925, 6857.803587518528, 1.0496267049244044),
            125_000_000,
            Pose2D(7284.827731661166, 6857.890379850511, 1.042576755146484),
        ),
        # D006 in view: tracked 10 cm and 1.3 deg off, rock read as D005's middle panel
        (
            "drive40s0_scan1689_mm.csv",
            Pose2D(7343.198279158187, 6887.080150616394, 1.34544388711025),
            75_000_000,
            Pose2D(7343.336293237513, 6887.115657741955, 1.3445703705593242),
        ),
    ],
)
def test_a_tracked_pose_proves_its_second_beacon(
    scan: str, last: Pose2D, gap_ns: int, truth: Pose2D
) -> None:
    """Tracked from the previous fix, as `mast locate RUN` and `mast live` do: no fix
    is owed (one beacon shows two panels at most), and none may be 3 cm off or more."""
    tracker = SequenceLocator(read_survey(DATA / "drive40s0_beacons.csv"), config=LONG_CONFIG)
    s = _long_scan(scan)
    tracker.assume(last, s.stamp_ns - gap_ns)
    step = tracker.step(s)
    assert step.tracked
    if step.fix.ok:
        assert step.fix.pose is not None
        assert math.dist(step.fix.pose.position, truth.position) < 0.03


def test_a_pose_from_two_middle_panels_gives_way_to_a_corner_read_another_way() -> None:
    """Seed 2 at 40 Hz, scan 3194 (issue 31, sixth round): D012 in view, with its corner.
    The corner-free stage read it as its look-alike D008 65 m away and rock as D007's
    middle panel, both bent as their shapes are, 53 log-units ahead of D012's own
    reading on its identified corner. A corner identified on its surveyed edge at
    another pose outweighs two middle panels."""
    scan = _long_scan("drive40s2_scan3194_mm.csv")
    fix = locate(scan, read_survey(DATA / "drive40s2_beacons.csv"), config=LONG_CONFIG)
    assert not fix.ok, (fix.pose, fix.beacons)
    far = [v for v in fix.verified if v.hypothesis.kind == "panels" and len(v.shaped) >= 2]
    assert far  # the look-alike reading was found and refused, not missed
    assert any(v.cornered == ("D012",) for v in fix.verified)


def test_a_prior_searches_other_basins_against_what_its_best_poses_found() -> None:
    """Seed 0 at 50 Hz, scan 4422, tracked 0.1 s after the last fix: the prior's best six
    poses give D012 alone; a pose of the second batch, 5 cm and 0.55 degrees off, read
    rock beside D011 as its panel. Judged with the first batch's poses, D012's reading
    explains the scan as well, and a tracked pose resting on one shaped beacon does not
    outrank it."""
    tracker = SequenceLocator(read_survey(DATA / "drive50s0_beacons.csv"), config=LONG_CONFIG)
    s = _long_scan("drive50s0_scan4422_mm.csv", math.inf)
    last = Pose2D(7432.13194323877, 6885.10772632997, 1.7680036205866971)
    truth = Pose2D(7432.301951536272, 6885.067338900567, 1.7643246871731326)
    tracker.assume(last, s.stamp_ns - 100_000_000)
    step = tracker.step(s)
    assert step.tracked
    if step.fix.ok:
        assert step.fix.pose is not None
        assert math.dist(step.fix.pose.position, truth.position) < 0.03
