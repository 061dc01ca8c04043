"""The prediction checked against reality: the bound against the scatter of actual fixes,
and the predicted availability against the locator's outcome on fresh scans."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.core.pose import wrap_angle
from mast.pipeline.locator import locate
from mast.plan.predict import (
    PlanSettings,
    locator_config,
    plan_world,
    position_major_sigma,
    predict,
)
from mast.sim.scanner import scanner_model, simulate_scan
from tests.test_plan._scenes import pair_scene

SCANNER = scanner_model("lms1xx-0.25")
SETTINGS = PlanSettings(step_m=2.0, scans_per_cell=3, roughness_m=0.02)


@pytest.fixture(scope="module")
def plan():  # type: ignore[no-untyped-def]
    _, drift, survey = pair_scene()
    return predict(drift, survey, SCANNER, SETTINGS)


def _fresh(plan, row: int, col: int, heading: int, n: int, seed: int):  # type: ignore[no-untyped-def]
    from mast.plan.predict import cell_pose

    world = plan_world(
        plan.drift, plan.survey, roughness_m=SETTINGS.roughness_m, seed=SETTINGS.seed
    )
    pose = cell_pose(plan.grid, row, col, heading)
    cfg = locator_config(SCANNER, SETTINGS)
    rng = np.random.default_rng(seed)
    errors = []
    for _ in range(n):
        fix = locate(simulate_scan(world, pose, SCANNER, rng=rng).scan, plan.survey, config=cfg)
        if fix.ok:
            errors.append(
                (
                    fix.pose.easting - pose.easting,
                    fix.pose.northing - pose.northing,
                    wrap_angle(fix.pose.azimuth - pose.azimuth),
                )
            )
    return np.array(errors).reshape(-1, 3)


def test_the_plan_has_fixes_near_the_beacons_and_none_far_away(plan) -> None:  # type: ignore[no-untyped-def]
    c = plan.grid.centre
    near = (plan.grid.stations_m >= 10.0) & (plan.grid.stations_m <= 30.0)
    far = plan.grid.stations_m <= 3.0
    assert plan.has_fix[near, c].any()
    assert not plan.owed[far].any()
    assert not plan.has_fix[far].any()
    assert plan.wrong.sum() == 0
    assert np.all(plan.beacons_in_view[far] <= 1)


def test_predicted_sigma_matches_the_scatter_of_fixes(plan) -> None:  # type: ignore[no-untyped-def]
    """Monte Carlo in three cells: the fixes' RMS error is the Cramér–Rao sigma."""
    c = plan.grid.centre
    rows = np.flatnonzero(plan.owed[:, c, 0] & (plan.fix_rate[:, c, 0] == 1.0))
    assert len(rows) >= 3
    for k, row in enumerate(rows[:: max(1, len(rows) // 3)][:3]):
        errors = _fresh(plan, int(row), c, 0, 120, seed=k)
        assert len(errors) >= 110  # the availability the plan predicted
        rms = np.sqrt(np.mean(errors**2, axis=0))
        bound = np.sqrt(np.diag(plan.covariance[row, c, 0]))
        ratio = rms / bound
        # 120 draws: the sample RMS is within about 13 % (2 sigma) of the truth; the
        # locator is at the bound, a little above where corners' returns are left out
        assert np.all((ratio > 0.75) & (ratio < 1.4)), (row, rms, bound)
        major = position_major_sigma(plan.covariance[row, c, 0])
        assert major >= max(bound[:2])


def test_predicted_availability_matches_the_locator(plan) -> None:  # type: ignore[no-untyped-def]
    """Cells the plan says fix do fix on fresh scans; cells it says do not, do not."""
    c = plan.grid.centre
    agree = total = 0
    for row in range(0, len(plan.grid.stations_m), 2):
        for h in (0, 1):
            predicted = plan.fix_rate[row, c, h]
            got = len(_fresh(plan, row, c, h, 6, seed=1000 + row * 2 + h)) / 6
            total += 1
            agree += (predicted >= 0.5) == (got >= 0.5)
            if predicted == 0.0 and not plan.owed[row, c, h]:
                assert got <= 1 / 6
    assert agree / total >= 0.85


def test_heading_and_sigma_columns_are_consistent(plan) -> None:  # type: ignore[no-untyped-def]
    h = np.degrees(plan.headings_rad())
    np.testing.assert_allclose((h[:, 1] - h[:, 0]) % 360.0, 180.0)
    cov = plan.covariance[plan.grid.inside]
    finite = np.isfinite(cov[..., 0, 0])
    assert finite.any()
    assert np.all(cov[finite][..., 0, 0] > 0)
    assert math.isfinite(float(np.nanmin(plan.sigma_position)))
