"""Linear algebra the tests of a fix share: quadratic forms that never build an n x n matrix."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["grouped_quadratic_form"]


def grouped_quadratic_form(
    d: NDArray[np.float64],
    variances: NDArray[np.float64],
    g: NDArray[np.float64],
    q: NDArray[np.float64],
    lever: NDArray[np.float64],
    groups: NDArray[np.intp],
    group_variance: float,
) -> float:
    """``d^T C^-1 d`` for ``C = diag(variances) + g q g^T + group_variance * S``.

    ``S[i, j] = lever_i * lever_j`` where observations ``i`` and ``j`` share a
    group (a panel whose surveyed position errs once for all its returns),
    else 0. ``C`` is diagonal plus a low-rank part ``U M U^T`` (``U`` the
    columns of ``g`` and one column per group holding its levers, ``M``
    block-diagonal: ``q``, then ``group_variance`` per group), so the
    Woodbury identity gives the form from ``k x k`` matrices, ``k`` the
    columns of ``g`` plus the groups::

        d^T C^-1 d = d^T D^-1 d - y^T (I + M K)^-1 M y,
        y = U^T D^-1 d,  K = U^T D^-1 U

    Time and memory are linear in the observations, where solving with ``C``
    itself is cubic in time and quadratic in memory. Equal to that solve to
    rounding.

    Raises
    ------
    numpy.linalg.LinAlgError
        When ``C`` is singular.
    """
    names, col = np.unique(groups, return_inverse=True)
    n, p = g.shape
    u = np.zeros((n, p + names.size))
    u[:, :p] = g
    u[np.arange(n), p + col.reshape(-1)] = lever
    m = np.zeros((u.shape[1], u.shape[1]))
    m[:p, :p] = q
    m[p:, p:] = group_variance * np.eye(names.size)
    w = 1.0 / variances
    y = u.T @ (w * d)
    k = u.T @ (w[:, None] * u)
    z = np.linalg.solve(np.eye(u.shape[1]) + m @ k, m @ y)
    return float(d @ (w * d) - y @ z)
