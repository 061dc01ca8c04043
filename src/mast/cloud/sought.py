"""Surveyed beacons looked for where the beacons already found put them.

Detection (:mod:`mast.cloud.detect`, :mod:`mast.cloud.match`) finds a beacon from
plan pieces cut out of the cloud before anything is known about where beacons are.
On rough rock that reaches up to the beacons it loses many (on simulated clouds of
the kind in ``mast bench georef --hard``, about four in ten of those plainly in the
cloud): the rock above a panel runs on in its plane and the piece is not vertical,
an outer panel at 20-35 degrees to the middle one is swallowed by its line, a short
panel falls apart in fragments. Once the beacons detection did find fix the
transformation, every other surveyed beacon has a predicted place in the cloud,
millimetres to centimetres off; there its design is fitted directly (to every
point of the cloud about it where georef read them, see :func:`seek_beacon`), as a
surveyor's software looks for a target where the orientation says it must be. Per
beacon (:func:`seek_beacon`):

0. **Snap.** The predicted edges moved, within three sigmas of the prediction (at
   least a centimetre), to where most points lie within two noise sigmas of its
   panels: a drift correction's prediction may be centimetres off.
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
4. **The top**: a step in the count of the points on the fitted lines per height,
   from the panels' density below to whatever runs on above (rock in a panel's plane),
   blurred by a normal spread; the top, the blur and both densities fitted by least
   squares about the run's end, the top's standard deviation from the counts' Poisson
   information (:func:`_top_step`). A top taken from wherever a piece's points stop
   ran 0.56 m up into the rock on one simulated beacon; a detected beacon's top is
   measured this way too, about its fitted edges (:func:`measure_top`).

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

__all__ = ["Sought", "measure_top", "reach_m", "seek_beacon"]

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
STEP_WINDOW_M = 0.15
#: The blurs of the top's step tried, in noise sigmas.
STEP_BLURS = (0.75, 1.0, 1.25, 1.5, 2.0, 2.5)
#: The prediction is first moved to where most points lie on its panels, within three
#: of its sigmas (:func:`_snapped`), in steps of this; after it, it is taken to be this
#: far off.
SNAP_STEP_M = 0.01
#: ... never farther than this (the beacon-level fit's own reach), in blocks of this
#: many shifts at once.
MAX_SNAP_M = 0.15
SNAP_BLOCK = 64
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
        Points on its panels (every point, with ``every``; else the candidates).
    """

    fit: BeaconFit
    top: float
    sigma_top: float
    time: float | None
    points: int


def reach_m(edges: NDArray[np.float64]) -> float:
    """Half the side of the square about a beacon's edges (plan) whose points are
    looked at: its farthest edge from their middle and :data:`REACH_SLACK_M`."""
    return float(np.max(np.hypot(*(edges - edges.mean(axis=0)).T))) + REACH_SLACK_M


def _around(xyz: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which points lie in the square of :func:`reach_m` about ``edges``."""
    return np.asarray(np.max(np.abs(xyz[:, :2] - edges.mean(axis=0)), axis=1) < reach_m(edges))


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
    among: tuple[float, float] | None = None,
) -> tuple[float, float] | None:
    """The panels' run of heights about the predicted edges (step 1 of the module), or
    None when no run as tall as a panel is there; with ``among`` (bottom, top), the
    longest run that reaches into those heights."""
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
        if among is not None and not (
            z0 + s * BIN_M < among[1] and z0 + (e + 1) * BIN_M > among[0]
        ):
            continue
        held = int(count[s : e + 1].sum())
        if best is None or held > best[0]:
            best = (held, int(s), int(e))
    if best is None:
        return None
    lo, hi = z0 + best[1] * BIN_M, z0 + (best[2] + 1) * BIN_M
    if not cfg.min_panel_height_m <= hi - lo <= cfg.max_panel_height_m + 2 * BIN_M:
        return None
    return lo, hi


def _snapped(
    plan: NDArray[np.float64], predicted: NDArray[np.float64], noise_m: float, reach_m: float
) -> NDArray[np.float64]:
    """The predicted edges moved (within ``reach_m``, on a grid of :data:`SNAP_STEP_M`,
    then a fifth of it about the best) to where most points lie within two noise sigmas
    of their panels."""
    lines = []
    for j in range(3):
        a, b = predicted[j], predicted[j + 1]
        length = math.dist(a, b)
        d = (b - a) / max(length, 1e-12)
        n = np.array([-d[1], d[0]])
        lines.append(((plan - a) @ d, (plan - a) @ n, d, n, length))

    def best(shifts: NDArray[np.float64]) -> NDArray[np.float64]:
        count = np.zeros(len(shifts))
        for first in range(0, len(shifts), SNAP_BLOCK):  # points x shifts, in blocks
            block = shifts[first : first + SNAP_BLOCK]
            for t, off, d, n, length in lines:
                ts, os_ = t[:, None] - block @ d, off[:, None] - block @ n
                on = (
                    (np.abs(os_) <= 2.0 * noise_m)
                    & (ts > END_MARGIN_M)
                    & (ts < length - END_MARGIN_M)
                )
                count[first : first + SNAP_BLOCK] += on.sum(axis=0)
        return np.asarray(shifts[int(np.argmax(count))])

    steps = max(1, math.ceil(min(reach_m, MAX_SNAP_M) / SNAP_STEP_M))
    r = np.arange(-steps, steps + 1) * SNAP_STEP_M
    shift = best(np.array([(x, y) for x in r for y in r]))
    fine = np.arange(-2, 3) * (0.2 * SNAP_STEP_M)
    shift = best(np.array([(shift[0] + x, shift[1] + y) for x in fine for y in fine]))
    return np.asarray(predicted + shift)


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
    every: NDArray[np.float64] | None = None,
) -> Sought | None:
    """The beacon of design ``shape`` (four edges, any frame) among the candidate points
    ``xyz`` (times ``time``) where ``predicted`` (its four edges in the cloud's plan)
    puts it, or None when it is not there (module docstring). ``prediction_sigma_m``:
    the prediction's standard deviation per coordinate (the survey's, at least).

    With ``every`` (all the cloud's points about it, not only the candidates), the
    edges are fitted, and tested (steps 2-3), on those: the column test keeps a panel's
    points only in cells it finds panel-like, and a panel it cut short keeps half of
    them (an edge 9 mm off on a simulated beacon, 2.8 mm with every point). The snap,
    the heights and the top (steps 0, 1 and 4) stay the candidates': among all points,
    the wall and rock about a beacon's ends run on along its lines above its top."""
    box = _around(xyz, predicted)
    near = xyz[box]
    if len(near) == 0:
        return None
    plan, z = near[:, :2], near[:, 2]
    predicted = _snapped(plan, predicted, noise_m, max(3.0 * prediction_sigma_m, SNAP_STEP_M))
    heights = _panel_heights(plan, z, predicted, math.hypot(noise_m, SNAP_STEP_M), cfg)
    if heights is None:
        return None
    dense = near if every is None else every[_around(every, predicted)]
    fit = fit_beacon(dense, shape, predicted, heights, noise_m)
    if fit is None or fit.rms_m > MAX_RMS_NOISE * noise_m:
        return None
    gate = 3.0 * noise_m
    if float(np.min(_spans(dense[:, :2], dense[:, 2], fit, gate, heights))) < MIN_SPAN_SHARE:
        return None
    on = np.isfinite(_offsets(plan, z, fit.edges, 2.0 * noise_m))
    edge = _top_step(z[on], heights[1], noise_m)
    if edge is None:
        return None
    top, sigma_top = edge
    inside = on & (z >= heights[0]) & (z <= top)
    when = None if time is None or not inside.any() else float(np.median(time[box][inside]))
    return Sought(fit, top, sigma_top, when, int(sum(fit.points)))


def measure_top(
    xyz: NDArray[np.float64],
    edges: NDArray[np.float64],
    noise_m: float,
    cfg: DetectConfig,
    among: tuple[float, float],
) -> tuple[float, float] | None:
    """The top edge of a beacon fitted at ``edges`` (four, plan) among the candidate
    points ``xyz``, and its standard deviation (steps 1 and 4 of the module docstring,
    about the fitted lines, the run of heights one that reaches into ``among``, the
    heights its detection gave); None when its panels' run of heights is not found."""
    near = xyz[_around(xyz, edges)]
    plan, z = near[:, :2], near[:, 2]
    heights = _panel_heights(plan, z, edges, noise_m, cfg, among)
    if heights is None:
        return None
    on = np.isfinite(_offsets(plan, z, edges, 2.0 * noise_m))
    return _top_step(z[on], heights[1], noise_m)


def _step_fit(
    count: NDArray[np.float64],
    mid: NDArray[np.float64],
    noise_m: float,
    weight: NDArray[np.float64],
) -> tuple[float, float, float, float] | None:
    """The step (top, blur, density below, density above) whose counts per bin at
    heights ``mid`` fit ``count`` best by least squares weighted by ``weight``: every
    top on a grid of a fifth of a bin, every blur of :data:`STEP_BLURS`, the densities
    solved for each."""
    lo, hi = float(mid[0]), float(mid[-1])
    best: tuple[float, float, float, float, float] | None = None
    for spread in STEP_BLURS:
        blur = max(spread * noise_m, 0.5 * STEP_BIN_M)
        tops = np.arange(lo + 2 * blur, hi - 2 * blur, 0.2 * STEP_BIN_M)
        if tops.size == 0:
            continue  # a blur as wide as the window: no step to place in it
        a = special.ndtr((tops[:, None] - mid) / blur)  # the share below each top
        c = 1.0 - a
        # count = dense a + rest c for every top at once
        wa, wc = a * weight, c * weight
        saa, scc, sac = (wa * a).sum(1), (wc * c).sum(1), (wa * c).sum(1)
        san, scn = wa @ count, wc @ count
        det = saa * scc - sac**2
        ok = det > 1e-12
        dense = np.where(ok, (scc * san - sac * scn) / np.where(ok, det, 1.0), 0.0)
        rest = np.where(ok, (saa * scn - sac * san) / np.where(ok, det, 1.0), 0.0)
        sse = (weight * (dense[:, None] * a + rest[:, None] * c - count) ** 2).sum(1)
        sse = np.where(ok & (dense > rest) & (rest >= -1.0), sse, np.inf)
        k = int(np.argmin(sse))
        if np.isfinite(sse[k]) and (best is None or sse[k] < best[0]):
            best = (float(sse[k]), float(tops[k]), blur, float(dense[k]), float(rest[k]))
    return None if best is None else best[1:]


def _top_step(z: NDArray[np.float64], near: float, noise_m: float) -> tuple[float, float] | None:
    """The top edge of panels whose points (heights ``z``, those on their lines) end
    near ``near``, and its standard deviation: a step in the points' count per height,
    from the panels' density below to whatever lies on their lines above (rock running
    on in a panel's plane), blurred by a normal spread of the points' heights (the
    noise, and whatever else spreads the edge: its width is fitted too). Fitted to the
    counts in :data:`STEP_BIN_M` bins over :data:`STEP_WINDOW_M` either side of
    ``near`` by least squares, then again weighted by the first fit's Poisson variances
    (a count's variance is its mean: unweighted, the many points below the top would
    outweigh the few above, and the top's spread would exceed its Cramér-Rao bound);
    its standard deviation from the counts' Poisson information, the densities and the
    blur estimated with it. None when no step down is there."""
    lo, hi = near - STEP_WINDOW_M, near + STEP_WINDOW_M
    zz = z[(z >= lo) & (z < hi)]
    bins = round(2 * STEP_WINDOW_M / STEP_BIN_M)
    k = ((zz - lo) / STEP_BIN_M).astype(np.intp)
    count = np.bincount(k, minlength=bins)[:bins].astype(np.float64)
    mid = np.asarray(lo + (np.arange(bins) + 0.5) * STEP_BIN_M, dtype=np.float64)
    first = _step_fit(count, mid, noise_m, np.ones(bins))
    if first is None:
        return None
    top, blur, inner, outer = first
    below = special.ndtr((top - mid) / blur)
    mu = np.maximum(inner * below + max(outer, 0.0) * (1.0 - below), 0.5)
    best = _step_fit(count, mid, noise_m, 1.0 / mu)
    if best is None:
        return None
    top, blur, inner, rest_fit = best
    outer = max(rest_fit, 0.0)
    # the count per bin is Poisson with mean mu: the Fisher information of (top, blur,
    # dense, rest) is J' diag(1 / mu) J; the top's variance is its share of the inverse
    u = (top - mid) / blur
    below = special.ndtr(u)
    mu = np.maximum(inner * below + outer * (1.0 - below), 0.5)
    bump = (inner - outer) * np.exp(-0.5 * u**2) / (blur * math.sqrt(2 * math.pi))
    jac = np.column_stack([bump, -bump * u, below, 1.0 - below])
    information = jac.T @ (jac / mu[:, None])
    try:
        var = float(np.linalg.inv(information)[0, 0])
    except np.linalg.LinAlgError:
        return None
    if not var > 0:
        return None
    return top, max(math.sqrt(var), 0.2 * STEP_BIN_M)
