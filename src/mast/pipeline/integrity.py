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
from numpy.typing import NDArray

from mast.core._kernels import beacon_statistics, group_residuals, standardised
from mast.core.linalg import grouped_quadratic_form
from mast.core.noise import NoiseModel
from mast.core.stats import W_TEST_ALPHA, BeaconTest, beacon_critical, w_critical
from mast.pipeline.adjustment import Adjustment, Observations

__all__ = [
    "GroupResiduals",
    "Observations",
    "Residuals",
    "beacon_tests",
    "exclude_inconsistent",
    "residual_summary",
    "snoop",
    "standardised_residuals",
]


def standardised_residuals(adj: Adjustment) -> NDArray[np.float64]:
    """Baarda's ``w_i = v_i / sigma_vi`` with ``sigma_vi^2 = sigma_i^2 - g_i Q g_i^T``."""
    return standardised(adj.jacobian, adj.cofactor, adj.sigmas_m, adj.residuals_m)


def _standardised_reference(adj: Adjustment) -> NDArray[np.float64]:
    """:func:`standardised_residuals` in numpy, the compiled kernel's reference."""
    g = adj.jacobian
    qvv = adj.sigmas_m**2 - np.einsum("ij,jk,ik->i", g, adj.cofactor, g)
    return np.asarray(adj.residuals_m / np.sqrt(np.maximum(qvv, 1e-30)), dtype=float)


def snoop(
    obs: Observations,
    adj: Adjustment,
    *,
    noise: NoiseModel,
    alpha: float = W_TEST_ALPHA,
    max_removed: int = 50,
) -> tuple[Observations, Adjustment, int]:
    """Remove, one at a time, returns whose w-test fails; returns what is left."""
    removed = 0
    while removed < max_removed and len(obs) > 4:
        w = standardised_residuals(adj)
        i = int(np.argmax(np.abs(w)))
        if abs(w[i]) <= w_critical(len(obs), alpha):
            break
        keep = np.ones(len(obs), dtype=bool)
        keep[i] = False
        obs = obs.subset(keep)
        adj = obs.adjust(adj.pose, noise)
        removed += 1
    return obs, adj, removed


def beacon_tests(
    obs: Observations,
    adj: Adjustment,
    *,
    noise: NoiseModel,
    alpha: float = W_TEST_ALPHA,
) -> list[BeaconTest[int]]:
    """Leave-one-beacon-out tests for every beacon with returns (needs two or more).

    Each beacon in turn: the others' fit, linearised at the joint solution (the
    best-determined pose, where the linear model holds best: a weak beacon left
    alone may fit a pose far enough off for a relinearised prediction to fail the
    test by itself), when the others alone determine the pose; the left-out
    beacon's misclosures ``d`` against it, and ``T_b = d^T C^-1 d`` with ``C =
    diag(sigma^2) + G_b Q_(-b) G_b^T`` plus the survey's share (a panel's surveyed
    position errs once for all its returns, ``sigma_s / |n . u|`` each), from the
    low-rank parts of ``C`` (:func:`~mast.core.linalg.grouped_quadratic_form`), never
    forming it. The others' own misfit, when larger than the a-priori precisions
    allow for (unmodelled range bias, mixed pixels), widens the test as it widens
    theirs. Compiled (:func:`mast.core._kernels.beacon_statistics`).
    """
    ids = np.unique(obs.beacon)
    if ids.size < 2:
        return []
    stat, count, tested = beacon_statistics(
        np.ascontiguousarray(adj.jacobian),
        np.ascontiguousarray(adj.residuals_m),
        np.ascontiguousarray(adj.sigmas_m),
        np.ascontiguousarray(obs.survey_levers(adj.pose)),
        np.ascontiguousarray(obs.beacon, dtype=np.intp),
        np.ascontiguousarray(obs.panel, dtype=np.intp),
        ids.astype(np.intp),
        np.ascontiguousarray(obs.survey_var, dtype=float),
        MAX_TEST_CONDITION,
    )
    return [
        BeaconTest(int(b), float(t), int(n), beacon_critical(alpha / ids.size, int(n)))
        for b, t, n, ok in zip(ids, stat, count, tested, strict=True)
        if ok
    ]


#: Condition number of the other beacons' normal matrix beyond which they do not
#: determine the pose alone (the beacon is then not tested).
MAX_TEST_CONDITION = 1e14


def _beacon_tests_reference(
    obs: Observations,
    adj: Adjustment,
    *,
    noise: NoiseModel,
    alpha: float = W_TEST_ALPHA,
) -> list[BeaconTest[int]]:
    """:func:`beacon_tests` in numpy, the compiled kernel's reference."""
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
        if not np.all(np.isfinite(n_rest)) or np.linalg.cond(n_rest) > MAX_TEST_CONDITION:
            continue  # the others alone do not determine the pose: no test
        q_rest = np.linalg.inv(n_rest)
        delta = q_rest @ (g[rest].T @ (w[rest] * v[rest]))
        d = v[mine] - g[mine] @ delta
        # C = diag(sigma^2) + G_b Q_(-b) G_b^T + the survey's share: a panel's surveyed
        # position errs once for all its returns (sigma_s / |n . u| each); C is never
        # formed (n_b x n_b), its quadratic form comes from its low-rank parts.
        try:
            t = grouped_quadratic_form(
                d,
                sig[mine] ** 2,
                g[mine],
                q_rest,
                lever_all[mine],
                obs.panel[mine],
                obs.survey_var[mine],
            )
        except np.linalg.LinAlgError:
            continue
        # The others' own misfit, when larger than the a-priori precisions allow for
        # (unmodelled range bias, mixed pixels), widens the test as it widens theirs.
        v_rest = v[rest] - g[rest] @ delta
        dof_rest = int(rest.sum()) - 3
        if dof_rest > 0:
            t /= max(1.0, float(v_rest @ (w[rest] * v_rest)) / dof_rest)
        n = int(d.size)
        out.append(BeaconTest(int(b), t, n, beacon_critical(alpha / ids.size, n)))
    return out


def exclude_inconsistent(
    obs: Observations,
    adj: Adjustment,
    *,
    noise: NoiseModel,
    min_beacons: int,
) -> tuple[Observations, Adjustment, list[int], int, list[BeaconTest[int]]] | list[int]:
    """Leave out, one at a time, a beacon whose ranges disagree with the others.

    A beacon is at fault only when its removal alone leaves the others
    consistent; if no single removal does, or more than one does, the scan
    cannot tell which beacon moved and a fix would rest on a guess.

    Returns
    -------
    (obs, adj, excluded, outliers, tests) when the rest is consistent
    (``excluded``: beacon indices left out; ``outliers``: returns data snooping
    removed on the way; ``tests``: the beacon tests of ``obs`` and ``adj``, all
    passed), or the list of suspect beacon indices when it cannot be made so.
    """
    excluded: list[int] = []
    outliers = 0
    while True:
        tests = beacon_tests(obs, adj, noise=noise)
        failed = [t for t in tests if t.failed]
        if not failed:
            return obs, adj, excluded, outliers, tests
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


@dataclass(frozen=True, slots=True)
class GroupResiduals:
    """Residuals of one group of returns (a beacon, a panel)."""

    returns: int
    rms_m: float
    max_abs_w: float


@dataclass(frozen=True, slots=True)
class Residuals:
    """What a survey adjustment report lists about the residuals of a fix.

    Attributes
    ----------
    rms_m : float
        RMS of the range residuals ``v`` (metres).
    max_abs_w : float
        Largest standardised residual |w| (Baarda's w-test statistic).
    w_critical : float
        The w-test's critical value at 0.1 %, shared over all returns.
    per_beacon : dict
        Beacon id -> its returns' :class:`GroupResiduals`.
    per_panel : dict
        (beacon id, panel 1..3) -> its returns' :class:`GroupResiduals`.
    beacon_tests : dict
        Beacon id -> its left-out :class:`BeaconTest` (two or more beacons).
    """

    rms_m: float
    max_abs_w: float
    w_critical: float
    per_beacon: dict[str, GroupResiduals]
    per_panel: dict[tuple[str, int], GroupResiduals]
    beacon_tests: dict[str, BeaconTest[int]]


def _groups(
    keys: NDArray[np.intp], v: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.intp], list[GroupResiduals]]:
    """The residuals of each group of returns sharing a key: the keys, sorted, and
    their returns' count, RMS of ``v`` and largest ``|w|``."""
    names, count, rms, largest = group_residuals(np.ascontiguousarray(keys, dtype=np.intp), v, w)
    return names, [
        GroupResiduals(int(c), float(r), float(m))
        for c, r, m in zip(count, rms, largest, strict=True)
    ]


def _groups_reference(
    keys: NDArray[np.intp], v: NDArray[np.float64], w: NDArray[np.float64]
) -> tuple[NDArray[np.intp], list[GroupResiduals]]:
    """:func:`_groups` in numpy, the compiled kernel's reference."""
    names, at = np.unique(keys, return_inverse=True)
    at = at.reshape(-1)
    count = np.bincount(at, minlength=names.size)
    rms = np.sqrt(np.bincount(at, weights=v * v, minlength=names.size) / count)
    order = np.argsort(at, kind="stable")
    starts = np.concatenate(([0], np.cumsum(count)[:-1]))
    largest = np.maximum.reduceat(np.abs(w[order]), starts)
    return names, [
        GroupResiduals(int(c), float(r), float(m))
        for c, r, m in zip(count, rms, largest, strict=True)
    ]


def residual_summary(
    obs: Observations,
    adj: Adjustment,
    *,
    ids: tuple[str, ...],
    panel_numbers: NDArray[np.intp],
    noise: NoiseModel,
    tests: list[BeaconTest[int]] | None = None,
) -> Residuals:
    """Residuals of an adjustment, overall, per beacon and per panel, with the beacon tests.

    ``ids`` names the beacon indices of ``obs.beacon``; ``panel_numbers`` gives
    the panel number (1..3) of each panel index in ``obs.panel``; ``tests`` are
    the beacon tests of ``obs`` and ``adj`` when already computed.
    """
    v, w = adj.residuals_m, standardised_residuals(adj)
    beacons, by_beacon = _groups(obs.beacon, v, w)
    per_beacon = {ids[b]: g for b, g in zip(beacons, by_beacon, strict=True)}
    panels, by_panel = _groups(obs.panel, v, w)
    owner = np.zeros(int(panels.max()) + 1 if panels.size else 0, dtype=np.intp)
    owner[obs.panel] = obs.beacon  # a panel's returns all belong to its one beacon
    per_panel = {
        (ids[int(owner[k])], int(panel_numbers[k])): g
        for k, g in zip(panels, by_panel, strict=True)
    }
    if tests is None:
        tests = beacon_tests(obs, adj, noise=noise)
    return Residuals(
        rms_m=float(np.sqrt(np.mean(v**2))),
        max_abs_w=float(np.max(np.abs(w))),
        w_critical=w_critical(len(obs)),
        per_beacon=per_beacon,
        per_panel=per_panel,
        beacon_tests={ids[t.beacon]: t for t in tests},
    )
