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

from mast.core.beacon import Survey
from mast.core.geometry import PanelSet, first_hits
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D
from mast.pipeline.adjustment import MIN_INCIDENCE_COS, range_model

__all__ = ["cramer_rao_bound", "truth_bound"]


def cramer_rao_bound(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    normals: NDArray[np.float64],
    offsets: NDArray[np.float64],
    *,
    noise: NoiseModel,
) -> NDArray[np.float64]:
    """Covariance bound ``(sum g g^T / sigma^2)^-1`` for (E [m], N [m], A [rad]).

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

    Returns
    -------
    ndarray, shape (3, 3)
        ``inf`` on the diagonal when the beams do not determine the pose.
    """
    _, jac, d_phi = range_model(pose, angles_rad, normals, offsets)
    var = noise.variance(d_phi)
    info = jac.T @ (jac / var[:, None])
    try:
        out: NDArray[np.float64] = np.asarray(np.linalg.inv(info), dtype=np.float64)
    except np.linalg.LinAlgError:
        return np.diag([math.inf] * 3)
    if not np.all(np.isfinite(out)) or np.linalg.cond(info) > 1e14:
        return np.diag([math.inf] * 3)
    return out


def truth_bound(
    pose: Pose2D,
    angles_rad: NDArray[np.float64],
    valid: NDArray[np.bool_],
    survey: Survey,
    *,
    noise: NoiseModel,
    beacon_beams: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """The bound from every valid beam that, at ``pose``, first hits a surveyed panel.

    ``beacon_beams`` (e.g. the simulator's truth of which beams hit a panel)
    restricts the beams further, so occlusion by other objects is honoured.
    Beams within 2 degrees of grazing are left out, as the adjustment does.
    """
    panels = PanelSet.from_survey(survey)
    dirs = pose.beam_directions(angles_rad)
    _, j = first_hits(pose.position, dirs, panels.a, panels.b)
    use = valid & (j >= 0)
    if beacon_beams is not None:
        use &= beacon_beams
    k = j[use]
    nrm = panels.normal[k]
    nu = np.abs(np.einsum("ij,ij->i", nrm, dirs[use]))
    keep = nu > MIN_INCIDENCE_COS
    off = np.einsum("ij,ij->i", nrm, panels.a[k])
    return cramer_rao_bound(
        pose,
        angles_rad[use][keep],
        nrm[keep],
        off[keep],
        noise=noise,
    )
