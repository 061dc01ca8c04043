import numpy as np
import pytest

from mast.core.linalg import grouped_quadratic_form


@pytest.mark.parametrize("group_variance", [0.0, 9e-6, 1.0])
def test_grouped_quadratic_form_equals_solving_with_the_full_matrix(group_variance: float) -> None:
    rng = np.random.default_rng(4)
    n = 60
    d = rng.normal(0, 0.01, n)
    variances = rng.uniform(1e-5, 4e-4, n)
    g = rng.normal(size=(n, 3))
    a = rng.normal(size=(3, 3))
    q = a @ a.T * 1e-4 + 1e-6 * np.eye(3)
    lever = rng.uniform(1.0, 5.0, n)
    groups = rng.integers(10, 13, n)
    c = np.diag(variances) + g @ q @ g.T
    c += group_variance * np.outer(lever, lever) * (groups[:, None] == groups[None, :])
    want = float(d @ np.linalg.solve(c, d))
    got = grouped_quadratic_form(d, variances, g, q, lever, groups, group_variance)
    assert got == pytest.approx(want, rel=1e-10)
