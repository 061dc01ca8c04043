"""The prior's grid search: its tiled likelihood field against the field over the whole box."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D
from mast.pipeline.alignment import Similarity
from mast.pipeline.hypotheses import Hypothesis
from mast.pipeline.tracking import (
    Prior,
    TrackingConfig,
    _likelihood_field,
    _TiledField,
    _window_grid,
    _window_returns,
    centre_hypotheses,
)
from mast.sim import drive_scene, paper_scene

RES = 0.02
SIGMA = 0.04


def _whole_box(panels: PanelSet) -> tuple[np.ndarray, np.ndarray]:
    """The field over the box of every panel (the reference), and its lower corner."""
    ends = np.concatenate([panels.a, panels.b])
    lo = ends.min(axis=0) - 1.0
    hi = ends.max(axis=0) + 1.0
    shape = (int((hi[0] - lo[0]) / RES) + 1, int((hi[1] - lo[1]) / RES) + 1)
    return _likelihood_field(panels, np.arange(len(panels)), lo, shape, RES, SIGMA), lo


def _tiled(field: _TiledField, pts: np.ndarray) -> np.ndarray:
    """The tiled field at ``pts``: the largest value over the tiles reaching each point."""
    tiles = field.reaching(pts, np.zeros(len(pts)))
    cells = pts / RES
    none = np.zeros((1, 2))
    value = field.lookup(cells, tiles[:, 0], none)[0]
    for slot in range(1, tiles.shape[1]):
        value = np.maximum(value, field.lookup(cells, tiles[:, slot], none)[0])
    return np.asarray(value)


def test_tiles_hold_the_field_wherever_it_is_not_negligible() -> None:
    # Paper layout: beacons close together, so tiles overlap and draw each other's panels.
    panels = PanelSet.from_survey(paper_scene().survey)
    whole, lo = _whole_box(panels)
    field = _TiledField.build(panels, np.arange(len(panels)), RES, SIGMA)
    rng = np.random.default_rng(3)
    on = panels.a + panels.direction * rng.uniform(0, 1, (len(panels), 1)) * panels.length[:, None]
    pts = np.vstack(
        [
            rng.uniform(lo, lo + np.array(whole.shape) * RES, size=(20000, 2)),
            (on[:, None, :] + rng.normal(0.0, 2 * SIGMA, (len(panels), 500, 2))).reshape(-1, 2),
        ]
    )
    got = _tiled(field, pts)
    ij = np.floor((pts - lo) / RES).astype(int)
    ref = whole[ij[:, 0], ij[:, 1]]
    exact = _distance_to_panels(panels, pts)
    # Both rasters place a panel to within a cell: the distance each implies is the
    # true one to within a cell's diagonal, wherever the field is not negligible.
    cutoff = math.exp(-0.5 * 6.0**2)
    for values in (ref, got):
        seen = values > cutoff
        implied = SIGMA * np.sqrt(-2.0 * np.log(values[seen]))
        assert np.max(np.abs(implied - exact[seen])) <= 1.5 * RES
    assert np.count_nonzero(got > 0.5) > 1000  # the test looks where the field is
    # Where the true distance is within the cutoff, the tiles hold the field.
    assert np.all(got[exact < 5.0 * SIGMA] > cutoff)
    assert np.all(got[exact > 6.0 * SIGMA + 2 * RES] <= cutoff)


def _distance_to_panels(panels: PanelSet, pts: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest panel (as a segment), metres."""
    rel = pts[:, None, :] - panels.a[None, :, :]
    t = np.clip(np.einsum("npk,pk->np", rel, panels.direction), 0.0, panels.length[None, :])
    foot = panels.a[None, :, :] + t[:, :, None] * panels.direction[None, :, :]
    return np.asarray(np.min(np.hypot(*(pts[:, None, :] - foot).transpose(2, 0, 1)), axis=1))


def test_tiles_stay_small_when_beacons_are_far_apart() -> None:
    # A drift: beacons tens of metres apart. The whole box would be millions of cells.
    scene = drive_scene(0, scans=2000)
    panels = PanelSet.from_survey(scene.survey)
    ends = np.concatenate([panels.a, panels.b])
    box_cells = np.prod((ends.max(axis=0) - ends.min(axis=0)) / RES)
    field = _TiledField.build(panels, np.arange(len(panels)), RES, SIGMA)
    beacons = len(np.unique(panels.beacon))
    assert box_cells > 1e6
    # Each tile: a beacon (about a metre) widened by the cutoff.
    assert field.values.size < 20_000 * beacons
    assert field.values.size < box_cells / 50


def test_compiled_window_scores_match_the_lookups() -> None:
    panels = PanelSet.from_survey(paper_scene().survey)
    field = _TiledField.build(panels, np.arange(len(panels)), RES, SIGMA)
    rng = np.random.default_rng(5)
    on = panels.a + panels.direction * rng.uniform(0, 1, (len(panels), 1)) * panels.length[:, None]
    pts = (on[:, None, :] + rng.normal(0.0, 0.3, (len(panels), 40, 2))).reshape(-1, 2)
    # Reaches wide enough that returns between the two beacons meet both tiles.
    tiles = field.reaching(pts, np.full(len(pts), 10.0))
    assert tiles.shape[1] >= 2  # some returns reach two tiles: the largest value counts
    shifts = rng.uniform(-0.5, 0.5, (300, 2)) / RES
    got = field.scores(pts / RES, tiles, shifts)
    ref = field.lookup(pts / RES, tiles[:, 0], shifts)
    for slot in range(1, tiles.shape[1]):
        ref = np.maximum(ref, field.lookup(pts / RES, tiles[:, slot], shifts))
    np.testing.assert_allclose(got, ref.sum(axis=1), rtol=1e-12, atol=1e-12)
    assert np.ptp(got) > 1.0  # the translations score differently


def _reference_prior_hypotheses(
    points_scanner: np.ndarray, panels: PanelSet, prior: Prior, range_max_m: float
) -> list[list[Hypothesis]]:
    """``prior_hypotheses`` written plainly: every grid pose of the window scored, kept in
    a Python list, sorted, and picked one at a time against those chosen before."""
    from mast.core._kernels import near_pose

    config = TrackingConfig()
    tol = prior.azimuth_tolerance_rad
    assert tol is not None
    near = panels.near(prior.pose.position, range_max_m + prior.radius_m)
    pts, r = _window_returns(points_scanner, panels, prior, near, tol, config)
    step, res = config.step_m, config.field_resolution_m
    field = _TiledField.build(panels, near, res, sigma=step)
    shifts, d_rot, n_r = _window_grid(prior.radius_m, tol, step, r)
    rot0 = math.pi / 2 - prior.pose.azimuth
    tiles = field.reaching(
        prior.pose.scanner_to_mine(pts), prior.radius_m + r * math.sin(tol) + step + res
    )
    best: list[tuple[float, float, float, float]] = []
    for k in range(-n_r, n_r + 1):
        rot = rot0 + k * d_rot
        c, s = math.cos(rot), math.sin(rot)
        x, y = pts[:, 0], pts[:, 1]
        px, py = prior.pose.position
        cells = np.column_stack([(x * c - y * s + px) / res, (x * s + y * c + py) / res])
        total = field.scores(cells, tiles, shifts / res)
        for t in range(total.size):
            if total[t] > 0.0:  # a pose that puts no return near a panel is no hypothesis
                best.append((float(total[t]), rot, float(shifts[t, 0]), float(shifts[t, 1])))
    best.sort(reverse=True)
    reach = float(np.median(r))
    chosen = np.zeros((2 * config.candidates, 3))
    count = 0

    def pick(apart_m: float) -> list[Hypothesis]:
        nonlocal count
        out: list[Hypothesis] = []
        for total_score, rot, x, y in best:
            if any(near_pose(rot, x, y, chosen[c], apart_m, reach) for c in range(count)):
                continue
            chosen[count] = (rot, x, y)
            count += 1
            t = prior.pose.position + np.array([x, y])
            sim = Similarity(1.0, math.remainder(rot, 2 * math.pi), t, 0.0)
            out.append(Hypothesis((), sim, -total_score, "prior"))
            if len(out) == config.candidates:
                break
        return out

    first = pick(config.distinct_m)
    other = pick(config.other_basins_m)
    return [first, other] if other else [first]


@pytest.mark.parametrize(
    ("radius_m", "tol_deg"), [(0.05, 1.0), (0.12, 2.0), (0.3, 4.0), (1.0, 10.0), (1.9, 14.0)]
)
def test_the_window_search_ranks_and_picks_its_poses_as_the_reference(
    radius_m: float, tol_deg: float
) -> None:
    """Poses found by branch and bound, tiles taken from the cache: the same hypotheses,
    in the same order, to the last bit, as scoring every grid pose in Python, ranking
    them and picking one at a time."""
    from mast.pipeline.tracking import prior_hypotheses

    scene = drive_scene(0, scans=3)
    panels = PanelSet.from_survey(scene.survey)
    rng = np.random.default_rng(3)
    for sim in scene.iter_simulated():
        truth = sim.pose
        prior = Prior(
            Pose2D(
                truth.easting + rng.uniform(-0.5, 0.5) * radius_m,
                truth.northing + rng.uniform(-0.5, 0.5) * radius_m,
                truth.azimuth + math.radians(rng.uniform(-0.5, 0.5) * tol_deg),
            ),
            radius_m,
            math.radians(tol_deg),
        )
        pts = sim.scan.points()[1]
        want = _reference_prior_hypotheses(pts, panels, prior, sim.scan.range_max_m)
        for _ in range(2):  # built, then from the cache
            got = prior_hypotheses(pts, panels, prior, sim.scan.range_max_m)
            assert [len(b) for b in got] == [len(b) for b in want]
            assert len(got[0]) > 0
            for g, w in zip([h for b in got for h in b], [h for b in want for h in b], strict=True):
                assert g.misfit == w.misfit
                assert g.similarity.rotation_rad == w.similarity.rotation_rad
                assert np.array_equal(g.similarity.translation, w.similarity.translation)


def test_a_narrow_window_is_first_searched_from_its_centre_alone() -> None:
    cfg = TrackingConfig()
    for az in (0.0, 1.0, math.radians(359.99), 4.0):
        pose = Pose2D(1234.5, -876.25, az)
        hyps = centre_hypotheses(Prior(pose, 0.06, math.radians(1.1)), cfg)
        assert len(hyps) == 1
        (h,) = hyps
        assert h.kind == "prior"
        assert h.nodes == ()
        start = h.similarity.pose()
        assert (start.easting, start.northing) == (pose.easting, pose.northing)
        assert math.remainder(start.azimuth - az, math.tau) == pytest.approx(0.0, abs=1e-15)
    # A window wider than ICP's reach in either way, or without an azimuth bound: the grid.
    pose = Pose2D(0.0, 0.0, 0.0)
    assert centre_hypotheses(Prior(pose, cfg.direct_radius_m + 0.01, 0.01), cfg) == []
    assert centre_hypotheses(Prior(pose, 0.05, cfg.direct_tolerance_rad + 0.01), cfg) == []
    assert centre_hypotheses(Prior(pose, 0.05, None), cfg) == []


def test_sliding_maxima_bound_each_square_as_the_pyramid_does() -> None:
    """Each cell of a tile's sliding maxima (padded before the tile) is what the window's
    pyramid bound reads for a point whose translations span that many cells from it: at
    least the largest field value over the square within the tile, and no value from
    beyond the square's side either way."""
    from mast.core._kernels import _cells_bound_jit, field_sliding

    panels = PanelSet.from_survey(paper_scene().survey)
    field = _TiledField.build(panels, np.arange(len(panels)), RES, SIGMA)
    widths = np.array([1, 3, 7, 15, 31], dtype=np.intp)
    sliding, starts = field_sliding(field.shape, field.offset, field.pyramid, widths)
    rng = np.random.default_rng(5)
    checked = 0
    for lw, width in enumerate(widths.tolist()):
        pad = width - 1
        for t in range(field.shape.shape[0]):
            w, h = (int(x) for x in field.shape[t])
            tile = field.values[field.offset[t] : field.offset[t] + w * h].reshape(w, h)
            for u, v in zip(
                rng.integers(0, w + pad, 60), rng.integers(0, h + pad, 60), strict=True
            ):
                got = sliding[starts[lw, t] + u * (h + pad) + v]
                cells = np.array([[[u - pad, v - pad]]], dtype=np.int64)
                one = np.array([[t]], dtype=np.intp)
                bound = _cells_bound_jit(
                    cells, one, field.shape, field.offset, field.pyramid, 0, pad, 0, pad
                )
                assert got == bound
                i0, j0 = max(u - pad, 0), max(v - pad, 0)
                i1, j1 = min(u - pad + width, w), min(v - pad + width, h)
                span = max(i1 - i0, j1 - j0)
                assert tile[i0:i1, j0:j1].max() <= got <= tile[i0 : i0 + span, j0 : j0 + span].max()
                checked += 1
    assert checked == 60 * widths.size * field.shape.shape[0]
