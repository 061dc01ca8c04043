"""The MAST locator: one scan and a beacon survey in, a fix (or a reasoned no-fix) out.

Stages, as in the paper's "MAST Algorithm":

1. :func:`mast.pipeline.segmentation.segment_scan` — PCA line segmentation;
2. :func:`mast.pipeline.identification.identify_panels` — Table 1 panel identification;
3. :func:`mast.pipeline.hypotheses.pose_hypotheses` — template matching between beacons;
4. :func:`mast.pipeline.alignment.similarity_transform` and
   :func:`mast.pipeline.alignment.icp_point_to_line` — alignment and verification;
5. :func:`mast.pipeline.adjustment.adjust_pose` — least-squares adjustment and statistics.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.geometry import PanelSet, first_hits
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.pipeline.adjustment import MIN_INCIDENCE_COS, Adjustment, adjust_pose, range_model
from mast.pipeline.alignment import IcpResult, Similarity, icp_point_to_line
from mast.pipeline.bounds import cramer_rao_bound
from mast.pipeline.hypotheses import Hypothesis, MatchingConfig, node_sigma, pose_hypotheses
from mast.pipeline.identification import IdentificationConfig, PanelIdentification, identify_panels
from mast.pipeline.integrity import Observations, beacon_tests, snoop
from mast.pipeline.segmentation import Segmentation, SegmentationConfig, segment_scan

__all__ = ["NO_FIX_REASONS", "Fix", "LocatorConfig", "Verified", "locate"]

#: Every reason a scan can get no fix, with what it means.
NO_FIX_REASONS: dict[str, str] = {
    "no_beacon": "no corner of the scan matches any surveyed beacon's panels",
    "one_beacon": "beacon panels were identified on fewer than two beacons",
    "inconsistent": "the identified beacons do not agree with their surveyed geometry",
    "ambiguous": "two different poses explain the scan equally well",
    "degenerate_geometry": "the panels seen do not determine position and azimuth",
}


@dataclass(frozen=True, slots=True)
class LocatorConfig:
    """Everything the locator can be told; defaults suit a typical 2D scanner.

    Attributes
    ----------
    range_sigma_m : float
        A-priori standard deviation of one range.
    angle_sigma_rad : float
        A-priori standard deviation of one beam angle.
    min_beacons : int
        Beacons that must support a fix (each with two panels seen).
    min_panel_points : int
        Returns a panel needs to count as seen.
    gate_sigmas : float
        Returns farther than this many standard deviations from their panel
        are not used.
    survey_sigma_m : float
        Standard deviation of surveyed edge coordinates: widens the gates and
        adds its share to the fix's covariance (0 for a simulated, exact survey).
    coarse_gates_m : tuple of float
        Association gates while the pose is still rough (ICP stages).
    max_violation_fraction : float
        Fraction of the beams that should hit a surveyed panel but pass
        through it, beyond which a hypothesis is refused.
    min_coverage : float
        Fraction of the beams that should land on a beacon (at the pose) that
        must do so for the beacon to confirm the pose.
    ambiguity_ratio : float
        A second pose with this fraction of the best one's support makes the
        scan ambiguous.
    near : Pose2D, optional
        A prior position (and azimuth): hypotheses farther than
        ``near_radius_m`` (or, when ``near_azimuth_tol_rad`` is set, turned
        further than that) are not considered. It only narrows the search;
        an unambiguous scan needs none.
    """

    range_sigma_m: float = 0.01
    angle_sigma_rad: float = 0.0
    min_beacons: int = 2
    min_panel_points: int = 3
    gate_sigmas: float = 4.0
    survey_sigma_m: float = 0.003
    coarse_gates_m: tuple[float, ...] = (0.15, 0.05)
    max_violation_fraction: float = 0.1
    min_coverage: float = 0.5
    ambiguity_ratio: float = 0.8
    near: Pose2D | None = None
    near_radius_m: float = 10.0
    near_azimuth_tol_rad: float | None = None
    segmentation: SegmentationConfig = field(default_factory=SegmentationConfig)
    identification: IdentificationConfig = field(default_factory=IdentificationConfig)
    matching: MatchingConfig = field(default_factory=MatchingConfig)

    @property
    def final_gate_m(self) -> float:
        return self.gate_sigmas * math.hypot(self.range_sigma_m, self.survey_sigma_m)


@dataclass(frozen=True, eq=False)
class Verified:
    """A hypothesis after ICP and its checks against the whole survey."""

    hypothesis: Hypothesis
    icp: IcpResult
    panel_points: dict[tuple[str, int], int]
    supported: tuple[str, ...]
    checks: dict[str, BeamCheck]

    @property
    def violations(self) -> int:
        """Beams that went through where a surveyed panel should be."""
        return sum(c.through for c in self.checks.values())

    @property
    def score(self) -> tuple[int, int, float]:
        return (len(self.supported), self.icp.inliers, -self.icp.rms_m)


@dataclass(frozen=True, eq=False)
class Fix:
    """What the locator concluded about one scan.

    ``status`` is ``"fix"`` with ``pose`` and ``adjustment``, or ``"no_fix"``
    with ``reason`` (a key of :data:`NO_FIX_REASONS`) and ``detail``.
    The remaining fields keep what each stage found, for people debugging.
    """

    status: str
    pose: Pose2D | None
    adjustment: Adjustment | None
    beacons: tuple[str, ...]
    panels: dict[str, list[int]]
    points_used: int
    reason: str | None
    detail: str
    segmentation: Segmentation
    identification: PanelIdentification
    hypotheses: tuple[Hypothesis, ...]
    verified: tuple[Verified, ...]
    chosen: Verified | None
    observations: NDArray[np.intp]
    """Beam indices used in the adjustment."""
    observation_panels: NDArray[np.intp]
    """Panel (index into the survey's PanelSet) of each observation."""
    elapsed_s: float
    config: LocatorConfig
    crb: NDArray[np.float64] | None = None
    """Cramer-Rao bound of (E, N, A) for the returns used, at the fixed pose."""
    excluded_beacons: tuple[str, ...] = ()
    """Beacons seen but left out because their ranges disagree with the others
    (moved or mis-surveyed)."""
    outliers_removed: int = 0
    """Returns removed by data snooping."""

    @property
    def ok(self) -> bool:
        return self.status == "fix"

    @property
    def similarity(self) -> Similarity | None:
        return None if self.chosen is None else self.chosen.hypothesis.similarity

    @property
    def icp_iterations(self) -> int:
        return 0 if self.chosen is None else self.chosen.icp.iterations


def _support(
    icp: IcpResult,
    panels: PanelSet,
    survey: Survey,
    ident: PanelIdentification,
    noise_m: float,
    checks: dict[str, BeamCheck],
    cfg: LocatorConfig,
) -> tuple[dict[tuple[str, int], int], tuple[str, ...]]:
    """Beacons that confirm a pose, and the returns on each panel.

    A beacon confirms the pose when, at that pose, (1) two of its panels
    carry at least ``min_panel_points`` returns, (2) a corner of the scan
    identified as one of its edges lands on that surveyed edge, and (3) at
    least ``min_coverage`` of the unoccluded beams that should hit it do.
    """
    counts: dict[tuple[str, int], int] = {}
    idx, n = np.unique(icp.panel[icp.panel >= 0], return_counts=True)
    for k, c in zip(idx, n, strict=True):
        counts[(panels.ids[panels.beacon[k]], int(panels.panel[k]))] = int(c)
    per_beacon: dict[str, int] = {}
    for (b, _p), c in counts.items():
        if c >= cfg.min_panel_points:
            per_beacon[b] = per_beacon.get(b, 0) + 1
    node_ok: set[str] = set()
    for node in ident.nodes:
        if node.beacon in node_ok or per_beacon.get(node.beacon, 0) < 2:
            continue
        mapped = icp.pose.scanner_to_mine(node.node_scanner[None, :])[0]
        edge = survey[node.beacon].edges[node.edge - 1]
        sig = node_sigma(node, noise_m)
        if math.dist(mapped, edge) <= cfg.gate_sigmas * math.hypot(
            sig, cfg.survey_sigma_m, cfg.range_sigma_m
        ):
            node_ok.add(node.beacon)
    supported = tuple(
        sorted(b for b in node_ok if checks.get(b, BeamCheck()).coverage >= cfg.min_coverage)
    )
    return counts, supported


@dataclass(frozen=True, slots=True)
class BeamCheck:
    """What the beams predicted to land on one beacon's panels actually did.

    ``hit``: returned within the gate of the predicted range; ``occluded``:
    returned short (something stood in front: allowed); ``through``: returned
    beyond the panel (the beam went where the beacon should be: evidence
    against the pose); ``missing``: no return.
    """

    hit: int = 0
    occluded: int = 0
    through: int = 0
    missing: int = 0

    @property
    def coverage(self) -> float:
        """Share of the unoccluded returns that landed on the panels."""
        seen = self.hit + self.through
        return self.hit / seen if seen else 0.0


def _check_beams(
    scan: Scan, pose: Pose2D, panels: PanelSet, gate_m: float, margin_m: float = 0.02
) -> dict[str, BeamCheck]:
    """Predict, at ``pose``, every beam that must cross a surveyed panel and compare.

    Panel ends are shrunk by ``margin_m`` and beams within 10 degrees of a
    panel's plane are left out: near an edge or at grazing incidence a beam
    may legitimately miss.
    """
    dirs = pose.beam_directions(scan.angles_rad)
    a = panels.a + margin_m * panels.direction
    b = panels.b - margin_m * panels.direction
    t, j = first_hits(pose.position, dirs, a, b)
    hit = (j >= 0) & (t <= scan.range_max_m) & (t >= scan.range_min_m)
    nu = np.abs(np.einsum("ij,ij->i", panels.normal[np.maximum(j, 0)], dirs))
    hit &= nu > math.sin(math.radians(10.0))
    r = scan.ranges_m
    counts: dict[str, list[int]] = {}
    for i in np.flatnonzero(hit):
        c = counts.setdefault(panels.ids[panels.beacon[j[i]]], [0, 0, 0, 0])
        if not scan.valid[i]:
            c[3] += 1
        elif r[i] < t[i] - gate_m:
            c[1] += 1
        elif r[i] > t[i] + gate_m:
            c[2] += 1
        else:
            c[0] += 1
    return {bid: BeamCheck(*c) for bid, c in counts.items()}


def _no_fix(reason: str, detail: str, **kw: object) -> dict[str, object]:
    return {"status": "no_fix", "reason": reason, "detail": detail, **kw}


def locate(scan: Scan, survey: Survey, *, config: LocatorConfig | None = None) -> Fix:
    """Fix the scanner's pose from one scan of surveyed beacons.

    Parameters
    ----------
    scan : Scan
        One horizontal scan, scanner frame.
    survey : Survey
        The surveyed beacons.
    config : LocatorConfig, optional

    Returns
    -------
    Fix
        ``status == "fix"`` with the adjusted pose and its statistics, or
        ``"no_fix"`` with a reason from :data:`NO_FIX_REASONS`. The locator
        never raises for what a scan contains.
    """
    cfg = config or LocatorConfig()
    t0 = time.perf_counter()
    seg_cfg = cfg.segmentation
    segmentation = segment_scan(scan, seg_cfg)
    ident = identify_panels(segmentation, survey, cfg.identification)
    panels = PanelSet.from_survey(survey)
    common: dict[str, object] = {
        "segmentation": segmentation,
        "identification": ident,
        "config": cfg,
    }

    def finish(**kw: object) -> Fix:
        fields: dict[str, object] = {
            "status": "fix",
            "pose": None,
            "adjustment": None,
            "beacons": (),
            "panels": {},
            "points_used": 0,
            "reason": None,
            "detail": "",
            "hypotheses": (),
            "verified": (),
            "chosen": None,
            "observations": np.zeros(0, dtype=np.intp),
            "observation_panels": np.zeros(0, dtype=np.intp),
            **common,
            **kw,
        }
        fields["elapsed_s"] = time.perf_counter() - t0
        return Fix(**fields)  # type: ignore[arg-type]

    seen = sorted({n.beacon for n in ident.nodes})
    if not seen:
        return finish(
            **_no_fix(
                "no_beacon", f"{len(segmentation.segments)} segments, no beacon corner identified"
            )
        )
    if len(seen) < cfg.min_beacons:
        return finish(**_no_fix("one_beacon", f"only beacon {', '.join(seen)} identified"))
    hyps = pose_hypotheses(ident, segmentation, survey, cfg.matching)
    if not hyps:
        return finish(
            **_no_fix(
                "inconsistent",
                f"corners matching beacons {', '.join(seen)} disagree with the surveyed geometry",
            )
        )
    if cfg.near is not None:
        hyps = [h for h in hyps if _near(h.similarity.pose(), cfg)]
        if not hyps:
            return finish(
                **_no_fix(
                    "inconsistent",
                    f"no pose within {cfg.near_radius_m:g} m of the prior {cfg.near}",
                )
            )
    _, pts = scan.points()
    gates = (*cfg.coarse_gates_m, cfg.final_gate_m)
    verified: list[Verified] = []
    for h in hyps:
        icp = icp_point_to_line(pts, h.similarity.pose(), panels, gates_m=gates)
        checks = _check_beams(scan, icp.pose, panels, cfg.final_gate_m)
        counts, supported = _support(icp, panels, survey, ident, segmentation.noise_m, checks, cfg)
        if not set(h.beacons) <= set(supported):
            continue
        v = Verified(h, icp, counts, supported, checks)
        unoccluded = sum(c.hit + c.through for c in checks.values())
        if v.violations > max(3, cfg.max_violation_fraction * unoccluded):
            continue
        verified.append(v)
    if not verified:
        return finish(
            hypotheses=tuple(hyps),
            **_no_fix(
                "inconsistent", f"no pose from beacons {', '.join(seen)} is confirmed by the scan"
            ),
        )
    verified.sort(key=lambda v: v.score, reverse=True)
    best = verified[0]

    def refuse(reason: str, detail: str) -> Fix:
        return finish(
            hypotheses=tuple(hyps),
            verified=tuple(verified),
            chosen=best,
            **_no_fix(reason, detail),
        )

    if len(best.supported) < cfg.min_beacons:
        return refuse(
            "one_beacon", f"only beacon {', '.join(best.supported)} confirmed with two panels"
        )
    for other in verified[1:]:
        d = math.hypot(
            other.icp.pose.easting - best.icp.pose.easting,
            other.icp.pose.northing - best.icp.pose.northing,
        )
        da = abs(math.remainder(other.icp.pose.azimuth - best.icp.pose.azimuth, 2 * math.pi))
        if d < 0.1 and da < math.radians(1.0):
            continue  # the same pose reached from another pair of nodes
        if (
            len(other.supported) >= len(best.supported)
            and other.icp.inliers >= cfg.ambiguity_ratio * best.icp.inliers
        ):
            return refuse(
                "ambiguous",
                f"poses {best.icp.pose} ({', '.join(best.supported)}) and "
                f"{other.icp.pose} ({', '.join(other.supported)}) fit equally well",
            )
    # Adjustment on the returns of the supporting beacons, and of any other beacon whose
    # panels the beams confirm at this pose (more returns, a tighter fix); re-associate
    # as it moves.
    agree = set(best.supported) | {
        b
        for b, c in best.checks.items()
        if c.coverage >= cfg.min_coverage and c.hit >= cfg.min_panel_points
    }
    keep = np.flatnonzero(np.isin(panels.beacon, [panels.ids.index(b) for b in agree]))
    pose = best.icp.pose
    adj: Adjustment | None = None
    used = np.zeros(0, dtype=np.intp)
    used_panels = np.zeros(0, dtype=np.intp)
    for _ in range(8):
        beams, pk = _ray_association(
            scan, pose, panels, keep, cfg, None if adj is None else adj.cofactor
        )
        nrm = panels.normal[pk]
        if adj is not None:
            # Residuals far outside the spread of the others (robust scale, so the
            # test tightens on clean data) are not ranges to the panel.
            good = _robust_inliers(adj, pose, scan, beams, nrm, panels.a[pk], cfg)
            beams, pk, nrm = beams[good], pk[good], nrm[good]
        if np.array_equal(beams, used) and adj is not None:
            break
        if beams.size < 4:
            return refuse("degenerate_geometry", f"only {beams.size} returns on the panels")
        offsets = np.einsum("ij,ij->i", nrm, panels.a[pk])
        try:
            adj = adjust_pose(
                pose,
                scan.angles_rad[beams],
                scan.ranges_m[beams],
                nrm,
                offsets,
                range_sigma_m=cfg.range_sigma_m,
                angle_sigma_rad=cfg.angle_sigma_rad,
            )
        except np.linalg.LinAlgError:
            adj = None
        if (
            adj is None
            or not np.all(np.isfinite(adj.cofactor))
            or np.linalg.cond(_scaled(adj.cofactor)) > 1e10
        ):
            return refuse(
                "degenerate_geometry",
                "the panels seen do not constrain all of E, N and azimuth",
            )
        used, used_panels = beams, pk
        pose = adj.pose
    assert adj is not None
    obs = Observations(
        used,
        scan.angles_rad[used],
        scan.ranges_m[used],
        panels.normal[used_panels],
        np.einsum("ij,ij->i", panels.normal[used_panels], panels.a[used_panels]),
        used_panels,
        panels.beacon[used_panels],
    )
    sig = {"range_sigma_m": cfg.range_sigma_m, "angle_sigma_rad": cfg.angle_sigma_rad}
    obs, adj, outliers = snoop(
        obs, adj, range_sigma_m=cfg.range_sigma_m, angle_sigma_rad=cfg.angle_sigma_rad
    )
    excluded: list[str] = []
    while True:
        tests = beacon_tests(obs, adj, survey_sigma_m=cfg.survey_sigma_m, **sig)
        failed = [t for t in tests if t.failed]
        if not failed:
            break
        # Which beacon is at fault: the one whose removal leaves the others consistent.
        # If no single removal does, or more than one does, the scan cannot tell which
        # beacon moved, and a fix would rest on a guess.
        present = sorted(set(obs.beacon.tolist()))
        culprits = []
        for b in present:
            rest = obs.subset(obs.beacon != b)
            if len(set(rest.beacon.tolist())) < cfg.min_beacons:
                continue
            try:
                rest_adj = rest.adjust(adj.pose, **sig)
            except np.linalg.LinAlgError:
                continue
            rest_tests = beacon_tests(rest, rest_adj, survey_sigma_m=cfg.survey_sigma_m, **sig)
            if (
                not any(t.failed for t in rest_tests)
                and rest_adj.reference_variance <= rest_adj.chi2_upper
            ):
                culprits.append(b)
        if len(culprits) != 1:
            names = sorted(panels.ids[b] for b in (culprits or [t.beacon for t in failed]))
            return refuse(
                "inconsistent",
                f"the beacons seen disagree with each other; {' or '.join(names)} may have "
                "been moved or mis-surveyed",
            )
        excluded.append(panels.ids[culprits[0]])
        obs = obs.subset(obs.beacon != culprits[0])
        adj = obs.adjust(adj.pose, **sig)
        obs, adj, more = snoop(
            obs, adj, range_sigma_m=cfg.range_sigma_m, angle_sigma_rad=cfg.angle_sigma_rad
        )
        outliers += more
    used, used_panels, offsets = obs.beam, obs.panel, obs.offsets
    if cfg.survey_sigma_m > 0:
        adj = replace(
            adj, covariance=adj.covariance + _survey_covariance(adj, obs, cfg.survey_sigma_m)
        )
    bound = cramer_rao_bound(
        adj.pose,
        scan.angles_rad[used],
        panels.normal[used_panels],
        offsets,
        range_sigma_m=cfg.range_sigma_m,
        angle_sigma_rad=cfg.angle_sigma_rad,
    )
    panels_used: dict[str, list[int]] = {}
    for k in np.unique(used_panels):
        panels_used.setdefault(panels.ids[panels.beacon[k]], []).append(int(panels.panel[k]))
    return finish(
        pose=adj.pose,
        adjustment=adj,
        beacons=tuple(sorted(panels_used)),
        panels=panels_used,
        points_used=int(used.size),
        hypotheses=tuple(hyps),
        verified=tuple(verified),
        chosen=best,
        observations=used,
        observation_panels=used_panels,
        crb=bound,
        excluded_beacons=tuple(excluded),
        outliers_removed=outliers,
    )


def _ray_association(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    keep: NDArray[np.intp],
    cfg: LocatorConfig,
    pose_cofactor: NDArray[np.float64] | None,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Beams whose ray, cast from ``pose``, first meets a kept panel, and that panel.

    Casting the ray decides which panel a beam near a corner hits (the nearer
    one), where the nearest line to the return would be a coin toss within
    the noise. A return is kept when it lies within ``gate_sigmas`` standard
    deviations of the predicted range, counting the pose's own uncertainty
    (``g^T Q g``, once an adjustment gives ``Q``): a beam that meets a panel
    obliquely, far away, is very sensitive to the azimuth and would otherwise
    be gated out exactly when it carries the most information. Beams within
    2 degrees of grazing are left out.
    """
    beams = np.flatnonzero(scan.valid)
    dirs = pose.beam_directions(scan.angles_rad[beams])
    t, j = first_hits(pose.position, dirs, panels.a[keep], panels.b[keep])
    hit = j >= 0
    pk = keep[np.maximum(j, 0)]
    nrm = panels.normal[pk]
    nu = np.abs(np.einsum("ij,ij->i", nrm, dirs))
    gate = np.full(beams.size, cfg.final_gate_m)
    if pose_cofactor is not None and np.any(hit):
        offsets = np.einsum("ij,ij->i", nrm, panels.a[pk])
        _rho, jac, d_phi = range_model(pose, scan.angles_rad[beams], nrm, offsets)
        var = cfg.range_sigma_m**2 + cfg.survey_sigma_m**2 + (d_phi * cfg.angle_sigma_rad) ** 2
        pred = np.einsum("ij,jk,ik->i", jac, pose_cofactor, jac)
        gate = cfg.gate_sigmas * np.sqrt(var + np.where(np.isfinite(pred), pred, 0.0))
    ok = hit & (np.abs(scan.ranges_m[beams] - t) <= gate) & (nu > MIN_INCIDENCE_COS)
    return beams[ok], pk[ok]


def _robust_inliers(
    adj: Adjustment,
    pose: Pose2D,
    scan: Scan,
    beams: NDArray[np.intp],
    normals: NDArray[np.float64],
    points_on: NDArray[np.float64],
    cfg: LocatorConfig,
) -> NDArray[np.bool_]:
    """Observations within ``gate_sigmas`` robust standard deviations of the prediction.

    The standard deviation of ``r - rho`` is that of the range and of the
    predicted range (``g^T Q g``, the pose's uncertainty seen along the beam),
    both scaled by 1.4826 times the median absolute standardised residual of
    the previous adjustment, capped at 1 (the a-priori precision): the test
    tightens on clean data, and never below a numerical floor.
    """
    std = adj.residuals_m / adj.sigmas_m
    scale = min(1.0, 1.4826 * float(np.median(np.abs(std)))) if std.size else 1.0
    offsets = np.einsum("ij,ij->i", normals, points_on)
    rho, jac, d_phi = range_model(pose, scan.angles_rad[beams], normals, offsets)
    var = cfg.range_sigma_m**2 + (d_phi * cfg.angle_sigma_rad) ** 2
    pred = np.einsum("ij,jk,ik->i", jac, adj.cofactor, jac)
    sig = np.sqrt(var + pred)
    floor = 1e-7 * (1.0 + np.abs(rho))
    return np.asarray(
        np.abs(scan.ranges_m[beams] - rho) <= cfg.gate_sigmas * np.maximum(scale * sig, floor)
    )


def _survey_covariance(
    adj: Adjustment, obs: Observations, survey_sigma_m: float
) -> NDArray[np.float64]:
    """Pose covariance from the surveyed panels' own position errors.

    A panel surveyed ``sigma_s`` off across its face moves every range to it by
    ``sigma_s / |n . u|`` together; through the estimator ``K = Q G^T W`` that
    adds ``K S K^T`` to the noise covariance (S: those shared range errors).
    """
    lever = obs.survey_levers(adj.pose)
    k = adj.cofactor @ (adj.jacobian / (adj.sigmas_m**2)[:, None]).T  # (3, n)
    out = np.zeros((3, 3))
    for p in np.unique(obs.panel):
        sel = obs.panel == p
        col = k[:, sel] @ lever[sel]
        out += survey_sigma_m**2 * np.outer(col, col)
    return out


def _near(pose: Pose2D, cfg: LocatorConfig) -> bool:
    assert cfg.near is not None
    d = math.hypot(pose.easting - cfg.near.easting, pose.northing - cfg.near.northing)
    if d > cfg.near_radius_m:
        return False
    if cfg.near_azimuth_tol_rad is None:
        return True
    return (
        abs(math.remainder(pose.azimuth - cfg.near.azimuth, 2 * math.pi))
        <= cfg.near_azimuth_tol_rad
    )


def _scaled(q: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.sqrt(np.abs(np.diag(q)))
    d[d == 0] = 1.0
    return np.asarray(q / np.outer(d, d))
