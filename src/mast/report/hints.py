"""Hints for a run that went wrong in a way a newcomer cannot read from the reasons alone.

A command that locates scans (``locate``, ``track``) feeds every scan and its fix to a
:class:`Hints` and, at the end, prints the lines :meth:`Hints.lines` gives (one line
each, on standard error). Each hint is a measured fact, not a guess: the scans it
names were located again with the change it suggests.

* **The range sigma.** Scans refused by the global test whose returns simply scatter
  more than ``--range-sigma`` says (a scanner noisier than the default 10 mm): the
  scatter the refused adjustments show gives a sigma, and the refused scans are
  located again with it. The hint names it, how many of them then fix, and
  ``--scanner``.
* **Easting and northing swapped.** No scan fixed: a few of them are located again
  against the survey with its easting and northing exchanged (its mirror image).
  Where that fixes them, the survey's columns are most likely in the wrong order.
  A layout that is its own mirror image (two beacons, each the other's mirror image
  across the drift, as in the paper's parallel walls) fixes either way, turned: no
  scan can tell that a survey of it was swapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from mast.core.beacon import Survey
from mast.core.scan import Scan
from mast.pipeline.locator import Fix, LocatorConfig, locate

__all__ = ["Hints", "swapped_survey"]

#: How many refused scans are kept to be located again (the rest are only counted).
KEEP = 12


def swapped_survey(survey: Survey) -> Survey:
    """``survey`` with every edge's easting and northing exchanged (its mirror image)."""
    return Survey(
        [replace(b, edges=np.ascontiguousarray(b.edges[:, ::-1])) for b in survey],
        source=survey.source,
    )


@dataclass(slots=True)
class Hints:
    """What the hints need of a run's scans (see the module)."""

    survey: Survey
    config: LocatorConfig
    scans: int = 0
    fixed: int = 0
    rejected: int = 0
    _variances: list[float] = field(default_factory=list)
    _rejected: list[Scan] = field(default_factory=list)
    _unfixed: list[Scan] = field(default_factory=list)

    def add(self, scan: Scan, fix: Fix) -> None:
        """One scan and what the locator made of it."""
        self.scans += 1
        self.fixed += fix.ok
        if fix.ok and fix.adjustment is not None and fix.adjustment.dof > 0:
            self._variances.append(float(fix.adjustment.reference_variance))
        elif fix.reason == "rejected" and fix.refused is not None:
            self.rejected += 1
            self._variances.append(fix.refused[0])
            if len(self._rejected) < KEEP:
                self._rejected.append(scan)
        if not fix.ok and not self.fixed and len(self._unfixed) < KEEP:
            self._unfixed.append(scan)

    def lines(self) -> list[str]:
        """The hints this run earned (none when nothing went wrong)."""
        out = []
        if (text := self._range_sigma()) is not None:
            out.append(text)
        if (text := self._swapped()) is not None:
            out.append(text)
        return out

    def _range_sigma(self) -> str | None:
        if not self._rejected:
            return None
        sigma = self.config.range_sigma_m
        # The returns' own scatter: the reference variance of every adjustment, fixed or
        # refused, says how many times the stated sigma the returns scatter.
        scale = math.sqrt(float(np.median(self._variances)))
        if scale <= 1.0:
            return None  # not a sigma stated too small: something else refused them
        fitted = math.ceil(sigma * scale * 1e3 - 1e-9) / 1e3  # up to the next millimetre
        again = replace(self.config, range_sigma_m=fitted)
        fixed = sum(locate(scan, self.survey, config=again).ok for scan in self._rejected)
        if 2 * fixed < len(self._rejected):
            return None  # the scatter does not explain the refusals
        tried = len(self._rejected)
        if tried < self.rejected:
            again_text = f"{fixed} of {tried} of them tried fix"
        else:
            again_text = f"all {tried} fix" if fixed == tried else f"{fixed} of the {tried} fix"
        return (
            f"hint: {self.rejected} of {self.scans} scans were refused by the global test; "
            f"their returns scatter about {1e3 * sigma * scale:.1f} mm where --range-sigma is "
            f"{1e3 * sigma:g} mm, and with --range-sigma {fitted:g} {again_text}: give the "
            "scanner's noise (--range-sigma, or --scanner; `mast scanners` lists them)"
        )

    def _swapped(self) -> str | None:
        if self.fixed or not self._unfixed:
            return None
        mirror = swapped_survey(self.survey)
        fixed = sum(locate(scan, mirror, config=self.config).ok for scan in self._unfixed)
        if fixed == 0:
            return None
        source = self.survey.source or "the survey"
        return (
            f"hint: no scan fixed, but with easting and northing exchanged {source} fixes "
            f"{fixed} of {len(self._unfixed)} scans tried: are its columns "
            "beacon,edge,easting,northing (easting first)?"
        )
