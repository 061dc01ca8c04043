"""A prior's window in which no pose could put enough returns on two beacons is not
searched at all (issue 32): most scans near the last fix on a drive see one beacon or
none, and their window search was wasted before the global one ran."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from mast.core.pose import Pose2D
from mast.pipeline.locator import LocatorConfig, locate, survey_index
from mast.pipeline.tracking import Prior, window_may_fix
from mast.sim import DriveScene, drive_scene


def _config(scene: DriveScene) -> LocatorConfig:
    return LocatorConfig(range_sigma_m=scene.shots[0].scanner.range_sigma_m)


def test_a_window_no_pose_of_which_sees_two_beacons_is_not_searched() -> None:
    """``window_may_fix`` is a bound: where it says no, locating with that window as the
    prior (its own search, and the global one kept inside it) gives no fix."""
    scene = drive_scene(0, scans=400, rate_hz=25.0)
    cfg = _config(scene)
    _, panels = survey_index(scene.survey, scene.shots[0].scanner.range_max_m)
    rng = np.random.default_rng(7)
    told = {True: 0, False: 0}
    for k, sim in enumerate(scene.iter_simulated()):
        if k % 8:
            continue
        truth = sim.pose
        angle = rng.uniform(0.0, math.tau)
        moved = Pose2D(
            truth.easting + 0.1 * math.cos(angle),
            truth.northing + 0.1 * math.sin(angle),
            truth.azimuth + math.radians(rng.uniform(-2.0, 2.0)),
        )
        prior = Prior(moved, 0.3, math.radians(4.0))
        may = window_may_fix(
            sim.scan.points()[1],
            panels,
            prior,
            sim.scan.range_max_m,
            gate_m=cfg.verification.gate_sigmas * cfg.noise.gate_sigma_m,
            margin_m=cfg.prior_margin_m,
            margin_rad=cfg.prior_margin_rad,
            min_beacons=cfg.min_beacons,
            min_panel_points=cfg.verification.min_panel_points,
        )
        told[may] += 1
        if not may:
            assert not locate(sim.scan, scene.survey, config=replace(cfg, prior=prior)).ok, k
        if sim.owes_fix():
            assert may, k
    assert told[True] >= 5, told
    assert told[False] >= 5, told
