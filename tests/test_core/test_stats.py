"""The tests' critical values against scipy.stats, and one BeaconTest for every adjustment."""

from __future__ import annotations

import math

import pytest
from scipy import stats

from mast.core.stats import (
    GLOBAL_ALPHA,
    W_TEST_ALPHA,
    BeaconTest,
    beacon_critical,
    variance_bounds,
    w_critical,
)


@pytest.mark.parametrize("dof", [1, 2, 7, 50, 248, 5000])
def test_the_variance_bounds_are_the_two_sided_chi_square_quantiles(dof: int) -> None:
    lo, hi = variance_bounds(dof)
    assert lo == pytest.approx(stats.chi2.ppf(GLOBAL_ALPHA / 2, dof) / dof, rel=1e-12)
    assert hi == pytest.approx(stats.chi2.ppf(1 - GLOBAL_ALPHA / 2, dof) / dof, rel=1e-12)
    assert lo < 1.0 < hi


def test_no_redundancy_accepts_any_variance() -> None:
    assert variance_bounds(0) == (0.0, math.inf)


@pytest.mark.parametrize("n", [1, 10, 251, 100_000])
def test_the_w_critical_value_shares_alpha_over_every_residual(n: int) -> None:
    expected = stats.norm.ppf(1 - W_TEST_ALPHA / 2 / n)
    assert w_critical(n) == pytest.approx(expected, rel=1e-12)
    assert w_critical(n) >= w_critical(1)


def test_the_beacon_critical_value_is_the_upper_chi_square_quantile() -> None:
    assert beacon_critical(W_TEST_ALPHA / 2, 25) == pytest.approx(
        stats.chi2.isf(W_TEST_ALPHA / 2, 25), rel=1e-12
    )


def test_a_beacon_test_fails_past_its_critical_value() -> None:
    passed = BeaconTest("B1", 21.9, 25, 54.9)
    failed = BeaconTest(3, 60.0, 25, 54.9, role="check")
    assert not passed.failed
    assert passed.ratio == pytest.approx(21.9 / 54.9)
    assert failed.failed
    assert failed.role == "check"
