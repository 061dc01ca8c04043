"""Stage 5: least-squares adjustment of the pose from the measured ranges.

Adjustment of indirect observations (Wolf and Ghilani 1997, ch. 11; Gracie
and Mikhail 1981): every return ``r_i`` on a surveyed panel line
``{x : n . x = c}`` is an observation of

    rho_i(E, N, A) = (c - n . P) / (n . u_i),   u_i = (sin(A - phi_i), cos(A - phi_i)),

the distance from the scanner at ``P = (E, N)`` along beam ``phi_i`` to the
line. Gauss-Newton on ``v = r - rho`` with weights ``1 / sigma_i^2``, where
``sigma_i^2 = sigma_r^2 + (d rho / d phi)^2 sigma_phi^2`` carries both the
range and the beam-angle precision into the range direction. The same
Jacobian rows ``g_i`` build the Cramer-Rao bound (Censi 2007).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core._kernels import (
    adjust_rounds,
    gauss_newton,
    range_rows,
    ray_association,
    survey_shares,
)
from mast.core.geometry import PanelSet, first_hits
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.core.quantiles import chi2_ppf, f_ppf, norm_ppf, t_ppf
from mast.core.scan import Scan
from mast.core.stats import variance_bounds
from mast.pipeline.edges import SILHOUETTE_VARIANCE, at_silhouette, jump_m

__all__ = [
    "Adjustment",
    "ErrorEllipse",
    "Observations",
    "adjust_on_panels",
    "adjust_pose",
    "range_model",
    "survey_covariance",
]

#: Most Gauss-Newton iterations of one adjustment.
MAX_GAUSS_NEWTON_ITERATIONS = 20
#: Beams closer than this to grazing a panel (|n . u| below) carry no usable range.
MIN_INCIDENCE_COS = math.sin(math.radians(2.0))


@dataclass(frozen=True, slots=True)
class ErrorEllipse:
    """Confidence ellipse of the position.

    Attributes
    ----------
    semi_major_m, semi_minor_m : float
    azimuth_rad : float
        Azimuth of the semi-major axis (clockwise from north, in [0, pi)).
    confidence : float
    """

    semi_major_m: float
    semi_minor_m: float
    azimuth_rad: float
    confidence: float


def _floats(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a`` as a C-contiguous float64 array (what the kernels are compiled for)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def range_model(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Predicted ranges to lines ``n . x = c``, their Jacobian and d rho / d phi.

    Returns
    -------
    rho : ndarray, shape (n,)
    jac : ndarray, shape (n, 3)
        d rho / d (E, N, A), A in radians.
    d_phi : ndarray, shape (n,)
        d rho / d phi (equal to minus the azimuth column).
    """
    angles, nrm, off = _floats(angles_rad), _floats(normals), _floats(offsets)
    rho = np.empty(angles.size)
    jac = np.empty((angles.size, 3))
    range_rows(pose.easting, pose.northing, pose.azimuth, angles, nrm, off, rho, jac)
    return rho, jac, -jac[:, 2]


def _range_model_reference(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`range_model` in numpy, the compiled kernel's reference."""
    u = pose.beam_directions(angles_rad)
    u_a = np.stack([u[:, 1], -u[:, 0]], axis=1)  # du/dA = (cos(A - phi), -sin(A - phi))
    nu = np.einsum("ij,ij->i", normals, u)
    # Offsets relative to the scanner keep precision at large mine coordinates.
    c_rel = offsets - normals @ pose.position
    rho = c_rel / nu
    n_ua = np.einsum("ij,ij->i", normals, u_a)
    jac = np.column_stack([-normals[:, 0] / nu, -normals[:, 1] / nu, -rho * n_ua / nu])
    return rho, jac, -jac[:, 2]


_VERDICTS = {
    "pass": "passed",
    "too_small": "too small (a-priori precisions pessimistic)",
    "too_large": "too large (model or precisions do not fit)",
}


@dataclass(frozen=True, eq=False)
class Adjustment:
    """The adjusted pose with its statistics.

    Attributes
    ----------
    pose : Pose2D
    cofactor : ndarray, shape (3, 3)
        ``(G^T W G)^-1`` for (E [m], N [m], A [rad]): the a-priori covariance.
    covariance : ndarray, shape (3, 3)
        The covariance reported: the cofactor scaled by the reference variance
        when the global test rejects it as too large (the a-priori precisions
        were too optimistic), otherwise the cofactor itself.
    reference_variance : float
        A-posteriori ``sigma_0^2 = v^T W v / (n - 3)``.
    dof : int
    chi2_lower, chi2_upper : float
        Two-sided 95 % acceptance bounds for ``sigma_0^2``.
    residuals_m : ndarray, shape (n,)
        ``v = r - rho`` at the solution.
    sigmas_m : ndarray, shape (n,)
        A-priori standard deviation of each observation.
    iterations : int
    jacobian : ndarray, shape (n, 3)
    """

    pose: Pose2D
    cofactor: NDArray[np.float64]
    covariance: NDArray[np.float64]
    reference_variance: float
    dof: int
    chi2_lower: float
    chi2_upper: float
    residuals_m: NDArray[np.float64]
    sigmas_m: NDArray[np.float64]
    iterations: int
    jacobian: NDArray[np.float64]

    @property
    def test_passed(self) -> bool:
        """Global (chi-square) test of the reference variance at 5 %, two-sided."""
        return self.chi2_lower <= self.reference_variance <= self.chi2_upper

    @property
    def test_code(self) -> str:
        """The global test as a code: ``pass``, ``too_small`` or ``too_large``."""
        if self.reference_variance < self.chi2_lower:
            return "too_small"
        if self.reference_variance > self.chi2_upper:
            return "too_large"
        return "pass"

    @property
    def test_verdict(self) -> str:
        """The global test in words."""
        return _VERDICTS[self.test_code]

    @property
    def sigma(self) -> NDArray[np.float64]:
        """Standard deviations of (E [m], N [m], A [rad])."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def scaled(self) -> bool:
        """Whether the covariance was scaled by the reference variance (test rejected high)."""
        return self.reference_variance > self.chi2_upper

    def quantile95(self) -> float:
        """Two-sided 95 % factor: normal for a-priori, Student t for a-posteriori scaling."""
        if self.scaled:
            return t_ppf(0.975, max(self.dof, 1))
        return norm_ppf(0.975)

    def interval95(self) -> NDArray[np.float64]:
        """Half-widths of the 95 % intervals for (E [m], N [m], A [rad])."""
        return self.quantile95() * self.sigma

    def ellipse(self, confidence: float = 0.95) -> ErrorEllipse:
        """Position confidence ellipse (chi-square with 2 degrees of freedom)."""
        if self.scaled:
            k = math.sqrt(2 * f_ppf(confidence, 2, max(self.dof, 1)))
        else:
            k = math.sqrt(chi2_ppf(confidence, 2))
        return position_ellipse(self.covariance, k, confidence)


def position_ellipse(cov: NDArray[np.float64], scale: float, confidence: float) -> ErrorEllipse:
    """The ellipse of a pose covariance's (E, N) block, its axes ``scale`` standard deviations."""
    w, v = np.linalg.eigh(cov[:2, :2])
    major = v[:, 1]
    az = math.atan2(major[0], major[1]) % math.pi
    return ErrorEllipse(
        scale * math.sqrt(max(w[1], 0.0)), scale * math.sqrt(max(w[0], 0.0)), az, confidence
    )


def adjust_pose(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    ranges_m: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    *,
    noise: NoiseModel,
    variance_scale: NDArray[np.float64] | None = None,
    max_iterations: int = MAX_GAUSS_NEWTON_ITERATIONS,
) -> Adjustment:
    """Weighted least squares for (E, N, A) from ranges to known lines.

    Parameters
    ----------
    pose : Pose2D
        Starting pose (from ICP).
    angles_rad, ranges_m : ndarray, shape (n,)
        Beam angles (scanner frame) and measured ranges.
    normals : ndarray, shape (n, 2); offsets : ndarray, shape (n,)
        The surveyed line each return lies on, ``n . x = c``, mine frame.
    noise : NoiseModel
        A-priori precision of a range and of a beam angle.
    variance_scale : ndarray, shape (n,), optional
        Each return's a-priori variance is the noise model's times this (returns
        at a beacon's silhouette, which may be mixed pixels: :mod:`mast.pipeline.edges`).

    Raises
    ------
    numpy.linalg.LinAlgError
        When the normal matrix is singular (degenerate geometry).
    """
    n = angles_rad.size
    scale = np.ones(n) if variance_scale is None else _floats(variance_scale)
    return _adjustment_of(
        gauss_newton(
            pose.easting,
            pose.northing,
            pose.azimuth,
            _floats(angles_rad),
            _floats(ranges_m),
            _floats(normals),
            _floats(offsets),
            scale,
            noise.range_sigma_m,
            noise.angle_sigma_rad,
            max_iterations,
        )
    )


def _adjustment_of(gn: tuple[Any, ...]) -> Adjustment:
    """The :class:`Adjustment` of :func:`mast.core._kernels.gauss_newton`'s outputs.

    Raises
    ------
    numpy.linalg.LinAlgError
        When a normal matrix was singular.
    """
    e, nn, az, it, solved, chi2, v, var, jac, q = gn
    if not solved:
        raise np.linalg.LinAlgError("Singular matrix")
    dof = v.size - 3
    s0 = chi2 / dof if dof > 0 else math.nan
    lo, hi = variance_bounds(dof)
    # Surveying practice: when the global test passes, the a-priori precisions
    # stand (sigma_0 = 1); when it rejects high, they were too optimistic and
    # the covariance is scaled by the a-posteriori reference variance.
    cov: NDArray[np.float64] = q * s0 if s0 > hi else q.copy()
    return Adjustment(Pose2D(e, nn, az), q, cov, s0, dof, lo, hi, v, np.sqrt(var), it, jac)


def _adjust_pose_reference(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    ranges_m: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    *,
    noise: NoiseModel,
    variance_scale: NDArray[np.float64] | None = None,
    max_iterations: int = MAX_GAUSS_NEWTON_ITERATIONS,
) -> Adjustment:
    """:func:`adjust_pose` in numpy, the compiled kernel's reference."""
    n = angles_rad.size
    scale = 1.0 if variance_scale is None else variance_scale
    p = pose
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - the count is reported
        rho, jac, d_phi = _range_model_reference(p, angles_rad, normals, offsets)
        var = noise.variance(d_phi) * scale
        w = 1.0 / var
        v = ranges_m - rho
        N = jac.T @ (w[:, None] * jac)
        t = jac.T @ (w * v)
        delta = np.linalg.solve(N, t)
        p = Pose2D(
            p.easting + float(delta[0]),
            p.northing + float(delta[1]),
            (p.azimuth + float(delta[2])) % (2 * math.pi),
        )
        tol_m = max(1e-11, 4 * np.spacing(max(abs(p.easting), abs(p.northing), 1.0)))
        if math.hypot(delta[0], delta[1]) < tol_m and abs(delta[2]) < 1e-13:
            break
    rho, jac, d_phi = _range_model_reference(p, angles_rad, normals, offsets)
    var = noise.variance(d_phi) * scale
    w = 1.0 / var
    v = ranges_m - rho
    N = jac.T @ (w[:, None] * jac)
    Q: NDArray[np.float64] = np.asarray(np.linalg.inv(N), dtype=np.float64)
    dof = n - 3
    s0 = float(v @ (w * v) / dof) if dof > 0 else math.nan
    lo, hi = variance_bounds(dof)
    cov: NDArray[np.float64] = Q * s0 if s0 > hi else Q.copy()
    return Adjustment(p, Q, cov, s0, dof, lo, hi, v, np.sqrt(var), it, jac)


@dataclass(frozen=True, eq=False)
class Observations:
    """Ranges to surveyed panel lines, and which beam, beacon and panel each is."""

    beam: NDArray[np.intp]
    angles_rad: NDArray[np.float64]
    ranges_m: NDArray[np.float64]
    normals: NDArray[np.float64]
    offsets: NDArray[np.float64]
    panel: NDArray[np.intp]
    beacon: NDArray[np.intp]
    survey_var: NDArray[np.float64]
    """Each return's panel's surveyed variance across its face, m²
    (:meth:`~mast.core.geometry.PanelSet.survey_variance`)."""
    variance_scale: NDArray[np.float64] | None = None
    """Each return's variance over the noise model's (None: all 1)."""

    def subset(self, keep: NDArray[np.bool_]) -> Observations:
        return Observations(
            self.beam[keep],
            self.angles_rad[keep],
            self.ranges_m[keep],
            self.normals[keep],
            self.offsets[keep],
            self.panel[keep],
            self.beacon[keep],
            self.survey_var[keep],
            None if self.variance_scale is None else self.variance_scale[keep],
        )

    def __len__(self) -> int:
        return int(self.ranges_m.size)

    def survey_levers(self, pose: Pose2D) -> NDArray[np.float64]:
        """``1 / |n . u|``: how far each range moves per metre its panel is surveyed off."""
        u = pose.beam_directions(self.angles_rad)
        return np.asarray(1.0 / np.abs(np.einsum("ij,ij->i", self.normals, u)))

    def adjust(self, pose: Pose2D, noise: NoiseModel) -> Adjustment:
        return adjust_pose(
            pose,
            self.angles_rad,
            self.ranges_m,
            self.normals,
            self.offsets,
            noise=noise,
            variance_scale=self.variance_scale,
        )


def _ray_association(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    keep: NDArray[np.intp],
    noise: NoiseModel,
    gate_sigmas: float,
    pose_cofactor: NDArray[np.float64] | None,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Beams whose ray, cast from ``pose``, first meets a kept panel, that panel, and
    whether the beam lies at its beacon's silhouette (:func:`~mast.pipeline.edges.at_silhouette`:
    it may be a mixed pixel).

    Casting the ray decides which panel a beam near a corner hits (the nearer
    one), where the nearest line to the return would be a coin toss within
    the noise. A return is kept when it lies within ``gate_sigmas`` standard
    deviations of the predicted range, counting the pose's own uncertainty
    (``g^T Q g``, once an adjustment gives ``Q``): a beam that meets a panel
    obliquely, far away, is very sensitive to the azimuth and would otherwise
    be gated out exactly when it carries the most information. Beams within
    2 degrees of grazing are left out.
    """
    beams, rows, edge = ray_association(
        pose.easting,
        pose.northing,
        pose.azimuth,
        _floats(scan.angles_rad),
        _floats(scan.ranges_m),
        scan.valid,
        _floats(panels.a[keep]),
        _floats(panels.b[keep]),
        _floats(panels.normal[keep]),
        panels.beacon[keep],
        _NO_COFACTOR if pose_cofactor is None else _floats(pose_cofactor),
        gate_sigmas * _first_gate_sigma(panels, keep, noise),
        gate_sigmas,
        noise.range_sigma_m,
        noise.angle_sigma_rad,
        _floats(panels.survey_variance(noise.survey_sigma_m)[keep]),
        MIN_INCIDENCE_COS,
        jump_m(noise.range_sigma_m),
    )
    return beams, keep[rows], edge


def _first_gate_sigma(panels: PanelSet, keep: NDArray[np.intp], noise: NoiseModel) -> float:
    """The range gate's standard deviation before an adjustment gives the pose's own:
    the range noise with the largest surveyed variance among the ``keep`` panels
    (``noise.gate_sigma_m`` when the survey gives none of its own)."""
    if panels.edge_sigma_m is None or keep.size == 0:
        return noise.gate_sigma_m
    worst = float(panels.survey_variance(noise.survey_sigma_m)[keep].max())
    return math.sqrt(noise.range_sigma_m**2 + worst)


#: What :func:`mast.core._kernels.ray_association` takes for "no pose uncertainty yet".
_NO_COFACTOR = np.zeros((0, 0))


def _ray_association_reference(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    keep: NDArray[np.intp],
    noise: NoiseModel,
    gate_sigmas: float,
    pose_cofactor: NDArray[np.float64] | None,
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """:func:`_ray_association` in numpy, the compiled kernel's reference."""
    beams = np.flatnonzero(scan.valid)
    dirs = pose.beam_directions(scan.angles_rad[beams])
    t, j = first_hits(pose.position, dirs, panels.a[keep], panels.b[keep])
    # Only the beams that meet a kept panel go on (memory follows them, not the scan).
    hit = np.flatnonzero(j >= 0)
    ray_owner = np.full(scan.ranges_m.size, -1, dtype=np.intp)
    ray_owner[beams[hit]] = panels.beacon[keep[j[hit]]]
    beams, dirs, t = beams[hit], dirs[hit], t[hit]
    pk = keep[j[hit]]
    nrm = panels.normal[pk]
    nu = np.abs(np.einsum("ij,ij->i", nrm, dirs))
    gate = np.full(beams.size, gate_sigmas * _first_gate_sigma(panels, keep, noise))
    if pose_cofactor is not None and beams.size:
        offsets = np.einsum("ij,ij->i", nrm, panels.a[pk])
        _rho, jac, d_phi = _range_model_reference(pose, scan.angles_rad[beams], nrm, offsets)
        pred = np.einsum("ij,jk,ik->i", jac, pose_cofactor, jac)
        surveyed = panels.survey_variance(noise.survey_sigma_m)[pk]
        var = noise.variance(d_phi) + surveyed + np.where(np.isfinite(pred), pred, 0.0)
        gate = gate_sigmas * np.sqrt(var)
    ok = (np.abs(scan.ranges_m[beams] - t) <= gate) & (nu > MIN_INCIDENCE_COS)
    edge = at_silhouette(
        scan.ranges_m,
        scan.valid,
        beams[ok],
        t[ok],
        panels.beacon[pk[ok]],
        ray_owner,
        jump_m(noise.range_sigma_m),
    )
    return beams[ok], pk[ok], edge


def _robust_inliers_reference(
    adj: Adjustment,
    angles_rad: NDArray[np.float64],
    ranges_m: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    noise: NoiseModel,
    gate_sigmas: float,
) -> NDArray[np.bool_]:
    """Observations within ``gate_sigmas`` robust standard deviations of the prediction.

    The standard deviation of ``r - rho`` is that of the range and of the
    predicted range (``g^T Q g``, the pose's uncertainty seen along the beam),
    both scaled by 1.4826 times the median absolute standardised residual of
    the previous adjustment, capped at 1 (the a-priori precision): the test
    tightens on clean data, and never below a numerical floor. The numpy reference
    of the robust gate in :func:`mast.core._kernels.adjust_rounds`.
    """
    std = adj.residuals_m / adj.sigmas_m
    scale = 1.0
    if std.size:
        mad = float(np.median(np.abs(std))) / norm_ppf(0.75)  # about the prediction, 0
        scale = min(1.0, mad)
    rho, jac, d_phi = _range_model_reference(adj.pose, angles_rad, normals, offsets)
    pred = np.einsum("ij,jk,ik->i", jac, adj.cofactor, jac)
    sig = np.sqrt(noise.variance(d_phi) + pred)
    floor = 1e-7 * (1.0 + np.abs(rho))
    return np.asarray(np.abs(ranges_m - rho) <= gate_sigmas * np.maximum(scale * sig, floor))


def _scaled(q: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.sqrt(np.abs(np.diag(q)))
    d[d == 0] = 1.0
    return np.asarray(q / np.outer(d, d))


#: Most association and adjustment rounds before the returns used settle.
MAX_ASSOCIATION_ROUNDS = 8
#: Condition number of the correlation matrix beyond which (E, N, A) are not determined.
MAX_CONDITION = 1e10


def adjust_on_panels(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    keep: NDArray[np.intp],
    *,
    noise: NoiseModel,
    gate_sigmas: float,
) -> tuple[Observations, Adjustment] | str:
    """Adjust the pose on the returns of the ``keep`` panels, re-associating as it moves.

    Each round casts every beam from the current pose (:func:`_ray_association`),
    weights returns at a beacon's silhouette down (they may be mixed pixels:
    :data:`~mast.pipeline.edges.SILHOUETTE_VARIANCE`), drops returns far outside
    the robust spread of the last round's residuals, and adjusts; it stops when
    the returns used, and their weights, no longer change.

    Returns
    -------
    (Observations, Adjustment), or a sentence saying why the panels seen do
    not determine the pose.
    """
    code, count, used, rows, scale, gn = adjust_rounds(
        pose.easting,
        pose.northing,
        pose.azimuth,
        _floats(scan.angles_rad),
        _floats(scan.ranges_m),
        scan.valid,
        _floats(panels.a[keep]),
        _floats(panels.b[keep]),
        _floats(panels.normal[keep]),
        panels.beacon[keep],
        gate_sigmas * _first_gate_sigma(panels, keep, noise),
        gate_sigmas,
        noise.range_sigma_m,
        noise.angle_sigma_rad,
        _floats(panels.survey_variance(noise.survey_sigma_m)[keep]),
        MIN_INCIDENCE_COS,
        jump_m(noise.range_sigma_m),
        SILHOUETTE_VARIANCE,
        norm_ppf(0.75),
        MAX_ASSOCIATION_ROUNDS,
        MAX_GAUSS_NEWTON_ITERATIONS,
        MAX_CONDITION,
    )
    if code == 1:
        return f"only {count} returns on the panels"
    if code == 2:
        return "the panels seen do not constrain all of E, N and azimuth"
    used_panels = keep[rows]
    nrm = panels.normal[used_panels]
    obs = Observations(
        used,
        scan.angles_rad[used],
        scan.ranges_m[used],
        nrm,
        np.einsum("ij,ij->i", nrm, panels.a[used_panels]),
        used_panels,
        panels.beacon[used_panels],
        panels.survey_variance(noise.survey_sigma_m)[used_panels],
        scale,
    )
    return obs, _adjustment_of(gn)


def _adjust_on_panels_reference(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    keep: NDArray[np.intp],
    *,
    noise: NoiseModel,
    gate_sigmas: float,
) -> tuple[Observations, Adjustment] | str:
    """:func:`adjust_on_panels` in numpy, the compiled kernel's reference."""
    adj: Adjustment | None = None
    used = np.zeros(0, dtype=np.intp)
    used_panels = np.zeros(0, dtype=np.intp)
    used_scale = np.zeros(0)
    for _ in range(MAX_ASSOCIATION_ROUNDS):
        beams, pk, edge = _ray_association_reference(
            scan, pose, panels, keep, noise, gate_sigmas, None if adj is None else adj.cofactor
        )
        nrm = panels.normal[pk]
        offsets = np.einsum("ij,ij->i", nrm, panels.a[pk])
        if adj is not None:
            good = _robust_inliers_reference(
                adj, scan.angles_rad[beams], scan.ranges_m[beams], nrm, offsets, noise, gate_sigmas
            )
            beams, pk, nrm, offsets, edge = (
                beams[good],
                pk[good],
                nrm[good],
                offsets[good],
                edge[good],
            )
        scale = np.where(edge, SILHOUETTE_VARIANCE, 1.0)
        if np.array_equal(beams, used) and np.array_equal(scale, used_scale) and adj is not None:
            break
        if beams.size < 4:
            return f"only {beams.size} returns on the panels"
        try:
            adj = _adjust_pose_reference(
                pose,
                scan.angles_rad[beams],
                scan.ranges_m[beams],
                nrm,
                offsets,
                noise=noise,
                variance_scale=scale,
            )
        except np.linalg.LinAlgError:
            adj = None
        if (
            adj is None
            or not np.all(np.isfinite(adj.cofactor))
            or np.linalg.cond(_scaled(adj.cofactor)) > MAX_CONDITION
        ):
            return "the panels seen do not constrain all of E, N and azimuth"
        used, used_panels, used_scale = beams, pk, scale
        pose = adj.pose
    assert adj is not None
    nrm = panels.normal[used_panels]
    obs = Observations(
        used,
        scan.angles_rad[used],
        scan.ranges_m[used],
        nrm,
        np.einsum("ij,ij->i", nrm, panels.a[used_panels]),
        used_panels,
        panels.beacon[used_panels],
        panels.survey_variance(noise.survey_sigma_m)[used_panels],
        used_scale,
    )
    return obs, adj


def survey_covariance(adj: Adjustment, obs: Observations) -> NDArray[np.float64]:
    """Pose covariance from the surveyed panels' own position errors.

    A panel surveyed ``sigma_s`` off across its face (``obs.survey_var``, its own per
    panel) moves every range to it by ``sigma_s / |n . u|`` together; through the
    estimator ``K = Q G^T W`` that adds ``K S K^T`` to the noise covariance (S: those
    shared range errors).
    """
    return survey_shares(
        adj.pose.easting,
        adj.pose.northing,
        adj.pose.azimuth,
        _floats(obs.angles_rad),
        _floats(obs.normals),
        adj.jacobian,
        adj.sigmas_m,
        adj.cofactor,
        np.ascontiguousarray(obs.panel, dtype=np.intp),
        _floats(obs.survey_var),
    )


def _survey_covariance_reference(adj: Adjustment, obs: Observations) -> NDArray[np.float64]:
    """:func:`survey_covariance` in numpy, the compiled kernel's reference."""
    lever = obs.survey_levers(adj.pose)
    k = adj.cofactor @ (adj.jacobian / (adj.sigmas_m**2)[:, None]).T  # (3, n)
    # Each panel's column K_p l_p, all panels at once: (3, panels).
    _, first, at = np.unique(obs.panel, return_index=True, return_inverse=True)
    cols = np.stack([np.bincount(at.reshape(-1), weights=row * lever) for row in k])
    return np.asarray((cols * obs.survey_var[first]) @ cols.T)
