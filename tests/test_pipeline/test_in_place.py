"""Whether a beacon's returns lie on its surveyed panels within their noise."""

import math
from dataclasses import replace

import numpy as np

from mast.core.beacon import Beacon, Survey
from mast.core.geometry import PanelSet
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.pipeline.alignment import IcpResult
from mast.pipeline.verification import VerificationConfig, _in_place


def _case(off_m: float, grazing: bool) -> bool:
    # A hat on the wall y = 0: panel 1 from e1 (0, 0) to the node e2 (0.3, 0.2).
    survey = Survey([Beacon("B", np.array([[0, 0], [0.3, 0.2], [0.9, 0.2], [1.2, 0]]))])
    panels = PanelSet.from_survey(survey)
    middle = np.column_stack([np.linspace(0.35, 0.85, 20), np.full(20, 0.2)])
    # The scanner stands on panel 1's line, 1 degree off it, or square in front.
    d1 = panels.direction[0]
    if grazing:
        along = np.array([math.cos(math.radians(1.0)), math.sin(math.radians(1.0))])
        rot = np.array([[d1[0], -d1[1]], [d1[1], d1[0]]])
        origin = panels.a[0] + 0.15 * d1 - 6.0 * (rot @ along)
    else:
        origin = np.array([0.6, 6.0])
    odd = panels.a[0] + 0.15 * d1 + off_m * panels.normal[0]
    pts = np.vstack([middle, odd[None]])
    panel = np.array([1] * 20 + [0])
    resid = np.zeros(21)
    resid[-1] = off_m
    icp = IcpResult(Pose2D(origin[0], origin[1], 0.0), 1, True, panel, resid)
    noise = NoiseModel(range_sigma_m=0.012, angle_sigma_rad=0.0, survey_sigma_m=0.0)
    return _in_place(icp, pts, panels, "B", noise, VerificationConfig())


def test_a_return_well_off_its_panel_misfits_the_beacon() -> None:
    assert _case(0.0, grazing=False)
    assert not _case(0.08, grazing=False)


def test_a_beam_grazing_its_panel_carries_no_range_to_misfit_with() -> None:
    # Within 2 degrees of grazing the footprint spreads along the whole panel (the
    # adjustment leaves such beams out too): its return is not held against the beacon.
    assert _case(0.08, grazing=True)


def test_the_compiled_test_is_the_numpy_one_on_scans() -> None:
    """``_in_place`` (compiled) and ``_in_place_reference`` (numpy) agree for every
    beacon at poses ICP reaches from the truth and from starts around it."""
    from mast.pipeline.alignment import icp_point_to_line
    from mast.pipeline.verification import _in_place_reference
    from mast.sim import paper_scene, simulate_scan

    scene = paper_scene()
    # Every other shot's survey gives each edge its own sigma (one left to the default).
    own = Survey(
        Beacon(b.id, b.edges, edge_sigmas_m=[0.001 * (k + 1), 0.004, math.nan, 0.001])
        for k, b in enumerate(scene.survey)
    )
    surveys = (PanelSet.from_survey(scene.survey), PanelSet.from_survey(own))
    rng = np.random.default_rng(5)
    cfg = VerificationConfig()
    said = {True: 0, False: 0}
    for k, shot in enumerate(scene.shots[:6]):
        panels = surveys[k % 2]
        scanner = replace(shot.scanner, range_sigma_m=0.01)
        scan = simulate_scan(scene.world, shot.pose, scanner, rng=rng).scan
        pts = scan.points()[1]
        for _ in range(6):
            off = rng.normal(0.0, [0.05, 0.05, 0.01])
            start = Pose2D(
                shot.pose.easting + off[0],
                shot.pose.northing + off[1],
                (shot.pose.azimuth + off[2]) % math.tau,
            )
            icp = icp_point_to_line(pts, start, panels, gates_m=(0.15, 0.05))
            mine = icp.pose.scanner_to_mine(pts)
            for beacon in scene.survey.ids:
                # About the scanner's noise, and a noise too small for its returns.
                sigma = float(rng.choice([0.012, 0.002]))
                noise = NoiseModel(range_sigma_m=sigma, angle_sigma_rad=1e-4, survey_sigma_m=0.0)
                got = _in_place(icp, mine, panels, beacon, noise, cfg)
                assert got == _in_place_reference(icp, mine, panels, beacon, noise, cfg)
                said[got] += 1
    assert said[True] > 0, said
    assert said[False] > 0, said
