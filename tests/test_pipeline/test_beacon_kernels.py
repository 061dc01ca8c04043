"""A beacon's compiled tests give what their numpy references give: the returns that
run on past its nodes (counts to the return) and its straight-line and panel
chi-squares (to rounding)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from mast.core.beacon import Beacon, Survey
from mast.core.geometry import PanelSet
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.pipeline.alignment import icp_point_to_line
from mast.pipeline.verification import (
    VerificationConfig,
    _overrun,
    _overrun_reference,
    _straight_and_fitted,
    _straight_and_fitted_reference,
)
from mast.sim import paper_scene, simulate_scan


def _hat() -> PanelSet:
    # A hat on the wall y = 0: e1 (0, 0), nodes (0.3, 0.2) and (0.9, 0.2), e4 (1.2, 0).
    survey = Survey([Beacon("B", np.array([[0, 0], [0.3, 0.2], [0.9, 0.2], [1.2, 0]]))])
    return PanelSet.from_survey(survey)


def _both(points: np.ndarray, panels: PanelSet, to_free_ends: bool) -> dict[int, int]:
    mine = panels.of_beacon(0)
    args = (points, panels, mine, 0.03, 0.01, VerificationConfig(), to_free_ends)
    got = _overrun(*args)
    assert got == _overrun_reference(*args)
    return got


@pytest.mark.parametrize("to_free_ends", [False, True])
def test_a_shelf_in_the_middle_panels_line_runs_on_and_a_crossing_wall_does_not(
    to_free_ends: bool,
) -> None:
    panels = _hat()
    rng = np.random.default_rng(3)
    middle = np.column_stack([np.linspace(0.32, 0.88, 30), 0.2 + 0.002 * rng.standard_normal(30)])
    # A shelf going on in the middle panel's line 0.25 m past the node at x = 0.9 ...
    shelf = np.column_stack([np.linspace(1.0, 1.25, 12), 0.2 + 0.002 * rng.standard_normal(12)])
    counts = _both(np.vstack([middle, shelf]), panels, to_free_ends)
    middle_panel = int(panels.of_beacon(0)[1])
    assert counts[middle_panel] > 0
    # ... and a surface only crossing the band there, steeply.
    x = np.linspace(1.0, 1.25, 12)
    crossing = np.column_stack([x, 0.2 + 0.2 * (x - 1.12)])
    counts = _both(np.vstack([middle, crossing]), panels, to_free_ends)
    assert counts[middle_panel] == 0


def test_the_compiled_tests_are_the_numpy_ones_on_scans() -> None:
    """At poses ICP reaches from the truth and from starts well away from it (where
    returns of rock lie along the panels' lines), every beacon's counts are the same
    and its chi-squares the same to rounding."""
    scene = paper_scene()
    # Every other shot's survey gives each edge its own sigma (one left to the default).
    own = Survey(
        Beacon(b.id, b.edges, edge_sigmas_m=[0.001 * (k + 1), 0.004, math.nan, 0.001])
        for k, b in enumerate(scene.survey)
    )
    surveys = (PanelSet.from_survey(scene.survey), PanelSet.from_survey(own))
    rng = np.random.default_rng(11)
    cfg = VerificationConfig()
    ran_on = 0
    for k, shot in enumerate(scene.shots[:6]):
        panels = surveys[k % 2]
        scanner = replace(shot.scanner, range_sigma_m=0.01)
        scan = simulate_scan(scene.world, shot.pose, scanner, rng=rng).scan
        pts = scan.points()[1]
        for spread in (0.0, 0.05, 0.4):
            off = rng.normal(0.0, [spread, spread, spread / 5])
            start = Pose2D(
                shot.pose.easting + off[0],
                shot.pose.northing + off[1],
                (shot.pose.azimuth + off[2]) % math.tau,
            )
            icp = icp_point_to_line(pts, start, panels, gates_m=(0.15, 0.05))
            mine_pts = icp.pose.scanner_to_mine(pts)
            noise = NoiseModel(range_sigma_m=0.01, angle_sigma_rad=1e-4, survey_sigma_m=0.002)
            for number, _beacon in enumerate(scene.survey.ids):
                mine = panels.of_beacon(number)
                for to_free_ends in (False, True):
                    args = (mine_pts, panels, mine, 0.03, 0.01, cfg, to_free_ends)
                    got = _overrun(*args)
                    assert got == _overrun_reference(*args)
                    ran_on += sum(got.values()) > 0
                on = np.isin(icp.panel, mine)
                if np.count_nonzero(on) < 4:
                    continue
                var = panels.survey_variance(noise.survey_sigma_m)
                chi = _straight_and_fitted(
                    mine_pts, on, icp.residual_m, icp.panel, icp.pose.position, noise, var
                )
                ref = _straight_and_fitted_reference(
                    mine_pts[on], icp.residual_m[on], icp.pose.position, noise, var[icp.panel[on]]
                )
                np.testing.assert_allclose(chi, ref, rtol=1e-9)
    assert ran_on > 0
