"""Stage 4: align the scan to the mine frame.

First a four-parameter (similarity) transformation from matched points, as in
the paper (after Wolf and Ghilani); then point-to-line ICP of the panel
returns against the surveyed panel lines, linearised for a small rotation as
in Low (2004).

References
----------
K.-L. Low, "Linear least-squares optimization for point-to-plane ICP surface
registration", Technical Report TR04-004, UNC Chapel Hill, 2004.
P. R. Wolf and C. D. Ghilani, *Adjustment Computations*, 1997, ch. 18.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.frames import azimuth_of_yaw, yaw_of_azimuth
from mast.core.geometry import PanelSet
from mast.core.linalg import pose_step
from mast.core.pose import Pose2D

__all__ = ["IcpResult", "Similarity", "icp_point_to_line", "similarity_transform"]


@dataclass(frozen=True, slots=True)
class Similarity:
    """``mine = scale * R(rotation) @ scanner + translation``.

    Attributes
    ----------
    scale : float
        Uniform scale (1 for a perfect rigid match; a diagnostic here).
    rotation_rad : float
        Counter-clockwise rotation from the scanner frame to the mine frame.
    translation : ndarray, shape (2,)
        Image of the scanner origin.
    rms_m : float
        RMS of the point residuals.
    """

    scale: float
    rotation_rad: float
    translation: NDArray[np.float64]
    rms_m: float

    def pose(self) -> Pose2D:
        """The scanner pose it implies (the rotation is ``pi/2 - azimuth``)."""
        return Pose2D(
            float(self.translation[0]),
            float(self.translation[1]),
            azimuth_of_yaw(self.rotation_rad),
        )


def similarity_transform(
    points_scanner: NDArray[np.float64], points_mine: NDArray[np.float64]
) -> Similarity:
    """Least-squares four-parameter transformation from two or more point pairs.

    Each pair gives the rows ``[x -y 1 0; y x 0 1]`` of the design matrix for
    the unknowns ``(a, b, tx, ty)`` with ``a = s cos(alpha)``, ``b = s sin(alpha)``
    (the paper's eq. for ``N = u R P + t``). Coordinates are centred first so
    large mine coordinates do not spoil the conditioning; centred, the two columns
    for ``a`` and ``b`` are orthogonal and of equal norm, so the normal equations
    are diagonal and the solution is ``a = sum(x u + y v) / S``, ``b = sum(x v - y u)
    / S`` (``u, v`` the centred mine coordinates, ``S = sum(x^2 + y^2)``).
    """
    p = np.asarray(points_scanner, dtype=float).reshape(-1, 2)
    q = np.asarray(points_mine, dtype=float).reshape(-1, 2)
    if p.shape[0] < 2:
        raise ValueError("a similarity transformation needs at least two points")
    if q.shape != p.shape:
        raise ValueError(f"{p.shape[0]} scanner points but {q.shape[0]} mine points")
    return similarity_transforms(p[None], q[None])[0]


def similarity_transforms(
    points_scanner: NDArray[np.float64], points_mine: NDArray[np.float64]
) -> list[Similarity]:
    """:func:`similarity_transform` for ``k`` sets of ``n >= 2`` point pairs at once
    (shape (k, n, 2) each)."""
    p = np.asarray(points_scanner, dtype=float)
    q = np.asarray(points_mine, dtype=float)
    if p.ndim != 3 or p.shape[2] != 2 or q.shape != p.shape:
        raise ValueError(f"point sets of shapes {p.shape} and {q.shape}: (k, n, 2) each")
    if p.shape[1] < 2:
        raise ValueError("a similarity transformation needs at least two points")
    pc, qc = p.mean(axis=1), q.mean(axis=1)
    x, y = p[..., 0] - pc[:, None, 0], p[..., 1] - pc[:, None, 1]
    u, v = q[..., 0] - qc[:, None, 0], q[..., 1] - qc[:, None, 1]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        sum_sq = np.sum(x * x + y * y, axis=1)
        a = np.sum(x * u + y * v, axis=1) / sum_sq
        b = np.sum(x * v - y * u, axis=1) / sum_sq
    solved = (sum_sq >= _TINY) & (sum_sq < math.inf) & np.isfinite(a) & np.isfinite(b)
    for k in np.flatnonzero(~solved).tolist():
        # Coincident points, or coordinates whose squares underflow or overflow: lstsq's
        # answer (the minimum-norm one where nothing is constrained).
        n = p.shape[1]
        design = np.zeros((2 * n, 2))
        design[0::2, 0], design[0::2, 1] = x[k], -y[k]
        design[1::2, 0], design[1::2, 1] = y[k], x[k]
        (a[k], b[k]), *_ = np.linalg.lstsq(
            design, np.column_stack([u[k], v[k]]).reshape(-1), rcond=None
        )
    # t = qc - R pc, R = [[a, -b], [b, a]]; the residuals q - (R p + t)
    t = np.stack(
        [qc[:, 0] - (a * pc[:, 0] - b * pc[:, 1]), qc[:, 1] - (b * pc[:, 0] + a * pc[:, 1])],
        axis=1,
    )
    a_, b_ = a[:, None], b[:, None]
    rx = q[..., 0] - ((a_ * p[..., 0] - b_ * p[..., 1]) + t[:, None, 0])
    ry = q[..., 1] - ((b_ * p[..., 0] + a_ * p[..., 1]) + t[:, None, 1])
    rms = np.sqrt(np.mean(rx**2 + ry**2, axis=1))
    return [
        Similarity(math.hypot(ak, bk), math.atan2(bk, ak), tk, rk)
        for ak, bk, tk, rk in zip(a.tolist(), b.tolist(), t, rms.tolist(), strict=True)
    ]


#: Smallest normal double: a sum of squares below it has lost its precision.
_TINY = float(np.finfo(np.float64).tiny)


@dataclass(frozen=True, slots=True)
class IcpResult:
    """Outcome of point-to-line ICP.

    Attributes
    ----------
    pose : Pose2D
    iterations : int
    converged : bool
    panel : ndarray of int, shape (n,)
        Panel (index into the PanelSet) each point was matched to; -1 for none.
    residual_m : ndarray, shape (n,)
        Signed point-to-line distance of each matched point (``nan`` if none).
    """

    pose: Pose2D
    iterations: int
    converged: bool
    panel: NDArray[np.intp]
    residual_m: NDArray[np.float64]

    @property
    def inliers(self) -> int:
        return int(np.count_nonzero(self.panel >= 0))

    @property
    def rms_m(self) -> float:
        r = self.residual_m[self.panel >= 0]
        return float(np.sqrt(np.mean(r**2))) if r.size else math.inf


def icp_point_to_line(
    points_scanner: NDArray[np.float64],
    pose: Pose2D,
    panels: PanelSet,
    *,
    gates_m: Sequence[float],
    max_iterations: int = 50,
    tolerance_m: float = 1e-7,
    tolerance_rad: float = 1e-9,
    subset: NDArray[np.intp] | None = None,
    angles: NDArray[np.float64] | None = None,
) -> IcpResult:
    """Refine ``pose`` by point-to-line ICP against surveyed panels.

    Each iteration matches every point to its nearest panel within the current
    gate (and inside the panel's extent), then solves the linearised problem
    ``min sum ((R s_i + t - d_i) . n_i)^2`` for a small rotation about the
    scanner position and a translation (Low 2004). The gate shrinks through
    ``gates_m`` as each stage converges.

    Parameters
    ----------
    points_scanner : ndarray, shape (n, 2)
    pose : Pose2D
        Starting pose.
    panels : PanelSet
    gates_m : sequence of float
        Decreasing association gates, metres.
    tolerance_m, tolerance_rad : float
        The last stage stops when a step moves the pose less than this; the
        pose is a start for the adjustment, which iterates to full precision.
    subset : ndarray of int, optional
        The panels to match (all when not given).
    angles : ndarray, shape (n,), optional
        The points' beam angles, strictly increasing and spanning a turn at most
        (a :class:`~mast.core.scan.Scan`'s, as ``Scan.points`` gives the points):
        then each panel is matched only on the beams that can reach it, for the
        same result.

    Compiled end to end (:func:`mast.core._kernels.icp_refine`);
    :func:`_icp_reference` is the same in numpy (the tests compare the two).
    """
    from mast.core._kernels import icp_refine

    e, n, az, total, converged, panel, resid = icp_refine(
        np.ascontiguousarray(points_scanner, dtype=float).reshape(-1, 2),
        pose.easting,
        pose.northing,
        pose.azimuth,
        panels.a,
        panels.direction,
        panels.normal,
        panels.length,
        np.arange(len(panels)) if subset is None else np.ascontiguousarray(subset, dtype=np.intp),
        np.asarray(gates_m, dtype=float),
        max_iterations,
        tolerance_m,
        tolerance_rad,
        np.zeros(0) if angles is None else np.ascontiguousarray(angles, dtype=float),
    )
    return IcpResult(
        Pose2D(float(e), float(n), float(az)), int(total), bool(converged), panel, resid
    )


def _icp_reference(
    points_scanner: NDArray[np.float64],
    pose: Pose2D,
    panels: PanelSet,
    *,
    gates_m: Sequence[float],
    max_iterations: int = 50,
    tolerance_m: float = 1e-7,
    tolerance_rad: float = 1e-9,
    subset: NDArray[np.intp] | None = None,
) -> IcpResult:
    """:func:`icp_point_to_line` in numpy (the tests compare the two)."""
    p = pose
    total = 0
    converged = False
    # Only returns that could come within a gate of a panel take part in the
    # iterations, and only the panels they could reach: twice the widest gate
    # at the start (the pose moves by less than a gate), so a few dozen
    # returns and panels, not the whole scan and every panel in range.
    near, reached = panels.within(
        pose.scanner_to_mine(points_scanner), 2.0 * max(gates_m) + 0.05, subset=subset
    )
    pts = points_scanner[near]
    panel = np.full(pts.shape[0], -1, dtype=np.intp)
    for stage, gate in enumerate(gates_m):
        converged = False
        final = stage == len(gates_m) - 1
        previous = panel
        seen: set[bytes] = set()
        for _ in range(max_iterations):
            total += 1
            m = p.scanner_to_mine(pts)
            panel, dist = panels.associate(m, gate, subset=reached)
            # A coarse stage only has to bring the returns to their panels: once the
            # matches stop changing, the next (narrower) stage takes over.
            if not final and np.array_equal(panel, previous):
                converged = True
                break
            # Returns on the gate's edge can flip in and out for ever: a set of
            # matches met before in this stage closes the loop.
            key = panel.tobytes()
            if key in seen and not np.array_equal(panel, previous):
                converged = True
                break
            seen.add(key)
            previous = panel
            ok = panel >= 0
            if np.count_nonzero(ok) < 3:
                break
            nrm = panels.normal[panel[ok]]
            rel = m[ok] - p.position
            # d/d(omega) of n.(m) for a rotation about the scanner: n . J rel, J = [[0,-1],[1,0]]
            jw = nrm[:, 1] * rel[:, 0] - nrm[:, 0] * rel[:, 1]
            A = np.column_stack([nrm, jw])
            b = -dist[ok]
            x = pose_step(A, b)
            omega = yaw_of_azimuth(p.azimuth) + float(x[2])
            p = Pose2D(
                p.easting + float(x[0]),
                p.northing + float(x[1]),
                azimuth_of_yaw(omega),
            )
            # A step below the spacing of doubles at these coordinates cannot change them.
            tol_m = max(tolerance_m, 4 * np.spacing(max(abs(p.easting), abs(p.northing), 1.0)))
            if math.hypot(x[0], x[1]) < tol_m and abs(x[2]) < max(tolerance_rad, tol_m / 100.0):
                converged = True
                break
    m = p.scanner_to_mine(points_scanner)
    panel, dist = panels.associate(m, gates_m[-1], subset=subset)
    resid = np.where(panel >= 0, dist, np.nan)
    return IcpResult(p, total, converged, panel, resid)
