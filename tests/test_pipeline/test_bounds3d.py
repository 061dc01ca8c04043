"""The six-parameter bound (pipeline.bounds3d) on the paper's layout ray-cast by a 16-ring
lidar, tilted: its information is the ranges' own (finite differences of each ray's range
to its panel), it moves with the grid, it tightens with more returns, the elevation's
reference is the brackets' uniform variance, and it is the adjustment's covariance on
the same returns, the survey's share included."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mast.core.beacon import Survey
from mast.core.pose3d import Pose3D, rotation_rpy
from mast.pipeline.adjust3d import PanelPlanes, adjust_pose
from mast.pipeline.bounds3d import (
    FIVE,
    Z,
    cramer_rao_bound3d,
    crossing_height_gradient,
    information3d,
    panel_rows,
    top_brackets,
)
from tests._raycast3d import cast_labelled, paper_walls

SIGMA = 0.01
TRUTH = Pose3D.from_degrees(7.0, 7.0, 1.2, 0.0, 6.0, -4.0)


def _frame(pose: Pose3D = TRUTH, variant: str = "convergent"):  # type: ignore[no-untyped-def]
    """Noise-free returns, each labelled with its panel (-1: the wall)."""
    walls, scene = paper_walls(variant)
    planes = PanelPlanes.of(scene.survey)
    frame, label = cast_labelled(pose, walls, 0.0, 0)
    panel = np.where(label < len(planes), label, -1).astype(np.intp)
    return frame.points, panel, planes, scene.survey


def _with(pose: Pose3D, theta: np.ndarray) -> Pose3D:
    """``pose`` moved by ``theta`` in PARAMETERS order (E, N, Z, roll, pitch, azimuth)."""
    return Pose3D(
        pose.easting + theta[0],
        pose.northing + theta[1],
        pose.elevation + theta[2],
        pose.azimuth + theta[5],
        pose.pitch + theta[4],
        pose.roll + theta[3],
    )


def _ranges(pose: Pose3D, rays: np.ndarray, panel: np.ndarray, planes: PanelPlanes) -> np.ndarray:
    """Each ray's range to its panel's plane from ``pose``: where the rays fall."""
    R = rotation_rpy(pose.roll, pose.pitch, pose.yaw)
    n, d = planes.normal[panel], planes.offset[panel]
    along = np.einsum("ij,ij->i", n, (rays @ R.T)[:, :2])
    return (d - n @ np.array([pose.easting, pose.northing])) / along


def test_the_derivatives_are_the_residuals_finite_differences() -> None:
    points, panel, planes, _ = _frame()
    on = panel >= 0
    p, k = points[on], panel[on]
    v, J, _ = panel_rows(TRUTH, p, k, planes)
    assert np.abs(v).max() < 1e-9  # noise-free returns lie on their planes
    h = 1e-6
    for j in range(6):
        step = np.zeros(6)
        step[j] = h
        up = panel_rows(_with(TRUTH, step), p, k, planes)[0]
        down = panel_rows(_with(TRUTH, -step), p, k, planes)[0]
        np.testing.assert_allclose(J[:, j], (up - down) / (2 * h), atol=1e-7)
    assert np.all(J[:, Z] == 0.0)  # vertical panels say nothing of the elevation


def test_the_information_is_the_ranges_own() -> None:
    """``sum (d rho / d theta)^2 / sigma_r^2``, the range of each ray to its panel
    differentiated numerically: the point-to-plane weighting by cos(incidence) is right."""
    points, panel, planes, _ = _frame()
    on = panel >= 0
    p, k = points[on], panel[on]
    rays = p / np.linalg.norm(p, axis=1)[:, None]
    R = TRUTH.rotation
    cos_inc = np.einsum("ij,ij->i", planes.normal[k], (rays @ R.T)[:, :2])
    keep = np.abs(cos_inc) > math.sin(math.radians(2.0))
    assert keep.sum() > 1000
    np.testing.assert_allclose(
        _ranges(TRUTH, rays, k, planes), np.linalg.norm(p, axis=1), rtol=1e-9
    )
    h = 1e-6
    G = np.zeros((int(keep.sum()), 6))
    for j in range(6):
        step = np.zeros(6)
        step[j] = h
        up = _ranges(_with(TRUTH, step), rays[keep], k[keep], planes)
        down = _ranges(_with(TRUTH, -step), rays[keep], k[keep], planes)
        G[:, j] = (up - down) / (2 * h)
    want = G.T @ G / SIGMA**2
    got = information3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA)
    scale = np.sqrt(np.outer(np.diag(want), np.diag(want)))[np.ix_(FIVE, FIVE)]
    np.testing.assert_allclose(
        got[np.ix_(FIVE, FIVE)] / scale, want[np.ix_(FIVE, FIVE)] / scale, atol=1e-5
    )
    assert np.all(got[Z] == 0.0)


def test_the_bound_moves_with_the_grid() -> None:
    points, panel, planes, survey = _frame()
    shift = np.array([4_321.5, -2_468.25, 812.0])
    moved = Survey(
        [
            replace(
                b,
                edges=b.edges + shift[:2],
                elevations=None if b.elevations is None else b.elevations + shift[2],
            )
            for b in survey
        ]
    )
    there = Pose3D(
        TRUTH.easting + shift[0], TRUTH.northing + shift[1], TRUTH.elevation + shift[2],
        TRUTH.azimuth, TRUTH.pitch, TRUTH.roll,
    )  # fmt: skip
    here = cramer_rao_bound3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA)
    away = cramer_rao_bound3d(there, points, panel, PanelPlanes.of(moved), range_sigma_m=SIGMA)
    assert here.brackets
    assert len(away.brackets) == len(here.brackets)
    scale = np.sqrt(np.outer(here.sigma, here.sigma))
    np.testing.assert_allclose(away.covariance / scale, here.covariance / scale, atol=1e-6)


def test_more_returns_bound_tighter() -> None:
    points, panel, planes, _ = _frame()
    half = panel.copy()
    on = np.flatnonzero(panel >= 0)
    half[on[::2]] = -1
    five = np.ix_(FIVE, FIVE)

    def bound(labels: np.ndarray) -> np.ndarray:
        info = information3d(TRUTH, points, labels, planes, range_sigma_m=SIGMA)
        return np.linalg.inv(info[five])

    fewer, more = bound(half), bound(panel)
    # fewer returns: a bound larger in every direction (the difference positive definite)
    assert np.linalg.eigvalsh(fewer - more).min() > 0
    assert np.all(np.diag(fewer) > 1.3 * np.diag(more))


def test_the_elevation_reference_is_the_brackets_uniform_variance() -> None:
    points, panel, planes, _ = _frame()
    bound = cramer_rao_bound3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA)
    # one bracket a beacon (here B1's: no ring passes over B2's top inside its extent)
    assert [br.beacon for br in bound.brackets] == ["B1"]
    for br in bound.brackets:
        # at the truth each beacon's bracket holds the sensor's elevation
        assert br.low_m <= TRUTH.elevation <= br.high_m
        assert 0 < br.width_m < 0.5
        assert panel[br.hit] == br.hit_panel
        assert panel[br.over] != br.over_panel
    weights = [1.0 / (br.width_m**2 / 12) for br in bound.brackets]
    # each bracket one observation of the elevation with a uniform's variance over it
    assert bound.information[Z, Z] == pytest.approx(sum(weights), rel=1e-12)
    # the other five's uncertainty, which moves the crossings, only widens it
    assert bound.covariance[Z, Z] >= 1.0 / sum(weights)
    assert bound.elevation_observed


def test_the_crossing_heights_derivatives_are_their_finite_differences() -> None:
    points, panel, planes, _ = _frame()
    bound = cramer_rao_bound3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA)
    h = 1e-6
    for br in bound.brackets:
        for ray, k in ((br.hit, br.hit_panel), (br.over, br.over_panel)):
            got = crossing_height_gradient(
                TRUTH, points[ray], planes.normal[k], float(planes.offset[k])
            )

            def height(pose: Pose3D, ray: int = ray, k: int = k) -> float:
                rel = points[[ray]] @ pose.rotation.T
                return float(planes.crossing(k, pose.position, rel)[2][0] - pose.elevation)

            for j in range(6):
                step = np.zeros(6)
                step[j] = h
                fd = (height(_with(TRUTH, step)) - height(_with(TRUTH, -step))) / (2 * h)
                assert got[j] == pytest.approx(fd, abs=1e-6), (j, got, fd)


def test_without_a_top_the_elevation_is_unobserved_and_the_rest_bounded() -> None:
    _walls, scene = paper_walls("convergent")
    flat = Survey([replace(b, elevations=None) for b in scene.survey])
    points, panel, _, _ = _frame()
    bound = cramer_rao_bound3d(TRUTH, points, panel, PanelPlanes.of(flat), range_sigma_m=SIGMA)
    assert bound.brackets == ()
    assert not bound.elevation_observed
    assert math.isinf(bound.covariance[Z, Z])
    assert np.all(np.isfinite(bound.sigma[FIVE]))


def test_the_points_own_bound_leaves_the_brackets_out() -> None:
    points, panel, planes, survey = _frame()
    full = cramer_rao_bound3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA)
    own = cramer_rao_bound3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA, top_edges=False)
    assert own.brackets == ()
    assert math.isinf(own.covariance[Z, Z])
    # the same as a survey without tops; the brackets only narrow the five
    flat = Survey([replace(b, elevations=None) for b in survey])
    alone = cramer_rao_bound3d(TRUTH, points, panel, PanelPlanes.of(flat), range_sigma_m=SIGMA)
    assert np.allclose(own.sigma[FIVE], alone.sigma[FIVE], rtol=1e-9)
    assert np.all(own.sigma[FIVE] >= full.sigma[FIVE] * (1 - 1e-9))


@pytest.mark.parametrize("survey_sigma", [0.0, 0.003])
def test_the_bound_is_the_adjustments_covariance_on_the_same_returns(
    survey_sigma: float,
) -> None:
    """On noise-free returns, assigned as the adjustment assigns them, the adjustment's
    covariance of the five is the bound of those returns, with the survey's share
    propagated the same way."""
    points, _, planes, _ = _frame()
    gate = 4 * SIGMA
    which = planes.assign(TRUTH.sensor_to_grid(points), TRUTH.position, gate, top_margin_m=0.0)
    adj = adjust_pose(
        points, which, planes, TRUTH, range_sigma_m=SIGMA, survey_sigma_m=survey_sigma,
        gate_m=gate,
    )  # fmt: skip
    bound = cramer_rao_bound3d(
        TRUTH, points, which, planes, range_sigma_m=SIGMA, survey_sigma_m=survey_sigma
    )
    assert adj.returns == bound.returns
    got = np.sqrt(np.diag(adj.covariance))[FIVE]
    np.testing.assert_allclose(got, bound.sigma[FIVE], rtol=0.05)


def test_the_survey_share_widens_the_bound() -> None:
    points, panel, planes, _ = _frame()
    exact = cramer_rao_bound3d(TRUTH, points, panel, planes, range_sigma_m=SIGMA)
    shared = cramer_rao_bound3d(
        TRUTH, points, panel, planes, range_sigma_m=SIGMA, survey_sigma_m=0.003
    )
    assert np.linalg.eigvalsh(shared.covariance - exact.covariance).min() > -1e-15
    # six panels' offsets of 3 mm: the position is no better than a millimetre or so
    assert shared.sigma[0] > 5 * exact.sigma[0]


def test_the_brackets_need_a_ray_over_the_top() -> None:
    points, panel, planes, _ = _frame()
    rel_z = (points @ TRUTH.rotation.T)[:, 2]
    # only the returns below every panel's top: nothing passes over one
    low = rel_z < float(np.nanmin(planes.top)) - TRUTH.elevation - 0.05
    assert top_brackets(TRUTH, points[low], panel[low], planes) == ()
