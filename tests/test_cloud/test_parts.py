"""The georeference's parts on their own: grids, the top edge, the adjustment, classes."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from mast.cloud.adjust import (
    AdjustmentError,
    BeaconObs,
    adjust_transformation,
    check_beacons,
    rigid_solution,
)
from mast.cloud.detect import _top_edge
from mast.cloud.drift import DriftCorrection, correct_drift
from mast.cloud.grid import PlanGrid, PlanIndex, cell_keys, key_ij, pack_ij
from mast.cloud.outputs import accuracy_class
from mast.core.trajectory import ScannerPath
from mast.pipeline.segmentation import Segment


def test_cell_keys_round_trip_on_both_sides_of_the_origin() -> None:
    ij = np.array([[-5, 7], [0, 0], [123456, -98765], [-1, -1]], dtype=np.int64)
    keys = pack_ij(ij)
    assert np.all(keys > 0)
    assert np.array_equal(key_ij(keys), ij)
    # sorted keys sort by column then row
    assert np.array_equal(np.argsort(keys), np.lexsort((ij[:, 1], ij[:, 0])))
    xy = np.array([[-0.26, 0.35], [10.0, -3.0]])
    back = key_ij(cell_keys(xy, np.zeros(2), 0.05))
    assert np.array_equal(back, np.floor(xy / 0.05).astype(int))


def test_plan_index_squares_are_the_points_a_full_scan_finds_in_order() -> None:
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 50, (20_000, 2)) + [452_000.0, 7_101_000.0]
    xy[:50, 0] = xy[50, 0]  # ties in x
    index = PlanIndex(xy)
    for centre in [*xy[rng.integers(0, len(xy), 20)], np.array([0.0, 0.0])]:
        for half in (0.01, 0.7, 3.0):
            full = np.flatnonzero(np.max(np.abs(xy - centre), axis=1) < half)
            np.testing.assert_array_equal(index.square(centre, half), full)


def test_plan_grid_merges_chunks_into_min_max_count_and_bins() -> None:
    g = PlanGrid(np.zeros(2), 0.5)
    g.add(np.array([[0.1, 0.1, 1.0], [0.2, 0.2, 3.0]]), np.array([1, 2], dtype=np.uint64))
    g.add(np.array([[0.3, 0.1, -1.0], [2.0, 2.0, 5.0]]), np.array([4, 1], dtype=np.uint64))
    row, hit = g.at(np.array([[0.4, 0.4], [2.1, 2.1], [9.0, 9.0]]))
    assert hit.tolist() == [True, True, False]
    assert g.zmin[row[0]] == -1.0
    assert g.zmax[row[0]] == 3.0
    assert g.count[row[0]] == 3
    assert int(g.bins[row[0]]) == 7


@pytest.mark.parametrize(
    ("noise", "fall"), [(0.0, 1.0), (0.005, 1.0), (0.01, 1.0), (0.005, 0.5), (0.01, 0.5)]
)
def test_top_edge_is_unbiased_and_its_sigma_honest(noise: float, fall: float) -> None:
    """Points over a 0.6 m panel with Gaussian noise, evenly or thinning out upwards to
    ``fall`` of the bottom's density (a scanner's range and incidence change up a
    panel): the top comes back within 0.3 of its spread, and within its own sigma
    about as often as a normal distribution says. (Assuming an even density, as the
    estimate once did, put it 7-14 mm low at half the density.)"""
    rng = np.random.default_rng(1)
    errs, sigs = [], []
    for _ in range(300):
        u = rng.uniform(0, 1, 400)
        # a density falling linearly from 1 to ``fall``: its inverse distribution function
        x = u if fall == 1.0 else (-1 + np.sqrt(1 + (fall**2 - 1) * u)) / (fall - 1)
        z = 1.4 + 0.6 * x + rng.normal(0, noise, 400)
        top, sigma, bottom = _top_edge(z, max(noise, 0.002))
        errs.append(top - 2.0)
        sigs.append(sigma)
        assert abs(bottom - 1.4) < 0.05
    e, s = np.array(errs), np.array(sigs)
    assert abs(float(np.mean(e))) < 0.3 * float(np.std(e))
    inside = float(np.mean(np.abs(e) <= 1.96 * s))
    assert 0.88 <= inside <= 0.995


def _beacons(
    rot: float, t: np.ndarray, dz: float, n: int, rng: np.random.Generator, sigma: float
) -> list[BeaconObs]:
    c, s = math.cos(rot), math.sin(rot)
    r = np.array([[c, -s], [s, c]])
    out = []
    for k in range(n):
        local = np.array([[10.0 * k, 3.0 + k % 2], [10.0 * k + 0.5, 3.3 + k % 2]])
        top = 1.0 + 0.1 * k
        grid = local @ r.T + t
        cov = np.eye(4) * sigma**2
        out.append(
            BeaconObs(
                f"B{k}",
                (2, 3),
                local + rng.normal(0, sigma, local.shape),
                cov,
                top + rng.normal(0, sigma),
                sigma,
                grid,
                top + dz,
            )
        )
    return out


def test_adjustment_recovers_the_transformation_and_names_a_moved_beacon() -> None:
    rng = np.random.default_rng(3)
    t = np.array([452000.0, 7101000.0])
    obs = _beacons(0.7, t, -850.0, 6, rng, 0.002)
    sol = adjust_transformation(obs, survey_sigma_m=0.0, heights=True)
    assert sol.chi2_test == "pass"
    assert abs(math.radians(sol.transformation.rotation_deg) - 0.7) < 1e-3
    moved = list(obs)
    bad = moved[3]
    moved[3] = BeaconObs(
        bad.beacon,
        bad.edges,
        bad.cloud_xy,
        bad.cloud_cov,
        bad.top,
        bad.sigma_top,
        bad.grid_xy + 0.05,
        bad.grid_top,
    )
    sol = adjust_transformation(moved, survey_sigma_m=0.0, heights=True)
    assert sol.excluded == ["B3"]
    with pytest.raises(AdjustmentError, match="too_few"):
        adjust_transformation(obs[:1], survey_sigma_m=0.0, heights=True)
    with pytest.raises(AdjustmentError, match="helmert7 needs"):
        adjust_transformation(obs, model="helmert7", survey_sigma_m=0.0, heights=False)


def test_icsm_classes_follow_c_times_d_plus_0_2() -> None:
    # 20 m from control: allowance c * 0.22 mm
    assert accuracy_class(0.0002, 20.0) == "3A"
    assert accuracy_class(0.005, 20.0) == "C"
    assert accuracy_class(0.010, 20.0) == "D"
    assert accuracy_class(0.5, 20.0) is None


def _drifting_run(rng: np.random.Generator, drift: float) -> tuple[ScannerPath, list[BeaconObs]]:
    """A 240 m straight run whose SLAM drifts (heading 0.5 mrad per 10 m, scale ``drift``,
    a lateral wander), with a beacon on alternate walls every 20 m: each seen in the
    cloud where the SLAM put it and surveyed where it is."""
    t = np.arange(0.0, 241.0)  # one metre a second
    slam_xyz = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
    true_yaw = 0.00005 * t
    true_xy = np.column_stack([(1 + drift) * t, 0.3 * np.sin(t / 50.0)])
    traj = ScannerPath(t, slam_xyz, np.zeros_like(t), Path("run.tum"))
    grid0 = np.array([452000.0, 7101000.0])
    out = []
    for k, tb in enumerate(range(10, 240, 20)):
        q = np.array([[0.0, 3.0], [0.4, 3.2]]) * (1 if k % 2 else -1)  # in the body frame
        c, s = math.cos(true_yaw[tb]), math.sin(true_yaw[tb])
        grid = q @ np.array([[c, -s], [s, c]]).T + true_xy[tb] + grid0
        sigma = 0.002
        out.append(
            BeaconObs(
                f"B{k:02d}",
                (2, 3),
                q + slam_xyz[tb, :2] + rng.normal(0, sigma, q.shape),
                np.eye(4) * sigma**2,
                1.0,
                0.002,
                grid + rng.normal(0, 0.003, grid.shape),
                -850.0,
                float(tb),
            )
        )
    return traj, out


def test_the_drift_correction_tests_each_beacon_and_leaves_a_moved_one_out() -> None:
    """Each control beacon is tested against the pose graph solved without it: on a
    consistent run none fails and the checks pass; a beacon moved 0.3 m after its survey
    fails and is left out (the graph would otherwise bend the cloud onto it); a drift
    model far tighter than the SLAM's drift fails so many that the run is refused."""
    rng = np.random.default_rng(5)
    traj, obs = _drifting_run(rng, 0.004)
    controls, checks = [o for o in obs if o.beacon != "B05"], [o for o in obs if o.beacon == "B05"]
    rigid = rigid_solution(controls, "4", 0.003, False).transformation

    def run(cs: list[BeaconObs], drift: float = 0.01) -> DriftCorrection:
        return correct_drift(
            traj, cs, rigid, drift=drift, survey_sigma_m=0.003, heights=False, checks=checks
        )

    clean = run(controls)
    assert clean.excluded == ()
    # how well the drift model fits (1.2 here): ten times looser, statistics far smaller
    assert 0.0 < 2 * run(controls, drift=0.1).statistic_per_dof < clean.statistic_per_dof
    assert [t.beacon for t in clean.tests if t.role == "check"] == ["B05"]
    assert not any(t.failed for t in clean.tests)
    # the check, 20 m from its neighbours, within half of its rigid misclosure (0.19 m)
    rigid_check = check_beacons(rigid_solution(controls, "4", 0.003, False), checks,
                                survey_sigma_m=0.003)[0]  # fmt: skip
    after = max(np.hypot(*clean.residuals["B05"][:, :2].T))
    assert after < 0.5 * rigid_check.horizontal_m
    moved = [
        o if o.beacon != "B07" else replace(o, grid_xy=o.grid_xy + np.array([0.0, 0.3]))
        for o in controls
    ]
    bent = run(moved)
    assert bent.excluded == ("B07",)
    left_out = next(t for t in bent.tests if t.beacon == "B07")
    assert left_out.role == "excluded"  # and tested against the final graph
    assert left_out.failed
    assert not any(t.failed for t in bent.tests if t.beacon != "B07")
    # left out, the moved beacon stays 0.3 m off rather than the cloud bending onto it
    assert 0.25 < max(np.hypot(*bent.residuals["B07"][:, :2].T)) < 0.35
    # knocked round by 0.15 rad about its middle: its mean stays, its edges move 34 mm
    c, s = math.cos(0.15), math.sin(0.15)
    turned = [
        o
        if o.beacon != "B07"
        else replace(
            o,
            grid_xy=(o.grid_xy - o.grid_xy.mean(axis=0)) @ np.array([[c, -s], [s, c]]).T
            + o.grid_xy.mean(axis=0),
        )
        for o in controls
    ]
    assert run(turned).excluded == ("B07",)
    with pytest.raises(AdjustmentError, match="inconsistent"):
        run(controls, drift=0.00002)
    # heights: the top against the height chain solved without it, one more dof
    level = correct_drift(traj, controls, rigid, drift=0.01, survey_sigma_m=0.003, heights=True)
    assert level.excluded == ()
    assert {t.dof for t in level.tests} == {5}
    raised = [o if o.beacon != "B03" else replace(o, grid_top=o.grid_top + 0.3) for o in controls]
    high = correct_drift(traj, raised, rigid, drift=0.01, survey_sigma_m=0.003, heights=True)
    assert high.excluded == ("B03",)
    assert abs(float(high.residuals["B03"][0, 2]) + 0.3) < 0.05  # left out: 0.3 m low


def test_a_beacon_the_rest_cannot_place_is_not_tested() -> None:
    """Two controls of one edge each: either left out leaves one point, about which the
    graph may turn freely, so neither is tested (as the adjustment does with a beacon
    whose removal leaves no redundancy), and the correction is still made."""
    rng = np.random.default_rng(6)
    traj, obs = _drifting_run(rng, 0.004)
    ends = [
        replace(o, edges=(2,), cloud_xy=o.cloud_xy[:1], cloud_cov=o.cloud_cov[:2, :2],
                grid_xy=o.grid_xy[:1])
        for o in (obs[0], obs[-1])
    ]  # fmt: skip
    rigid = rigid_solution(ends, "4", 0.003, False).transformation
    done = correct_drift(traj, ends, rigid, drift=0.01, survey_sigma_m=0.003, heights=False)
    assert done.tests == ()
    assert done.excluded == ()
    assert math.isnan(done.statistic_per_dof)  # no verdict, null in transform.json
    assert max(np.hypot(*done.residuals["B00"][:, :2].T)) < 0.01


def test_dense_clusters_and_wide_plans_are_worked_in_blocks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The column test unpacks height bins a block of cells at a time, and RANSAC counts
    inliers a block of points at a time: the answers do not depend on the blocks, and a
    dense 200 000-point wall takes tens of MiB, not the 1.4 GiB of a tries x points
    matrix."""
    import tracemalloc

    from mast.cloud import detect

    rng = np.random.default_rng(2)
    side = 120
    ij = np.column_stack([np.arange(side * side) % side, np.arange(side * side) // side])
    keys = np.unique(pack_ij(ij))
    bits = np.zeros(keys.size, np.uint64)
    for _ in range(3):  # runs of random lengths, some cut by a missing bin
        start, length = rng.integers(0, 60, keys.size), rng.integers(1, 30, keys.size)
        for k in range(30):
            on = (k < length) & (start + k < 64)
            bits[on] |= np.left_shift(np.uint64(1), (start[on] + k).astype(np.uint64))
        bits &= ~np.left_shift(np.uint64(1), rng.integers(0, 64, keys.size).astype(np.uint64))
    n = keys.size
    cols = PlanGrid(
        np.zeros(2), 0.05, keys, np.zeros(n), np.full(n, 3.0), np.ones(n, np.int64), bits
    )
    cfg = detect.DetectConfig(band=(0.0, 3.2))
    whole = detect._panel_runs(cols, cols, cfg)
    # pinned from the loop these replaced (each cell's tallest run, the lowest of equals)
    assert int(whole[0].sum()) == 155
    assert float(whole[1].sum()) == pytest.approx(8653.4, rel=1e-12)
    assert float(whole[2].sum()) == pytest.approx(18770.7, rel=1e-12)
    assert float(whole[1] @ np.arange(n)) == pytest.approx(62114827.9, rel=1e-12)
    monkeypatch.setattr(detect, "RUN_BLOCK_CELLS", 997)
    for a, b in zip(whole, detect._panel_runs(cols, cols, cfg), strict=True):
        assert np.array_equal(a, b)

    t = rng.uniform(0.0, 10.0, 200_000)
    wall = np.column_stack([t, rng.normal(0.0, 0.01, t.size)])
    tracemalloc.start()
    pieces = detect._lines_in(wall, 0.01, 50, 0.3)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 200 * 2**20
    assert len(pieces[0]) > 0.99 * t.size
    monkeypatch.setattr(detect, "RANSAC_BLOCK_POINTS", 333)
    small = detect._lines_in(wall[:20_000], 0.01, 50, 0.3)
    monkeypatch.setattr(detect, "RANSAC_BLOCK_POINTS", 1 << 20)
    large = detect._lines_in(wall[:20_000], 0.01, 50, 0.3)
    assert [p.tolist() for p in small] == [p.tolist() for p in large]


def test_a_top_edge_always_has_a_spread() -> None:
    """However the points pile up under the top (rock, a ledge), the top's sigma is never
    zero: a zero weighed one panel's top over every other beacon's in the adjustment."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(40, 400))
        z = np.concatenate([rng.uniform(1.4, 2.0, n), rng.normal(1.9, 0.01, 3 * n)])
        top, sigma, _ = _top_edge(z, 0.01)
        assert math.isfinite(top)
        assert sigma > 1e-4


def test_a_panel_line_running_on_over_rock_stops_at_the_panel() -> None:
    """Within a dense scan's noise band a panel's line runs on over the rock beside its
    free end; the rock's points reach from floor to roof, the panel's stay between its
    bottom and top: the panel is a stretch of its own. The wall above a panel, in the
    same band, is a run of heights of its own."""
    from mast.cloud.detect import _even_stretches, _height_runs

    rng = np.random.default_rng(5)
    panel = np.column_stack(
        [rng.uniform(0.0, 0.2, 2000), rng.normal(0.0, 0.001, 2000), rng.uniform(0.0, 0.5, 2000)]
    )
    rock = np.column_stack(
        [rng.uniform(0.25, 0.4, 500), rng.normal(0.0, 0.001, 500), rng.uniform(-0.5, 1.2, 500)]
    )
    parts = _even_stretches(np.vstack([panel, rock]), 0.05)
    assert sorted(np.sort(p).tolist() for p in parts) == [
        list(range(2000)),
        list(range(2000, 2500)),
    ]
    # a panel alone, with a bin or two missing and a few rock points, is one stretch
    gappy = panel[(panel[:, 0] < 0.08) | (panel[:, 0] > 0.13)]
    stray = np.column_stack([rng.uniform(0, 0.2, 20), np.zeros(20), rng.uniform(-0.5, 1.2, 20)])
    assert [p.size for p in _even_stretches(np.vstack([gappy, stray]), 0.05)] == [
        gappy.shape[0] + 20
    ]
    # sparse: bins grow until they hold enough points to say
    sparse = panel[:60]
    assert len(_even_stretches(sparse, 0.05)) == 1
    # the wall above the panel, along its line for metres, is a run of its own
    wall = np.column_stack(
        [rng.uniform(-1.0, 3.0, 1500), rng.normal(0.0, 0.01, 1500), rng.uniform(1.1, 1.35, 1500)]
    )
    runs = _height_runs(np.vstack([panel, wall])[:, 2], 0.05)
    assert sorted(np.sort(r).tolist() for r in runs) == [
        list(range(2000)),
        list(range(2000, 3500)),
    ]


def _piece(index: int, xy: NDArray[np.float64]) -> Segment:
    from mast.cloud.detect import _segment

    return _segment(index, 0, np.arange(xy.shape[0]), xy, 0.001, 0.1)


def test_a_short_piece_crossing_a_panel_does_not_cut_it() -> None:
    """A few mixed returns in a line 7 mm long across a panel, 17 cm from its end, meet
    it in a 'corner' whose node is anywhere along the panel (the streak's direction is
    not known to 4 degrees): the panel keeps its whole length (it was cut to 33 cm of
    50 there)."""
    from mast.cloud.detect import _corners, _trimmed

    rng = np.random.default_rng(6)
    t = np.sort(rng.uniform(0.0, 0.5, 3000))
    panel = np.column_stack([t, rng.normal(0.0, 0.001, t.size)])
    s = np.linspace(0.0, 0.007, 40)
    streak = np.column_stack([0.33 + 0.5 * s, 0.003 + 0.866 * s])
    segs = [_piece(0, panel), _piece(1, streak)]
    corners = _corners(segs, 0.001)
    assert corners  # the streak's line meets the panel's near an end of each
    xy = np.vstack([panel, streak])
    segs[1] = replace(segs[1], beams=segs[1].beams + panel.shape[0])
    trimmed = _trimmed(segs, corners, xy, 0.001, 0.1)
    assert trimmed[0].length > 0.49
    # a true corner still trims both pieces where their points mix
    other = np.column_stack(
        [0.5 + 0.3 * np.cos(1.0) * t[::3] / 0.5, 0.3 * np.sin(1.0) * t[::3] / 0.5]
    )
    segs = [_piece(0, panel), _piece(1, other)]
    segs[1] = replace(segs[1], beams=segs[1].beams + panel.shape[0])
    corner = _corners(segs, 0.001)
    trimmed = _trimmed(segs, corner, np.vstack([panel, other]), 0.001, 0.1)
    assert 0.48 < trimmed[0].length < 0.5
    assert 0.28 < trimmed[1].length < 0.3


def test_streaks_meeting_a_panel_face_do_not_shred_it() -> None:
    """Mixed returns between a panel's vertical edge and the rock behind lie in plan
    along the beam, in streaks tens of centimetres long that meet the panel's face
    inside it. Each end of a piece is trimmed by its strongest corner alone: here the
    neighbouring panel's, not the streaks' (which cut the panel to 40 cm of 50)."""
    from mast.cloud.detect import _corners, _trimmed

    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0.0, 0.5, 3000))
    panel = np.column_stack([t, rng.normal(0.0, 0.001, t.size)])
    u = rng.uniform(0.0, 0.3, 1500)
    neighbour = np.column_stack([0.5 + np.cos(0.5) * u, np.sin(0.5) * u])
    parts = [panel, neighbour]
    for x0 in (0.40, 0.45):  # streaks running away from the face at 60 degrees
        s = rng.uniform(0.005, 0.15, 150)
        parts.append(np.column_stack([x0 - 0.5 * s, 0.866 * s]))
    segs, first = [], 0
    for k, p in enumerate(parts):
        segs.append(replace(_piece(k, p), beams=_piece(k, p).beams + first))
        first += p.shape[0]
    corners = _corners(segs, 0.001)
    assert sum(1 for c in corners if {c.first % 4, c.second % 4} & {2, 3}) >= 2
    trimmed = _trimmed(segs, corners, np.vstack(parts), 0.001, 0.1)
    assert 0.48 < trimmed[0].length < 0.5


def test_a_piece_along_a_larger_one_is_a_duplicate_and_a_shallow_neighbour_is_not() -> None:
    from mast.cloud.detect import _duplicates

    rng = np.random.default_rng(8)
    t = rng.uniform(0.0, 0.6, 3000)
    middle = np.column_stack([t, rng.normal(0.0, 0.01, t.size)])
    # a short outer panel 25 degrees off: most of its points lie in the middle's band
    s = rng.uniform(0.0, 0.16, 300)
    outer = np.column_stack([0.6 + np.cos(0.44) * s, np.sin(0.44) * s])
    xy = np.vstack([middle, outer])
    pieces = [np.arange(3000), np.arange(3000, 3300)]
    rows_near_middle = np.flatnonzero(np.abs(xy[:, 1]) < 0.03)
    # the outer panel's points found again along its line hold many of the middle's
    pieces[1] = np.union1d(pieces[1], rows_near_middle[xy[rows_near_middle, 0] > 0.52])
    # a streak crossing the middle at 2 degrees found the middle's points again
    along = rows_near_middle[(xy[rows_near_middle, 0] > 0.1) & (xy[rows_near_middle, 0] < 0.4)]
    pieces.append(along)
    assert _duplicates(pieces, xy, xy.shape[0]).tolist() == [False, False, True]


def test_a_far_panel_cut_apart_by_the_clusters_is_joined_again() -> None:
    """At 18 m an oblique panel is seen in scan columns 7 cm apart; where the column
    cells leave an empty cell between two columns, its pieces fall in clusters of
    their own. Pieces on one line, with the same heights, across gaps of a few cells,
    are one piece again; a piece around a corner joins their cluster (its corner with
    them is looked for there); a piece above them, or too far along, stays apart."""
    from mast.cloud.detect import _joined

    rng = np.random.default_rng(9)

    def column(x: float, y: float, z0: float = 0.0) -> NDArray[np.float64]:
        z = np.linspace(z0, z0 + 0.5, 40)
        return np.column_stack([np.full(40, x), np.full(40, y), z]) + rng.normal(
            0.0, [0.0015, 0.0015, 0.0], (40, 3)
        )

    parts = [
        [column(x, 0.0) for x in (0.0, 0.07, 0.14)],  # cluster 1
        [column(x, 0.0) for x in (0.28, 0.35)],  # a column lost: a 14 cm gap
        [column(x, 0.0) for x in (0.42, 0.49, 0.56)],
        [column(0.64 + 0.07 * k * math.cos(0.5), 0.07 * k * math.sin(0.5)) for k in range(4)],
        [column(x, 0.0, 0.8) for x in (0.7, 0.77)],  # the rock above, on the same line
        [column(x, 0.0) for x in (1.1, 1.17)],  # 54 cm on
    ]
    xyz = np.vstack([np.vstack(p) for p in parts])
    pieces, first = [], 0
    for cluster, p in enumerate(parts, start=1):
        n = 40 * len(p)
        pieces.append((cluster, np.arange(first, first + n)))
        first += n
    out = _joined(pieces, xyz, 0.0015, 0.2, 0.05)
    assert len(out) == 4
    (c1, panel), (c4, _), (c5, above), (c6, far) = sorted(out, key=lambda p: p[1][0])
    assert panel.tolist() == list(range(40 * 8))
    assert c1 == c4 == 1  # the corner's piece is in the panel's cluster
    assert (c5, above.size) == (5, 80)
    assert (c6, far.size) == (6, 80)
    # three noises off the line, the pieces are not one
    bent = xyz.copy()
    bent[pieces[1][1], 1] += 0.006
    assert len(_joined(pieces, bent, 0.0015, 0.2, 0.05)) == 5


def test_lone_columns_find_their_neighbours_further_off_and_rock_does_not() -> None:
    """A far panel's columns stand two cells apart with nothing between them: each finds
    two level neighbours within three cells. A column in rock, every cell around it
    holding points, needs two level neighbours of its eight."""
    from mast.cloud import detect

    panel = [(0, 0), (2, 1), (3, 2), (5, 3), (6, 4)]
    rock = [(20, 0), (22, 0), (24, 0)]
    around = [(19, 0), (21, 0), (20, 1), (20, -1)]  # points, but no panel-like column
    ij = np.array(panel + rock + around)
    keys = pack_ij(ij)
    order = np.argsort(keys)
    keys = keys[order]
    found = np.array([True] * 8 + [False] * 4)[order]
    zlo = np.where(found, 1.5, 0.0)
    zhi = np.where(found, 2.0, 3.0)
    ok = detect._level_with_neighbours(keys, found, zlo, zhi, detect.DetectConfig())
    by_cell = {tuple(c): bool(v) for c, v in zip(key_ij(keys).tolist(), ok, strict=True)}
    assert all(by_cell[c] for c in panel)
    assert not by_cell[(20, 0)]  # rock around it: the nearer test, and it has none level
    assert not any(by_cell[c] for c in around)
    # an uneven column among lone ones is not level with them
    zhi_uneven = zhi.copy()
    zhi_uneven[np.flatnonzero(keys == pack_ij(np.array([[3, 2]])))[0]] = 2.4
    ok = detect._level_with_neighbours(keys, found, zlo, zhi_uneven, detect.DetectConfig())
    assert not ok[keys == pack_ij(np.array([[3, 2]]))][0]


def test_a_cell_holding_only_a_panel_takes_the_floor_and_roof_around_it() -> None:
    """From far off a panel shadows the rock behind it, and the floor and roof in front
    of it lie in the next cells: its own cell's lowest and highest points are its
    bottom and top, which would make it floor to roof. The cells around say where the
    floor and roof are."""
    from mast.cloud.detect import _floor_and_roof_around

    floor = PlanGrid(np.zeros(2), 0.5)
    pts = [[0.25, 0.25, 1.5], [0.25, 0.25, 2.0]]  # the panel alone
    pts += [[0.75, 0.25, 0.0], [0.75, 0.25, 4.5], [-0.25, 0.25, 0.1], [-0.25, 0.25, 4.4]]
    pts += [[5.25, 5.25, 1.0], [5.25, 5.25, 3.0]]  # a cell with no neighbour
    floor.add(np.array(pts))
    around = _floor_and_roof_around(floor)
    row, _ = around.at(np.array([[0.25, 0.25], [5.25, 5.25]]))
    assert around.zmin[row].tolist() == [0.0, 1.0]
    assert around.zmax[row].tolist() == [4.5, 3.0]
    assert floor.zmin[floor.at(np.array([[0.25, 0.25]]))[0]][0] == 1.5  # not changed
