"""The compiled kernels give what their numpy references give, to the last bit."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mast.core import lines
from mast.core._kernels import line_fits, partition_dp, penalty, segment_run
from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D
from mast.pipeline import segmentation as seg
from mast.sim import paper_scene, simulate_scan


def _kernel_pointers(points: np.ndarray, var: float, max_piece: int = seg.MAX_PIECE) -> np.ndarray:
    _, moments = seg._cumulative_moments(points)
    n = points.shape[0]
    return np.asarray(partition_dp(*moments, var, penalty(n), min(n, max_piece)))


def _scan_objects() -> list[Any]:
    """Scans of the paper's scene, noise-free and noisy."""
    scene = paper_scene()
    out = []
    for k, shot in enumerate(scene.shots[:6]):
        for noisy in (False, True):
            rng = np.random.default_rng(k)
            scanner = shot.scanner if noisy else shot.scanner.noise_free()
            out.append(simulate_scan(scene.world, shot.pose, scanner, rng=rng).scan)
    return out


def _scans() -> list[np.ndarray]:
    return [scan.points()[1] for scan in _scan_objects()]


def _polyline(n: int, seed: int, corners: int, sigma: float, length: float) -> np.ndarray:
    """``n`` returns along a polyline of straight pieces seen from the origin, range noise
    ``sigma``."""
    rng = np.random.default_rng(seed)
    knots = np.sort(rng.uniform(0, 1, corners))
    t = np.linspace(0, 1, n)
    heading = np.cumsum(np.r_[0.0, rng.uniform(-1.2, 1.2, corners)])
    piece = np.searchsorted(knots, t)
    step = np.column_stack([np.cos(heading[piece]), np.sin(heading[piece])]) * (length / max(n, 1))
    pts = np.array([3.0, -4.0]) + np.cumsum(step, axis=0)
    r = np.hypot(*pts.T)
    return np.asarray(pts * ((r + sigma * rng.standard_normal(n)) / r)[:, None])


@pytest.mark.parametrize("max_piece", [seg.MAX_PIECE, 16])
def test_partition_kernel_matches_the_reference_on_scans(max_piece: int) -> None:
    for pts in _scans():
        for var in (1e-10, 0.003**2, 0.02**2):
            ref = seg._partition_reference(pts, var, max_piece)
            np.testing.assert_array_equal(_kernel_pointers(pts, var, max_piece), ref)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 300),
    seed=st.integers(0, 2**32 - 1),
    corners=st.integers(0, 5),
    sigma=st.sampled_from([0.0, 1e-3, 0.02]),
)
def test_partition_kernel_matches_the_reference_on_polylines(
    n: int, seed: int, corners: int, sigma: float
) -> None:
    pts = _polyline(n, seed, corners, sigma, 8.0)
    var = max(sigma, 1e-4) ** 2
    np.testing.assert_array_equal(_kernel_pointers(pts, var), seg._partition_reference(pts, var))


def _pieces_reference(points: np.ndarray, var: float, min_points: int = 3) -> np.ndarray:
    pieces = seg._refine(points, seg._partition(points, var), var, min_points)
    return np.array(pieces, dtype=np.intp).reshape(-1, 2)


def _runs_of(points: np.ndarray) -> list[np.ndarray]:
    """The scan's stretches without a breakpoint, as segment_scan cuts them."""
    step = np.hypot(*np.diff(points, axis=0).T)
    cuts = np.flatnonzero(step > 0.3) + 1
    return [r for r in np.split(points, cuts) if len(r) >= 3]


def test_segment_run_kernel_matches_partition_and_refine_on_scans() -> None:
    for pts in _scans():
        for run in _runs_of(pts):
            for var in (1e-10, 0.003**2, 0.02**2):
                got = segment_run(np.ascontiguousarray(run), var, 3, seg.MAX_PIECE)
                np.testing.assert_array_equal(got, _pieces_reference(run, var))


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(3, 400),
    seed=st.integers(0, 2**32 - 1),
    corners=st.integers(0, 6),
    sigma=st.sampled_from([0.0, 1e-3, 0.02]),
)
def test_segment_run_kernel_matches_the_reference_on_polylines(
    n: int, seed: int, corners: int, sigma: float
) -> None:
    pts = _polyline(n, seed, corners, sigma, 12.0)
    var = max(sigma, 1e-4) ** 2
    got = segment_run(np.ascontiguousarray(pts), var, 3, seg.MAX_PIECE)
    np.testing.assert_array_equal(got, _pieces_reference(pts, var))


def test_line_fit_kernel_matches_make_segment() -> None:
    for pts in _scans():
        for run in _runs_of(pts):
            pieces = _pieces_reference(run, 0.003**2)
            fits = line_fits(np.ascontiguousarray(run), pieces, 0.003)
            for (i, j), fit in zip(pieces.tolist(), fits, strict=True):
                ref = seg._make_segment(0, 0, np.arange(i, j), run[i:j], 0.003)
                got = seg._segment_of(0, 0, np.arange(i, j), run[i:j], fit)
                for name in ("centroid", "direction", "normal", "start", "end"):
                    np.testing.assert_allclose(
                        getattr(got, name), getattr(ref, name), rtol=0, atol=1e-9, err_msg=name
                    )
                for name in ("length", "rms", "spacing_start", "spacing_end"):
                    assert getattr(got, name) == pytest.approx(getattr(ref, name), abs=1e-9)
                assert got.sigma_direction == pytest.approx(ref.sigma_direction, rel=1e-7)


def test_association_kernel_matches_the_reference() -> None:
    scene = paper_scene()
    panels = PanelSet.from_survey(scene.survey)
    rng = np.random.default_rng(1)
    lo, hi = panels.a.min(axis=0) - 1.0, panels.a.max(axis=0) + 1.0
    pts = rng.uniform(lo, hi, size=(4000, 2))
    # Points on the panels themselves, and exactly between two of them (ties).
    on = panels.a + panels.direction * (0.5 * panels.length)[:, None]
    pts = np.vstack([pts, on, on + 1e-3 * panels.normal, panels.a, panels.b])
    subsets = [None, np.arange(len(panels))[::2], np.array([3, 1, 2], dtype=np.intp)]
    for subset in subsets:
        for gate in (0.05, 0.5, 10.0, rng.uniform(0.0, 0.4, len(pts))):
            idx, dist = panels.associate(pts, gate, subset=subset)
            ref_idx, ref_dist = panels._associate_reference(pts, gate, subset=subset)
            np.testing.assert_array_equal(idx, ref_idx)
            np.testing.assert_array_equal(dist, ref_dist)
    empty_idx, empty_dist = panels.associate(np.zeros((0, 2)), 0.1)
    assert empty_idx.shape == empty_dist.shape == (0,)
    idx, dist = panels.associate(pts[:5], 0.1, subset=np.zeros(0, dtype=np.intp))
    assert np.all(idx == -1)
    assert np.all(np.isinf(dist))
    assert math.isinf(float(dist[0]))


IcpCase = tuple[np.ndarray, Pose2D, PanelSet, tuple[float, ...], np.ndarray, np.ndarray]


def _icp_cases() -> list[IcpCase]:
    """Whole noisy scans with every kind of start verification gives ICP: near the truth,
    off by a metre and degrees (wide gates), and at UTM-sized coordinates."""
    rng = np.random.default_rng(7)
    cases: list[IcpCase] = []
    for variant in ("parallel", "divergent"):
        scene = paper_scene(variant, range_sigma_m=0.01, seed=3)
        panels = PanelSet.from_survey(scene.survey)
        for shot, sim in zip(scene.shots, scene.simulate_all(), strict=True):
            beams, pts = sim.scan.points()
            angles = sim.scan.angles_rad[beams]
            for scale in (0.01, 0.1, 0.5):
                start = Pose2D(
                    shot.pose.easting + scale * rng.normal(),
                    shot.pose.northing + scale * rng.normal(),
                    shot.pose.azimuth + math.radians(scale * 5 * rng.normal()),
                )
                gates = (0.5, 0.15, 0.05, 0.03) if scale > 0.1 else (0.15, 0.05, 0.03)
                near = panels.near(start.position, 100.0)
                cases.append((pts, start, panels, gates, near, angles))
    return cases


def test_icp_kernel_matches_the_reference() -> None:
    from mast.pipeline.alignment import _icp_reference, icp_point_to_line

    cases = _icp_cases()
    assert len(cases) >= 30
    converged = 0
    for pts, start, panels, gates, near, angles in cases:
        got = icp_point_to_line(pts, start, panels, gates_m=gates, subset=near)
        ref = _icp_reference(pts, start, panels, gates_m=gates, subset=near)
        # Told the beams' angles, it tests each panel on the beams that can reach it
        # only: the same result to the last bit.
        by_bearing = icp_point_to_line(
            pts, start, panels, gates_m=gates, subset=near, angles=angles
        )
        assert by_bearing.pose == got.pose
        assert (by_bearing.iterations, by_bearing.converged) == (got.iterations, got.converged)
        np.testing.assert_array_equal(by_bearing.panel, got.panel)
        np.testing.assert_array_equal(by_bearing.residual_m, got.residual_m)
        assert got.iterations == ref.iterations
        assert got.converged == ref.converged
        converged += got.converged
        # The same solver on the same sums: equal to the last few bits.
        assert got.pose.easting == pytest.approx(ref.pose.easting, abs=1e-9)
        assert got.pose.northing == pytest.approx(ref.pose.northing, abs=1e-9)
        assert math.remainder(got.pose.azimuth - ref.pose.azimuth, 2 * math.pi) == pytest.approx(
            0.0, abs=1e-11
        )
        np.testing.assert_array_equal(got.panel, ref.panel)
        np.testing.assert_allclose(got.residual_m, ref.residual_m, rtol=0.0, atol=1e-9)
    assert converged >= len(cases) // 2
    # no return at all, with or without their (no) angles: no match, the start kept
    pts, start, panels, gates, near, _ = cases[0]
    for angles in (None, np.zeros(0)):
        empty = icp_point_to_line(
            np.zeros((0, 2)), start, panels, gates_m=gates, subset=near, angles=angles
        )
        assert empty.pose == start
        assert empty.panel.size == 0


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    first=st.floats(-10.0, 10.0),
    turn=st.sampled_from([math.radians(270.0), 2 * math.pi + 5e-7, math.radians(90.0)]),
    reach=st.sampled_from([0.0, 0.03, 0.3, 1.05, 40.0]),
    utm=st.booleans(),
)
def test_bearing_windows_find_what_a_pass_over_every_beam_finds(
    seed: int, first: float, turn: float, reach: float, utm: bool
) -> None:
    """Testing each panel only on the beams that can reach it (by bearing) finds the
    same returns within reach, the same pairs and the same matches as testing every
    return against every panel: scans of any span starting at any angle (a turn apart
    is the same bearing), panels all round, at UTM-sized coordinates, the scanner
    beside a panel or on it."""
    from mast.core import _kernels as k

    rng = np.random.default_rng(seed)
    origin = np.array([500_000.0, 7_000_000.0]) if utm else np.zeros(2)
    n_panels = 40
    a = origin + rng.uniform(-6.0, 6.0, size=(n_panels, 2))
    heading = rng.uniform(0.0, 2 * math.pi, size=n_panels)
    direction = np.column_stack([np.cos(heading), np.sin(heading)])
    normal = np.column_stack([-direction[:, 1], direction[:, 0]])
    length = rng.uniform(0.05, 2.0, size=n_panels)
    n = 700
    angles = np.sort(first + rng.uniform(0.0, turn, size=n))
    angles = np.unique(angles)
    ranges = rng.uniform(0.05, 9.0, size=angles.size)
    pts = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
    pose = Pose2D(*(origin + rng.uniform(-3.0, 3.0, size=2)), rng.uniform(0.0, 2 * math.pi))
    if rng.random() < 0.2:  # the scanner on a panel
        pose = Pose2D(*(a[0] + 0.3 * length[0] * direction[0]), pose.azimuth)
    m = np.empty_like(pts)
    k._to_mine_jit(pts, pose.easting, pose.northing, pose.azimuth, m)
    panels = rng.permutation(n_panels)[: rng.integers(0, n_panels + 1)].astype(np.intp)
    args = (pose.easting, pose.northing, pose.azimuth, a, direction, normal, length, panels)
    near, reached = k.within(m, a, direction, normal, length, panels, reach)
    b_near, b_reached, ptr, pair_point = k._pairs_by_bearing_jit(m, angles, *args, reach)
    np.testing.assert_array_equal(b_near, near)
    np.testing.assert_array_equal(b_reached, reached)
    # the pairs: each reached panel's returns within reach, in increasing order
    assert ptr.size == np.count_nonzero(reached) + 1
    for j, q in enumerate(panels[reached]):
        one, _ = k.within(m, a, direction, normal, length, np.array([q]), reach)
        np.testing.assert_array_equal(pair_point[ptr[j] : ptr[j + 1]], np.flatnonzero(one))
    idx, dist = k.associate(m, a, direction, normal, length, panels, np.array([reach]))
    b_idx, b_dist = k._associate_by_bearing_jit(m, angles, *args, reach)
    np.testing.assert_array_equal(b_idx, idx)
    np.testing.assert_array_equal(b_dist, dist)
    # the matches over the pairs of the panels reached
    p_idx, p_dist = np.empty(m.shape[0], dtype=np.intp), np.empty(m.shape[0])
    k._associate_pairs_jit(
        m, a, direction, normal, length, panels[reached], reach, ptr, pair_point, p_idx, p_dist
    )
    np.testing.assert_array_equal(p_idx, idx)
    np.testing.assert_array_equal(p_dist, dist)


def test_within_kernel_matches_the_reference() -> None:
    panels = PanelSet.from_survey(paper_scene().survey)
    rng = np.random.default_rng(2)
    lo, hi = panels.a.min(axis=0) - 1.0, panels.a.max(axis=0) + 1.0
    pts = np.vstack([rng.uniform(lo, hi, size=(5000, 2)), panels.a, panels.b])
    for subset in (None, np.arange(len(panels))[1::2], np.zeros(0, dtype=np.intp)):
        for reach in (0.0, 0.05, 0.3, 5.0):
            near, reached = panels.within(pts, reach, subset=subset)
            ref_near, ref_reached = panels._within_reference(pts, reach, subset=subset)
            np.testing.assert_array_equal(near, ref_near)
            np.testing.assert_array_equal(reached, ref_reached)
    assert np.any(panels.within(pts, 0.05)[0])
    assert not np.all(panels.within(pts, 0.05)[0])


def test_reach_tallies_kernel_matches_the_reference() -> None:
    panels = PanelSet.from_survey(paper_scene().survey)
    rng = np.random.default_rng(3)
    lo, hi = panels.a.min(axis=0) - 1.0, panels.a.max(axis=0) + 1.0
    pts = np.vstack([rng.uniform(lo, hi, size=(3000, 2)), panels.a, panels.b])
    ranges = rng.uniform(0.0, 30.0, size=len(pts))
    seen = 0
    for subset in (None, np.arange(len(panels))[1::2], np.zeros(0, dtype=np.intp)):
        for reach, per_range, after in (
            (0.0, 0.0, 0.0),
            (0.05, 0.0, 0.04),
            (0.3, 0.01, 0.0),
            (1.0, 0.05, 0.04),
        ):
            got = panels.reach_tallies(pts, ranges, reach, per_range, after, subset=subset)
            ref = panels._reach_tallies_reference(
                pts, ranges, reach, per_range, after, subset=subset
            )
            for g, r in zip(got, ref, strict=True):
                np.testing.assert_array_equal(g, r)
            seen += int(got[2].sum())
    # a point near two panels of one beacon counts once for it, and once for each panel
    per_panel, beacons, per_beacon = panels.reach_tallies(pts, ranges, 1e6, 0.0)
    np.testing.assert_array_equal(beacons, np.arange(len(panels.ids)))
    np.testing.assert_array_equal(per_beacon, np.full(len(panels.ids), len(pts)))
    np.testing.assert_array_equal(per_panel, np.full(len(panels), len(pts)))
    assert seen > 0


def test_beacons_in_reach_of_many_starts_are_in_reach_of_each() -> None:
    """The look-alikes' bound for every start in one compiled call (each beacon tested on
    the beams pointing its way, counting stopped once it has enough) finds the beacons
    ``_in_reach`` finds for each start alone: starts on a real scan's truth, near it,
    far off, turned round, and scans starting anywhere in the turn."""
    from mast.pipeline.verification import VerificationConfig, _beacons_in_reach, _in_reach

    scene = paper_scene()
    panels = PanelSet.from_survey(scene.survey)
    cfg = VerificationConfig()
    rng = np.random.default_rng(12)
    found = shorter = 0
    for k, shot in enumerate(scene.shots[:4]):
        scan = simulate_scan(scene.world, shot.pose, shot.scanner, rng=rng).scan
        beams, pts = scan.points()
        angles = scan.angles_rad[beams]
        if k % 2:  # the same returns, their beams' angles a turn on
            angles = angles + 2.0 * math.pi
        ranges = np.hypot(pts[:, 0], pts[:, 1])
        starts = [shot.pose]
        for _ in range(40):
            off = rng.normal(0.0, [0.3, 0.3, 0.05]) * rng.choice([0.1, 1.0, 30.0])
            starts.append(
                Pose2D(
                    shot.pose.easting + off[0],
                    shot.pose.northing + off[1],
                    (shot.pose.azimuth + off[2] + rng.choice([0.0, math.pi])) % math.tau,
                )
            )
        nears = [panels.near(p.position, scan.range_max_m + 1.0) for p in starts]
        got = _beacons_in_reach(starts, nears, pts, angles, ranges, panels, 0.05, cfg)
        # Cut short: the same answers to "are its own beacons all in it" and "has it
        # enough", with one own beacon, two (one repeated) or none.
        ids = scene.survey.ids
        owns = [
            [ids[int(rng.integers(len(ids)))] for _ in range(int(rng.integers(0, 3)))]
            for _ in starts
        ]
        owns[0] = [ids[0], ids[0]]
        for enough in (1, 2, 3):
            short = _beacons_in_reach(
                starts, nears, pts, angles, ranges, panels, 0.05, cfg, owns=owns, enough=enough
            )
            for own, full, cut in zip(owns, got, short, strict=True):
                assert cut <= full
                assert (set(own) <= cut) == (set(own) <= full)
                if set(own) <= full:
                    assert (len(cut) >= enough) == (len(full) >= enough)
                    shorter += len(cut) < len(full)
        for start, near, g in zip(starts, nears, got, strict=True):
            assert g == _in_reach(start, pts, ranges, panels, near, 0.05, cfg)
            found += len(g)
    assert found > 0
    assert shorter > 0
    assert _beacons_in_reach([], [], pts, angles, ranges, panels, 0.05, cfg) == []
    none = np.zeros((0, 2))
    away = [Pose2D(p.easting + 100.0, p.northing, p.azimuth) for p in starts[:3]]
    nears = [panels.near(p.position, 200.0) for p in away]
    got = _beacons_in_reach(away, nears, none, np.zeros(0), np.zeros(0), panels, 0.05, cfg)
    assert got == [frozenset()] * 3


def test_near_many_is_near_of_each_position() -> None:
    """The batched look-up (a k-d tree query for a mine's survey, a distance table for a
    small one) gives each position the panels :meth:`PanelSet.near` gives it, in order."""
    from mast.core.beacon import Beacon, Survey

    small = paper_scene().survey
    rng = np.random.default_rng(8)
    shapes = [b.edges - b.centroid for b in small]
    big = Survey(
        [
            Beacon(f"C{k}", shapes[k % len(shapes)] + rng.uniform(-400.0, 400.0, size=2))
            for k in range(400)
        ]
    )
    for survey in (small, big):
        panels = PanelSet.from_survey(survey)
        lo, hi = panels.a.min(axis=0), panels.a.max(axis=0)
        positions = rng.uniform(lo, hi, size=(50, 2))
        for radius in (0.0, 5.0, 40.0):
            got = panels.near_many(positions, radius)
            assert len(got) == len(positions)
            for p, g in zip(positions, got, strict=True):
                np.testing.assert_array_equal(g, panels.near(p, radius))
        assert panels.near_many(np.zeros((0, 2)), 10.0) == []
    assert sum(g.size for g in PanelSet.from_survey(big).near_many(positions, 40.0)) > 0


def test_first_hits_kernel_matches_the_reference() -> None:
    from mast.core.geometry import _first_hits_reference, first_hits

    rng = np.random.default_rng(4)
    seg_a = rng.uniform(-10, 10, (30, 2))
    seg_b = seg_a + rng.normal(0, 2, (30, 2))
    # A segment through the origin, one parallel to a ray, a degenerate one.
    seg_a = np.vstack([seg_a, [[-1.0, 0.0], [1.0, 1.0], [3.0, 3.0]]])
    seg_b = np.vstack([seg_b, [[1.0, 0.0], [5.0, 1.0], [3.0, 3.0]]])
    ang = np.concatenate([rng.uniform(-np.pi, np.pi, 2000), [0.0, np.pi / 2]])
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    for origin in (np.zeros(2), np.array([0.3, -0.2]), np.array([4e5, 7e6])):
        t, j = first_hits(origin, dirs, seg_a + origin, seg_b + origin)
        ref_t, ref_j = _first_hits_reference(origin, dirs, seg_a + origin, seg_b + origin)
        np.testing.assert_array_equal(j, ref_j)
        np.testing.assert_array_equal(t, ref_t)
        assert np.any(j >= 0)
        assert np.any(j < 0)
    empty_t, empty_j = first_hits(np.zeros(2), dirs, np.zeros((0, 2)), np.zeros((0, 2)))
    assert np.all(np.isinf(empty_t))
    assert np.all(empty_j == -1)


def _assert_same_checks(got: dict[str, Any], ref: dict[str, Any]) -> None:
    """The compiled beam checks give the reference's verdicts, beacon by beacon."""
    assert got.keys() == ref.keys()
    for b, c in ref.items():
        g = got[b]
        assert (g.hit, g.occluded, g.through, g.missing, g.near) == (
            c.hit,
            c.occluded,
            c.through,
            c.missing,
            c.near,
        )
        assert g.log_likelihood == pytest.approx(c.log_likelihood, rel=1e-12, abs=1e-9)


def test_beam_check_kernel_matches_the_reference() -> None:
    from mast.core.noise import NoiseModel
    from mast.pipeline.verification import (
        VerificationConfig,
        _check_beams_reference,
        check_beams,
    )

    scene = paper_scene()
    panels = PanelSet.from_survey(scene.survey)
    strict = VerificationConfig()
    lenient = replace(strict, wall_behind_m=0.15)  # a plan view's (locator3d)
    rng = np.random.default_rng(3)
    near_seen = 0
    through = {strict: 0, lenient: 0}
    for k, shot in enumerate(scene.shots[:6]):
        scan = simulate_scan(scene.world, shot.pose, shot.scanner, rng=rng).scan
        for dx, dy, da in ((0.0, 0.0, 0.0), (0.03, -0.02, 0.004), (0.5, 0.3, -0.05)):
            pose = Pose2D(shot.pose.easting + dx, shot.pose.northing + dy, shot.pose.azimuth + da)
            for subset in (None, np.arange(len(panels))[k % 2 :: 2]):
                noise = NoiseModel(range_sigma_m=0.01)
                for cfg in (strict, lenient):
                    got = check_beams(scan, pose, panels, noise, cfg, subset=subset)
                    ref = _check_beams_reference(scan, pose, panels, noise, cfg, subset=subset)
                    _assert_same_checks(got, ref)
                    near_seen += sum(c.near for c in ref.values())
                    through[cfg] += sum(c.through for c in ref.values())
    assert near_seen > 0  # returns just short of a panel were counted and compared
    # the poses off put panels before walls: some beams through them land on the wall
    assert 0 < through[lenient] < through[strict]


def test_a_panels_chord_is_its_beacons_e1_to_e4_whatever_the_panels_order() -> None:
    """``PanelSet.chords`` (the wall ``wall_behind_m`` measures from) gives each panel
    its own beacon's first and last edges, with the panels in survey order and shuffled."""
    scene = paper_scene()
    panels = PanelSet.from_survey(scene.survey)
    edges = [b.edges for b in scene.survey]
    shuffled = np.random.default_rng(5).permutation(len(panels))
    mixed = PanelSet(
        *(getattr(panels, f)[shuffled] for f in ("a", "b", "direction", "normal", "length")),
        panels.beacon[shuffled],
        panels.panel[shuffled],
        panels.ids,
    )
    for ps in (panels, mixed):
        a, b = ps.chords
        for k in range(len(ps)):
            e = edges[int(ps.beacon[k])]
            assert np.array_equal(a[k], e[0])
            assert np.array_equal(b[k], e[3])


def test_a_beam_onto_a_beacons_own_wall_is_no_verdict_where_asked() -> None:
    """With ``wall_behind_m``, a beam beyond a panel that lands on the line of its
    beacon's free ends (the wall it stands on: in a plan view of a 3D frame, a ring that
    passed over or under the beacon) is missing, not through; one landing a metre
    beyond that wall is through either way; without it, both are through."""
    from mast.core.geometry import first_hits
    from mast.core.noise import NoiseModel
    from mast.core.scan import Scan
    from mast.pipeline.verification import VerificationConfig, _check_beams_reference, check_beams

    scene = paper_scene()
    panels = PanelSet.from_survey(scene.survey)
    pose = scene.shots[0].pose
    angles = np.linspace(-math.pi, math.pi, 1440, endpoint=False)
    dirs = pose.beam_directions(angles)
    t, which = first_hits(pose.position, dirs, panels.a, panels.b)
    crossing = np.flatnonzero(which >= 0)
    # each beam that crosses a panel: how far to its beacon's chord e1-e4
    first = {int(b): int(np.flatnonzero(panels.beacon == b)[0]) for b in set(panels.beacon)}
    last = {int(b): int(np.flatnonzero(panels.beacon == b)[-1]) for b in set(panels.beacon)}
    to_wall = np.full(angles.size, np.nan)
    for i in crossing:
        b = int(panels.beacon[which[i]])
        e1, e4 = panels.a[first[b]], panels.b[last[b]]
        c = e4 - e1
        normal = np.array([-c[1], c[0]]) / np.hypot(*c)
        to_wall[i] = float((e1 - pose.position) @ normal) / float(dirs[i] @ normal)
    behind = crossing[to_wall[crossing] > t[crossing] + 0.05]  # the wall well behind
    assert behind.size > 20
    noise = NoiseModel(range_sigma_m=0.01)
    strict = VerificationConfig()
    lenient = replace(strict, wall_behind_m=0.15)
    for past in (0.0, 1.0):
        ranges = np.full(angles.size, np.nan)
        ranges[behind] = to_wall[behind] + past
        scan = Scan(angles, ranges)
        tally = {}
        for cfg in (strict, lenient):
            got = check_beams(scan, pose, panels, noise, cfg)
            _assert_same_checks(got, _check_beams_reference(scan, pose, panels, noise, cfg))
            tally[cfg] = [sum(getattr(c, v) for c in got.values()) for v in ("through", "missing")]
            assert sum(c.hit + c.occluded for c in got.values()) == 0
        checked = tally[strict][0]  # those at a panel's ends or grazing it are not
        assert checked > 0.9 * behind.size
        assert tally[lenient] == ([0, checked + tally[strict][1]] if past == 0.0 else tally[strict])


@pytest.mark.parametrize("turn", [0.0, 2.0 * math.pi, 0.75 * math.pi, -0.25 * math.pi])
def test_beam_checks_by_the_angle_each_panel_spans_are_the_reference(turn: float) -> None:
    """Each panel is crossed only by the beams within the angle it spans from the scanner;
    testing it on those alone gives the reference's verdicts for scans whose beam angles
    start anywhere in the turn, from poses near, far and turned round."""
    from mast.core.noise import NoiseModel
    from mast.core.scan import Scan
    from mast.pipeline.verification import VerificationConfig, _check_beams_reference, check_beams

    scene = paper_scene()
    panels = PanelSet.from_survey(scene.survey)
    cfg = VerificationConfig()
    noise = NoiseModel(range_sigma_m=0.01)
    rng = np.random.default_rng(21)
    hits = 0
    for shot in scene.shots[:4]:
        sim = simulate_scan(scene.world, shot.pose, shot.scanner, rng=rng).scan
        # The same beams, their angles a part of a turn on (the pose turned to match).
        scan = Scan(sim.angles_rad + turn, sim.ranges_m, None, sim.range_min_m, sim.range_max_m)
        for dx, dy, da in (
            (0.0, 0.0, 0.0),
            (0.4, -0.3, 0.02),
            (8.0, 5.0, 2.5),
            (0.0, 0.0, math.pi),
        ):
            pose = Pose2D(
                shot.pose.easting + dx,
                shot.pose.northing + dy,
                (shot.pose.azimuth + turn + da) % math.tau,
            )
            ref = _check_beams_reference(scan, pose, panels, noise, cfg)
            _assert_same_checks(check_beams(scan, pose, panels, noise, cfg), ref)
            hits += sum(c.hit for c in ref.values())
    assert hits > 0


def test_first_same_kernel_matches_the_reference() -> None:
    import math

    from mast.core.pose import Pose2D
    from mast.pipeline.verification import VerificationConfig, _PoseList

    rng = np.random.default_rng(5)
    cfg = VerificationConfig()
    poses = _PoseList(cfg)
    base = np.array([7000.0, 6800.0, 1.0])
    for k in range(60):
        poses.add(Pose2D(*(base + rng.normal(0.0, [0.03, 0.03, 0.004]))))
        if k % 7 == 3:
            poses.forget(k)
    poses.add(Pose2D(7000.0, 6800.0, 2 * math.pi - 1e-4))  # the same across north
    found = 0
    for _ in range(2000):
        q = Pose2D(*(base + rng.normal(0.0, [0.05, 0.05, 0.006])))
        got = poses.first_same(q)
        assert got == poses._first_same_reference(q)
        found += got is not None
    wrapped = Pose2D(7000.0, 6800.0, 1e-4)
    assert poses.first_same(wrapped) == poses._first_same_reference(wrapped) == 60
    assert 0 < found < 2000


def test_tallies_are_numpy_unique_of_the_matched() -> None:
    """The panels' tallies of an ICP's matches (kernels.tallies) are numpy.unique's of the
    entries >= 0, with their counts: none, all unmatched, one, and many repeated."""
    from mast.core._kernels import tallies

    rng = np.random.default_rng(3)
    cases = [np.zeros(0, dtype=np.intp), np.full(5, -1, dtype=np.intp), np.array([7])]
    cases += [rng.integers(-1, k, size=n).astype(np.intp) for k, n in ((3, 40), (500, 300))]
    for values in cases:
        want = np.unique(values[values >= 0], return_counts=True)
        got = tallies(values)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)


def test_pose_step_is_the_least_squares_solution_and_declines_when_singular() -> None:
    from mast.core._kernels import _normal_step_jit
    from mast.core.linalg import pose_step

    rng = np.random.default_rng(5)
    for n in (3, 10, 400):
        # a pose step's columns: a panel's normal, and the normal across the range
        ang = rng.uniform(-np.pi, np.pi, n)
        r = rng.uniform(0.5, 30.0, n)
        design = np.column_stack([np.cos(ang), np.sin(ang), r * rng.uniform(-1, 1, n)])
        rhs = rng.normal(scale=0.01, size=n)
        want = np.linalg.lstsq(design, rhs, rcond=None)[0]
        np.testing.assert_allclose(pose_step(design, rhs), want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(_normal_step_jit(design, rhs, n), want, rtol=0, atol=1e-12)
    # every return on one line: the step along it is free; lstsq's minimum-norm answer
    flat = np.column_stack([np.zeros(5), np.ones(5), np.arange(5.0)])
    rhs = np.arange(5.0) * 0.01
    assert np.isnan(_normal_step_jit(flat, rhs, 5)).all()
    np.testing.assert_allclose(
        pose_step(flat, rhs), np.linalg.lstsq(flat, rhs, rcond=None)[0], atol=1e-15
    )


@pytest.mark.parametrize("noise_m", [None, 0.01])
def test_runs_and_noise_kernels_match_the_reference_on_scans(noise_m: float | None) -> None:
    """Breakpoints, runs and the noise estimate compiled: the same to the bit."""
    cfg = seg.SegmentationConfig(noise_m=noise_m)
    for scan in _scan_objects():
        beams, pts = scan.points()
        got_ids, got_noise = seg._runs(scan, beams, pts, cfg)
        want_ids, want_noise = seg._runs_reference(scan, beams, pts, cfg)
        np.testing.assert_array_equal(got_ids, want_ids)
        assert got_noise == want_noise
        assert lines.range_noise_from_triples(
            pts, got_ids
        ) == lines.range_noise_from_triples_reference(pts, got_ids)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 300),
    seed=st.integers(0, 2**32 - 1),
    corners=st.integers(0, 5),
    sigma=st.sampled_from([0.0, 1e-3, 0.02]),
    cut=st.integers(1, 50),
)
def test_noise_estimate_kernel_matches_the_reference_on_polylines(
    n: int, seed: int, corners: int, sigma: float, cut: int
) -> None:
    pts = _polyline(n, seed, corners, sigma, 8.0)
    ids = np.arange(n, dtype=np.intp) // cut  # runs of ``cut`` returns
    assert lines.range_noise_from_triples(pts, ids) == lines.range_noise_from_triples_reference(
        pts, ids
    )


@pytest.mark.parametrize("scale", [1e-277, 1e-160, 1e150])
def test_noise_estimate_kernel_matches_the_reference_where_products_overflow_or_vanish(
    scale: float,
) -> None:
    """Returns so close together (or so far) that a product of two distances is 0 (or
    inf): the quotients are numpy's, inf or nan, not an error."""
    pts = _polyline(60, 4, 2, 0.02, 8.0) * scale
    ids = np.zeros(60, dtype=np.intp)
    with np.errstate(all="ignore"):
        want = lines.range_noise_from_triples_reference(pts, ids)
    got = lines.range_noise_from_triples(pts, ids)
    assert got == want or (math.isnan(got) and math.isnan(want))


@settings(max_examples=200, deadline=None)
@given(
    values=st.lists(
        st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_subnormal=False),
        min_size=1,
        max_size=40,
    )
)
def test_linear_median_is_numpys_quantile(values: list[float]) -> None:
    from mast.core._kernels import linear_median

    v = np.array(values)
    assert linear_median(v.copy()) == np.quantile(v, 0.5)
