"""The Cramer-Rao bound of a single-scan pose fix.

With known panel lines, known correspondences and independent Gaussian range
errors, the Fisher information of (E, N, A) is ``sum_i g_i g_i^T / sigma_i^2``
where ``g_i`` is the derivative of beam i's range with respect to (E, N, A)
(the same rows as the adjustment's Jacobian). Its inverse is the covariance
floor no unbiased estimator beats.

References
----------
A. Censi, "On achievable accuracy for range-finder localization", ICRA 2007.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from mast.core import _kernels
from mast.core.beacon import Survey
from mast.core.geometry import PanelSet, first_hits
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.pipeline.adjustment import MIN_INCIDENCE_COS, range_model

__all__ = [
    "bound_of",
    "cramer_rao_bound",
    "information",
    "inverse_bound",
    "truth_bound",
    "truth_information",
]


def information(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    *,
    noise: NoiseModel,
) -> NDArray[np.float64]:
    """Fisher information ``sum g g^T / sigma^2`` of (E [m], N [m], A [rad]).

    Parameters
    ----------
    pose : Pose2D
        Where the information is evaluated (the true pose, or an estimate).
    angles_rad : ndarray, shape (n,)
        Beam angles of the returns on panels.
    normals, offsets : ndarray, shapes (n, 2) and (n,)
        The panel line each beam hits, ``n . x = c``, mine frame.
    noise : NoiseModel
        Noise of a range and of a beam angle (the angle term enters through
        ``d rho / d phi``, as in the adjustment).
    """
    return _kernels.information(
        pose.easting,
        pose.northing,
        pose.azimuth,
        np.ascontiguousarray(angles_rad, dtype=np.float64),
        np.ascontiguousarray(normals, dtype=np.float64),
        np.ascontiguousarray(offsets, dtype=np.float64),
        noise.range_sigma_m,
        noise.angle_sigma_rad,
    )


def _information_reference(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    *,
    noise: NoiseModel,
) -> NDArray[np.float64]:
    """:func:`information` in numpy, the compiled kernel's reference."""
    _, jac, d_phi = range_model(pose, angles_rad, normals, offsets)
    var = noise.variance(d_phi)
    info: NDArray[np.float64] = jac.T @ (jac / var[:, None])
    return info


def bound_of(info: NDArray[np.float64]) -> NDArray[np.float64]:
    """The covariance bound ``info^-1``; ``inf`` on the diagonal when the pose is not
    determined (singular or ill-conditioned information)."""
    return _kernels.bound(np.ascontiguousarray(info, dtype=np.float64), MAX_CONDITION)


#: Condition number of the information beyond which the pose is not determined.
MAX_CONDITION = 1e14


def inverse_bound(info: NDArray[np.float64]) -> NDArray[np.float64]:
    """:func:`bound_of` in numpy, for an information of any size: ``info^-1``, or ``inf``
    on the diagonal (0 off it) when ``info`` is not finite, singular, its inverse not
    finite, or its condition number above :data:`MAX_CONDITION`. The compiled 3×3
    kernel's reference, and the six-parameter bound's (:mod:`mast.pipeline.bounds3d`)."""
    fail = np.diag([math.inf] * len(info))
    if not np.all(np.isfinite(info)):
        return fail
    try:
        out: NDArray[np.float64] = np.asarray(np.linalg.inv(info), dtype=np.float64)
    except np.linalg.LinAlgError:
        return fail
    if not np.all(np.isfinite(out)) or np.linalg.cond(info) > MAX_CONDITION:
        return fail
    return out


def cramer_rao_bound(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    *,
    noise: NoiseModel,
) -> NDArray[np.float64]:
    """Covariance bound ``(sum g g^T / sigma^2)^-1`` for (E [m], N [m], A [rad]).

    The parameters are those of :func:`information`. Returns an array of shape
    (3, 3), ``inf`` on the diagonal when the beams do not determine the pose.
    """
    return bound_of(information(pose, angles_rad, normals, offsets, noise=noise))


def truth_information(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    valid: NDArray[np.bool_],
    panels: PanelSet,
    *,
    noise: NoiseModel,
    beacon_beams: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """The information from every valid beam that, at ``pose``, first hits a panel.

    ``beacon_beams`` (e.g. the simulator's truth of which beams hit a panel)
    restricts the beams further, so occlusion by other objects is honoured.
    Beams within 2 degrees of grazing are left out, as the adjustment does.
    """
    use = valid if beacon_beams is None else valid & beacon_beams
    if not np.any(use):
        return np.zeros((3, 3))
    dirs = pose.beam_directions(angles_rad[use])
    _, j = first_hits(pose.position, dirs, panels.a, panels.b)
    hit = j >= 0
    k = j[hit]
    nrm = panels.normal[k]
    keep = np.abs(np.einsum("ij,ij->i", nrm, dirs[hit])) > MIN_INCIDENCE_COS
    off = np.einsum("ij,ij->i", nrm, panels.a[k])
    return information(pose, angles_rad[use][hit][keep], nrm[keep], off[keep], noise=noise)


def truth_bound(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    valid: NDArray[np.bool_],
    survey: Survey,
    *,
    noise: NoiseModel,
    beacon_beams: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """The bound from every valid beam that, at ``pose``, first hits a surveyed panel
    (:func:`truth_information`)."""
    panels = PanelSet.from_survey(survey)
    info = truth_information(
        pose, angles_rad, valid, panels, noise=noise, beacon_beams=beacon_beams
    )
    return bound_of(info)
