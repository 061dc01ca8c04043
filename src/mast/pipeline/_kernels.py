"""Compiled kernels (numba) of the locator's hot loops.

Each kernel has a readable numpy reference next to the code that calls it;
the tests compare the two. Compilation is cached on disk (``cache=True``): the
first call after installation compiles (about a second), later processes load
the machine code.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["associate", "partition_dp"]


def _partition_dp(
    sx: NDArray[np.float64],
    sy: NDArray[np.float64],
    sxx: NDArray[np.float64],
    syy: NDArray[np.float64],
    sxy: NDArray[np.float64],
    uxx: NDArray[np.float64],
    uyy: NDArray[np.float64],
    uxy: NDArray[np.float64],
    var: float,
    pen: float,
    w: int,
) -> NDArray[np.intp]:
    """Optimal partition's back-pointers: ``last[j]`` is where the piece ending at
    ``j`` (exclusive) starts, for every ``j`` in 1..n.

    The cost of a piece is that of ``segmentation._partition_reference`` (its
    total-least-squares SSE in range-noise units across its line, plus the
    penalty, plus 4 per return of a piece of one or two); the line's normal comes
    from the scatter matrix by the half-angle identities instead of ``arctan2``,
    ``sin`` and ``cos``. Ties go to the shortest piece, as ``argmin`` does there.
    """
    n = sx.shape[0] - 1
    best = np.empty(n + 1)
    best[0] = -pen
    last = np.zeros(n + 1, dtype=np.intp)
    for j in range(1, n + 1):
        top = min(j, w)
        bj = math.inf
        arg = j - 1
        for d in range(1, top + 1):
            i = j - d
            m = float(d)
            ax = sx[j] - sx[i]
            ay = sy[j] - sy[i]
            vxx = sxx[j] - sxx[i] - ax * ax / m
            vyy = syy[j] - syy[i] - ay * ay / m
            vxy = sxy[j] - sxy[i] - ax * ay / m
            dv = vxx - vyy
            q = 0.25 * dv * dv + vxy * vxy
            half_r = math.sqrt(q) if q > 0.0 else 0.0
            sse = 0.5 * (vxx + vyy) - half_r
            if sse < 0.0:
                sse = 0.0
            # Normal of the line (the scatter's minor axis): with cos 2t = dv / r and
            # sin 2t = 2 vxy / r (t = 0 when r = 0), n = (-sin t, cos t).
            if half_r > 0.0:
                c2 = 0.5 * dv / half_r
                s2 = vxy / half_r
            else:
                c2 = 1.0
                s2 = 0.0
            nu2 = (
                0.5 * (1.0 - c2) * (uxx[j] - uxx[i])
                - s2 * (uxy[j] - uxy[i])
                + 0.5 * (1.0 + c2) * (uyy[j] - uyy[i])
            ) / m
            if nu2 < 0.05:
                nu2 = 0.05
            cost = sse / (var * nu2) + pen
            if d < 3:
                cost += 4.0 * m
            total = best[i] + cost
            if total < bj:
                bj = total
                arg = i
        best[j] = bj
        last[j] = arg
    return last


def _associate(
    points: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gates: NDArray[np.float64],
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Nearest panel (of ``panels``) of each point within its gate of the panel's line
    and inside its extent, and the signed distance; -1 and inf for none.

    ``gates`` holds one gate per point, or a single gate for all. Ties go to the
    first panel, as ``argmin`` does in ``PanelSet._associate_reference``.
    """
    n = points.shape[0]
    idx = np.full(n, -1, dtype=np.intp)
    dist = np.full(n, np.inf)
    one = gates.shape[0] == 1
    for p in range(n):
        g = gates[0] if one else gates[p]
        best = np.inf
        for k in range(panels.shape[0]):
            q = panels[k]
            rx = points[p, 0] - a[q, 0]
            ry = points[p, 1] - a[q, 1]
            t = rx * direction[q, 0] + ry * direction[q, 1]
            if t < 0.0 or t > length[q]:
                continue
            s = rx * normal[q, 0] + ry * normal[q, 1]
            if abs(s) <= g and abs(s) < best:
                best = abs(s)
                idx[p] = q
                dist[p] = s
    return idx, dist


#: Compiled on first use (numba's own types; mypy sees plain callables).
partition_dp: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True)(_partition_dp)
associate: Callable[..., Any] = njit(cache=True, nogil=True)(_associate)
