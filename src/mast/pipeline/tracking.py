"""Tracking with a prior: find the pose near a prior without identifying panels.

With a prior pose (the previous scan's fix, or ``--near``), identification is
not needed: every surveyed panel is where the prior says, to within the
prior's radius and azimuth tolerance. The window is searched exhaustively on
a grid (a correlative scan match against a likelihood field of the surveyed
panels), and the best poses are handed on as hypotheses to be refined by ICP
and verified like any other. A wrong prior finds no pose that the beams
confirm and gives no fix, never one that follows the prior.

References
----------
E. Olson, "Real-time correlative scan matching", ICRA 2009.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D
from mast.pipeline.alignment import Similarity
from mast.pipeline.hypotheses import Hypothesis

__all__ = ["Prior", "TrackingConfig", "prior_hypotheses"]


@dataclass(frozen=True, slots=True)
class Prior:
    """Where the scanner is believed to be.

    Attributes
    ----------
    pose : Pose2D
    radius_m : float
        The true position lies within this distance of ``pose``.
    azimuth_tolerance_rad : float or None
        The true azimuth lies within this of ``pose.azimuth``; None: unknown.
    """

    pose: Pose2D
    radius_m: float
    azimuth_tolerance_rad: float | None = None

    def admits(self, pose: Pose2D, margin_m: float = 0.0, margin_rad: float = 0.0) -> bool:
        """Whether ``pose`` lies inside the prior's window, widened by the margins.

        The margins are the estimate's own uncertainty: a true pose on the
        window's rim is estimated a few millimetres either side of it.
        """
        d = math.hypot(pose.easting - self.pose.easting, pose.northing - self.pose.northing)
        if d > self.radius_m + margin_m:
            return False
        if self.azimuth_tolerance_rad is None:
            return True
        da = abs(math.remainder(pose.azimuth - self.pose.azimuth, 2 * math.pi))
        return da <= self.azimuth_tolerance_rad + margin_rad


@dataclass(frozen=True, slots=True)
class TrackingConfig:
    """The grid search of a prior's window.

    Attributes
    ----------
    max_radius_m : float
        Widest position window searched on a grid; wider priors go through
        identification instead.
    max_azimuth_tolerance_rad : float
        Widest azimuth window searched on a grid.
    step_m : float
        Grid step in position, and the largest step a return may move per
        azimuth step.
    field_resolution_m : float
        Cell size of the panels' likelihood field.
    max_points : int
        Returns used in the search at most (evenly thinned beyond).
    candidates : int
        Distinct best poses handed on as hypotheses.
    distinct_m : float
        Two grid poses are distinct hypotheses when one moves the returns by
        at least this much from the other (translation, or rotation times the
        returns' median range): closer ones fall in the same ICP basin.
    """

    max_radius_m: float = 2.0
    max_azimuth_tolerance_rad: float = math.radians(15.0)
    step_m: float = 0.04
    field_resolution_m: float = 0.02
    max_points: int = 600
    candidates: int = 6
    distinct_m: float = 0.1


def _likelihood_field(
    panels: PanelSet,
    subset: NDArray[np.intp],
    lo: NDArray[np.float64],
    shape: tuple[int, int],
    res: float,
    sigma: float,
) -> NDArray[np.float64]:
    """``exp(-d^2 / 2 sigma^2)`` of the distance to the nearest surveyed panel, on a grid."""
    occ = np.ones(shape, dtype=bool)
    for k in subset:
        n = max(2, math.ceil(panels.length[k] / (0.5 * res)) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        p = panels.a[k] + s * (panels.b[k] - panels.a[k])
        ij = np.floor((p - lo) / res).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[1])
        occ[ij[ok, 0], ij[ok, 1]] = False
    dist = ndimage.distance_transform_edt(occ) * res
    return np.asarray(np.exp(-0.5 * (dist / sigma) ** 2))


def prior_hypotheses(
    points_scanner: NDArray[np.float64],
    panels: PanelSet,
    prior: Prior,
    range_max_m: float,
    config: TrackingConfig = TrackingConfig(),
) -> list[Hypothesis]:
    """The best poses in the prior's window by a grid search, as hypotheses.

    Every candidate pose is scored by the likelihood field of the surveyed
    panels at the returns; rotations step so that no return moves more than
    ``step_m``, translations step by ``step_m``. Returns an empty list when
    the window is too wide to search this way or no panel is in reach.
    """
    tol = prior.azimuth_tolerance_rad
    if (
        prior.radius_m > config.max_radius_m
        or tol is None
        or tol > config.max_azimuth_tolerance_rad
    ):
        return []
    near = panels.near(prior.pose.position, range_max_m + prior.radius_m)
    if near.size == 0 or points_scanner.shape[0] == 0:
        return []
    pts = points_scanner
    r = np.hypot(pts[:, 0], pts[:, 1])
    # Returns that, anywhere in the window, could lie on a panel.
    at_prior = prior.pose.scanner_to_mine(pts)
    slack = prior.radius_m + r * math.sin(tol) + 0.1
    _, dist = panels.associate(at_prior, np.inf, subset=near)
    mid = 0.5 * (panels.a[near] + panels.b[near])
    d_mid = np.min(
        np.hypot(at_prior[:, None, 0] - mid[None, :, 0], at_prior[:, None, 1] - mid[None, :, 1])
        - 0.5 * panels.length[near][None, :],
        axis=1,
    )
    cand = np.minimum(np.abs(dist), d_mid) <= slack
    pts, r = pts[cand], r[cand]
    if pts.shape[0] < 6:
        return []
    if pts.shape[0] > config.max_points:
        keep = np.linspace(0, pts.shape[0] - 1, config.max_points).round().astype(int)
        pts, r = pts[keep], r[keep]
    step = config.step_m
    res = config.field_resolution_m
    span = np.concatenate([panels.a[near], panels.b[near]])
    lo = span.min(axis=0) - 0.5
    hi = span.max(axis=0) + 0.5
    shape = (int((hi[0] - lo[0]) / res) + 1, int((hi[1] - lo[1]) / res) + 1)
    field = _likelihood_field(panels, near, lo, shape, res, sigma=step)
    n_t = math.ceil(prior.radius_m / step)
    offs = np.arange(-n_t, n_t + 1) * step
    tx, ty = np.meshgrid(offs, offs, indexing="ij")
    inside = np.hypot(tx, ty) <= prior.radius_m + 1e-9
    tx, ty = tx[inside], ty[inside]
    d_rot = step / max(float(r.max()), step)
    n_r = math.ceil(tol / d_rot)
    rot0 = math.pi / 2 - prior.pose.azimuth
    best: list[tuple[float, float, float, float]] = []
    for k in range(-n_r, n_r + 1):
        rot = rot0 + k * d_rot
        c, s = math.cos(rot), math.sin(rot)
        m = pts @ np.array([[c, s], [-s, c]]) + prior.pose.position
        ij = (m - lo) / res
        gi = np.floor(ij[:, 0][None, :] + tx[:, None] / res).astype(int)
        gj = np.floor(ij[:, 1][None, :] + ty[:, None] / res).astype(int)
        ok = (gi >= 0) & (gi < shape[0]) & (gj >= 0) & (gj < shape[1])
        score = np.where(ok, field[np.clip(gi, 0, shape[0] - 1), np.clip(gj, 0, shape[1] - 1)], 0.0)
        total = score.sum(axis=1)
        for t in np.argsort(total)[-4 * config.candidates :]:
            best.append((float(total[t]), rot, float(tx[t]), float(ty[t])))
    best.sort(reverse=True)
    out: list[Hypothesis] = []
    chosen: list[tuple[float, float, float]] = []
    reach = float(np.median(r))
    for total_score, rot, x, y in best:
        if any(
            math.hypot(x - cx, y - cy) < config.distinct_m
            and abs(rot - cr) * reach < config.distinct_m
            for cr, cx, cy in chosen
        ):
            continue
        chosen.append((rot, x, y))
        t = prior.pose.position + np.array([x, y])
        sim = Similarity(1.0, math.remainder(rot, 2 * math.pi), t, 0.0)
        out.append(Hypothesis((), sim, -total_score, "prior"))
        if len(out) == config.candidates:
            break
    return out
