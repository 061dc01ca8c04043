"""A beacon's whole design fitted to all its panel points at once.

The edges of a beacon found from its plan pieces' lines meeting two by two (the
corners of :mod:`mast.cloud.detect`) rest on whatever piece of each panel the
pieces kept: a short outer panel cut to a few centimetres gives a line whose
direction the noise decides, and the two inner edges, which share the middle
panel, come out as if independent. Here the whole beacon is fitted at once:

1. **Placement**: the design (its four edges, from the survey or the designs file)
   placed rigidly, ``(x, y, theta)``, by least squares on the distances across its
   three panels of every candidate point on their faces (:func:`place_design`).
   The points of a panel are those within a gate of its line, between its edges
   less a margin at each (the corners' and free ends' mixed returns), and within
   the panels' heights less a margin at the top and bottom
   (:func:`points_on_panel`); they are gathered again from each new placement,
   the gate narrowing from a first slack to three noise sigmas.
2. **Lines**: each panel's line fitted by total least squares to the points the
   placement gathers (:func:`panel_line`), with its 2 x 2 covariance from its own
   residuals; the lines are free, so the edges are the beacon as built: a survey's
   own errors in the design only move the gathering gate (3 noise sigmas and 3 mm
   about the placed shape), which cuts a panel's points on one side only where the
   shape is off by more than that.
3. **Edges**: e2 = L1 x L2 and e3 = L2 x L3; e1 and e4 at the design's lengths of
   P1 and P3 along their lines (:func:`edges_from_lines`). Their 8 x 8 covariance
   follows from the six line parameters' (:func:`edges_covariance`): e2 and e3
   share L2, and are correlated through it.

``georef`` fits the survey's own shape (:func:`fit_beacon`); ``survey-in``, which
measures beacons it does not know yet, gathers from its own pieces and uses steps
2 and 3 (:mod:`mast.cloud.survey_in`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.lines import fit_line

__all__ = [
    "BeaconFit",
    "edges_covariance",
    "edges_from_lines",
    "fit_beacon",
    "panel_line",
    "place_design",
    "points_on_panel",
]

#: Points this close to a panel's boundary are left out of its fit (mixed returns).
END_MARGIN_M = 0.02
#: The first gathering's gate: three noise sigmas and this (the start's own error).
FIRST_SLACK_M = 0.02
#: Later gatherings' gate: three noise sigmas and this (a bulge, the fit's own error).
SLACK_M = 0.003
#: Fewest points on the middle panel, and on each outer panel its line is fitted to.
MIN_POINTS = 30
#: Most placements gathered and fitted.
MAX_ROUNDS = 8
#: A placement has settled when it moves less than this (metres, and radians times a metre).
SETTLED_M = 1e-5
#: A placement is refused when an edge moves farther than this from the start (the
#: detection's corners are centimetres off at worst: farther, it slid onto rock).
MAX_MOVE_M = 0.15
#: ... and when the free lines' inner edges are farther than this from the placed shape's
#: (the points it gathered are not the beacon's panels).
MAX_DISAGREE_M = 0.05


@dataclass(frozen=True, eq=False)
class BeaconFit:
    """A beacon fitted in a cloud's plan.

    Attributes
    ----------
    edges : ndarray, shape (4, 2)
        e1..e4.
    covariance : ndarray, shape (8, 8)
        Their joint covariance, ``(x, y)`` of each edge in turn.
    points : tuple of int
        Points fitted on each panel.
    rms_m : float
        The points' RMS distance from their panels' lines.
    """

    edges: NDArray[np.float64]
    covariance: NDArray[np.float64]
    points: tuple[int, int, int]
    rms_m: float

    def edge_covariance(self, edges: tuple[int, ...]) -> NDArray[np.float64]:
        """The joint covariance of some edges (numbers 1-4), ``(x, y)`` of each in turn."""
        rows = np.array([[2 * (e - 1), 2 * (e - 1) + 1] for e in edges]).reshape(-1)
        return np.asarray(self.covariance[np.ix_(rows, rows)])


def points_on_panel(
    plan: NDArray[np.float64],
    z: NDArray[np.float64],
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    heights: tuple[float, float],
    gate_m: float,
    margin_m: float,
) -> NDArray[np.bool_]:
    """Which points (plan ``plan``, heights ``z``) lie on the face of the panel from
    ``a`` to ``b``: within ``gate_m`` of its line, more than ``margin_m`` inside its
    edges, and between its ``heights`` (bottom, top) less ``margin_m``."""
    length = math.dist(a, b)
    d = (b - a) / max(length, 1e-12)
    rel = plan - a
    t = rel @ d
    off = rel @ np.array([-d[1], d[0]])
    return np.asarray(
        (np.abs(off) <= gate_m)
        & (t > margin_m)
        & (t < length - margin_m)
        & (z > heights[0] + margin_m)
        & (z < heights[1] - margin_m)
    )


def _turn(theta: float) -> NDArray[np.float64]:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def place_design(
    xyz: NDArray[np.float64],
    shape: NDArray[np.float64],
    start: NDArray[np.float64],
    heights: tuple[float, float],
    noise_m: float,
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]] | None:
    """Place the design ``shape`` (its four edges, shape (4, 2), in any frame) at the
    points ``xyz`` (the cloud's points near the beacon, z up), starting from
    ``start`` (the four edges where a first estimate puts them). Returns the placed
    edges and each panel's points (plan) gathered from them; None when a panel is seen
    too little (fewer than :data:`MIN_POINTS` on the middle panel or on the outer two
    together) or the points do not determine the placement."""
    local = shape - shape.mean(axis=0)
    # the start as a placement: the rotation of the design's chord e1 -> e4 onto the
    # start's, the translation of their centroids
    u, v = local[3] - local[0], start[3] - start[0]
    theta = math.atan2(v[1], v[0]) - math.atan2(u[1], u[0])
    centre = start.mean(axis=0) - (_turn(theta) @ local.mean(axis=0))
    origin = centre.copy()  # coordinates about the beacon: 70 km offsets would swamp
    plan = xyz[:, :2] - origin
    z = xyz[:, 2]
    t = np.zeros(2)  # the placement's translation, about ``origin``
    gate = 3.0 * noise_m + FIRST_SLACK_M
    for round_ in range(MAX_ROUNDS):
        rot = _turn(theta)
        edges = local @ rot.T + t
        rows, res, got = [], [], []
        for j in range(3):
            a, b = edges[j], edges[j + 1]
            on = points_on_panel(plan, z, a, b, heights, gate, END_MARGIN_M)
            p = plan[on]
            d = (b - a) / max(math.dist(a, b), 1e-12)
            n = np.array([-d[1], d[0]])
            off = (p - a) @ n
            # d off / d (tx, ty) = -n; d off / d theta, with a = R s + t, n = R n0:
            # (J n) . (p - a) - n . (J R s), J the quarter turn
            jn = np.array([-n[1], n[0]])
            js = np.array([-(a - t)[1], (a - t)[0]])
            d_theta = (p - a) @ jn - float(n @ js)
            rows.append(np.column_stack([np.full(len(p), -n[0]), np.full(len(p), -n[1]), d_theta]))
            res.append(off)
            got.append(len(p))
        if got[1] < MIN_POINTS or got[0] + got[2] < MIN_POINTS:
            return None
        jac_rows = np.vstack(rows)
        resid = np.concatenate(res)
        normal = jac_rows.T @ jac_rows
        if not np.all(np.isfinite(normal)) or np.linalg.cond(normal) > 1e12:
            return None
        step = np.linalg.solve(normal, -(jac_rows.T @ resid))
        t = t + step[:2]
        theta += float(step[2])
        gate = 3.0 * noise_m + SLACK_M
        if round_ > 0 and max(abs(step[0]), abs(step[1]), abs(step[2])) < SETTLED_M:
            break
    rot = _turn(theta)
    edges = local @ rot.T + t
    start_rel = start - origin
    if float(np.max(np.hypot(*(edges - start_rel).T))) > MAX_MOVE_M:
        return None  # slid off to another surface: not the beacon the detection saw
    own = [
        plan[points_on_panel(plan, z, edges[j], edges[j + 1], heights, gate, END_MARGIN_M)] + origin
        for j in range(3)
    ]
    return edges + origin, own


def panel_line(
    points: NDArray[np.float64], noise_m: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """A panel's line as (angle of its normal, offset) about the plan's origin, their 2x2
    covariance from a total-least-squares fit (its own residuals, never below a tenth
    of the noise), and the fit's RMS. Give points about a point near the beacon: in
    grid coordinates (70 km from the origin) an angle's variance times the lever would
    swamp the offsets' in the propagation."""
    fit = fit_line(points)
    sigma = max(fit.rms, 0.1 * noise_m)
    n = fit.normal
    phi = math.atan2(n[1], n[0])
    rho = float(fit.centroid @ n)
    var_phi = sigma**2 / max(fit.t_spread, 1e-12)
    var_off = sigma**2 / len(points)
    # offset about the centroid is independent of the angle; about the origin it is not:
    # the normal (direction turned +90 deg) turns by -direction per radian, so the offset
    # at the origin moves by -(centroid . direction) per radian
    lever = -float(fit.centroid @ fit.direction)
    jac = np.array([[1.0, 0.0], [lever, 1.0]])  # d(phi, rho) / d(phi, offset at centroid)
    cov = jac @ np.diag([var_phi, var_off]) @ jac.T
    return np.array([phi, rho]), cov, float(fit.rms)


def edges_from_lines(
    lines: NDArray[np.float64], lengths: NDArray[np.float64], outward: NDArray[np.float64]
) -> NDArray[np.float64]:
    """e1..e4 (8,) from the three lines (phi, rho each): e2 = L1 x L2, e3 = L2 x L3; e1
    and e4 the design's P1 and P3 lengths along their lines, on the ``outward`` sides."""

    def meet(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        na = np.array([math.cos(a[0]), math.sin(a[0])])
        nb = np.array([math.cos(b[0]), math.sin(b[0])])
        return np.linalg.solve(np.array([na, nb]), np.array([a[1], b[1]]))

    def along(line: NDArray[np.float64], sign_ref: NDArray[np.float64]) -> NDArray[np.float64]:
        d = np.array([-math.sin(line[0]), math.cos(line[0])])
        return d if float(d @ sign_ref) >= 0 else -d

    e2 = meet(lines[0], lines[1])
    e3 = meet(lines[1], lines[2])
    e1 = e2 + lengths[0] * along(lines[0], outward[0])
    e4 = e3 + lengths[2] * along(lines[2], outward[1])
    return np.concatenate([e1, e2, e3, e4])


def edges_covariance(
    lines: NDArray[np.float64],
    covs: list[NDArray[np.float64]] | tuple[NDArray[np.float64], ...],
    lengths: NDArray[np.float64],
    outward: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The 8 x 8 covariance of :func:`edges_from_lines` from the three lines' own 2x2
    covariances (independent: each line has its own points), by a central-difference
    Jacobian."""
    cov_lines = np.zeros((6, 6))
    for k, c in enumerate(covs):
        cov_lines[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = c
    jac = np.zeros((8, 6))
    for j in range(6):
        step = 1e-7 if j % 2 == 0 else 1e-6
        up, down = lines.copy().reshape(-1), lines.copy().reshape(-1)
        up[j] += step
        down[j] -= step
        jac[:, j] = (
            edges_from_lines(up.reshape(3, 2), lengths, outward)
            - edges_from_lines(down.reshape(3, 2), lengths, outward)
        ) / (2 * step)
    return np.asarray(jac @ cov_lines @ jac.T)


def fit_beacon(
    xyz: NDArray[np.float64],
    shape: NDArray[np.float64],
    start: NDArray[np.float64],
    heights: tuple[float, float],
    noise_m: float,
) -> BeaconFit | None:
    """The beacon of design ``shape`` near ``start`` (see the module): placed, its three
    lines fitted to the points the placement gathers, its edges and their covariance.
    None when it cannot be placed or a panel has fewer than :data:`MIN_POINTS`."""
    placed = place_design(xyz, shape, start, heights, noise_m)
    if placed is None:
        return None
    edges, own = placed
    if min(len(p) for p in own) < MIN_POINTS:
        return None
    origin = edges.mean(axis=0)
    fitted = [panel_line(p - origin, noise_m) for p in own]
    lines = np.array([f[0] for f in fitted])
    lengths = np.hypot(*np.diff(shape, axis=0).T)
    rel = edges - origin
    outward = np.array([rel[0] - rel[1], rel[3] - rel[2]])
    if (
        abs(math.sin(lines[0, 0] - lines[1, 0])) < 1e-3
        or abs(math.sin(lines[1, 0] - lines[2, 0])) < 1e-3
    ):
        return None  # panels in line: no corner
    out = edges_from_lines(lines, lengths, outward).reshape(4, 2) + origin
    if float(np.max(np.hypot(*(out[1:3] - edges[1:3]).T))) > MAX_DISAGREE_M:
        return None  # the free lines do not meet where the shape is: not its panels
    cov = edges_covariance(lines, [f[1] for f in fitted], lengths, outward)
    sq = sum(f[2] ** 2 * len(p) for f, p in zip(fitted, own, strict=True))
    rms = math.sqrt(sq / sum(len(p) for p in own))
    return BeaconFit(out, cov, (len(own[0]), len(own[1]), len(own[2])), rms)
