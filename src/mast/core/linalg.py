"""Linear algebra the tests of a fix share: quadratic forms that never build an n x n
matrix, and the least-squares step of a pose."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["grouped_quadratic_form", "pose_step"]


def grouped_quadratic_form(
    d: NDArray[np.float64],
    variances: NDArray[np.float64],
    g: NDArray[np.float64],
    q: NDArray[np.float64],
    lever: NDArray[np.float64],
    groups: NDArray[np.intp],
    group_variance: NDArray[np.float64],
) -> float:
    """``d^T C^-1 d`` for ``C = diag(variances) + g q g^T + S``.

    ``S[i, j] = s_g * lever_i * lever_j`` where observations ``i`` and ``j`` share a
    group ``g`` (a panel whose surveyed position errs once for all its returns; ``s_g``
    its variance, ``group_variance`` given per observation), else 0. ``C`` is
    diagonal plus a low-rank part ``U M U^T`` (``U`` the columns of ``g`` and one
    column per group holding its levers, ``M`` block-diagonal: ``q``, then each
    group's variance), so the
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
    per_group = np.zeros(names.size)
    per_group[col.reshape(-1)] = group_variance
    m[p:, p:] = np.diag(per_group)
    w = 1.0 / variances
    y = u.T @ (w * d)
    k = u.T @ (w[:, None] * u)
    z = np.linalg.solve(np.eye(u.shape[1]) + m @ k, m @ y)
    return float(d @ (w * d) - y @ z)


def pose_step(design: NDArray[np.float64], rhs: NDArray[np.float64]) -> NDArray[np.float64]:
    """The least-squares solution of ``design @ x = rhs`` for three unknowns (a pose's
    step in ICP and odometry): the normal equations solved by cofactors, or LAPACK's
    ``lstsq`` when they are near singular (the determinant below 1e-9 of the product of
    their diagonal). The numpy reference of :func:`mast.core._kernels._normal_step`.

    A pose step's normal matrix is well conditioned (columns in metres and in metres
    times range: condition numbers in the thousands), so its solution is the SVD's to
    about 1e-12 of the step, at a twentieth of the cost.
    """
    a = design.T @ design
    b = design.T @ rhs
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[1, 2]
    c01 = a[0, 2] * a[1, 2] - a[0, 1] * a[2, 2]
    c02 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    if not abs(det) > 1e-9 * a[0, 0] * a[1, 1] * a[2, 2]:
        return np.asarray(np.linalg.lstsq(design, rhs, rcond=None)[0])
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[0, 2]
    c12 = a[0, 1] * a[0, 2] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]
    cof = np.array([[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]])
    return np.asarray(cof @ b / det)
