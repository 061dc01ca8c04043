"""Where two fitted lines meet, and how well: the node covariance against Monte Carlo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.pipeline.hypotheses import corner_covariance, major_sigma
from mast.pipeline.segmentation import _make_segment


def _segment(points: np.ndarray, noise: float, index: int = 0):  # type: ignore[no-untyped-def]
    return _make_segment(index, 0, np.arange(len(points)), points, noise)


def _corner(a_dir: float, b_dir: float, n: int, rng: np.random.Generator, noise: float):  # type: ignore[no-untyped-def]
    """Two straight runs of returns meeting at (4, 1), ranges noisy by ``noise``."""
    node = np.array([4.0, 1.0])
    t = np.linspace(0.05, 0.6, n)
    ua = np.array([math.cos(a_dir), math.sin(a_dir)])
    ub = np.array([math.cos(b_dir), math.sin(b_dir)])
    a = node - t[::-1, None] * ua
    b = node + t[:, None] * ub

    def noisy(p: np.ndarray) -> np.ndarray:
        r = np.hypot(*p.T)
        return p * ((r + noise * rng.standard_normal(len(r))) / r)[:, None]

    return _segment(noisy(a), noise), _segment(noisy(b), noise, 1), node


def _meet(a, b) -> np.ndarray:  # type: ignore[no-untyped-def]
    nmat = np.array([a.normal, b.normal])
    return np.linalg.solve(nmat, [a.normal @ a.centroid, b.normal @ b.centroid])


@pytest.mark.parametrize("turn_deg", [90.0, 30.0, 150.0])
def test_corner_covariance_matches_the_scatter_of_intersections(turn_deg: float) -> None:
    rng = np.random.default_rng(4)
    noise = 0.01
    nodes, covs = [], []
    for _ in range(600):
        a, b, _node = _corner(1.2, 1.2 + math.radians(turn_deg), 40, rng, noise)
        at = _meet(a, b)
        nodes.append(at)
        covs.append(corner_covariance(a, b, at, noise))
    scatter = np.cov(np.array(nodes).T)
    predicted = np.mean(covs, axis=0)
    # Never optimistic (beyond Monte Carlo error, ~6 % for 600 draws), and not much
    # wider: the range noise bounds the noise across each line (face-on beams).
    ratio = np.trace(predicted) / np.trace(scatter)
    assert 0.85 <= ratio <= 2.0
    assert 0.9 <= major_sigma(predicted) / major_sigma(scatter) <= 1.5


def test_corner_covariance_equals_the_matrix_formula() -> None:
    rng = np.random.default_rng(1)
    for turn in (90.0, 10.0, 0.01):  # the last nearly parallel: regularised, still finite
        a, b, node = _corner(0.3, 0.3 + math.radians(turn), 20, rng, 0.005)
        nmat = np.array([a.normal, b.normal])
        if abs(np.linalg.det(nmat)) < 1e-3:
            nmat = nmat + np.array([[0.0, 0.0], [1e-3, 0.0]])
        inv = np.linalg.inv(nmat)

        var = [
            0.005**2 / len(s) + (float((node - s.centroid) @ s.direction) * s.sigma_direction) ** 2
            for s in (a, b)
        ]
        ref = inv @ np.diag(var) @ inv.T
        got = corner_covariance(a, b, node, 0.005)
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=0)
        assert np.all(np.isfinite(got))
        assert major_sigma(got) == pytest.approx(math.sqrt(np.linalg.eigvalsh(ref)[-1]), rel=1e-10)


def _drive_and_mine(scans: int, **mine: bool):  # type: ignore[no-untyped-def]
    """A simulated drive of ``scans`` scans and a mine of 300 beacons more, out of its
    sight (:func:`~mast.bench.minewide.minewide_survey`'s options in ``mine``)."""
    from mast.bench.minewide import minewide_survey
    from mast.sim.drive import drive_scene

    scene = drive_scene(3, scans=scans)
    poses = [s.pose for s in scene.shots]
    rng = np.random.default_rng(5)
    return scene, minewide_survey(
        scene.survey, poses, copies=300, clearance_m=60.0, rng=rng, **mine
    )


@pytest.mark.parametrize("distinct", [False, True])
def test_design_pairs_for_every_pair_of_candidates_at_once_match_one_at_a_time(
    distinct: bool,
) -> None:
    """The corner-free stage's look-up of the design pairs surveyed at about each pair of
    candidate middle panels' distance gives, for all pairs at once, the rows the look-up
    one pair at a time gives, in its order: drive scans against their survey and against
    a mine of 300 beacons of repeated or of distinct designs."""
    from mast.core.index import SurveyIndex
    from mast.pipeline.hypotheses import HypothesisConfig, _design_pairs, _design_pairs_reference
    from mast.pipeline.segmentation import segment_scan

    scene, mine = _drive_and_mine(120, distinct=distinct)
    config = HypothesisConfig()
    compared = rows = 0
    for survey in (scene.survey, mine):
        index = SurveyIndex.from_survey(survey)
        lengths, _ = index.middle_panels
        for k, sim in enumerate(scene.iter_simulated()):
            if k % 4:
                continue
            seg = segment_scan(sim.scan)
            cands = []
            for s in seg.segments:
                fits = np.flatnonzero(
                    (config.panel_short_fraction * lengths <= s.length)
                    & (s.length <= lengths + config.panel_long_m)
                )
                if fits.size and len(s) >= config.panel_min_points:
                    cands.append((s, fits))
            apart = [
                (i, j, float(np.hypot(*(cands[j][0].midpoint - cands[i][0].midpoint))))
                for i in range(len(cands))
                for j in range(i + 1, len(cands))
            ]
            noise = config.sigmas * seg.noise_m
            got = _design_pairs(apart, cands, index, noise)
            want = _design_pairs_reference(apart, cands, index, noise)
            for g, w in zip(got, want, strict=True):
                if np.issubdtype(np.asarray(w).dtype, np.floating):
                    # to rounding: numpy's vectorised loops differ from its one-element
                    # ones by an ulp or so on some processors (AVX-512 here)
                    np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12)
                else:
                    np.testing.assert_array_equal(g, w)
            compared += 1
            rows += got[0].size
    assert compared >= 50
    assert rows > 0


@pytest.mark.parametrize(("distinct", "survey_sigma_m"), [(False, 0.0), (True, 0.005)])
def test_readings_of_every_node_pair_at_once_match_one_pair_at_a_time(
    distinct: bool, survey_sigma_m: float
) -> None:
    """The survey's readings of a scan's node pairs, taken for every pair at once, are
    those taken one pair at a time, in their order (integers exactly, floats to
    rounding): drive scans against their survey and against a mine of 300 beacons of
    repeated or of distinct designs (so that pairs of keys are looked up both ways
    round)."""
    import functools

    from mast.core.index import SurveyIndex
    from mast.pipeline.hypotheses import (
        HypothesisConfig,
        _PanelsSeen,
        _readings,
        _readings_reference,
        node_covariance,
    )
    from mast.pipeline.identification import identify_panels
    from mast.pipeline.segmentation import segment_scan

    scene, mine = _drive_and_mine(120, distinct=distinct)
    config = HypothesisConfig()
    compared = rows = ones = 0
    for survey in (scene.survey, mine):
        index = SurveyIndex.from_survey(survey)
        for k, sim in enumerate(scene.iter_simulated()):
            if k % 4:
                continue
            seg = segment_scan(sim.scan)
            nodes = identify_panels(seg, index.representatives).nodes
            covs = np.array([node_covariance(n, seg) for n in nodes]).reshape(-1, 2, 2)
            seen = functools.cache(lambda i: _PanelsSeen.of(nodes[i], seg))  # noqa: B023
            got = _readings(nodes, covs, seen, index, config, survey_sigma_m)
            want = _readings_reference(nodes, covs, seen, index, config, survey_sigma_m)
            for g, w in zip(got, want, strict=True):
                if np.issubdtype(np.asarray(w).dtype, np.floating):
                    # to rounding: numpy's vectorised loops differ from its one-element
                    # ones by an ulp or so on some processors (AVX-512 here)
                    np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12)
                else:
                    np.testing.assert_array_equal(g, w)
            compared += 1
            rows += got[0].size
            ones += int(np.count_nonzero(got[0]))
    assert compared >= 50
    assert rows > ones > 0


@pytest.mark.parametrize(("cap", "blind"), [(90, False), (5, False), (1, True), (0, False)])
def test_single_node_hypotheses_take_turns_over_every_look_alike(cap: int, blind: bool) -> None:
    """Each single-node hypothesis puts its node on the edge of the beacon it is taken
    for, turned by its panels' rotations averaged by their weights, its spread the node's
    ellipse plus that rotation's error over twice its range; the nodes take turns
    (lowest Table 1 option first), each over every beacon of its design in the survey's
    order, up to the cap; a node without an identified panel (``blind``: the first one
    made so) takes no turn: drive scans against a mine of 300 copies of their beacons,
    listed first, so that each node's design has dozens of look-alikes."""
    from dataclasses import replace

    from mast.core.index import SurveyIndex
    from mast.core.pose import wrap_angles
    from mast.pipeline.hypotheses import HypothesisConfig, node_covariance, pose_hypotheses
    from mast.pipeline.identification import PanelIdentification, identify_panels
    from mast.pipeline.segmentation import segment_scan

    scene, mine = _drive_and_mine(40, copies_first=True)
    index = SurveyIndex.from_survey(mine)
    config = HypothesisConfig(max_single_hypotheses=cap)
    checked = later = 0
    for k, sim in enumerate(scene.iter_simulated()):
        if k % 4:
            continue
        seg = segment_scan(sim.scan)
        ident = identify_panels(seg, index.representatives)
        if blind and ident.nodes:
            first = min(range(len(ident.nodes)), key=lambda i: ident.nodes[i].option)
            nodes_ = list(ident.nodes)
            nodes_[first] = replace(nodes_[first], identified=(False, False))
            ident = PanelIdentification(tuple(nodes_), ident.singles)
        nodes = ident.nodes
        made = pose_hypotheses(ident, seg, index, config)
        singles = [h for h in made if h.kind == "single"]
        # the order: a round over the nodes with a panel (by option), each its next beacon
        queues = []
        for n in sorted(nodes, key=lambda n: n.option):
            if any(n.identified):
                queues.append([(n, b) for b in index.beacons_like(n.beacon)])
        want = []
        while queues and len(want) < config.max_single_hypotheses:
            for q in queues:
                if q:
                    want.append(q.pop(0))
            queues = [q for q in queues if q]
        want = want[: config.max_single_hypotheses]
        assert len(singles) == len(want)
        for h, (n, b) in zip(singles, want, strict=True):
            (got,) = h.nodes
            assert (got.beacon, got.edge, got.segments) == (b, n.edge, n.segments)
            # the rotation: each panel's, averaged by its direction's weight
            beacon = mine[b]
            turns = []
            weights = []
            for s, panel, ok in zip(n.segments, n.panels, n.identified, strict=True):
                if ok:
                    d = seg.segments[s].direction
                    e0, e1 = beacon.edges[panel - 1], beacon.edges[panel]
                    mine_angle = math.atan2(e1[1] - e0[1], e1[0] - e0[0]) + (
                        0 if n.forward else math.pi
                    )
                    turns.append(mine_angle - math.atan2(d[1], d[0]))
                    weights.append(1.0 / max(seg.segments[s].sigma_direction, 1e-9) ** 2)
            turns_ = wrap_angles(np.array(turns))
            mean = turns_[0] + np.sum(np.array(weights) * wrap_angles(turns_ - turns_[0])) / sum(
                weights
            )
            assert math.remainder(h.similarity.rotation_rad - mean, 2 * math.pi) == pytest.approx(
                0.0, abs=1e-12
            )
            c, s_ = math.cos(mean), math.sin(mean)
            placed = np.array([[c, -s_], [s_, c]]) @ n.node_scanner + h.similarity.translation
            np.testing.assert_allclose(placed, beacon.edges[n.edge - 1], rtol=0, atol=1e-8)
            spread = major_sigma(node_covariance(n, seg)) + 2.0 * float(
                np.hypot(*n.node_scanner)
            ) / math.sqrt(sum(weights))
            assert h.spread_m == pytest.approx(spread, rel=1e-12)
            checked += 1
            later += got.beacon != index.beacons_like(n.beacon)[0]
    if cap == 0:
        assert checked == 0
    else:
        assert checked > {90: 100, 5: 40, 1: 8}[cap]
    if cap == 90:
        assert later > 50
