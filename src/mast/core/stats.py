"""The statistical tests every adjustment in MAST reports, written once: the global test
of the reference variance, Baarda's w-test and the leave-one-beacon-out test, with their
significance levels.

The 2D pipeline (:mod:`mast.pipeline.adjustment`, :mod:`mast.pipeline.integrity`) and the
point-cloud georeference (:mod:`mast.cloud.adjust`, :mod:`mast.cloud.drift`) both use
these, so that a test means the same, at the same level, wherever it is printed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Generic, TypeVar

from mast.core.quantiles import chi2_isf, norm_ppf

__all__ = [
    "GLOBAL_ALPHA",
    "W_TEST_ALPHA",
    "BeaconTest",
    "beacon_critical",
    "variance_bounds",
    "w_critical",
]

#: Two-sided significance of the global test of the reference variance.
GLOBAL_ALPHA = 0.05
#: Significance of the w-test (shared over all observations, Bonferroni) and of the
#: beacon tests (shared over the beacons tested).
W_TEST_ALPHA = 0.001


@lru_cache(maxsize=4096)
def variance_bounds(dof: int, alpha: float = GLOBAL_ALPHA) -> tuple[float, float]:
    """The global test's acceptance interval for a reference variance on ``dof`` degrees of
    freedom (a chi-square over its ``dof``, two-sided at ``alpha``); (0, inf) without
    redundancy."""
    if dof <= 0:
        return 0.0, math.inf
    return chi2_isf(1 - alpha / 2, dof) / dof, chi2_isf(alpha / 2, dof) / dof


def w_critical(n: int, alpha: float = W_TEST_ALPHA) -> float:
    """Critical |w| for the largest of ``n`` standardised residuals (two-sided, Bonferroni)."""
    return norm_ppf(1 - alpha / 2 / max(n, 1))


@lru_cache(maxsize=4096)
def beacon_critical(alpha: float, dof: int) -> float:
    """Critical value of a beacon test (a chi-square on ``dof``) at significance ``alpha``
    (the caller's share of :data:`W_TEST_ALPHA` over the beacons it tests)."""
    return chi2_isf(alpha, dof)


#: How a tested beacon is named: its number in the 2D pipeline's panel set, its survey
#: id in a point cloud's adjustment.
BeaconKey = TypeVar("BeaconKey", int, str)


@dataclass(frozen=True, slots=True)
class BeaconTest(Generic[BeaconKey]):
    """A beacon left out and tested against the solution of the rest: ``statistic`` (a
    squared Mahalanobis distance of its misclosures) on ``dof`` degrees of freedom,
    ``critical`` its bound (:func:`beacon_critical`).

    ``role``: ``control`` (left out to be tested), or, in a point cloud's drift
    correction, ``excluded`` (left out as an outlier) or ``check`` (never in the
    solution), each against the final solution.
    """

    beacon: BeaconKey
    statistic: float
    dof: int
    critical: float
    role: str = "control"

    @property
    def ratio(self) -> float:
        """The statistic in multiples of its critical value."""
        return self.statistic / self.critical

    @property
    def failed(self) -> bool:
        return self.statistic > self.critical
