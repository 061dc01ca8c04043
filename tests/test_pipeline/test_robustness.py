"""Never a confident wrong fix: hostile scenes, many beacons, moved beacons, garbage, real scans."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mast import Beacon, Scan, Survey
from mast.bench.realscans import run_real_scans
from mast.bench.robustness import is_wrong
from mast.errors import InputError
from mast.pipeline.locator import NO_FIX_REASONS, LocatorConfig, locate
from mast.sim import drift_scene, hard_scene, paper_scene, random_scene
from tests._paths import SHARED_DATA

NOISY = LocatorConfig(range_sigma_m=0.012)


@pytest.mark.parametrize("seed", range(6))
def test_hostile_scenes_give_no_wrong_fix(seed: int) -> None:
    for index in range(2):
        scene = hard_scene(seed, index)
        for sim in scene.simulate_all():
            fix = locate(sim.scan, scene.survey, config=NOISY)
            assert not is_wrong(fix, sim), (scene.name, sim.pose, fix.pose)
            assert fix.ok or fix.reason in NO_FIX_REASONS


@pytest.mark.parametrize("seed", range(3))
def test_many_identical_beacons_give_no_wrong_fix(seed: int) -> None:
    scene = drift_scene(seed, 0, poses=6)
    assert len(scene.survey) >= 20
    for sim in scene.simulate_all():
        fix = locate(sim.scan, scene.survey, config=NOISY)
        assert not is_wrong(fix, sim), (scene.name, sim.pose, fix.pose, fix.beacons)


def test_a_moved_beacon_is_named_or_refused() -> None:
    scene = random_scene(2, 1, noise=True)
    shot, sim = scene.shots[1], scene.simulate_all()[1]
    base = locate(sim.scan, scene.survey, config=NOISY)
    assert base.ok
    assert len(base.beacons) == 3
    shift = {"B1": np.array([0.05, 0.0])}
    moved = Survey([Beacon(b.id, b.edges + shift.get(b.id, 0.0)) for b in scene.survey])
    fix = locate(sim.scan, moved, config=NOISY)
    if fix.ok:
        assert "B1" in fix.excluded_beacons
        assert "B1" not in fix.beacons
        assert fix.pose is not None
        err = math.hypot(
            fix.pose.easting - shot.pose.easting, fix.pose.northing - shot.pose.northing
        )
        assert err < 0.01
    else:
        assert fix.reason == "inconsistent"
        assert "B1" in fix.detail


def test_two_beacons_that_disagree_refuse_the_fix() -> None:
    # B1 surveyed 12 cm off across the drift: the beacons' distance no longer matches.
    # (A shift along the line of sight of a two-beacon layout can be absorbed by a
    # rotation and escape every test: see the issue notes; three beacons catch it.)
    scene = paper_scene("parallel", range_sigma_m=0.012, seed=4)
    sim = scene.simulate_all()[1]
    b1 = scene.survey["B1"]
    moved = Survey([Beacon("B1", b1.edges + [0.12, 0.0]), scene.survey["B2"]])
    fix = locate(sim.scan, moved, config=NOISY)
    assert not fix.ok
    assert fix.reason in ("inconsistent", "one_beacon")


ranges = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-10, 100),
    st.just(0.0),
    st.floats(1e6, 1e300),
)


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(ranges, min_size=0, max_size=400),
    st.floats(1e-4, 0.05),
    st.floats(-4.0, 0.0),
)
def test_garbage_scans_never_raise(values: list[float], step: float, start: float) -> None:
    survey = paper_scene("parallel").survey
    r = np.array(values, dtype=float)
    finite = r[np.isfinite(r) & (r > 0)]
    with np.errstate(over="ignore"):  # the median of two ranges near 1e300 is inf
        median = np.median(finite) if finite.size else 0.0
    if step * max(r.size - 1, 0) > 2 * math.pi + 1e-6 or median > 1000.0:
        # Beyond a full turn or at kilometre ranges, the scan is refused with a unit hint.
        with pytest.raises(InputError, match="look like"):
            Scan.from_laserscan(angle_min=start, angle_increment=step, ranges=r)
        return
    scan = Scan.from_laserscan(angle_min=start, angle_increment=step, ranges=r)
    fix = locate(scan, survey)
    assert fix.status in ("fix", "no_fix")
    if not fix.ok:
        assert fix.reason in NO_FIX_REASONS


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 0.3))
def test_real_walls_with_random_beacon_surveys_never_fix(seed: int, jitter: float) -> None:
    # a survey that places beacons where the scan has no beacons
    rng = np.random.default_rng(seed)
    scene = paper_scene("parallel")
    sim = scene.simulate_all()[1]
    fake = Survey(
        [
            Beacon(b.id, b.edges + rng.uniform(-3, 3, 2) + rng.normal(0, jitter, (4, 2)))
            for b in scene.survey
            if not Beacon(b.id, b.edges + rng.normal(0, jitter, (4, 2))).identifiability_problems()
        ]
    )
    if len(fake) < 2:
        return
    fix = locate(sim.scan, fake)
    if fix.ok:
        # Only possible when the random shifts moved both beacons alike (the fake survey is
        # the real one moved rigidly, so the scan cannot tell): edge distances agree.
        fake_e = np.concatenate([b.edges for b in fake])
        real_e = np.concatenate([scene.survey[b.id].edges for b in fake])
        d_fake = np.hypot(*(fake_e[:, None] - fake_e[None]).transpose(2, 0, 1))
        d_real = np.hypot(*(real_e[:, None] - real_e[None]).transpose(2, 0, 1))
        assert np.allclose(d_fake, d_real, atol=0.06)


@pytest.mark.skipif(not SHARED_DATA.is_dir(), reason="shared data not present")
def test_real_scans_no_false_fix_and_inserted_beacons_fix() -> None:
    out = run_real_scans(SHARED_DATA, every=25, echo=lambda _s: None)
    assert out
    assert sum(s.false_fixes for s in out) == 0
    assert sum(s.inserted_wrong for s in out) == 0
    assert sum(s.inserted_fixed for s in out) >= 5


def test_survey_files_of_hostile_scenes_round_trip(tmp_path: Path) -> None:
    from mast.io import read_survey, write_survey

    scene = drift_scene(0, 0, poses=1)
    write_survey(tmp_path / "b.csv", scene.survey)
    assert read_survey(tmp_path / "b.csv").ids == scene.survey.ids


def test_identical_beacon_drift_scan_is_never_wrong_and_a_prior_resolves_it() -> None:
    from dataclasses import replace

    from mast.pipeline.tracking import Prior

    scene = drift_scene(2, 0, poses=10)
    shot = next(s for s in scene.shots if s.label == "pose3")
    sims = dict(zip([s.label for s in scene.shots], scene.simulate_all(), strict=True))
    sim = sims["pose3"]
    truth = shot.pose

    def off(fix: object) -> float:
        p = fix.pose  # type: ignore[attr-defined]
        return math.hypot(p.easting - truth.easting, p.northing - truth.northing)

    # Two pairs of identical beacons 60 m apart: the beacons at the edge of the view
    # (hits on the right ones, beams through the wrong ones) decide, or it is ambiguous.
    fix = locate(sim.scan, scene.survey, config=NOISY)
    assert (fix.ok and off(fix) < 0.02) or fix.reason == "ambiguous"
    near = replace(NOISY, prior=Prior(truth, 5.0))
    fix = locate(sim.scan, scene.survey, config=near)
    assert fix.ok
    assert off(fix) < 0.02
    moved = replace(NOISY, prior=Prior(type(truth)(truth.easting + 500, truth.northing, 0.0), 1.0))
    assert locate(sim.scan, scene.survey, config=moved).reason == "inconsistent"
