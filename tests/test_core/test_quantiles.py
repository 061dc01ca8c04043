"""The fast quantiles agree with scipy.stats to the last few digits."""

from __future__ import annotations

import pytest
from scipy import stats

from mast.core.quantiles import chi2_isf, chi2_ppf, chi2_sf, f_ppf, norm_ppf, t_ppf

DOFS = [1, 2, 3, 7, 57, 500, 3000]
QS = [1e-6, 0.001, 0.025, 0.5, 0.95, 0.975, 0.999, 1 - 1e-9]


@pytest.mark.parametrize("dof", DOFS)
@pytest.mark.parametrize("q", QS)
def test_quantiles_match_scipy_stats(dof: int, q: float) -> None:
    assert chi2_ppf(q, dof) == pytest.approx(stats.chi2.ppf(q, dof), rel=1e-10, abs=1e-300)
    assert chi2_isf(q, dof) == pytest.approx(stats.chi2.isf(q, dof), rel=1e-10, abs=1e-300)
    assert t_ppf(q, dof) == pytest.approx(stats.t.ppf(q, dof), rel=1e-9, abs=1e-12)
    assert f_ppf(q, 2, dof) == pytest.approx(stats.f.ppf(q, 2, dof), rel=1e-9, abs=1e-300)
    x = stats.chi2.ppf(q, dof)
    assert chi2_sf(x, dof) == pytest.approx(stats.chi2.sf(x, dof), rel=1e-9, abs=1e-15)
    assert norm_ppf(q) == pytest.approx(stats.norm.ppf(q), rel=1e-12, abs=1e-15)


def test_tails_are_the_right_way_round() -> None:
    assert chi2_ppf(0.975, 2) > chi2_ppf(0.025, 2)
    assert chi2_isf(0.001, 2) == pytest.approx(13.815510557964274)
    assert chi2_sf(chi2_isf(0.05, 10), 10) == pytest.approx(0.05)
    assert norm_ppf(0.975) == pytest.approx(1.959963984540054)
