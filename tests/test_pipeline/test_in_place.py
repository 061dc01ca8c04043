"""Whether a beacon's returns lie on its surveyed panels within their noise."""

import math

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
