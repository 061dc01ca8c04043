"""Quantiles and tail probabilities of the test distributions, at the cost of a ufunc.

``scipy.stats``' distribution objects check and broadcast their arguments on every
call (tens of microseconds each); a fix asks for a dozen of these numbers. The
same values come from ``scipy.special``'s cumulative-distribution inverses in
about a microsecond; the tests compare every function here with ``scipy.stats``.
"""

from __future__ import annotations

from scipy import special

__all__ = ["chi2_isf", "chi2_ppf", "chi2_sf", "f_ppf", "norm_ppf", "t_ppf"]


def norm_ppf(q: float) -> float:
    """Quantile ``q`` of the standard normal distribution."""
    return float(special.ndtri(q))


def chi2_ppf(q: float, dof: float) -> float:
    """Quantile ``q`` of the chi-square distribution with ``dof`` degrees of freedom."""
    return float(special.chdtri(dof, 1.0 - q))


def chi2_isf(p: float, dof: float) -> float:
    """Value exceeded with probability ``p`` under chi-square with ``dof`` degrees of freedom."""
    return float(special.chdtri(dof, p))


def chi2_sf(x: float, dof: float) -> float:
    """Probability that chi-square with ``dof`` degrees of freedom exceeds ``x``."""
    return float(special.chdtrc(dof, x))


def t_ppf(q: float, dof: float) -> float:
    """Quantile ``q`` of Student's t distribution with ``dof`` degrees of freedom."""
    return float(special.stdtrit(dof, q))


def f_ppf(q: float, dfn: float, dfd: float) -> float:
    """Quantile ``q`` of the F distribution with ``dfn`` and ``dfd`` degrees of freedom."""
    return float(special.fdtri(dfn, dfd, q))
