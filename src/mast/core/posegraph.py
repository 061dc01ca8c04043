"""MAST's pose graphs solved alike: a survey run's smoothing window (:mod:`mast.runs.track`)
and a point cloud's drift correction (:mod:`mast.cloud.drift`) both go through
:func:`solve`, Levenberg-Marquardt in GTSAM to the same tolerances.
"""

from __future__ import annotations

from typing import Any

__all__ = ["ABSOLUTE_TOL", "MAX_ITERATIONS", "RELATIVE_TOL", "solve"]

#: Levenberg-Marquardt stops when the error falls by less than this share in a step...
RELATIVE_TOL = 1e-10
#: ... or by less than this much (the error is a sum of squared standardised residuals) ...
ABSOLUTE_TOL = 1e-12
#: ... or after this many iterations.
MAX_ITERATIONS = 100


def solve(graph: Any, initial: Any) -> Any:
    """The values that minimise ``graph``'s error (a ``gtsam.NonlinearFactorGraph``),
    from ``initial`` (``gtsam.Values``)."""
    import gtsam

    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(RELATIVE_TOL)
    params.setAbsoluteErrorTol(ABSOLUTE_TOL)
    params.setMaxIterations(MAX_ITERATIONS)
    return gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
