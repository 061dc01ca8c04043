"""The 3D locator (pipeline.locator3d) on simulated drifts: never a wrong or overconfident
fix, tilted frames fixed at the paper's layout within their covariance, the plan view's
tries, a panel kept to one run of heights and near a free end on the rings its beacon
shows clear of it (a shallow middle panel by its mean off the wall the ring shows), and
a survey without elevations refused."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from mast.core._kernels import contiguous3d, floors3d
from mast.core.beacon import Survey
from mast.core.pose import Pose2D
from mast.core.pose3d import Frame3D, Pose3D, rotation_rpy
from mast.core.scan import Scan
from mast.errors import InputError
from mast.pipeline import adjust3d, locator3d
from mast.pipeline.adjust3d import FLOOR_PAST_M, Adjustment3D, PanelPlanes
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.pipeline.locator3d import (
    NEAR_M,
    PITCH_TRIES_DEG,
    PLATE_RINGS,
    PLATE_SLACK_M,
    START_HITS,
    Fix3D,
    Locator3DConfig,
    _beacon_bands,
    _checked,
    _contiguous,
    _moved,
    _on_one_beacon,
    _plate_floors,
    _refused_off_plan,
    _start_elevation,
    _tries,
    _witnessed,
    locate3d,
)
from mast.pipeline.plan_view import _bin_bands, level_rotation
from mast.pipeline.verification import VerificationConfig
from mast.report.record import fix3d_record, fix3d_text
from mast.sim.lidar3d import DriftScene3D, SimulatedFrame3D, random_drift_scene
from tests._raycast3d import cast, paper_walls


def test_no_simulated_frame_gets_a_wrong_or_overconfident_fix() -> None:
    fixed = 0
    for seed in range(3):
        scene = random_drift_scene(seed, frames=5, lidar="vlp16", range_sigma_m=0.02)
        for i in range(5):
            sim = scene.simulate(i)
            fix = locate3d(sim.frame, scene.survey, config=Locator3DConfig(range_sigma_m=0.02))
            if not fix.ok:
                assert fix.reason is not None
                continue
            assert fix.pose is not None
            assert fix.adjustment is not None
            fixed += 1
            p, t = fix.pose, sim.pose
            err = p.minus(t)
            assert math.hypot(err[0], err[1]) < 0.1
            # each of the six within 4.5 sigmas of its own covariance (a 1-in-150 000
            # draw each): a fix on the wall's returns, or a bracket the wall made, is
            # many more
            assert np.all(np.abs(err) < 4.5 * np.sqrt(np.diag(fix.adjustment.covariance)))
    assert fixed >= 4  # not vacuous: the frames it fixes are checked


# the rounds' moves, in sigmas of that covariance, warn of the root of its negative variance
@pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt:RuntimeWarning")
def test_an_adjustment_whose_variances_are_not_all_positive_gives_no_fix(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Normal equations near singular invert to a "covariance" with a negative variance
    # (an intermediate adjustment of a VLP-16 draw had -2e10 m^2 in plan): such an
    # adjustment is refused, never given as a fix with a NaN sigma (nor a traceback).
    walls, scene = paper_walls("convergent")
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, 6.0, -4.0)
    frame = cast(truth, walls, 0.01, 2)
    real = locator3d.adjust_pose

    def broken(*args: object, **kwargs: object) -> Adjustment3D:
        adj = real(*args, **kwargs)  # type: ignore[arg-type]
        if kwargs.get("elevation", True):  # the elevation rounds, not the growth stages
            cov = adj.covariance.copy()
            cov[0, 0] = -cov[0, 0]
            adj = replace(adj, covariance=cov)
        return adj

    monkeypatch.setattr(locator3d, "adjust_pose", broken)
    fix = locate3d(frame, scene.survey, config=Locator3DConfig(range_sigma_m=0.01))
    assert not fix.ok
    assert fix.reason == "degenerate_geometry"
    assert "variances are not all positive" in fix.detail


@pytest.mark.parametrize(("pitch", "roll"), [(0.0, 0.0), (6.0, -4.0)])
def test_the_paper_layout_tilted_is_fixed_in_six_parameters(pitch: float, roll: float) -> None:
    walls, scene = paper_walls("convergent")
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, pitch, roll)
    fix = locate3d(
        cast(truth, walls, 0.01, 2), scene.survey, config=Locator3DConfig(range_sigma_m=0.01)
    )
    assert fix.ok, fix.detail
    assert fix.pose is not None
    assert fix.adjustment is not None
    p = fix.pose
    sd = np.sqrt(np.diag(fix.adjustment.covariance))
    err = [
        p.easting - 7.0,
        p.northing - 7.0,
        p.elevation - 1.2,
        p.roll - truth.roll,
        p.pitch - truth.pitch,
        (p.azimuth - truth.azimuth + math.pi) % (2 * math.pi) - math.pi,
    ]
    assert np.all(np.abs(err) < 4.0 * sd), np.round(np.array(err) / sd, 1)
    assert math.hypot(err[0], err[1]) < 0.01
    assert fix.beacons == ("B1", "B2")


def test_the_plan_view_is_tried_level_first_then_pitched_either_way() -> None:
    tries = _tries(Locator3DConfig())
    bands = Locator3DConfig().bands_m
    assert tries[: len(bands)] == [(0.0, b) for b in bands]
    pitches = [t for t, _ in tries]
    assert sorted({abs(t) for t in pitches}) == sorted({abs(t) for t in PITCH_TRIES_DEG})
    assert all(pitches.count(t) == pitches.count(-t) for t in pitches)  # either way alike


def test_a_refined_vertical_is_tried_in_every_band(monkeypatch: pytest.MonkeyPatch) -> None:
    # A VLP-16 2 cm look-alike frame of fresh draws (seed 1, drift 1, frame 3): the first
    # try's plan view shows one beacon, whose panels refine the vertical; at that
    # vertical the second beacon is in the widest band only. Refined tries in the first
    # two bands, as they were, left the frame refused. (The one-beacon start again from
    # that beacon's own panels fixes it first: not made here, see the next test.)
    scene = random_drift_scene(1, 1, frames=10, lidar="vlp16", range_sigma_m=0.02, lookalikes=True)
    monkeypatch.setattr(locator3d, "OWN_TILT_SIGMA_DEG", -1.0)
    seen: list[tuple[NDArray[np.float64], tuple[float, float]]] = []
    refined: list[NDArray[np.float64]] = []
    plan_view, on_its_panels = locator3d._plan_view, locator3d._on_its_panels

    def viewed(frame: Frame3D, up: NDArray[np.float64], band: tuple[float, float], *a: Any) -> Any:
        seen.append((np.array(up), band))
        return plan_view(frame, up, band, *a)

    def refining(*a: Any, **k: Any) -> Any:
        own = on_its_panels(*a, **k)
        if own is not None and own[1] <= math.radians(locator3d.REFINE_TILT_SIGMA_DEG):
            refined.append(np.asarray(own[0].rotation[2]))
        return own

    monkeypatch.setattr(locator3d, "_plan_view", viewed)
    monkeypatch.setattr(locator3d, "_on_its_panels", refining)
    sim, fix = _located(scene, 3, 0.02)
    _within(fix, sim)
    assert refined  # the first holds the refined tries' vertical
    at_refined = [band for up, band in seen if np.array_equal(up, refined[0])]
    assert at_refined[:3] == list(Locator3DConfig().bands_m)
    assert fix.up is not None
    assert np.array_equal(fix.up, refined[0])  # the fix is the refined vertical's
    assert fix.plan.pose is not None


def test_a_one_beacon_start_starts_again_from_that_beacons_own_panels(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The same frame as above: its first try's plan view confirms one beacon, smeared by
    # a vertical degrees off, and the 3D stages from its pose refuse. The beacon's own
    # panels put it and the vertical elsewhere, and from there the 3D stages fix it.
    scene = random_drift_scene(1, 1, frames=10, lidar="vlp16", range_sigma_m=0.02, lookalikes=True)
    made: list[tuple[Pose2D, NDArray[np.float64], bool]] = []
    from_one = locator3d._from_one_beacon

    def recorded(frame: Frame3D, survey: Survey, planes: PanelPlanes, plan: Fix,
                 start: Pose2D, seen: tuple[str, ...], up: NDArray[np.float64], *a: Any,
                 **k: Any) -> Fix3D:  # fmt: skip
        fix = from_one(frame, survey, planes, plan, start, seen, up, *a, **k)
        made.append((start, np.array(up), fix.ok))
        return fix

    monkeypatch.setattr(locator3d, "_from_one_beacon", recorded)
    sim, fix = _located(scene, 3, 0.02)
    _within(fix, sim, 3.0)
    (plan_start, tried, plan_fixed), (own_start, own_up, own_fixed) = made
    assert not plan_fixed
    assert own_fixed
    truth = np.asarray(sim.pose.rotation[2])
    off = [math.degrees(math.acos(min(1.0, float(v @ truth)))) for v in (tried, own_up)]
    assert off[1] < 1.0 < locator3d.OWN_APART_DEG < off[0], off  # 5.8 and 0.16 deg off
    monkeypatch.setattr(locator3d, "OWN_TILT_SIGMA_DEG", -1.0)
    made.clear()
    _located(scene, 3, 0.02)
    assert made[0][0] == plan_start
    for start, _, _ in made:  # none started from its panels
        assert not locator3d._same_start(start, (), tried, own_start, (), tried)


def test_the_plan_view_located_again_near_a_3d_pose_is_not_dragged_onto_a_wall(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 2 cm frame of fresh draws (seed 2, drift 3, frame 4): B3, 3.3 m off, has
    # its top 0.79 m below the sensor and only the lowest ring grazing it, so the plan
    # view shows there its wall, a decimetre or two behind its panels. The 3D stages
    # from B4's own panels fix B4 and B5; the plan view located again near that pose
    # must confirm them, and with the 2D gates (15 cm first) ICP took B3's wall for its
    # panels and dragged each hypothesis decimetres, the beams refusing the rest.
    scene = random_drift_scene(2, 3, frames=10, lidar="vlp16", range_sigma_m=0.02, lookalikes=True)
    again: list[Fix] = []
    plan_again = locator3d._plan_again

    def recorded(*a: Any) -> Fix:
        fix = plan_again(*a)
        again.append(fix)
        return fix

    monkeypatch.setattr(locator3d, "_plan_again", recorded)
    sim, fix = _located(scene, 4, 0.02)
    _within(fix, sim, 3.0)
    assert set(fix.beacons) >= {"B4", "B5"}
    confirmed = [f for f in again if f.ok and f.pose is not None]
    assert confirmed
    for f in confirmed:  # the 2D fix where the 3D pose is, not dragged off it
        assert f.pose is not None
        off = math.hypot(f.pose.easting - sim.pose.easting, f.pose.northing - sim.pose.northing)
        assert off < 0.02, off
    strict = VerificationConfig().coarse_gates_m
    for gates, wall in ((strict, locator3d.AGAIN_WALL_M), (locator3d.AGAIN_GATES_M, 0.0)):
        monkeypatch.setattr(locator3d, "AGAIN_GATES_M", gates)
        monkeypatch.setattr(locator3d, "AGAIN_WALL_M", wall)
        again.clear()
        _, refused = _located(scene, 4, 0.02)
        assert not refused.ok  # either rule alone leaves the frame unfixed
        assert again
        assert not any(f.ok for f in again)


def test_top_edges_alternating_between_two_choices_give_their_mixture(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 1 cm look-alike frame of fresh draws (seed 3, drift 3, frame 4): B1, 3.1 m
    # off, has its top at the sensor's height, and the top edges' rays chosen at each
    # adjusted pose alternate between two choices, each adjustment within about a
    # sigma of the truth. The fix is their mean, its covariance their mixture's.
    scene = random_drift_scene(3, 3, frames=10, lidar="vlp16", range_sigma_m=0.01, lookalikes=True)
    pairs: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    covariances: list[NDArray[np.float64]] = []
    mixed: list[tuple[Adjustment3D, tuple[NDArray[np.float64], ...], list[NDArray[Any]]]] = []
    alternate, adjust, covariance = adjust3d._alternate, locator3d.adjust_pose, adjust3d._covariance

    def recorded(solved: Any, before: Any, *a: Any) -> Any:
        other = alternate(solved, before, *a)
        if other is not None:
            pairs.append((solved.x.copy(), other.x.copy()))
        return other

    def kept(*a: Any) -> NDArray[np.float64]:
        covariances.append(covariance(*a))
        return covariances[-1]

    def adjusted(*a: Any, **k: Any) -> Adjustment3D:
        covariances.clear()
        adj = adjust(*a, **k)
        if adj.mixed:
            mixed.append((adj, pairs[-1], list(covariances)))
        return adj

    monkeypatch.setattr(adjust3d, "_alternate", recorded)
    monkeypatch.setattr(adjust3d, "_covariance", kept)
    monkeypatch.setattr(locator3d, "adjust_pose", adjusted)
    sim, fix = _located(scene, 4, 0.01)
    _within(fix, sim, 3.0)
    assert fix.adjustment is not None
    assert fix.adjustment.mixed
    assert mixed
    order = [0, 1, 5, 4, 3, 2]  # (E, N, A, pitch, roll, Z) -> the record's order
    for adj, (one, other), (c_one, c_other) in mixed:
        half = 0.5 * (other - one)
        mean = adj.pose.minus(Pose3D(one[0], one[1], one[5], one[2], one[3], one[4]))
        assert np.allclose(mean, half[order], atol=1e-9)  # the mean of the two
        mixture = 0.5 * (c_one + c_other) + np.outer(half, half)
        assert np.allclose(adj.covariance, mixture[np.ix_(order, order)], rtol=1e-12, atol=0)
        assert np.abs(half[5]) > 0.2 * math.sqrt(mixture[5, 5])  # the choices differ
    # without the mixture the rays alternate to the last round: refused, as unsettled
    # (since the start's START_HITS, by the cut that changed at the last round)
    monkeypatch.setattr(adjust3d, "_alternate", lambda *a: None)
    refused = _located(scene, 4, 0.01)[1]
    assert not refused.ok
    assert refused.reason == "inconsistent"
    assert "settle" in refused.detail


def test_only_a_two_choice_cycle_of_converged_bracketing_adjustments_is_mixed() -> None:
    # _alternate's guards, on stand-ins for the adjustments: the rays chosen at the
    # last pose must be the first's, both choices must bracket, differ and have
    # converged.
    a_tops, b_tops = [(0, 1, 2)], [(0, 3, 4)]
    planes = PanelPlanes.of(paper_walls("parallel")[1].survey)

    def solved(tops: list[tuple[int, int, int]], iterations: int = 3) -> Any:
        return SimpleNamespace(x=np.zeros(6), tops=tops, iterations=iterations)

    back = lambda tops: lambda x: tops  # noqa: E731 - the rays chosen at any pose
    alternate = adjust3d._alternate
    assert alternate(solved(b_tops), None, 20, planes, back(a_tops)) is None
    assert alternate(solved(a_tops), solved(a_tops), 20, planes, back(a_tops)) is None
    assert alternate(solved(b_tops), solved([]), 20, planes, back([])) is None
    assert alternate(solved([]), solved(a_tops), 20, planes, back(a_tops)) is None
    assert alternate(solved(b_tops), solved(a_tops, 20), 20, planes, back(a_tops)) is None
    assert alternate(solved(b_tops, 20), solved(a_tops), 20, planes, back(a_tops)) is None
    assert alternate(solved(b_tops), solved(a_tops), 20, planes, back(b_tops)) is None


def test_a_fix_is_given_with_its_tilts_own_sigma_up_to_a_degree(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 3 cm frame of fresh draws (seed 3, drift 2, frame 0): its panels hold the
    # roll to 0.67 deg. It is given, its position and azimuth right within their sigmas
    # and its roll's sigma saying how loose it is; at the former limit, 0.6 deg, it was
    # refused.
    scene = random_drift_scene(3, 2, frames=10, lidar="vlp16", range_sigma_m=0.03)
    sim, fix = _located(scene, 0, 0.03)
    _within(fix, sim, 3.0)
    assert fix.adjustment is not None
    tilt = math.degrees(locator3d._tilt_sigma(fix.adjustment))
    assert 0.6 < tilt <= locator3d.MAX_TILT_SIGMA_DEG
    monkeypatch.setattr(locator3d, "MAX_TILT_SIGMA_DEG", 0.6)
    refused = _located(scene, 0, 0.03)[1]
    assert refused.reason == "degenerate_geometry"
    assert "hold the tilt to 0.67 deg only" in refused.detail


def test_a_one_beacon_start_made_already_is_not_run_again(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 2 cm frame (seed 0, drift 6, frame 1): two tries' plan views confirm the
    # same beacon within a few millimetres, with the same vertical. The 3D stages from
    # the second are not run again (SAME_START_M): their result is the first's, handed
    # on with the second try's plan view, and confirmed in its band.
    scene = random_drift_scene(0, 6, frames=10, lidar="vlp16", range_sigma_m=0.02)
    runs: list[Pose2D] = []
    handed: list[tuple[Fix, Fix3D | None]] = []
    fix3d, from_one = locator3d._fix3d, locator3d._from_one_beacon

    def counted(*a: Any, one_beacon: Pose2D | None = None, **k: Any) -> Fix3D:
        if one_beacon is not None:
            runs.append(one_beacon)
        return fix3d(*a, one_beacon=one_beacon, **k)

    def recorded(frame: Frame3D, survey: Survey, planes: PanelPlanes, plan: Fix,
                 *a: Any, **k: Any) -> Fix3D:  # fmt: skip
        handed.append((plan, k.get("first")))
        return from_one(frame, survey, planes, plan, *a, **k)

    monkeypatch.setattr(locator3d, "_fix3d", counted)
    monkeypatch.setattr(locator3d, "_from_one_beacon", recorded)
    sim, fix = _located(scene, 1, 0.02)
    _within(fix, sim, 3.0)
    assert len(handed) == 2
    assert len(runs) == 1  # the second start's 3D stages were the first's
    for plan, first in handed:  # each handed on with its own try's plan view
        assert first is not None
        assert first.plan is plan
    monkeypatch.setattr(locator3d, "SAME_START_M", -1.0)
    runs.clear()
    _, again = _located(scene, 1, 0.02)
    _within(again, sim, 3.0)
    assert len(runs) == 2


def test_wall_returns_above_rays_passing_over_a_panel_do_not_set_its_top() -> None:
    # A VLP-16 3 cm frame of fresh draws (seed 1, drift 2, frame 7), its 3D stages
    # started from the true plan pose and vertical. B5's middle panel, 2.6 m off, stands
    # close to its wall: rings 13 to 15 pass over it to the wall, and put 2, 1 and 2
    # returns within the hit gate of its plane, 0.08 to 0.31 m above its top (ring 12,
    # the top's own, put 42 on it, and passes over it too). Its highest hit was ring
    # 15's, bracketed by ring 15's own returns: the elevation a ring off (0.28 m at 41
    # sigma), which the beam test refused. Split where the fewest of the panel's hits
    # and crossings over contradict it, the top is bracketed by ring 12's hit and its
    # crossing over: the five wall returns are outvoted by rings 12 to 14's crossings.
    scene = random_drift_scene(1, 2, frames=10, lidar="vlp16", range_sigma_m=0.03)
    sim = scene.simulate(7)
    cfg = Locator3DConfig(range_sigma_m=0.03, survey_sigma_m=0.0)
    up = np.asarray(sim.pose.rotation[2])
    plan_cfg = LocatorConfig(range_sigma_m=0.03, survey_sigma_m=0.0)
    plan = locate(locator3d._plan_view(sim.frame, up, (-1.0, 0.5), cfg), scene.survey,
                  config=plan_cfg)  # fmt: skip
    start = Pose2D(sim.pose.easting, sim.pose.northing, sim.pose.azimuth)
    planes = PanelPlanes.of(scene.survey)
    fix = locator3d._fix3d(sim.frame, planes, plan, up, cfg, one_beacon=start)
    _within(fix, sim, 3.0)
    assert fix.adjustment is not None
    assert fix.adjustment.top_edges >= 2


def _starts_seen(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, ...]]:
    """The beacons each start of the 3D stages without a plan view's 2D fix must show
    (:func:`locator3d._from_one_beacon`), in turn, as the locator runs."""
    starts: list[tuple[str, ...]] = []
    from_one = locator3d._from_one_beacon

    def counted(frame: Frame3D, survey: Survey, planes: PanelPlanes, plan: Fix, start: Pose2D,
                seen: tuple[str, ...], *a: Any, **k: Any) -> Fix3D:  # fmt: skip
        starts.append(seen)
        return from_one(frame, survey, planes, plan, start, seen, *a, **k)

    monkeypatch.setattr(locator3d, "_from_one_beacon", counted)
    return starts


def test_one_beacon_starts_reach_the_try_whose_beacon_is_the_true_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 1 cm frame of fresh draws (seed 1, drift 2, frame 7): its beacons share
    # a design, and the first tries' plan views confirm one beacon only, each taking it
    # for another beacon (B2, 24 m off). A later try's confirms the true one (B5), from
    # which the 3D stages find the second beacon. Two starts, as before 2026-12-07 (the
    # next session), stop short of it.
    scene = random_drift_scene(1, 2, frames=10, lidar="vlp16", range_sigma_m=0.01)
    starts = _starts_seen(monkeypatch)
    monkeypatch.setattr(locator3d, "LENIENT_STARTS", 0)  # the one-beacon starts alone,
    monkeypatch.setattr(locator3d, "OWN_TILT_SIGMA_DEG", -1.0)  # from the plan views
    sim, fix = _located(scene, 7, 0.01)
    _within(fix, sim, 3.0)
    assert starts == [("B2",), ("B2",), ("B5",)]
    assert set(fix.beacons) == {"B4", "B5"}
    assert fix.plan.ok  # the plan view located again from the 3D pose agrees
    monkeypatch.setattr(locator3d, "ONE_BEACON_STARTS", 2)
    starts.clear()
    _, refused = _located(scene, 7, 0.01)
    assert not refused.ok
    assert starts == [("B2",), ("B2",)]


def test_a_plan_view_that_sees_a_beacon_on_its_own_wall_starts_a_fix_leniently(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 1 cm frame of fresh draws with look-alikes (seed 2, drift 0, frame 1):
    # no try's plan view confirms two beacons, for beams over or under a beacon onto the
    # wall it stands on, which the plan view takes for beams through its panels. Located
    # again with those beams no verdict (LENIENT_WALL_M), a plan view's 2D fix starts
    # the 3D stages, whose fix the plan view levelled by it and each beacon in the band
    # of its tops confirms.
    scene = random_drift_scene(2, 0, frames=10, lidar="vlp16", range_sigma_m=0.01, lookalikes=True)
    starts = _starts_seen(monkeypatch)
    sim, fix = _located(scene, 1, 0.01)
    _within(fix, sim, 3.0)
    assert len(starts[-1]) >= 2  # the last start was a lenient plan view's 2D fix
    assert fix.plan.ok  # the plan view located again from the 3D pose agrees
    monkeypatch.setattr(locator3d, "LENIENT_STARTS", 0)
    _, refused = _located(scene, 1, 0.01)
    assert not refused.ok


def test_a_move_is_infinite_where_its_variance_is_not_positive() -> None:
    # near-singular normal equations can give a covariance with a variance not positive
    # (the fix is refused for it); the move there is not a number of sigmas, and says so
    # without numpy's warning of a square root of a negative
    before = Pose3D.from_degrees(10.0, 20.0, 1.5, 30.0, 1.0, -2.0)
    after = Pose3D.from_degrees(10.01, 20.0, 1.5, 30.0, 1.0, -2.0)
    cov = np.diag([1e-4, 1e-4, -1e-6, 1e-6, 1e-6, 0.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        moved = _moved(before, after, cov)
    assert moved[0] == pytest.approx(1.0)
    assert moved[2] == math.inf
    assert moved[5] == math.inf
    assert moved[1] == 0.0


def test_a_panel_is_one_run_of_heights() -> None:
    walls, scene = paper_walls("parallel")
    planes = PanelPlanes.of(scene.survey)
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0)
    frame = cast(truth, walls, 0.005, 0)
    grid = truth.sensor_to_grid(frame.points)
    which = planes.assign(grid, truth.position, 0.02)
    k = int(np.bincount(which[which >= 0]).argmax())
    # a return of the roof, 2 m above the panel, within the gate of its plane
    on = np.flatnonzero(which == k)
    far = grid[on[0]] + np.array([0.0, 0.0, 2.0])
    grid2 = np.vstack([grid, far])
    which2 = np.append(which, k)
    kept = _contiguous(which2, grid2, truth.position, planes, math.radians(2.0))
    assert kept[-1] == -1
    assert np.array_equal(kept[:-1], which)


def test_a_lone_stray_return_on_a_panel_does_not_set_the_start_elevation() -> None:
    # A beacon's three panels hit up to 10 cm under their tops, no ray over them: each
    # bracket is open below (Z <= top - highest hit), and all three say the sensor is at
    # most 10 cm above its true elevation. Two returns on a panel of the other beacon,
    # 2.9 m above its top (the roof, within the gate of its plane), open a fourth that
    # every elevation under it meets with the three: they alone must not set the start.
    _, scene = paper_walls("parallel")  # the first beacon: panels 0-2, the second 3-5
    planes = PanelPlanes.of(scene.survey)
    z_true = float(planes.top[1]) - 0.6  # the sensor 0.6 m below the first beacon's tops
    middle = planes.start[1] + 0.5 * planes.length[1] * planes.along[1]
    assert planes.front[1] != 0.0
    origin = np.array([*(middle + 2.5 * planes.front[1] * planes.normal[1]), 0.0])  # facing it
    points, which = [], []
    for k in range(3):
        for share in (0.3, 0.5, 0.7):
            xy = planes.start[k] + share * planes.length[k] * planes.along[k]
            for below in (0.1, 0.2, 0.3):  # grid heights: the sensor at elevation 0
                points.append([*xy, planes.top[k] - below - z_true])
                which.append(k)
    for share in (0.4, 0.6):
        stray = planes.start[3] + share * planes.length[3] * planes.along[3]
        points.append([*stray, planes.top[3] + 2.9 - z_true])
        which.append(3)
    grid, hits = np.array(points), np.array(which)
    local = planes.local(grid, NEAR_M)
    args = (grid, origin, hits, planes, 0.05, math.radians(2.0), local)
    start = _start_elevation(*args, least=START_HITS)
    assert start is not None
    assert -0.3 < start[0] - z_true <= 0.1
    for least in (1, START_HITS - 1):  # the strays' bracket counted: it wins
        alone = _start_elevation(*args, least=least)
        assert alone is not None
        assert alone[0] - z_true < -2.5


def test_the_3d_stages_start_from_panels_with_enough_tight_hits(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    walls, scene = paper_walls("parallel")
    frame = cast(Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0), walls, 0.01, 0)
    seen: list[int] = []
    real = locator3d._start_elevation

    def recorded(*a: Any, least: int = 1, **k: Any) -> Any:
        seen.append(least)
        return real(*a, least=least, **k)

    monkeypatch.setattr(locator3d, "_start_elevation", recorded)
    fix = locate3d(frame, scene.survey, config=Locator3DConfig(range_sigma_m=0.01))
    assert fix.ok, fix.detail
    assert set(seen) == {START_HITS}


def test_the_compiled_runs_of_heights_and_floors_agree_with_their_numpy_references() -> None:
    # A panel's run of heights, with gaps cut into it above and below its median, and
    # each panel's floor, compiled and in numpy: the same returns, the same floors.
    from mast.pipeline.locator3d import _contiguous_reference

    scene = random_drift_scene(3, frames=4, lidar="vlp16", range_sigma_m=0.02)
    planes = PanelPlanes.of(scene.survey)
    rng = np.random.default_rng(4)
    floors = cut = 0
    for i in range(4):
        sim = scene.simulate(i)
        pose = sim.pose
        grid = pose.sensor_to_grid(sim.frame.points)
        which = planes.assign(grid, pose.position, 0.08)
        # holes in some panels' runs: their returns in a band of heights left out
        z = grid[:, 2]
        for k in np.unique(which[which >= 0]):
            on = np.flatnonzero(which == k)
            lo = float(rng.uniform(z[on].min(), z[on].max()))
            which[on[(z[on] > lo) & (z[on] < lo + 0.3)]] = -1
        rays = planes._rays(grid - pose.position, pose.position, planes.local(grid, 1.0))
        rays, j = planes._own(rays, which)
        k, at = rays.k[j], rays.i[j]
        h = rays.s[j] * rays.rel[at, 2]
        for spacing in (math.radians(0.5), math.radians(2.0)):
            got = contiguous3d(k, at, h, rays.reach, len(planes), spacing)
            want = _contiguous_reference(k, at, h, rays.reach, len(planes), spacing)
            np.testing.assert_array_equal(got, want)
            kept = _contiguous(which, grid, pose.position, planes, spacing, rays)
            np.testing.assert_array_equal(kept[at[got]], -1)
            cut += int(np.count_nonzero(got))
        about = planes.local(grid, 1.5)
        flat = np.concatenate(about)
        first = np.cumsum([0] + [len(idx) for idx in about], dtype=np.intp)
        got_floors = floors3d(
            sim.frame.points, pose.rotation, pose.position, flat, first, planes.wall,
            planes.front, planes.depth + FLOOR_PAST_M,
        )  # fmt: skip
        want_floors = planes.floors(grid, about)
        np.testing.assert_allclose(got_floors, want_floors, rtol=0, atol=1e-12)
        floors += int(np.count_nonzero(np.isfinite(want_floors)))
    assert cut > 0
    assert floors > 0


def test_a_panel_is_cut_below_its_beacons_other_panels_lowest_hits() -> None:
    # A beacon is one plate: its panels' bottoms are as far below their tops. A ring
    # under the other panels' lowest hits by more than a ring and a half at the range
    # (and a slack for their lower parts hidden) would have crossed them too: below that
    # a return on a panel is the floor's.
    _, scene = paper_walls("parallel")
    planes = PanelPlanes.of(scene.survey)
    origin = np.array([7.0, 7.0, 1.2])
    spacing = math.radians(2.0)
    assert len(planes) == 6
    lows = planes.top - 0.6  # every panel seen 0.6 m down
    lows[2] = planes.top[2] - 2.4  # the first beacon's end panel: the floor at its foot
    lows[4:] = np.nan  # the second beacon seen on its first panel only
    floor = _plate_floors(planes, lows, origin, spacing)
    middle = planes.start + planes.along * (0.5 * planes.length)[:, None]
    gap = PLATE_RINGS * spacing * np.hypot(*(middle - origin[:2]).T) + PLATE_SLACK_M
    # the end panel cut 0.6 m down and the gap more, the floor at 2.4 m out
    assert floor[2] == pytest.approx(planes.top[2] - 0.6 - gap[2])
    assert floor[2] > lows[2]
    # its neighbours by the deepest of the others: the end panel's floor (permissive)
    assert floor[0] == pytest.approx(planes.top[0] - 2.4 - gap[0])
    assert floor[1] == pytest.approx(planes.top[1] - 2.4 - gap[1])
    # the second beacon's unseen panels by its first; the first by none
    assert np.isnan(floor[3])
    assert floor[4:] == pytest.approx(planes.top[4:] - 0.6 - gap[4:])


def test_a_return_near_a_free_end_is_kept_on_a_ring_its_beacon_shows_clear_of_it() -> None:
    _, scene = paper_walls("parallel")  # two beacons: panels 0-2 and 3-5
    planes = PanelPlanes.of(scene.survey)
    lines = np.array([5, 5, 5, 5, 6, 6, 7, 7, 7, 7, 7])
    which = np.array([1, 1, 1, -1, 1, -1, 4, 4, 4, -1, -1])  # cut clear of the free ends
    nearer = np.array([1, 1, 1, 0, 1, 0, 4, 4, 4, 3, 2])  # cut nearer them
    # each return on the middle of the panel it is given (or the first beacon's P1)
    k = np.where(which >= 0, which, 0)
    grid = planes.start[k] + 0.5 * planes.length[k, None] * planes.along[k]
    gate = 0.04
    kept, same = _witnessed(which, (nearer, which), grid, lines, planes, 3, gate)
    # ring 5 crosses the first beacon at three returns clear of its ends: its return by
    # the free end is P1's; ring 6 puts one there only (the wall above or below the
    # beacon, at that height, may be all it is); ring 7 crosses the second beacon only
    assert kept.tolist() == [1, 1, 1, 0, 1, -1, 4, 4, 4, 3, -1]
    assert same.tolist() == which.tolist()
    # each of several cuts nearer the ends is given what it is given alone
    nearest = np.array([1, 1, 1, 0, 1, 0, 4, 4, 4, 5, 2])  # ring 7's second return on P3
    both = _witnessed(which, (nearer, nearest), grid, lines, planes, 3, gate)
    for given, alone in zip(both, (nearer, nearest), strict=True):
        assert (
            given.tolist() == _witnessed(which, (alone,), grid, lines, planes, 3, gate)[0].tolist()
        )
    assert both[1].tolist() == [1, 1, 1, 0, 1, -1, 4, 4, 4, 5, -1]
    # the wall a beacon stands on is no witness: returns within the gate and the rock's
    # bulge of it do not count one by one (the paper's middle panels stand 0.2 m out),
    # nor three as a mean from the chord (1.5 gates over root 3 is more than 0.2 m less
    # the bulge)
    assert _witnessed(which, (nearer,), grid, lines, planes, 3, 0.2)[0].tolist() == which.tolist()


def test_a_shallow_middle_panel_witnesses_its_ring_by_its_mean_off_the_wall_the_ring_shows(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    _, scene = paper_walls("parallel")  # the first beacon: panels 0-2, its middle 0.2 m out
    planes = PanelPlanes.of(scene.survey)
    e1 = planes.start[0]
    e4 = planes.start[2] + planes.length[2] * planes.along[2]
    chord = (e4 - e1) / np.linalg.norm(e4 - e1)
    out = planes.front[0] * planes.wall[0, :2]  # from the wall out to the drift
    middle = planes.start[1] + np.outer(
        np.linspace(0.2, 0.8, 8) * planes.length[1], planes.along[1]
    )
    past = np.vstack([e1 - np.outer([0.05, 0.1, 0.15], chord), e4 + np.outer([0.05, 0.1], chord)])
    end = planes.start[0] + 0.1 * planes.length[0] * planes.along[0]  # by P1's free end
    grid = np.vstack([middle, past, end[None]])
    lines = np.full(len(grid), 5)
    which = np.r_[np.full(8, 1), np.full(5, -1), -1]
    nearer = np.r_[np.full(8, 1), np.full(5, -1), 0]
    gate = 0.2  # each middle return within the gate and the rock's bulge of the wall
    assert _witnessed(which, (nearer,), grid, lines, planes, 3, gate)[0][-1] == 0
    # a pose off across the wall by the panel's depth: the wall the middle panel is put
    # on, and the wall past the ends, stand off the chord alike, and witness nothing
    moved = grid.copy()
    moved[8:13] += 0.2 * out
    assert _witnessed(which, (nearer,), moved, lines, planes, 3, gate)[0][-1] == -1
    # with no wall shown past the ends, the chord is the wall
    alone = np.r_[np.arange(8), 13]
    (kept,) = _witnessed(which[alone], (nearer[alone],), grid[alone], lines[alone], planes, 3, gate)
    assert kept[-1] == 0
    # a gate widened for the tilt's error: the wall the ring shows moves with the tilt as
    # its returns do, and the range noise's gate holds; the chord does not move
    assert _witnessed(which, (nearer,), grid, lines, planes, 3, 2 * gate, gate)[0][-1] == 0
    args = (which[alone], (nearer[alone],), grid[alone], lines[alone], planes, 3, 2 * gate, gate)
    assert _witnessed(*args)[0][-1] == -1
    # three returns on the middle panel, 0.2 m out: from the wall the ring shows, the bar
    # is the bulge and one gate over root 3 (2.5 sigmas of the difference), 0.18 m at a
    # gate of 0.22 m; from the chord, 1.5 gates (0.24 m), as it was from the wall too
    few = np.r_[np.arange(3), np.arange(8, 14)]
    args = (which[few], (nearer[few],), grid[few], lines[few], planes, 3, 0.22)
    assert _witnessed(*args)[0][-1] == 0
    chord = np.r_[np.arange(3), 13]
    args_chord = (which[chord], (nearer[chord],), grid[chord], lines[chord], planes, 3, 0.22)
    assert _witnessed(*args_chord)[0][-1] == -1
    monkeypatch.setattr(locator3d, "WITNESS_WALL_GATES", locator3d.WITNESS_MEAN_GATES)
    assert _witnessed(*args)[0][-1] == -1


def test_a_shallow_beacons_rings_are_witnessed_by_the_wall_they_show(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Seed 1, VLP-16 at 3 cm with look-alikes, drift 1 frame 3: B4, 10.6 m off, stands
    # 0.128 m off its wall; two rings cross its middle and end panels. Its rings' returns
    # stand off the wall they show past its free ends by more than the rock's bulge and
    # one gate over the root of their count, not 1.5: witnessed, they give the end panel
    # its returns nearer its free end, and the frame is fixed on B4 and B5.
    scene = random_drift_scene(1, 1, frames=10, lidar="vlp16", range_sigma_m=0.03, lookalikes=True)
    sim, fix = _located(scene, 3, 0.03)
    _within(fix, sim, 3.0)
    assert fix.beacons == ("B4", "B5")
    monkeypatch.setattr(locator3d, "WITNESS_WALL_GATES", locator3d.WITNESS_MEAN_GATES)
    _, fix = _located(scene, 3, 0.03)
    assert not fix.ok


def test_a_far_beacons_end_panel_is_shown_by_its_returns_nearer_its_free_end(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # An OS1-64 2 cm frame of fresh draws (seed 1, drift 1, frame 1): the second beacon,
    # B4, 10 m off, is crossed by rings of three returns on its end panel P3. Cut clear
    # of its free end, the panel keeps two a ring, and the frame was refused as one
    # beacon; the returns nearer the end show it, and the fix adjusted on the others
    # is within 3 sigma.
    scene = random_drift_scene(1, 1, frames=10, lidar="os1-64", range_sigma_m=0.02)
    sim, fix = _located(scene, 1, 0.02)
    _within(fix, sim, 3.0)
    assert set(fix.beacons) == {"B4", "B5"}
    assert fix.panels["B4"] == (2, 3)
    monkeypatch.setattr(locator3d, "SHOWN_CLEAR", locator3d.WITNESSED_CLEAR)
    _, refused = _located(scene, 1, 0.02)
    assert refused.reason == "one_beacon"


def test_the_wall_below_a_shallow_panel_opens_no_beam_test_window(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 3 cm frame of fresh draws (seed 2, drift 3, frame 2): B2's middle panel,
    # 0.29 m wide, stands off its wall by less than the gate. Its five lowest rings put
    # 16 returns of the wall below it on it (4.5 cm behind it on average), and the
    # rays of those rings that the noise took beyond the gate, 107, were misfits of a
    # fix 0.6 sigma off. Those rings stand behind the panel and open no window.
    scene = random_drift_scene(2, 3, frames=10, lidar="vlp16", range_sigma_m=0.03)
    sim, fix = _located(scene, 2, 0.03)
    _within(fix, sim, 3.0)
    monkeypatch.setattr(adjust3d, "BEHIND_GATES", math.inf)  # no line stands behind
    _, refused = _located(scene, 2, 0.03)
    assert refused.reason == "inconsistent"
    assert "B2/P2" in refused.detail
    assert "do not fit it" in refused.detail


def test_one_beacons_panels_move_a_growth_stages_pose_where_they_hold_the_tilt() -> None:
    walls, scene = paper_walls("convergent")
    planes = PanelPlanes.of(scene.survey)
    truth = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, 3.0, -2.0)
    frame = cast(truth, walls, 0.005, 0)
    which = planes.assign(truth.sensor_to_grid(frame.points), truth.position, 0.02)
    first = np.where(which < 3, which, -1)  # the first beacon's three panels only
    off = replace(truth, pitch=truth.pitch + math.radians(2.0), elevation=1.5)
    prior = (off.pitch, off.roll, math.radians(5.0))
    moved = _on_one_beacon(frame.points, first, planes, off, prior, 0.005, 0.0, 0.02)
    assert abs(math.degrees(moved.pitch - truth.pitch)) < 0.2
    assert abs(math.degrees(moved.roll - truth.roll)) < 0.2
    assert moved.elevation == 1.5  # held
    # one panel alone leaves a tilt to the walls' loose vertical: the pose stays
    panel = int(np.bincount(first[first >= 0]).argmax())
    one = np.where(which == panel, which, -1)
    assert _on_one_beacon(frame.points, one, planes, off, prior, 0.005, 0.0, 0.02) == off


def test_a_survey_without_elevations_is_refused_for_a_3d_frame() -> None:
    walls, scene = paper_walls("parallel")
    flat = Survey([replace(b, elevations=None) for b in scene.survey])
    frame = cast(Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0), walls, 0.01, 0)
    with pytest.raises(InputError, match="needs the survey's elevations"):
        locate3d(frame, flat)


def test_a_panels_lone_return_is_left_out_of_the_adjustment() -> None:
    which = np.array([0, 0, -1, 1, 2, 2, 2, -1, 4])
    planes = PanelPlanes.of(paper_walls("parallel")[1].survey)  # two beacons, six panels
    assert locator3d.MIN_PANEL_RETURNS == 2
    assert _checked(which, planes).tolist() == [0, 0, -1, -1, 2, 2, 2, -1, -1]
    assert _checked(np.full(3, -1), planes).tolist() == [-1, -1, -1]


def test_a_far_beacons_lone_return_does_not_lever_the_fix(
    bin_centre_plan: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A far beacon's middle-panel return just past the joint, taken for its end panel
    # (the panel's only return), held the azimuth 7.3 sigma off (0.15 deg at 0.02) and
    # the roll 4.1 sigma (1.3 deg): nothing else of that panel could check it. Since the
    # panel rows are range residuals (their derivatives through the incidence), the same
    # return adjusted on no longer levers this frame's fix; a panel's lone return is
    # still not adjusted on (MIN_PANEL_RETURNS), and either way the fix is within 3.5 sigma.
    scene = random_drift_scene(3000, 1, frames=10, lidar="os1-64", range_sigma_m=0.03)
    sim = scene.simulate(3)

    def z() -> NDArray[np.float64]:
        fix = locate3d(sim.frame, scene.survey, config=Locator3DConfig(range_sigma_m=0.03))
        assert fix.ok, fix.detail
        assert fix.pose is not None
        assert fix.adjustment is not None
        return np.abs(fix.pose.minus(sim.pose)) / np.sqrt(np.diag(fix.adjustment.covariance))

    assert z().max() < 3.5
    monkeypatch.setattr(locator3d, "MIN_PANEL_RETURNS", 1)  # the lone return adjusted on
    assert z().max() < 3.5


@pytest.mark.parametrize(
    ("lidar", "lookalikes", "index"), [("os1-64", False, 9), ("vlp16", True, 4)]
)
def test_returns_above_their_panels_tops_refuse_the_fix(
    bin_centre_plan: None, monkeypatch: pytest.MonkeyPatch, lidar: str, lookalikes: bool, index: int
) -> None:
    # Two frames whose fix took returns 2.2 m above a panel's top (the OS1-64's, 1.45 deg
    # off in roll at 8 sigma) and 1 m above (the VLP-16's, its pitch 9.4 deg off at 26
    # sigma: the vehicle tilted 13 deg, and a tilt within the drift's walls moves each
    # panel within its own plane). Their panels' tops refuse them. The returns that
    # show a panel are those it is adjusted on, as when these frames were found (nearer
    # a free end, the OS1-64's is refused as one beacon by another flow), and the tilt's
    # limit is 0.6 deg, as then (at 1 deg, without the tops test, the VLP-16's is fixed
    # right at a try before the one that gave the wrong fix).
    monkeypatch.setattr(locator3d, "SHOWN_CLEAR", locator3d.WITNESSED_CLEAR)
    monkeypatch.setattr(locator3d, "MAX_TILT_SIGMA_DEG", 0.6)
    scene = random_drift_scene(
        3000, 0, frames=10, lidar=lidar, range_sigma_m=0.03, lookalikes=lookalikes
    )
    sim = scene.simulate(index)
    cfg = Locator3DConfig(range_sigma_m=0.03)
    fix = locate3d(sim.frame, scene.survey, config=cfg)
    if fix.ok:
        _within(fix, sim)
    monkeypatch.setattr(locator3d, "TOP_SIGMAS", math.inf)  # no return too high
    wrong = locate3d(sim.frame, scene.survey, config=cfg)
    assert wrong.ok
    assert wrong.pose is not None
    assert wrong.adjustment is not None
    z = np.abs(wrong.pose.minus(sim.pose)) / np.sqrt(np.diag(wrong.adjustment.covariance))
    assert z.max() > 5.0


def _off_plan_refused(*args: Any) -> Fix3D:
    # _confirmed in its place: every fix whose plan view puts it elsewhere is refused
    return _refused_off_plan(args[3])


@pytest.mark.parametrize(
    ("lidar", "drift", "index", "name", "off", "refusal"),
    [
        # A VLP-16: the first plan view, seen with a vertical degrees off, put the
        # position 83 mm from the 3D fix. Levelled by the 3D pose and located near it,
        # the plan view agrees, and so does the 3D fix it starts.
        ("vlp16", 6, 1, "_confirmed", _off_plan_refused, ("inconsistent", "plan view")),
        # An OS1-64: the first plan view 100 mm off; levelled by the 3D fix, it confirms
        # one of its beacons alone near it, the other smeared out of its band. The fix
        # stands on its own tests, its tilt held as a one-beacon start's must be. (Refused,
        # the frame's reason is a later try's, which shows one beacon.)
        ("os1-64", 6, 1, "ALONE_TILT_SIGMA_DEG", 0.0, ("one_beacon", "1 beacon(s)")),
        # An OS1-64: one ring crosses a near beacon's middle panel within a few
        # millimetres of its top, some of its beams on the panel and some over it; 17 of
        # them, counted against the pose, refused it.
        ("os1-64", 1, 6, "_under_tops", lambda *a: None, ("inconsistent", "do not fit it")),
    ],
)
def test_right_fixes_are_not_refused_for_their_plan_view_or_their_panels_tops(
    bin_centre_plan: None,
    two_refined_bands: None,
    request: pytest.FixtureRequest,
    monkeypatch: pytest.MonkeyPatch,
    lidar: str,
    drift: int,
    index: int,
    name: str,
    off: object,
    refusal: tuple[str, str],
) -> None:
    # Each at 3 cm, a fix right to millimetres that the stage ``name`` now lets stand:
    # with ``off`` in its place, it is refused (``refusal``: the reason and its words),
    # where no one-beacon start is made again from its beacon's own panels (the VLP-16's
    # is fixed so, within 1.5 sigma).
    # The one-beacon fix that stands alone is the plan view's, located again as before
    # 2026-12-07's seventh session: it now confirms both beacons (strict_plan_again);
    # and with the tilt's limit at 1 deg rather than 0.6, another try fixes the frame.
    if name == "ALONE_TILT_SIGMA_DEG":
        request.getfixturevalue("strict_plan_again")
        monkeypatch.setattr(locator3d, "MAX_TILT_SIGMA_DEG", 0.6)
    scene = random_drift_scene(0, drift, frames=10, lidar=lidar, range_sigma_m=0.03)
    sim, fix = _located(scene, index, 0.03)
    err = _within(fix, sim, 3.0)
    assert np.hypot(err[0], err[1]) < 0.01
    monkeypatch.setattr(locator3d, name, off)
    monkeypatch.setattr(locator3d, "OWN_TILT_SIGMA_DEG", -1.0)
    refused = _located(scene, index, 0.03)[1]
    assert not refused.ok
    assert refused.reason == refusal[0]
    assert refusal[1] in refused.detail


def _highest_hit_tops(  # type: ignore[no-untyped-def]
    p, which, planes, x, gate_m, skip=frozenset(), panels=None, pairs=None
) -> list[tuple[int, int, int]]:
    """``adjust3d._chosen_tops`` as it was before 2026-12-07 (the next session): each
    panel's highest hit, and the lowest crossing over above it."""
    R = rotation_rpy(x[4], x[3], math.pi / 2 - x[2])
    origin, rel = np.array([x[0], x[1], x[5]]), p @ R.T
    grid = rel + origin
    rays = planes._rays(rel, origin, pairs or planes._pairs(planes._everywhere(len(p))))
    own, j = planes._own(rays, which)
    inset, lo, hi = adjust3d._top_extents(planes, gate_m)
    n, d = planes.normal, planes.offset
    k, i, t = own.k[j], own.i[j], own.t[j]
    across = grid[i, 0] * n[k, 0] + grid[i, 1] * n[k, 1] - d[k]
    close = (np.abs(across) <= adjust3d.HIT_SHARE * gate_m) & (t > lo[k]) & (t < hi[k])
    close &= np.isfinite(planes.top[k])
    hit, ray_of = np.full(len(planes), math.inf), np.full(len(planes), -1)
    for c in np.flatnonzero(close)[np.lexsort((i[close], -(own.s[j] * rel[i, 2])[close]))]:
        if ray_of[k[c]] < 0:
            hit[k[c]], ray_of[k[c]] = own.s[j[c]] * rel[i[c], 2], i[c]
    side = origin[0] * n[:, 0] + origin[1] * n[:, 1] - d
    low, over_of = np.full(len(planes), math.inf), np.full(len(planes), -1)
    for k, i, s, t in zip(rays.k, rays.i, rays.s, rays.t, strict=True):
        across = grid[i, 0] * n[k, 0] + grid[i, 1] * n[k, 1] - d[k]
        h = s * rel[i, 2]
        if (0 < s < 1 and inset[k] < t < planes.length[k] - inset[k] and across * side[k] < 0
                and abs(across) >= gate_m and hit[k] < h < low[k]):  # fmt: skip
            low[k], over_of[k] = h, i
    return [
        (k, int(ray_of[k]), int(over_of[k]))
        for k in range(len(planes))
        if over_of[k] >= 0 and planes.beacon[k] not in skip and (panels is None or k in panels)
    ]


def test_the_beam_test_keeps_the_rays_just_under_a_panels_top(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A VLP-16 at 2 cm whose adjustment, each top bracketed by its highest hit as before
    # 2026-12-07 (the adjustment's choice, _chosen_tops, replicated; the start
    # elevation's brackets are the new rule's), put the elevation 116 mm off at 9 sigma:
    # six beams crossing a panel within 4 cm under its top, where the pose puts it,
    # passed through it. The beam test's window ends at the top, not below it.
    # (Bracketed where the fewest hits and crossings contradict a top, the frame is
    # fixed within its sigmas.)
    scene = random_drift_scene(3000, 3, frames=10, lidar="vlp16", range_sigma_m=0.02)
    sim = scene.simulate(2)
    cfg = Locator3DConfig(range_sigma_m=0.02)
    _within(locate3d(sim.frame, scene.survey, config=cfg), sim, 3.0)
    monkeypatch.setattr(adjust3d, "_chosen_tops", _highest_hit_tops)
    refused = locate3d(sim.frame, scene.survey, config=cfg)
    assert not refused.ok
    assert "do not fit it" in refused.detail
    monkeypatch.setattr(
        locator3d, "_under_tops", lambda planes, adj: planes.top - 0.04 if adj.top_edges else None
    )
    wrong = locate3d(sim.frame, scene.survey, config=cfg)
    assert wrong.pose is not None
    assert wrong.adjustment is not None
    z = np.abs(wrong.pose.minus(sim.pose)) / np.sqrt(np.diag(wrong.adjustment.covariance))
    assert z.max() > 5.0


def test_a_beacon_at_the_lowest_rings_is_not_its_own_floor(monkeypatch: pytest.MonkeyPatch) -> None:
    # A VLP-16 pitched 13 deg: its lowest ring crosses B2 12 cm above the sensor, 33 cm
    # below the beacon's top, on the panels and the wall beside them. The panels stand
    # out from the wall, so those lowest returns spread 0.4 m across it, as a floor
    # would; but they reach no further out than the panels. B3's floor, 2 m below, is
    # the floor's, and reaches out into the drift.
    scene = random_drift_scene(
        3000, 0, frames=10, lidar="vlp16", range_sigma_m=0.03, lookalikes=True
    )
    sim = scene.simulate(4)
    planes = PanelPlanes.of(scene.survey)
    grid = sim.pose.sensor_to_grid(sim.frame.points)
    about = planes.local(grid, locator3d.FLOOR_RADIUS_M)
    b2 = [k for k in range(len(planes)) if planes.beacon[k] == "B2"]
    b3 = [k for k in range(len(planes)) if planes.beacon[k] == "B3"]
    floors = planes.floors(grid, about) - sim.pose.elevation
    assert np.all(np.isnan(floors[b2]))
    truth = [float(scene.drift.floor_at(planes.start[k])[0]) - sim.pose.elevation for k in b3]
    np.testing.assert_allclose(floors[b3], truth, atol=0.15)
    # not vacuous: wherever they reach, B2's own panels pass for its floor, within
    # 0.4 m of its top
    monkeypatch.setattr(adjust3d, "FLOOR_PAST_M", -math.inf)
    taken = planes.floors(grid, about)
    assert np.all(planes.top[b2] - taken[b2] < 0.4)


@pytest.mark.parametrize(("seed", "index"), [(4, 3), (6, 0), (7, 2), (0, 3)])
def test_hard_64_ring_frames_are_fixed_within_their_covariance_or_refused(
    seed: int, index: int
) -> None:
    # Frames that once got a confidently wrong fix: 4/3 an elevation 0.19 m and a pitch
    # 1.2 deg off (the top cut alternating while the pose jumped), 6/0 a pitch 1.45 deg
    # off, 7/2 an elevation 10 sigma off (rough rock by a free end taken for a top hit),
    # 0/3 an elevation 25 sigma off (a bracket whose panels disagreed taken as exact).
    scene = random_drift_scene(seed, frames=6, lidar="os1-64", range_sigma_m=0.02, lookalikes=True)
    sim = scene.simulate(index)
    fix = locate3d(
        sim.frame, scene.survey, config=Locator3DConfig(range_sigma_m=0.02, survey_sigma_m=0.0)
    )
    if not fix.ok:
        assert fix.reason in {"inconsistent", "one_beacon", "rejected", "degenerate_geometry"}
        return
    assert fix.pose is not None
    assert fix.adjustment is not None
    p, t = fix.pose, sim.pose
    err = p.minus(t)
    assert np.all(np.abs(err) < 4.5 * np.sqrt(np.diag(fix.adjustment.covariance))), err
    assert np.linalg.norm(err[:3]) < 0.1, err
    assert np.degrees(np.abs(err[3:])).max() < 1.0, err


def test_a_plan_view_of_one_beacon_starts_a_fix_the_2d_prior_confirms() -> None:
    # Every plan view of this frame confirms one beacon only: the second is fixed in 3D
    # where the first's pose puts it, and the plan view, levelled by that pose and
    # located with it as a prior, confirms both (the fix's plan view has the prior).
    scene = random_drift_scene(0, frames=6, lidar="os1-64", range_sigma_m=0.02)
    sim, fix = _located(scene, 4, 0.02)
    _within(fix, sim)
    assert fix.plan.ok
    assert fix.plan.config.prior is not None


def _bin_centre_plan_scan(
    frame: Frame3D,
    *,
    up: NDArray[np.float64],
    band: tuple[float, float],
    resolution_deg: float,
    range_sigma_m: float = 0.0,
    bands: Sequence[tuple[float, float, float, float]] = (),
) -> Scan:
    """The plan view as it was built before its beams moved to their returns' centroid
    (2026-12-07): each bin at its centre, the mean range of the returns within 5 cm of
    its nearest. In it, the frames below are hard in the ways their tests need (the plan
    view confirms one beacon, or its fix is smeared), as they no longer are: each test
    takes it (the fixture ``bin_centre_plan``) to show the stage it is about still does
    its part."""
    n = round(360.0 / resolution_deg)
    step = 2.0 * math.pi / n
    low, high = _bin_bands(n, band, bands)
    p = frame.points @ level_rotation(up).T
    bins = np.floor((np.arctan2(p[:, 1], p[:, 0]) + math.pi) / step).astype(np.intp) % n
    keep = (p[:, 2] >= low[bins]) & (p[:, 2] <= high[bins])
    bins, r = bins[keep], np.hypot(p[keep, 0], p[keep, 1])
    nearest = np.full(n, np.inf)
    np.minimum.at(nearest, bins, r)
    near = r <= nearest[bins] + 0.05
    count = np.bincount(bins[near], minlength=n)
    total = np.bincount(bins[near], r[near], minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        ranges = np.where(count > 0, total / count, np.nan)
    centres = -math.pi + (np.arange(n) + 0.5) * step
    return Scan(angles_rad=centres, ranges_m=ranges, stamp_ns=frame.stamp_ns)


@pytest.fixture
def two_refined_bands(monkeypatch: pytest.MonkeyPatch) -> None:
    """A refined vertical tried in the first two bands, as it was before 2026-12-07 (the
    next session): frames that showed a stage deciding them were found so, and tried in
    the widest band too, some are fixed by another way."""
    monkeypatch.setattr(locator3d, "REFINED_BANDS", 2)


@pytest.fixture
def strict_plan_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan view located again near a 3D pose as it was before 2026-12-07 (the
    seventh session that day): the strict beam rule and the 2D gates. A frame whose
    plan view, so located, confirmed one beacon alone may now confirm both."""
    monkeypatch.setattr(locator3d, "AGAIN_GATES_M", VerificationConfig().coarse_gates_m)
    monkeypatch.setattr(locator3d, "AGAIN_WALL_M", 0.0)


@pytest.fixture
def bin_centre_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan views as they were before 2026-12-07: bin centres, and the plan view
    located again in the band of the shown beacons' tops or the try's (no beacon's
    bearings given their own band)."""
    monkeypatch.setattr(locator3d, "plan_scan", _bin_centre_plan_scan)
    monkeypatch.setattr(locator3d, "_beacon_bands", lambda survey, pose: [])


def _located(scene: DriftScene3D, index: int, sigma: float) -> tuple[SimulatedFrame3D, Fix3D]:
    """Frame ``index`` of ``scene`` and its fix (range sigma ``sigma``, no survey sigma)."""
    sim = scene.simulate(index)
    cfg = Locator3DConfig(range_sigma_m=sigma, survey_sigma_m=0.0)
    return sim, locate3d(sim.frame, scene.survey, config=cfg)


def _within(fix: Fix3D, sim: SimulatedFrame3D, sigmas: float = 4.5) -> NDArray[np.float64]:
    """The fix's errors (record order), each asserted within ``sigmas`` of its own."""
    assert fix.ok, fix.detail
    assert fix.pose is not None
    assert fix.adjustment is not None
    err = fix.pose.minus(sim.pose)
    assert np.all(np.abs(err) < sigmas * np.sqrt(np.diag(fix.adjustment.covariance))), err
    return err


def _thin_second_beacon() -> DriftScene3D:
    # Frame 0: on a grade of 1 in 14, the vehicle pitched 7.5 deg and rolled 8 deg; a
    # beacon 2 m away, its top 0.36 m above the sensor, fills the plan view; the second,
    # 12.7 m off and its top 0.58 m below the sensor, is crossed by two rings on two
    # panels (6 and 10 returns), which no plan view confirms.
    return random_drift_scene(3000, 9, frames=10, lidar="vlp16", range_sigma_m=0.01)


def test_a_one_beacon_3d_fix_stands_where_the_plan_view_located_again_finds_none() -> None:
    # Located again with the 3D pose as its prior, the plan view still confirms the
    # first beacon only. The 3D fix shows both and passes every 3D test (its position
    # within 0.4 mm; refused where the one-beacon fix does not stand, below); its record
    # names the panels the 3D fix used.
    sim, fix = _located(_thin_second_beacon(), 0, 0.01)
    _within(fix, sim)
    assert not fix.plan.ok  # the one-beacon plan view it started from
    assert set(fix.beacons) >= {"B3", "B4"}
    rec = fix3d_record(fix, frame=sim.frame, range_sigma_m=0.01, survey_sigma_m=0.0)
    assert rec["plan_view"] == {"status": "no_fix", "reason": "one_beacon"}
    assert len(rec["panels"]["B3"]) >= 2
    text = fix3d_text(fix, frame=sim.frame, range_sigma_m=0.01, survey_sigma_m=0.0)
    assert "a plan view confirming one beacon" in text


@pytest.mark.parametrize("confirmed", [(), ("B3",)])
def test_a_one_beacon_3d_fix_the_plan_view_located_again_does_not_confirm_is_refused(
    confirmed: tuple[str, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    # The same frame, its plan view located again confirming no beacon near the 3D pose,
    # or another beacon than the first: the one-beacon 3D fix does not stand.
    real = locator3d.locate

    def located(scan: Scan, survey: Survey, *, config: LocatorConfig) -> Fix:
        got = real(scan, survey, config=config)
        if config.prior is None or got.ok:
            return got
        verified = [replace(v, supported=confirmed) for v in got.verified[:1]]
        reason = "one_beacon" if confirmed else "inconsistent"
        return replace(got, reason=reason, verified=verified)

    monkeypatch.setattr(locator3d, "locate", located)
    _, fix = _located(_thin_second_beacon(), 0, 0.01)
    assert not fix.ok
    assert fix.detail.startswith("plan view located again near the one-beacon 3D pose")


def test_floor_returns_by_a_walls_foot_are_no_end_panels() -> None:
    # The floor rises 22 cm from the drift's middle to the wall's foot under a beacon
    # whose end panel no ring crosses: with the floor taken from 2 m about, one ring's
    # floor returns passed for that panel and levered a fix 1.06 deg off in roll.
    scene = random_drift_scene(34, frames=6, lidar="vlp16", range_sigma_m=0.03, lookalikes=True)
    sim, fix = _located(scene, 4, 0.03)
    assert np.degrees(np.abs(_within(fix, sim)[3:])).max() < 1.0


def test_floor_returns_under_a_beacons_end_panel_lever_no_tilt() -> None:
    # A VLP-16 at 3 cm: four floor returns of one ring cross a beacon's end panel's plane
    # 2.4 m below its top, lower than its other panels are seen; taken for the panel
    # they held a fix more than 1 deg off in tilt (7 sigma in pitch). Below the plate's
    # other panels by more than a ring and a half, they are the floor's.
    scene = random_drift_scene(1014, frames=10, lidar="vlp16", range_sigma_m=0.03, lookalikes=True)
    sim, fix = _located(scene, 9, 0.03)
    assert np.degrees(np.abs(_within(fix, sim, 3.0)[3:])).max() < 1.0


def test_two_wall_returns_alone_on_a_near_beacons_end_panel_lever_no_tilt() -> None:
    # A beacon 1.2 m away: two wall returns by its short end panel's free end, 2.3 deg
    # off grazing it and alone on it, bent the pose to fit them (each within its own
    # w-test) and held a fix 1.4 deg off in pitch (6 sigma); their panel's common
    # shift fails its test, and the panel is left out.
    scene = random_drift_scene(46, frames=6, lidar="vlp16", range_sigma_m=0.03, lookalikes=True)
    sim, fix = _located(scene, 0, 0.03)
    assert np.degrees(np.abs(_within(fix, sim)[3:])).max() < 0.3


def test_a_one_beacon_3d_fix_the_plan_view_confirms_no_beacon_near_is_refused(
    bin_centre_plan: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Located again near the one-beacon 3D pose, this plan view confirms no beacon at
    # all: that 3D fix was 1.7 deg off in pitch and 0.7 deg in azimuth at 120 sigma.
    # (The reason is the first 3D refusal of the frame's tries: since grazing returns
    # are left out, an earlier try's adjustment is rejected by the global test.) With
    # the two one-beacon starts it was found with; a later start fixes it right, and so,
    # after the tries, does a plan view located leniently (LENIENT_STARTS), and a start
    # again from the beacon's own panels (OWN_TILT_SIGMA_DEG).
    scene = random_drift_scene(49, frames=6, lidar="vlp16", range_sigma_m=0.02, lookalikes=True)
    sim, fix = _located(scene, 2, 0.02)
    _within(fix, sim, 3.0)
    monkeypatch.setattr(locator3d, "ONE_BEACON_STARTS", 2)
    _, fix = _located(scene, 2, 0.02)
    _within(fix, sim, 3.0)
    monkeypatch.setattr(locator3d, "LENIENT_STARTS", 0)
    _, fix = _located(scene, 2, 0.02)
    _within(fix, sim, 3.0)
    monkeypatch.setattr(locator3d, "OWN_TILT_SIGMA_DEG", -1.0)
    _, fix = _located(scene, 2, 0.02)
    assert not fix.ok
    assert fix.reason in {"inconsistent", "one_beacon", "rejected"}


def test_a_one_beacon_3d_fix_without_the_plan_views_agreement_holds_the_tilt_tighter(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Standing without the plan view's agreement, a one-beacon 3D fix is held to a tilt
    # sigma of ALONE_TILT_SIGMA_DEG: the benchmark's VLP-16 3 cm look-alike frame 9 of
    # drift 1 (before the look-alikes kept clear of the beacons) had come out 1.05 deg off
    # in pitch at 3.6 sigma, its tilt held to 0.29 deg. The thin second beacon's frame
    # stands so; with the limit below its own tilt sigma it is refused.
    _, fix = _located(_thin_second_beacon(), 0, 0.01)
    assert fix.adjustment is not None
    tilt = math.degrees(
        math.sqrt(max(fix.adjustment.covariance[3, 3], fix.adjustment.covariance[4, 4]))
    )
    assert tilt <= locator3d.ALONE_TILT_SIGMA_DEG
    monkeypatch.setattr(locator3d, "ALONE_TILT_SIGMA_DEG", 0.5 * tilt)
    _, held = _located(_thin_second_beacon(), 0, 0.01)
    assert not held.ok


def test_each_beacons_bearings_get_the_band_of_its_tops() -> None:
    # Bearings counter-clockwise from the heading (DESIGN.md: a beam at bearing phi
    # lands at E0 + r sin(A - phi), N0 + r cos(A - phi)); the band from ONE_BEACON_BAND_M
    # below the lowest top to below the highest, relative to the pose's elevation.
    _, scene = paper_walls("parallel")
    pose = Pose3D.from_degrees(7.0, 7.0, 1.2, 30.0, 2.0, -1.0)
    bands = _beacon_bands(scene.survey, pose)
    assert len(bands) == len(list(scene.survey))
    for (start, end, low, high), beacon in zip(
        bands, sorted(scene.survey, key=lambda b: -np.hypot(*(b.centroid - 7.0))), strict=True
    ):
        for e, n in beacon.edges:
            phi = pose.azimuth - math.atan2(e - 7.0, n - 7.0)
            r = math.hypot(e - 7.0, n - 7.0)
            assert (phi - start + 1e-9) % (2 * math.pi) <= end - start + 2e-9
            assert math.isclose(7.0 + r * math.sin(pose.azimuth - phi), e)
        top = float(beacon.elevations.min()) - 1.2
        assert low == pytest.approx(top - locator3d.ONE_BEACON_BAND_M[0])
        assert high < float(beacon.elevations.max()) - 1.2


@pytest.mark.parametrize(
    ("lidar", "sigma", "lookalikes", "index", "refusal"),
    [
        # A grade puts the drift's other beacons above or below the band the 3D fix
        # was confirmed in: the plan view levelled by the fix saw its beams pass over
        # them (87 mm from the 3D position it had agreed with, seen in the try's band)
        ("os1-64", 0.03, False, 0, "from the plan view's fix"),
        # and, from one beacon's 3D pose, confirmed no pose near it.
        ("os1-64", 0.01, True, 8, "no pose hypothesis within the prior"),
    ],
)
def test_the_plan_view_located_again_sees_each_beacon_in_the_band_of_its_tops(
    two_refined_bands: None,
    monkeypatch: pytest.MonkeyPatch,
    lidar: str,
    sigma: float,
    lookalikes: bool,
    index: int,
    refusal: str,
) -> None:
    scene = random_drift_scene(
        0, 4, frames=10, lidar=lidar, range_sigma_m=sigma, lookalikes=lookalikes
    )
    sim, fix = _located(scene, index, sigma)
    _within(fix, sim, 3.5)
    monkeypatch.setattr(locator3d, "_beacon_bands", lambda survey, pose: [])
    # the plan view located again with the lenient rule and narrow gates (AGAIN_GATES_M)
    # confirms the fix in the try's band too, where the beams passing over the other
    # beacons land on their walls
    _within(_located(scene, index, sigma)[1], sim, 3.5)
    monkeypatch.setattr(locator3d, "AGAIN_GATES_M", VerificationConfig().coarse_gates_m)
    monkeypatch.setattr(locator3d, "AGAIN_WALL_M", 0.0)
    refused = _located(scene, index, sigma)[1]
    assert not refused.ok
    assert refusal in refused.detail
