"""Surveyed beacons looked for where the beacons already found put them.

Detection (:mod:`mast.cloud.detect`, :mod:`mast.cloud.match`) finds a beacon from
plan pieces cut out of the cloud before anything is known about where beacons are.
On rough rock that reaches up to the beacons it loses many (on simulated clouds of
the kind in ``mast bench georef --hard``, about four in ten of those plainly in the
cloud): the rock above a panel runs on in its plane and the piece is not vertical,
an outer panel at 20-35 degrees to the middle one is swallowed by its line, a short
panel falls apart in fragments. Once the beacons detection did find fix the
transformation, every other surveyed beacon has a predicted place in the cloud,
millimetres to centimetres off; there its design is fitted to the candidate points
directly, as a surveyor's software looks for a target where the orientation says it
must be. Per beacon (:func:`seek_beacon`):

1. **Heights.** The candidate points within a gate of the predicted panels, in
   height bins of :data:`BIN_M`: a bin is the panels' when at least
   :data:`ON_SHARE` of its points lie within two sigmas of the predicted lines (the
   cloud's noise and the survey's, together). Rock crossing a panel's plane above
   or below it scatters across the whole gate; the panels' run of heights is the
   longest run of such bins (one odd bin inside it allowed), and it must be as tall
   as a panel may be (:class:`~mast.cloud.detect.DetectConfig`).
2. **The beacon-level fit** (:func:`mast.cloud.beacon_fit.fit_beacon`) between those
   heights, from the predicted edges: placed, the three lines free, the edges with
   their covariance. It refuses a placement that slides more than 15 cm or whose
   free lines do not meet where the design does.
3. **Is it the beacon?** The points it fitted lie on its panels as on planes
   (RMS at most :data:`MAX_RMS_NOISE` times the noise: rock in the gate scatters
   across it, about 1.7 times), and each panel's points run over at least
   :data:`MIN_SPAN_SHARE` of the panel's width inside its margins (a design whose
   panels are not there is not confirmed by stray points on its lines).
4. **The top** from the fitted panels' points up to three sigmas above the run
   (:func:`mast.cloud.detect._top_edge`, as for a detected panel).

The transformation's prediction only says where to look: the edges are the fit's,
its covariance its own, and a beacon found here goes through the same tests as a
detected one. A check beacon is looked for from the control beacons alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import special

from mast.cloud.beacon_fit import END_MARGIN_M, BeaconFit, fit_beacon, points_on_panel
from mast.cloud.detect import DetectConfig

__all__ = ["Sought", "seek_beacon"]

#: Height bins of the panels' run.
BIN_M = 0.05
#: A bin is the panels' when this share of its points in the gate lie within two
#: sigmas of the predicted lines (a normal scatter puts 95 % there; rock spread
#: across the gate, about 40 %).
ON_SHARE = 0.75
#: ... and it holds at least this share of the median bin's points.
MIN_BIN_SHARE = 0.25
#: The gate about the predicted lines: three sigmas and this (the prediction's error).
GATE_SLACK_M = 0.02
#: The fitted points' RMS from their lines, at most this many noise sigmas.
MAX_RMS_NOISE = 1.25
#: Each panel's points run over at least this share of its width between the margins.
MIN_SPAN_SHARE = 0.5
#: Height bins of the top's step, and how far either side of the run's end it is fitted.
STEP_BIN_M = 0.005
STEP_WINDOW_M = 0.1
#: Points looked at around the predicted beacon: its reach and this.
REACH_SLACK_M = 0.3


@dataclass(frozen=True, eq=False)
class Sought:
    """A surveyed beacon found where it was predicted.

    Attributes
    ----------
    fit : BeaconFit
        The beacon-level fit: edges and their covariance.
    top, sigma_top : float
        Its top edge's height in the cloud and that height's standard deviation.
    time : float or None
        Median time of its panel points.
    points : int
        Points on its panels.
    """

    fit: BeaconFit
    top: float
    sigma_top: float
    time: float | None
    points: int


def _offsets(
    plan: NDArray[np.float64],
    z: NDArray[np.float64],
    edges: NDArray[np.float64],
    gate_m: float,
    heights: tuple[float, float] = (-math.inf, math.inf),
) -> NDArray[np.float64]:
    """Each point's distance from the nearest panel whose face it is on (within
    ``gate_m`` of its line, inside its edges less the margin, between ``heights``);
    infinite for points on none."""
    out = np.full(len(plan), np.inf)
    for j in range(3):
        a, b = edges[j], edges[j + 1]
        on = points_on_panel(plan, z, a, b, heights, gate_m, END_MARGIN_M)
        d = (b - a) / max(math.dist(a, b), 1e-12)
        off = np.abs((plan - a) @ np.array([-d[1], d[0]]))
        out = np.where(on & (off < out), off, out)
    return out


def _panel_heights(
    plan: NDArray[np.float64],
    z: NDArray[np.float64],
    predicted: NDArray[np.float64],
    sigma_m: float,
    cfg: DetectConfig,
) -> tuple[float, float] | None:
    """The panels' run of heights about the predicted edges (step 1 of the module), or
    None when no run as tall as a panel is there."""
    off = _offsets(plan, z, predicted, 3.0 * sigma_m + GATE_SLACK_M)
    gated = np.isfinite(off)
    zg = z[gated]
    if zg.size == 0:
        return None
    on = off[gated] <= 2.0 * sigma_m
    z0 = float(zg.min())
    k = ((zg - z0) / BIN_M).astype(np.intp)
    count = np.bincount(k)
    share = np.bincount(k, weights=on.astype(float)) / np.maximum(count, 1)
    good = (share >= ON_SHARE) & (count >= MIN_BIN_SHARE * float(np.median(count[count > 0])))
    # runs of good bins, a single odd bin between two good ones bridged
    bridged = good.copy()
    bridged[1:-1] |= good[:-2] & good[2:]
    best: tuple[int, int, int] | None = None
    starts = np.flatnonzero(bridged & ~np.r_[False, bridged[:-1]])
    ends = np.flatnonzero(bridged & ~np.r_[bridged[1:], False])
    for s, e in zip(starts, ends, strict=True):
        held = int(count[s : e + 1].sum())
        if best is None or held > best[0]:
            best = (held, int(s), int(e))
    if best is None:
        return None
    lo, hi = z0 + best[1] * BIN_M, z0 + (best[2] + 1) * BIN_M
    if not cfg.min_panel_height_m <= hi - lo <= cfg.max_panel_height_m + 2 * BIN_M:
        return None
    return lo, hi


def _spans(
    plan: NDArray[np.float64],
    z: NDArray[np.float64],
    fit: BeaconFit,
    gate_m: float,
    heights: tuple[float, float],
) -> NDArray[np.float64]:
    """The share of each panel's width (between its margins) its points run over."""
    out = np.zeros(3)
    for j in range(3):
        a, b = fit.edges[j], fit.edges[j + 1]
        on = points_on_panel(plan, z, a, b, heights, gate_m, END_MARGIN_M)
        width = math.dist(a, b) - 2 * END_MARGIN_M
        if not on.any() or width <= 0:
            continue
        t = (plan[on] - a) @ ((b - a) / math.dist(a, b))
        lo, hi = np.quantile(t, [0.02, 0.98])
        out[j] = float(hi - lo) / width
    return out


def seek_beacon(
    xyz: NDArray[np.float64],
    time: NDArray[np.float64] | None,
    shape: NDArray[np.float64],
    predicted: NDArray[np.float64],
    noise_m: float,
    prediction_sigma_m: float,
    cfg: DetectConfig,
) -> Sought | None:
    """The beacon of design ``shape`` (four edges, any frame) among the candidate points
    ``xyz`` (times ``time``) where ``predicted`` (its four edges in the cloud's plan)
    puts it, or None when it is not there (module docstring). ``prediction_sigma_m``:
    the prediction's standard deviation per coordinate (the survey's, at least)."""
    centre = predicted.mean(axis=0)
    reach = float(np.max(np.hypot(*(predicted - centre).T))) + REACH_SLACK_M
    box = np.max(np.abs(xyz[:, :2] - centre), axis=1) < reach
    near = xyz[box]
    if len(near) == 0:
        return None
    plan, z = near[:, :2], near[:, 2]
    sigma = math.hypot(noise_m, prediction_sigma_m)
    heights = _panel_heights(plan, z, predicted, sigma, cfg)
    if heights is None:
        return None
    fit = fit_beacon(near, shape, predicted, heights, noise_m)
    if fit is None or fit.rms_m > MAX_RMS_NOISE * noise_m:
        return None
    gate = 3.0 * noise_m
    if float(np.min(_spans(plan, z, fit, gate, heights))) < MIN_SPAN_SHARE:
        return None
    on = np.isfinite(_offsets(plan, z, fit.edges, 2.0 * noise_m))
    edge = _top_step(z[on], heights[1], noise_m)
    if edge is None:
        return None
    top, sigma_top = edge
    inside = on & (z >= heights[0]) & (z <= top)
    when = None if time is None else float(np.median(time[box][inside]))
    return Sought(fit, top, sigma_top, when, int(sum(fit.points)))


def _top_step(z: NDArray[np.float64], near: float, noise_m: float) -> tuple[float, float] | None:
    """The top edge of panels whose points (heights ``z``, those on their lines) end
    near ``near``, and its standard deviation: a step in the points' count per height,
    from the panels' density below to whatever lies on their lines above (rock running
    on in a panel's plane), blurred by the noise. Fitted by least squares on counts in
    :data:`STEP_BIN_M` bins over :data:`STEP_WINDOW_M` either side of ``near``; its
    standard deviation from the counts' Poisson information. None when no step down is
    there."""
    lo, hi = near - STEP_WINDOW_M, near + STEP_WINDOW_M
    zz = z[(z >= lo) & (z < hi)]
    bins = round(2 * STEP_WINDOW_M / STEP_BIN_M)
    count = np.bincount(((zz - lo) / STEP_BIN_M).astype(np.intp), minlength=bins)[:bins]
    mid = lo + (np.arange(bins) + 0.5) * STEP_BIN_M
    blur = max(noise_m, 0.5 * STEP_BIN_M)
    best: tuple[float, float, float, float] | None = None
    for top in np.arange(lo + 3 * blur, hi - 3 * blur, 0.2 * STEP_BIN_M):
        below = special.ndtr((top - mid) / blur)
        design = np.column_stack([below, 1.0 - below])
        (dense, rest), *_ = np.linalg.lstsq(design, count, rcond=None)
        sse = float(np.sum((design @ np.array([dense, rest]) - count) ** 2))
        if dense > rest >= -1.0 and (best is None or sse < best[0]):
            best = (sse, float(top), float(dense), max(float(rest), 0.0))
    if best is None:
        return None
    _, top, dense, rest = best
    # the count per bin is Poisson with mean mu: information on the top sum(mu'^2 / mu)
    below = special.ndtr((top - mid) / blur)
    mu = np.maximum(dense * below + rest * (1.0 - below), 0.5)
    slope = (
        (dense - rest) * np.exp(-0.5 * ((top - mid) / blur) ** 2) / (blur * math.sqrt(2 * math.pi))
    )
    information = float(np.sum(slope**2 / mu))
    if information <= 0:
        return None
    return top, max(1.0 / math.sqrt(information), 0.2 * STEP_BIN_M)
