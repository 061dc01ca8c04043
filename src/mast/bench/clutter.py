"""Real clutter: beacons mounted on the real walls of CARMEN logs, every scan located.

The CARMEN logs in ``../shared/data/carmen_corrected`` are whole runs through
office buildings with corrected (SLAM-optimised) laser poses. For each log:

1. *Sites.* Every scan's straight stretches (:func:`segment_scan`, long
   enough for the largest beacon plus a margin) are mapped into the mine
   frame (:func:`mast.io.carmen_log.read_carmen_log`) with the scan's pose.
   A candidate site is a point on such a stretch; the scans that *see it
   face-on* are those with a collinear stretch covering the whole chord, from
   the same side, within a useful range and at a useful incidence. Sites are
   chosen greedily, each adding the most scans that still see fewer than two
   beacons (then the most scans), at least :data:`MIN_SITE_SEPARATION_M`
   from the others and clear of the trajectory (no pose within
   :data:`MAX_DEPTH_M` plus :data:`ROBOT_CLEARANCE_M` of the wall in front of
   the site). The wall line at a site is refitted to the returns of every
   scan that saw it there.
2. *Beacons.* Identifiable random hats (:func:`mast.sim.random_design`,
   0.6-1.2 m chords for a 0.5 degree scanner, 0.9-1.8 m for a 1 degree one,
   every panel at least :data:`MIN_PANEL_M`, at most :data:`MAX_DEPTH_M`
   deep) stand out from the wall towards the side the scans saw it from.
   Most designs are distinct; one in :data:`REPEAT_EVERY` repeats an earlier
   one, as happens in real mines.
3. *Scans.* Each scan's beams are ray-cast against the panels at the scan's
   corrected pose: a beam that meets a panel before its real return (or
   that had no return) returns the panel, with Gaussian range noise
   (:data:`PANEL_NOISE_M`, the locator's a-priori sigma, by default: the
   fhw log's ranges come in 5 cm steps and its own noise estimate is some
   30 mm). The rest of the scan, real clutter included, is untouched. A
   scan is owed a fix when two beacons each show two panels with at least 4
   returns seen at 15 degrees or more (:data:`mast.sim.owed.OWED_REAL_WALLS`).
4. *Fixes.* Every scan is located and compared with its corrected pose by
   :func:`mast.bench.robustness.is_wrong`. The beacons are consistent
   with that pose by construction (they are cast at it), so a wrong fix is
   the locator's, not the pose's; the clutter is real.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast.bench.robustness import is_wrong
from mast.bench.tracking import prior_pair
from mast.core.beacon import Beacon, Survey
from mast.core.geometry import first_hits
from mast.core.lines import fit_line
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.errors import BeaconError
from mast.io.carmen_log import read_carmen_log
from mast.pipeline.locator import LocatorConfig, locate
from mast.pipeline.segmentation import Segmentation, segment_scan
from mast.sim.design import BeaconDesign, random_design
from mast.sim.owed import OWED_REAL_WALLS
from mast.sim.scanner import ScannerModel, SimulatedScan
from mast.sim.world import Surface

__all__ = [
    "CARMEN_LOGS",
    "ClutterSummary",
    "ScanOutcome",
    "WallSite",
    "beacon_designs",
    "carmen_logs",
    "cast_beacons",
    "chord_range_for",
    "mount_beacons",
    "run_clutter_log",
    "run_real_clutter",
    "scanner_model",
    "wall_sites",
]

#: The logs, by name, under ``data_dir``.
CARMEN_LOGS: dict[str, str] = {
    "fhw": "carmen_corrected/fhw-corrected.log.gz",
    "freiburg-101": "carmen_corrected/freiburg-101-corrected.log.gz",
}

#: Beacon chords along the wall, metres, for a 0.5 degree scanner at office ranges ...
CHORD_RANGE_M = (0.6, 1.2)
#: ... grown with coarser beam spacing (1 degree: 0.9-1.8 m) up to this factor, so that
#: panels still catch a few beams; office walls have little room for more.
MAX_CHORD_SCALE = 1.5
#: The beam spacing the chord range is meant for, radians.
CHORD_RANGE_SPACING_RAD = math.radians(0.5)
#: Shortest panel a design may have, metres (a 1 degree scanner puts 4 beams on 0.15 m at 2 m).
MIN_PANEL_M = 0.15
#: Deepest a design may stand out of the wall, metres (the paper's beacons: 0.1-0.4 m).
MAX_DEPTH_M = 0.4
#: The trajectory passes no closer than this to a beacon, metres (a robot's half width).
ROBOT_CLEARANCE_M = 0.25
#: Two distinct designs differ by at least this in some panel length, metres ...
DISTINCT_PANEL_M = 0.05
#: ... or by at least this in some deflection, radians.
DISTINCT_DEFLECTION_RAD = math.radians(10.0)
#: One beacon in this many repeats an earlier design (look-alikes on purpose).
REPEAT_EVERY = 6
#: Free wall kept beyond each end of the chord, metres.
SITE_MARGIN_M = 0.15
#: Candidate sites are spaced this far along each stretch, metres.
SITE_STEP_M = 0.25
#: Sites are at least this far apart, metres.
MIN_SITE_SEPARATION_M = 2.0
#: A stretch needs this many returns to count as a wall.
MIN_STRETCH_POINTS = 8
#: Another scan's stretch is the same wall when within this angle ...
SAME_WALL_ANGLE_RAD = math.radians(3.0)
#: ... and this perpendicular distance, metres.
SAME_WALL_OFFSET_M = 0.05
#: A site is seen face-on when the beam meets the wall at this incidence or more.
FACE_ON_INCIDENCE_RAD = math.radians(15.0)
#: A site is in useful range when a panel this long catches ...
USEFUL_PANEL_M = 0.4
#: ... at least this many beams face-on.
USEFUL_BEAMS = 4
#: Range noise added to panel returns, metres (the locator is told 10 mm).
PANEL_NOISE_M = 0.01


@dataclass(frozen=True, eq=False)
class WallSite:
    """A straight stretch of real wall chosen for a beacon, mine frame.

    Attributes
    ----------
    point : ndarray, shape (2,)
        Middle of the beacon's chord, on the refitted wall line (E, N).
    direction : ndarray, shape (2,)
        Unit tangent of the wall.
    free_side : ndarray, shape (2,)
        Unit normal pointing into the free space the scans saw it from.
    seen_by : ndarray of int
        Scans that saw the whole stretch face-on.
    rms_m : float
        RMS distance of those scans' returns from the refitted line.
    """

    point: NDArray[np.float64]
    direction: NDArray[np.float64]
    free_side: NDArray[np.float64]
    seen_by: NDArray[np.intp]
    rms_m: float

    @property
    def tunnel_side(self) -> int:
        """+1 when the free side lies left of ``direction`` (BeaconDesign.mounted)."""
        left = np.array([-self.direction[1], self.direction[0]])
        return 1 if float(left @ self.free_side) > 0 else -1


@dataclass(frozen=True, slots=True)
class ScanOutcome:
    """One located scan: what it was owed and what the locator said."""

    scan: int
    owed: bool
    status: str
    reason: str | None
    wrong: bool
    beacons: tuple[str, ...]
    beacons_hit: tuple[str, ...]
    error_m: float


@dataclass
class ClutterSummary:
    """Counts for one log (see :func:`run_real_clutter`)."""

    log: str
    beacons: int = 0
    designs: int = 0
    scans: int = 0
    owed: int = 0
    owed_fixed: int = 0
    fixes: int = 0
    fixes_not_owed: int = 0
    wrong: int = 0
    reasons: Counter[str] = field(default_factory=Counter)
    errors_mm: list[float] = field(default_factory=list)
    noise_mm: float = math.nan
    seconds: float = 0.0
    outcomes: list[ScanOutcome] = field(default_factory=list)
    tracked: bool = False
    prior_owed_fixed: int = 0
    prior_fixes: int = 0
    prior_wrong: int = 0
    wrong_prior_fixes: int = 0

    @property
    def fix_rate_owed(self) -> float:
        return self.owed_fixed / self.owed if self.owed else math.nan

    def line(self) -> str:
        reasons = ", ".join(f"{k} {v}" for k, v in self.reasons.most_common())
        err = np.asarray(self.errors_mm)
        med = float(np.median(err)) if err.size else math.nan
        top = float(err.max()) if err.size else math.nan
        return (
            f"{self.log:<12} beacons {self.beacons} ({self.designs} designs)  "
            f"scans {self.scans:4d}  owed {self.owed:4d}  fixed where owed {self.owed_fixed:4d} "
            f"({100 * self.fix_rate_owed:5.1f} %)  fixes {self.fixes:4d} "
            f"(not owed {self.fixes_not_owed})  WRONG {self.wrong}  "
            f"error median {med:.1f} mm max {top:.1f} mm  no-fix: {reasons}  "
            f"(scan noise {self.noise_mm:.0f} mm, {self.seconds:.0f} s)"
            + (
                f"\n{'':<12} with a good prior: fixed where owed {self.prior_owed_fixed:4d}  "
                f"fixes {self.prior_fixes:4d}  WRONG {self.prior_wrong};  "
                f"with a wrong prior: fixes {self.wrong_prior_fixes}"
                if self.tracked
                else ""
            )
        )


@dataclass(frozen=True, eq=False)
class _Stretches:
    """Every scan's long straight stretches, mine frame, as arrays."""

    scan: NDArray[np.intp]
    start: NDArray[np.float64]
    direction: NDArray[np.float64]
    normal: NDArray[np.float64]  # towards the scanner that saw it
    length: NDArray[np.float64]
    points: list[NDArray[np.float64]]


def _stretches(
    poses: Sequence[Pose2D], segmentations: Sequence[Segmentation], min_length_m: float
) -> _Stretches:
    scan, start, dirs, normals, lengths, points = [], [], [], [], [], []
    for i, (pose, seg) in enumerate(zip(poses, segmentations, strict=True)):
        for s in seg.segments:
            if s.length < min_length_m or len(s) < MIN_STRETCH_POINTS:
                continue
            a, b = pose.scanner_to_mine(np.array([s.start, s.end]))
            d = (b - a) / np.hypot(*(b - a))
            n = np.array([-d[1], d[0]])
            if float(n @ (pose.position - a)) < 0:
                n = -n
            scan.append(i)
            start.append(a)
            dirs.append(d)
            normals.append(n)
            lengths.append(float(np.hypot(*(b - a))))
            points.append(pose.scanner_to_mine(s.points))
    return _Stretches(
        np.array(scan, dtype=np.intp),
        np.array(start, dtype=float).reshape(-1, 2),
        np.array(dirs, dtype=float).reshape(-1, 2),
        np.array(normals, dtype=float).reshape(-1, 2),
        np.array(lengths, dtype=float),
        points,
    )


def wall_sites(
    poses: Sequence[Pose2D],
    segmentations: Sequence[Segmentation],
    count: int,
    *,
    half_span_m: float,
    useful_range_m: float,
    clearance_m: float = MAX_DEPTH_M + ROBOT_CLEARANCE_M,
) -> list[WallSite]:
    """Choose up to ``count`` straight stretches of real wall for beacons.

    Parameters
    ----------
    poses : sequence of Pose2D
        Each scan's pose in the mine frame.
    segmentations : sequence of Segmentation
        Each scan's segmentation (scanner frame), in the same order.
    count : int
        Sites wanted; fewer come back when the walls run out.
    half_span_m : float
        Free straight wall needed either side of a site, metres.
    useful_range_m : float
        Farthest a scanner may be from a site to count as seeing it, metres.
    clearance_m : float
        No pose may lie this close to the wall in front of a site (the beacon
        and the robot must not overlap), metres.

    Returns
    -------
    list of WallSite
        In the order chosen (greedy: most scans brought to two beacons first).
    """
    st = _stretches(poses, segmentations, 2 * half_span_m)
    if st.scan.size == 0:
        return []
    cand_pt, cand_n = [], []
    for k in range(st.scan.size):
        # a grid of points along the stretch, centred, half a span clear of its ends
        free = st.length[k] - 2 * half_span_m
        steps = int(free // SITE_STEP_M)
        ts = half_span_m + 0.5 * (free - steps * SITE_STEP_M) + SITE_STEP_M * np.arange(steps + 1)
        cand_pt.append(st.start[k] + ts[:, None] * st.direction[k])
        cand_n.append(np.broadcast_to(st.normal[k], (ts.size, 2)))
    pts = np.vstack(cand_pt)
    nrm = np.vstack(cand_n)
    # One candidate per cell and side of the wall: many scans see the same wall.
    key = np.column_stack(
        [np.floor(pts / SITE_STEP_M).astype(np.int64), np.round(4 * nrm).astype(np.int64)]
    )
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    pts, nrm = pts[first], nrm[first]
    positions = np.array([p.position for p in poses])
    rel = positions[None, :, :] - pts[:, None, :]
    perp = np.einsum("cpj,cj->cp", rel, nrm)
    along = np.abs(rel[..., 0] * nrm[:, None, 1] - rel[..., 1] * nrm[:, None, 0])
    blocked = np.any(
        (along <= half_span_m) & (perp > -SAME_WALL_OFFSET_M) & (perp < clearance_m), 1
    )
    seen = [
        _seen_by(pts[c], nrm[c], st, positions, half_span_m, useful_range_m)
        for c in range(len(pts))
    ]
    sees = np.zeros((len(pts), len(poses)), dtype=np.int64)
    for c, s in enumerate(seen):
        sees[c, s] = 1
    beacons_seen = np.zeros(len(poses), dtype=np.int64)
    open_ = ~blocked
    coverage = sees.sum(axis=1)
    chosen: list[WallSite] = []
    while len(chosen) < count and open_.any():
        # most scans still short of two beacons, then most scans in all
        gain = sees @ (beacons_seen < 2).astype(np.int64)
        score = np.where(open_ & (coverage > 0), gain * (len(poses) + 1) + coverage, -1)
        best = int(np.argmax(score))
        if score[best] < 0:
            break
        site = _refit(pts[best], nrm[best], seen[best], st, half_span_m)
        beacons_seen[site.seen_by] += 1
        chosen.append(site)
        open_ &= np.hypot(*(pts - site.point).T) >= MIN_SITE_SEPARATION_M
    return chosen


def _seen_by(
    point: NDArray[np.float64],
    normal: NDArray[np.float64],
    st: _Stretches,
    positions: NDArray[np.float64],
    half_span_m: float,
    useful_range_m: float,
) -> NDArray[np.intp]:
    """Scans with a stretch of the same wall, same side, covering the site face-on."""
    same = st.normal @ normal > math.cos(SAME_WALL_ANGLE_RAD)
    rel = point - st.start
    offset = np.abs(np.einsum("ij,ij->i", rel, st.normal))
    along = np.einsum("ij,ij->i", rel, st.direction)
    covers = (along >= half_span_m) & (along <= st.length - half_span_m)
    to_scanner = positions[st.scan] - point
    dist = np.hypot(*to_scanner.T)
    incidence = np.einsum("ij,j->i", to_scanner, normal) / np.maximum(dist, 1e-9)
    ok = (
        same
        & (offset < SAME_WALL_OFFSET_M)
        & covers
        & (dist <= useful_range_m)
        & (incidence >= math.sin(FACE_ON_INCIDENCE_RAD))
    )
    return np.unique(st.scan[ok])


def _refit(
    point: NDArray[np.float64],
    normal: NDArray[np.float64],
    seen: NDArray[np.intp],
    st: _Stretches,
    half_span_m: float,
) -> WallSite:
    """The wall line at a site from every seeing scan's returns on it (TLS)."""
    same = (st.normal @ normal > math.cos(SAME_WALL_ANGLE_RAD)) & np.isin(st.scan, seen)
    d0 = np.array([normal[1], -normal[0]])
    near: list[NDArray[np.float64]] = []
    for k in np.flatnonzero(same):
        p = st.points[k]
        rel = p - point
        keep = (np.abs(rel @ d0) <= half_span_m) & (np.abs(rel @ normal) < SAME_WALL_OFFSET_M)
        near.append(p[keep])
    pts = np.vstack([*near, point[None, :]])
    fit = fit_line(pts)
    d = fit.direction
    n = np.array([-d[1], d[0]])
    if float(n @ normal) < 0:
        n = -n
    mid = fit.centroid + float((point - fit.centroid) @ d) * d
    return WallSite(mid, d, n, seen, fit.rms)


def chord_range_for(angle_increment_rad: float) -> tuple[float, float]:
    """Beacon chord range for a scanner of this beam spacing (see :data:`MAX_CHORD_SCALE`)."""
    scale = min(MAX_CHORD_SCALE, max(1.0, angle_increment_rad / CHORD_RANGE_SPACING_RAD))
    return CHORD_RANGE_M[0] * scale, CHORD_RANGE_M[1] * scale


def _distinct(a: BeaconDesign, b: BeaconDesign) -> bool:
    ta = Beacon("a", a.edges_local).template
    tb = Beacon("b", b.edges_local).template
    return bool(
        np.max(np.abs(ta.panel_lengths - tb.panel_lengths)) >= DISTINCT_PANEL_M
        or np.max(np.abs(ta.deflections - tb.deflections)) >= DISTINCT_DEFLECTION_RAD
    )


def beacon_designs(
    count: int,
    rng: np.random.Generator,
    *,
    chord_range_m: tuple[float, float] = CHORD_RANGE_M,
) -> list[BeaconDesign]:
    """``count`` identifiable designs; one in :data:`REPEAT_EVERY` repeats an earlier one.

    Distinct designs differ by :data:`DISTINCT_PANEL_M` in a panel length or
    :data:`DISTINCT_DEFLECTION_RAD` in a deflection; every panel is at least
    :data:`MIN_PANEL_M` long, none stands out more than :data:`MAX_DEPTH_M`, and
    the design passes
    :meth:`Beacon.check_identifiable`.
    """
    distinct: list[BeaconDesign] = []
    repeats = count // REPEAT_EVERY
    while len(distinct) < count - repeats:
        d = random_design(rng, chord_range_m=chord_range_m)
        b = Beacon("design", d.edges_local)
        if b.template.panel_lengths.min() < MIN_PANEL_M or d.depth_m > MAX_DEPTH_M:
            continue
        try:
            b.check_identifiable()
        except BeaconError:
            continue
        if all(_distinct(d, o) for o in distinct):
            distinct.append(d)
    out = list(distinct)
    for _ in range(repeats):
        out.insert(int(rng.integers(0, len(out) + 1)), distinct[int(rng.integers(len(distinct)))])
    return out


def scanner_model(scan: Scan, name: str) -> ScannerModel:
    fov = math.degrees(float(scan.angles_rad[-1] - scan.angles_rad[0]))
    return ScannerModel(
        name,
        fov,
        math.degrees(scan.angle_increment),
        range_min_m=scan.range_min_m,
        range_max_m=scan.range_max_m,
    )


def cast_beacons(
    scan: Scan,
    pose: Pose2D,
    survey: Survey,
    rng: np.random.Generator,
    *,
    noise_m: float,
    scanner: ScannerModel | None = None,
) -> SimulatedScan:
    """Ray-cast the survey's panels into a real scan taken at ``pose``.

    A beam whose ray meets a panel before its real return, or that had no
    return, returns the panel (plus Gaussian noise ``noise_m``) if within the
    scanner's limits. The result records which beam hit which panel
    (surface 0 is the real scene, ``1 + 3 k + j`` panel ``j + 1`` of beacon ``k``).
    """
    beacons = list(survey)
    a = np.vstack([b.edges[:-1] for b in beacons])
    b = np.vstack([b.edges[1:] for b in beacons])
    surfaces = (Surface("wall"),) + tuple(
        Surface("beacon", bc.id, p) for bc in beacons for p in (1, 2, 3)
    )
    t, j = first_hits(pose.position, pose.beam_directions(scan.angles_rad), a, b)
    real = np.where(scan.valid, scan.ranges_m, np.inf)
    hit = (j >= 0) & (t < real) & (t >= scan.range_min_m) & (t <= scan.range_max_m)
    r = scan.ranges_m.copy()
    r[hit] = t[hit] + rng.normal(0.0, noise_m, int(hit.sum()))
    cast = Scan(
        scan.angles_rad, r, None, scan.range_min_m, scan.range_max_m, scan.stamp_ns, scan.frame_id
    )
    surface = np.where(hit, 1 + j, np.where(scan.valid, 0, -1)).astype(np.intp)
    true_r = np.where(hit, t, real)
    model = scanner if scanner is not None else scanner_model(scan, scan.frame_id)
    return SimulatedScan(cast, pose, model, true_r, surface, surfaces)


def mount_beacons(
    data: Sequence[tuple[Scan, Pose2D]], beacons: int, rng: np.random.Generator
) -> tuple[Survey, list[WallSite], list[BeaconDesign], list[Segmentation]]:
    """Beacons of random designs mounted on a log's walls (:func:`wall_sites`), in the
    frame of its true poses: the survey, the sites, their designs, and every scan's
    segmentation."""
    scans = [s for s, _ in data]
    poses = [p for _, p in data]
    segs = [segment_scan(s) for s in scans]
    inc = float(np.median([s.angle_increment for s in scans]))
    chord_range = chord_range_for(inc)
    sites = wall_sites(
        poses,
        segs,
        beacons,
        half_span_m=chord_range[1] / 2 + SITE_MARGIN_M,
        useful_range_m=chord_range[1] / CHORD_RANGE_M[1] * USEFUL_PANEL_M / (USEFUL_BEAMS * inc),
    )
    designs = beacon_designs(len(sites), rng, chord_range_m=chord_range)
    survey = Survey(
        Beacon(f"B{k + 1:02d}", d.mounted(s.point, s.direction, tunnel_side=s.tunnel_side))
        for k, (s, d) in enumerate(zip(sites, designs, strict=True))
    )
    return survey, sites, designs, segs


def run_clutter_log(
    name: str,
    data: Sequence[tuple[Scan, Pose2D]],
    *,
    beacons: int = 29,
    seed: int = 0,
    panel_noise_m: float | None = PANEL_NOISE_M,
    every: int = 1,
    config: LocatorConfig | None = None,
    priors: bool = False,
    echo: Callable[[str], object] = print,
) -> tuple[ClutterSummary, Survey, list[WallSite]]:
    """Mount beacons on one log's walls, cast them into every scan and locate each scan.

    Parameters
    ----------
    name : str
        The log's name in the report.
    data : sequence of (Scan, Pose2D)
        Scans with their true poses in the mine frame.
    beacons : int
        Beacons to mount (fewer when the walls run out).
    seed : int
        Seeds the designs and the range noise.
    panel_noise_m : float or None
        Range noise of panel returns; ``None`` uses each scan's own level
        (:attr:`Segmentation.noise_m`).
    every : int
        Locate every ``every``-th scan only (the sites use all of them): the
        locator takes 0.1-1 s a scan on these logs.
    config : LocatorConfig, optional
        Defaults to ``LocatorConfig(range_sigma_m=0.01)``.
    priors : bool
        Also locate every scan with a good prior (within 0.5 m and 5 degrees
        of its true pose) and with a wrong one (1.5 m off), as
        :func:`mast.bench.tracking.prior_pair` draws them: tracking in
        real clutter must fix as often and never follow a wrong prior.
    echo : callable
        Receives every wrong fix and the summary line.
    """
    t0 = time.perf_counter()
    if not data:
        return ClutterSummary(name), Survey([]), []
    cfg = config if config is not None else LocatorConfig(range_sigma_m=0.01)
    rng = np.random.default_rng(seed)
    scans = [s for s, _ in data]
    survey, sites, designs, segs = mount_beacons(data, beacons, rng)
    summary = ClutterSummary(
        name, beacons=len(survey), designs=len({id(d) for d in designs}), tracked=priors
    )
    prior_rng = np.random.default_rng([seed, 5])
    summary.noise_mm = 1e3 * float(np.median([g.noise_m for g in segs]))
    model = scanner_model(scans[0], name)
    for i, (scan, pose) in enumerate(data):
        if i % every:
            continue
        summary.scans += 1
        if len(survey) == 0:
            summary.reasons["no_beacon"] += 1
            continue
        sigma = panel_noise_m if panel_noise_m is not None else segs[i].noise_m
        sim = cast_beacons(scan, pose, survey, rng, noise_m=sigma, scanner=model)
        owed = sim.owes_fix(OWED_REAL_WALLS)
        fix = locate(sim.scan, survey, config=cfg)
        wrong = is_wrong(fix, pose)
        error = (
            math.hypot(fix.pose.easting - pose.easting, fix.pose.northing - pose.northing)
            if fix.ok and fix.pose is not None
            else math.nan
        )
        hit = tuple(sorted({b for b, _ in sim.panel_hits()}))
        summary.owed += owed
        summary.owed_fixed += owed and fix.ok
        summary.fixes += fix.ok
        summary.fixes_not_owed += fix.ok and not owed
        summary.wrong += wrong
        if fix.ok:
            summary.errors_mm.append(1e3 * error)
        else:
            summary.reasons[fix.reason or "?"] += 1
        if wrong:
            echo(
                f"  WRONG FIX {name} scan {i}: {fix.pose} (true {pose}), "
                f"beacons {', '.join(fix.beacons)} (panels hit on {', '.join(hit) or 'none'})"
            )
        summary.outcomes.append(
            ScanOutcome(i, owed, fix.status, fix.reason, wrong, fix.beacons, hit, error)
        )
        if priors:
            good, bad = prior_pair(pose, prior_rng)
            tracked = locate(sim.scan, survey, config=replace(cfg, prior=good))
            summary.prior_owed_fixed += owed and tracked.ok
            summary.prior_fixes += tracked.ok
            summary.prior_wrong += is_wrong(tracked, pose)
            followed = locate(sim.scan, survey, config=replace(cfg, prior=bad))
            summary.wrong_prior_fixes += followed.ok
            for what, f in (("good", tracked), ("wrong", followed)):
                if f.ok and (what == "wrong" or is_wrong(f, pose)):
                    echo(f"  WRONG FIX ({what} prior) {name} scan {i}: {f.pose} (true {pose})")
    summary.seconds = time.perf_counter() - t0
    echo(summary.line())
    return summary, survey, sites


def carmen_logs(
    data_dir: Path, logs: Iterable[str], seed: int
) -> Iterator[tuple[str, list[tuple[Scan, Pose2D]], int]]:
    """Each of ``logs`` present under ``data_dir``: its name, its scans with their
    corrected poses, and its seed (``seed`` plus its place in :data:`CARMEN_LOGS`, so
    that a log's run does not depend on which other logs are run)."""
    for name in logs:
        path = data_dir / CARMEN_LOGS[name]
        if path.is_file():
            yield name, list(read_carmen_log(path)), seed + list(CARMEN_LOGS).index(name)


def run_real_clutter(
    data_dir: Path,
    *,
    beacons: int = 29,
    seed: int = 0,
    panel_noise_m: float | None = PANEL_NOISE_M,
    every: int = 1,
    logs: Iterable[str] = tuple(CARMEN_LOGS),
    priors: bool = False,
    echo: Callable[[str], object] = print,
) -> list[ClutterSummary]:
    """Run :func:`run_clutter_log` on each CARMEN log present under ``data_dir``.

    Each log gets its own seed (``seed`` plus its place in :data:`CARMEN_LOGS`), so
    the runs are deterministic and independent of which other logs are run.
    """
    out: list[ClutterSummary] = []
    for name, data, log_seed in carmen_logs(data_dir, logs, seed):
        summary, _, _ = run_clutter_log(
            name,
            data,
            beacons=beacons,
            seed=log_seed,
            panel_noise_m=panel_noise_m,
            every=every,
            priors=priors,
            echo=echo,
        )
        out.append(summary)
    return out
