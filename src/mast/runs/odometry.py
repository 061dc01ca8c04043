"""Scan-to-scan odometry: how the scanner moved between two scans, with its covariance.

The previous scan is cut into straight pieces by the locator's own PCA
segmentation (stage 1), and the current scan's returns are fitted to those
lines by the same point-to-line ICP that aligns a scan with the surveyed
panels (stage 4, Low 2004): a drift's rock walls are the "panels". The
covariance is that of the linearised fit, ``s^2 (J^T J)^-1``, with ``s^2``
the residual variance (never below the range variance) and inflated by the
number of beams per independent piece of evidence, as the locator tempers
its beam likelihoods: returns of one wall share its roughness, so they are
not independent. Along a smooth, straight drift the fit cannot see motion
along the walls; the covariance then says so (its information along the
drift is near zero) instead of inventing a step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.pipeline.alignment import icp_point_to_line
from mast.pipeline.segmentation import Segmentation, SegmentationConfig, segment_scan

__all__ = ["Motion", "OdometryConfig", "lines_of", "scan_lines", "scan_to_scan"]


@dataclass(frozen=True, slots=True)
class OdometryConfig:
    """How scans are matched to each other.

    Attributes
    ----------
    gates_m : tuple of float
        Association gates of the ICP stages, decreasing, metres.
    min_line_m : float
        Shortest straight piece of the previous scan used as a line.
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
    """

    gates_m: tuple[float, ...] = (0.5, 0.15, 0.06)
    min_line_m: float = 0.3
    min_matches: int = 40
    max_rms_m: float = 0.05
    tempering: float = 2.0
    min_sigma_m: float = 0.002
    min_sigma_rad: float = math.radians(0.02)


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


def lines_of(seg: Segmentation, min_line_m: float = 0.3) -> PanelSet:
    """The straight pieces of a segmented scan as lines to match the next scan to."""
    keep = [s for s in seg.segments if s.length >= min_line_m]
    if not keep:
        empty = np.zeros((0, 2))
        none = np.zeros(0, dtype=np.intp)
        return PanelSet(empty, empty, empty, empty, np.zeros(0), none, none, ())
    a = np.array([s.start for s in keep], dtype=float)
    b = np.array([s.end for s in keep], dtype=float)
    v = b - a
    length = np.hypot(v[:, 0], v[:, 1])
    d = v / length[:, None]
    nrm = np.stack([-d[:, 1], d[:, 0]], axis=1)
    idx = np.arange(len(keep), dtype=np.intp)
    return PanelSet(a, b, d, nrm, length, idx, np.ones(len(keep), dtype=np.intp), ("scan",))


def scan_lines(
    scan: Scan, *, config: SegmentationConfig | None = None, min_line_m: float = 0.3
) -> PanelSet:
    """The straight pieces of a scan (the locator's segmentation) as lines, scanner frame."""
    return lines_of(segment_scan(scan, config or SegmentationConfig()), min_line_m)


def _as_pose(dx: float, dy: float, dtheta: float) -> Pose2D:
    # The previous scanner frame plays the mine frame: x as "easting", y as "northing";
    # a counter-clockwise rotation dtheta is the azimuth pi/2 - dtheta.
    return Pose2D(dx, dy, (math.pi / 2 - dtheta) % (2 * math.pi))


def scan_to_scan(
    previous: PanelSet,
    scan: Scan,
    *,
    guess: tuple[float, float, float] = (0.0, 0.0, 0.0),
    range_sigma_m: float,
    config: OdometryConfig | None = None,
) -> Motion | None:
    """How the scanner moved from the scan whose lines are ``previous`` to ``scan``.

    Parameters
    ----------
    previous : PanelSet
        The previous scan's lines (:func:`scan_lines`).
    scan : Scan
    guess : (dx, dy, dtheta)
        Starting motion (a constant-velocity prediction).
    range_sigma_m : float
        A-priori range precision: the floor of the residual variance.

    Returns
    -------
    Motion, or None when the returns do not find the previous scan's walls
    (too few matches, or residuals too large).
    """
    cfg = config or OdometryConfig()
    if len(previous) == 0:
        return None
    _, pts = scan.points()
    if pts.shape[0] < cfg.min_matches:
        return None
    icp = icp_point_to_line(pts, _as_pose(*guess), previous, gates_m=cfg.gates_m)
    ok = icp.panel >= 0
    n = int(np.count_nonzero(ok))
    if n < cfg.min_matches or icp.rms_m > cfg.max_rms_m:
        return None
    p = icp.pose
    m = p.scanner_to_mine(pts[ok])
    nrm = previous.normal[icp.panel[ok]]
    rel = m - p.position
    jw = nrm[:, 1] * rel[:, 0] - nrm[:, 0] * rel[:, 1]
    jac = np.column_stack([nrm, jw])
    resid = icp.residual_m[ok]
    s2 = max(float(resid @ resid) / max(n - 3, 1), range_sigma_m**2)
    info = jac.T @ jac / (s2 * cfg.tempering)
    floor = np.diag([cfg.min_sigma_m**2, cfg.min_sigma_m**2, cfg.min_sigma_rad**2])
    # A direction the walls do not constrain gets (almost) no information: its variance
    # is large but finite, so that a pose graph can still be solved around it.
    w, v = np.linalg.eigh(info)
    w = np.maximum(w, 1e-6)
    cov = (v / w) @ v.T + floor
    dtheta = math.pi / 2 - p.azimuth
    dtheta = (dtheta + math.pi) % (2 * math.pi) - math.pi
    return Motion(p.easting, p.northing, dtheta, (cov + cov.T) / 2, n, icp.rms_m)
