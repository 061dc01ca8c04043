"""The compiled adjustment (stage 5) against its numpy references.

The kernels sum in another order than numpy's BLAS calls, so poses and
covariances agree to rounding, not to the bit; which returns are used, and every
decision, must agree exactly.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mast.core.beacon import Beacon, Survey
from mast.core.geometry import PanelSet
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.pipeline import adjustment as adj_mod
from mast.pipeline import bounds, integrity
from mast.pipeline.adjustment import Adjustment, Observations
from mast.sim import paper_scene, simulate_scan

NOISES = (NoiseModel(range_sigma_m=0.01), NoiseModel(0.012, 2e-4, 0.0))
GATE_SIGMAS = 4.0

Case = tuple[Scan, Pose2D, PanelSet, NoiseModel]


def _cases(*, adjusted: bool = True) -> list[Case]:
    """Scans of the paper scene, each from the truth and from a pose a few cm off;
    with ``adjusted``, only those whose panels determine the pose. Every other scan's
    survey gives each edge its own sigma (1 to 7 mm, one left to the noise model)."""
    scene = paper_scene()
    own = Survey(
        Beacon(b.id, b.edges, edge_sigmas_m=[0.001 * (k + 1), 0.002, math.nan, 0.001 * (7 - k)])
        for k, b in enumerate(scene.survey)
    )
    surveys = (PanelSet.from_survey(scene.survey), PanelSet.from_survey(own))
    rng = np.random.default_rng(11)
    out = []
    for k, shot in enumerate(scene.shots[:8]):
        scan = simulate_scan(scene.world, shot.pose, shot.scanner, rng=rng).scan
        for dx, dy, da in ((0.0, 0.0, 0.0), (0.04, -0.03, 0.003)):
            pose = Pose2D(shot.pose.easting + dx, shot.pose.northing + dy, shot.pose.azimuth + da)
            noise = NOISES[k % 2]
            panels = surveys[(k // 2) % 2]
            every = np.arange(len(panels))
            if adjusted and isinstance(
                adj_mod._adjust_on_panels_reference(
                    scan, pose, panels, every, noise=noise, gate_sigmas=GATE_SIGMAS
                ),
                str,
            ):
                continue
            out.append((scan, pose, panels, noise))
    assert len(out) >= 8
    return out


def _assert_scaled_close(got: np.ndarray, ref: np.ndarray, tol: float) -> None:
    """Symmetric 3 x 3 matrices equal to ``tol`` in units of their diagonals' geometric
    means (entries that cancel to almost nothing are compared to the scale they cancel
    from)."""
    scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    np.testing.assert_allclose(got / scale, ref / scale, rtol=0, atol=tol)


def _assert_adjustments_agree(got: Adjustment, ref: Adjustment) -> None:
    assert got.pose.easting == pytest.approx(ref.pose.easting, abs=1e-9)
    assert got.pose.northing == pytest.approx(ref.pose.northing, abs=1e-9)
    # Across north, 2 pi - 1e-15 and 0 are the same azimuth.
    assert abs(math.remainder(got.pose.azimuth - ref.pose.azimuth, 2 * math.pi)) < 1e-11
    _assert_scaled_close(got.cofactor, ref.cofactor, 1e-8)
    _assert_scaled_close(got.covariance, ref.covariance, 1e-8)
    assert got.reference_variance == pytest.approx(ref.reference_variance, rel=1e-8)
    assert (got.dof, got.chi2_lower, got.chi2_upper) == (ref.dof, ref.chi2_lower, ref.chi2_upper)
    np.testing.assert_allclose(got.residuals_m, ref.residuals_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got.sigmas_m, ref.sigmas_m, rtol=1e-10)
    np.testing.assert_allclose(got.jacobian, ref.jacobian, rtol=1e-9, atol=1e-12)


def _observations(
    case: Case,
) -> tuple[Observations, Adjustment]:
    scan, pose, panels, noise = case
    out = adj_mod.adjust_on_panels(
        scan,
        pose,
        panels,
        np.arange(len(panels)),
        noise=noise,
        gate_sigmas=GATE_SIGMAS,
    )
    assert not isinstance(out, str)
    return out


def test_range_model_kernel_matches_the_reference() -> None:
    rng = np.random.default_rng(2)
    th = rng.uniform(0, 2 * math.pi, 200)
    normals = np.column_stack([np.cos(th), np.sin(th)])
    for pose in (Pose2D(1.0, -2.0, 0.3), Pose2D(4e5, 7e6, 6.2)):
        angles = rng.uniform(-math.pi, math.pi, 200)
        offsets = normals @ pose.position + rng.uniform(1, 30, 200)
        got = adj_mod.range_model(pose, angles, normals, offsets)
        ref = adj_mod._range_model_reference(pose, angles, normals, offsets)
        # The offsets relative to the scanner cancel to rounding of the coordinates.
        tol = 1e-13 * max(1.0, abs(pose.easting), abs(pose.northing))
        for g, r in zip(got, ref, strict=True):
            np.testing.assert_allclose(g, r, rtol=1e-9, atol=tol)


@pytest.mark.parametrize("with_cofactor", [False, True])
def test_ray_association_kernel_matches_the_reference(with_cofactor: bool) -> None:
    edges = 0
    for case in _cases(adjusted=with_cofactor):
        scan, pose, panels, noise = case
        keep = np.arange(len(panels))
        q = _observations(case)[1].cofactor if with_cofactor else None
        got = adj_mod._ray_association(scan, pose, panels, keep, noise, GATE_SIGMAS, q)
        ref = adj_mod._ray_association_reference(scan, pose, panels, keep, noise, GATE_SIGMAS, q)
        for g, r in zip(got, ref, strict=True):
            np.testing.assert_array_equal(g, r)
        edges += int(ref[2].sum())
    assert edges > 0  # silhouette returns were met and compared


def test_adjust_on_panels_kernel_matches_the_reference() -> None:
    for case in _cases(adjusted=False):
        scan, pose, panels, noise = case
        for keep in (np.arange(len(panels)), np.arange(3), np.arange(1)):
            got = adj_mod.adjust_on_panels(
                scan,
                pose,
                panels,
                keep,
                noise=noise,
                gate_sigmas=GATE_SIGMAS,
            )
            ref = adj_mod._adjust_on_panels_reference(
                scan,
                pose,
                panels,
                keep,
                noise=noise,
                gate_sigmas=GATE_SIGMAS,
            )
            if isinstance(ref, str):
                assert got == ref
                continue
            assert not isinstance(got, str)
            (g_obs, g_adj), (r_obs, r_adj) = got, ref
            np.testing.assert_array_equal(g_obs.beam, r_obs.beam)
            np.testing.assert_array_equal(g_obs.panel, r_obs.panel)
            np.testing.assert_array_equal(g_obs.variance_scale, r_obs.variance_scale)
            np.testing.assert_array_equal(g_obs.offsets, r_obs.offsets)
            _assert_adjustments_agree(g_adj, r_adj)


def test_adjust_pose_kernel_matches_the_reference_and_refuses_a_singular_system() -> None:
    for case in _cases():
        obs, adj = _observations(case)
        noise = case[3]
        start = Pose2D(adj.pose.easting + 0.02, adj.pose.northing - 0.01, adj.pose.azimuth + 0.002)
        args = (start, obs.angles_rad, obs.ranges_m, obs.normals, obs.offsets)
        got = adj_mod.adjust_pose(*args, noise=noise, variance_scale=obs.variance_scale)
        ref = adj_mod._adjust_pose_reference(*args, noise=noise, variance_scale=obs.variance_scale)
        _assert_adjustments_agree(got, ref)
        # Every return on lines facing east: northing is not observed, exactly.
        east = np.tile([1.0, 0.0], (len(obs), 1))
        for fn in (adj_mod.adjust_pose, adj_mod._adjust_pose_reference):
            with pytest.raises(np.linalg.LinAlgError):
                fn(start, obs.angles_rad, obs.ranges_m, east, obs.offsets, noise=noise)


def test_integrity_kernels_match_the_references() -> None:
    failed = 0
    for k, case in enumerate(_cases()):
        obs, adj = _observations(case)
        noise = case[3]
        if k % 3 == 2:  # one beacon knocked 5 cm along its beams: its test fails
            moved = obs.beacon == obs.beacon[0]
            obs = Observations(
                obs.beam,
                obs.angles_rad,
                obs.ranges_m + np.where(moved, 0.05, 0.0),
                obs.normals,
                obs.offsets,
                obs.panel,
                obs.beacon,
                obs.survey_var,
                obs.variance_scale,
            )
            adj = obs.adjust(adj.pose, noise)
        np.testing.assert_allclose(
            integrity.standardised_residuals(adj),
            integrity._standardised_reference(adj),
            rtol=1e-12,
        )
        # No survey error, one sigma for every edge, and each panel its own.
        for survey_var in (
            np.zeros(len(obs)),
            np.full(len(obs), 0.003**2),
            (0.001 * (1 + obs.panel % 5)) ** 2,
        ):
            surveyed = replace(obs, survey_var=survey_var)
            got = integrity.beacon_tests(surveyed, adj, noise=noise)
            ref = integrity._beacon_tests_reference(surveyed, adj, noise=noise)
            assert [(t.beacon, t.dof, t.critical, t.failed) for t in got] == [
                (t.beacon, t.dof, t.critical, t.failed) for t in ref
            ]
            for t_got, t_ref in zip(got, ref, strict=True):
                assert t_got.statistic == pytest.approx(t_ref.statistic, rel=1e-9)
            failed += sum(t.failed for t in ref)
            if not survey_var.any():
                continue
            _assert_scaled_close(
                adj_mod.survey_covariance(adj, surveyed),
                adj_mod._survey_covariance_reference(adj, surveyed),
                1e-10,
            )
        w = integrity.standardised_residuals(adj)
        for keys in (obs.beacon, obs.panel):
            g_names, g_groups = integrity._groups(keys, adj.residuals_m, w)
            r_names, r_groups = integrity._groups_reference(keys, adj.residuals_m, w)
            np.testing.assert_array_equal(g_names, r_names)
            for g, r in zip(g_groups, r_groups, strict=True):
                assert g.returns == r.returns
                assert g.rms_m == pytest.approx(r.rms_m, rel=1e-12)
                assert g.max_abs_w == r.max_abs_w
    assert failed > 0  # the knocked beacons failed, in both


def test_information_and_bound_kernels_match_the_references() -> None:
    for case in _cases():
        obs, adj = _observations(case)
        noise = case[3]
        args = (adj.pose, obs.angles_rad, obs.normals, obs.offsets)
        info = bounds.information(*args, noise=noise)
        _assert_scaled_close(info, bounds._information_reference(*args, noise=noise), 1e-12)
        _assert_scaled_close(bounds.bound_of(info), bounds.inverse_bound(info), 1e-9)
    nowhere = np.diag([math.inf] * 3)
    for bad in (
        np.zeros((3, 3)),  # singular
        np.diag([1.0, 1.0, math.nan]),  # not finite
        np.diag([1.0, 1.0, 1e-15]),  # ill-conditioned
    ):
        np.testing.assert_array_equal(bounds.bound_of(bad), nowhere)
        np.testing.assert_array_equal(bounds.inverse_bound(bad), nowhere)


@pytest.mark.parametrize(
    ("first_deg", "span_deg", "beams"), [(-135.0, 270.0, 1081), (-180.0, 359.8, 1800)]
)
def test_beams_left_out_of_the_ray_association_cross_no_segment(
    first_deg: float, span_deg: float, beams: int
) -> None:
    """The ray association casts only the beams pointing within the angle some segment
    subtends (kernels._beams_toward): every beam left out meets no segment, from poses
    of any azimuth, segments near and far, in front and behind, and across the scan's
    seam."""
    from mast.core import _kernels as kernels

    rng = np.random.default_rng(5)
    angles = np.radians(first_deg + span_deg * np.arange(beams) / (beams - 1))
    left_out = 0
    for _ in range(300):
        e, n = rng.uniform(-5.0, 5.0, 2)
        azimuth = float(rng.uniform(-2 * math.pi, 2 * math.pi))
        k = int(rng.integers(1, 10))
        a = rng.uniform(-12.0, 12.0, (k, 2))
        b = a + rng.normal(0.0, rng.choice([0.05, 0.5, 3.0]), (k, 2))
        cast = kernels._beams_toward_jit(e, n, azimuth, angles, a, b)
        ex, ey, wx, wy, w_x_e = kernels._crossing_terms_jit(np.array([e, n]), a, b)
        for i in np.flatnonzero(~cast):
            bearing = azimuth - angles[i]
            _, j = kernels._first_crossing_jit(
                math.sin(bearing), math.cos(bearing), ex, ey, wx, wy, w_x_e
            )
            assert j == -1
        left_out += int((~cast).sum())
    assert left_out > 0
