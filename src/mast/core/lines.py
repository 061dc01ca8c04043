"""Straight lines in the plane, written once: the total-least-squares fit of points, the
meeting point of two lines, and the noise of points about the lines they lie on. The
scan's segmentation (:mod:`mast.pipeline.segmentation`) and the point cloud's plan pieces
(:mod:`mast.cloud.detect`) both use them.

Two noise estimates, one for each kind of data, each named for its method:
:func:`range_noise_from_triples` for a scan's returns in beam order (the middle of three
neighbours against the line through the outer two, turned into range noise by the beam's
incidence) and :func:`plan_noise_from_neighbours` for an unordered cloud in plan (the
least spread of each point's nearest neighbours).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "LineFit",
    "fit_line",
    "intersect_lines",
    "plan_noise_from_neighbours",
    "range_noise_from_triples",
]


@dataclass(frozen=True, slots=True)
class LineFit:
    centroid: NDArray[np.float64]
    direction: NDArray[np.float64]
    normal: NDArray[np.float64]
    rms: float
    t_spread: float  # sum of squared projections about the centroid


def fit_line(points: NDArray[np.float64]) -> LineFit:
    """Total least squares line through ``(n, 2)`` points (principal component).

    The direction points from the first point towards the last.
    """
    c = points.mean(axis=0)
    q = points - c
    cov = q.T @ q
    _, v = np.linalg.eigh(cov)
    d = v[:, 1]
    if np.dot(points[-1] - points[0], d) < 0:
        d = -d
    n = np.array([-d[1], d[0]])
    resid = q @ n
    t = q @ d
    return LineFit(c, d, n, float(np.sqrt(np.mean(resid**2))), float(np.sum(t**2)))


def intersect_lines(
    centroid_a: NDArray[np.float64],
    direction_a: NDArray[np.float64],
    centroid_b: NDArray[np.float64],
    direction_b: NDArray[np.float64],
    *,
    min_sine: float,
) -> NDArray[np.float64] | None:
    """Where two lines (a point and a unit direction each) meet; None when the sine of
    the angle between them is below ``min_sine`` (parallel for the caller's purpose) or
    zero."""
    cross = direction_a[0] * direction_b[1] - direction_a[1] * direction_b[0]
    if abs(cross) < min_sine or cross == 0:
        return None
    # centroid_a + s direction_a = centroid_b + u direction_b
    w = centroid_b - centroid_a
    s = (w[0] * direction_b[1] - w[1] * direction_b[0]) / cross
    node: NDArray[np.float64] = centroid_a + s * direction_a
    return node


# --------------------------------------------------------------------------- noise

#: Quantile of the triple deviations used for the noise estimate, and that
#: quantile of a unit half-normal distribution.
NOISE_QUANTILE = 0.5
_HALF_NORMAL_Q = 0.6745


def range_noise_from_triples(points: NDArray[np.float64], run_ids: NDArray[np.intp]) -> float:
    """Robust estimate of the range noise from triples of consecutive returns.

    For three neighbours on a straight surface, the middle one's distance
    from the line through the outer two has variance about 1.5 sigma_perp^2,
    and a range error e moves a return by e |n . u| across the surface (n
    the surface normal, u the beam). Dividing by |n . u| gives the range
    noise, which bounds the noise across every surface; triples seen within
    about 17 degrees of grazing are left out. The median is used: triples
    on corners only lengthen the upper tail (rough rock, whose bumps are
    shape, raises it, which only makes the segmentation more cautious).
    The deviations are compiled (:func:`mast.core._kernels.triple_deviations`);
    :func:`range_noise_from_triples_reference` is the same in numpy.
    """
    from mast.core._kernels import linear_median, triple_deviations

    deviations = triple_deviations(
        np.ascontiguousarray(points, dtype=float).reshape(-1, 2),
        np.ascontiguousarray(run_ids, dtype=np.intp),
    )
    if deviations.size == 0:
        return 0.0
    # median of |N(0, s)| = 0.6745 s, s^2 = 1.5 sigma^2 (NOISE_QUANTILE is the median)
    return float(linear_median(deviations) / _HALF_NORMAL_Q / math.sqrt(1.5))


def range_noise_from_triples_reference(
    points: NDArray[np.float64], run_ids: NDArray[np.intp]
) -> float:
    """:func:`range_noise_from_triples` in numpy (the tests compare the two)."""
    if points.shape[0] < 3:
        return 0.0
    a, b, c = points[:-2], points[1:-1], points[2:]
    same = (run_ids[:-2] == run_ids[1:-1]) & (run_ids[1:-1] == run_ids[2:])
    if not np.any(same):
        return 0.0
    ac = c - a
    length = np.hypot(ac[:, 0], ac[:, 1])
    rb = np.hypot(b[:, 0], b[:, 1])
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # |n . u| = |sin(angle between the surface and the beam)|
        nu = np.abs(ac[:, 0] * b[:, 1] - ac[:, 1] * b[:, 0]) / (length * rb)
    ok = same & (length > 0) & (rb > 0) & (nu > 0.3)
    if not np.any(ok):
        return 0.0
    dist = (
        np.abs(ac[ok, 0] * (b[ok, 1] - a[ok, 1]) - ac[ok, 1] * (b[ok, 0] - a[ok, 0])) / length[ok]
    )
    # median of |N(0, s)| = 0.6745 s, s^2 = 1.5 sigma^2
    return float(np.quantile(dist / nu[ok], NOISE_QUANTILE) / _HALF_NORMAL_Q / math.sqrt(1.5))


def plan_noise_from_neighbours(xy: NDArray[np.float64], k: int = 48) -> float:
    """The plan noise from local line fits: median smallest spread of ``k`` neighbours."""
    from scipy.spatial import cKDTree

    if xy.shape[0] < k + 1:
        return 0.0
    tree = cKDTree(xy)
    sample = xy[:: max(1, xy.shape[0] // 20000)]
    _, idx = tree.query(sample, k=k)
    nb = xy[idx]
    c = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", c, c) / (k - 1)
    lam = np.linalg.eigvalsh(cov)[:, 0]
    return float(math.sqrt(max(float(np.median(lam)), 0.0)))
