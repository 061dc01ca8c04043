"""When a scan is owed a fix: the one rule every benchmark, test and plan counts by.

A scan is owed a fix when two beacons each show two panels (:func:`owes_fix`): the least
a beacon must show for its shape (the bend between two panels) to be known from the
returns alone, and two beacons the least that fixes position and azimuth. What counts as
a panel shown is an :class:`OwedRule`, and the rules MAST's figures are counted by are
named here, each with why it is what it is; a benchmark quotes its rule by name.
"""

from __future__ import annotations

from collections.abc import Mapping, Sized
from dataclasses import dataclass

__all__ = [
    "OWED",
    "OWED_CLEAN",
    "OWED_FIELD",
    "OWED_REAL_WALLS",
    "OwedRule",
    "owes_fix",
]


@dataclass(frozen=True, slots=True)
class OwedRule:
    """What counts as a panel shown: at least ``min_points`` returns, seen at least
    ``min_incidence_deg`` off grazing (the beam's angle to the panel's plane at its
    returns' centroid; sparser returns draw no line)."""

    min_points: int = 3
    min_incidence_deg: float = 10.0


#: The rule of the accuracy, tracking, live and long-drive benchmarks and of ``mast plan``:
#: three returns draw a line, and ten degrees off grazing they are not a smear.
OWED = OwedRule(3, 10.0)
#: The field benchmark's, as the independent scenes are scored: every panel with four
#: returns, at any incidence (those scenes count the panels a person sees).
OWED_FIELD = OwedRule(4, 0.0)
#: The robustness benchmark's hostile scenes: clean panels only (eight returns, fifteen
#: degrees), so that a miss is the locator's and not a scan no method could fix.
OWED_CLEAN = OwedRule(8, 15.0)
#: Beacons mounted on the real walls of logged runs (``mast bench clutter``): four returns
#: and fifteen degrees, the real scanners' mixed pixels at grazing incidence aside.
OWED_REAL_WALLS = OwedRule(4, 15.0)


def owes_fix(panels_shown: Mapping[str, Sized]) -> bool:
    """Whether two beacons each show two panels (``panels_shown``: the panels each beacon
    shows, counted by an :class:`OwedRule`)."""
    return sum(len(p) >= 2 for p in panels_shown.values()) >= 2
