"""Integrity of a fix: outlier tests on single returns and on whole beacons.

* Data snooping (Baarda): the standardised residual ``w_i = v_i / sigma_vi``
  with ``sigma_vi^2 = sigma_i^2 - g_i Q g_i^T``; the largest beyond the
  critical value (0.1 % shared over all returns, Bonferroni: only returns no
  noise explains) is removed and the pose adjusted again, until none is.
* Beacon test: each beacon in turn is left out, the pose fitted to the others
  (linearised at the joint solution, where the linear model holds best), and
  the left-out beacon's ranges compared with their prediction:
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
from scipy import stats

from mast.core.noise import NoiseModel
from mast.pipeline.adjustment import Adjustment, Observations

__all__ = ["BeaconTest", "Observations", "beacon_tests", "exclude_inconsistent", "snoop"]


def snoop(
    obs: Observations,
    adj: Adjustment,
    *,
    noise: NoiseModel,
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
        adj = obs.adjust(adj.pose, noise)
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
    noise: NoiseModel,
    alpha: float = 0.001,
) -> list[BeaconTest]:
    """Leave-one-beacon-out tests for every beacon with returns (needs two or more)."""
    ids = np.unique(obs.beacon)
    if ids.size < 2:
        return []
    g, v, sig = adj.jacobian, adj.residuals_m, adj.sigmas_m
    w = 1.0 / sig**2
    lever_all = obs.survey_levers(adj.pose)
    out = []
    for b in ids:
        mine = obs.beacon == b
        rest = ~mine
        # The others' fit, linearised at the joint solution: the best-determined pose,
        # where the linear model holds best (a weak beacon left alone may fit a pose
        # far enough off for a relinearised prediction to fail the test by itself).
        n_rest = g[rest].T @ (w[rest, None] * g[rest])
        if not np.all(np.isfinite(n_rest)) or np.linalg.cond(n_rest) > 1e14:
            continue  # the others alone do not determine the pose: no test
        q_rest = np.linalg.inv(n_rest)
        delta = q_rest @ (g[rest].T @ (w[rest] * v[rest]))
        d = v[mine] - g[mine] @ delta
        c = np.diag(sig[mine] ** 2) + g[mine] @ q_rest @ g[mine].T
        # A panel's surveyed position errs once for all its returns: sigma_s / |n . u| each.
        lever = lever_all[mine]
        same = obs.panel[mine][:, None] == obs.panel[mine][None, :]
        c += noise.survey_sigma_m**2 * np.outer(lever, lever) * same
        try:
            t = float(d @ np.linalg.solve(c, d))
        except np.linalg.LinAlgError:
            continue
        # The others' own misfit, when larger than the a-priori precisions allow for
        # (unmodelled range bias, mixed pixels), widens the test as it widens theirs.
        v_rest = v[rest] - g[rest] @ delta
        dof_rest = int(rest.sum()) - 3
        if dof_rest > 0:
            t /= max(1.0, float(v_rest @ (w[rest] * v_rest)) / dof_rest)
        n = int(d.size)
        out.append(BeaconTest(int(b), t, n, float(stats.chi2.ppf(1 - alpha / ids.size, n))))
    return out


def exclude_inconsistent(
    obs: Observations,
    adj: Adjustment,
    *,
    noise: NoiseModel,
    min_beacons: int,
) -> tuple[Observations, Adjustment, list[int], int] | list[int]:
    """Leave out, one at a time, a beacon whose ranges disagree with the others.

    A beacon is at fault only when its removal alone leaves the others
    consistent; if no single removal does, or more than one does, the scan
    cannot tell which beacon moved and a fix would rest on a guess.

    Returns
    -------
    (obs, adj, excluded, outliers) when the rest is consistent (``excluded``:
    beacon indices left out; ``outliers``: returns data snooping removed on
    the way), or the list of suspect beacon indices when it cannot be made so.
    """
    excluded: list[int] = []
    outliers = 0
    while True:
        failed = [t for t in beacon_tests(obs, adj, noise=noise) if t.failed]
        if not failed:
            return obs, adj, excluded, outliers
        culprits = []
        for b in sorted(set(obs.beacon.tolist())):
            rest = obs.subset(obs.beacon != b)
            if len(set(rest.beacon.tolist())) < min_beacons:
                continue
            try:
                rest_adj = rest.adjust(adj.pose, noise)
            except np.linalg.LinAlgError:
                continue
            if (
                not any(t.failed for t in beacon_tests(rest, rest_adj, noise=noise))
                and rest_adj.reference_variance <= rest_adj.chi2_upper
            ):
                culprits.append(b)
        if len(culprits) != 1:
            return culprits or [t.beacon for t in failed]
        excluded.append(culprits[0])
        obs = obs.subset(obs.beacon != culprits[0])
        adj = obs.adjust(adj.pose, noise)
        obs, adj, more = snoop(obs, adj, noise=noise)
        outliers += more
