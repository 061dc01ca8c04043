"""Two lines meet where both say; parallel ones do not meet."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.core.lines import fit_line, intersect_lines


def test_two_lines_meet_at_the_corner_both_pass_through() -> None:
    corner = np.array([3.0, -2.0])
    da = np.array([1.0, 0.0])
    db = np.array([math.cos(0.7), math.sin(0.7)])
    node = intersect_lines(corner - 5 * da, da, corner + 2 * db, db, min_sine=1e-12)
    assert node is not None
    assert node == pytest.approx(corner, abs=1e-12)


def test_lines_closer_to_parallel_than_the_caller_allows_do_not_meet() -> None:
    a = np.array([0.0, 0.0])
    d = np.array([1.0, 0.0])
    nearly = np.array([math.cos(1e-8), math.sin(1e-8)])
    assert intersect_lines(a, d, a + 1.0, nearly, min_sine=1e-6) is None
    assert intersect_lines(a, d, a + 1.0, nearly, min_sine=1e-12) is not None
    assert intersect_lines(a, d, a + 1.0, d, min_sine=0.0) is None


def test_a_fitted_line_runs_from_the_first_point_to_the_last() -> None:
    pts = np.array([[2.0, 2.0], [1.0, 1.0], [0.0, 0.0]])
    fit = fit_line(pts)
    assert fit.direction == pytest.approx(-np.array([1.0, 1.0]) / math.sqrt(2))
    assert fit.rms == pytest.approx(0.0, abs=1e-12)
