"""Verification: what every beam says of a pose hypothesis.

A hypothesis is refined by point-to-line ICP, then judged by all the beams:
each beam that, at the pose, should meet a surveyed panel either returns there
(a hit), returns short (something stands in front: allowed), returns beyond
(it went where the panel should be: evidence against the pose) or not at all.
From that come

* the beacons that **support** the pose: two of their panels carry returns,
  most beams that should reach them do, a corner of the scan identified as
  one of their edges lands on that edge *or* their returns are explained by
  the beacon better than by clutter (no surface runs on past the beacon's
  surveyed ends, as a wall or a shelf would);
* a **log-likelihood ratio** of the pose against background clutter, summed
  over every beam that should meet a surveyed panel: it rewards hits, charges
  every beam that passes through a surveyed panel, and so counts every beacon
  the pose says should be seen. Competing poses are compared by it.

References
----------
S. Thrun, W. Burgard and D. Fox, *Probabilistic Robotics*, 2005, sec. 6.3
(the beam model of range finders).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core._kernels import first_same
from mast.core.geometry import PanelSet, first_hits
from mast.core.index import SurveyIndex
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D, wrap_angles
from mast.core.quantiles import chi2_isf, chi2_sf
from mast.core.scan import Scan
from mast.pipeline.adjustment import MIN_INCIDENCE_COS
from mast.pipeline.alignment import IcpResult, icp_point_to_line
from mast.pipeline.edges import at_silhouette, jump_m
from mast.pipeline.hypotheses import Hypothesis, corner_covariance, node_sigma
from mast.pipeline.identification import PanelIdentification
from mast.pipeline.segmentation import Segmentation

__all__ = ["BeamCheck", "Refinement", "VerificationConfig", "Verified", "check_beams", "verify"]


@dataclass(frozen=True, slots=True)
class VerificationConfig:
    """Thresholds of verification.

    Attributes
    ----------
    min_panel_points : int
        Returns a panel needs to count as seen.
    gate_sigmas : float
        Returns farther than this many standard deviations from their panel
        are not hits.
    coarse_gates_m : tuple of float
        ICP association gates while the pose is still rough.
    start_gate_sigmas, max_start_gate_m : float
        A hypothesis less certain than the first coarse gate (its
        ``spread_m`` times ``start_gate_sigmas``) starts ICP with a gate that
        wide, up to ``max_start_gate_m``; certain ones keep the narrow gates,
        which clutter near the beacons cannot drag away.
    max_violation_fraction : float
        Fraction of the beams that should hit a surveyed panel but pass
        through it, beyond which a hypothesis is refused (never fewer than
        ``min_violations``).
    min_violations : int
        Through-beams always tolerated (edges, mixed pixels).
    min_coverage : float
        Share of the unoccluded beams that should land on a beacon that must,
        for the beacon to support the pose.
    edge_margin_m : float
        Panel ends shrunk by this much when predicting which beams must hit.
    min_check_incidence_deg : float
        Beams closer than this to a panel's plane are not predicted to hit it.
    overrun_reach_m : float
        How far past a panel's surveyed end returns on its line are looked for.
    max_overrun_fraction : float
        Returns running on past a panel's ends, as a fraction of its hits
        (never fewer than ``min_panel_points``), beyond which the beacon's
        returns are taken for a longer surface (clutter) and do not support.
    overrun_slope_sigmas : float
        Returns past a panel's end whose offset from its line drifts by more
        than this many standard deviations of the slope are another surface
        crossing the line, not the line running on.
    wall_past_free_ends : bool
        A beacon (without a node of its own, its returns on its panels within
        their noise) may have returns in a middle panel's line past the free
        end of a short outer panel: that is the wall the beacon is mounted on
        (rough rock standing in the middle panel's line). The overrun search
        stops at the beacon's free end when the full reach of
        ``overrun_reach_m`` past the node finds the panel running on. (A
        look-alike read as the beacon misfits its shape and is refused for
        that.)
    through_probability : float
        Probability of a return beyond a surveyed panel at the true pose
        (edges, mixed pixels): what each through-beam costs in the likelihood.
    straight_alpha : float
        Significance at which the returns on a beacon must prefer its surveyed
        shape to one straight line through them (a likelihood-ratio test), for
        the beacon to support without an identified node.
    corner_reach_m : float
        A corner of the scan this close to a beacon's node edge, but not on
        it (farther than ``gate_sigmas`` of the corner's own uncertainty),
        keeps the beacon from supporting the pose without an identified node.
    duplicate_m, duplicate_rad : float
        A hypothesis starting this close to an already verified pose is not
        verified again, nor is a refined pose this close to one kept. A few
        sigmas of a fix: a start 4 cm and 0.5 degrees from a pose that misfits
        one beacon can refine to the pose that fits both (shared hostile scene
        0046 with a prior, when these were 5 cm and 0.5 degrees).
    placed_support : bool
        A beacon without a node of its own may support a pose on which
        another beacon's identified corner lands on its surveyed edge when
        its returns lie on its panels within their noise and fit its shape
        better than one straight line, though not by the margin of
        ``straight_alpha`` (a small beacon's bend inside the noise).
    grazing_noise_floor : float
        Whether returns lie on their panels within their noise
        (:func:`_in_place`) weighs each offset by the range noise across
        its panel, never less than this fraction of it: seen at grazing
        incidence a beam's footprint and jitter put returns off a surface by
        far more than its range noise projected on the normal (on the shared
        independent scenes, 0.2-1.2 of the range noise where the projection
        gives 0.15).
    same_reading_share : float
        Two verified poses that put at least this share of their returns on
        the same panels read the scan alike (:meth:`Verified.reads_alike`):
        they do not compete as two places the scan could have been taken.
    near_short_m, max_near_share : float
        A return no more than ``near_short_m`` short of where a panel should be
        (beyond the gate) is what stands right in front of it. A real panel is
        seldom hugged by clutter (at the true pose on the shared independent
        scenes, 1 beacon in 146 of the hostile ones, none of the noisy ones,
        had more than a quarter of its returns so), but rock read as a panel
        has more rock just in front of it: a beacon without an identified
        corner of its own whose near-short returns are more than
        ``max_near_share`` of them and its hits does not support the pose
        unless all three of its panels carry returns (a look-alike 117 m away
        on a long drive, seed 2 at 40 Hz scan 7724: 7 near-short to 12 hits on
        two panels of the beacon that was not there; a box against a beacon
        on shared hostile 0066: 41 near-short, 18 hits on three panels). Each
        near-short return weighs ``log(near_probability)`` in the beam
        likelihood, as a through-beam weighs ``log(through_probability)``.
    look_alike_reach_m, look_alike_reach_rad : float
        How far ICP is taken to carry a one-beacon hypothesis' start (a corner,
        or one beacon's two corners, matched to one beacon of its design: a
        look-alike wherever the mine repeats it). A beacon with fewer than
        ``2 * min_panel_points`` returns within this reach of its panels at the
        start (a return at range ``r`` moves by ``reach_m + r * reach_rad``,
        plus the final gate) cannot be among the refined pose's beacons. Such a
        start whose own beacon cannot is not refined, and one that leaves fewer
        than two beacons is refined only if the poses kept do not settle the
        choice without it (the caller's ``settled``). On drive scans with two
        beacons in view, 7 of 18 ICP runs a scan went to such look-alikes,
        which could change nothing; of them, 1 start in 1 651 so set aside had
        refined to two beacons' returns (an ICP that slid 2.5 m and 42 degrees,
        onto the pose already kept). Against a 200-beacon survey of repeated
        designs, 1 306 of 2 191 such starts are left unrefined (20 scans).
    wall_behind_m : float
        A return beyond a panel that lands within this of its beacon's wall
        (the line of its free ends, e1-e4, and as far past them) is no verdict
        (counted ``missing``) rather than a through-beam. 0 in a 2D scan,
        where a beam at a panel's bearing is at its height. A plan view of a
        3D frame cannot tell a beam through a panel from one passing over or
        under it onto the wall the beacon is mounted on: the 3D locator's
        lenient plan view (:data:`mast.pipeline.locator3d.LENIENT_WALL_M`).
    """

    min_panel_points: int = 3
    gate_sigmas: float = 4.0
    coarse_gates_m: tuple[float, ...] = (0.15, 0.05)
    start_gate_sigmas: float = 3.0
    max_start_gate_m: float = 0.5
    max_violation_fraction: float = 0.1
    min_violations: int = 3
    min_coverage: float = 0.5
    edge_margin_m: float = 0.02
    min_check_incidence_deg: float = 10.0
    overrun_reach_m: float = 0.3
    max_overrun_fraction: float = 0.25
    overrun_slope_sigmas: float = 3.0
    wall_past_free_ends: bool = True
    through_probability: float = 0.01
    corner_reach_m: float = 0.3
    straight_alpha: float = 1e-3
    duplicate_m: float = 0.02
    duplicate_rad: float = math.radians(0.2)
    placed_support: bool = True
    grazing_noise_floor: float = 0.5
    same_reading_share: float = 0.8
    near_short_m: float = 0.3
    max_near_share: float = 0.25
    near_probability: float = 0.3
    look_alike_reach_m: float = 1.0
    look_alike_reach_rad: float = math.radians(3.0)
    wall_behind_m: float = 0.0


@dataclass(frozen=True, slots=True)
class BeamCheck:
    """What the beams predicted to land on one beacon's panels actually did.

    ``hit``: returned within the gate of the predicted range; ``occluded``:
    returned short (something stood in front: allowed); ``through``: returned
    beyond the panel (the beam went where the beacon should be: evidence
    against the pose); ``missing``: no return (or, with
    ``VerificationConfig.wall_behind_m``, one beyond the panel on its beacon's own
    wall: no verdict either way). ``log_likelihood`` is the
    beam-model log-likelihood ratio of these beams against background clutter.
    ``near``: of the occluded, those no more than ``near_short_m`` short (what
    stands right in front of where the panels should be).
    """

    hit: int = 0
    occluded: int = 0
    through: int = 0
    missing: int = 0
    log_likelihood: float = 0.0
    near: int = 0

    @property
    def coverage(self) -> float:
        """Share of the unoccluded returns that landed on the panels."""
        seen = self.hit + self.through
        return self.hit / seen if seen else 0.0


def check_beams(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    noise: NoiseModel,
    cfg: VerificationConfig,
    subset: NDArray[np.intp] | None = None,
) -> dict[str, BeamCheck]:
    """Predict, at ``pose``, every beam that must cross a surveyed panel and compare.

    Panel ends are shrunk by ``edge_margin_m`` and beams near a panel's plane
    are left out: near an edge or at grazing incidence a beam may
    legitimately miss. The log-likelihood ratio of a hit is that of a
    Gaussian about the predicted range against a return anywhere in the
    scanner's range; a through-beam costs ``log(through_probability)``.

    Compiled (:func:`mast.core._kernels.beam_checks_of`); :func:`_check_beams_reference`
    is the same in numpy (the tests compare the two).
    """
    from mast.core._kernels import beam_checks_of

    sel = np.arange(len(panels)) if subset is None else subset
    sigma = noise.gate_sigma_m
    span = _span(scan)
    chord_a, chord_b = panels.chords if cfg.wall_behind_m > 0.0 else (panels.a, panels.b)
    # The subset's beacons numbered from 0: the tallies cost the panels checked, not the
    # survey's size.
    beacons, counts, ll = beam_checks_of(
        np.array([pose.easting, pose.northing]),
        pose.azimuth,
        np.ascontiguousarray(scan.angles_rad, dtype=float),
        np.ascontiguousarray(scan.ranges_m, dtype=float),
        np.ascontiguousarray(scan.valid),
        float(scan.range_min_m),
        float(scan.range_max_m),
        panels.a,
        panels.b,
        panels.direction,
        panels.normal,
        panels.beacon,
        np.ascontiguousarray(sel, dtype=np.intp),
        cfg.edge_margin_m,
        math.sin(math.radians(cfg.min_check_incidence_deg)),
        cfg.gate_sigmas * sigma,
        sigma,
        math.log(span / (sigma * math.sqrt(2 * math.pi))),
        math.log(cfg.through_probability),
        cfg.near_short_m,
        math.log(cfg.near_probability),
        chord_a,
        chord_b,
        cfg.wall_behind_m,
    )
    out: dict[str, BeamCheck] = {}
    for k in np.flatnonzero(counts.sum(axis=1)):
        hit_n, occ_n, thr_n, mis_n, near_n = (int(c) for c in counts[k])
        out[panels.ids[beacons[k]]] = BeamCheck(hit_n, occ_n, thr_n, mis_n, float(ll[k]), near_n)
    return out


def _on_wall(
    points: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64], reach: float
) -> NDArray[np.bool_]:
    """Whether each of ``points`` lies within ``reach`` of the line from its ``a`` to its
    ``b`` (rows), and no farther than ``reach`` past either end."""
    c = b - a
    length = np.maximum(np.hypot(c[:, 0], c[:, 1]), 1e-12)
    d = points - a
    along = (d[:, 0] * c[:, 0] + d[:, 1] * c[:, 1]) / length
    off = np.abs(d[:, 0] * c[:, 1] - d[:, 1] * c[:, 0]) / length
    return np.asarray((off <= reach) & (along >= -reach) & (along <= length + reach))


def _span(scan: Scan) -> float:
    """How far clutter may return: the scanner's range, or the farthest return when the
    scan states no finite maximum; 1 m at least."""
    reach = scan.range_max_m
    if not math.isfinite(reach):
        reach = float(np.max(scan.ranges_m[scan.valid], initial=1.0))
    return max(reach, 1.0)


def _check_beams_reference(
    scan: Scan,
    pose: Pose2D,
    panels: PanelSet,
    noise: NoiseModel,
    cfg: VerificationConfig,
    subset: NDArray[np.intp] | None = None,
) -> dict[str, BeamCheck]:
    """:func:`check_beams` in numpy (the tests compare the two)."""
    sel = np.arange(len(panels)) if subset is None else subset
    dirs = pose.beam_directions(scan.angles_rad)
    a = panels.a[sel] + cfg.edge_margin_m * panels.direction[sel]
    b = panels.b[sel] - cfg.edge_margin_m * panels.direction[sel]
    t, jj = first_hits(pose.position, dirs, a, b)
    # Only the beams that meet a panel within the scanner's range go on.
    idx = np.flatnonzero((jj >= 0) & (t <= scan.range_max_m) & (t >= scan.range_min_m))
    j = sel[jj[idx]]
    nu = np.abs(np.einsum("ij,ij->i", panels.normal[j], dirs[idx]))
    steep = nu > math.sin(math.radians(cfg.min_check_incidence_deg))
    idx, j, t = idx[steep], j[steep], t[idx[steep]]
    r = scan.ranges_m[idx]
    valid = scan.valid[idx]
    sigma = noise.gate_sigma_m
    gate = cfg.gate_sigmas * sigma
    res = np.where(valid, r - t, np.nan)
    kind = np.full(idx.size, 3)  # missing
    kind[valid & (res < -gate)] = 1
    kind[valid & (res > gate)] = 2
    if cfg.wall_behind_m > 0.0:
        ca, cb = panels.chords
        land = pose.position + np.where(valid, r, 0.0)[:, None] * dirs[idx]
        kind[(kind == 2) & _on_wall(land, ca[j], cb[j], cfg.wall_behind_m)] = 3
    kind[valid & (np.abs(res) <= gate)] = 0
    near = valid & (res < -gate) & (res >= -cfg.near_short_m)
    # Clutter may return anywhere in the scanner's range.
    span = _span(scan)
    hit_ll = math.log(span / (sigma * math.sqrt(2 * math.pi))) - 0.5 * (res / sigma) ** 2
    beacon = panels.beacon[j]
    out: dict[str, BeamCheck] = {}
    for k in np.unique(beacon):
        m = beacon == k
        counts = np.bincount(kind[m], minlength=4)
        near_n = int(np.sum(near[m]))
        ll = (
            float(np.sum(hit_ll[m & (kind == 0)]))
            + counts[2] * math.log(cfg.through_probability)
            + near_n * math.log(cfg.near_probability)
        )
        hit_n, occ_n, thr_n, mis_n = (int(c) for c in counts)
        out[panels.ids[k]] = BeamCheck(hit_n, occ_n, thr_n, mis_n, ll, near_n)
    return out


def _same_pose(p: Pose2D, other: Pose2D, cfg: VerificationConfig) -> bool:
    """Whether two poses are one for verification (within ``duplicate_m`` and ``duplicate_rad``)."""
    d = math.hypot(other.easting - p.easting, other.northing - p.northing)
    da = abs(math.remainder(other.azimuth - p.azimuth, 2 * math.pi))
    return d < cfg.duplicate_m and da < cfg.duplicate_rad


@dataclass(frozen=True, eq=False)
class Verified:
    """A hypothesis after ICP and its checks against the whole survey."""

    hypothesis: Hypothesis
    icp: IcpResult
    panel_points: dict[tuple[str, int], int]
    supported: tuple[str, ...]
    checks: dict[str, BeamCheck]
    cornered: tuple[str, ...] = ()
    """Supporting beacons on whose surveyed edge an identified corner of the scan lands."""
    shaped: tuple[str, ...] = ()
    """Supporting beacons whose returns prove their shape: cornered, or bent as no line is."""
    misfit: tuple[str, ...] = ()
    """Beacons whose returns at this pose do not lie on their surveyed panels within
    their noise (:func:`_in_place`): the pose reads rock beside them, or another
    shape, as theirs. They do not support the pose, identified corner or not."""

    @property
    def pose(self) -> Pose2D:
        return self.icp.pose

    @property
    def violations(self) -> int:
        """Beams that went through where a surveyed panel should be."""
        return sum(c.through for c in self.checks.values())

    @property
    def log_likelihood(self) -> float:
        """Beam-model log-likelihood ratio against clutter, over every predicted beam."""
        return sum(c.log_likelihood for c in self.checks.values())

    @property
    def rank(self) -> tuple[int, float]:
        """What orders verified poses, higher first: beacons supporting, then likelihood."""
        return len(self.supported), self.log_likelihood

    def same_pose(self, other: Pose2D, cfg: VerificationConfig) -> bool:
        return _same_pose(self.icp.pose, other, cfg)

    def reads_alike(self, other: Verified, share: float) -> bool:
        """Whether ``other`` puts the same returns on the same surveyed panels (at least
        ``share`` of the returns either puts on a panel): the same reading of the scan,
        two ICP optima apart, not another place the scan could have been taken."""
        mine, theirs = self.icp.panel, other.icp.panel
        if mine.shape != theirs.shape:
            return False
        either = (mine >= 0) | (theirs >= 0)
        n = int(either.sum())
        return n > 0 and int(np.sum((mine == theirs) & either)) >= share * n


def _overrun(
    points_mine: NDArray[np.float64],
    panels: PanelSet,
    beacon_panels: NDArray[np.intp],
    gate_m: float,
    sigma_m: float,
    cfg: VerificationConfig,
    to_free_ends: bool = False,
) -> dict[int, int]:
    """Returns continuing each panel's line past its nodes, on no other panel of the beacon.

    Past a node the next panel turns away: returns that run on along a panel's line
    there belong to a longer surface (a wall, a shelf, a door frame) that merely
    resembles the beacon where it is. Compiled (:func:`mast.core._kernels.overrun_counts`);
    :func:`_overrun_reference` is the same in numpy, and says it in full.
    """
    from mast.core._kernels import overrun_counts

    counts = overrun_counts(
        np.ascontiguousarray(points_mine, dtype=float).reshape(-1, 2),
        panels.a,
        panels.direction,
        panels.normal,
        panels.length,
        panels.panel,
        np.ascontiguousarray(beacon_panels, dtype=np.intp),
        float(gate_m),
        2.0 * gate_m + cfg.edge_margin_m,
        cfg.overrun_reach_m,
        cfg.overrun_slope_sigmas,
        float(sigma_m),
        bool(to_free_ends),
    )
    return dict(zip(beacon_panels.tolist(), counts.tolist(), strict=True))


def _overrun_reference(
    points_mine: NDArray[np.float64],
    panels: PanelSet,
    beacon_panels: NDArray[np.intp],
    gate_m: float,
    sigma_m: float,
    cfg: VerificationConfig,
    to_free_ends: bool = False,
) -> dict[int, int]:
    """:func:`_overrun` in numpy (the tests compare the two).

    Past a node the next panel turns away: returns that run on along a
    panel's line there belong to a longer surface — a wall, a shelf, a door
    frame — that merely resembles the beacon where it is. The free ends (e1
    and the last edge) are not looked past: there the beacon meets its wall,
    which may well run on in the outer panel's line. A surface that only
    crosses the band about the line (the wall a panel meets at a shallow
    angle) is not a continuation: the returns past each end count only when
    the line through them keeps the panel's direction (their lateral drift
    along the reach is within ``overrun_slope_sigmas`` standard deviations of
    none). With ``to_free_ends``, the search past a node stops where the
    beacon does: no farther than the outer panel beyond that node is long.
    """
    # Only returns within a gate of a panel's line, and at most the reach past its
    # ends, can count: the others are left out before any (returns x panels) array.
    reach = math.hypot(gate_m, max(gate_m, cfg.overrun_reach_m)) + gate_m
    near, _ = panels.within(points_mine, reach, subset=beacon_panels)
    t, s = panels.project(points_mine[near], beacon_panels)
    length = panels.length[beacon_panels][None, :]
    on_panel = (np.abs(s) <= gate_m) & (t >= -gate_m) & (t <= length + gate_m)
    near_any = np.asarray(on_panel.any(axis=1), dtype=bool)
    margin = 2.0 * gate_m + cfg.edge_margin_m
    band = (np.abs(s) <= gate_m) & ~near_any[:, None]
    out: dict[int, int] = {}
    numbers = panels.panel[beacon_panels]
    first, last = int(numbers.min()), int(numbers.max())
    outer = {int(n): float(length[0, col]) for col, n in enumerate(numbers) if n in (first, last)}

    def reach_past(neighbour: int) -> float:
        if to_free_ends and neighbour in outer:
            return min(cfg.overrun_reach_m, outer[neighbour])
        return cfg.overrun_reach_m

    for col, k in enumerate(beacon_panels.tolist()):
        count = 0
        tk, sk, lk = t[:, col], s[:, col], float(length[0, col])
        number = int(panels.panel[k])
        ends_checked = []
        if number != last:
            ends_checked.append((tk > lk) & (tk < lk + reach_past(number + 1)))
        if number != first:
            ends_checked.append((tk < 0) & (tk > -reach_past(number - 1)))
        for beyond in ends_checked:
            ends = band[:, col] & beyond
            past = ends & ((tk > lk + margin) | (tk < -margin))
            n = int(past.sum())
            if n >= 3:
                # Slope of the lateral offset against the distance along the line,
                # over every return in the band beyond this end.
                tt = tk[ends] - tk[ends].mean()
                spread = float(tt @ tt)
                slope = float(tt @ sk[ends]) / spread if spread > 0 else 0.0
                if abs(slope) > cfg.overrun_slope_sigmas * sigma_m / math.sqrt(max(spread, 1e-30)):
                    continue  # another surface crossing the band
            count += n
        out[int(k)] = count
    return out


def _runs_on(
    points_mine: NDArray[np.float64],
    panels: PanelSet,
    beacon_panels: NDArray[np.intp],
    counts: dict[tuple[str, int], int],
    beacon: str,
    gate_m: float,
    noise: NoiseModel,
    cfg: VerificationConfig,
    to_free_ends: bool,
) -> bool:
    """Whether a beacon's returns run on past a node: on any panel, more returns
    past it (:func:`_overrun`) than ``max_overrun_fraction`` of the panel's own
    (never fewer than ``min_panel_points``)."""
    over = _overrun(
        points_mine, panels, beacon_panels, gate_m, noise.gate_sigma_m, cfg, to_free_ends
    )
    return any(
        over[int(k)]
        > max(
            cfg.min_panel_points,
            cfg.max_overrun_fraction * counts.get((beacon, int(panels.panel[k])), 0),
        )
        for k in beacon_panels
    )


def _seen_from_front(edges: NDArray[np.float64], position: NDArray[np.float64]) -> bool:
    """Whether a scanner at ``position`` is on the side the beacon stands out to.

    A beacon is mounted on a wall with its nodes standing out from the chord
    e1-e4 into the drift; seen from the chord's other side, the scanner would
    be looking through the wall at the back of the beacon. A design whose
    nodes do not stand out to one side passes.
    """
    chord = edges[3] - edges[0]
    bump = 0.5 * (edges[1] + edges[2]) - edges[0]
    out = chord[0] * bump[1] - chord[1] * bump[0]
    rel = position - edges[0]
    side = chord[0] * rel[1] - chord[1] * rel[0]
    if abs(out) < 1e-9 * float(chord @ chord):
        return True
    return bool(out * side > 0)


def _incidence(
    points: NDArray[np.float64], origin: NDArray[np.float64], normals: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each return's range from ``origin`` and the cosine between its beam and the
    surface normal (``normals``: one per return, or one row for all): what turns the
    range and angle noise into the noise across that surface."""
    ray = points - origin
    rho = np.hypot(ray[:, 0], ray[:, 1])
    u = ray / np.where(rho > 0, rho, 1.0)[:, None]
    return rho, np.einsum("ij,ij->i", u, np.broadcast_to(normals, u.shape))


def _straight_and_fitted(
    points: NDArray[np.float64],
    on: NDArray[np.bool_],
    to_panels_m: NDArray[np.float64],
    panel_of: NDArray[np.intp],
    origin: NDArray[np.float64],
    noise: NoiseModel,
    survey_var: NDArray[np.float64],
) -> tuple[float, float]:
    """Chi-squares of a beacon's returns (``points`` where ``on``; ``to_panels_m`` their
    offsets from its panels ``panel_of``, one per point) about one straight line and
    about its panels (``survey_var``: each panel's surveyed variance).

    Each offset is weighed by the noise a return really has across the line:
    the range noise projected on the line's normal (``sigma_r * |n . u|`` for
    a beam along ``u`` from ``origin``) and the angle noise on its tangent
    (``rho * sigma_phi * |n x u|``), so an oblique panel's returns are judged
    as tightly as they lie. The panels' offsets also carry the survey's
    variance. Compiled (:func:`mast.core._kernels.straight_and_fitted_chi`);
    :func:`_straight_and_fitted_reference` is the same in numpy on the returns on.
    """
    from mast.core._kernels import straight_and_fitted_chi

    chi_line, chi_beacon = straight_and_fitted_chi(
        np.ascontiguousarray(points, dtype=float).reshape(-1, 2),
        np.ascontiguousarray(on, dtype=np.bool_),
        np.ascontiguousarray(to_panels_m, dtype=float),
        np.asarray(origin, dtype=float),
        noise.range_sigma_m,
        noise.angle_sigma_rad,
        np.ascontiguousarray(panel_of, dtype=np.intp),
        np.ascontiguousarray(survey_var, dtype=float),
    )
    return float(chi_line), float(chi_beacon)


def _straight_and_fitted_reference(
    points: NDArray[np.float64],
    to_panels_m: NDArray[np.float64],
    origin: NDArray[np.float64],
    noise: NoiseModel,
    survey_var: NDArray[np.float64],
) -> tuple[float, float]:
    """:func:`_straight_and_fitted` in numpy, on the returns on the beacon (the tests
    compare the two); ``survey_var`` is each return's panel's surveyed variance."""
    centre = points.mean(axis=0)
    q = points - centre
    _, vecs = np.linalg.eigh(q.T @ q)
    normal = vecs[:, 0]
    rho, cos_n = _incidence(points, origin, normal[None, :])
    var = (noise.range_sigma_m * cos_n) ** 2 + (rho * noise.angle_sigma_rad) ** 2 * (1 - cos_n**2)
    var = np.maximum(var, (0.1 * noise.range_sigma_m) ** 2)
    chi_line = float(np.sum((q @ normal) ** 2 / var))
    chi_beacon = float(np.sum(to_panels_m**2 / (var + survey_var)))
    return chi_line, chi_beacon


def _in_place(
    icp: IcpResult,
    points_mine: NDArray[np.float64],
    panels: PanelSet,
    beacon: str,
    noise: NoiseModel,
    cfg: VerificationConfig,
) -> bool:
    """Whether a beacon's returns at ``icp``'s pose lie on its surveyed panels within
    their noise: their chi-square within its ``straight_alpha`` point.

    Each offset is weighed by the noise a return has across its own panel: the range
    noise on the panel's normal, never less than ``grazing_noise_floor`` of it, the
    angle noise on its tangent, and the survey's variance. (:func:`_straight_and_fitted`
    weighs every offset across the one line through all the returns, as the bend test
    compares the two; whether the returns lie on the panels turns on each panel's own
    incidence.) Returns within ``edge_margin_m`` of the beacon's free ends are left
    out: there a beam may as well meet the rock the beacon is mounted on; so are
    beams within 2 degrees of grazing their panel; and so are
    returns at the beacon's silhouette (the next return, off the beacon, lies more than
    a jump behind: :mod:`mast.pipeline.edges`), which may be mixed pixels. Compiled
    (:func:`mast.core._kernels.in_place_chi`); :func:`_in_place_reference` is the same
    in numpy.
    """
    from mast.core._kernels import in_place_chi

    chi, count = in_place_chi(
        np.ascontiguousarray(points_mine, dtype=float).reshape(-1, 2),
        np.asarray(icp.pose.position, dtype=float),
        np.ascontiguousarray(icp.panel, dtype=np.intp),
        np.ascontiguousarray(icp.residual_m, dtype=float),
        panels.of_beacon(panels.number[beacon]),
        panels.panel,
        panels.a,
        panels.direction,
        panels.normal,
        panels.length,
        cfg.edge_margin_m,
        jump_m(noise.range_sigma_m),
        MIN_INCIDENCE_COS,
        noise.range_sigma_m,
        noise.angle_sigma_rad,
        cfg.grazing_noise_floor,
        panels.survey_variance(noise.survey_sigma_m),
    )
    return count > 0 and chi2_sf(chi, count) > cfg.straight_alpha


def _in_place_reference(
    icp: IcpResult,
    points_mine: NDArray[np.float64],
    panels: PanelSet,
    beacon: str,
    noise: NoiseModel,
    cfg: VerificationConfig,
) -> bool:
    """:func:`_in_place` in numpy (the tests compare the two)."""
    mine = np.flatnonzero(panels.beacon == panels.number[beacon])
    numbers = panels.panel[mine]
    ours = np.isin(icp.panel, mine)
    on = np.flatnonzero(ours)
    if on.size:
        # The returns' own ranges stand for the prediction here: a test, not an estimate.
        reach = np.hypot(*(points_mine - icp.pose.position).T)
        edge = at_silhouette(
            reach,
            np.ones(reach.size, dtype=bool),
            on,
            reach[on],
            np.zeros(on.size, dtype=np.intp),
            np.where(ours, 0, -1),
            jump_m(noise.range_sigma_m),
        )
        on = on[~edge]
    k = icp.panel[on]
    p = points_mine[on]
    t = np.einsum("ij,ij->i", p - panels.a[k], panels.direction[k])
    first, last = int(numbers.min()), int(numbers.max())
    free = ((panels.panel[k] == first) & (t < cfg.edge_margin_m)) | (
        (panels.panel[k] == last) & (t > panels.length[k] - cfg.edge_margin_m)
    )
    on, k, p = on[~free], k[~free], p[~free]
    rho, cos_n = _incidence(p, icp.pose.position, panels.normal[k])
    cos_n = np.abs(cos_n)
    # A beam within 2 degrees of grazing carries no usable range (the adjustment
    # leaves it out too): its footprint spreads along the whole panel.
    usable = cos_n > MIN_INCIDENCE_COS
    on, k, rho, cos_n = on[usable], k[usable], rho[usable], cos_n[usable]
    across = noise.range_sigma_m * np.maximum(cos_n, cfg.grazing_noise_floor)
    var = across**2 + (rho * noise.angle_sigma_rad) ** 2 * (1 - cos_n**2)
    surveyed = panels.survey_variance(noise.survey_sigma_m)[k]
    chi = float(np.sum(icp.residual_m[on] ** 2 / (var + surveyed)))
    return on.size > 0 and chi2_sf(chi, int(on.size)) > cfg.straight_alpha


def _shows_a_bend(chi_line: float, chi_beacon: float, alpha: float) -> bool:
    """Whether a beacon's shape explains its returns better than one straight line.

    A flat wall crossing the place where a beacon should be puts returns near
    its panels too. The two explanations are compared by their chi-square
    (a likelihood ratio, see :func:`_straight_and_fitted`). The beacon wins
    when the line's excess passes the chi-square(2) quantile at ``alpha``
    (the line has two free parameters; the panels none). Roughness and extra
    noise inflate both sums alike, so rough rock does not pass for a bend.
    """
    return chi_line - chi_beacon > chi2_isf(alpha, 2)


def _stray_corner(
    edges_scanner: NDArray[np.float64],
    seg: Segmentation,
    gate_m: float,
    noise: NoiseModel,
    cfg: VerificationConfig,
    survey_sigma_m: float | None = None,
) -> bool:
    """Whether a corner of the scan lands beside one of a beacon's node edges, not on an edge.

    Corners of the scan near a beacon's edges must be its edges: one that
    lands beside an edge says the shape there is another (or the beacon
    moved). A corner is on an edge when within ``gate_m`` of it, or within
    ``gate_sigmas`` of its own uncertainty (:func:`corner_covariance`, with
    the range and survey variances): two short or nearly collinear lines
    meet far from where their surfaces do. A corner on any surveyed edge,
    the free ends where the beacon meets the wall included, is the
    beacon's own. A corner is the scan's only where its two lines meet
    where they end: within ``gate_m`` of each line's facing end (plus the
    spacing of its returns there).
    Two lines of rock nearly straight on (a few degrees apart) meet far from
    their ends, back among one line's returns or beyond them, where the scan
    shows no corner at all (field hostile 1-1 pose 2: 0.33 m from both ends,
    beside a small beacon's 0.1 m panel; shared noisy 0124: 3.5 m, beside a
    beacon of a turned-round pose, which is then ambiguous with the truth).
    Everything is compared in the scanner frame, where the corners and
    their covariances are (``edges_scanner``: the beacon's surveyed edges
    mapped there by the pose; ``survey_sigma_m`` their largest standard deviation,
    the noise model's when not given).
    """
    if not seg.corners:
        return False
    nodes = np.array([c.node for c in seg.corners])
    d = np.hypot(*(nodes[:, None, :] - edges_scanner[None, :, :]).transpose(2, 0, 1))
    near_node = np.any(d[:, 1:3] < cfg.corner_reach_m, axis=1) & ~np.any(d <= gate_m, axis=1)
    surveyed = noise.survey_sigma_m if survey_sigma_m is None else survey_sigma_m
    extra = noise.gate_sigma_m**2 + surveyed**2
    for k in np.flatnonzero(near_node):
        c = seg.corners[k]
        a, b = seg.segments[c.first], seg.segments[c.second]
        if (
            math.dist(c.node, a.end) > gate_m + a.spacing_end
            or math.dist(c.node, b.start) > gate_m + b.spacing_start
        ):
            continue  # the lines meet away from where they end: no corner in the scan
        cov = corner_covariance(a, b, c.node, seg.noise_m)
        inv = np.linalg.inv(cov + extra * np.eye(2))
        off = edges_scanner - c.node
        maha = np.einsum("ij,jk,ik->i", off, inv, off)
        if np.all(maha > cfg.gate_sigmas**2):
            return True
    return False


def _beams_favour(check: BeamCheck, cfg: VerificationConfig) -> bool:
    """Whether the beams predicted onto a beacon prove it against clutter.

    At least ``min_coverage`` of the unoccluded beams must land on it, and
    their log-likelihood ratio against returns from anywhere in the
    scanner's range must be positive: a few hits at the edge of their gate
    and as many beams through the panels are what rock near a look-alike
    gives, not what a beacon does.
    """
    return check.coverage >= cfg.min_coverage and check.log_likelihood > 0.0


def _panel_counts(icp: IcpResult, panels: PanelSet) -> dict[tuple[str, int], int]:
    """Returns matched to each (beacon, panel) at the refined pose."""
    from mast.core._kernels import tallies

    counts: dict[tuple[str, int], int] = {}
    idx, n = tallies(icp.panel)
    for k, c in zip(idx, n, strict=True):
        counts[(panels.ids[panels.beacon[k]], int(panels.panel[k]))] = int(c)
    return counts


def _by_beacon(counts: dict[tuple[str, int], int]) -> dict[str, list[int]]:
    per_beacon: dict[str, list[int]] = {}
    for (b, _panel), c in counts.items():
        per_beacon.setdefault(b, []).append(c)
    return per_beacon


def _may_support(counts: dict[tuple[str, int], int], cfg: VerificationConfig) -> frozenset[str]:
    """Beacons whose returns are enough for :func:`_support` to consider them at all
    (two panels with returns, as many in all as two panels need): every beacon that
    supports a pose is one of these, whatever the beams and corners say."""
    return frozenset(
        b
        for b, cs in _by_beacon(counts).items()
        if len(cs) >= 2 and sum(cs) >= 2 * cfg.min_panel_points
    )


def _on_their_edges(
    icp: IcpResult,
    candidates: set[str],
    index: SurveyIndex,
    ident: PanelIdentification | None,
    seg: Segmentation | None,
    noise: NoiseModel,
    cfg: VerificationConfig,
    node_sigmas: dict[int, float] | None = None,
) -> set[str]:
    """The ``candidates`` one of whose edges an identified corner of the scan (of the
    beacon's design) lands on at ``icp``'s pose, within ``gate_sigmas`` of the corner's
    own uncertainty, the survey's and the range noise; none without a segmentation.
    ``node_sigmas``, when given, keeps each corner's uncertainty (:func:`node_sigma`) by
    the ``id`` of its node (``ident`` holds the nodes while the scan is verified), for
    the scan's other poses."""
    node_ok: set[str] = set()
    if ident is None or seg is None:
        return node_ok
    if node_sigmas is None:
        node_sigmas = {}
    by_beacon = ident.nodes_by_beacon
    designs = {index.design_of(b) for b in candidates}
    # Only the nodes of a candidate's design (a survey of many designs reads each corner
    # as a node of many), found from whichever is fewer, the design's beacons (a mine of
    # repeated designs has thousands) or the beacons the nodes name; whether a candidate
    # is taken does not depend on their order.
    for design in sorted(designs):
        members = index.designs[design]
        if len(members) <= len(by_beacon):
            named = [b for b in members if b in by_beacon]
        else:
            named = [b for b in by_beacon if index.design_of(b) == design]
        nodes = [n for b in named for n in by_beacon[b]]
        if not nodes:
            continue
        # The candidates of the design (not every look-alike in a mine's survey).
        mine = sorted(b for b in candidates if index.design_of(b) == design)
        mapped = icp.pose.scanner_to_mine(np.array([n.node_scanner for n in nodes])).tolist()
        for node, at in zip(nodes, mapped, strict=True):
            left = [b for b in mine if b not in node_ok]
            if not left:
                break
            spread = node_sigmas.get(id(node))
            if spread is None:
                spread = node_sigmas[id(node)] = node_sigma(node, seg)
            for b in left:
                edge = node.edge - 1
                surveyed = float(index.survey[b].sigmas_or(noise.survey_sigma_m)[edge])
                gate = cfg.gate_sigmas * math.hypot(spread, surveyed, noise.range_sigma_m)
                if math.dist(at, index.survey[b].edges[edge]) <= gate:
                    node_ok.add(b)
    return node_ok


def _support(
    icp: IcpResult,
    counts: dict[tuple[str, int], int],
    points_mine: NDArray[np.float64],
    panels: PanelSet,
    index: SurveyIndex,
    ident: PanelIdentification | None,
    seg: Segmentation | None,
    checks: dict[str, BeamCheck],
    noise: NoiseModel,
    cfg: VerificationConfig,
    tracked: bool = False,
    kept: Refinement | None = None,
    node_sigmas: dict[int, float] | None = None,
) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    """Beacons that confirm a pose, the cornered and the shaped beacons, and the beacons
    refused only because their returns do not lie on their panels within their noise.

    A beacon confirms the pose when, at that pose, (1) two of its panels
    have returns, ``2 * min_panel_points`` in all, (2) at least
    ``min_coverage`` of the unoccluded beams that should hit it do, and (3)
    its returns are the beacon's and not clutter's: a corner of the scan
    identified as one of its edges lands on that edge, or two panels carry
    ``min_panel_points`` returns each that lie on its panels within their noise
    (:func:`_in_place`), no panel's returns run on past its nodes (nor past
    a short outer panel's free end when ``wall_past_free_ends`` is off), they
    show a bend one straight line cannot explain (or, when another beacon's
    identified corner lands on its edge, fit the panels better than a line:
    ``placed_support``), and no corner of the scan lands beside one of its node
    edges (:func:`_stray_corner`). When
    ``tracked`` (a prior already says which beacon is where) no node need be
    identified and two panels carrying ``min_panel_points`` returns each that
    lie on them within their noise suffice, but they must still not run on
    past its nodes (a wrong prior must not let clutter, or a few returns of
    the right beacons, confirm a pose the beams do not prove); a stray corner
    beside an edge is not held against them (the prior, not a corner, names
    the beacon). Without a segmentation (``seg`` and ``ident`` None: a scan
    searched near a prior before it is segmented) no beacon has a node. ``kept``
    holds the beacons' tests at this pose from an earlier judgement of it, and keeps
    those made now; ``node_sigmas`` the scan's corners' uncertainties (:func:`_on_their_edges`).
    """
    in_place_memo: dict[str, bool] = {} if kept is None else kept.in_place
    fitted_memo: dict[str, tuple[float, float]] = {} if kept is None else kept.fitted
    runs_memo: dict[tuple[str, bool], bool] = {} if kept is None else kept.runs_on

    def in_place(b: str) -> bool:
        if b not in in_place_memo:
            in_place_memo[b] = _in_place(icp, points_mine, panels, b, noise, cfg)
        return in_place_memo[b]

    # Loosely: two panels with returns and as many in all as two panels need.
    per_beacon = _by_beacon(counts)
    candidates = {
        b
        for b in _may_support(counts, cfg)
        if _beams_favour(checks.get(b, BeamCheck()), cfg)
        and _seen_from_front(index.survey[b].edges, icp.pose.position)
    }
    gate = cfg.gate_sigmas * noise.gate_sigma_m
    node_ok = _on_their_edges(icp, candidates, index, ident, seg, noise, cfg, node_sigmas)
    # Identified by its corner or not, a beacon whose returns do not lie on its panels
    # within their noise is not read right at this pose (a look-alike 204 m away on a
    # long drive rested on such a corner).
    misfit = {b for b in node_ok if not in_place(b)}
    node_ok -= misfit
    supported = set(node_ok)
    shaped = set(node_ok)
    # Without a node of its own, each of two panels must show its returns, a prior or
    # not: one panel with a stray return or two on its neighbour is one panel (rock
    # beside it reads as the neighbour), and one panel cannot place a beacon.
    candidates = {
        b for b in candidates if sum(c >= cfg.min_panel_points for c in per_beacon[b]) >= 2
    }
    # Each return's beacon (its position in the survey), -1 for none.
    matched = icp.panel >= 0
    beacon_of = np.where(matched, panels.beacon[np.where(matched, icp.panel, 0)], -1)
    for b in candidates - node_ok:
        # Rock read as a beacon has more rock right in front of it; a beacon with
        # something standing against it still shows its three panels around it.
        check = checks.get(b, BeamCheck())
        three = sum(c >= cfg.min_panel_points for c in per_beacon[b]) >= 3
        if check.near > cfg.max_near_share * (check.hit + check.near) and not three:
            continue
        mine = panels.of_beacon(panels.number[b])
        on = beacon_of == panels.number[b]
        n_on = int(np.count_nonzero(on))
        if n_on < 4:
            continue
        if not tracked and seg is not None:
            edges_scanner = icp.pose.mine_to_scanner(index.survey[b].edges)
            gate_node = cfg.gate_sigmas * math.hypot(seg.noise_m * 3.0, noise.gate_sigma_m)
            worst = float(index.survey[b].sigmas_or(noise.survey_sigma_m).max())
            if _stray_corner(edges_scanner, seg, gate_node, noise, cfg, worst):
                continue
        if b not in fitted_memo:
            fitted_memo[b] = _straight_and_fitted(
                points_mine,
                on,
                icp.residual_m,
                icp.panel,
                icp.pose.position,
                noise,
                panels.survey_variance(noise.survey_sigma_m),
            )
        chi_line, chi_beacon = fitted_memo[b]
        bent = _shows_a_bend(chi_line, chi_beacon, cfg.straight_alpha)
        lies = in_place(b)
        # Where another beacon's identified corner already lands on its surveyed edge,
        # the pose is fixed to millimetres by it: this beacon need only lie where the
        # pose puts it, its returns on its panels within their noise and no straighter
        # than its shape (a small beacon's bend can be inside the noise).
        placed = cfg.placed_support and bool(node_ok) and lies and chi_line > chi_beacon
        if not (bent or placed or tracked):
            continue
        # Without a node of its own, a beacon's returns must lie on its panels within
        # their noise: bent or not, rock beside a panel read as its neighbour does not
        # (a tracked pose 5 cm off on a long drive, issue 31).
        if not lies:
            misfit.add(b)
            continue

        # Past a short outer panel's free end the wall may stand in the middle panel's
        # line (the beacon lies on its panels within their noise: checked above).
        def over(to_free_ends: bool, b: str = b, mine: NDArray[np.intp] = mine) -> bool:
            if (b, to_free_ends) not in runs_memo:
                runs_memo[(b, to_free_ends)] = _runs_on(
                    points_mine, panels, mine, counts, b, gate, noise, cfg, to_free_ends
                )
            return runs_memo[(b, to_free_ends)]

        if not over(False) or (cfg.wall_past_free_ends and not over(True)):
            supported.add(b)
            if bent:
                shaped.add(b)
    return (
        tuple(sorted(supported)),
        tuple(sorted(node_ok)),
        tuple(sorted(shaped)),
        tuple(sorted(misfit)),
    )


@dataclass(eq=False, slots=True)
class Refinement:
    """A hypothesis' ICP, and the beams' checks and each beacon's tests at its pose once
    they are made (whether its returns lie on its panels, its straight-line and panel
    fits, whether they run on past its edges): kept for a second verification of the
    same hypothesis (:func:`verify`'s ``icp_memo``), where only the corners differ."""

    hypothesis: Hypothesis
    icp: IcpResult
    checks: dict[str, BeamCheck] | None = None
    in_place: dict[str, bool] = field(default_factory=dict)
    fitted: dict[str, tuple[float, float]] = field(default_factory=dict)
    runs_on: dict[tuple[str, bool], bool] = field(default_factory=dict)


@dataclass(eq=False, slots=True)
class _Refined:
    """A start refined by ICP; judged by the beams only when some hypothesis needs it."""

    hypothesis: Hypothesis
    icp: IcpResult
    counts: dict[tuple[str, int], int]
    may_support: frozenset[str]
    near: NDArray[np.intp]  # the panels in reach of the start
    verified: Verified | None = None
    kept: Refinement | None = None  # its entry in the caller's memo


@dataclass(eq=False, slots=True)
class _PoseList:
    """Poses in arrays, so that finding one the same as a new pose (:func:`_same_pose`)
    costs one vector comparison however many hypotheses a mine's look-alikes make."""

    cfg: VerificationConfig
    _enr: NDArray[np.float64] = field(default_factory=lambda: np.zeros((16, 3)))
    size: int = 0

    def add(self, pose: Pose2D) -> None:
        if self.size == self._enr.shape[0]:
            self._enr = np.concatenate([self._enr, np.zeros_like(self._enr)])
        self._enr[self.size] = (pose.easting, pose.northing, pose.azimuth)
        self.size += 1

    def forget(self, k: int) -> None:
        """Pose ``k`` no longer matches any pose."""
        self._enr[k] = np.nan

    def first_same(self, pose: Pose2D) -> int | None:
        """Position of the first pose the same as ``pose``, or None (compiled:
        :func:`mast.core._kernels.first_same`; :meth:`_first_same_reference` in numpy)."""
        at = first_same(
            self._enr,
            self.size,
            pose.easting,
            pose.northing,
            pose.azimuth,
            self.cfg.duplicate_m,
            self.cfg.duplicate_rad,
        )
        return None if at < 0 else int(at)

    def _first_same_reference(self, pose: Pose2D) -> int | None:
        """:meth:`first_same` in numpy (the tests compare the two)."""
        e = self._enr[: self.size]
        d = np.hypot(e[:, 0] - pose.easting, e[:, 1] - pose.northing)
        da = np.abs(wrap_angles(e[:, 2] - pose.azimuth))
        at = np.flatnonzero((d < self.cfg.duplicate_m) & (da < self.cfg.duplicate_rad))
        return int(at[0]) if at.size else None


def verify(
    hypotheses: list[Hypothesis],
    scan: Scan,
    panels: PanelSet,
    index: SurveyIndex,
    ident: PanelIdentification | None,
    seg: Segmentation | None,
    noise: NoiseModel,
    cfg: VerificationConfig,
    *,
    settled: Callable[[list[Verified]], bool] | None = None,
    min_beacons: int = 2,
    icp_memo: dict[int, Refinement] | None = None,
) -> list[Verified]:
    """Refine every hypothesis by ICP and keep those the beams confirm, best first.

    A hypothesis is kept when the beacons it was formed from support the
    refined pose and few beams pass through surveyed panels. Hypotheses that
    start where an earlier one ended are skipped (the same pose again). A
    refined pose is judged by the beams (:func:`check_beams`, :func:`_support`)
    only when its returns leave the hypothesis' beacons a chance of support:
    otherwise the hypothesis could not be kept whatever the beams say.

    With ``settled``, a refined pose whose returns leave fewer than
    ``min_beacons`` beacons a chance of support is set aside, and judged only
    if ``settled(kept)`` is false once every other hypothesis has been, or
    when a later pose is the same as it (whether it is kept decides whether
    the later one is skipped): the caller says when such poses (a mine's
    look-alikes of one beacon seen) can no longer change its choice. What is
    returned is then what judging every pose in turn returns, less set-aside
    poses never judged.

    A one-beacon hypothesis is not refined at all when its start leaves too
    few returns in reach of its own beacon, and with ``settled`` it is set
    aside unrefined when they leave fewer than ``min_beacons`` beacons enough
    (:func:`_in_reach`, ``look_alike_reach_m`` and ``look_alike_reach_rad``):
    refined, it would be set aside as above.

    ``ident`` and ``seg`` are the scan's identified corners and segmentation; None for
    a scan searched near a prior without them (then no beacon is held to a corner).
    ``icp_memo``, when given, keeps each hypothesis' ICP result and the beams' checks at
    its pose by its ``id`` (with the hypothesis, so that an id reused by a later object
    is not mistaken for it), so that the same hypotheses verified again (with the
    corners, after a search without them) are neither refined nor checked twice.
    """
    beams, pts = scan.points()
    angles = scan.angles_rad[beams]
    final_gate = cfg.gate_sigmas * noise.gate_sigma_m
    gates = (*cfg.coarse_gates_m, final_gate)
    reach = scan.range_max_m + 1.0
    out: list[Verified] = []
    out_poses = _PoseList(cfg)
    done: list[_Refined] = []
    done_poses = _PoseList(cfg)
    sequence: dict[int, int] = {}  # id of a kept Verified -> its hypothesis' position
    node_sigmas: dict[int, float] = {}  # id of an identified node -> its node_sigma

    def judged(r: _Refined) -> Verified:
        """``r`` judged by the beams, under the hypothesis it was refined for."""
        if r.verified is None:
            h0, icp = r.hypothesis, r.icp
            if r.kept is not None and r.kept.checks is not None:
                checks = r.kept.checks
            else:
                checks = check_beams(scan, icp.pose, panels, noise, cfg, subset=r.near)
                if r.kept is not None:
                    r.kept.checks = checks
            points_mine = icp.pose.scanner_to_mine(pts)
            supported, cornered, shaped, refused = _support(
                icp,
                r.counts,
                points_mine,
                panels,
                index,
                ident,
                seg,
                checks,
                noise,
                cfg,
                tracked=h0.kind == "prior",
                kept=r.kept,
                node_sigmas=node_sigmas,
            )
            r.verified = Verified(h0, icp, r.counts, supported, checks, cornered, shaped, refused)
        return r.verified

    def keep(seq: int, h: Hypothesis, refined: _Refined, again: bool) -> None:
        """Judge ``refined`` under ``h`` and keep it if its beacons support it."""
        v = judged(refined)
        if again:
            v = replace(v, hypothesis=h)
        supported, checks = v.supported, v.checks
        if not set(h.beacons) <= set(supported):
            return
        unoccluded = sum(c.hit + c.through for c in checks.values())
        if v.violations > max(cfg.min_violations, cfg.max_violation_fraction * unoccluded):
            return
        out.append(v)
        out_poses.add(v.pose)
        sequence[id(v)] = seq

    # Poses set aside for judging later (a mine's look-alikes on one beacon's returns),
    # in hypothesis order. Whether one is kept matters before the end only when a later
    # pose is the same as it (then, as when every pose was judged in turn, the later one
    # is skipped if it was kept): it is judged then.
    pending: list[tuple[int, Hypothesis, _Refined, bool] | None] = []
    pending_poses = _PoseList(cfg)

    def settle(k: int) -> None:
        entry = pending[k]
        if entry is not None:
            pending[k] = None
            pending_poses.forget(k)
            keep(*entry)

    def duplicate(pose: Pose2D) -> bool:
        """Whether ``pose`` is the same as a kept one (judging set-aside ones it meets)."""
        while out_poses.first_same(pose) is None:
            k = pending_poses.first_same(pose)
            if k is None:
                return False
            settle(k)
        return True

    # One-beacon hypotheses whose start leaves no second beacon the returns to be in
    # ``may_support`` (:func:`_in_reach`): refined only if, at the end, the poses kept do
    # not settle the choice.
    deferred: list[tuple[int, Hypothesis]] = []
    ranges = np.hypot(pts[:, 0], pts[:, 1])
    # Every start's panels in reach, looked up at once (a mine's look-alikes are many),
    # and the beacons that could gather returns at each one-beacon start's refined pose.
    starts = [h.similarity.pose() for h in hypotheses]
    nears = panels.near_many(
        np.array([h.similarity.translation for h in hypotheses], dtype=float).reshape(-1, 2),
        reach,
    )
    one_beacon = [
        seq
        for seq, h in enumerate(hypotheses)
        if h.kind in ("single", "pair") and len(h.beacons) < min_beacons
    ]
    in_reach = dict(
        zip(
            one_beacon,
            _beacons_in_reach(
                [starts[k] for k in one_beacon],
                [nears[k] for k in one_beacon],
                pts,
                angles,
                ranges,
                panels,
                final_gate,
                cfg,
                # Only whether its own beacons are in it, and whether there are
                # min_beacons, is asked of each set (in ``refine``).
                owns=[hypotheses[k].beacons for k in one_beacon],
                enough=min_beacons,
            ),
            strict=True,
        )
    )

    def refine(seq: int, h: Hypothesis, last: bool) -> None:
        """Refine ``h`` by ICP and keep it, set it aside or defer it (not ``last``:
        before every hypothesis has been refined once)."""
        aside = settled is not None and not last
        start = starts[seq]
        at = done_poses.first_same(start)
        again = None if at is None else done[at]
        if again is not None:
            # The same start refines to the same pose: judge it again under this
            # hypothesis' labels (another beacon's name may be the right one).
            if duplicate(again.icp.pose):
                return
            refined = again
        else:
            near = nears[seq]
            if near.size == 0:
                return
            if h.kind in ("single", "pair") and len(h.beacons) < min_beacons:
                may = in_reach[seq]
                if not set(h.beacons) <= may:
                    return  # its beacon cannot gather the returns to support any pose
                if aside and len(may) < min_beacons:
                    deferred.append((seq, h))
                    return
            start_gate = min(cfg.max_start_gate_m, cfg.start_gate_sigmas * h.spread_m)
            wide = (start_gate,) if start_gate > gates[0] else ()
            kept = None if icp_memo is None else icp_memo.get(id(h))
            if kept is not None and kept.hypothesis is h:
                icp = kept.icp
            else:
                icp = icp_point_to_line(
                    pts, start, panels, gates_m=(*wide, *gates), subset=near, angles=angles
                )
                kept = None
                if icp_memo is not None:
                    kept = icp_memo[id(h)] = Refinement(h, icp)
            if duplicate(icp.pose):
                return  # converged onto a pose already confirmed
            counts = _panel_counts(icp, panels)
            refined = _Refined(h, icp, counts, _may_support(counts, cfg), near, kept=kept)
            done.append(refined)
            done_poses.add(icp.pose)
        if not set(h.beacons) <= refined.may_support:
            return  # its beacons cannot support the pose: no beam need be checked
        if aside and len(refined.may_support) < min_beacons:
            pending.append((seq, h, refined, again is not None))
            pending_poses.add(refined.icp.pose)
            return
        keep(seq, h, refined, again is not None)

    for seq, h in enumerate(hypotheses):
        refine(seq, h, False)
    if (any(pending) or deferred) and (settled is None or not settled(_ranked(out, sequence))):
        for k in range(len(pending)):
            settle(k)
        for seq, h in deferred:
            refine(seq, h, True)
    return _ranked(out, sequence)


def _beacons_in_reach(
    starts: list[Pose2D],
    nears: list[NDArray[np.intp]],
    pts: NDArray[np.float64],
    angles: NDArray[np.float64],
    ranges: NDArray[np.float64],
    panels: PanelSet,
    gate_m: float,
    cfg: VerificationConfig,
    owns: Sequence[Sequence[str]] | None = None,
    enough: int = 0,
) -> list[frozenset[str]]:
    """:func:`_in_reach` of every start (its panels in reach ``nears``) in one compiled
    call (:func:`mast.core._kernels.beacons_in_reach`): each beacon tested only on the
    beams pointing its way (``angles``, increasing), and only until it has enough. The
    tests compare the two.

    With ``owns`` (each start's own beacons) and ``enough`` > 0, a start's set is cut
    short where the rest cannot change whether its own beacons are all in it, nor
    whether it has ``enough``: its own beacons are tested first, and the search stops
    at the first that falls short or at ``enough`` beacons."""
    from mast.core._kernels import beacons_in_reach

    if not starts:
        return []
    centre, radius = panels.discs
    sizes = np.array([n.size for n in nears], dtype=np.intp)
    if owns is None or enough <= 0:
        owns, enough = [() for _ in starts], 0
    number = panels.number
    own_lists = [sorted({number[b] for b in own}) for own in owns]
    own_ptr = np.zeros(len(starts) + 1, dtype=np.intp)
    own_ptr[1:] = np.cumsum([len(o) for o in own_lists])
    own = np.array([b for o in own_lists for b in o], dtype=np.intp)
    found, ptr = beacons_in_reach(
        np.ascontiguousarray(pts, dtype=float).reshape(-1, 2),
        np.ascontiguousarray(angles, dtype=float),
        np.ascontiguousarray(ranges, dtype=float),
        np.array([(p.easting, p.northing, p.azimuth) for p in starts], dtype=float),
        np.concatenate([[0], np.cumsum(sizes)]).astype(np.intp),
        np.concatenate(nears).astype(np.intp),
        panels.a,
        panels.direction,
        panels.normal,
        panels.length,
        panels.beacon,
        centre,
        radius,
        cfg.look_alike_reach_m + gate_m,
        math.tan(cfg.look_alike_reach_rad),
        2 * cfg.min_panel_points,
        own_ptr,
        own,
        enough,
    )
    ids = panels.ids
    return [frozenset(ids[b] for b in found[ptr[k] : ptr[k + 1]]) for k in range(len(starts))]


def _in_reach(
    start: Pose2D,
    pts: NDArray[np.float64],
    ranges: NDArray[np.float64],
    panels: PanelSet,
    near: NDArray[np.intp],
    gate_m: float,
    cfg: VerificationConfig,
) -> frozenset[str]:
    """The beacons that could be in ``may_support`` (:func:`_may_support`) at a pose ICP
    refines ``start`` to: those with ``2 * min_panel_points`` returns within
    ``look_alike_reach_m`` and ``look_alike_reach_rad`` of the start, and the gate
    ``gate_m``, of their panels (among ``near``). A return at range ``r`` moves by at
    most ``reach_m + r * reach_rad`` when the pose moves by ``reach_m`` and turns by
    ``reach_rad``. The reference of :func:`_beacons_in_reach`, which verification
    uses."""
    _, beacons, counts = panels.reach_tallies(
        start.scanner_to_mine(pts),
        ranges,
        cfg.look_alike_reach_m + gate_m,
        math.tan(cfg.look_alike_reach_rad),
        subset=near,
    )
    return frozenset(panels.ids[b] for b in beacons[counts >= 2 * cfg.min_panel_points])


def _ranked(out: list[Verified], sequence: dict[int, int]) -> list[Verified]:
    """Kept poses most supported first, then by likelihood, then in hypothesis order."""
    in_order = sorted(out, key=lambda v: sequence[id(v)])
    return sorted(in_order, key=lambda v: v.rank, reverse=True)
