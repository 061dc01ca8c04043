"""The prior's grid search: its tiled likelihood field against the field over the whole box."""

from __future__ import annotations

import math

import numpy as np

from mast.core.geometry import PanelSet
from mast.pipeline.tracking import _likelihood_field, _TiledField
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
