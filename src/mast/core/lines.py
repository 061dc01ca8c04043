"""Straight lines in the plane, written once: the total-least-squares fit of points and
the meeting point of two lines. The scan's segmentation (:mod:`mast.pipeline.segmentation`)
and the point cloud's plan pieces (:mod:`mast.cloud.detect`) both use them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["LineFit", "fit_line", "intersect_lines"]


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
