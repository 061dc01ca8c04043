"""Returns at a beacon's silhouette: possibly mixed pixels, weighted down in the fit.

A laser beam is not a ray: its footprint is a few tenths of a degree wide. Where it
straddles a silhouette edge (a panel's free end with rock behind it) the echo mixes
the two surfaces and the range lands anywhere between them (Hebert and Krotkov 1992;
Tuley, Vandapel and Hebert 2005). The mixed returns that lie a few centimetres beyond
a panel pass any gate: weighted as clean returns, they pull the pose by more than its
sigmas say. On scenes drawn as widely as the field (``mast bench field``, issue 31),
with mixed pixels at every jump, the 95 % intervals held the truth 90-92 % of the time.

Which returns straddle is not known, but only a return at the jump can: a beam on a
beacon whose neighbouring beam passes the beacon by and returns from more than a jump
(:data:`JUMP_SIGMAS` of the step's noise, at least :data:`JUMP_MIN_M`) beyond where the
pose puts the beacon is at its silhouette. Whether it is does not depend on the beam's
own range, so no return is chosen by its own noise. Such a return's variance is
:data:`SILHOUETTE_VARIANCE` times a clean one's: a mixed pixel inside the gate lies
0-4 sigmas beyond its panel, some 2.3 sigmas RMS, so a return mixed a fifth of the
time has about twice the variance (half the time: four times). The returns at a
silhouette are a node's or a free end's, the ones that hold a beacon's azimuth, so
their weight is a trade: leaving them out cost a small beacon 40-100 % of its
azimuth precision; four times the variance cost 5 % of the azimuth's efficiency on
the accuracy benchmark (RMS/CRB 1.058 -> 1.109 at 270/0.5) for 95 % coverage on the
field scenes' hostile half of 0.929/0.954/0.942 (E/N/A; 0.904/0.938/0.917 weighted
as clean); twice the variance costs 2 % (1.079) for 0.925/0.954/0.938. The beams are
still judged on every return.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

__all__ = ["JUMP_MIN_M", "JUMP_SIGMAS", "SILHOUETTE_VARIANCE", "at_silhouette", "jump_m"]

#: A step between neighbouring returns is a jump beyond this many of its sigmas ...
JUMP_SIGMAS = 4.0
#: ... and beyond this many metres.
JUMP_MIN_M = 0.03
#: A return at a beacon's silhouette has this many times a clean return's variance.
SILHOUETTE_VARIANCE = 2.0


def jump_m(range_sigma_m: float) -> float:
    """The least range step between neighbouring beams that counts as a jump."""
    return max(JUMP_MIN_M, JUMP_SIGMAS * math.sqrt(2.0) * range_sigma_m)


def at_silhouette(
    ranges_m: NDArray[np.float64],
    valid: NDArray[np.bool_],
    beams: NDArray[np.intp],
    predicted_m: NDArray[np.float64],
    owner: NDArray[np.intp],
    ray_owner: NDArray[np.intp],
    jump: float,
) -> NDArray[np.bool_]:
    """Which of ``beams`` lie at their beacon's silhouette.

    ``beams`` return from beacon ``owner`` where the pose predicts ``predicted_m``;
    ``ray_owner`` says, for every beam of the scan, which beacon its ray first
    meets at the pose (-1: none). A beam is at the silhouette when a neighbouring
    beam's ray misses its beacon and that beam returns from more than ``jump``
    beyond the prediction.
    """
    n = ranges_m.size
    out = np.zeros(beams.size, dtype=bool)
    for side in (-1, 1):
        nb = beams + side
        inside = (nb >= 0) & (nb < n)
        nbc = np.clip(nb, 0, n - 1)
        with np.errstate(invalid="ignore"):
            past = ranges_m[nbc] - predicted_m > jump
        out |= inside & valid[nbc] & (ray_owner[nbc] != owner) & past
    return out
