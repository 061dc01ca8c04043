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
    got = grouped_quadratic_form(d, variances, g, q, lever, groups, np.full(n, group_variance))
    assert got == pytest.approx(want, rel=1e-10)


def test_grouped_quadratic_form_takes_each_groups_own_variance() -> None:
    """Each group (a panel) its own surveyed variance, given per observation."""
    rng = np.random.default_rng(5)
    n = 50
    d = rng.normal(0, 0.01, n)
    variances = rng.uniform(1e-5, 4e-4, n)
    g = rng.normal(size=(n, 3))
    q = 1e-4 * np.eye(3)
    lever = rng.uniform(1.0, 5.0, n)
    groups = rng.integers(0, 4, n)
    per_group = np.array([1e-6, 4e-5, 0.0, 9e-4])
    same = groups[:, None] == groups[None, :]
    c = (
        np.diag(variances)
        + g @ q @ g.T
        + per_group[groups][:, None] * np.outer(lever, lever) * same
    )
    want = float(d @ np.linalg.solve(c, d))
    got = grouped_quadratic_form(d, variances, g, q, lever, groups, per_group[groups])
    assert got == pytest.approx(want, rel=1e-10)
    # one variance for all would be another form
    flat = grouped_quadratic_form(d, variances, g, q, lever, groups, np.full(n, 4e-5))
    assert abs(flat - want) > 1e-6 * abs(want)
