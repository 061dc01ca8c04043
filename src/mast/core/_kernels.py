"""Compiled kernels (numba) of the locator's hot loops.

Each kernel has a readable numpy reference next to the code that calls it;
the tests compare the two. Compilation is cached on disk (``cache=True``): the
first call after installation compiles (about a second), later processes load
the machine code.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = [
    "adjust_rounds",
    "assigns3d",
    "associate",
    "beacon_statistics",
    "beacons_in_reach",
    "beam_checks_of",
    "bound",
    "brackets3d",
    "contiguous3d",
    "field_pyramid",
    "field_sliding",
    "first_at_least",
    "first_hits",
    "first_same",
    "floor_lows",
    "floors3d",
    "gauss_newton",
    "gauss_newton3d",
    "group_residuals",
    "icp_refine",
    "in_place_chi",
    "information",
    "key_pair_nodes",
    "line_fits",
    "linear_median",
    "near_pose",
    "nearest_by_bearing",
    "nearest_within",
    "odometry_fit",
    "overrun_counts",
    "panel_rows3d",
    "partition_dp",
    "penalty",
    "plan_ranges",
    "range_rows",
    "ray_association",
    "rays3d",
    "reach_tallies",
    "rebreak",
    "robust_gate",
    "rotation_derivatives",
    "run_breaks",
    "segment_run",
    "standardised",
    "straight_and_fitted_chi",
    "survey_shares",
    "tallies",
    "top_edges3d",
    "triple_deviations",
    "window_picks",
    "window_scores",
    "within",
]


def _penalty(n: int) -> float:
    """SSE, in noise variances, that one more line must buy (BIC-like, grows as ln n).

    A new line adds two parameters and a break point chosen among n; the
    margin is wide because a false break costs a panel its identity.
    """
    return 4.0 * math.log(max(n, 2)) + 12.0


def _piece_costs(
    sx: NDArray[np.float64],
    sy: NDArray[np.float64],
    sxx: NDArray[np.float64],
    syy: NDArray[np.float64],
    sxy: NDArray[np.float64],
    uxx: NDArray[np.float64],
    uyy: NDArray[np.float64],
    uxy: NDArray[np.float64],
    var: float,
    w: int,
) -> NDArray[np.float64]:
    """Every candidate piece's cost without the penalty: ``out[j, k]`` for the piece
    ending at ``j`` (exclusive) that starts at ``j - min(j, w) + k``, for ``k <
    min(j, w)``.

    The cost is that of ``segmentation._partition_reference`` (the piece's
    total-least-squares SSE in range-noise units across its line); the line's normal
    comes from the scatter matrix by the half-angle identities instead of ``arctan2``,
    ``sin`` and ``cos``. A piece's cost depends only on the cumulative moments at its
    two ends, so one table serves the run and every piece of it partitioned again.
    """
    n = sx.shape[0] - 1
    out = np.empty((n + 1, w))
    for j in range(1, n + 1):
        top = min(j, w)
        i0 = j - top
        sxj, syj, sxxj, syyj, sxyj = sx[j], sy[j], sxx[j], syy[j], sxy[j]
        uxxj, uyyj, uxyj = uxx[j], uyy[j], uxy[j]
        cost = out[j]
        # Branch-free over the piece starts, in increasing order, so that the compiler
        # runs four at a time; IEEE division and square root round the same either way.
        for k in range(top):
            i = i0 + k
            m = float(j - i)
            ax = sxj - sx[i]
            ay = syj - sy[i]
            vxx = sxxj - sxx[i] - ax * ax / m
            vyy = syyj - syy[i] - ay * ay / m
            vxy = sxyj - sxy[i] - ax * ay / m
            dv = vxx - vyy
            q = 0.25 * dv * dv + vxy * vxy
            root = np.sqrt(q)
            half_r = root if q > 0.0 else 0.0
            sse = 0.5 * (vxx + vyy) - half_r
            sse = sse if sse >= 0.0 else 0.0
            # Normal of the line (the scatter's minor axis): with cos 2t = dv / r and
            # sin 2t = 2 vxy / r (t = 0 when r = 0), n = (-sin t, cos t).
            turned = half_r > 0.0
            den = half_r if turned else 1.0
            c2 = 0.5 * dv / den if turned else 1.0
            s2 = vxy / den if turned else 0.0
            nu2 = (
                0.5 * (1.0 - c2) * (uxxj - uxx[i])
                - s2 * (uxyj - uxy[i])
                + 0.5 * (1.0 + c2) * (uyyj - uyy[i])
            ) / m
            nu2 = nu2 if nu2 >= 0.05 else 0.05
            cost[k] = sse / (var * nu2)
    return out


def _best_pointers(
    costs: NDArray[np.float64], lo: int, hi: int, pen: float, w: int, w_costs: int
) -> NDArray[np.intp]:
    """Optimal partition's back-pointers of the returns ``lo:hi`` of a run whose piece
    costs are ``costs`` (:func:`_piece_costs`, pieces of at most ``w_costs``): ``last[j]``
    is where the piece ending at ``lo + j`` (exclusive) starts, less ``lo``, for every
    ``j`` in 1..hi - lo, pieces of at most ``w`` returns, each paying ``pen`` and 4 per
    return of a piece of one or two. Ties go to the shortest piece, as ``argmin`` does
    in ``segmentation._partition_reference``."""
    n = hi - lo
    best = np.empty(n + 1)
    best[0] = -pen
    last = np.zeros(n + 1, dtype=np.intp)
    for j in range(1, n + 1):
        top = min(j, w)
        row = costs[lo + j]
        end = min(lo + j, w_costs)  # the row's entry of the piece of length d is end - d
        bj = math.inf
        arg = j - 1
        for d in range(1, top + 1):  # shortest piece first: ties go to it
            total = row[end - d] + pen
            if d < 3:
                total += 4.0 * d
            total = best[j - d] + total
            if total < bj:
                bj = total
                arg = j - d
        best[j] = bj
        last[j] = arg
    return last


def _partition_dp(
    sx: NDArray[np.float64],
    sy: NDArray[np.float64],
    sxx: NDArray[np.float64],
    syy: NDArray[np.float64],
    sxy: NDArray[np.float64],
    uxx: NDArray[np.float64],
    uyy: NDArray[np.float64],
    uxy: NDArray[np.float64],
    var: float,
    pen: float,
    w: int,
) -> NDArray[np.intp]:
    """Optimal partition's back-pointers: ``last[j]`` is where the piece ending at
    ``j`` (exclusive) starts, for every ``j`` in 1..n (:func:`_piece_costs`, then
    :func:`_best_pointers`): ``segmentation._partition_reference`` compiled."""
    n = sx.shape[0] - 1
    costs = _piece_costs_jit(sx, sy, sxx, syy, sxy, uxx, uyy, uxy, var, w)
    return _best_pointers_jit(costs, 0, n, pen, w, w)


def _associate(
    points: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gates: NDArray[np.float64],
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Nearest panel (of ``panels``) of each point within its gate of the panel's line
    and inside its extent, and the signed distance; -1 and inf for none.

    ``gates`` holds one gate per point, or a single gate for all. Ties go to the
    first panel, as ``argmin`` does in ``PanelSet._associate_reference``
    (:func:`_associate_into`).
    """
    n = points.shape[0]
    idx = np.empty(n, dtype=np.intp)
    dist = np.empty(n)
    _associate_into_jit(points, a, direction, normal, length, panels, gates, idx, dist)
    return idx, dist


def _associate_into(
    points: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gates: NDArray[np.float64],
    idx: NDArray[np.intp],
    dist: NDArray[np.float64],
) -> None:
    """:func:`_associate` into ``idx`` and ``dist``, for a loop that associates again and
    again without allocating. One panel at a time over every point (panels in order, so
    ties still go to the first), so that the compiler runs several points at once."""
    n = points.shape[0]
    one = gates.shape[0] == 1
    if not one and gates.shape[0] != n:
        raise ValueError("associate: one gate, or one per point")
    idx[:n] = -1
    dist[:n] = np.inf
    for k in range(panels.shape[0]):
        q = panels[k]
        ax, ay = a[q, 0], a[q, 1]
        dx, dy = direction[q, 0], direction[q, 1]
        nx, ny = normal[q, 0], normal[q, 1]
        ln = length[q]
        for p in range(n):
            rx = points[p, 0] - ax
            ry = points[p, 1] - ay
            t = rx * dx + ry * dy
            s = rx * nx + ry * ny
            d = abs(s)
            g = gates[0] if one else gates[p]
            if t >= 0.0 and t <= ln and d <= g and d < abs(dist[p]):
                idx[p] = q
                dist[p] = s


def _crossing_terms(
    origin: NDArray[np.float64], seg_a: NDArray[np.float64], seg_b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], ...]:
    """Per segment, what every ray from ``origin`` needs to find where it crosses it."""
    m = seg_a.shape[0]
    ex = np.empty(m)
    ey = np.empty(m)
    wx = np.empty(m)
    wy = np.empty(m)
    w_x_e = np.empty(m)
    for k in range(m):
        ex[k] = seg_b[k, 0] - seg_a[k, 0]
        ey[k] = seg_b[k, 1] - seg_a[k, 1]
        wx[k] = seg_a[k, 0] - origin[0]
        wy[k] = seg_a[k, 1] - origin[1]
        w_x_e[k] = wx[k] * ey[k] - wy[k] * ex[k]
    return ex, ey, wx, wy, w_x_e


def _first_crossing(
    dx: float,
    dy: float,
    ex: NDArray[np.float64],
    ey: NDArray[np.float64],
    wx: NDArray[np.float64],
    wy: NDArray[np.float64],
    w_x_e: NDArray[np.float64],
) -> tuple[float, int]:
    """Distance along the ray ``(dx, dy)`` to the first segment it crosses, and which
    (``inf`` and -1 for none; the first segment on a tie, as ``argmin``)."""
    bt = np.inf
    bj = -1
    for k in range(ex.shape[0]):
        tt = _crossing_jit(dx, dy, k, ex, ey, wx, wy, w_x_e)
        if tt < bt:
            bt = tt
            bj = k
    return bt, bj


def _crossing(
    dx: float,
    dy: float,
    k: int,
    ex: NDArray[np.float64],
    ey: NDArray[np.float64],
    wx: NDArray[np.float64],
    wy: NDArray[np.float64],
    w_x_e: NDArray[np.float64],
) -> float:
    """Distance along the ray ``(dx, dy)`` to segment ``k`` (:func:`_crossing_terms`),
    ``inf`` when it does not cross it ahead of the origin."""
    den = dx * ey[k] - dy * ex[k]
    if den == 0.0:
        return np.inf
    tt: float = w_x_e[k] / den
    s = (wx[k] * dy - wy[k] * dx) / den
    if tt > 1e-12 and s >= 0.0 and s <= 1.0:
        return tt
    return np.inf


def _beam_windows(
    angles: NDArray[np.float64], lo_angle: float, width: float, lo_hi: NDArray[np.intp]
) -> int:
    """The runs of ``angles`` (increasing, a turn at most) within ``[lo_angle, lo_angle +
    width]`` turned by any whole number of turns, into ``lo_hi`` (rows start, stop);
    returns how many. ``width`` is under half a turn."""
    two_pi = 2.0 * math.pi
    # The interval's start, a turn at most above the first beam's angle.
    base = angles[0] + (lo_angle - angles[0]) % two_pi
    windows = 0
    for shift in (-two_pi, 0.0, two_pi):
        lo = np.searchsorted(angles, base + shift, side="left")
        hi = np.searchsorted(angles, base + width + shift, side="right")
        if hi > lo:
            lo_hi[windows, 0], lo_hi[windows, 1] = lo, hi
            windows += 1
    return windows


def _first_hits(
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """``geometry._first_hits_reference`` ray by ray: the same crossing formulas,
    the first segment on a tie (as ``argmin``)."""
    n = directions.shape[0]
    best = np.full(n, np.inf)
    which = np.full(n, -1, dtype=np.intp)
    ex, ey, wx, wy, w_x_e = _crossing_terms_jit(origin, seg_a, seg_b)
    for i in range(n):
        best[i], which[i] = _first_crossing_jit(
            directions[i, 0], directions[i, 1], ex, ey, wx, wy, w_x_e
        )
    return best, which


def _within(
    points: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    reach: float,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Points within ``reach`` (Euclidean) of any of ``panels``, and which of ``panels``
    have a point that close: ``PanelSet._within_reference`` without its
    (points x panels) arrays. One panel at a time over every point, so that the
    compiler runs several points at once."""
    n = points.shape[0]
    x = np.ascontiguousarray(points[:, 0])
    y = np.ascontiguousarray(points[:, 1])
    zero = np.zeros(n)
    near = np.zeros(n, dtype=np.bool_)
    close = np.empty(n, dtype=np.bool_)
    reached = np.zeros(panels.shape[0], dtype=np.bool_)
    for k in range(panels.shape[0]):
        _close_to_jit(x, y, zero, panels[k], a, direction, normal, length, reach, 0.0, close)
        any_close = False
        for p in range(n):
            any_close |= close[p]
            near[p] |= close[p]
        reached[k] = any_close
    return near, reached


def _reach_windows(
    angles: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    length: NDArray[np.float64],
    q: int,
    reach: float,
    lo_hi: NDArray[np.intp],
) -> int:
    """The runs of beams (``angles``, increasing, a turn at most) from the pose that a
    return within ``reach`` of panel ``q`` can lie on, into ``lo_hi`` (:func:`_beam_windows`);
    returns how many, or -1 for every beam.

    A point within ``r`` of a point ``p`` of the panel lies within ``asin(r / |p|)`` of
    ``p``'s bearing from the scanner, and ``|p|`` is at least the panel's distance ``D``
    from it: the beams within the angle the panel subtends widened by ``asin(r / D)`` on
    each side hold every return within ``r`` of it. ``r`` is ``reach`` widened by a
    micrometre (a mine-frame place is rounded to about 1e-9 m at a UTM northing), the
    angles by a nanoradian; every beam when the scanner is within ``r`` of the panel or
    the widened angle is half a turn or more."""
    ax, ay = a[q, 0] - easting, a[q, 1] - northing
    dx, dy = direction[q, 0], direction[q, 1]
    ln = length[q]
    r = reach * (1.0 + 1e-9) + 1e-6
    # the scanner's distance from the panel (as a segment)
    t = min(max(-(ax * dx + ay * dy), 0.0), ln)
    far = math.hypot(ax + t * dx, ay + t * dy)
    if not far > r:
        return -1
    bx, by = ax + ln * dx, ay + ln * dy
    # A mine-frame direction (dx, dy) is the beam at angle azimuth - atan2(dx, dy).
    at_a = azimuth - math.atan2(ax, ay)
    at_b = azimuth - math.atan2(bx, by)
    turn = (at_b - at_a + math.pi) % (2.0 * math.pi) - math.pi
    widen = math.asin(r / far) + 1e-9
    width = abs(turn) + 2.0 * widen
    if not width < math.pi - 1e-6:
        return -1
    return _beam_windows_jit(angles, min(at_a, at_a + turn) - widen, width, lo_hi)


def _bearing_spans(
    n: int,
    angles: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    reach: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp], int]:
    """Each of ``panels``' runs of beams (:func:`_reach_windows`; every one of the ``n``
    beams where it says so): ``spans[k, w]`` the ``w``-th (start, stop) of ``panels[k]``,
    ``windows[k]`` how many, and how many beams in all."""
    n_panels = panels.shape[0]
    spans = np.empty((n_panels, 3, 2), dtype=np.intp)
    windows = np.empty(n_panels, dtype=np.intp)
    room = 0
    for k in range(n_panels):
        w = _reach_windows_jit(
            angles, easting, northing, azimuth, a, direction, length, panels[k], reach, spans[k]
        )
        if w < 0:
            spans[k, 0, 0], spans[k, 0, 1] = 0, n
            w = 1
        windows[k] = w
        for j in range(w):
            room += spans[k, j, 1] - spans[k, j, 0]
    return spans, windows, room


def _pairs_by_bearing(
    points: NDArray[np.float64],
    angles: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    reach: float,
) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.intp], NDArray[np.intp]]:
    """:func:`_within` of the mine-frame ``points`` the pose places returns at (beam
    ``angles``, increasing, a turn at most), each panel tested only on the beams that
    can reach it (:func:`_reach_windows`): the same ``(near, reached)``, a few dozen
    returns a panel instead of the scan; and the pairs found, the points of each
    reached panel in turn (``pair_point[ptr[j]:ptr[j + 1]]`` for the ``j``-th reached
    panel, points in increasing order)."""
    n = points.shape[0]
    n_panels = panels.shape[0]
    near = np.zeros(n, dtype=np.bool_)
    reached = np.zeros(n_panels, dtype=np.bool_)
    spans, windows, room = _bearing_spans_jit(
        n, angles, easting, northing, azimuth, a, direction, length, panels, reach
    )
    pair_point = np.empty(room, dtype=np.intp)
    ptr = np.zeros(n_panels + 1, dtype=np.intp)
    r2 = reach * reach
    got = 0
    n_reached = 0
    for k in range(n_panels):
        q = panels[k]
        ax, ay = a[q, 0], a[q, 1]
        dx, dy = direction[q, 0], direction[q, 1]
        nx, ny = normal[q, 0], normal[q, 1]
        ln = length[q]
        first = got
        for w in range(windows[k]):
            for p in range(spans[k, w, 0], spans[k, w, 1]):
                rx = points[p, 0] - ax
                ry = points[p, 1] - ay
                t = rx * dx + ry * dy
                s = rx * nx + ry * ny
                over = max(max(-t, t - ln), 0.0)
                if over * over + s * s <= r2:
                    near[p] = True
                    pair_point[got] = p
                    got += 1
        if got > first:
            reached[k] = True
            n_reached += 1
            ptr[n_reached] = got
    return near, reached, ptr[: n_reached + 1], pair_point[:got]


def _associate_pairs(
    points: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gate: float,
    ptr: NDArray[np.intp],
    pair_point: NDArray[np.intp],
    idx: NDArray[np.intp],
    dist: NDArray[np.float64],
) -> None:
    """:func:`_associate_into` with one gate, testing only the pairs of each panel
    (``pair_point[ptr[k]:ptr[k + 1]]`` for ``panels[k]``), panels in the same order:
    the same matches when every point within the gate of a panel is among its pairs."""
    n = points.shape[0]
    idx[:n] = -1
    dist[:n] = np.inf
    for k in range(panels.shape[0]):
        q = panels[k]
        ax, ay = a[q, 0], a[q, 1]
        dx, dy = direction[q, 0], direction[q, 1]
        nx, ny = normal[q, 0], normal[q, 1]
        ln = length[q]
        for j in range(ptr[k], ptr[k + 1]):
            p = pair_point[j]
            rx = points[p, 0] - ax
            ry = points[p, 1] - ay
            t = rx * dx + ry * dy
            s = rx * nx + ry * ny
            d = abs(s)
            if t >= 0.0 and t <= ln and d <= gate and d < abs(dist[p]):
                idx[p] = q
                dist[p] = s


def _associate_by_bearing(
    points: NDArray[np.float64],
    angles: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gate: float,
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """:func:`_associate` with one gate, of the mine-frame ``points`` the pose places
    returns at (beam ``angles``, increasing, a turn at most), each panel tested only on
    the beams that can reach it within the gate (:func:`_reach_windows`: a return
    inside a panel's extent and within the gate of its line is within the gate of the
    panel): the same answer, panels in the same order."""
    n = points.shape[0]
    n_panels = panels.shape[0]
    spans, windows, room = _bearing_spans_jit(
        n, angles, easting, northing, azimuth, a, direction, length, panels, gate
    )
    ptr = np.zeros(n_panels + 1, dtype=np.intp)
    pair_point = np.empty(room, dtype=np.intp)
    got = 0
    for k in range(n_panels):
        for w in range(windows[k]):
            for p in range(spans[k, w, 0], spans[k, w, 1]):
                pair_point[got] = p
                got += 1
        ptr[k + 1] = got
    idx = np.empty(n, dtype=np.intp)
    dist = np.empty(n)
    _associate_pairs_jit(
        points, a, direction, normal, length, panels, gate, ptr, pair_point, idx, dist
    )
    return idx, dist


def _close_to(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    ranges: NDArray[np.float64],
    q: int,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    reach: float,
    per_range: float,
    close: NDArray[np.bool_],
    after: float = 0.0,
) -> None:
    """``close[p]``: point ``p`` within ``reach + per_range * ranges[p] + after`` of panel
    ``q``, as a segment."""
    ax, ay = a[q, 0], a[q, 1]
    dx, dy = direction[q, 0], direction[q, 1]
    nx, ny = normal[q, 0], normal[q, 1]
    ln = length[q]
    for p in range(x.shape[0]):
        rx = x[p] - ax
        ry = y[p] - ay
        t = rx * dx + ry * dy
        s = rx * nx + ry * ny
        over = max(max(-t, t - ln), 0.0)
        r = reach + per_range * ranges[p] + after
        close[p] = over * over + s * s <= r * r


def _reach_tallies(
    points: NDArray[np.float64],
    ranges: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    beacon: NDArray[np.intp],
    panels: NDArray[np.intp],
    reach: float,
    per_range: float,
    after: float,
    beacons: int,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Points within ``reach + per_range * range + after`` (Euclidean, in that order of
    sums) of each of ``panels`` (a point counts for every panel it is that close to),
    and of any panel of each beacon (a point counts once for a beacon, however many of
    its panels it is near). ``beacon[q]`` is panel ``q``'s beacon (``0 <= beacon <
    beacons``), ``ranges`` each point's range. ``PanelSet._reach_tallies_reference``
    without its (points x panels) arrays."""
    n = points.shape[0]
    x = np.ascontiguousarray(points[:, 0])
    y = np.ascontiguousarray(points[:, 1])
    per_panel = np.zeros(panels.shape[0], dtype=np.int64)
    per_beacon = np.zeros(beacons, dtype=np.int64)
    close = np.empty(n, dtype=np.bool_)
    mark = np.zeros(n, dtype=np.bool_)
    done = np.zeros(panels.shape[0], dtype=np.bool_)
    for k in range(panels.shape[0]):
        if done[k]:
            continue
        b = beacon[panels[k]]
        mark[:] = False
        for m in range(k, panels.shape[0]):  # every panel of beacon b, once
            if beacon[panels[m]] != b:
                continue
            done[m] = True
            _close_to_jit(
                x,
                y,
                ranges,
                panels[m],
                a,
                direction,
                normal,
                length,
                reach,
                per_range,
                close,
                after,
            )
            c = 0
            for p in range(n):
                c += close[p]
                mark[p] |= close[p]
            per_panel[m] = c
        c = 0
        for p in range(n):
            c += mark[p]
        per_beacon[b] = c
    return per_panel, per_beacon


def _beacon_gathers(
    b: int,
    j: int,
    last: int,
    e: float,
    nn: float,
    az: float,
    points: NDArray[np.float64],
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    near: NDArray[np.intp],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    beacon: NDArray[np.intp],
    centre: NDArray[np.float64],
    radius: NDArray[np.float64],
    reach: float,
    per_range: float,
    far: float,
    need: int,
    lo_hi: NDArray[np.intp],
) -> bool:
    """Whether beacon ``b`` (its panels among ``near[j:last]``, the first at ``j``) has
    ``need`` returns within reach from the start ``(e, nn, az)``: :func:`_beacons_in_reach`'s
    test of one beacon (``far`` the farthest range, ``lo_hi`` room for the windows)."""
    n = points.shape[0]
    sa, ca = math.sin(az), math.cos(az)
    rotation = math.pi / 2 - az
    dx, dy = centre[b, 0] - e, centre[b, 1] - nn
    dist = math.hypot(dx, dy)
    grow = radius[b] + reach + per_range * far
    # The beam angle of the centre's direction, and the beams either side.
    bearing = math.atan2(dy, dx) - rotation
    windows = 0
    if dist <= grow:
        lo_hi[0, 0], lo_hi[0, 1] = 0, n
        windows = 1
    else:
        half = math.asin(grow / dist) + 1e-9
        windows = _beam_windows_jit(angles, bearing - half, 2.0 * half, lo_hi)
    # Each window's returns from the beam nearest the centre's direction outwards, one
    # side then the other: a beacon that has enough has them there, and counting stops
    # once it has (the count does not depend on the order).
    two_pi = 2.0 * math.pi
    towards = np.searchsorted(angles, angles[0] + (bearing - angles[0]) % two_pi)
    # The beacon's panels, in their order among ``near``.
    mine = np.empty(last - j, dtype=np.intp)
    panels = 0
    for jj in range(j, last):
        if beacon[near[jj]] == b:
            mine[panels] = near[jj]
            panels += 1
    count = 0
    for w in range(windows):
        lo, hi = lo_hi[w, 0], lo_hi[w, 1]
        up = min(max(towards, lo), hi - 1)
        down = up - 1
        upwards = True
        while up < hi or down >= lo:
            if up < hi and (upwards or down < lo):
                p = up
                up += 1
            else:
                p = down
                down -= 1
            upwards = not upwards
            x, y = points[p, 0], points[p, 1]
            mx = sa * x - ca * y + e
            my = ca * x + sa * y + nn
            r = reach + per_range * ranges[p]
            for m in range(panels):
                q = mine[m]
                rx = mx - a[q, 0]
                ry = my - a[q, 1]
                t = rx * direction[q, 0] + ry * direction[q, 1]
                s = rx * normal[q, 0] + ry * normal[q, 1]
                over = max(max(-t, t - length[q]), 0.0)
                if over * over + s * s <= r * r:
                    count += 1
                    break
            if count >= need:
                return True
    return False


def _beacons_in_reach(
    points: NDArray[np.float64],
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    starts: NDArray[np.float64],
    near_ptr: NDArray[np.intp],
    near: NDArray[np.intp],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    beacon: NDArray[np.intp],
    centre: NDArray[np.float64],
    radius: NDArray[np.float64],
    reach: float,
    per_range: float,
    need: int,
    own_ptr: NDArray[np.intp],
    own: NDArray[np.intp],
    stop_at: int,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """For each start pose (rows E, N, azimuth), the beacons with at least ``need``
    returns within ``reach + per_range * range`` of their panels among the start's
    ``near[near_ptr[h]:near_ptr[h + 1]]`` (a return counts once for a beacon): the
    beacons ``verification._in_reach`` finds, for every start in one call.

    With ``stop_at`` > 0, each start's own beacons ``own[own_ptr[h]:own_ptr[h + 1]]``
    are tested first and the search stops at the first of them that falls short (it is
    left out) or once ``stop_at`` beacons are found: then whether the own beacons are
    all among those found, and whether at least ``stop_at`` are, is what the whole set
    would say.

    ``points`` are the returns in the scanner frame, ``angles`` their beams' angles
    (increasing, a turn at most), ``ranges`` their ranges; ``beacon[q]`` is panel
    ``q``'s beacon, whose panels all lie within ``radius`` of ``centre`` (indexed by
    beacon). Each beacon is tested only on the beams pointing its way, and counting
    stops at ``need``: a return at bearing ``d`` off the direction of a centre ``D``
    away lies at least ``D sin(d)`` from it (``d`` up to a right angle; beyond, at
    least ``D``), so when ``D`` exceeds ``g = radius + reach + per_range * (the
    farthest range)``, a return more than ``asin(g / D)`` off that direction is farther
    than its reach from every panel of the beacon. A point's mine-frame place is
    ``Pose2D.scanner_to_mine``'s arithmetic. Returns the beacons found, start after
    start, and where each start's begin (``ptr[h]:ptr[h + 1]``).
    """
    k_starts = starts.shape[0]
    n = points.shape[0]
    ptr = np.zeros(k_starts + 1, dtype=np.intp)
    found = np.empty(max(near.shape[0], 1), dtype=np.intp)
    got = 0
    if n == 0:
        return found[:0], ptr  # no return is in reach of anything
    far = 0.0
    for i in range(n):
        far = max(far, ranges[i])
    lo_hi = np.empty((3, 2), dtype=np.intp)
    for h in range(k_starts):
        e, nn, az = starts[h, 0], starts[h, 1], starts[h, 2]
        first, last = near_ptr[h], near_ptr[h + 1]
        done = False
        if stop_at > 0:
            for o in range(own_ptr[h], own_ptr[h + 1]):
                b = own[o]
                j = first
                while j < last and beacon[near[j]] != b:
                    j += 1
                if j == last or not _beacon_gathers_jit(
                    b, j, last, e, nn, az, points, angles, ranges, near, a, direction,
                    normal, length, beacon, centre, radius, reach, per_range, far, need, lo_hi,
                ):  # fmt: skip
                    done = True  # an own beacon falls short: the rest cannot matter
                    break
                found[got] = b
                got += 1
            if got - ptr[h] >= stop_at:
                done = True
        j = first
        while not done and j < last:
            b = beacon[near[j]]
            repeat = False
            for jj in range(first, j):
                if beacon[near[jj]] == b:
                    repeat = True
                    break
            if stop_at > 0:
                for o in range(own_ptr[h], own_ptr[h + 1]):
                    if own[o] == b:
                        repeat = True  # tested first
            if not repeat and _beacon_gathers_jit(
                b, j, last, e, nn, az, points, angles, ranges, near, a, direction, normal,
                length, beacon, centre, radius, reach, per_range, far, need, lo_hi,
            ):  # fmt: skip
                found[got] = b
                got += 1
                if stop_at > 0 and got - ptr[h] >= stop_at:
                    done = True
            j += 1
        ptr[h + 1] = got
    return found[:got], ptr


def _first_same(
    poses: NDArray[np.float64],
    size: int,
    easting: float,
    northing: float,
    azimuth: float,
    within_m: float,
    within_rad: float,
) -> int:
    """The first of ``poses[:size]`` (rows E, N, azimuth) within ``within_m`` and
    ``within_rad`` (both strictly) of the pose given, or -1: ``hypot`` of the offsets,
    and the azimuth difference wrapped as ``pose.wrap_angles`` does (a row of NaN is
    never the same)."""
    two_pi = 2.0 * math.pi
    for i in range(size):
        d = math.hypot(poses[i, 0] - easting, poses[i, 1] - northing)
        a = poses[i, 2] - azimuth
        da = abs(a - two_pi * np.rint(a / two_pi))
        if d < within_m and da < within_rad:
            return i
    return -1


def _to_mine(
    points: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    out: NDArray[np.float64],
) -> None:
    """Scanner-frame ``points`` placed in the mine frame by the pose, into ``out``."""
    sa, ca = math.sin(azimuth), math.cos(azimuth)
    for i in range(points.shape[0]):
        x, y = points[i, 0], points[i, 1]
        out[i, 0] = sa * x - ca * y + easting
        out[i, 1] = ca * x + sa * y + northing


def _normal_step(
    design: NDArray[np.float64], rhs: NDArray[np.float64], k: int
) -> NDArray[np.float64]:
    """The least-squares solution of ``design[:k] @ x = rhs[:k]`` for three unknowns by
    the normal equations, solved by cofactors; NaNs when they are near singular (the
    determinant below 1e-9 of the diagonal's product), for the caller's LAPACK
    ``lstsq`` to answer instead. A pose step's normal matrix is well conditioned (its
    columns are metres, metres and metres-times-range: a condition number in the
    thousands), so the answer is the SVD's to about 1e-12 of a step, at a twentieth of
    its cost; :func:`mast.core.linalg.pose_step` is the same in numpy."""
    a00 = a01 = a02 = a11 = a12 = a22 = b0 = b1 = b2 = 0.0
    for r in range(k):
        d0, d1, d2, y = design[r, 0], design[r, 1], design[r, 2], rhs[r]
        a00 += d0 * d0
        a01 += d0 * d1
        a02 += d0 * d2
        a11 += d1 * d1
        a12 += d1 * d2
        a22 += d2 * d2
        b0 += d0 * y
        b1 += d1 * y
        b2 += d2 * y
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    out = np.full(3, np.nan)
    if not abs(det) > 1e-9 * a00 * a11 * a22:
        return out
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    out[0] = (c00 * b0 + c01 * b1 + c02 * b2) / det
    out[1] = (c01 * b0 + c11 * b1 + c12 * b2) / det
    out[2] = (c02 * b0 + c12 * b1 + c22 * b2) / det
    return out


def _icp_stages(
    points: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gates: NDArray[np.float64],
    max_iterations: int,
    tolerance_m: float,
    tolerance_rad: float,
    ptr: NDArray[np.intp],
    pair_point: NDArray[np.intp],
    slack_m: float,
) -> tuple[float, float, float, int, bool]:
    """The iterations of ``alignment._icp_reference``: ``(E, N, azimuth, iterations, converged)``.

    Each stage associates every point with its nearest panel within the
    stage's gate (:func:`_associate`), stops a coarse stage once the matches
    stop changing, closes a loop of matches met before in the stage, and
    otherwise takes the least-squares step of the linearised point-to-line
    problem (Low 2004) for a translation and a rotation about the scanner:
    the same rules and the same solver as the reference (:func:`_normal_step`, and
    LAPACK's ``lstsq`` where it declines). Its arrays are made once, not per
    iteration.

    ``ptr`` and ``pair_point`` (empty when not known), the points within reach of each
    of ``panels`` at the start (:func:`_pairs_by_bearing`); ``slack_m``, that reach.
    While no point has moved more than the reach less its stage's gate from its start
    (a move of ``t`` and a turn of ``w`` move a point at range ``r`` by at most ``t + r
    * w``), a point within a gate of a panel is among its pairs, and only those are
    tested: the same matches.
    """
    n = points.shape[0]
    e, nn, az = easting, northing, azimuth
    total = 0
    converged = False
    # The matches of the last association and of the one before, in turn; every one
    # of a stage met so far; the step's rows.
    matches = np.full((2, n), -1, dtype=np.intp)
    latest = 0
    dist = np.empty(n)
    seen = np.empty((max_iterations, n), dtype=np.intp)
    design = np.empty((n, 3))
    rhs = np.empty(n)
    m = np.empty((n, 2))
    paired = ptr.shape[0] == panels.shape[0] + 1
    farthest = 0.0
    for i in range(n):
        farthest = max(farthest, math.hypot(points[i, 0], points[i, 1]))
    n_stages = gates.shape[0]
    for stage in range(n_stages):
        converged = False
        final = stage == n_stages - 1
        before = latest
        n_seen = 0
        gate = gates[stage : stage + 1]
        for _ in range(max_iterations):
            total += 1
            _to_mine_jit(points, e, nn, az, m)
            latest = 1 - before
            panel = matches[latest]
            previous = matches[before]
            turned = (az - azimuth + math.pi) % (2.0 * math.pi) - math.pi
            moved = math.hypot(e - easting, nn - northing) + farthest * abs(turned)
            if paired and moved < slack_m - gate[0] - 1e-6:
                _associate_pairs_jit(
                    m, a, direction, normal, length, panels, gate[0], ptr, pair_point, panel, dist
                )
            else:
                _associate_into_jit(m, a, direction, normal, length, panels, gate, panel, dist)
            same = True
            for i in range(n):
                if panel[i] != previous[i]:
                    same = False
                    break
            if not final and same:
                converged = True
                break
            if not same:
                met = False
                for k in range(n_seen):
                    met = True
                    for i in range(n):
                        if seen[k, i] != panel[i]:
                            met = False
                            break
                    if met:
                        break
                if met:
                    converged = True
                    break
            if n_seen < max_iterations:
                seen[n_seen, :] = panel
                n_seen += 1
            before = latest
            k_ok = 0
            for i in range(n):
                q = panel[i]
                if q < 0:
                    continue
                rx, ry = m[i, 0] - e, m[i, 1] - nn
                design[k_ok, 0] = normal[q, 0]
                design[k_ok, 1] = normal[q, 1]
                design[k_ok, 2] = normal[q, 1] * rx - normal[q, 0] * ry
                rhs[k_ok] = -dist[i]
                k_ok += 1
            if k_ok < 3:
                break
            step: NDArray[np.floating[Any]] = _normal_step_jit(design, rhs, k_ok)
            if not math.isfinite(step[0]):
                step = np.linalg.lstsq(design[:k_ok], rhs[:k_ok])[0]
            omega = math.pi / 2 - az + step[2]
            e = e + step[0]
            nn = nn + step[1]
            az = (math.pi / 2 - omega) % (2 * math.pi)
            tol_m = max(tolerance_m, 4 * np.spacing(max(abs(e), abs(nn), 1.0)))
            if math.hypot(step[0], step[1]) < tol_m and abs(step[2]) < max(
                tolerance_rad, tol_m / 100.0
            ):
                converged = True
                break
    return e, nn, az, total, converged


def _icp_refine(
    points: NDArray[np.float64],
    easting: float,
    northing: float,
    azimuth: float,
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    panels: NDArray[np.intp],
    gates: NDArray[np.float64],
    max_iterations: int,
    tolerance_m: float,
    tolerance_rad: float,
    angles: NDArray[np.float64],
) -> tuple[float, float, float, int, bool, NDArray[np.intp], NDArray[np.float64]]:
    """``alignment.icp_point_to_line`` in one call: the returns and ``panels`` within
    twice the widest gate (plus 5 cm) of each other at the start
    (:func:`_within`), :func:`_icp_stages` on them, and every return associated at the
    pose reached within the last gate (:func:`_associate`; residual NaN for none).
    A return's mine-frame place is :func:`_icp_stages`' arithmetic. With the returns'
    beam ``angles`` (increasing, a turn at most; empty when not known) each panel is
    tested only on the beams that can reach it (:func:`_pairs_by_bearing`,
    :func:`_associate_by_bearing`): the same answer.

    Returns ``(E, N, azimuth, iterations, converged, panel, residual)``.
    """
    n = points.shape[0]
    by_bearing = n > 0 and angles.shape[0] == n
    m = np.empty((n, 2))
    _to_mine_jit(points, easting, northing, azimuth, m)
    widest = gates.max()
    reach = 2.0 * widest + 0.05
    if by_bearing:
        near, reached, ptr, pair_point = _pairs_by_bearing_jit(
            m, angles, easting, northing, azimuth, a, direction, normal, length, panels, reach
        )
    else:
        near, reached = _within_jit(m, a, direction, normal, length, panels, reach)
        ptr = np.zeros(0, dtype=np.intp)
        pair_point = np.zeros(0, dtype=np.intp)
    count = 0
    for i in range(n):
        if near[i]:
            count += 1
    close = np.empty((count, 2))
    # each point's place among the close ones, for the pairs
    place = np.empty(n, dtype=np.intp)
    c = 0
    for i in range(n):
        if near[i]:
            close[c, 0] = points[i, 0]
            close[c, 1] = points[i, 1]
            place[i] = c
            c += 1
    for j in range(pair_point.shape[0]):
        pair_point[j] = place[pair_point[j]]
    e, nn, az, total, converged = _icp_stages_jit(
        close,
        easting,
        northing,
        azimuth,
        a,
        direction,
        normal,
        length,
        panels[reached],
        gates,
        max_iterations,
        tolerance_m,
        tolerance_rad,
        ptr,
        pair_point,
        reach,
    )
    _to_mine_jit(points, e, nn, az, m)
    if by_bearing:
        panel, dist = _associate_by_bearing_jit(
            m, angles, e, nn, az, a, direction, normal, length, panels, gates[gates.shape[0] - 1]
        )
    else:
        panel, dist = _associate_jit(
            m, a, direction, normal, length, panels, gates[gates.shape[0] - 1 :]
        )
    for i in range(n):
        if panel[i] < 0:
            dist[i] = np.nan
    return e, nn, az, total, converged, panel, dist


def _first_at_least(
    values: NDArray[np.float64],
    start: NDArray[np.intp],
    stop: NDArray[np.intp],
    bound: NDArray[np.float64],
    strict: bool,
) -> NDArray[np.intp]:
    """``index._first_at_least_reference`` slice by slice: in each sorted slice
    ``values[start:stop]``, the position of the first value at least ``bound`` (above
    it, if ``strict``), or ``stop``, by the same halvings."""
    n = start.shape[0]
    out = np.empty(n, dtype=np.intp)
    last = max(values.shape[0] - 1, 0)
    for k in range(n):
        lo, hi = start[k], stop[k]
        b = bound[k]
        while lo < hi:
            mid = (lo + hi) // 2
            v = values[min(mid, last)]
            below = (v <= b) if strict else (v < b)
            if below:
                lo = mid + 1
            else:
                hi = mid
        out[k] = lo
    return out


def _tallies(values: NDArray[np.intp]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The values ``>= 0`` of ``values``, each once in increasing order, and how many
    times each occurs: ``numpy.unique(values[values >= 0], return_counts=True)``."""
    kept = np.sort(values[values >= 0])
    n = kept.shape[0]
    distinct = np.empty(n, dtype=np.intp)
    counts = np.empty(n, dtype=np.intp)
    got = 0
    for i in range(n):
        if got > 0 and kept[i] == distinct[got - 1]:
            counts[got - 1] += 1
        else:
            distinct[got] = kept[i]
            counts[got] = 1
            got += 1
    return distinct[:got], counts[:got]


def _key_pair_walk(
    order: NDArray[np.intp],
    first: NDArray[np.intp],
    low: NDArray[np.int64],
    high: NDArray[np.int64],
    places: NDArray[np.float64],
    slack: NDArray[np.float64],
    span_lo: NDArray[np.float64],
    span_hi: NDArray[np.float64],
    out_a: NDArray[np.intp],
    out_b: NDArray[np.intp],
    store: bool,
) -> int:
    """:func:`_key_pair_nodes`' pairs, counted, and stored in ``out_a``, ``out_b`` when
    ``store``."""
    total = 0
    for q in range(low.shape[0]):
        ka, kb = low[q], high[q]
        for x in range(first[ka], first[ka + 1]):
            a = order[x]
            for y in range(first[kb], first[kb + 1]):
                b = order[y]
                if ka == kb and not a < b:
                    continue
                d = math.hypot(places[b, 0] - places[a, 0], places[b, 1] - places[a, 1])
                tol = (slack[a] + slack[b]) * (1.0 + 1e-9) + 1e-9
                if d + tol >= span_lo[q] and d - tol <= span_hi[q]:
                    if store:
                        out_a[total] = a
                        out_b[total] = b
                    total += 1
    return total


def _key_pair_nodes(
    order: NDArray[np.intp],
    first: NDArray[np.intp],
    low: NDArray[np.int64],
    high: NDArray[np.int64],
    places: NDArray[np.float64],
    slack: NDArray[np.float64],
    span_lo: NDArray[np.float64],
    span_hi: NDArray[np.float64],
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """``index.SurveyIndex._pairs_to_look_up_reference``'s node pairs before their sort:
    for each pair of keys ``(low[q], high[q])``, every node of the low key (``order[
    first[k]:first[k + 1]]`` hold key ``k``) with every node of the high key (each pair
    once where the keys are the same), those ``places`` apart within ``slack[a] +
    slack[b]`` (a hair more) of ``[span_lo[q], span_hi[q]]``; in that order, the low
    key's node first. Counted first, then stored."""
    none = np.zeros(0, dtype=np.intp)
    args = (order, first, low, high, places, slack, span_lo, span_hi)
    total = _key_pair_walk_jit(*args, none, none, False)
    out_a = np.empty(total, dtype=np.intp)
    out_b = np.empty(total, dtype=np.intp)
    _key_pair_walk_jit(*args, out_a, out_b, True)
    return out_a, out_b


def _overrun_counts(
    points: NDArray[np.float64],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    number: NDArray[np.intp],
    mine: NDArray[np.intp],
    gate: float,
    margin: float,
    overrun_reach: float,
    slope_sigmas: float,
    sigma: float,
    to_free_ends: bool,
) -> NDArray[np.int64]:
    """``verification._overrun_reference``'s counts, one per panel of ``mine`` (a
    beacon's panels; ``number`` holds every panel's number on its beacon): the returns
    within ``gate`` of a panel's line past its nodes, on no panel of the beacon, over
    the reach past each end, less an end's returns whose line drifts across the panel's
    (more than ``slope_sigmas`` standard deviations of its slope for noise ``sigma``).
    Returns beyond the reach of every panel, which the reference leaves out first, are
    never in a band past an end, so every return is looked at here."""
    n, m = points.shape[0], mine.shape[0]
    t = np.empty((m, n))
    s = np.empty((m, n))
    near_any = np.zeros(n, dtype=np.bool_)
    first, last = number[mine[0]], number[mine[0]]
    for c in range(m):
        q = mine[c]
        first = min(first, number[q])
        last = max(last, number[q])
        ax, ay = a[q, 0], a[q, 1]
        dx, dy = direction[q, 0], direction[q, 1]
        nx, ny = normal[q, 0], normal[q, 1]
        ln = length[q]
        for i in range(n):
            rx = points[i, 0] - ax
            ry = points[i, 1] - ay
            tc = rx * dx + ry * dy
            sc = rx * nx + ry * ny
            t[c, i] = tc
            s[c, i] = sc
            if abs(sc) <= gate and tc >= -gate and tc <= ln + gate:
                near_any[i] = True
    # The outer panels' lengths (the last of a number, as the reference's dict keeps).
    first_len = last_len = 0.0
    for c in range(m):
        if number[mine[c]] == first:
            first_len = length[mine[c]]
        if number[mine[c]] == last:
            last_len = length[mine[c]]
    counts = np.zeros(m, dtype=np.int64)
    for c in range(m):
        q = mine[c]
        lk = length[q]
        k = number[q]
        count = 0
        for side in range(2):  # past the far end, then before the near one
            if side == 0:
                if k == last:
                    continue
                neighbour = k + 1
            else:
                if k == first:
                    continue
                neighbour = k - 1
            past_by = overrun_reach
            if to_free_ends and neighbour in (first, last):
                past_by = min(overrun_reach, first_len if neighbour == first else last_len)
            # The stretch of the line beyond this end, open at both ends.
            t_lo, t_hi = (lk, lk + past_by) if side == 0 else (-past_by, 0.0)
            ends = 0
            past = 0
            total = 0.0
            for i in range(n):
                tc = t[c, i]
                if t_lo < tc < t_hi and abs(s[c, i]) <= gate and not near_any[i]:
                    ends += 1
                    total += tc
                    if tc > lk + margin or tc < -margin:
                        past += 1
            if past >= 3:
                mean = total / ends
                spread = 0.0
                cross = 0.0
                for i in range(n):
                    tc = t[c, i]
                    if t_lo < tc < t_hi and abs(s[c, i]) <= gate and not near_any[i]:
                        tt = tc - mean
                        spread += tt * tt
                        cross += tt * s[c, i]
                slope = cross / spread if spread > 0 else 0.0
                if abs(slope) > slope_sigmas * sigma / math.sqrt(max(spread, 1e-30)):
                    continue  # another surface crossing the band
            count += past
        counts[c] = count
    return counts


def _straight_and_fitted_chi(
    points: NDArray[np.float64],
    on: NDArray[np.bool_],
    residual: NDArray[np.float64],
    origin: NDArray[np.float64],
    range_sigma: float,
    angle_sigma: float,
    panel_of: NDArray[np.intp],
    survey_var: NDArray[np.float64],
) -> tuple[float, float]:
    """``verification._straight_and_fitted_reference`` on the returns where ``on``: the
    chi-squares of their offsets from their one total-least-squares line and of their
    residuals from their panels (``panel_of``, each panel's surveyed variance in
    ``survey_var``), each weighed by the noise across that line."""
    mx = 0.0
    my = 0.0
    m = 0
    for i in range(points.shape[0]):
        if on[i]:
            mx += points[i, 0]
            my += points[i, 1]
            m += 1
    mx /= m
    my /= m
    vxx = 0.0
    vyy = 0.0
    vxy = 0.0
    for i in range(points.shape[0]):
        if on[i]:
            cx, cy = points[i, 0] - mx, points[i, 1] - my
            vxx += cx * cx
            vyy += cy * cy
            vxy += cx * cy
    _, dx, dy = _major_axis_jit(vxx, vyy, vxy)
    nx, ny = -dy, dx
    floor = (0.1 * range_sigma) ** 2
    chi_line = 0.0
    chi_beacon = 0.0
    for i in range(points.shape[0]):
        if not on[i]:
            continue
        rx, ry = points[i, 0] - origin[0], points[i, 1] - origin[1]
        rho = math.hypot(rx, ry)
        d = rho if rho > 0.0 else 1.0
        cos_n = (rx / d) * nx + (ry / d) * ny
        spread = rho * angle_sigma
        var = (range_sigma * cos_n) ** 2 + spread * spread * (1.0 - cos_n * cos_n)
        var = max(var, floor)
        off = (points[i, 0] - mx) * nx + (points[i, 1] - my) * ny
        chi_line += off * off / var
        chi_beacon += residual[i] * residual[i] / (var + survey_var[panel_of[i]])
    return chi_line, chi_beacon


def _in_place_chi(
    points: NDArray[np.float64],
    origin: NDArray[np.float64],
    panel_of: NDArray[np.intp],
    residual: NDArray[np.float64],
    mine: NDArray[np.intp],
    number: NDArray[np.intp],
    a: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    length: NDArray[np.float64],
    edge_margin: float,
    jump: float,
    min_cos: float,
    range_sigma: float,
    angle_sigma: float,
    floor: float,
    survey_var: NDArray[np.float64],
) -> tuple[float, int]:
    """``verification._in_place_reference``'s chi-square and its count of returns: the
    returns matched (``panel_of``, residuals ``residual``) to a beacon's panels
    (``mine``; ``number`` holds every panel's number on its beacon), less those at its
    silhouette (a neighbouring return, off the beacon, more than ``jump`` farther from
    ``origin``), within ``edge_margin`` of its free ends, or within ``min_cos`` of
    grazing, each residual weighed by the noise across its own panel and its surveyed
    variance (``survey_var``, per panel)."""
    n = points.shape[0]
    ours = np.zeros(n, dtype=np.bool_)
    first, last = number[mine[0]], number[mine[0]]
    for j in range(mine.shape[0]):
        first = min(first, number[mine[j]])
        last = max(last, number[mine[j]])
    for i in range(n):
        q = panel_of[i]
        if q < 0:
            continue
        for j in range(mine.shape[0]):
            if mine[j] == q:
                ours[i] = True
                break
    chi = 0.0
    count = 0
    ox, oy = origin[0], origin[1]
    for i in range(n):
        if not ours[i]:
            continue
        rx, ry = points[i, 0] - ox, points[i, 1] - oy
        rho = math.hypot(rx, ry)
        edge = False
        for j in (i - 1, i + 1):
            if (
                j >= 0
                and j < n
                and not ours[j]
                and math.hypot(points[j, 0] - ox, points[j, 1] - oy) - rho > jump
            ):
                edge = True
        if edge:
            continue
        q = panel_of[i]
        t = (points[i, 0] - a[q, 0]) * direction[q, 0] + (points[i, 1] - a[q, 1]) * direction[q, 1]
        if number[q] == first and t < edge_margin:
            continue
        if number[q] == last and t > length[q] - edge_margin:
            continue
        d = rho if rho > 0.0 else 1.0
        cos_n = abs((rx / d) * normal[q, 0] + (ry / d) * normal[q, 1])
        if not cos_n > min_cos:
            continue
        across = range_sigma * max(cos_n, floor)
        spread = rho * angle_sigma
        var = across * across + spread * spread * (1.0 - cos_n * cos_n)
        den = var + survey_var[q]
        # A noiseless model (numpy's division gives inf or NaN): the test fails.
        chi += residual[i] * residual[i] / den if den > 0.0 else math.inf
        count += 1
    return chi, count


def _window_scores(
    cells: NDArray[np.float64],
    tiles: NDArray[np.intp],
    tile_lo: NDArray[np.float64],
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    values: NDArray[np.float64],
    shifts: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Sum over the points of the tiled likelihood field, for each translation.

    ``tracking._TiledField.lookup`` summed over the points, without its
    (translations x points) arrays: a point moved by ``shifts[m]`` (cells)
    reads, in each tile it can reach (``tiles``, -1 pads), the cell
    ``floor(cells - tile_lo + shift)`` and keeps the largest value.
    """
    n = cells.shape[0]
    slots = tiles.shape[1]
    local = np.empty((n, slots, 2))
    for i in range(n):
        for k in range(slots):
            t = tiles[i, k]
            if t >= 0:
                local[i, k, 0] = cells[i, 0] - tile_lo[t, 0]
                local[i, k, 1] = cells[i, 1] - tile_lo[t, 1]
    out = np.zeros(shifts.shape[0])
    for m in range(shifts.shape[0]):
        out[m] = _pose_score_jit(
            local, tiles, tile_shape, tile_offset, values, shifts[m, 0], shifts[m, 1]
        )
    return out


def _field_pyramid(
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    values: NDArray[np.float64],
    levels: int,
) -> NDArray[np.float64]:
    """Row ``h`` holds, for each cell of each tile, the largest value of the ``2^h x 2^h``
    cells from it (those inside its tile): the bounds of :func:`_window_picks`. Row 0 is
    ``values``, last (outside) cell included."""
    out = np.empty((levels + 1, values.shape[0]))
    out[0, :] = values
    for h in range(1, levels + 1):
        half = 1 << (h - 1)
        out[h, values.shape[0] - 1] = values[values.shape[0] - 1]
        for t in range(tile_shape.shape[0]):
            w, ht, off = tile_shape[t, 0], tile_shape[t, 1], tile_offset[t]
            for i in range(w):
                for j in range(ht):
                    v = out[h - 1, off + i * ht + j]
                    if i + half < w:
                        v = max(v, out[h - 1, off + (i + half) * ht + j])
                        if j + half < ht:
                            v = max(v, out[h - 1, off + (i + half) * ht + j + half])
                    if j + half < ht:
                        v = max(v, out[h - 1, off + i * ht + j + half])
                    out[h, off + i * ht + j] = v
    return out


def _pose_score(
    local: NDArray[np.float64],
    tiles: NDArray[np.intp],
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    values: NDArray[np.float64],
    sx: float,
    sy: float,
) -> float:
    """One translation's score: over the points, the largest value of the cells they
    fall in (over their tiles), summed in the points' order."""
    total = 0.0
    for i in range(local.shape[0]):
        best = 0.0
        for k in range(tiles.shape[1]):
            t = tiles[i, k]
            if t < 0:
                continue
            gi = math.floor(local[i, k, 0] + sx)
            gj = math.floor(local[i, k, 1] + sy)
            w, h = tile_shape[t, 0], tile_shape[t, 1]
            if gi >= 0 and gi < w and gj >= 0 and gj < h:
                v = values[tile_offset[t] + gi * h + gj]
                if v > best:
                    best = v
        total += best
    return total


def _cells_score(
    cells: NDArray[np.int64],
    tiles: NDArray[np.intp],
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    values: NDArray[np.float64],
    sx: int,
    sy: int,
) -> float:
    """:func:`_pose_score` for points already in whole cells of their tiles (``cells``,
    the floors of ``local``) and a translation of whole cells: the same sum, without a
    floor per point and translation."""
    total = 0.0
    for i in range(cells.shape[0]):
        best = 0.0
        for k in range(tiles.shape[1]):
            t = tiles[i, k]
            if t < 0:
                continue
            gi = cells[i, k, 0] + sx
            gj = cells[i, k, 1] + sy
            w, h = tile_shape[t, 0], tile_shape[t, 1]
            if gi >= 0 and gi < w and gj >= 0 and gj < h:
                v = values[tile_offset[t] + gi * h + gj]
                if v > best:
                    best = v
        total += best
    return total


def _rectangle_max(
    pyramid: NDArray[np.float64], off: int, h: int, i0: int, i1: int, j0: int, j1: int
) -> float:
    """At least the largest value of the cells ``[i0, i1] x [j0, j1]`` (inside it) of the
    tile at ``off`` (rows of ``h`` cells), from the pyramid (:func:`_field_pyramid`):
    squares of ``2^lv`` cells, ``2^lv <= width < 2^(lv + 1)``, from the rectangle's two
    ends along each axis, together covering it and no cell beyond its span."""
    levels = pyramid.shape[0] - 1
    width = max(i1 - i0, j1 - j0) + 1
    lv = 0
    while (2 << lv) <= width and lv < levels:
        lv += 1
    side = 1 << lv
    ia = max(i1 - side + 1, i0)
    ja = max(j1 - side + 1, j0)
    row = pyramid[lv]
    return float(
        max(
            max(row[off + i0 * h + j0], row[off + i0 * h + ja]),
            max(row[off + ia * h + j0], row[off + ia * h + ja]),
        )
    )


def _cells_bound(
    cells: NDArray[np.int64],
    tiles: NDArray[np.intp],
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    pyramid: NDArray[np.float64],
    x0: int,
    x1: int,
    y0: int,
    y1: int,
) -> float:
    """At least the score (:func:`_cells_score`) of every translation in ``[x0, x1] x
    [y0, y1]`` (whole cells): each point's largest value over the cells it can fall in,
    from the pyramid. The sum of these bounds in the same order is at least every
    score."""
    total = 0.0
    for i in range(cells.shape[0]):
        best = 0.0
        for k in range(tiles.shape[1]):
            t = tiles[i, k]
            if t < 0:
                continue
            w, h = tile_shape[t, 0], tile_shape[t, 1]
            ci, cj = cells[i, k, 0], cells[i, k, 1]
            i0, i1 = ci + x0, ci + x1
            j0, j1 = cj + y0, cj + y1
            if i1 < 0 or i0 >= w or j1 < 0 or j0 >= h:
                continue
            v = _rectangle_max_jit(
                pyramid,
                tile_offset[t],
                h,
                max(i0, 0),
                min(i1, w - 1),
                max(j0, 0),
                min(j1, h - 1),
            )
            if v > best:
                best = v
        total += best
    return total


def _field_sliding(
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    pyramid: NDArray[np.float64],
    widths: NDArray[np.intp],
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """For each width ``W`` of ``widths`` and each tile, every cell's largest value over
    the ``W x W`` cells from it (those inside its tile), from the pyramid
    (:func:`_field_pyramid`) as :func:`_cells_bound` takes it: a block of the window's
    grid whose translations span ``W`` cells is bounded by one read a point
    (:func:`_sliding_bound`) instead of four and a level.

    Each tile's map is padded by ``W - 1`` cells before it along both axes (a point
    whose square starts up to that far before the tile still reaches into it): map
    ``l`` of tile ``t`` starts at ``starts[l, t]`` in the returned values, rows of
    ``h + W - 1`` cells, ``w + W - 1`` rows."""
    n_tiles = tile_shape.shape[0]
    starts = np.zeros((widths.shape[0], n_tiles), dtype=np.intp)
    total = 0
    for lw in range(widths.shape[0]):
        pad = widths[lw] - 1
        for t in range(n_tiles):
            starts[lw, t] = total
            total += (tile_shape[t, 0] + pad) * (tile_shape[t, 1] + pad)
    out = np.zeros(total)
    for lw in range(widths.shape[0]):
        width = widths[lw]
        pad = width - 1
        for t in range(n_tiles):
            w, h = tile_shape[t, 0], tile_shape[t, 1]
            off = tile_offset[t]
            rows = h + pad
            base = starts[lw, t]
            for u in range(w + pad):
                i0 = max(u - pad, 0)
                i1 = min(u - pad + width - 1, w - 1)
                for v in range(h + pad):
                    j0 = max(v - pad, 0)
                    j1 = min(v - pad + width - 1, h - 1)
                    out[base + u * rows + v] = _rectangle_max_jit(pyramid, off, h, i0, i1, j0, j1)
    return out, starts


def _sliding_bound(
    cells: NDArray[np.int64],
    tiles: NDArray[np.intp],
    tile_shape: NDArray[np.intp],
    sliding: NDArray[np.float64],
    starts: NDArray[np.intp],
    width: int,
    x0: int,
    y0: int,
) -> float:
    """:func:`_cells_bound` of the translations ``[x0, x0 + width) x [y0, y0 + width)``
    (whole cells) from the sliding maxima of that width (``sliding`` and this width's
    row of ``starts``, :func:`_field_sliding`): the same bound, one read a point. A
    block cut short by the grid's edge is bounded over the whole width: a bound still,
    if a looser one."""
    pad = width - 1
    total = 0.0
    for i in range(cells.shape[0]):
        best = 0.0
        for k in range(tiles.shape[1]):
            t = tiles[i, k]
            if t < 0:
                continue
            u = cells[i, k, 0] + x0 + pad
            v = cells[i, k, 1] + y0 + pad
            rows = tile_shape[t, 1] + pad
            if u >= 0 and u < tile_shape[t, 0] + pad and v >= 0 and v < rows:
                val = sliding[starts[t] + u * rows + v]
                if val > best:
                    best = val
        total += best
    return total


def _near_pose(
    rot: float, x: float, y: float, other: NDArray[np.float64], apart: float, reach: float
) -> bool:
    """Whether pose (rotation ``rot``, translation ``x, y``) moves the returns less than
    ``apart`` from pose ``other`` (rotation, x, y): its translation within ``apart`` and
    its rotation within ``apart / reach``."""
    return abs(rot - other[0]) * reach < apart and math.hypot(x - other[1], y - other[2]) < apart


def _recount(places: NDArray[np.int64], free: NDArray[np.bool_], start: int = 0) -> None:
    """``places[a, b]``: how many of ``free[:a, :b]`` are set (a summed-area table), its
    rows recounted from ``start`` on (those before it count ``free`` as it is)."""
    for a in range(start, free.shape[0]):
        for b in range(free.shape[1]):
            places[a + 1, b + 1] = places[a, b + 1] + places[a + 1, b] - places[a, b] + free[a, b]


def _within_span(offs: NDArray[np.float64], centre: float, apart: float) -> tuple[int, int]:
    """The places ``[lo, hi)`` of the increasing ``offs`` within ``apart`` of ``centre``,
    and one more each way against rounding."""
    side = offs.shape[0]
    lo = 0
    while lo < side and offs[lo] <= centre - apart:
        lo += 1
    hi = side
    while hi > lo and offs[hi - 1] >= centre + apart:
        hi -= 1
    return max(lo - 1, 0), min(hi + 1, side)


def _suppress(
    free: NDArray[np.bool_],
    places: NDArray[np.int64],
    rots: NDArray[np.float64],
    offs_m: NDArray[np.float64],
    pose: NDArray[np.float64],
    apart: float,
    reach: float,
) -> None:
    """Mark the grid poses near ``pose`` as no longer free, and recount the free places
    of every rotation that changed (``places[r, a, b]``: free ones in ``[0, a) x [0, b)``).

    Only places within ``apart`` of the pose along each axis can be near it (``offs_m``
    increasing), one more each way against rounding: the others are not visited, and a
    rotation's table is recounted from the first row that changed."""
    side = offs_m.shape[0]
    a0, a1 = _within_span_jit(offs_m, pose[1], apart)
    b0, b1 = _within_span_jit(offs_m, pose[2], apart)
    for r in range(rots.shape[0]):
        if abs(rots[r] - pose[0]) * reach >= apart:
            continue
        changed = side
        for a in range(a0, a1):
            for b in range(b0, b1):
                if free[r, a, b] and _near_pose_jit(
                    rots[r], offs_m[a], offs_m[b], pose, apart, reach
                ):
                    free[r, a, b] = False
                    changed = min(changed, a)
        if changed < side:
            _recount_jit(places[r], free[r], changed)


def _window_picks(
    points: NDArray[np.float64],
    rots: NDArray[np.float64],
    origin: NDArray[np.float64],
    res: float,
    tiles: NDArray[np.intp],
    tile_lo: NDArray[np.float64],
    tile_shape: NDArray[np.intp],
    tile_offset: NDArray[np.intp],
    pyramid: NDArray[np.float64],
    offs_cells: NDArray[np.int64],
    offs_m: NDArray[np.float64],
    inside: NDArray[np.bool_],
    reach: float,
    candidates: int,
    distinct_m: float,
    other_m: float,
    sliding: NDArray[np.float64],
    sliding_starts: NDArray[np.intp],
    sliding_widths: NDArray[np.intp],
) -> tuple[NDArray[np.float64], int, int]:
    """The window's hypotheses by branch and bound (Olson 2009; Hess et al. 2016): the
    poses of the grid in order of score (then rotation, then translation, each from the
    largest), taking each that moves the returns at least ``distinct_m`` from every pose
    taken before (:func:`_near_pose`), up to ``candidates``; then, going on down the
    same order, up to ``candidates`` more at least ``other_m`` from every pose taken.
    Poses scoring zero (no return near a panel) are never taken.

    ``points`` are the returns in the scanner frame, shape (n, 2); at rotation
    ``rots[r]`` (increasing, radians counter-clockwise from east) and translation ``t``
    a return ``(x, y)`` lies at ``((x cos - y sin + origin[0] + t[0]) / res, (x sin + y cos
    + origin[1] + t[1]) / res)`` cells; ``tiles`` the tiles each point reaches (-1 pads);
    ``pyramid`` the field's :func:`_field_pyramid`. The translation at grid place (a, b)
    is ``(offs_cells[a], offs_cells[b])`` whole cells, ``(offs_m[a], offs_m[b])`` metres,
    in the window where ``inside[a, b]``: each return is put in its cell once per
    rotation, and a translation adds whole cells to it (:func:`_cells_score`,
    :func:`_cells_bound`). Each rotation's grid is a quadtree of blocks,
    opened best bound first (blocks before poses of an equal value), so poses come out
    in exactly the order of scoring them all; the places still free (not near a pose
    taken) are counted per rotation, and a block with none is never opened. The second
    pass needs no pose the first passed over: every pose within ``distinct_m`` of one
    taken is within ``other_m`` of it.

    ``sliding`` and ``sliding_starts`` (:func:`_field_sliding`), the field's sliding
    maxima over ``sliding_widths[l]`` cells, for blocks of ``2^(l + 1)`` translations a
    side (as many sizes as there are widths, none when there are none): such a block is
    bounded by :func:`_sliding_bound` when the width covers what its translations span
    (``(2^(l + 1) - 1)`` grid steps and a cell), by :func:`_cells_bound` otherwise, and
    every block too wide for them likewise. Either is at least every score in the
    block, so the poses come out in the same order.

    Returns the poses taken as rows (rotation index, a, b, score), and how many of them
    the first pass took and the second.
    """
    rotations, n = rots.shape[0], points.shape[0]
    step_cells = offs_cells[1] - offs_cells[0] if offs_cells.shape[0] > 1 else 1
    slots = tiles.shape[1]
    side = offs_cells.shape[0]
    size = 1
    while size < side:
        size *= 2
    free = np.empty((rotations, side, side), dtype=np.bool_)
    places = np.zeros((rotations, side + 1, side + 1), dtype=np.int64)
    for r in range(rotations):
        free[r] = inside
        _recount_jit(places[r], free[r])
    values = pyramid[0]
    cells = np.zeros((rotations, n, slots, 2), dtype=np.int64)
    for r in range(rotations):
        c, s = math.cos(rots[r]), math.sin(rots[r])
        for i in range(n):
            x, y = points[i, 0], points[i, 1]
            cx = (x * c - y * s + origin[0]) / res
            cy = (x * s + y * c + origin[1]) / res
            for k in range(slots):
                t = tiles[i, k]
                if t >= 0:
                    cells[r, i, k, 0] = math.floor(cx - tile_lo[t, 0])
                    cells[r, i, k, 1] = math.floor(cy - tile_lo[t, 1])
    taken = np.zeros((2 * candidates, 4))
    chosen = np.zeros((2 * candidates, 3))  # rotation, x, y (metres)
    got = 0
    first = -1
    apart = distinct_m
    last = side - 1
    # (minus the value, 0 for a block and 1 for a pose, minus the rotation index, minus
    # a, minus b, block size): the heap gives the largest value, then blocks, then the
    # largest rotation, a and b.
    heap = [(0.0, 0, 0, 0, 0, 0) for _ in range(0)]
    for r in range(rotations):
        if size == 1:
            if inside[0, 0]:
                v = _cells_score_jit(
                    cells[r], tiles, tile_shape, tile_offset, values, offs_cells[0], offs_cells[0]
                )
                heap.append((-v, 1, -r, 0, 0, 1))
            continue
        v = _cells_bound_jit(
            cells[r],
            tiles,
            tile_shape,
            tile_offset,
            pyramid,
            offs_cells[0],
            offs_cells[last],
            offs_cells[0],
            offs_cells[last],
        )
        heap.append((-v, 0, -r, 0, 0, size))
    heapq.heapify(heap)
    while len(heap) > 0 and got < 2 * candidates:
        value, kind, neg_r, neg_a, neg_b, s = heapq.heappop(heap)
        if -value <= 0.0:
            break  # every pose left scores zero
        r, a0, b0 = -neg_r, -neg_a, -neg_b
        if kind == 1:
            if not free[r, a0, b0]:
                continue
            taken[got, 0] = r
            taken[got, 1] = a0
            taken[got, 2] = b0
            taken[got, 3] = -value
            chosen[got, 0] = rots[r]
            chosen[got, 1] = offs_m[a0]
            chosen[got, 2] = offs_m[b0]
            _suppress_jit(free, places, rots, offs_m, chosen[got], apart, reach)
            got += 1
            if got == candidates and first < 0:
                first = got
                apart = other_m
                for c in range(got):
                    _suppress_jit(free, places, rots, offs_m, chosen[c], apart, reach)
            continue
        half = s // 2
        for da in (0, half):
            for db in (0, half):
                a, b = a0 + da, b0 + db
                if a >= side or b >= side:
                    continue
                a1, b1 = min(a + half, side), min(b + half, side)
                pr = places[r]
                if pr[a1, b1] - pr[a, b1] - pr[a1, b] + pr[a, b] == 0:
                    continue  # no place in it, or every one near a pose taken
                if half == 1:
                    sx, sy = offs_cells[a], offs_cells[b]
                    v = _cells_score_jit(cells[r], tiles, tile_shape, tile_offset, values, sx, sy)
                    heapq.heappush(heap, (-v, 1, neg_r, -a, -b, 1))
                else:
                    # the sliding maxima of the cells 2^lw translations span (half = 2^lw)
                    lw = 0
                    while (2 << lw) <= half:
                        lw += 1
                    if (
                        lw <= sliding_widths.shape[0]
                        and sliding_widths[lw - 1] >= (half - 1) * step_cells + 1
                    ):
                        v = _sliding_bound_jit(
                            cells[r],
                            tiles,
                            tile_shape,
                            sliding,
                            sliding_starts[lw - 1],
                            sliding_widths[lw - 1],
                            offs_cells[a],
                            offs_cells[b],
                        )
                    else:
                        v = _cells_bound_jit(
                            cells[r],
                            tiles,
                            tile_shape,
                            tile_offset,
                            pyramid,
                            offs_cells[a],
                            offs_cells[a1 - 1],
                            offs_cells[b],
                            offs_cells[b1 - 1],
                        )
                    heapq.heappush(heap, (-v, 0, neg_r, -a, -b, half))
    if first < 0:
        first = got
    return taken[:got], first, got - first


def _run_breaks(
    beams: NDArray[np.intp],
    ranges: NDArray[np.float64],
    angles: NDArray[np.float64],
    points: NDArray[np.float64],
    max_gap_beams: int,
    incidence_limit: float,
    slack: float,
) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """``segmentation._runs_reference``'s first pass: each return's run (the count of
    breakpoints before it), and between consecutive returns the largest step a surface
    at the limiting incidence explains plus ``slack`` and the step itself. A break is a
    gap of more than ``max_gap_beams`` beams, a step beyond the largest explained, or
    beams ``incidence_limit`` or more apart."""
    n = beams.shape[0]
    explained = np.empty(max(n - 1, 0))
    step = np.empty(max(n - 1, 0))
    for i in range(n - 1):
        dphi = angles[i + 1] - angles[i]
        reach = ranges[i] * math.sin(dphi) / math.sin(max(incidence_limit - dphi, 1e-6))
        explained[i] = reach + slack
        step[i] = math.hypot(points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1])
    # (a step beyond explained + 0.0 is one beyond explained)
    ids = _rebreak_jit(beams, angles, explained, step, max_gap_beams, incidence_limit, 0.0)
    return ids, explained, step


def _rebreak(
    beams: NDArray[np.intp],
    angles: NDArray[np.float64],
    explained: NDArray[np.float64],
    step: NDArray[np.float64],
    max_gap_beams: int,
    incidence_limit: float,
    slack: float,
) -> NDArray[np.intp]:
    """Each return's run from the steps between consecutive returns and the largest
    each explains (:func:`_run_breaks`), ``slack`` more explained at every gap (the
    estimated noise's, in the second pass)."""
    n = beams.shape[0]
    ids = np.zeros(n, dtype=np.intp)
    run = 0
    for i in range(n - 1):
        if (
            beams[i + 1] - beams[i] > max_gap_beams + 1
            or step[i] > explained[i] + slack
            or angles[i + 1] - angles[i] >= incidence_limit
        ):
            run += 1
        ids[i + 1] = run
    return ids


def _triple_deviations(points: NDArray[np.float64], ids: NDArray[np.intp]) -> NDArray[np.float64]:
    """``lines.range_noise_from_triples_reference``'s deviations: for each three consecutive
    returns of one run seen more than about 17 degrees from grazing, the middle one's
    distance from the line through the outer two over ``|n . u|``, in order."""
    n = points.shape[0]
    out = np.empty(max(n - 2, 0))
    m = 0
    for i in range(n - 2):
        if ids[i] != ids[i + 1] or ids[i + 1] != ids[i + 2]:
            continue
        acx = points[i + 2, 0] - points[i, 0]
        acy = points[i + 2, 1] - points[i, 1]
        bx, by = points[i + 1, 0], points[i + 1, 1]
        length = math.hypot(acx, acy)
        rb = math.hypot(bx, by)
        if not (length > 0 and rb > 0):
            continue
        nu = abs(acx * by - acy * bx) / (length * rb)
        if not nu > 0.3:
            continue
        dist = abs(acx * (by - points[i, 1]) - acy * (bx - points[i, 0])) / length
        out[m] = dist / nu
        m += 1
    return out[:m]


def _linear_median(values: NDArray[np.float64]) -> float:
    """``np.quantile(values, 0.5)`` (its default, linear method) of finite ``values``, to
    the bit: the middle value, or between the two middle ones ``b - (b - a) * 0.5`` as
    numpy's interpolation takes it."""
    n = values.shape[0]
    lo = (n - 1) // 2
    part = np.partition(values, lo)
    a = float(part[lo])
    if n % 2 == 1:
        return a + 0.0  # numpy adds (b - a) * 0 to it: -0.0 comes out as 0.0
    b = float(part[lo + 1])
    for i in range(lo + 2, n):
        if part[i] < b:
            b = float(part[i])
    return b - (b - a) * 0.5


def _run_moments(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cumulative sums (from 0) of the centred points' first and second moments and
    of the unit beam vectors' second moments, rows in ``partition_dp``'s order
    (``segmentation._cumulative_moments`` in numpy)."""
    n = points.shape[0]
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += points[i, 0]
        my += points[i, 1]
    mx /= n
    my /= n
    out = np.zeros((8, n + 1))
    for i in range(n):
        x, y = points[i, 0], points[i, 1]
        cx, cy = x - mx, y - my
        r = math.hypot(x, y)
        ux, uy = (x / r, y / r) if r > 0.0 else (x, y)
        out[0, i + 1] = out[0, i] + cx
        out[1, i + 1] = out[1, i] + cy
        out[2, i + 1] = out[2, i] + cx * cx
        out[3, i + 1] = out[3, i] + cy * cy
        out[4, i + 1] = out[4, i] + cx * cy
        out[5, i + 1] = out[5, i] + ux * ux
        out[6, i + 1] = out[6, i] + uy * uy
        out[7, i + 1] = out[7, i] + ux * uy
    return out


def _scatter(points: NDArray[np.float64], lo: int, hi: int) -> tuple[float, ...]:
    """Centroid and centred scatter (two passes) of ``points[lo:hi]``."""
    m = hi - lo
    mx = 0.0
    my = 0.0
    for i in range(lo, hi):
        mx += points[i, 0]
        my += points[i, 1]
    mx /= m
    my /= m
    vxx = 0.0
    vyy = 0.0
    vxy = 0.0
    for i in range(lo, hi):
        cx, cy = points[i, 0] - mx, points[i, 1] - my
        vxx += cx * cx
        vyy += cy * cy
        vxy += cx * cy
    return mx, my, vxx, vyy, vxy


def _major_axis(vxx: float, vyy: float, vxy: float) -> tuple[float, float, float]:
    """Smallest eigenvalue of the scatter (the TLS SSE, >= 0) and the unit major axis."""
    dv = vxx - vyy
    q = 0.25 * dv * dv + vxy * vxy
    half_r = math.sqrt(q) if q > 0.0 else 0.0
    sse = max(0.5 * (vxx + vyy) - half_r, 0.0)
    theta = 0.5 * math.atan2(2.0 * vxy, dv)
    return sse, math.cos(theta), math.sin(theta)


def _piece_sse_nu2(points: NDArray[np.float64], lo: int, hi: int) -> tuple[float, float]:
    """TLS SSE of ``points[lo:hi]`` (0 below three points) and mean (normal . u)^2."""
    _, _, vxx, vyy, vxy = _scatter_jit(points, lo, hi)
    sse, dx, dy = _major_axis_jit(vxx, vyy, vxy)
    nx, ny = -dy, dx
    acc = 0.0
    for i in range(lo, hi):
        x, y = points[i, 0], points[i, 1]
        r = math.hypot(x, y)
        if r > 0.0:
            x, y = x / r, y / r
        c = nx * x + ny * y
        acc += c * c
    return (sse if hi - lo >= 3 else 0.0), acc / (hi - lo)


def _partition_run(
    points: NDArray[np.float64],
    costs: NDArray[np.float64],
    w_costs: int,
    lo: int,
    hi: int,
    var: float,
    max_piece: int,
) -> NDArray[np.intp]:
    """``segmentation._partition_impl`` compiled, for the returns ``lo:hi`` of a run
    whose piece costs are ``costs`` (:func:`_piece_costs`): their optimal partition,
    cuts that only the cap on piece length made undone; pieces as (start, end) rows,
    from ``lo``."""
    n = hi - lo
    w = min(n, max_piece)
    pen = _penalty_jit(n)
    last = _best_pointers_jit(costs, lo, hi, pen, w, w_costs)
    k = 0
    e = n
    while e > 0:
        k += 1
        e = last[e]
    pieces = np.empty((k, 2), dtype=np.intp)
    e = n
    for q in range(k - 1, -1, -1):
        pieces[q, 0] = last[e]
        pieces[q, 1] = e
        e = last[e]
    out = np.empty((k, 2), dtype=np.intp)
    m = 0
    for q in range(k):
        a0, b0 = pieces[q, 0], pieces[q, 1]
        if m > 0 and b0 - out[m - 1, 0] > w:
            s0 = out[m - 1, 0]
            sse_j, _ = _piece_sse_nu2_jit(points, lo + s0, lo + a0)
            sse_p, _ = _piece_sse_nu2_jit(points, lo + a0, lo + b0)
            sse_b, nu2_b = _piece_sse_nu2_jit(points, lo + s0, lo + b0)
            if (sse_b - sse_j - sse_p) / (var * max(nu2_b, 0.05)) <= pen:
                out[m - 1, 1] = b0
                continue
        out[m, 0] = a0
        out[m, 1] = b0
        m += 1
    return out[:m]


def _segment_run(
    points: NDArray[np.float64], var: float, min_points: int, max_piece: int
) -> NDArray[np.intp]:
    """One run's pieces: partitioned, then each piece partitioned again with the
    penalty of its own length (``segmentation._partition`` then ``_refine``), every
    piece's cost from one table of the run's (:func:`_piece_costs`)."""
    n = points.shape[0]
    mom = _run_moments_jit(points)
    w = min(n, max_piece)
    costs = _piece_costs_jit(mom[0], mom[1], mom[2], mom[3], mom[4], mom[5], mom[6], mom[7], var, w)
    first = _partition_run_jit(points, costs, w, 0, n, var, max_piece)
    parts = []
    for q in range(first.shape[0]):
        i, j = first[q, 0], first[q, 1]
        if j - i >= 2 * min_points and j - i < n:
            sub = _partition_run_jit(points, costs, w, i, j, var, max_piece)
            for s in range(sub.shape[0]):
                parts.append((i + sub[s, 0], i + sub[s, 1]))
        else:
            parts.append((i, j))
    out = np.empty((len(parts), 2), dtype=np.intp)
    for q in range(len(parts)):
        out[q, 0] = parts[q][0]
        out[q, 1] = parts[q][1]
    return out


def _line_fits(
    points: NDArray[np.float64], pieces: NDArray[np.intp], noise: float
) -> NDArray[np.float64]:
    """Every piece's total-least-squares line (``segmentation.fit_line`` and
    ``_make_segment``): rows of centroid (2), direction (2), rms, length, start
    and end along the line from the centroid, the spacings at both ends, the
    direction's standard deviation for range noise ``noise``, then the normal (the
    direction turned +90 degrees) and the first and last return projected on the line
    (the centroid plus start or end times the direction), 16 columns."""
    out = np.empty((pieces.shape[0], 16))
    for q in range(pieces.shape[0]):
        lo, hi = pieces[q, 0], pieces[q, 1]
        m = hi - lo
        mx, my, vxx, vyy, vxy = _scatter_jit(points, lo, hi)
        _, dx, dy = _major_axis_jit(vxx, vyy, vxy)
        if (points[hi - 1, 0] - points[lo, 0]) * dx + (points[hi - 1, 1] - points[lo, 1]) * dy < 0:
            dx, dy = -dx, -dy
        nx, ny = -dy, dx
        res2 = 0.0
        t_spread = 0.0
        nu2 = 0.0
        for i in range(lo, hi):
            x, y = points[i, 0], points[i, 1]
            cx, cy = x - mx, y - my
            res = cx * nx + cy * ny
            tt = cx * dx + cy * dy
            res2 += res * res
            t_spread += tt * tt
            r = math.hypot(x, y)
            c = (x * nx + y * ny) / r
            nu2 += c * c
        t0 = (points[lo, 0] - mx) * dx + (points[lo, 1] - my) * dy
        t1 = (points[hi - 1, 0] - mx) * dx + (points[hi - 1, 1] - my) * dy
        s0 = s1 = 0.0
        if m > 1:
            s0 = abs(
                (points[lo + 1, 0] - points[lo, 0]) * dx + (points[lo + 1, 1] - points[lo, 1]) * dy
            )
            s1 = abs(
                (points[hi - 1, 0] - points[hi - 2, 0]) * dx
                + (points[hi - 1, 1] - points[hi - 2, 1]) * dy
            )
        perp = noise * math.sqrt(max(nu2 / m, 1e-6))
        out[q, 0] = mx
        out[q, 1] = my
        out[q, 2] = dx
        out[q, 3] = dy
        out[q, 4] = math.sqrt(res2 / m)
        out[q, 5] = t0
        out[q, 6] = t1
        out[q, 7] = s0
        out[q, 8] = s1
        out[q, 9] = perp / math.sqrt(t_spread) if t_spread > 0.0 else math.inf
        out[q, 10] = -dy
        out[q, 11] = dx
        out[q, 12] = mx + t0 * dx
        out[q, 13] = my + t0 * dy
        out[q, 14] = mx + t1 * dx
        out[q, 15] = my + t1 * dy
    return out


def _nearest_within(
    query: NDArray[np.float64],
    points: NDArray[np.float64],
    origin: NDArray[np.float64],
    cell: float,
    nx: int,
    ny: int,
    start: NDArray[np.intp],
    order: NDArray[np.intp],
    gate: float,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Nearest of ``points`` to each query point closer than ``gate``, through a grid.

    ``points`` are binned in cells of side ``cell`` from ``origin`` (``nx`` by
    ``ny``; cell ``ix * ny + iy`` holds ``order[start[c]:start[c + 1]]``). As
    ``scipy.spatial.cKDTree.query(query, distance_upper_bound=gate)`` (the tests
    compare the two): the distance, or ``inf`` and ``len(points)`` when none is
    nearer than the gate; equal distances go to the lower index.
    """
    m = query.shape[0]
    n = points.shape[0]
    dist = np.full(m, np.inf)
    idx = np.full(m, n, dtype=np.intp)
    reach = int(math.ceil(gate / cell))  # noqa: RUF046 (an int under numba too)
    g2 = gate * gate
    for i in range(m):
        qx, qy = query[i, 0], query[i, 1]
        fx = (qx - origin[0]) / cell
        fy = (qy - origin[1]) / cell
        if not (math.isfinite(fx) and math.isfinite(fy)):
            continue
        # clamped before the conversion: far points meet no cell, and no overflow
        cx = int(math.floor(min(max(fx, -reach - 1.0), nx + reach + 1.0)))  # noqa: RUF046
        cy = int(math.floor(min(max(fy, -reach - 1.0), ny + reach + 1.0)))  # noqa: RUF046
        best = g2
        bj = -1
        for ix in range(max(cx - reach, 0), min(cx + reach, nx - 1) + 1):
            for iy in range(max(cy - reach, 0), min(cy + reach, ny - 1) + 1):
                c = ix * ny + iy
                for s in range(start[c], start[c + 1]):
                    k = order[s]
                    dx = points[k, 0] - qx
                    dy = points[k, 1] - qy
                    d2 = dx * dx + dy * dy
                    if d2 < best or (d2 == best and bj >= 0 and k < bj):
                        best = d2
                        bj = k
        if bj >= 0:
            dist[i] = math.sqrt(best)
            idx[i] = bj
    return dist, idx


def _beam_checks(
    origin: NDArray[np.float64],
    azimuth: float,
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    valid: NDArray[np.bool_],
    range_min: float,
    range_max: float,
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
    normals: NDArray[np.float64],
    owner: NDArray[np.intp],
    owners: int,
    min_sin: float,
    gate: float,
    sigma: float,
    hit_ll0: float,
    through_ll: float,
    near: float,
    near_ll: float,
    chord_a: NDArray[np.float64],
    chord_b: NDArray[np.float64],
    wall: float,
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """``verification._check_beams_reference`` beam by beam: for every beam that
    meets a segment (panels shrunk at their ends) within the range limits, not
    near grazing, its verdict (hit, occluded, through, missing) counted per owner
    (beacon), the occluded ones no more than ``near`` short counted again, and the
    log-likelihood of the hits plus ``through_ll`` per through and ``near_ll`` per
    near-short return. Where ``wall`` is positive, a return beyond a segment that lands
    within ``wall`` of the line from its ``chord_a`` to its ``chord_b`` (and no farther
    past its ends) is missing, not through.

    Returns counts, shape (owners, 5), and log-likelihoods, shape (owners,).
    The ray-segment test is :func:`_first_hits`'s, to the bit.
    """
    n = angles.shape[0]
    counts = np.zeros((owners, 5), dtype=np.intp)
    ll = np.zeros(owners)
    ex, ey, wx, wy, w_x_e = _crossing_terms_jit(origin, seg_a, seg_b)
    # Each beam's first crossing, segment by segment over the beams within the angle the
    # segment spans from the origin (a hair wider): a beam outside it cannot cross it.
    # Segments in order and a strictly nearer crossing only, so a tie goes to the first
    # segment, as in :func:`_first_crossing`.
    first_t = np.full(n, np.inf)
    first_j = np.full(n, -1, dtype=np.intp)
    lo_hi = np.empty((3, 2), dtype=np.intp)
    for k in range(ex.shape[0]):
        ax, ay = wx[k], wy[k]  # the segment's ends seen from the origin
        bx, by = ax + ex[k], ay + ey[k]
        span = math.atan2(ax * by - ay * bx, ax * bx + ay * by)  # from end a to end b
        windows = 0
        if abs(span) >= math.pi - 1e-6 or (ax == 0.0 and ay == 0.0) or (bx == 0.0 and by == 0.0):
            lo_hi[0, 0], lo_hi[0, 1] = 0, n
            windows = 1
        else:
            # A beam's mine-frame direction is (sin(azimuth - angle), cos(azimuth - angle)):
            # its angle is azimuth - (the direction's bearing from north, clockwise).
            at_a = azimuth - math.atan2(ax, ay)
            lo_angle = at_a + min(span, 0.0) - 1e-9
            windows = _beam_windows_jit(angles, lo_angle, abs(span) + 2e-9, lo_hi)
        for w in range(windows):
            for i in range(lo_hi[w, 0], lo_hi[w, 1]):
                bearing = azimuth - angles[i]
                tt = _crossing_jit(math.sin(bearing), math.cos(bearing), k, ex, ey, wx, wy, w_x_e)
                if tt < first_t[i]:
                    first_t[i] = tt
                    first_j[i] = k
    for i in range(n):
        bt, bj = first_t[i], first_j[i]
        bearing = azimuth - angles[i]
        dx, dy = math.sin(bearing), math.cos(bearing)
        if bj < 0 or bt > range_max or bt < range_min:
            continue
        if abs(normals[bj, 0] * dx + normals[bj, 1] * dy) <= min_sin:
            continue
        b = owner[bj]
        if not valid[i]:
            counts[b, 3] += 1
            continue
        res = ranges[i] - bt
        if abs(res) <= gate:
            counts[b, 0] += 1
            z = res / sigma
            ll[b] += hit_ll0 - 0.5 * z * z
        elif res < -gate:
            counts[b, 1] += 1
            if res >= -near:
                counts[b, 4] += 1
        elif res > gate:
            px, py = origin[0] + ranges[i] * dx, origin[1] + ranges[i] * dy
            if wall > 0.0 and _lands_on_jit(px, py, chord_a[bj], chord_b[bj], wall):
                counts[b, 3] += 1
            else:
                counts[b, 2] += 1
        else:  # a NaN range marked valid: no verdict but missing
            counts[b, 3] += 1
    for b in range(owners):
        ll[b] += counts[b, 2] * through_ll + counts[b, 4] * near_ll
    return counts, ll


def _lands_on(
    px: float, py: float, a: NDArray[np.float64], b: NDArray[np.float64], reach: float
) -> bool:
    """Whether (``px``, ``py``) lies within ``reach`` of the line from ``a`` to ``b``, no
    farther than ``reach`` past either end (``verification._on_wall``, one point)."""
    cx, cy = float(b[0] - a[0]), float(b[1] - a[1])
    length = max(math.hypot(cx, cy), 1e-12)  # np.hypot's, as the reference has it
    dx, dy = px - float(a[0]), py - float(a[1])
    along = (dx * cx + dy * cy) / length
    off = abs(dx * cy - dy * cx) / length
    return off <= reach and -reach <= along <= length + reach


def _beam_checks_of(
    origin: NDArray[np.float64],
    azimuth: float,
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    valid: NDArray[np.bool_],
    range_min: float,
    range_max: float,
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    direction: NDArray[np.float64],
    normal: NDArray[np.float64],
    beacon: NDArray[np.intp],
    subset: NDArray[np.intp],
    margin: float,
    min_sin: float,
    gate: float,
    sigma: float,
    hit_ll0: float,
    through_ll: float,
    near: float,
    near_ll: float,
    chord_a: NDArray[np.float64],
    chord_b: NDArray[np.float64],
    wall: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """:func:`_beam_checks` of the panels ``subset`` (of a panel set's ends ``a``, ``b``,
    ``direction``, ``normal`` and ``beacon``), each shrunk by ``margin`` at both ends, the
    verdicts counted per beacon of the subset: ``(beacons, counts, ll)``, the beacons in
    increasing order (``numpy.unique``'s), a row of counts and a log-likelihood each.
    ``chord_a``, ``chord_b`` and ``wall``: as :func:`_beam_checks` takes them, one row a
    panel of the whole set (its beacon's e1 and e4)."""
    m = subset.shape[0]
    seg_a = np.empty((m, 2))
    seg_b = np.empty((m, 2))
    wall_a = np.empty((m, 2))
    wall_b = np.empty((m, 2))
    normals = np.empty((m, 2))
    mine = np.empty(m, dtype=np.intp)
    for k in range(m):
        q = subset[k]
        seg_a[k, 0] = a[q, 0] + margin * direction[q, 0]
        seg_a[k, 1] = a[q, 1] + margin * direction[q, 1]
        seg_b[k, 0] = b[q, 0] - margin * direction[q, 0]
        seg_b[k, 1] = b[q, 1] - margin * direction[q, 1]
        normals[k, 0] = normal[q, 0]
        normals[k, 1] = normal[q, 1]
        wall_a[k, 0], wall_a[k, 1] = chord_a[q, 0], chord_a[q, 1]
        wall_b[k, 0], wall_b[k, 1] = chord_b[q, 0], chord_b[q, 1]
        mine[k] = beacon[q]
    beacons = np.unique(mine)
    owner = np.searchsorted(beacons, mine).astype(np.intp)
    counts, ll = _beam_checks_jit(
        origin,
        azimuth,
        angles,
        ranges,
        valid,
        range_min,
        range_max,
        seg_a,
        seg_b,
        normals,
        owner,
        beacons.shape[0],
        min_sin,
        gate,
        sigma,
        hit_ll0,
        through_ll,
        near,
        near_ll,
        wall_a,
        wall_b,
        wall,
    )
    return beacons, counts, ll


def _range_rows(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    rho: NDArray[np.float64],
    jac: NDArray[np.float64],
) -> None:
    """``adjustment.range_model`` in place: the predicted range of each beam to its
    line ``n . x = c`` (``rho``) and its Jacobian d rho / d (E, N, A) (``jac``; d rho /
    d phi is minus its azimuth column)."""
    for i in range(angles.shape[0]):
        bearing = azimuth - angles[i]
        ux, uy = math.sin(bearing), math.cos(bearing)
        nx, ny = normals[i, 0], normals[i, 1]
        nu = nx * ux + ny * uy
        r = (offsets[i] - (nx * easting + ny * northing)) / nu
        rho[i] = r
        jac[i, 0] = -nx / nu
        jac[i, 1] = -ny / nu
        jac[i, 2] = -r * (nx * uy - ny * ux) / nu


def _lu_solve(m: NDArray[np.float64], rhs: NDArray[np.float64]) -> bool:
    """Solve ``m x = rhs`` (a small square ``m``, any number of right-hand columns) in
    place in ``rhs`` by LU with partial pivoting (LAPACK's ``dgesv``); False, and
    ``rhs`` left undefined, when a pivot is exactly zero (where ``numpy.linalg.solve``
    raises ``LinAlgError``)."""
    a = m.copy()
    k = a.shape[0]
    k_rhs = rhs.shape[1]
    for c in range(k):
        p = c
        for r in range(c + 1, k):
            if abs(a[r, c]) > abs(a[p, c]):
                p = r
        if a[p, c] == 0.0:
            return False
        if p != c:
            for q in range(k):
                a[c, q], a[p, q] = a[p, q], a[c, q]
            for q in range(k_rhs):
                rhs[c, q], rhs[p, q] = rhs[p, q], rhs[c, q]
        for r in range(c + 1, k):
            f = a[r, c] / a[c, c]
            for q in range(c + 1, k):
                a[r, q] -= f * a[c, q]
            for q in range(k_rhs):
                rhs[r, q] -= f * rhs[c, q]
    for q in range(k_rhs):
        for r in range(k - 1, -1, -1):
            acc = rhs[r, q]
            for s in range(r + 1, k):
                acc -= a[r, s] * rhs[s, q]
            rhs[r, q] = acc / a[r, r]
    return True


def _normal_equations(
    jac: NDArray[np.float64],
    residual: NDArray[np.float64],
    weight: NDArray[np.float64],
    normal: NDArray[np.float64],
    rhs: NDArray[np.float64],
) -> None:
    """``G^T W G`` into ``normal`` (3 x 3) and ``G^T W v`` into ``rhs`` (3 x 1)."""
    normal[:, :] = 0.0
    rhs[:, :] = 0.0
    for i in range(jac.shape[0]):
        g0, g1, g2 = jac[i, 0], jac[i, 1], jac[i, 2]
        w = weight[i]
        wv = w * residual[i]
        rhs[0, 0] += g0 * wv
        rhs[1, 0] += g1 * wv
        rhs[2, 0] += g2 * wv
        w0, w1, w2 = w * g0, w * g1, w * g2
        normal[0, 0] += g0 * w0
        normal[0, 1] += g0 * w1
        normal[0, 2] += g0 * w2
        normal[1, 1] += g1 * w1
        normal[1, 2] += g1 * w2
        normal[2, 2] += g2 * w2
    normal[1, 0] = normal[0, 1]
    normal[2, 0] = normal[0, 2]
    normal[2, 1] = normal[1, 2]


def _gauss_newton(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    variance_scale: NDArray[np.float64],
    range_sigma: float,
    angle_sigma: float,
    max_iterations: int,
) -> tuple[
    float,
    float,
    float,
    int,
    bool,
    float,
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]:
    """The iterations and statistics of ``adjustment._adjust_pose_reference``:
    ``(E, N, A, iterations, solved, v^T W v, residuals, variances, jacobian,
    cofactor)``.

    Gauss-Newton on ``v = r - rho`` with weights ``1 / sigma_i^2``, ``sigma_i^2 =
    (sigma_r^2 + (d rho / d phi sigma_phi)^2) * scale_i``, from the given pose until
    the step is below the coordinates' rounding (or ``max_iterations``); then the
    residuals, variances, Jacobian and ``(G^T W G)^-1`` at the solution. ``solved`` is
    False when a normal matrix is exactly singular (the rest is then undefined).
    """
    n = angles.shape[0]
    rho = np.empty(n)
    jac = np.empty((n, 3))
    var = np.empty(n)
    weight = np.empty(n)
    v = np.empty(n)
    normal = np.empty((3, 3))
    rhs = np.empty((3, 1))
    e, nn, az = easting, northing, azimuth
    rs2 = range_sigma**2
    it = 0
    done = max_iterations <= 0
    chi2 = 0.0
    while True:
        _range_rows_jit(e, nn, az, angles, normals, offsets, rho, jac)
        chi2 = 0.0
        for i in range(n):
            d = -jac[i, 2] * angle_sigma
            var[i] = (rs2 + d * d) * variance_scale[i]
            weight[i] = 1.0 / var[i]
            v[i] = ranges[i] - rho[i]
            chi2 += v[i] * (weight[i] * v[i])
        _normal_equations_jit(jac, v, weight, normal, rhs)
        if done:
            break  # the statistics at the last pose
        it += 1
        if not _lu_solve_jit(normal, rhs):
            return e, nn, az, it, False, chi2, v, var, jac, normal
        e = e + rhs[0, 0]
        nn = nn + rhs[1, 0]
        az = (az + rhs[2, 0]) % (2 * math.pi)
        tol_m = max(1e-11, 4 * np.spacing(max(abs(e), abs(nn), 1.0)))
        done = it >= max_iterations or (
            math.hypot(rhs[0, 0], rhs[1, 0]) < tol_m and abs(rhs[2, 0]) < 1e-13
        )
    cofactor = np.eye(3)
    solved = _lu_solve_jit(normal, cofactor)
    return e, nn, az, it, solved, chi2, v, var, jac, cofactor


def _spread(g0: float, g1: float, g2: float, cofactor: NDArray[np.float64]) -> float:
    """``g^T Q g``: the variance a pose of cofactor ``Q`` gives a predicted range whose
    Jacobian row is ``g``."""
    acc = 0.0
    for r in range(3):
        gr = g0 if r == 0 else (g1 if r == 1 else g2)
        acc += gr * (cofactor[r, 0] * g0 + cofactor[r, 1] * g1 + cofactor[r, 2] * g2)
    return acc


def _beams_toward(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Whether each beam (``angles``, increasing, a turn at most) from the pose points
    within the angle a segment ``seg_a[k]``-``seg_b[k]`` subtends, widened by a
    nanoradian against rounding: a ray outside every one crosses none
    (:func:`_crossing`). Every beam where a segment subtends half a turn or more."""
    n = angles.shape[0]
    cast = np.zeros(n, dtype=np.bool_)
    lo_hi = np.empty((3, 2), dtype=np.intp)
    for k in range(seg_a.shape[0]):
        # A mine-frame direction (dx, dy) is the beam at angle azimuth - atan2(dx, dy).
        at_a = azimuth - math.atan2(seg_a[k, 0] - easting, seg_a[k, 1] - northing)
        at_b = azimuth - math.atan2(seg_b[k, 0] - easting, seg_b[k, 1] - northing)
        turn = (at_b - at_a + math.pi) % (2.0 * math.pi) - math.pi
        width = abs(turn) + 2e-9
        if not width < math.pi - 1e-6:
            cast[:] = True
            return cast
        windows = _beam_windows_jit(angles, min(at_a, at_a + turn) - 1e-9, width, lo_hi)
        for w in range(windows):
            cast[lo_hi[w, 0] : lo_hi[w, 1]] = True
    return cast


def _ray_association(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    valid: NDArray[np.bool_],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
    normals: NDArray[np.float64],
    owner: NDArray[np.intp],
    cofactor: NDArray[np.float64],
    gate_m: float,
    gate_sigmas: float,
    range_sigma: float,
    angle_sigma: float,
    survey_var: NDArray[np.float64],
    min_incidence: float,
    jump: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """``adjustment._ray_association_reference`` beam by beam: the valid beams whose
    ray from the pose first meets one of the segments (:func:`_first_hits`' test and
    tie rule), within the gate of that crossing and not within ``min_incidence`` of
    grazing; which segment; and whether the beam is at its owner's silhouette
    (``edges.at_silhouette``). The gate is ``gate_m`` when ``cofactor`` is not 3 x 3,
    else ``gate_sigmas`` standard deviations of the range about its surveyed panel
    (``survey_var``: each segment's surveyed variance) with the pose's own uncertainty
    along the beam (``g^T Q g``, when finite)."""
    n = angles.shape[0]
    origin = np.array([easting, northing])
    ex, ey, wx, wy, w_x_e = _crossing_terms_jit(origin, seg_a, seg_b)
    hit_t = np.empty(n)
    hit_row = np.full(n, -1, dtype=np.intp)
    ray_owner = np.full(n, -1, dtype=np.intp)
    ux = np.empty(n)
    uy = np.empty(n)
    cast = _beams_toward_jit(easting, northing, azimuth, angles, seg_a, seg_b)
    for i in range(n):
        if not (valid[i] and cast[i]):
            continue
        bearing = azimuth - angles[i]
        ux[i], uy[i] = math.sin(bearing), math.cos(bearing)
        bt, bj = _first_crossing_jit(ux[i], uy[i], ex, ey, wx, wy, w_x_e)
        if bj >= 0:
            hit_t[i] = bt
            hit_row[i] = bj
            ray_owner[i] = owner[bj]
    with_pose = cofactor.shape[0] == 3 and cofactor.shape[1] == 3
    rs2 = range_sigma**2
    beams = np.empty(n, dtype=np.intp)
    rows = np.empty(n, dtype=np.intp)
    edge = np.zeros(n, dtype=np.bool_)
    got = 0
    for i in range(n):
        j = hit_row[i]
        if j < 0:
            continue
        nx, ny = normals[j, 0], normals[j, 1]
        nu = nx * ux[i] + ny * uy[i]
        gate = gate_m
        if with_pose:
            rho = (nx * seg_a[j, 0] + ny * seg_a[j, 1] - (nx * easting + ny * northing)) / nu
            g0, g1 = -nx / nu, -ny / nu
            g2 = -rho * (nx * uy[i] - ny * ux[i]) / nu
            pred = _spread_jit(g0, g1, g2, cofactor)
            d = g2 * angle_sigma
            var = rs2 + d * d + survey_var[j]
            if math.isfinite(pred):
                var += pred
            gate = gate_sigmas * math.sqrt(var)
        t = hit_t[i]
        if not (abs(ranges[i] - t) <= gate and abs(nu) > min_incidence):
            continue
        beams[got] = i
        rows[got] = j
        for nb in (i - 1, i + 1):
            if 0 <= nb < n and valid[nb] and ray_owner[nb] != owner[j] and ranges[nb] - t > jump:
                edge[got] = True
        got += 1
    return beams[:got], rows[:got], edge[:got]


def _robust_gate(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    cofactor: NDArray[np.float64],
    scale: float,
    range_sigma: float,
    angle_sigma: float,
    gate_sigmas: float,
) -> NDArray[np.bool_]:
    """``adjustment._robust_inliers_reference``' test, return by return: ``|r - rho|`` within
    ``gate_sigmas`` times ``scale`` standard deviations of the range and of its
    prediction (``g^T Q g``), never below the floor ``1e-7 (1 + |rho|)``."""
    n = angles.shape[0]
    rho = np.empty(n)
    jac = np.empty((n, 3))
    _range_rows_jit(easting, northing, azimuth, angles, normals, offsets, rho, jac)
    out = np.empty(n, dtype=np.bool_)
    rs2 = range_sigma**2
    for i in range(n):
        g0, g1, g2 = jac[i, 0], jac[i, 1], jac[i, 2]
        pred = _spread_jit(g0, g1, g2, cofactor)
        d = -g2 * angle_sigma
        sig = math.sqrt(rs2 + d * d + pred)
        floor = 1e-7 * (1.0 + abs(rho[i]))
        out[i] = abs(ranges[i] - rho[i]) <= gate_sigmas * max(scale * sig, floor)
    return out


def _beacon_statistics(
    jac: NDArray[np.float64],
    residuals: NDArray[np.float64],
    sigmas: NDArray[np.float64],
    lever: NDArray[np.float64],
    beacon: NDArray[np.intp],
    panel: NDArray[np.intp],
    ids: NDArray[np.intp],
    survey_var: NDArray[np.float64],
    max_condition: float,
) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.bool_]]:
    """``integrity._beacon_tests_reference``' statistics, beacon by beacon of ``ids``:
    ``T_b`` (``d^T C^-1 d`` by the Woodbury identity of ``linalg.grouped_quadratic_form``,
    divided by the others' reference variance when above 1), its returns, and whether
    the beacon could be tested (the others determine the pose: ``G^T W G`` finite with
    a condition number at most ``max_condition``; ``C`` not singular)."""
    n = jac.shape[0]
    m = ids.shape[0]
    stat = np.zeros(m)
    count = np.zeros(m, dtype=np.intp)
    tested = np.zeros(m, dtype=np.bool_)
    w = np.empty(n)
    for i in range(n):
        w[i] = 1.0 / sigmas[i] ** 2
    normal = np.empty((3, 3))
    rhs = np.empty((3, 1))
    for q in range(m):
        b = ids[q]
        normal[:, :] = 0.0
        rhs[:, :] = 0.0
        n_rest = 0
        for i in range(n):
            if beacon[i] == b:
                continue
            n_rest += 1
            wi = w[i]
            wv = wi * residuals[i]
            for r in range(3):
                rhs[r, 0] += jac[i, r] * wv
                for c in range(3):
                    normal[r, c] += jac[i, r] * (wi * jac[i, c])
        finite = True
        for r in range(3):
            for c in range(3):
                if not math.isfinite(normal[r, c]):
                    finite = False
        if not finite or np.linalg.cond(normal) > max_condition:
            continue  # the others alone do not determine the pose: no test
        q_rest = np.eye(3)
        if not _lu_solve_jit(normal, q_rest):
            continue
        delta = np.zeros(3)
        for r in range(3):
            for c in range(3):
                delta[r] += q_rest[r, c] * rhs[c, 0]
        # The beacon's returns, and one column of levers per panel among them.
        panels_of = np.unique(panel[beacon == b])
        k = 3 + panels_of.shape[0]
        y = np.zeros(k)
        kk = np.zeros((k, k))
        dwd = 0.0
        n_mine = 0
        col = np.zeros(k)
        group_var = np.zeros(k)
        for i in range(n):
            if beacon[i] != b:
                continue
            n_mine += 1
            d = residuals[i] - (jac[i, 0] * delta[0] + jac[i, 1] * delta[1] + jac[i, 2] * delta[2])
            col[:] = 0.0
            col[0], col[1], col[2] = jac[i, 0], jac[i, 1], jac[i, 2]
            at = 3 + np.searchsorted(panels_of, panel[i])
            col[at] = lever[i]
            group_var[at] = survey_var[i]
            wi = w[i]
            dwd += d * (wi * d)
            for r in range(k):
                y[r] += col[r] * (wi * d)
                for c in range(k):
                    kk[r, c] += col[r] * (wi * col[c])
        mm = np.zeros((k, k))
        mm[:3, :3] = q_rest
        for r in range(3, k):
            mm[r, r] = group_var[r]
        lhs = np.eye(k) + mm @ kk
        z = (mm @ y).reshape(k, 1)
        if not _lu_solve_jit(lhs, z):
            continue
        t = dwd
        for r in range(k):
            t -= y[r] * z[r, 0]
        if n_rest > 3:
            misfit = 0.0
            for i in range(n):
                if beacon[i] == b:
                    continue
                vr = residuals[i] - (
                    jac[i, 0] * delta[0] + jac[i, 1] * delta[1] + jac[i, 2] * delta[2]
                )
                misfit += vr * (w[i] * vr)
            t /= max(1.0, misfit / (n_rest - 3))
        stat[q] = t
        count[q] = n_mine
        tested[q] = True
    return stat, count, tested


def _information(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    range_sigma: float,
    angle_sigma: float,
) -> NDArray[np.float64]:
    """``bounds._information_reference``: ``sum g g^T / sigma^2`` of the range rows."""
    n = angles.shape[0]
    rho = np.empty(n)
    jac = np.empty((n, 3))
    _range_rows_jit(easting, northing, azimuth, angles, normals, offsets, rho, jac)
    out = np.zeros((3, 3))
    rs2 = range_sigma**2
    for i in range(n):
        d = -jac[i, 2] * angle_sigma
        w = 1.0 / (rs2 + d * d)
        for r in range(3):
            for c in range(3):
                out[r, c] += jac[i, r] * (jac[i, c] * w)
    return out


def _standardised(
    jac: NDArray[np.float64],
    cofactor: NDArray[np.float64],
    sigmas: NDArray[np.float64],
    residuals: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``integrity._standardised_reference``: Baarda's ``w_i = v_i / sigma_vi``, with
    ``sigma_vi^2 = sigma_i^2 - g_i Q g_i^T`` (at least 1e-30)."""
    n = jac.shape[0]
    out = np.empty(n)
    for i in range(n):
        g0, g1, g2 = jac[i, 0], jac[i, 1], jac[i, 2]
        pred = _spread_jit(g0, g1, g2, cofactor)
        out[i] = residuals[i] / math.sqrt(max(sigmas[i] ** 2 - pred, 1e-30))
    return out


def _group_residuals(
    keys: NDArray[np.intp], v: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
    """Per group of returns sharing a key: the keys (sorted), the returns' count, the
    RMS of ``v`` and the largest ``|w|`` (``integrity._groups_reference``)."""
    names = np.unique(keys)
    m = names.shape[0]
    count = np.zeros(m, dtype=np.intp)
    ss = np.zeros(m)
    largest = np.zeros(m)
    for i in range(keys.shape[0]):
        g = np.searchsorted(names, keys[i])
        count[g] += 1
        ss[g] += v[i] * v[i]
        largest[g] = max(largest[g], abs(w[i]))
    rms = np.sqrt(ss / count)
    return names, count, rms, largest


def _survey_shares(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    normals: NDArray[np.float64],
    jac: NDArray[np.float64],
    sigmas: NDArray[np.float64],
    cofactor: NDArray[np.float64],
    panel: NDArray[np.intp],
    survey_var: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``adjustment._survey_covariance_reference``: ``sum_p K_p l_p (K_p l_p)^T`` times
    panel ``p``'s surveyed variance (``survey_var``, per return), ``K = Q G^T W`` the
    estimator, ``l_i = 1 / |n . u_i|`` the levers of panel ``p``'s returns."""
    names = np.unique(panel)
    cols = np.zeros((names.shape[0], 3))
    group_var = np.zeros(names.shape[0])
    for i in range(angles.shape[0]):
        bearing = azimuth - angles[i]
        lever = 1.0 / abs(normals[i, 0] * math.sin(bearing) + normals[i, 1] * math.cos(bearing))
        scale = lever / sigmas[i] ** 2
        p = np.searchsorted(names, panel[i])
        group_var[p] = survey_var[i]
        for r in range(3):
            cols[p, r] += (
                cofactor[r, 0] * jac[i, 0] + cofactor[r, 1] * jac[i, 1] + cofactor[r, 2] * jac[i, 2]
            ) * scale
    out = np.zeros((3, 3))
    for p in range(names.shape[0]):
        for r in range(3):
            for c in range(3):
                out[r, c] += group_var[p] * (cols[p, r] * cols[p, c])
    return out


def _adjust_rounds(
    easting: float,
    northing: float,
    azimuth: float,
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    valid: NDArray[np.bool_],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
    normals: NDArray[np.float64],
    owner: NDArray[np.intp],
    gate_m: float,
    gate_sigmas: float,
    range_sigma: float,
    angle_sigma: float,
    survey_var: NDArray[np.float64],
    min_incidence: float,
    jump: float,
    silhouette_variance: float,
    mad_quantile: float,
    max_rounds: int,
    max_iterations: int,
    max_condition: float,
) -> tuple[
    int,
    int,
    NDArray[np.intp],
    NDArray[np.intp],
    NDArray[np.float64],
    tuple[
        float,
        float,
        float,
        int,
        bool,
        float,
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
        NDArray[np.float64],
    ],
]:
    """The rounds of ``adjustment._adjust_on_panels_reference``: ``(code, returns,
    beams, rows, variance scales, adjustment)``, the adjustment as
    :func:`_gauss_newton` returns it.

    Each round casts every beam from the current pose (:func:`_ray_association`),
    drops returns beyond the robust gate of the last round's adjustment
    (:func:`_robust_gate`, its scale the median absolute standardised residual over
    ``mad_quantile``, at most 1), weights those at a silhouette by
    ``silhouette_variance`` and adjusts, until the returns and their weights repeat.
    ``code`` is 0 for an adjustment, 1 when fewer than four returns are left
    (``returns`` says how many), 2 when the adjustment does not determine the pose
    (a singular normal matrix, a cofactor not finite, or its correlation matrix's
    condition number above ``max_condition``)."""
    no_cofactor = np.zeros((0, 0))
    e, nn, az = easting, northing, azimuth
    have = False
    used = np.zeros(0, dtype=np.intp)
    used_rows = np.zeros(0, dtype=np.intp)
    used_scale = np.zeros(0)
    empty = np.zeros(0)
    adj = (e, nn, az, 0, False, 0.0, empty, empty, np.zeros((0, 3)), no_cofactor)
    for _ in range(max_rounds):
        cof = adj[9] if have else no_cofactor
        beams, rows, edge = _ray_association_jit(
            e,
            nn,
            az,
            angles,
            ranges,
            valid,
            seg_a,
            seg_b,
            normals,
            owner,
            cof,
            gate_m,
            gate_sigmas,
            range_sigma,
            angle_sigma,
            survey_var,
            min_incidence,
            jump,
        )
        m = beams.shape[0]
        b_angles = np.empty(m)
        b_ranges = np.empty(m)
        b_normals = np.empty((m, 2))
        b_offsets = np.empty(m)
        for i in range(m):
            j = rows[i]
            b_angles[i] = angles[beams[i]]
            b_ranges[i] = ranges[beams[i]]
            b_normals[i, 0] = normals[j, 0]
            b_normals[i, 1] = normals[j, 1]
            b_offsets[i] = normals[j, 0] * seg_a[j, 0] + normals[j, 1] * seg_a[j, 1]
        if have:
            v, var = adj[6], adj[7]
            scale = 1.0
            if v.shape[0]:
                std = np.empty(v.shape[0])
                for i in range(v.shape[0]):
                    std[i] = abs(v[i] / math.sqrt(var[i]))
                scale = min(1.0, np.median(std) / mad_quantile)
            good = _robust_gate_jit(
                adj[0],
                adj[1],
                adj[2],
                b_angles,
                b_ranges,
                b_normals,
                b_offsets,
                adj[9],
                scale,
                range_sigma,
                angle_sigma,
                gate_sigmas,
            )
            beams, rows, edge = beams[good], rows[good], edge[good]
            b_angles, b_ranges = b_angles[good], b_ranges[good]
            b_normals, b_offsets = b_normals[good], b_offsets[good]
            m = beams.shape[0]
        weights = np.ones(m)
        for i in range(m):
            if edge[i]:
                weights[i] = silhouette_variance
        if have and m == used.shape[0]:
            same = True
            for i in range(m):
                if beams[i] != used[i] or weights[i] != used_scale[i]:
                    same = False
                    break
            if same:
                break
        if m < 4:
            return 1, m, used, used_rows, used_scale, adj
        adj = _gauss_newton_jit(
            e,
            nn,
            az,
            b_angles,
            b_ranges,
            b_normals,
            b_offsets,
            weights,
            range_sigma,
            angle_sigma,
            max_iterations,
        )
        q = adj[9]
        ok = adj[4]
        for r in range(3):
            for c in range(3):
                if not math.isfinite(q[r, c]):
                    ok = False
        if ok:
            d = np.empty(3)
            for r in range(3):
                d[r] = math.sqrt(abs(q[r, r]))
                if d[r] == 0.0:
                    d[r] = 1.0
            corr = np.empty((3, 3))
            for r in range(3):
                for c in range(3):
                    corr[r, c] = q[r, c] / (d[r] * d[c])
            ok = np.linalg.cond(corr) <= max_condition
        if not ok:
            return 2, m, used, used_rows, used_scale, adj
        have = True
        used, used_rows, used_scale = beams, rows, weights
        e, nn, az = adj[0], adj[1], adj[2]
    return 0, used.shape[0], used, used_rows, used_scale, adj


def _bound(info: NDArray[np.float64], max_condition: float) -> NDArray[np.float64]:
    """``bounds.inverse_bound``: ``info^-1``, or ``inf`` on the diagonal (0 off it)
    when ``info`` is not finite, singular, its inverse not finite, or its condition
    number above ``max_condition``."""
    out = np.eye(3)
    fail = np.zeros((3, 3))
    for r in range(3):
        fail[r, r] = np.inf
        for c in range(3):
            if not math.isfinite(info[r, c]):
                return fail
    if not _lu_solve_jit(info, out):
        return fail
    for r in range(3):
        for c in range(3):
            if not math.isfinite(out[r, c]):
                return fail
    if np.linalg.cond(info) > max_condition:
        return fail
    return out


def _odometry_fit(
    scan_points: NDArray[np.float64],
    dx: float,
    dy: float,
    dtheta: float,
    points: NDArray[np.float64],
    bearing: NDArray[np.float64],
    order: NDArray[np.intp],
    normals: NDArray[np.float64],
    gates: NDArray[np.float64],
    max_iterations: int,
    min_matches: int,
) -> tuple[float, float, float, int, float, NDArray[np.float64]]:
    """The point-to-plane ICP of ``odometry._scan_to_scan_reference``: ``(dx, dy,
    dtheta, matches, sum of squared residuals, J^T J)`` at the end, ``matches`` 0 when
    fewer than ``min_matches`` returns were matched on the way.

    ``scan_points`` are moved by the motion and matched to the nearest keyframe
    return (``points``, by bearing as :func:`_nearest_by_bearing` reads them) within each
    gate in turn, up to ``max_iterations`` least-squares steps a gate
    (:func:`_normal_step`; LAPACK's ``gelsd`` with numpy's cut-off where it declines),
    until a step is below 1e-5 m and 1e-6 rad, or the matches are a set met before in
    the gate (:func:`_matches_met`): the last one's, in a coarse gate (whose work is
    done once the returns keep their matches), or one two or more iterations back (a
    cycle no step ends, or matches that stood for three iterations). The residuals and
    Jacobian are those of the last gate at the final motion."""
    n = scan_points.shape[0]
    moved = np.empty((n, 2))
    x0, x1, x2 = dx, dy, dtheta
    info = np.zeros((3, 3))
    n_gates = gates.shape[0]
    # Each point's last nearest keyframe return lies within its distance then plus
    # how far the point has moved since: the next search looks no further.
    within = np.full(n, np.inf)
    seen = np.empty((max_iterations, n), dtype=np.intp)
    for g in range(n_gates + 1):
        final = g == n_gates
        gate = gates[n_gates - 1] if final else gates[g]
        n_seen = 0
        for _ in range(1 if final else max_iterations):
            c, s_ = math.cos(x2), math.sin(x2)
            for i in range(n):
                px, py = scan_points[i, 0], scan_points[i, 1]
                mx = px * c + py * -s_ + x0
                my = px * s_ + py * c + x1
                if math.isfinite(within[i]):
                    within[i] += math.hypot(mx - moved[i, 0], my - moved[i, 1])
                    within[i] = within[i] * (1.0 + 1e-9) + 1e-12  # rounding's share
                moved[i, 0] = mx
                moved[i, 1] = my
            dist, j = _nearest_by_bearing_jit(moved, points, bearing, order, gate, within)
            for i in range(n):
                within[i] = dist[i]
            if not final:
                for i in range(n):
                    seen[n_seen, i] = j[i] if math.isfinite(dist[i]) else -1
                if _matches_met_jit(seen, n_seen, g < n_gates - 1):
                    break
                n_seen += 1
            k = 0
            for i in range(n):
                if math.isfinite(dist[i]):
                    k += 1
            if k < min_matches:
                return x0, x1, x2, 0, 0.0, info
            jac = np.empty((k, 3))
            rhs = np.empty(k)
            r = 0
            for i in range(n):
                if not math.isfinite(dist[i]):
                    continue
                q = j[i]
                nrx, nry = normals[q, 0], normals[q, 1]
                rhs[r] = -((moved[i, 0] - points[q, 0]) * nrx + (moved[i, 1] - points[q, 1]) * nry)
                relx, rely = moved[i, 0] - x0, moved[i, 1] - x1
                jac[r, 0] = nrx
                jac[r, 1] = nry
                jac[r, 2] = nry * relx - nrx * rely
                r += 1
            if final:
                sse = 0.0
                for i in range(k):
                    sse += rhs[i] * rhs[i]
                for a in range(3):
                    for b in range(3):
                        acc = 0.0
                        for i in range(k):
                            acc += jac[i, a] * jac[i, b]
                        info[a, b] = acc
                return x0, x1, x2, k, sse, info
            step: NDArray[np.floating[Any]] = _normal_step_jit(jac, rhs, k)
            if not math.isfinite(step[0]):
                step = np.linalg.lstsq(jac, rhs, rcond=np.finfo(np.float64).eps * max(k, 3))[0]
            x0 += step[0]
            x1 += step[1]
            x2 += step[2]
            if math.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
                break
    return x0, x1, x2, 0, 0.0, info


def _matches_met(seen: NDArray[np.intp], last: int, coarse: bool) -> bool:
    """Whether the matches ``seen[last]`` end an ICP gate: the same as the iteration
    before's when ``coarse``, or the same as an earlier iteration's (not the one
    before) in any gate. The last step was solved with the matches before; with the
    same matches again a coarse gate has brought the returns to their walls, and a
    finer one takes another step. Matches met two or more iterations back either
    come round in a cycle (returns on the edge of their gate, or half-way between two
    neighbours), which the steps never leave, or have stood for three iterations: two
    Gauss-Newton steps on the same matches, the second the square of the first, which
    leaves the pose at their least-squares optimum to far below the range noise. The
    odometry's reference (``odometry._scan_to_scan_reference``) stops there too."""
    n = seen.shape[1]
    for k in range(last - 1, -1, -1):
        if k == last - 1 and not coarse:
            continue
        same = True
        for i in range(n):
            if seen[k, i] != seen[last, i]:
                same = False
                break
        if same:
            return True
    return False


def _walk_left(sorted_values: NDArray[np.float64], value: float, guess: int) -> int:
    """``searchsorted(sorted_values, value, side="left")``, walked from ``guess``: a few
    steps where consecutive queries move little (a scan's beams, in order)."""
    p = guess
    n = sorted_values.shape[0]
    while p > 0 and sorted_values[p - 1] >= value:
        p -= 1
    while p < n and sorted_values[p] < value:
        p += 1
    return p


def _walk_right(sorted_values: NDArray[np.float64], value: float, guess: int) -> int:
    """``searchsorted(sorted_values, value, side="right")``, walked from ``guess``."""
    p = guess
    n = sorted_values.shape[0]
    while p > 0 and sorted_values[p - 1] > value:
        p -= 1
    while p < n and sorted_values[p] <= value:
        p += 1
    return p


def _nearest_by_bearing(
    query: NDArray[np.float64],
    points: NDArray[np.float64],
    bearing: NDArray[np.float64],
    order: NDArray[np.intp],
    gate: float,
    within: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """:func:`_nearest_within`'s answers (the same distances, indices and tie rule)
    through the points' bearings from the origin, sorted (``bearing``; ``order`` the
    points in that order): a point nearer than ``gate`` to a query point at range
    ``r > gate`` lies within ``asin(gate / r)`` of its bearing, so only that window is
    searched (a scan's returns, one a beam: a few beams' worth); a query point within
    ``gate`` of the origin is compared with every point. The window's ends are walked
    from the previous query's, which a scan's next beam barely moves.

    ``within`` (empty, or one a query point) is a distance the caller knows some
    point to lie within (the last nearest's distance plus how far the query point
    moved since): the window is then that radius's, where it is below the gate. The
    nearest lies within it, so the answers are the same."""
    m = query.shape[0]
    n = points.shape[0]
    dist = np.full(m, np.inf)
    idx = np.full(m, n, dtype=np.intp)
    g2 = gate * gate
    left = 0
    right = 0
    known = within.shape[0] == m
    for i in range(m):
        qx, qy = query[i, 0], query[i, 1]
        if not (math.isfinite(qx) and math.isfinite(qy)):
            continue
        r = math.hypot(qx, qy)
        reach = min(gate, within[i]) if known else gate
        # (first, last) spans of sorted positions to search, two when the window
        # wraps across -pi / pi
        a0, b0, a1, b1 = 0, n, 0, 0
        if r > reach * (1.0 + 1e-9):
            # widened by far more than the rounding of the bearings: extra candidates
            # are harmless, every one's distance is computed exactly
            half = math.asin(reach / r) * (1.0 + 1e-9) + 1e-12
            t = math.atan2(qy, qx)
            lo, hi = t - half, t + half
            if lo < -math.pi:
                b0 = _walk_right_jit(bearing, hi, 0)
                a1 = _walk_left_jit(bearing, lo + 2.0 * math.pi, n)
                b1 = n
            elif hi > math.pi:
                a0 = _walk_left_jit(bearing, lo, n)
                b1 = _walk_right_jit(bearing, hi - 2.0 * math.pi, 0)
            else:
                left = _walk_left_jit(bearing, lo, left)
                right = _walk_right_jit(bearing, hi, max(right, left))
                a0, b0 = left, right
        best = g2
        bj = -1
        for span in range(2):
            first, last = (a0, b0) if span == 0 else (a1, b1)
            for s in range(first, last):
                k = order[s]
                dx = points[k, 0] - qx
                dy = points[k, 1] - qy
                d2 = dx * dx + dy * dy
                if d2 < best or (d2 == best and bj >= 0 and k < bj):
                    best = d2
                    bj = k
        if bj >= 0:
            dist[i] = math.sqrt(best)
            idx[i] = bj
    return dist, idx


def _panel_rows3d(
    weighed: NDArray[np.float64],
    rotations: NDArray[np.float64],
    offset: NDArray[np.float64],
    weight: float,
    v: NDArray[np.float64],
    J: NDArray[np.float64],
    W: NDArray[np.float64],
    N: NDArray[np.float64],
    g: NDArray[np.float64],
    cosines: NDArray[np.float64],
) -> None:
    """One Gauss-Newton iteration's panel rows of the 3D adjustment
    (``adjust3d._panel_rows_reference``): each return's ``weighed`` (m, 14) times the
    pose's ``rotations`` (14, 8; zero but for the blocks ``gauss_newton3d`` sets) gives
    its offset across its plane (less ``offset``), its derivatives by azimuth, pitch and
    roll, its ray's incidence ``cos i`` (into ``cosines``; a thousandth at least, with
    its sign) and that incidence's derivatives.
    Its row is the range residual, the offset over ``cos i`` (the measured range less the
    range along the ray to the plane), into ``v``; its derivatives by the five the plane
    observes into ``J[:, :5]``, through the incidence as well; its weight ``weight``
    into ``W``. ``N`` (6, 6) and ``g`` (6,) are set to ``J' W J`` and ``J' W v`` of those
    rows, in one pass."""
    m = weighed.shape[0]
    for a in range(6):
        g[a] = 0.0
        for b in range(6):
            N[a, b] = 0.0
    row = np.empty(8)
    for i in range(m):
        # the points' six columns by R and its derivatives, the rays' six by the same,
        # the normal by the position: the rest of ``rotations`` is zero
        for c in range(4):
            acc = 0.0
            ray = 0.0
            for j in range(6):
                acc += weighed[i, j] * rotations[j, c]
                ray += weighed[i, 6 + j] * rotations[6 + j, 4 + c]
            row[c] = acc
            row[4 + c] = ray
        row[0] += weighed[i, 12] * rotations[12, 0] + weighed[i, 13] * rotations[13, 0]
        cos = row[4]
        if abs(cos) < 1e-3:
            cos = 1e-3 if cos >= 0.0 else -1e-3
        cosines[i] = cos
        r = (row[0] - offset[i]) / cos
        v[i] = r
        J[i, 0] = weighed[i, 12] / cos
        J[i, 1] = weighed[i, 13] / cos
        J[i, 2] = (r * row[5] - row[1]) / cos  # d yaw / d A = -1
        J[i, 3] = (row[2] - r * row[6]) / cos
        J[i, 4] = (row[3] - r * row[7]) / cos
        W[i] = weight
        for a in range(5):
            wa = weight * J[i, a]
            g[a] += wa * r
            for b in range(a, 5):
                N[a, b] += wa * J[i, b]
    for a in range(5):
        for b in range(a):
            N[a, b] = N[b, a]


def _top_edges3d(
    rel: NDArray[np.float64],
    origin: NDArray[np.float64],
    which: NDArray[np.intp],
    pi: NDArray[np.intp],
    pk: NDArray[np.intp],
    normal: NDArray[np.float64],
    offset: NDArray[np.float64],
    start: NDArray[np.float64],
    along: NDArray[np.float64],
    length: NDArray[np.float64],
    top: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    inset: NDArray[np.float64],
    hit_gate: float,
    gate: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp], bool]:
    """Each panel's top edge (``adjust3d._top_edges``, its numpy reference) among the
    pairs of returns ``pi`` and panels ``pk``: the rays from ``origin`` to the returns
    ``origin + rel`` (n, 3) crossing the panels' planes (``normal``, ``offset``; from
    ``start`` along ``along`` for ``length``; tops ``top``); each panel's hits (returns
    ``which`` gives it, within ``hit_gate`` of its plane, inside ``lo``..``hi`` along
    it, their heights finite) and crossings over (a ray crossing the plane before its
    return, ``0 < s < 1``, returning from the wall behind the plane by ``gate`` or more,
    on the far side from the sensor, inside ``inset`` of either end), the hits at or
    above the median of its hits and the crossings above it, split at the height the
    fewest of them contradict (fewer than the crossings above it; the lowest, at a tie):
    the highest hit below (the least return at one height) and the lowest crossing above
    (the first pair), heights where the rays cross the plane. Returns the panels with
    both (ascending), their hits' and crossings' returns, and whether every return
    ``which`` gives a panel is paired with it (if not, the reference's fallback must
    answer)."""
    n_k = offset.shape[0]
    o0, o1 = origin[0], origin[1]
    side = np.empty(n_k)
    for k in range(n_k):
        side[k] = o0 * normal[k, 0] + o1 * normal[k, 1] - offset[k]
    # where each pair's ray crosses its panel's plane: along the ray, along the panel
    cross, along_panel, _ = _rays3d_jit(rel, origin, pi, pk, normal, offset, start, along)
    m = pi.shape[0]
    kind = np.zeros(m, dtype=np.int8)  # 1: a hit; 2: a crossing over
    height = np.empty(m)
    hits_of = np.zeros(n_k, dtype=np.intp)
    own = 0
    for j in range(m):
        i, k = pi[j], pk[j]
        height[j] = cross[j] * rel[i, 2]
        if which[i] != k:
            continue
        own += 1
        t = along_panel[j]
        across = (rel[i, 0] + o0) * normal[k, 0] + (rel[i, 1] + o1) * normal[k, 1] - offset[k]
        if (
            abs(across) <= hit_gate
            and t > lo[k]
            and t < hi[k]
            and np.isfinite(top[k])
            and np.isfinite(height[j])
        ):
            kind[j] = 1
            hits_of[k] += 1
    assigned = 0
    for i in range(which.shape[0]):
        if which[i] >= 0:
            assigned += 1
    # each panel's hits' median height
    begin = np.zeros(n_k + 1, dtype=np.intp)
    for k in range(n_k):
        begin[k + 1] = begin[k] + hits_of[k]
    heights = np.empty(begin[n_k])
    filled = begin[:n_k].copy()
    for j in range(m):
        if kind[j] == 1:
            k = pk[j]
            heights[filled[k]] = height[j]
            filled[k] += 1
    middle = np.full(n_k, np.nan)
    for k in range(n_k):
        c = hits_of[k]
        if c == 0:
            continue
        run = np.sort(heights[begin[k] : begin[k + 1]])
        half = c // 2
        middle[k] = run[half] if c % 2 == 1 else (run[half - 1] + run[half]) / 2
    # the hits and crossings over above it, per panel
    above = np.zeros(n_k, dtype=np.intp)
    crossings = np.zeros(n_k, dtype=np.intp)
    for j in range(m):
        i, k = pi[j], pk[j]
        if not np.isfinite(middle[k]):
            continue
        h = height[j]
        if kind[j] == 1:
            if h >= middle[k]:
                above[k] += 1
            continue
        s, t = cross[j], along_panel[j]
        if not (s > 0.0 and s < 1.0):
            continue
        across = (rel[i, 0] + o0) * normal[k, 0] + (rel[i, 1] + o1) * normal[k, 1] - offset[k]
        if (
            t > inset[k]
            and t < length[k] - inset[k]
            and across * side[k] < 0.0
            and abs(across) >= gate
            and h > middle[k]
        ):
            kind[j] = 2
            above[k] += 1
            crossings[k] += 1
    begin[0] = 0
    for k in range(n_k):
        begin[k + 1] = begin[k] + (above[k] if crossings[k] > 0 else 0)
    h_of = np.empty(begin[n_k])
    tie = np.empty(begin[n_k], dtype=np.intp)
    ray = np.empty(begin[n_k], dtype=np.intp)
    hit_of = np.empty(begin[n_k], dtype=np.bool_)
    filled = begin[:n_k].copy()
    for j in range(m):
        k = pk[j]
        if crossings[k] == 0 or kind[j] == 0:
            continue
        if kind[j] == 1 and not height[j] >= middle[k]:
            continue
        f = filled[k]
        h_of[f] = height[j]
        ray[f] = pi[j]
        hit_of[f] = kind[j] == 1
        # at one height, hits first (by return, descending), then crossings by pair
        tie[f] = -pi[j] - 1 if kind[j] == 1 else j
        filled[k] += 1
    ks = np.empty(n_k, dtype=np.intp)
    hits = np.empty(n_k, dtype=np.intp)
    overs = np.empty(n_k, dtype=np.intp)
    count = 0
    for k in range(n_k):
        b, e = begin[k], begin[k + 1]
        if e == b:
            continue
        first = np.argsort(tie[b:e], kind="mergesort")
        order = first[np.argsort(h_of[b:e][first], kind="mergesort")] + b
        # contradictions of a split just below each: the hits from it up, the
        # crossings below it
        hits_up = 0
        for q in range(e - b):
            if hit_of[order[q]]:
                hits_up += 1
        below = 0
        best, fewest = -1, 0
        for q in range(e - b):
            if q > 0:
                lower, upper = order[q - 1], order[q]
                wrong = hits_up + below
                if (
                    hit_of[lower]
                    and not hit_of[upper]
                    and h_of[lower] < h_of[upper]
                    and wrong < crossings[k] - below
                    and (best < 0 or wrong < fewest)
                ):
                    best, fewest = q, wrong
            if hit_of[order[q]]:
                hits_up -= 1
            else:
                below += 1
        if best > 0:
            ks[count], hits[count], overs[count] = k, ray[order[best - 1]], ray[order[best]]
            count += 1
    return ks[:count].copy(), hits[:count].copy(), overs[:count].copy(), own == assigned


def _brackets3d(
    p: NDArray[np.float64],
    rows: NDArray[np.intp],
    ray: NDArray[np.intp],
    D: NDArray[np.float64],
    origin: NDArray[np.float64],
    nx: NDArray[np.float64],
    ny: NDArray[np.float64],
    offset: NDArray[np.float64],
    top: NDArray[np.float64],
    member: NDArray[np.bool_],
    beam_sigma: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The beacons' elevation brackets of one Gauss-Newton iteration
    (``adjust3d._TopEdges.brackets_reference``): the top edges' rays, the returns
    ``p[rows[ray]]`` (the hits' first, then the crossings over) turned by ``D[0]`` (R;
    ``D[1..3]`` its derivatives by roll, pitch and yaw) from the sensor at ``origin``,
    crossing their panels' planes (``nx``, ``ny``, ``offset``; tops ``top``); per beacon
    (``member``: beacons × top edges) the middle of the intersection of its panels'
    brackets, its variance (the uniform's over the width, and ``beam_sigma`` times the
    range at each end) and the derivatives (beacons, 6) of ``Z - middle`` by (E, N, A,
    pitch, roll, Z), through the two rays setting its ends."""
    q_n = ray.shape[0]
    tops = member.shape[1]
    beacons = member.shape[0]
    o0, o1 = origin[0], origin[1]
    rel = np.empty((q_n, 3))
    s = np.empty(q_n)
    ends = np.empty(q_n)
    for q in range(q_n):
        row = rows[ray[q]]
        for c in range(3):
            rel[q, c] = D[0, c, 0] * p[row, 0] + D[0, c, 1] * p[row, 1] + D[0, c, 2] * p[row, 2]
        s[q] = (offset[q] - (o0 * nx[q] + o1 * ny[q])) / (rel[q, 0] * nx[q] + rel[q, 1] * ny[q])
        ends[q] = top[q] - s[q] * rel[q, 2]
    middle = np.empty(beacons)
    spread = np.empty(beacons)
    d = np.zeros((beacons, 6))
    for b in range(beacons):
        # the top edges setting its ends: the lowest high, the highest low (the first
        # at a tie; a NaN first of all, as numpy's argmin and argmax)
        hi, lo = -1, -1
        for e in range(tops):
            if not member[b, e]:
                continue
            h, low = ends[e], ends[tops + e]
            if hi < 0 or (not np.isnan(ends[hi]) and (np.isnan(h) or h < ends[hi])):
                hi = e
            if lo < 0 or (not np.isnan(ends[lo]) and (np.isnan(low) or low > ends[lo])):
                lo = tops + e
        reach2 = 0.0
        for q in (hi, lo):
            n0, n1 = nx[q], ny[q]
            r0, r1, r2 = rel[q, 0], rel[q, 1], rel[q, 2]
            across = r0 * n0 + r1 * n1
            d[b, 0] += 0.5 * (-(r2 / across) * n0)
            d[b, 1] += 0.5 * (-(r2 / across) * n1)
            row = rows[ray[q]]
            for a in range(3):  # by yaw, pitch, roll: the ray turned by each
                turn = D[3 - a]
                t0 = turn[0, 0] * p[row, 0] + turn[0, 1] * p[row, 1] + turn[0, 2] * p[row, 2]
                t1 = turn[1, 0] * p[row, 0] + turn[1, 1] * p[row, 1] + turn[1, 2] * p[row, 2]
                t2 = turn[2, 0] * p[row, 0] + turn[2, 1] * p[row, 1] + turn[2, 2] * p[row, 2]
                sideways = t0 * n0 + t1 * n1
                grad = s[q] * t2 - (s[q] * r2) * sideways / across
                if a == 0:
                    grad = -grad  # d yaw / d A = -1
                d[b, 2 + a] += 0.5 * grad
            x, y, z = s[q] * r0, s[q] * r1, s[q] * r2
            reach = beam_sigma * math.sqrt(x * x + y * y + z * z)
            reach2 += reach * reach
        d[b, 5] = 1.0
        middle[b] = 0.5 * (ends[lo] + ends[hi])
        width = ends[hi] - ends[lo]
        spread[b] = width * width / 12.0 + 0.25 * reach2
    return middle, spread, d


def _rotation_derivatives(roll: float, pitch: float, yaw: float) -> NDArray[np.float64]:
    """R = Rz(yaw) Ry(pitch) Rx(roll) and its derivatives by roll, pitch and yaw, (4, 3,
    3): ``adjust3d._derivatives``, compiled."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    D = np.zeros((4, 3, 3))
    D[0, 0, 0], D[0, 0, 1], D[0, 0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    D[0, 1, 0], D[0, 1, 1], D[0, 1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    D[0, 2, 0], D[0, 2, 1], D[0, 2, 2] = -sp, cp * sr, cp * cr
    for r in range(3):  # by roll: R Kx
        D[1, r, 1], D[1, r, 2] = D[0, r, 2], -D[0, r, 1]
    D[2, 0, 0], D[2, 0, 1], D[2, 0, 2] = -cy * sp, cy * cp * sr, cy * cp * cr
    D[2, 1, 0], D[2, 1, 1], D[2, 1, 2] = -sy * sp, sy * cp * sr, sy * cp * cr
    D[2, 2, 0], D[2, 2, 1], D[2, 2, 2] = -cp, -sp * sr, -sp * cr
    for c in range(3):  # by yaw: Kz R
        D[3, 0, c], D[3, 1, c] = -D[0, 1, c], D[0, 0, c]
    return D


def _gauss_newton3d(
    weighed: NDArray[np.float64],
    offset_k: NDArray[np.float64],
    weight: float,
    p: NDArray[np.float64],
    rows: NDArray[np.intp],
    ray: NDArray[np.intp],
    nx: NDArray[np.float64],
    ny: NDArray[np.float64],
    offset: NDArray[np.float64],
    top: NDArray[np.float64],
    member: NDArray[np.bool_],
    beam_sigma: float,
    survey_var: float,
    tilt: NDArray[np.float64],
    unobserved: float,
    x: NDArray[np.float64],
    iterations: int,
    converged: NDArray[np.float64],
    J: NDArray[np.float64],
    v: NDArray[np.float64],
    W: NDArray[np.float64],
    N: NDArray[np.float64],
    cosines: NDArray[np.float64],
) -> int:
    """The Gauss-Newton iterations of the 3D adjustment (``adjust3d._solve``; its numpy
    reference ``adjust3d._gauss_newton3d_reference``): from ``x`` (E, N, A, pitch, roll,
    Z; updated in place) until every step is below ``converged`` or ``iterations`` are
    done. Each iteration: the panel returns' rows (:func:`_panel_rows3d` on
    ``weighed``, ``offset_k``, ``weight``); each beacon's bracket (:func:`_brackets3d`
    on the top edges' rays; ``member`` has no row where there are none), weighed by
    one over its variance plus ``survey_var``; the tilt prior's two rows (``tilt``:
    pitch and roll, where given; their rows of ``J`` and ``W`` set already); and
    ``unobserved`` added to the elevation's normal where no bracket holds it. ``J``,
    ``v``, ``W``, ``N`` and the panel returns' incidences ``cosines`` are the last
    iteration's. Returns the iterations done, or -1 where the normal equations are
    singular."""
    m = weighed.shape[0]
    beacons = member.shape[0]
    rows_n = v.shape[0]
    rotations = np.zeros((14, 8))
    g = np.zeros(6)
    rhs = np.empty((6, 1))
    done = 0
    while True:
        done += 1
        D = _rotation_derivatives_jit(x[4], x[3], math.pi / 2 - x[2])
        for a in range(2):
            for b in range(3):
                r = a * 3 + b
                rotations[r, 0] = D[0, a, b]
                rotations[r, 1] = D[3, a, b]  # by yaw, pitch, roll
                rotations[r, 2] = D[2, a, b]
                rotations[r, 3] = D[1, a, b]
                rotations[6 + r, 4] = D[0, a, b]  # the ray's, for its incidence
                rotations[6 + r, 5] = D[3, a, b]
                rotations[6 + r, 6] = D[2, a, b]
                rotations[6 + r, 7] = D[1, a, b]
        rotations[12, 0], rotations[13, 0] = x[0], x[1]
        _panel_rows3d_jit(weighed, rotations, offset_k, weight, v[:m], J[:m], W[:m], N, g, cosines)
        if beacons:
            origin = np.array([x[0], x[1], x[5]])
            middle, spread, dz = _brackets3d_jit(
                p, rows, ray, D, origin, nx, ny, offset, top, member, beam_sigma
            )
            for b in range(beacons):
                J[m + b, :] = dz[b]
                v[m + b] = x[5] - middle[b]
                W[m + b] = 1.0 / (spread[b] + survey_var)
        if tilt.shape[0] == 2:
            v[rows_n - 2] = x[3] - tilt[0]
            v[rows_n - 1] = x[4] - tilt[1]
        for r in range(m, rows_n):
            w = W[r]
            for a in range(6):
                wa = w * J[r, a]
                g[a] += wa * v[r]
                for b in range(6):
                    N[a, b] += J[r, b] * wa
        if beacons == 0:
            N[5, 5] += unobserved
        for a in range(6):
            rhs[a, 0] = -g[a]
        if not _lu_solve_jit(N, rhs):
            return -1
        small = True
        for a in range(6):
            x[a] += rhs[a, 0]
            if not abs(rhs[a, 0]) < converged[a]:
                small = False
        if done >= iterations or small:
            return done


def _assigns3d(
    i: NDArray[np.intp],
    k: NDArray[np.intp],
    s: NDArray[np.float64],
    t: NDArray[np.float64],
    z: NDArray[np.float64],
    reach: NDArray[np.float64],
    grid: NDArray[np.float64],
    gate: float,
    height: float,
    reach_m: float,
    cap: NDArray[np.float64],
    capped: bool,
    floor: NDArray[np.float64],
    floored: bool,
    inner: NDArray[np.float64],
    boxes: NDArray[np.float64],
    boxed: bool,
    turned: NDArray[np.bool_],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    wall: NDArray[np.float64],
    normal: NDArray[np.float64],
    offset: NDArray[np.float64],
) -> NDArray[np.intp]:
    """The panel each return lies on, or -1, for each clearance's extent ``lo``..``hi``
    (clearances × panels): ``adjust3d.PanelPlanes._assigns`` (its numpy reference)
    over the pairs (return ``i``, panel ``k``; their ray's crossing ``s``, ``t``, ``z``;
    the returns' ``reach`` and ``grid`` places). A pair is within ``gate`` along its
    ray; its crossing within ``reach_m`` of the sensor's ``height`` (where finite), not
    above ``cap`` (where ``capped``), not below ``floor`` (where ``floored``); ``boxed``
    (where so) when it crosses below ``inner`` and above ``boxes`` (the heights the
    panel's returns show it at, plus the top margin: no wall test there); inside the
    extent, alone there or the only one ``turned`` to the sensor; and, unless boxed,
    nearer its panel's plane than its beacon's ``wall``."""
    n = grid.shape[0]
    m = i.shape[0]
    clears = lo.shape[0]
    out = np.full((clears, n), -1, dtype=np.intp)
    gated = np.empty(m, dtype=np.bool_)
    cut = np.empty(m, dtype=np.bool_)
    box = np.zeros(m, dtype=np.bool_)
    limited = np.isfinite(reach_m)
    for j in range(m):
        kj = k[j]
        gated[j] = abs(1.0 - s[j]) * reach[i[j]] < gate and s[j] > 0.0
        ok = True
        if limited:
            ok = abs(z[j] - height) <= reach_m
        if capped:
            ok = ok and z[j] <= cap[kj]
        if floored:
            ok = ok and z[j] >= floor[kj]
        cut[j] = ok
        if boxed:
            box[j] = z[j] < inner[kj] and z[j] > boxes[kj]
    facing = np.zeros(n, dtype=np.intp)
    either = np.zeros(n, dtype=np.intp)
    tested = np.zeros(n, dtype=np.bool_)
    for c in range(clears):
        facing[:] = 0
        either[:] = 0
        tested[:] = False
        which = out[c]
        for j in range(m):
            kj = k[j]
            if gated[j] and t[j] > lo[c, kj] and t[j] < hi[c, kj]:
                either[i[j]] += 1
                if turned[kj]:
                    facing[i[j]] += 1
        for j in range(m):
            kj, ij = k[j], i[j]
            if not (gated[j] and cut[j] and t[j] > lo[c, kj] and t[j] < hi[c, kj]):
                continue
            if facing[ij] > 0:
                if not (turned[kj] and facing[ij] == 1):
                    continue
            elif either[ij] != 1:
                continue
            which[ij] = kj
            if not box[j]:
                tested[ij] = True
        for q in range(n):  # nearer its beacon's wall than its panel: the wall's
            if not tested[q]:
                continue
            kq = which[q]
            x, y = grid[q, 0], grid[q, 1]
            to_wall = abs(x * wall[kq, 0] + y * wall[kq, 1] - wall[kq, 2])
            to_panel = abs(x * normal[kq, 0] + y * normal[kq, 1] - offset[kq])
            if to_wall < to_panel:
                which[q] = -1
    return out


def _contiguous3d(
    k: NDArray[np.intp],
    i: NDArray[np.intp],
    h: NDArray[np.float64],
    reach: NDArray[np.float64],
    panels: int,
    spacing: float,
) -> NDArray[np.bool_]:
    """Which of the panel returns (``i`` on panel ``k``, their rays crossing its plane at
    height ``h``; ``reach`` the returns' ranges) fall outside their panel's run of
    heights about its median that no gap wider than 1.5 ``spacing`` at its returns'
    median range, plus 5 cm, breaks: ``locator3d._contiguous`` (its numpy
    reference)."""
    m = k.shape[0]
    count = np.zeros(panels, dtype=np.intp)
    for j in range(m):
        count[k[j]] += 1
    first = np.zeros(panels + 1, dtype=np.intp)
    for q in range(panels):
        first[q + 1] = first[q] + count[q]
    filled = first[:-1].copy()
    grouped = np.empty(m, dtype=np.intp)  # by panel, in their order
    for j in range(m):
        grouped[filled[k[j]]] = j
        filled[k[j]] += 1
    drop = np.zeros(m, dtype=np.bool_)
    for q in range(panels):
        c = count[q]
        if c == 0:
            continue
        mine = grouped[first[q] : first[q + 1]]
        hs = h[mine]
        order = np.argsort(hs, kind="mergesort")  # by height, stable
        hs = hs[order]
        ranges = np.sort(reach[i[mine]])
        mid = c // 2
        if c % 2 == 1:
            median_h, median_r = hs[mid], ranges[mid]
        else:
            median_h = (hs[mid - 1] + hs[mid]) / 2
            median_r = (ranges[mid - 1] + ranges[mid]) / 2
        gap = 1.5 * spacing * median_r + 0.05
        middle = 0
        for a in range(c):
            if hs[a] < median_h:
                middle += 1
        lo, hi = 0, c
        for a in range(c - 1):
            if hs[a + 1] - hs[a] > gap:
                if a < middle:
                    lo = max(lo, a + 1)
                else:
                    hi = min(hi, a + 1)
        for a in range(c):
            if a < lo or a >= hi:
                drop[mine[order[a]]] = True
    return drop


def _floors3d(
    points: NDArray[np.float64],
    R: NDArray[np.float64],
    at: NDArray[np.float64],
    about: NDArray[np.intp],
    first: NDArray[np.intp],
    wall: NDArray[np.float64],
    side: NDArray[np.float64],
    reach: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Each panel's floor (``adjust3d.PanelPlanes._floors``, its numpy reference) from
    the ``points`` (sensor frame) at the pose ``R``, ``at``: of those about panel q,
    ``about[first[q]:first[q + 1]]``, the 2nd percentile of their heights, where there
    are 50 or more and the 20 or more within 5 cm of it spread across the beacon's
    ``wall`` (n, d) by more than 30 cm between their 10th and 90th percentiles and,
    where its panels stand out to ``side`` of it (+1 or -1; 0 for neither), reach out
    to that side by more than ``reach`` (their 90th percentile out); NaN elsewhere."""
    panels = first.shape[0] - 1
    out = np.full(panels, np.nan)
    height = np.empty(points.shape[0])
    for p in range(points.shape[0]):
        height[p] = points[p, 0] * R[2, 0] + points[p, 1] * R[2, 1] + points[p, 2] * R[2, 2]
        height[p] += at[2]
    for q in range(panels):
        close = about[first[q] : first[q + 1]]
        c = close.shape[0]
        if c < 50:
            continue
        z = height[close]
        low = np.partition(z, c // 50)[c // 50]
        n = 0
        for a in range(c):
            if abs(z[a] - low) < 0.05:
                n += 1
        if n < 20:
            continue
        across = np.empty(n)
        b = 0
        for a in range(c):
            if abs(z[a] - low) < 0.05:
                p = close[a]
                x = points[p, 0] * R[0, 0] + points[p, 1] * R[0, 1] + points[p, 2] * R[0, 2]
                y = points[p, 0] * R[1, 0] + points[p, 1] * R[1, 1] + points[p, 2] * R[1, 2]
                across[b] = (x + at[0]) * wall[q, 0] + (y + at[1]) * wall[q, 1]
                b += 1
        lo, hi = n // 10, (9 * n) // 10 - 1
        a_lo, a_hi = np.partition(across, lo)[lo], np.partition(across, hi)[hi]
        if a_hi - a_lo <= 0.3:
            continue
        out_by = side[q] * ((a_hi if side[q] > 0.0 else a_lo) - wall[q, 2])
        if side[q] == 0.0 or out_by > reach[q]:
            out[q] = low
    return out


def _floor_lows(
    q: NDArray[np.float64], below: float, reach: float, cell: float
) -> tuple[NDArray[np.intp], int]:
    """``plan_view._floor_lows_reference`` compiled: of the levelled returns ``q`` (m, 3)
    lower than ``below`` and within ``reach`` in plan, the index of the lowest in each
    ``cell`` square column (the first of those as low), by column (x, then y); and how
    many returns were that low and near."""
    m = q.shape[0]
    kept = np.empty(m, dtype=np.intp)
    cx = np.empty(m, dtype=np.int64)
    cy = np.empty(m, dtype=np.int64)
    k = 0
    for i in range(m):
        if q[i, 2] < below and math.hypot(q[i, 0], q[i, 1]) < reach:
            kept[k] = i
            cx[k] = math.floor(q[i, 0] / cell)
            cy[k] = math.floor(q[i, 1] / cell)
            k += 1
    if k == 0:
        return np.empty(0, dtype=np.intp), 0
    x0, x1, y0, y1 = cx[0], cx[0], cy[0], cy[0]
    for j in range(k):
        x0, x1 = min(x0, cx[j]), max(x1, cx[j])
        y0, y1 = min(y0, cy[j]), max(y1, cy[j])
    ny = y1 - y0 + 1
    best = np.full((x1 - x0 + 1) * ny, -1, dtype=np.intp)
    for j in range(k):
        c = (cx[j] - x0) * ny + cy[j] - y0
        i = kept[j]
        if best[c] < 0 or q[i, 2] < q[best[c], 2]:
            best[c] = i
    out = np.empty(best.size, dtype=np.intp)
    n = 0
    for c in range(best.size):
        if best[c] >= 0:
            out[n] = best[c]
            n += 1
    return out[:n], k


def _plan_ranges(
    points: NDArray[np.float64],
    L: NDArray[np.float64],
    low: NDArray[np.float64],
    high: NDArray[np.float64],
    n: int,
    step: float,
    surface: float,
) -> NDArray[np.float64]:
    """The plan view's bearings and ranges (``plan_view.plan_scan``; its numpy reference
    ``plan_view._plan_ranges_reference``), as a (2, n) array: the ``points`` levelled by
    ``L`` between the heights ``low`` and ``high``, binned by bearing from -pi in ``n``
    bins of ``step``; per bin, the bearing and range of the centroid of the returns
    within ``surface`` of its nearest (the bin's centre and NaN for none)."""
    m = points.shape[0]
    bins = np.empty(m, dtype=np.intp)
    r = np.empty(m)
    xs = np.empty(m)
    ys = np.empty(m)
    nearest = np.full(n, np.inf)
    lowest, highest = low.min(), high.max()
    kept = 0
    for q in range(m):
        px, py, pz = points[q, 0], points[q, 1], points[q, 2]
        z = px * L[2, 0] + py * L[2, 1] + pz * L[2, 2]
        if not (z >= lowest and z <= highest):
            continue  # outside every bin's band: no bearing needed
        x = px * L[0, 0] + py * L[0, 1] + pz * L[0, 2]
        y = px * L[1, 0] + py * L[1, 1] + pz * L[1, 2]
        b = math.floor((math.atan2(y, x) + math.pi) / step) % n
        if not (z >= low[b] and z <= high[b]):
            continue
        bins[kept] = b
        xs[kept] = x
        ys[kept] = y
        r[kept] = math.hypot(x, y)
        if r[kept] < nearest[b]:
            nearest[b] = r[kept]
        kept += 1
    sx = np.zeros(n)
    sy = np.zeros(n)
    count = np.zeros(n)
    for q in range(kept):
        b = bins[q]
        if r[q] <= nearest[b] + surface:
            sx[b] += xs[q]
            sy[b] += ys[q]
            count[b] += 1.0
    out = np.empty((2, n))
    for b in range(n):
        edge = -math.pi + b * step
        out[0, b] = edge + 0.5 * step
        out[1, b] = np.nan
        if count[b] > 0:  # within its bin: the bearings strictly increase
            out[0, b] = min(max(math.atan2(sy[b], sx[b]), edge + 1e-9), edge + step - 1e-9)
            out[1, b] = math.hypot(sx[b], sy[b]) / count[b]
    return out


def _rays3d(
    rel: NDArray[np.float64],
    origin: NDArray[np.float64],
    i: NDArray[np.intp],
    k: NDArray[np.intp],
    normal: NDArray[np.float64],
    offset: NDArray[np.float64],
    start: NDArray[np.float64],
    along: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Where the ray from ``origin`` to each return ``origin + rel[i]`` crosses the plane
    of panel ``k`` (``normal``, ``offset``; from ``start`` along ``along``): how far
    along the ray (1 at the return), along the panel and at what elevation
    (``adjust3d.PanelPlanes._rays``; its numpy reference
    ``PanelPlanes._rays_reference``)."""
    panels = offset.shape[0]
    o0, o1, o2 = origin[0], origin[1], origin[2]
    plane = np.empty(panels)
    ahead = np.empty(panels)
    for q in range(panels):
        plane[q] = offset[q] - (normal[q, 0] * o0 + normal[q, 1] * o1)
        ahead[q] = (o0 - start[q, 0]) * along[q, 0] + (o1 - start[q, 1]) * along[q, 1]
    m = i.shape[0]
    s = np.empty(m)
    t = np.empty(m)
    z = np.empty(m)
    for j in range(m):
        q, r = k[j], i[j]
        rx, ry = rel[r, 0], rel[r, 1]
        s[j] = plane[q] / (rx * normal[q, 0] + ry * normal[q, 1])
        z[j] = o2 + s[j] * rel[r, 2]
        t[j] = ahead[q] + s[j] * (rx * along[q, 0] + ry * along[q, 1])
    return s, t, z


#: Compiled on first use (numba's own types; mypy sees plain callables).
#: ``error_model="numpy"``: no division-by-zero checks in the loop (every divisor is
#: positive), so that it vectorises.
partition_dp: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True, error_model="numpy")(
    _partition_dp
)
_partition_dp_jit = partition_dp
_piece_costs_jit: Callable[..., NDArray[np.float64]] = njit(
    cache=True, nogil=True, error_model="numpy"
)(_piece_costs)
_best_pointers_jit: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True)(_best_pointers)
penalty: Callable[[int], float] = njit(cache=True, nogil=True)(_penalty)
_penalty_jit = penalty
_run_moments_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_run_moments)
#: ``error_model="numpy"``: a quotient of underflowed values is inf or nan, as in the
#: numpy references (returns 1e-277 m apart: a product of two distances is 0).
rebreak: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True)(_rebreak)
_rebreak_jit = rebreak
run_breaks: Callable[..., Any] = njit(cache=True, nogil=True, error_model="numpy")(_run_breaks)
triple_deviations: Callable[..., NDArray[np.float64]] = njit(
    cache=True, nogil=True, error_model="numpy"
)(_triple_deviations)
linear_median: Callable[..., float] = njit(cache=True, nogil=True)(_linear_median)
_scatter_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_scatter)
_major_axis_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_major_axis)
_piece_sse_nu2_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_piece_sse_nu2)
_partition_run_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_partition_run)
segment_run: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True)(_segment_run)
line_fits: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_line_fits)
nearest_within: Callable[..., Any] = njit(cache=True, nogil=True)(_nearest_within)
_crossing_terms_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_crossing_terms)
_crossing_jit: Callable[..., float] = njit(cache=True, nogil=True)(_crossing)
_beam_windows_jit: Callable[..., int] = njit(cache=True, nogil=True)(_beam_windows)
_first_crossing_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_first_crossing)
_beams_toward_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_beams_toward)
_beacon_gathers_jit: Callable[..., bool] = njit(cache=True, nogil=True)(_beacon_gathers)
_lands_on_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_lands_on)
_beam_checks_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_beam_checks)
beam_checks_of: Callable[..., Any] = njit(cache=True, nogil=True)(_beam_checks_of)
_associate_into_jit: Callable[..., None] = njit(cache=True, nogil=True)(_associate_into)
associate: Callable[..., Any] = njit(cache=True, nogil=True)(_associate)
_associate_jit = associate
_to_mine_jit: Callable[..., None] = njit(cache=True, nogil=True)(_to_mine)
_normal_step_jit: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_normal_step)
_reach_windows_jit: Callable[..., int] = njit(cache=True, nogil=True)(_reach_windows)
_bearing_spans_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_bearing_spans)
_associate_by_bearing_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_associate_by_bearing)
_icp_stages_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_icp_stages)
_close_to_jit: Callable[..., None] = njit(cache=True, nogil=True)(_close_to)
within: Callable[..., Any] = njit(cache=True, nogil=True)(_within)
_within_jit = within
_pairs_by_bearing_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_pairs_by_bearing)
_associate_pairs_jit: Callable[..., None] = njit(cache=True, nogil=True)(_associate_pairs)
icp_refine: Callable[..., Any] = njit(cache=True, nogil=True)(_icp_refine)
in_place_chi: Callable[..., Any] = njit(cache=True, nogil=True)(_in_place_chi)
tallies: Callable[..., Any] = njit(cache=True, nogil=True)(_tallies)
first_at_least: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True)(_first_at_least)
_key_pair_walk_jit: Callable[..., int] = njit(cache=True, nogil=True)(_key_pair_walk)
key_pair_nodes: Callable[..., Any] = njit(cache=True, nogil=True)(_key_pair_nodes)
overrun_counts: Callable[..., NDArray[np.int64]] = njit(cache=True, nogil=True)(_overrun_counts)
straight_and_fitted_chi: Callable[..., Any] = njit(cache=True, nogil=True)(_straight_and_fitted_chi)
reach_tallies: Callable[..., Any] = njit(cache=True, nogil=True)(_reach_tallies)
beacons_in_reach: Callable[..., Any] = njit(cache=True, nogil=True)(_beacons_in_reach)
first_same: Callable[..., int] = njit(cache=True, nogil=True)(_first_same)
window_scores: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_window_scores)
first_hits: Callable[..., Any] = njit(cache=True, nogil=True)(_first_hits)
field_pyramid: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_field_pyramid)
_pose_score_jit: Callable[..., float] = njit(cache=True, nogil=True)(_pose_score)
_cells_score_jit: Callable[..., float] = njit(cache=True, nogil=True)(_cells_score)
_rectangle_max_jit: Callable[..., float] = njit(cache=True, nogil=True)(_rectangle_max)
_cells_bound_jit: Callable[..., float] = njit(cache=True, nogil=True)(_cells_bound)
_sliding_bound_jit: Callable[..., float] = njit(cache=True, nogil=True)(_sliding_bound)
field_sliding: Callable[..., Any] = njit(cache=True, nogil=True)(_field_sliding)
near_pose: Callable[..., bool] = njit(cache=True, nogil=True)(_near_pose)
_near_pose_jit = near_pose
_recount_jit: Callable[..., None] = njit(cache=True, nogil=True)(_recount)
_within_span_jit: Callable[..., Any] = njit(cache=True, nogil=True)(_within_span)
_suppress_jit: Callable[..., None] = njit(cache=True, nogil=True)(_suppress)
window_picks: Callable[..., Any] = njit(cache=True, nogil=True)(_window_picks)
_range_rows_jit: Callable[..., None] = njit(cache=True, nogil=True)(_range_rows)
_spread_jit: Callable[..., float] = njit(cache=True, nogil=True)(_spread)
range_rows = _range_rows_jit
_lu_solve_jit: Callable[..., bool] = njit(cache=True, nogil=True)(_lu_solve)
_normal_equations_jit: Callable[..., None] = njit(cache=True, nogil=True)(_normal_equations)
gauss_newton: Callable[..., Any] = njit(cache=True, nogil=True)(_gauss_newton)
ray_association: Callable[..., Any] = njit(cache=True, nogil=True)(_ray_association)
robust_gate: Callable[..., NDArray[np.bool_]] = njit(cache=True, nogil=True)(_robust_gate)
beacon_statistics: Callable[..., Any] = njit(cache=True, nogil=True)(_beacon_statistics)
information: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_information)
standardised: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_standardised)
group_residuals: Callable[..., Any] = njit(cache=True, nogil=True)(_group_residuals)
survey_shares: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_survey_shares)
_ray_association_jit = ray_association
_robust_gate_jit = robust_gate
_gauss_newton_jit = gauss_newton
adjust_rounds: Callable[..., Any] = njit(cache=True, nogil=True)(_adjust_rounds)
bound: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_bound)
_walk_left_jit: Callable[..., int] = njit(cache=True, nogil=True)(_walk_left)
_matches_met_jit: Callable[..., bool] = njit(cache=True, nogil=True)(_matches_met)
_walk_right_jit: Callable[..., int] = njit(cache=True, nogil=True)(_walk_right)
nearest_by_bearing: Callable[..., Any] = njit(cache=True, nogil=True)(_nearest_by_bearing)
_nearest_by_bearing_jit = nearest_by_bearing
odometry_fit: Callable[..., Any] = njit(cache=True, nogil=True)(_odometry_fit)
panel_rows3d: Callable[..., None] = njit(cache=True, nogil=True)(_panel_rows3d)
#: The 3D kernels divide by a ray's incidence on a panel's plane, zero where the ray runs
#: along it: ``error_model="numpy"`` gives numpy's infinities and NaNs there, as their
#: references do, rather than an exception.
top_edges3d: Callable[..., Any] = njit(cache=True, nogil=True, error_model="numpy")(_top_edges3d)
brackets3d: Callable[..., Any] = njit(cache=True, nogil=True, error_model="numpy")(_brackets3d)
_brackets3d_jit = brackets3d
_panel_rows3d_jit = panel_rows3d
rotation_derivatives: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(
    _rotation_derivatives
)
_rotation_derivatives_jit = rotation_derivatives
gauss_newton3d: Callable[..., int] = njit(cache=True, nogil=True, error_model="numpy")(
    _gauss_newton3d
)
assigns3d: Callable[..., NDArray[np.intp]] = njit(cache=True, nogil=True)(_assigns3d)
contiguous3d: Callable[..., NDArray[np.bool_]] = njit(cache=True, nogil=True)(_contiguous3d)
floors3d: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_floors3d)
plan_ranges: Callable[..., NDArray[np.float64]] = njit(cache=True, nogil=True)(_plan_ranges)
floor_lows: Callable[..., tuple[NDArray[np.intp], int]] = njit(cache=True, nogil=True)(_floor_lows)
rays3d: Callable[..., Any] = njit(cache=True, nogil=True, error_model="numpy")(_rays3d)
_rays3d_jit = rays3d
