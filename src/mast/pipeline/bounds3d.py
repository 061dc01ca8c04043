"""The Cramér–Rao bound of a 3D frame's six-parameter pose, and what stands for it in
the elevation.

**Panel points** (easting, northing, roll, pitch, azimuth). A return on panel ``k``,
at ``p`` in the sensor frame, lies on the panel's vertical plane ``n_k · X = d_k``:
``n_k · (R p + t) - d_k = 0`` (the measurement model of :mod:`mast.pipeline.adjust3d`).
Its range noise ``sigma_r`` along its ray moves it across the plane by
``sigma_r |cos i|``, ``cos i = n_k · (R u)`` the cosine of the ray's incidence on the
panel (``u`` the ray's direction). With known panels and correspondences and
independent Gaussian ranges, the Fisher information is ``sum g g^T / (sigma_r cos i)^2``,
``g`` the residual's derivatives by the pose. That is the range's own information:
``d rho / d theta = -g / cos i``. Returns within 2° of grazing a panel are left out,
as by the adjustment (:data:`mast.pipeline.adjust3d.GRAZING_DEG`): a flat plane's grazing
ray would claim an information no real panel edge gives. The panels are vertical, so
the points carry nothing on the elevation.

**The survey's share.** A surveyed edge's error moves a whole panel: one offset per
panel, shared by every return on it. It is added to the bound as
:func:`mast.pipeline.adjust3d.adjust_pose` propagates it into the covariance
(``sigma_s^2 sum_k g_k g_k^T``, ``g_k`` the solution's sensitivity to panel ``k``'s
offset), so that the bound and the fix's covariance are the same kind of figure.

**The elevation is not a regular estimation problem.** It comes from the panels' top
edges: a ray that hit panel ``k`` crossed its plane below the top, one that went over
crossed above, so ``Z`` lies between ``top_k`` less the lowest crossing over it and
``top_k`` less the highest hit (heights relative to the sensor, where the rays cross
the panel's plane). The likelihood is flat inside that bracket and zero outside it; its
support moves with ``Z``, so no Fisher information exists and no Cramér–Rao bound
applies. What stands for it here is a reference, evaluated at the truth with the rays
of the frame: per beacon, the intersection of its panels' tightest brackets (its panels
are crossed by the same rings: one piece of evidence), one observation of ``Z`` at its
middle with the variance of a uniform over it and the survey's (``width^2 / 12 +
sigma_s^2``); different beacons, crossed by other rings at other ranges, independent.
Its derivatives by the other five are those of the two crossing heights that set its
ends (a ray's crossing moves with the sensor and turns with it), so a tilt's
uncertainty widens it. It is the bracket method's best, not a floor under every
estimator: one can beat a bracket's uniform variance. Without a bracket the
elevation's entry is ``inf`` (unobserved) and the other five are bounded alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.frames import yaw_of_azimuth
from mast.core.pose3d import Pose3D, rotation_rpy
from mast.pipeline.adjust3d import GRAZING_COS, PanelPlanes
from mast.pipeline.bounds import inverse_bound

__all__ = [
    "Bound3D",
    "Bracket",
    "cramer_rao_bound3d",
    "crossing_height_gradient",
    "information3d",
    "panel_rows",
    "top_brackets",
]

#: Indices of :data:`mast.pipeline.adjust3d.PARAMETERS`.
E, N, Z, ROLL, PITCH, AZIMUTH = range(6)
#: The five parameters the panel points observe.
FIVE = [E, N, ROLL, PITCH, AZIMUTH]


@dataclass(frozen=True, slots=True)
class Bracket:
    """Beacon ``beacon``'s top edges bracketing the sensor's elevation at a pose:
    ``low_m <= Z <= high_m``. The upper end is set by return ``hit``, the highest hit on
    panel ``hit_panel`` (relative to its top), the lower by return ``over``, whose ray
    crossed panel ``over_panel``'s plane lowest above its top."""

    beacon: str
    hit: int
    hit_panel: int
    over: int
    over_panel: int
    low_m: float
    high_m: float

    @property
    def width_m(self) -> float:
        return self.high_m - self.low_m


@dataclass(frozen=True, slots=True)
class Bound3D:
    """The six-parameter bound at a pose (see the module).

    ``covariance`` is 6×6 in :data:`mast.pipeline.adjust3d.PARAMETERS` order (metres
    and radians), ``inf`` on the diagonal where a parameter is not determined; its
    elevation entry is the bracket's reference, not a Cramér–Rao bound. ``information``
    holds the panel points' Fisher information and the brackets' pseudo-observations.
    ``returns`` the panel returns that count; ``brackets`` the top edges."""

    covariance: NDArray[np.float64]
    information: NDArray[np.float64]
    returns: int
    brackets: tuple[Bracket, ...]

    @property
    def sigma(self) -> NDArray[np.float64]:
        return np.sqrt(np.diag(self.covariance))

    @property
    def elevation_observed(self) -> bool:
        return bool(self.brackets) and math.isfinite(float(self.covariance[Z, Z]))


def _generators() -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    Kx = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    Ky = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    Kz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    return Kx, Ky, Kz


def _rotation_derivatives(pose: Pose3D) -> tuple[NDArray[np.float64], ...]:
    """``R`` and its derivatives by roll, pitch and azimuth (``yaw = 90° - azimuth``)."""
    Kx, Ky, Kz = _generators()
    Rz = rotation_rpy(0.0, 0.0, yaw_of_azimuth(pose.azimuth))
    Ry = rotation_rpy(0.0, pose.pitch, 0.0)
    Rx = rotation_rpy(pose.roll, 0.0, 0.0)
    R = Rz @ Ry @ Rx
    return R, Rz @ Ry @ Rx @ Kx, Rz @ Ry @ Ky @ Rx, -(Kz @ R)


def panel_rows(
    pose: Pose3D,
    points: NDArray[np.float64],
    panel: NDArray[np.intp],
    planes: PanelPlanes,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """For returns ``points`` (m, 3, sensor frame) on panels ``panel`` (m,) (indices into
    ``planes``): the residuals ``n · (R p + t) - d``, their derivatives (m, 6) by the
    parameters in :data:`~mast.pipeline.adjust3d.PARAMETERS` order (the elevation's
    column zero), and each ray's ``cos i = n · (R u)``."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    k = np.asarray(panel, dtype=np.intp)
    n_k, d_k = planes.normal[k], planes.offset[k]
    R, dR_roll, dR_pitch, dR_az = _rotation_derivatives(pose)

    def across(M: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(np.einsum("ij,ij->i", n_k, (p @ M.T)[:, :2]))

    t = np.array([pose.easting, pose.northing])
    v = across(R) + n_k @ t - d_k
    J = np.zeros((len(p), 6))
    J[:, E], J[:, N] = n_k[:, 0], n_k[:, 1]
    J[:, ROLL], J[:, PITCH], J[:, AZIMUTH] = across(dR_roll), across(dR_pitch), across(dR_az)
    ray = p / np.linalg.norm(p, axis=1)[:, None]
    cos_inc = np.einsum("ij,ij->i", n_k, (ray @ R.T)[:, :2])
    return v, J, cos_inc


def top_brackets(
    pose: Pose3D,
    points: NDArray[np.float64],
    panel: NDArray[np.intp],
    planes: PanelPlanes,
    *,
    inset_m: float = 0.02,
) -> tuple[Bracket, ...]:
    """Each beacon's top edges as the frame's rays bracket the elevation at ``pose`` (see
    the module): ``points`` every return of the frame (n, 3, sensor frame, noise-free
    for a bound) and ``panel`` (n,) the panel each hit (index into ``planes``, -1 for
    anything else). A ray goes over panel ``k`` when it crosses its plane before its
    return, above the top, inside the panel's plan extent (``inset_m`` in from its
    edges, as the adjustment takes it). A panel without a surveyed top, a hit or a ray
    over it brackets nothing; a beacon brackets by what its panels do."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    which = np.asarray(panel, dtype=np.intp)
    rel = p @ pose.rotation.T
    origin = pose.position
    ends: dict[str, list[tuple[float, int, int, float, int, int]]] = {}
    for k in range(len(planes)):
        on = np.flatnonzero(which == k)
        if on.size == 0 or not math.isfinite(float(planes.top[k])):
            continue
        s, t, z = planes.crossing(k, origin, rel)
        over = (which != k) & (s > 0) & (s < 1) & (t > inset_m)
        over &= (t < planes.length[k] - inset_m) & (z > planes.top[k])
        if not over.any():
            continue
        cand = np.flatnonzero(over)
        b = int(cand[np.argmin(z[cand])])
        a = int(on[np.argmax(z[on])])
        top = float(planes.top[k])
        # Z + height of the crossing = its elevation: Z in [top - h_over, top - h_hit]
        low, high = top - float(z[b] - origin[2]), top - float(z[a] - origin[2])
        ends.setdefault(planes.beacon[k], []).append((low, b, k, high, a, k))
    out = []
    for beacon, found in ends.items():
        low, b, kb, _, _, _ = max(found, key=lambda e: e[0])
        _, _, _, high, a, ka = min(found, key=lambda e: e[3])
        out.append(Bracket(beacon, a, ka, b, kb, low, high))
    return tuple(out)


def crossing_height_gradient(
    pose: Pose3D, point: NDArray[np.float64], normal: NDArray[np.float64], offset: float
) -> NDArray[np.float64]:
    """How the height above the sensor at which the ray through ``point`` (sensor frame)
    crosses the vertical plane ``normal · X = offset`` changes with the pose, in
    :data:`~mast.pipeline.adjust3d.PARAMETERS` order: ``h = s (R p)_z``, ``s`` the
    plane's distance along the ray over the return's, so moving the sensor slides the
    crossing along the ray and turning it turns the ray."""
    R, dR_roll, dR_pitch, dR_az = _rotation_derivatives(pose)
    rel = R @ point
    across = float(rel[:2] @ normal)
    s = (offset - float(normal @ np.array([pose.easting, pose.northing]))) / across
    g = np.zeros(6)
    g[[E, N]] = -rel[2] * normal / across
    for j, dR in ((ROLL, dR_roll), (PITCH, dR_pitch), (AZIMUTH, dR_az)):
        turn = dR @ point
        g[j] = s * turn[2] - s * rel[2] * float(turn[:2] @ normal) / across
    return g


def _top_rows(
    pose: Pose3D,
    points: NDArray[np.float64],
    brackets: tuple[Bracket, ...],
    planes: PanelPlanes,
    survey_sigma_m: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The brackets' pseudo-observations of the elevation, ``Z - middle``: rows (b, 6) and
    weights (b,)."""
    rows = np.zeros((len(brackets), 6))
    weights = np.zeros(len(brackets))
    for i, br in enumerate(brackets):
        for ray, k in ((br.hit, br.hit_panel), (br.over, br.over_panel)):
            rows[i] += 0.5 * crossing_height_gradient(
                pose, points[ray], planes.normal[k], float(planes.offset[k])
            )
        rows[i, Z] = 1.0
        weights[i] = 1.0 / (max(br.width_m, 1e-6) ** 2 / 12.0 + survey_sigma_m**2)
    return rows, weights


def _usable(cos_inc: NDArray[np.float64]) -> NDArray[np.bool_]:
    return np.asarray(np.abs(cos_inc) > GRAZING_COS)


def information3d(
    pose: Pose3D,
    points: NDArray[np.float64],
    panel: NDArray[np.intp],
    planes: PanelPlanes,
    *,
    range_sigma_m: float,
    survey_sigma_m: float = 0.0,
    brackets: tuple[Bracket, ...] = (),
) -> NDArray[np.float64]:
    """The 6×6 information (:data:`~mast.pipeline.adjust3d.PARAMETERS` order) of the
    returns ``points`` (m, 3) on panels ``panel`` (m,) at ``pose`` (those within ``GRAZING_DEG`` of
    grazing left out), plus the ``brackets``' pseudo-observations (which need
    ``points`` to be the whole frame they were found in, ``panel`` -1 off the panels)."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    which = np.asarray(panel, dtype=np.intp)
    on = which >= 0
    _, J, cos_inc = panel_rows(pose, p[on], which[on], planes)
    keep = _usable(cos_inc)
    J, w = J[keep], 1.0 / (range_sigma_m * cos_inc[keep]) ** 2
    info: NDArray[np.float64] = J.T @ (w[:, None] * J)
    if brackets:
        rows, wt = _top_rows(pose, p, brackets, planes, survey_sigma_m)
        info = info + rows.T @ (wt[:, None] * rows)
    return info


def cramer_rao_bound3d(
    pose: Pose3D,
    points: NDArray[np.float64],
    panel: NDArray[np.intp],
    planes: PanelPlanes,
    *,
    range_sigma_m: float,
    survey_sigma_m: float = 0.0,
    top_edges: bool = True,
) -> Bound3D:
    """The six-parameter bound (see the module) of a frame taken at ``pose``: ``points``
    (n, 3) every return in the sensor frame (noise-free: the truth's ranges along the
    rays), ``panel`` (n,) the panel each return is on (index into ``planes``; -1 for
    anything else, so that the rays over a panel's top are found among them). Without
    ``top_edges`` no bracket enters: the panel points' own Cramér–Rao bound of the five
    they observe, the elevation unobserved (a bracket's uniform variance is no Fisher
    information, and at the truth a beacon's tightest bracket may be a millimetre wide
    by luck, which would pin the tilt its derivatives reach)."""
    if range_sigma_m <= 0:
        raise ValueError("a bound needs a range sigma above zero")
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    which = np.asarray(panel, dtype=np.intp)
    brackets = top_brackets(pose, p, which, planes) if top_edges else ()
    info = information3d(
        pose, p, which, planes, range_sigma_m=range_sigma_m, survey_sigma_m=survey_sigma_m,
        brackets=brackets,
    )  # fmt: skip
    on = which >= 0
    _, J, cos_inc = panel_rows(pose, p[on], which[on], planes)
    keep = _usable(cos_inc)
    returns = int(keep.sum())
    # without a bracket the elevation is unobserved: the other five bounded alone
    idx = list(range(6)) if brackets else FIVE
    sub = inverse_bound(info[np.ix_(idx, idx)])
    if survey_sigma_m > 0 and np.all(np.isfinite(np.diag(sub))):
        # one offset per panel, shared by its returns, as the adjustment propagates it
        w = 1.0 / (range_sigma_m * cos_inc[keep]) ** 2
        G = sub @ (J[keep][:, idx].T * w)  # the solution's sensitivity to each residual
        k_used = which[on][keep]
        for k in np.unique(k_used):
            g = G[:, k_used == k].sum(axis=1)
            sub = sub + survey_sigma_m**2 * np.outer(g, g)
    cov = np.diag([math.inf] * 6)
    cov[np.ix_(idx, idx)] = sub
    return Bound3D(np.asarray(cov, dtype=np.float64), info, returns, brackets)
