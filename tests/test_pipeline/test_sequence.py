"""Scans located in sequence: the constant-velocity window first, the wide one after.

A scan near the last fix is searched first in the window the last two fixes predict
(constant velocity, a few of the prediction's sigmas plus what the vehicle's
accelerations allow), then in the window of all the vehicle can have done since the
last fix, then over the whole survey.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from mast.core.pose import Pose2D
from mast.pipeline.locator import (
    STAGES,
    FixedPose,
    Locator,
    LocatorConfig,
    SequenceConfig,
    SequenceLocator,
    locate,
    locate_near,
)
from mast.sim import DriveScene, SimulatedScan, drive_scene

SEQ = SequenceConfig()


def test_the_prediction_carries_the_last_two_fixes_on_across_north() -> None:
    # 0.1 m east and 1 degree clockwise (azimuth 359.5 -> 0.5) in 0.04 s.
    cov = np.diag([1e-6, 4e-6, 1e-8])
    before = FixedPose(0, Pose2D(100.0, 200.0, math.radians(359.5)), cov)
    last = FixedPose(40_000_000, Pose2D(100.1, 200.0, math.radians(0.5)), cov)
    window = SEQ.predicted(before, last, 60_000_000)  # half a step on
    assert window is not None
    assert window.pose.easting == pytest.approx(100.15, abs=1e-12)
    assert window.pose.northing == pytest.approx(200.0, abs=1e-12)
    assert math.degrees(window.pose.azimuth) == pytest.approx(1.0, abs=1e-9)
    # (1 + k)^2 + k^2 of the larger position variance, k = 0.5; what 3 m/s^2 allows
    # over 0.02 s beyond a secant velocity 0.04 s wide: 3 * 0.02 * 0.06 / 2.
    sigma = math.sqrt(2.5 * 4e-6)
    unseen = 0.5 * 0.02 * 0.06
    assert window.radius_m == pytest.approx(0.05 + 3 * sigma + 3.0 * unseen, rel=1e-9)
    assert window.azimuth_tolerance_rad == pytest.approx(
        math.radians(1.0) + 3 * math.sqrt(2.5e-8) + 2.0 * unseen, rel=1e-9
    )


def test_no_prediction_across_a_gap_or_backwards_in_time() -> None:
    p, cov = Pose2D(0.0, 0.0, 0.0), np.zeros((3, 3))
    at = FixedPose(0, p, cov)
    assert SEQ.predicted(at, FixedPose(600_000_000, p, cov), 650_000_000) is None
    assert SEQ.predicted(at, FixedPose(40_000_000, p, cov), 600_000_000) is None
    assert SEQ.predicted(at, FixedPose(40_000_000, p, cov), 30_000_000) is None
    assert SEQ.predicted(at, FixedPose(0, p, cov), 40_000_000) is None


@cache
def _drive() -> tuple[DriveScene, tuple[SimulatedScan, ...]]:
    # The first 40 scans of this drive (25 Hz, 1-3 m/s) each show two beacons.
    scene = drive_scene(0, scans=30)
    return scene, tuple(scene.iter_simulated())


def _config(scene: DriveScene) -> LocatorConfig:
    return LocatorConfig(range_sigma_m=scene.shots[0].scanner.range_sigma_m)


def _off(pose: Pose2D, truth: Pose2D) -> tuple[float, float]:
    d = math.hypot(pose.easting - truth.easting, pose.northing - truth.northing)
    return d, abs(math.remainder(pose.azimuth - truth.azimuth, math.tau))


def test_a_drive_is_tracked_in_the_predicted_window() -> None:
    scene, sims = _drive()
    tracker = SequenceLocator(scene.survey, config=_config(scene))
    radii = []
    for k, sim in enumerate(sims[:12]):
        step = tracker.step(sim.scan)
        assert step.fix.ok, (k, step.fix.reason)
        assert step.fix.pose is not None
        d, a = _off(step.fix.pose, sim.pose)
        assert d < 0.02
        assert a < math.radians(0.1)
        assert step.tracked == (k > 0)
        assert not step.track_lost
        if k >= 2:  # two fixes before: a velocity
            prior = step.fix.config.prior
            assert prior is not None
            radii.append(prior.radius_m)
            # the prediction's window is narrow: its centre, refined by ICP, is the fix
            chosen = step.fix.chosen
            assert chosen is not None
            assert chosen.hypothesis.similarity.pose().position.tolist() == (
                prior.pose.position.tolist()
            )
    wide = SEQ.prior(sims[0].pose, 0.04).radius_m
    assert max(radii) < 0.5 * wide


def test_a_jolt_off_the_prediction_is_found_in_the_wide_window() -> None:
    scene, sims = _drive()
    tracker = SequenceLocator(scene.survey, config=_config(scene))
    for sim in sims[:4]:
        assert tracker.step(sim.scan).fix.ok
    # The vehicle is where it would be three scans on, one scan's time later.
    ahead = sims[6]
    jumped = _off(ahead.pose, sims[4].pose)[0]
    assert 0.1 < jumped < SEQ.prior(sims[3].pose, 0.04).radius_m - 0.02
    scan = replace(ahead.scan, stamp_ns=sims[4].scan.stamp_ns)
    step = tracker.step(scan)
    assert step.fix.ok
    assert step.fix.pose is not None
    assert not step.track_lost
    assert _off(step.fix.pose, ahead.pose)[0] < 0.02
    prior = step.fix.config.prior
    assert prior is not None
    assert prior.radius_m == pytest.approx(SEQ.prior(sims[3].pose, 0.04).radius_m)


def test_the_locator_object_is_the_one_chain_and_times_its_stages() -> None:
    """``Locator`` holds the survey's index once and gives what ``locate`` and
    ``locate_near`` give, with each stage's time on the result."""
    scene, sims = _drive()
    cfg = _config(scene)
    locator = Locator(scene.survey, cfg)
    range_max = sims[0].scan.range_max_m
    assert locator.ready(range_max) is locator.ready(range_max)
    first = locator.locate(sims[0].scan)
    again = locate(sims[0].scan, scene.survey, config=cfg)
    assert first.ok
    assert again.ok
    assert first.pose == again.pose
    assert first.verified[0].pose == again.verified[0].pose
    # Without a prior: no window was searched; every stage's time within the total.
    assert set(first.stages_s) <= set(STAGES)
    assert {"segmentation", "identification", "hypotheses", "verification", "adjustment"} <= set(
        first.stages_s
    )
    assert "window" not in first.stages_s
    assert all(t >= 0.0 for t in first.stages_s.values())
    assert sum(first.stages_s.values()) <= first.elapsed_s
    # Near the first fix: the window's search fixes the next scan, as locate_near does.
    assert first.pose is not None
    prior = SEQ.prior(first.pose, 0.04)
    near = locator.locate(sims[1].scan, prior)
    assert near.ok
    assert near.config.prior == prior
    assert near.pose == locate_near(sims[1].scan, scene.survey, prior, config=cfg).pose
    assert near.stages_s["window"] > 0.0
    assert "hypotheses" not in near.stages_s  # the global hypotheses were not needed
    assert sum(near.stages_s.values()) <= near.elapsed_s


def test_a_tracked_scan_is_segmented_only_when_a_corner_must_prove_a_beacon() -> None:
    """Near the last fix the prior names the beacons: a pose whose beacons show two
    panels' returns on their panels is fixed without segmenting the scan. When that is
    not enough (here scans 44-47, a beacon with one panel's returns and its corner), the
    scan is segmented and the same poses judged again with the corners; still tracked,
    not lost to the global search."""
    scene = drive_scene(0, scans=48)
    sims = tuple(scene.iter_simulated())
    tracker = SequenceLocator(scene.survey, config=_config(scene))
    plain = []
    for k, sim in enumerate(sims):
        step = tracker.step(sim.scan)
        fix = step.fix
        if k == 0:
            assert fix.ok
            assert fix.segmentation is not None  # the global search: segmented
            continue
        assert step.tracked
        if not fix.ok:  # scan 43: one beacon in view; segmented for the global search
            assert fix.segmentation is not None
            continue
        assert fix.pose is not None
        assert fix.chosen is not None
        assert _off(fix.pose, sim.pose)[0] < 0.02
        assert not step.track_lost
        assert fix.chosen.hypothesis.kind == "prior"
        if fix.segmentation is None:
            assert fix.identification is None
            assert "segmentation" not in fix.stages_s
            plain.append(k)
        else:
            assert fix.identification is not None
            assert fix.identification.nodes
            assert k >= 44, k
    assert len(plain) >= 40
    assert set(range(44, 48)).isdisjoint(plain)


def test_a_second_judgement_with_corners_equals_a_fresh_one() -> None:
    """The search with corners after the one without reuses each pose's ICP, beam checks
    and beacon tests (``verify(icp_memo=...)``): it must judge as a fresh search with
    the corners does."""
    from mast.pipeline.identification import identify_panels
    from mast.pipeline.locator import survey_index
    from mast.pipeline.segmentation import segment_scan
    from mast.pipeline.tracking import Prior, prior_hypotheses
    from mast.pipeline.verification import verify

    scene = drive_scene(0, scans=48)
    cfg = _config(scene)
    compared = 0
    for sim in tuple(scene.iter_simulated())[40:48]:  # 44-47 need their corners
        scan = sim.scan
        index, panels = survey_index(scene.survey, scan.range_max_m)
        prior = Prior(sim.pose, 0.3, math.radians(4.0))
        batches = prior_hypotheses(scan.points()[1], panels, prior, scan.range_max_m)
        seg = segment_scan(scan, cfg.segmentation)
        ident = identify_panels(seg, index.representatives, cfg.identification)
        for batch in batches:
            memo: dict = {}
            common = (scan, panels, index)
            verify(batch, *common, None, None, cfg.noise, cfg.verification, icp_memo=memo)
            again = verify(batch, *common, ident, seg, cfg.noise, cfg.verification, icp_memo=memo)
            fresh = verify(batch, *common, ident, seg, cfg.noise, cfg.verification)
            assert [
                (v.pose, v.supported, v.cornered, v.shaped, v.misfit, v.log_likelihood)
                for v in again
            ] == [
                (v.pose, v.supported, v.cornered, v.shaped, v.misfit, v.log_likelihood)
                for v in fresh
            ]
            compared += len(fresh)
    assert compared >= 8
