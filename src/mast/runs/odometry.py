"""Scan-to-keyframe odometry: how the scanner moved between two scans, with its covariance.

The keyframe's returns, each with the normal of the wall around it (principal
component analysis over a window of about 0.3 m of consecutive returns, as
the locator's segmentation fits its lines), are the target; the current
scan's returns are fitted to them by point-to-plane ICP (Low 2004, the
linearisation the locator's alignment uses), associating each return with
its nearest keyframe return (a k-d tree). Fitting to the returns, not to long
straight segments, keeps the rock's roughness: that is what tells motion
along a drift.

The covariance is that of the linearised fit, ``s^2 (J^T J)^-1``, with
``s^2`` the residual variance (never below twice the range variance: both
scans are noisy) and inflated by the returns per independent piece of
evidence, as the locator tempers its beam likelihoods. Along a smooth,
straight drift the fit cannot see motion along the walls; the covariance
then says so (almost no information along the drift) instead of inventing a
step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.neighbours import PointGrid
from mast.core.scan import Scan

__all__ = ["Keyframe", "Motion", "OdometryConfig", "keyframe", "scan_to_scan"]


@dataclass(frozen=True, slots=True)
class OdometryConfig:
    """How scans are matched to a keyframe.

    Attributes
    ----------
    gates_m : tuple of float
        Association gates of the ICP stages, decreasing, metres.
    normal_span_m : float
        Length of wall over which a return's normal is fitted.
    max_planarity : float
        A return whose window is less straight than this (smallest over
        largest principal variance) has no normal and is not a target.
    min_matches : int
        Returns that must be matched for a motion to count.
    max_rms_m : float
        A fit whose residuals are larger than this did not find the walls again.
    tempering : float
        Returns per independent piece of evidence: the covariance of the fit
        is multiplied by it.
    min_sigma_m, min_sigma_rad : float
        Floors on the motion's standard deviations (time sync, vehicle
        vibration, the walls' unmodelled roughness).
    max_iterations : int
        Per gate.
    """

    gates_m: tuple[float, ...] = (0.3, 0.12, 0.06)
    normal_span_m: float = 0.3
    max_planarity: float = 0.1
    min_matches: int = 40
    max_rms_m: float = 0.05
    tempering: float = 2.0
    min_sigma_m: float = 0.002
    min_sigma_rad: float = math.radians(0.02)
    max_iterations: int = 30


@dataclass(frozen=True, slots=True)
class Keyframe:
    """A scan as a target for the next scans: its returns with their wall normals."""

    grid: PointGrid
    """The returns, binned for nearest-neighbour queries."""
    normals: NDArray[np.float64]

    @property
    def points(self) -> NDArray[np.float64]:
        return self.grid.points

    def __len__(self) -> int:
        return len(self.grid)


def keyframe(scan: Scan, config: OdometryConfig | None = None) -> Keyframe:
    """The scan's returns that lie on a locally straight wall, with the wall's normal."""
    cfg = config or OdometryConfig()
    _, pts = scan.points()
    n = pts.shape[0]
    if n < 3:
        return Keyframe(PointGrid.build(np.zeros((0, 2)), max(cfg.gates_m)), np.zeros((0, 2)))
    # Runs of consecutive returns without a jump; a window never crosses one.
    step = np.hypot(*np.diff(pts, axis=0).T)
    r = np.hypot(pts[:, 0], pts[:, 1])
    spacing = np.maximum(r[1:] * max(scan.angle_increment, 1e-4), 0.01)
    cut = step > 5 * spacing + 0.05
    run = np.concatenate([[0], np.cumsum(cut)])
    first = np.searchsorted(run, run, side="left")
    last = np.searchsorted(run, run, side="right") - 1
    half = np.clip(
        np.round(cfg.normal_span_m / 2 / (r * max(scan.angle_increment, 1e-4))), 2, 50
    ).astype(np.intp)
    idx = np.arange(n)
    lo = np.maximum(idx - half, first)
    hi = np.minimum(idx + half, last)
    # Window moments by cumulative sums (centred on the scan's mean for precision).
    c = pts - pts.mean(axis=0)
    cols = np.column_stack(
        [np.ones(n), c[:, 0], c[:, 1], c[:, 0] ** 2, c[:, 0] * c[:, 1], c[:, 1] ** 2]
    )
    cs = np.vstack([np.zeros(6), np.cumsum(cols, axis=0)])
    m = cs[hi + 1] - cs[lo]
    k = m[:, 0]
    mx, my = m[:, 1] / k, m[:, 2] / k
    sxx = m[:, 3] / k - mx**2
    sxy = m[:, 4] / k - mx * my
    syy = m[:, 5] / k - my**2
    # Principal direction angle; the normal is perpendicular to it.
    ang = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    tr = sxx + syy
    det = np.sqrt(np.maximum((sxx - syy) ** 2 / 4 + sxy**2, 0.0))
    lmax, lmin = tr / 2 + det, tr / 2 - det
    good = (k >= 5) & (lmin <= cfg.max_planarity * np.maximum(lmax, 1e-12))
    nrm = np.column_stack([-np.sin(ang), np.cos(ang)])
    return Keyframe(PointGrid.build(pts[good], max(cfg.gates_m)), nrm[good])


@dataclass(frozen=True, slots=True)
class Motion:
    """The pose of a scan in the frame of the scan before it.

    Attributes
    ----------
    dx, dy : float
        Translation in the previous scanner frame (x forward, y left), metres.
    dtheta : float
        Rotation counter-clockwise, radians.
    covariance : ndarray, shape (3, 3)
        Of (dx, dy, dtheta), in the previous scanner frame.
    matches : int
        Returns matched to the previous scan's lines.
    rms_m : float
        RMS point-to-line residual.
    """

    dx: float
    dy: float
    dtheta: float
    covariance: NDArray[np.float64]
    matches: int
    rms_m: float


def scan_to_scan(
    key: Keyframe,
    scan: Scan,
    *,
    guess: tuple[float, float, float] = (0.0, 0.0, 0.0),
    range_sigma_m: float,
    config: OdometryConfig | None = None,
) -> Motion | None:
    """How the scanner moved from the keyframe ``key`` to ``scan``.

    Parameters
    ----------
    key : Keyframe
        The keyframe's returns and normals (:func:`keyframe`).
    scan : Scan
    guess : (dx, dy, dtheta)
        Starting motion (a constant-velocity prediction).
    range_sigma_m : float
        A-priori range precision of either scan.

    Returns
    -------
    Motion, or None when the returns do not find the keyframe's walls (too
    few matches, or residuals too large).
    """
    cfg = config or OdometryConfig()
    _, pts = scan.points()
    if len(key) < cfg.min_matches or pts.shape[0] < cfg.min_matches:
        return None
    x = np.array(guess, dtype=float)
    ok = np.zeros(0, dtype=bool)
    for gate in cfg.gates_m:
        for _ in range(cfg.max_iterations):
            c, s_ = math.cos(x[2]), math.sin(x[2])
            m = pts @ np.array([[c, s_], [-s_, c]]) + x[:2]
            dist, j = key.grid.query(m, gate)
            ok = np.isfinite(dist)
            if np.count_nonzero(ok) < cfg.min_matches:
                return None
            nrm = key.normals[j[ok]]
            res = np.einsum("ij,ij->i", m[ok] - key.points[j[ok]], nrm)
            rel = m[ok] - x[:2]
            jac = np.column_stack([nrm, nrm[:, 1] * rel[:, 0] - nrm[:, 0] * rel[:, 1]])
            step, *_ = np.linalg.lstsq(jac, -res, rcond=None)
            x = x + step
            if math.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
                break
    c, s_ = math.cos(x[2]), math.sin(x[2])
    m = pts @ np.array([[c, s_], [-s_, c]]) + x[:2]
    dist, j = key.grid.query(m, cfg.gates_m[-1])
    ok = np.isfinite(dist)
    n = int(np.count_nonzero(ok))
    if n < cfg.min_matches:
        return None
    nrm = key.normals[j[ok]]
    res = np.einsum("ij,ij->i", m[ok] - key.points[j[ok]], nrm)
    rms = float(np.sqrt(np.mean(res**2)))
    if rms > cfg.max_rms_m:
        return None
    rel = m[ok] - x[:2]
    jac = np.column_stack([nrm, nrm[:, 1] * rel[:, 0] - nrm[:, 0] * rel[:, 1]])
    s2 = max(float(res @ res) / max(n - 3, 1), 2 * range_sigma_m**2)
    info = jac.T @ jac / (s2 * cfg.tempering)
    floor = np.diag([cfg.min_sigma_m**2, cfg.min_sigma_m**2, cfg.min_sigma_rad**2])
    # A direction the walls do not constrain gets (almost) no information: its variance
    # is large but finite, so that a pose graph can still be solved around it.
    w, v = np.linalg.eigh(info)
    w = np.maximum(w, 1e-6)
    cov = (v / w) @ v.T + floor
    dtheta = (float(x[2]) + math.pi) % (2 * math.pi) - math.pi
    return Motion(float(x[0]), float(x[1]), dtheta, (cov + cov.T) / 2, n, rms)
