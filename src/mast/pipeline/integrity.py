"""Integrity of a fix: outlier tests on single returns and on whole beacons.

* Data snooping (Baarda): the standardised residual ``w_i = v_i / sigma_vi``
  with ``sigma_vi^2 = sigma_i^2 - g_i Q g_i^T``; the largest beyond the
  critical value (0.1 % shared over all returns, Bonferroni: only returns no
  noise explains) is removed and the pose adjusted again, until none is.
* Beacon test: each beacon in turn is left out, the pose fitted to the others,
  and the left-out beacon's ranges compared with their prediction:
  ``T_b = d^T C^-1 d`` with ``C = diag(sigma^2) + G_b Q_(-b) G_b^T`` plus the
  survey's uncertainty of each panel's position (shared by its returns). Under
  a correctly surveyed beacon ``T_b`` is chi-square with ``n_b`` degrees of
  freedom; a beacon that was knocked out of place or mis-surveyed fails. When
  the other beacons fit each other worse than the a-priori precisions say
  (reference variance above 1: range bias, mixed pixels), ``T_b`` is divided
  by their reference variance, as in Pope's tau test.

References
----------
W. Baarda, *A testing procedure for use in geodetic networks*, 1968.
P. J. G. Teunissen, *Testing Theory*, Delft, 2000 (w-test, group tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from mast.core.pose import Pose2D
from mast.pipeline.adjustment import Adjustment, adjust_pose, range_model

__all__ = ["BeaconTest", "Observations", "beacon_tests", "snoop"]


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

    def subset(self, keep: NDArray[np.bool_]) -> Observations:
        return Observations(
            self.beam[keep],
            self.angles_rad[keep],
            self.ranges_m[keep],
            self.normals[keep],
            self.offsets[keep],
            self.panel[keep],
            self.beacon[keep],
        )

    def __len__(self) -> int:
        return int(self.ranges_m.size)

    def survey_levers(self, pose: Pose2D) -> NDArray[np.float64]:
        """``1 / |n . u|``: how far each range moves per metre its panel is surveyed off."""
        u = pose.beam_directions(self.angles_rad)
        return np.asarray(1.0 / np.abs(np.einsum("ij,ij->i", self.normals, u)))

    def adjust(self, pose: Pose2D, range_sigma_m: float, angle_sigma_rad: float) -> Adjustment:
        return adjust_pose(
            pose,
            self.angles_rad,
            self.ranges_m,
            self.normals,
            self.offsets,
            range_sigma_m=range_sigma_m,
            angle_sigma_rad=angle_sigma_rad,
        )


def snoop(
    obs: Observations,
    adj: Adjustment,
    *,
    range_sigma_m: float,
    angle_sigma_rad: float,
    alpha: float = 0.001,
    max_removed: int = 50,
) -> tuple[Observations, Adjustment, int]:
    """Remove, one at a time, returns whose w-test fails; returns what is left."""
    removed = 0
    while removed < max_removed and len(obs) > 4:
        g = adj.jacobian
        qvv = adj.sigmas_m**2 - np.einsum("ij,jk,ik->i", g, adj.cofactor, g)
        w = adj.residuals_m / np.sqrt(np.maximum(qvv, 1e-30))
        crit = float(stats.norm.ppf(1 - alpha / 2 / len(obs)))
        i = int(np.argmax(np.abs(w)))
        if abs(w[i]) <= crit:
            break
        keep = np.ones(len(obs), dtype=bool)
        keep[i] = False
        obs = obs.subset(keep)
        adj = obs.adjust(adj.pose, range_sigma_m, angle_sigma_rad)
        removed += 1
    return obs, adj, removed


@dataclass(frozen=True, slots=True)
class BeaconTest:
    """The left-out test of one beacon."""

    beacon: int
    statistic: float
    dof: int
    critical: float

    @property
    def ratio(self) -> float:
        return self.statistic / self.critical

    @property
    def failed(self) -> bool:
        return self.statistic > self.critical


def beacon_tests(
    obs: Observations,
    adj: Adjustment,
    *,
    range_sigma_m: float,
    angle_sigma_rad: float,
    survey_sigma_m: float,
    alpha: float = 0.001,
) -> list[BeaconTest]:
    """Leave-one-beacon-out tests for every beacon with returns (needs two or more)."""
    ids = np.unique(obs.beacon)
    if ids.size < 2:
        return []
    out = []
    for b in ids:
        mine = obs.beacon == b
        rest = obs.subset(~mine)
        try:
            fit = rest.adjust(adj.pose, range_sigma_m, angle_sigma_rad)
        except np.linalg.LinAlgError:
            continue
        if not np.all(np.isfinite(fit.cofactor)) or np.linalg.cond(fit.cofactor) > 1e14:
            continue  # the others alone do not determine the pose: no test
        o = obs.subset(mine)
        rho, jac, d_phi = range_model(fit.pose, o.angles_rad, o.normals, o.offsets)
        d = o.ranges_m - rho
        var = range_sigma_m**2 + (d_phi * angle_sigma_rad) ** 2
        c = np.diag(var) + jac @ fit.cofactor @ jac.T
        # A panel's surveyed position errs once for all its returns: sigma_s / |n . u| each.
        lever = o.survey_levers(fit.pose)
        same = o.panel[:, None] == o.panel[None, :]
        c += survey_sigma_m**2 * np.outer(lever, lever) * same
        try:
            t = float(d @ np.linalg.solve(c, d))
        except np.linalg.LinAlgError:
            continue
        # The others' own misfit, when larger than the a-priori precisions allow for
        # (unmodelled range bias, mixed pixels), widens the test as it widens theirs.
        t /= max(1.0, fit.reference_variance)
        n = int(d.size)
        out.append(BeaconTest(int(b), t, n, float(stats.chi2.ppf(1 - alpha / ids.size, n))))
    return out
