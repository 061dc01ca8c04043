"""Issue 31 on the shared independent scenes (``../shared/data/independent-scenes``):
scans drawn by a simulator that shares no code with MAST, each with its truth.

Each test names the kind of miss it pins, with the cases that showed it; a change that
brings a miss back fails here, and a wrong fix on any of them fails too.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from mast.core.pose import Pose2D
from mast.io import read_scan_csv, read_survey
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.pipeline.tracking import Prior
from tests._paths import SHARED_DATA

SCENES = SHARED_DATA / "independent-scenes"

pytestmark = pytest.mark.skipif(not SCENES.is_dir(), reason="no shared independent scenes")


def _case(name: str) -> tuple[dict[str, Any], Fix, Any, Any, LocatorConfig]:
    """The case ``family/caseNNNN`` located as the scoring tool does: the scanner's true
    range noise, an exact survey for the noisy family."""
    folder: Path = SCENES / name
    truth = json.loads((folder / "truth.json").read_text())
    scan = read_scan_csv(folder / "scan.csv")
    survey = read_survey(folder / "beacons.csv")
    cfg = LocatorConfig(range_sigma_m=truth["sigma_r"])
    if name.startswith("noisy/"):
        cfg = replace(cfg, survey_sigma_m=0.0)
    return truth, locate(scan, survey, config=cfg), scan, survey, cfg


def _right(truth: dict[str, Any], fix: Fix) -> bool:
    """A fix within 5 cm and 0.25 degrees of the truth (the scoring tool's 'not wrong')."""
    assert fix.pose is not None
    d = math.hypot(fix.pose.easting - truth["easting"], fix.pose.northing - truth["northing"])
    da = (math.degrees(fix.pose.azimuth) - truth["azimuth_deg"] + 180.0) % 360.0 - 180.0
    return d < 0.05 and abs(da) < 0.25


def _prior(name: str, truth: dict[str, Any], radius_m: float, azimuth_deg: float) -> Prior:
    """A prior centred off the truth by ``radius_m`` and ``azimuth_deg``, its window twice
    that (as ``independent-scenes --prior`` draws them), in a direction fixed per case."""
    turn = (sum(map(ord, name)) % 360) * math.pi / 180.0
    centre = Pose2D(
        truth["easting"] + radius_m * math.cos(turn),
        truth["northing"] + radius_m * math.sin(turn),
        math.radians(truth["azimuth_deg"] + azimuth_deg),
    )
    return Prior(centre, 2.0 * radius_m, math.radians(2.0 * abs(azimuth_deg)))


#: Fixed without a prior and lost with a good one before the prior's search was made to
#: add to the global one instead of replacing it.
LOST_TO_A_PRIOR = [
    "noisy/case0002",
    "noisy/case0016",
    "noisy/case0032",
    "noisy/case0055",
    "hostile/case0042",
    "hostile/case0063",
]


@pytest.mark.parametrize("name", LOST_TO_A_PRIOR)
def test_a_good_prior_never_loses_a_fix_the_global_search_gives(name: str) -> None:
    truth, alone, scan, survey, cfg = _case(name)
    assert alone.ok, alone.detail
    assert _right(truth, alone)
    for radius_m, azimuth_deg in ((0.4, 4.0), (0.5, -5.0)):
        prior = _prior(name, truth, radius_m, azimuth_deg)
        near = locate(scan, survey, config=replace(cfg, prior=prior))
        assert near.ok, near.detail
        assert _right(truth, near)


def test_a_prior_searches_other_basins_of_its_window_when_the_best_poses_fail() -> None:
    """Hostile 0046 has no fix without a prior (its corners are not identified). With one
    0.5 m and 5 degrees off, the six best grid poses of its window all lie in one wrong
    basin, 1 m and 11-15 degrees off and within 0.3 m and 3.5 degrees of each other:
    the second batch, poses at least 0.4 m from every one before, holds the true one
    (its second)."""
    name = "hostile/case0046"
    truth, alone, scan, survey, cfg = _case(name)
    assert not alone.ok
    near = replace(cfg, prior=_prior(name, truth, 0.5, 5.0))
    fix = locate(scan, survey, config=near)
    assert fix.ok, fix.detail
    assert _right(truth, fix)
    one_batch = replace(near, tracking=replace(near.tracking, other_basins_m=math.inf))
    assert not locate(scan, survey, config=one_batch).ok


def test_a_start_near_a_misfitting_pose_is_still_refined_on_its_own() -> None:
    """Hostile 0046 with a prior 0.4 m and 4 degrees off: the first grid pose refines to a
    pose 0.5 degrees off that misfits one beacon; the third starts 4 cm and 0.14 degrees
    from it and refines to the truth, with both beacons. Taken for the same pose (within
    5 cm and 0.5 degrees, as verification once did), it was never refined."""
    name = "hostile/case0046"
    truth, _, scan, survey, cfg = _case(name)
    near = replace(cfg, prior=_prior(name, truth, 0.4, 4.0))
    fix = locate(scan, survey, config=near)
    assert fix.ok, fix.detail
    assert _right(truth, fix)
    coarse = replace(near.verification, duplicate_m=0.05, duplicate_rad=math.radians(0.5))
    assert not locate(scan, survey, config=replace(near, verification=coarse)).ok


@pytest.mark.parametrize("name", ["noisy/case0002", "hostile/case0042"])
def test_a_wrong_prior_still_gives_no_fix(name: str) -> None:
    """The global search a failed prior falls back on keeps only poses inside its window."""
    truth, alone, scan, survey, cfg = _case(name)
    assert alone.ok
    for radius_m, azimuth_deg in ((2.0, 3.0), (3.0, 20.0)):
        turn = _prior(name, truth, radius_m, azimuth_deg)
        wrong = Prior(turn.pose, 1.0, math.radians(10.0))
        fix = locate(scan, survey, config=replace(cfg, prior=wrong))
        assert not fix.ok
        assert "within the prior" in fix.detail


def test_two_icp_optima_of_one_reading_are_not_two_places() -> None:
    """Two verified poses 0.12 m and 1 degree apart put 88 % of their returns on the same
    panels of the same two beacons: one reading of the scan, not an ambiguity."""
    truth, fix, *_ = _case("hostile/case0059")
    assert fix.ok, fix.detail
    assert _right(truth, fix)


def test_no_beacon_confirmed_is_said_so_not_with_an_empty_name() -> None:
    """A record once read 'only beacon  confirmed by the beams' with no name in it."""
    from mast.pipeline.locator import _choose

    assert _choose([], LocatorConfig()) == (
        None,
        "one_beacon",
        "no beacon is confirmed by the beams",
    )


#: A visible second beacon refused because rock past the free end of its short outer
#: panel stood in the middle panel's line (the overrun search reached past the beacon).
WALL_PAST_A_FREE_END = [
    "noisy/case0011",
    "noisy/case0126",
    "noisy/case0133",
    "noisy/case0139",
    "hostile/case0032",
    "hostile/case0067",
    "hostile/case0074",
]

#: A beacon's corner not identified: its outer panel's segment ran on into the wall.
OUTER_PANEL_RUNS_ON = ["noisy/case0026", "hostile/case0009"]

#: Called ambiguous against a pose whose beacons' returns do not lie on their panels
#: (chi-square p of 1e-37 to 1e-7): rock beside a panel, or another design's shape,
#: read as theirs.
MISFIT_COMPETITOR = ["hostile/case0054", "hostile/case0057", "hostile/case0058", "hostile/case0063"]


@pytest.mark.parametrize("name", WALL_PAST_A_FREE_END + OUTER_PANEL_RUNS_ON + MISFIT_COMPETITOR)
def test_a_plainly_visible_second_beacon_now_fixes(name: str) -> None:
    truth, fix, *_ = _case(name)
    assert fix.ok, fix.detail
    assert _right(truth, fix)


@pytest.mark.parametrize("name", MISFIT_COMPETITOR)
def test_a_competitor_that_misfits_its_beacons_does_not_compete(name: str) -> None:
    """The competitor (more than a metre away) reads rock or another shape as its
    beacons: it is either refused outright (a misfitting beacon supports nothing) or
    kept with its misfit, and then does not make the fitting fix ambiguous."""
    truth, fix, *_ = _case(name)
    assert fix.ok
    assert fix.chosen is not None
    assert not fix.chosen.misfit
    for v in fix.verified:
        far = math.hypot(v.pose.easting - truth["easting"], v.pose.northing - truth["northing"])
        if far > 1 and len(v.supported) >= 2:
            assert v.misfit


#: Each beacon's short outer panel fitted into one line with the rock beside it, so no
#: corner lands on an edge (or one lands 0.1-0.25 m off and is named another design or
#: edge), while both middle panels are segments of their own.
CORNER_FREE = ["noisy/case0048", "noisy/case0096", "noisy/case0144", "hostile/case0023"]


@pytest.mark.parametrize("name", CORNER_FREE)
def test_two_middle_panels_fix_where_no_corner_lands_on_its_edge(name: str) -> None:
    truth, fix, *_ = _case(name)
    assert fix.ok, fix.detail
    assert _right(truth, fix)
    assert fix.chosen is not None
    assert fix.chosen.hypothesis.kind == "panels"
    assert len(fix.chosen.shaped) >= 2


@pytest.mark.parametrize("name", ["noisy/case0101", "hostile/case0060"])
def test_a_pose_whose_cornered_beacon_misfits_is_not_a_fix(name: str) -> None:
    """A beacon identified by its corner whose returns do not lie on its panels (rock
    read as a panel it does not show) supports no pose: 0101 was fixed 0.17 degrees,
    5.4 of its sigmas, off in azimuth; a look-alike 204 m away on a long drive rested on
    such a corner. 0060 (hostile) is the price: within 2.7 CRB."""
    _, fix, *_ = _case(name)
    assert not fix.ok
    assert fix.reason in ("inconsistent", "one_beacon")
