"""``mast survey-in``: beacon edges from terrestrial laser scans already in the mine grid.

The step the method starts from (the paper: beacons "surveyed in using a tripod based
laser scanner referenced to the mine reference system", their panel edges extracted
from the point cloud). The scans are in the grid already (the scanner set up over
control and backsighted, as every survey package does); the designs are the shapes
that were bolted up, one beacon per design in any frame (``DESIGNS.csv``).

1. **Panels**: :mod:`mast.cloud.detect`'s three passes and plan pieces, with the
   scanner's noise given (a TLS cloud is far denser than the local-fit noise estimate
   was made for: at millimetre spacing it measures the spacing, not the noise).
2. **Beacons**: the corners identified against the designs (Table 1 tests, as
   ``locate``'s), whole beacons (e2 and e3 sharing P2) kept when their middle panel's
   length is the design's; a beacon found from several pieces or stations is one
   beacon (the detection with the most panel points is kept).
3. **The beacon-level fit**: each panel's plan line fitted to its points (total least
   squares, its angle and offset with their variances from the fit's own residuals);
   e2 and e3 where neighbouring lines meet, e1 and e4 at the design's panel lengths
   along P1 and P3 from them (a panel's free end is where its points stop, which a
   scan sees short by its spacing; the length bolted up is known). The four edges'
   8x8 covariance is propagated from the three lines' (e1 and e2 share P1 and P2, e2
   and e3 share P2, ...), plus the station's own setup error (``station_sigma_m``)
   on every coordinate. ``sigma_m`` is the root mean square of an edge's two
   coordinate standard deviations. The top is where the panels' point density halves
   (:class:`mast.cloud.detect.Panel`), the panels' tops combined.
4. **Names**: with a previous survey, a beacon found within
   :data:`SAME_BEACON_M` of a previous one of the same design keeps its id, and each
   edge's displacement is tested against both surveys' precision (chi-square, two
   degrees of freedom, at :data:`MOVED_ALPHA`); new beacons are ``<design>-<n>``,
   numbered along increasing easting then northing.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast.cloud.beacon_fit import (
    edges_covariance,
    edges_from_lines,
    panel_line,
    points_on_panel,
)
from mast.cloud.detect import (
    NEARLY_PARALLEL_SINE,
    DetectConfig,
    Panel,
    PlanPieces,
    Progress,
    beacon_top,
    find_candidates,
    panel_from_points,
    plan_pieces,
)
from mast.cloud.grid import PlanIndex
from mast.cloud.io import Chunk, Cloud, open_cloud
from mast.cloud.match import Detection, detect_beacons
from mast.core.beacon import Beacon, BeaconTemplate, Survey
from mast.core.index import SurveyIndex
from mast.errors import InputError
from mast.pipeline.identification import IdentificationConfig, identify_panels

__all__ = [
    "MOVED_ALPHA",
    "SAME_BEACON_M",
    "FoundBeacon",
    "SurveyIn",
    "SurveyInConfig",
    "survey_in",
]

#: A beacon found within this of a previous one of the same design is that beacon.
SAME_BEACON_M = 0.5
#: An edge has moved when its displacement's chi-square (2 dof) passes this level.
MOVED_ALPHA = 0.001
#: A whole beacon's middle panel, between its fitted inner edges, may differ from its
#: design's by this, plus 2 % of it (a beacon built to its design).
LENGTH_SLACK_M = 0.005
#: A panel's points may reach this far beyond its edges (the noise, a mixed return).
PANEL_SLACK_M = 0.02
#: A panel is seen when its points span at least this share of its length.
MIN_SHARE_SEEN = 0.2
#: A panel's points are gathered again this many times from the fitted edges.
GATHER_ROUNDS = 2
#: A panel's points lie within three noise sigmas and this of its line (a bulge, the
#: fit's own error).
GATHER_SLACK_M = 0.003
#: Points this close to a panel's boundary are left out of its line (mixed returns).
END_MARGIN_M = 0.01
#: A free end's points may stop this short of a design's length and confirm it (the
#: scan's spacing, the mixed returns at the end, the margin kept from the boundary).
END_TOLERANCE_M = 0.015
#: Points running on this far past a design's free end refute it.
OVERRUN_M = 0.01
#: A panel's points are one run until a gap wider than this along its line, or than
#: :data:`REACH_GAP_SPACINGS` times the scan's spacing on it (:func:`column_spacing`).
REACH_GAP_M = 0.02
REACH_GAP_SPACINGS = 1.5
#: How far past a design's free end its points are looked for.
FREE_END_LOOK_M = 0.05
#: Fewest points a panel's line is fitted to.
MIN_PANEL_POINTS = 30
#: Detections whose centres are closer than this are one beacon.
ONE_BEACON_M = 0.3
#: A beacon's outer panels may meet at their design's angle give or take this, plus
#: three of their lines' standard deviations, when its middle panel is sought between
#: them: only where to look (the fitted beacon's angles are then held to Table 1's
#: half a degree, :func:`_angles_hold`).
EDGE_ON_ANGLE_RAD = math.radians(2.0)
#: Where the outer panels and the design put a middle panel seen edge-on, its points
#: are gathered this much wider than a fitted line's (the design's angles as built).
EDGE_ON_GATE_M = 0.01
#: A middle panel seen edge-on is gathered from this far below its outer panels' bottom
#: to as far above their top (a face running from floor to roof is no panel), and its
#: plane is looked at this far past e2 and e3 (:func:`_runs_on`).
EDGE_ON_REACH_M = 0.1
EDGE_ON_LOOK_M = 0.1
#: A beacon's panels' tops agree within this (levelled and cut alike).
TOP_AGREE_M = 0.03
#: A middle panel seen edge-on has points in this share of the 5 cm height bins between
#: its outer panels' bottom and top (a column of it, not rock crossing its plane).
EDGE_ON_HEIGHT_SHARE = 0.75


@dataclass(frozen=True, slots=True)
class SurveyInConfig:
    """What ``mast survey-in`` is asked to do.

    Attributes
    ----------
    noise_m : float
        The scanner's range noise (one coordinate's standard deviation), metres.
    station_sigma_m : float
        Standard deviation of a station's setup in each horizontal coordinate (the
        scanner over control, backsighted), added to every edge's; 0 where the scans'
        poses are exact (simulations).
    detect : DetectConfig
        The panel search's other settings.
    """

    noise_m: float = 0.002
    station_sigma_m: float = 0.001
    detect: DetectConfig = field(default_factory=DetectConfig)

    def __post_init__(self) -> None:
        if not 0.0 < self.noise_m < 1.0:
            raise ValueError(f"noise_m must be a positive number of metres, got {self.noise_m}")
        if not 0.0 <= self.station_sigma_m < 1.0:
            raise ValueError(
                f"station_sigma_m must be 0 or more metres, got {self.station_sigma_m}"
            )


@dataclass(frozen=True, eq=False)
class FoundBeacon:
    """One beacon surveyed in.

    Attributes
    ----------
    beacon : Beacon
        Its id, edges, the elevation of each edge's top, ``sigma_m`` and design.
    covariance : ndarray, shape (8, 8)
        The edges' covariance, (E1, N1, E2, N2, ..., N4), metres squared.
    sigma_top_m : float
    panels : tuple of Panel
        P1, P2, P3 as found.
    panel_lengths_m, design_lengths_m : ndarray, shape (3,)
        Each panel's length measured (its points' extent along its line; the inner
        ends at e2 and e3) and built.
    points_per_panel : tuple of int
        The points each panel's line was fitted to.
    previous : str or None
        The previous survey's id it kept, if any.
    moved : tuple of bool or None
        Per edge, whether its displacement from the previous survey is significant
        (``d^T (C + s^2 I)^-1 d`` against chi-square with 2 degrees of freedom, ``C`` the
        edge's 2x2 covariance now, ``s`` its previous ``sigma_m``); None when the
        previous survey gives no ``sigma_m`` for it (untested: its precision unknown).
    displacement_m : ndarray, shape (4,)
        Per edge, the horizontal displacement from the previous survey (NaN if none).
    """

    beacon: Beacon
    covariance: NDArray[np.float64]
    sigma_top_m: float
    panels: tuple[Panel, ...]
    panel_lengths_m: NDArray[np.float64]
    design_lengths_m: NDArray[np.float64]
    points_per_panel: tuple[int, ...] = ()
    previous: str | None = None
    moved: tuple[bool | None, ...] = (False, False, False, False)
    displacement_m: NDArray[np.float64] = field(default_factory=lambda: np.full(4, np.nan))


@dataclass(frozen=True, eq=False)
class SurveyIn:
    """What a survey-in found: the beacons, and what the search saw."""

    beacons: tuple[FoundBeacon, ...]
    designs: Survey
    pieces: PlanPieces
    points: int
    partial: int  # beacons seen in part (one corner): not surveyed
    rejected: int  # whole shapes whose middle panel is not their design's
    previous_missing: tuple[str, ...] = ()
    #: Where a middle panel seen edge-on stood between outer panels of a design and the
    #: beacon could not be fitted (its columns' line off the design's angles): plan.
    edge_on: tuple[NDArray[np.float64], ...] = ()

    @property
    def survey(self) -> Survey:
        return Survey([f.beacon for f in self.beacons])


class ChainedCloud(Cloud):
    """Several clouds read one after another as one (stations scanned apart)."""

    def __init__(self, clouds: Sequence[Cloud]) -> None:
        self._clouds = list(clouds)
        self.path = self._clouds[0].path
        self.count = sum(c.count for c in self._clouds)
        self.time_field = None

    def chunks(self, size: int = 2_000_000) -> Iterator[Chunk]:
        for c in self._clouds:
            for chunk in c.chunks(size):
                yield Chunk(chunk.xyz, None)


def survey_in(
    paths: Sequence[Path],
    designs: Survey,
    config: SurveyInConfig = SurveyInConfig(),
    *,
    previous: Survey | None = None,
    progress: Progress | None = None,
) -> SurveyIn:
    """Survey in the beacons the clouds at ``paths`` show (see the module); ``progress``
    is told of each pass over the points (:data:`mast.cloud.detect.Progress`: the pass,
    points done, points in all its passes)."""
    if not paths:
        raise InputError("no cloud given")
    clouds = [open_cloud(p) for p in paths]
    cloud: Cloud = clouds[0] if len(clouds) == 1 else ChainedCloud(clouds)
    detect = replace(config.detect, noise_m=config.noise_m)
    cand = find_candidates(cloud, detect, progress)
    pieces = plan_pieces(cand, detect)
    index = SurveyIndex.from_survey(designs, reach_m=5.0)
    for group in index.designs:
        if len(group) > 1:  # designs alike within the index's tolerance: one name for both
            raise InputError(
                f"designs {' and '.join(repr(g) for g in group[:2])} are the same shape within "
                "5 mm and 0.5 deg: a scan cannot tell them apart; name one design once",
                path=designs.source,
            )
    ident = identify_panels(pieces.segmentation, index.representatives, survey_sigma_m=0.0)
    dets = detect_beacons(pieces, ident, index)
    found: list[FoundBeacon] = []
    rejected = 0
    whole = _one_per_beacon([d for d in dets if d.whole and len(d.panels) == 3], pieces)
    for det in whole:
        panels = tuple(pieces.panels[det.panels[k]] for k in (1, 2, 3))
        fit = _fit(panels, (det.nodes[2], det.nodes[3]), det.designs, cand.xyz, index, config)
        if fit is None:
            rejected += 1
            continue
        found.append(fit)
    used = {k for d in whole for k in d.panels.values()}
    edge_on, refused = _middle_edge_on(pieces, cand.xyz, index, config, whole, used)
    found += edge_on
    # a corner of a beacon surveyed whole (from another piece or station) is not "in part"
    parts = _one_per_beacon([d for d in dets if not d.whole], pieces)
    partial = sum(
        all(math.dist(d.centre, f.beacon.edges.mean(axis=0)) > ONE_BEACON_M for f in found)
        for d in parts
    )
    named, missing = _name(found, previous)
    return SurveyIn(
        tuple(named), designs, pieces, cloud.count, partial, rejected, missing, tuple(refused)
    )


def _middle_edge_on(
    pieces: PlanPieces,
    xyz: NDArray[np.float64],
    index: SurveyIndex,
    config: SurveyInConfig,
    detected: list[Detection],
    used: set[int],
) -> tuple[list[FoundBeacon], list[NDArray[np.float64]]]:
    """Beacons whose middle panel a station saw edge-on (module, step 2): a couple of
    columns of points, too few and too close together for a piece of its own, so no
    corner finds the beacon. Two panels whose lines meet at a design's angle between
    P1 and P3, with their points where that design's P1 and P3 would lie, place its
    middle panel; its points are gathered there and tested as a piece's (vertical, flat,
    at the outer panels' heights, filling them), and the beacon is fitted as one found
    whole (:func:`_fit`: the middle panel's own line must meet the others at the
    design's length). Nowhere near a whole beacon found from corners, and never with a
    panel of one (``used``). With the beacons found, the places where a middle panel
    stood and the fit refused the beacon.

    A design whose P1 and P3 are parallel (a U or a Z) is not placed this way: two
    parallel lines do not say where along them the middle panel lies."""
    reps = index.representatives
    panels = pieces.panels
    if len(panels) < 2 or not reps or xyz.shape[0] == 0:
        return [], []
    plan = PlanIndex(xyz[:, :2])
    centroids = np.array([p.segment.centroid for p in panels])
    taken = [d.centre for d in detected]
    used = set(used)
    found: list[FoundBeacon] = []
    refused: list[NDArray[np.float64]] = []
    shapes = [(rep.template.directions, rep.template.panel_lengths) for rep in reps]
    span = max(float(lengths.sum()) for _, lengths in shapes)
    order = sorted(range(len(panels)), key=lambda i: -len(panels[i].segment.points))
    for i in order:
        a = panels[i]
        for j in np.flatnonzero(np.hypot(*(centroids - centroids[i]).T) <= span):
            b = panels[int(j)]
            if j == i or {i, int(j)} & used or abs(a.top_m - b.top_m) > TOP_AGREE_M:
                continue
            for sign in (1.0, -1.0):
                placed = _placed(a, b, sign, shapes)
                for _, edges in placed:
                    centre = 0.5 * (edges[1] + edges[2])
                    if any(math.dist(centre, t) <= ONE_BEACON_M for t in taken):
                        break
                    middle = _middle_panel(edges, a, b, xyz, plan, config)
                    if middle is None:
                        continue
                    fit = _fit(
                        (a, middle, b),
                        (edges[1], edges[2]),
                        [k for k, _ in placed],
                        xyz[plan.square(centre, span + 0.5)],
                        index,
                        config,
                        top_from=(0, 2),
                    )
                    if fit is not None:
                        found.append(fit)
                        taken.append(centre)
                        used.update((i, int(j)))
                    elif all(math.dist(centre, r) > ONE_BEACON_M for r in refused):
                        refused.append(centre)
                    break
    # a place refused from one couple of panels may be surveyed from another
    return found, [r for r in refused if all(math.dist(r, t) > ONE_BEACON_M for t in taken)]


def _placed(
    a: Panel,
    b: Panel,
    sign: float,
    shapes: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
) -> list[tuple[int, NDArray[np.float64]]]:
    """The designs (number, their four edges in plan) that panel ``a`` as P1 (directed
    from e1 to e2 by ``sign``) and ``b`` as P3 would make: the design turned onto
    ``a``'s line, ``b``'s line at its P3's angle (:data:`EDGE_ON_ANGLE_RAD`), e2 on
    ``a``'s line and e3 on ``b``'s at the middle panel's length apart, and each panel's
    points between its edges."""
    out = []
    d1 = sign * a.segment.direction
    tol = EDGE_ON_ANGLE_RAD + 3.0 * math.hypot(a.segment.sigma_direction,
                                               b.segment.sigma_direction)  # fmt: skip
    for k, (units, lengths) in enumerate(shapes):
        u1 = units[0]
        c, s = float(u1 @ d1), float(u1[0] * d1[1] - u1[1] * d1[0])
        turn = np.array([[c, -s], [s, c]])
        d2, d3 = turn @ units[1], turn @ units[2]
        d3b = b.segment.direction if float(d3 @ b.segment.direction) > 0 else -b.segment.direction
        if abs(math.atan2(d3[0] * d3b[1] - d3[1] * d3b[0], float(d3 @ d3b))) > tol:
            continue
        system = np.column_stack([d1, -d3b])
        if abs(float(np.linalg.det(system))) < NEARLY_PARALLEL_SINE:
            continue
        st = np.linalg.solve(system, b.segment.centroid - a.segment.centroid - lengths[1] * d2)
        e2 = a.segment.centroid + st[0] * d1
        e3 = e2 + lengths[1] * d2
        edges = np.array([e2 - lengths[0] * d1, e2, e3, e3 + lengths[2] * d3b])
        if _between(a, edges[0], edges[1]) and _between(b, edges[2], edges[3]):
            out.append((k, edges))
    return out


def _between(panel: Panel, a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """Whether nine in ten of a panel's points lie between ``a`` and ``b`` (give or take
    :data:`PANEL_SLACK_M`) along the line through them."""
    length = max(math.dist(a, b), 1e-9)
    t = (panel.segment.points - a) @ ((b - a) / length)
    return bool(np.mean((t > -PANEL_SLACK_M) & (t < length + PANEL_SLACK_M)) >= 0.9)


def _middle_panel(
    edges: NDArray[np.float64],
    a: Panel,
    b: Panel,
    xyz: NDArray[np.float64],
    plan: PlanIndex,
    config: SurveyInConfig,
) -> Panel | None:
    """The middle panel's points where a design placed between ``a`` (P1) and ``b`` (P3)
    puts it (``edges``, plan), as a :class:`Panel`; None unless they are one
    (:func:`~mast.cloud.detect.panel_from_points`, on every point of its face from
    :data:`EDGE_ON_REACH_M` below the outer panels to as far above: a surface running
    from floor to roof is none), its top the outer panels' (:data:`TOP_AGREE_M`), they
    fill its heights (:data:`EDGE_ON_HEIGHT_SHARE`), and its plane does not run on past
    e2 or e3 (:func:`_runs_on`). Its bottom and top are then the outer panels'."""
    centre = 0.5 * (edges[1] + edges[2])
    near = xyz[plan.square(centre, math.dist(edges[1], edges[2]) + EDGE_ON_LOOK_M)]
    shared = (max(a.bottom_m, b.bottom_m), min(a.top_m, b.top_m))
    wide = (shared[0] - EDGE_ON_REACH_M, shared[1] + EDGE_ON_REACH_M)
    gate = 3.0 * config.noise_m + GATHER_SLACK_M + EDGE_ON_GATE_M
    keep = points_on_panel(near[:, :2], near[:, 2], edges[1], edges[2], wide, gate, END_MARGIN_M)
    if np.count_nonzero(keep) < MIN_PANEL_POINTS:
        return None
    detect = replace(config.detect, noise_m=config.noise_m)
    panel = panel_from_points(near[keep], config.noise_m, detect)
    if isinstance(panel, str) or abs(panel.top_m - 0.5 * (a.top_m + b.top_m)) > TOP_AGREE_M:
        return None
    z = near[keep, 2]
    bins = np.arange(shared[0], shared[1], 0.05)
    inside = z[(z >= shared[0]) & (z < shared[1])]
    filled = np.unique(np.searchsorted(bins, inside, side="right")).size
    if filled < EDGE_ON_HEIGHT_SHARE * bins.size:
        return None
    if _runs_on(near, edges, shared, gate, inside.size):
        return None
    # its points are gathered again between the outer panels' heights (a beacon's panels
    # are cut alike; a couple of columns' own bottom and top are the least sure of three)
    return replace(panel, bottom_m=shared[0], top_m=shared[1])


def _runs_on(
    near: NDArray[np.float64],
    edges: NDArray[np.float64],
    heights: tuple[float, float],
    gate: float,
    count: int,
) -> bool:
    """Whether the middle panel's plane runs on past e2 or e3: points on its line from
    where the outer panels' own points clear it (its gate over the sine of the corner's
    angle) to :data:`EDGE_ON_LOOK_M` further, at its heights, at half its own density
    or more. A panel ends at its edges; a flat face that runs on is no middle panel."""
    e2, e3 = edges[1], edges[2]
    length = math.dist(e2, e3)
    u = (e3 - e2) / max(length, 1e-9)
    t = (near[:, :2] - e2) @ u
    off = (near[:, :2] - e2) @ np.array([-u[1], u[0]])
    level = (near[:, 2] > heights[0]) & (near[:, 2] < heights[1]) & (np.abs(off) <= gate)
    density = count / max(length, 1e-9)
    for k, ahead in ((0, -t), (2, t - length)):
        outer = edges[k + 1] - edges[k]
        sine = abs(float(outer[0] * u[1] - outer[1] * u[0])) / max(float(np.hypot(*outer)), 1e-9)
        clear = min(max(OVERRUN_M, gate / max(sine, 0.1)), 0.1)
        past = np.count_nonzero(level & (ahead > clear) & (ahead < clear + EDGE_ON_LOOK_M))
        if past >= 0.5 * density * EDGE_ON_LOOK_M:
            return True
    return False


def _points(det: Detection, pieces: PlanPieces) -> int:
    return sum(len(pieces.panels[k].segment.points) for k in det.panels.values())


def _one_per_beacon(dets: list[Detection], pieces: PlanPieces) -> list[Detection]:
    """The detection with the most panel points among those within :data:`ONE_BEACON_M`
    of each other (one beacon found from several pieces, corners or stations)."""
    out: list[Detection] = []
    for d in sorted(dets, key=lambda d: -_points(d, pieces)):
        if all(math.dist(d.centre, o.centre) > ONE_BEACON_M for o in out):
            out.append(d)
    return out


def _fit(
    panels: tuple[Panel, ...],
    inner: tuple[NDArray[np.float64], NDArray[np.float64]],
    designs: Iterable[int],
    xyz: NDArray[np.float64],
    index: SurveyIndex,
    config: SurveyInConfig,
    *,
    top_from: tuple[int, ...] = (0, 1, 2),
) -> FoundBeacon | None:
    """The beacon-level fit of a whole beacon, its panels P1-P3 with e2 and e3 where they
    were found (``inner``) and the ``designs`` its shape may be (module, step 3); its top
    from the panels ``top_from`` (0-based). None when no design holds it (:func:`_fits`,
    :func:`_free_ends`), a panel is seen too little or has too few points, or the panels
    do not meet at the design's angles (:func:`_angles_hold`)."""
    # lines about a point at the beacon: in grid coordinates (70 km from the origin) an
    # angle's variance times the lever would swamp the offsets' in the propagation
    origin = 0.5 * (inner[0] + inner[1])
    # the pieces' lines choose the design; the panels' own points fit the edges below
    lines = np.array([panel_line(p.segment.points - origin, config.noise_m)[0] for p in panels])
    reps = index.representatives
    # P1's points lie from e2 towards e1, P3's from e3 towards e4
    outward = np.array(
        [panels[0].segment.centroid - inner[0], panels[2].segment.centroid - inner[1]]
    )
    held = []
    for k in designs:
        lengths = reps[k].template.panel_lengths
        if _fits(edges_from_lines(lines, lengths, outward).reshape(4, 2), panels, origin, lengths):
            held.append(k)
    if not held:
        return None
    longest = max(float(reps[k].template.panel_lengths.sum()) for k in held)
    near = xyz[np.max(np.abs(xyz[:, :2] - origin), axis=1) < longest + 0.5]
    design = _free_ends(held, reps, lines, outward, near, origin, panels, config)
    if design is None:
        return None
    lengths = design.template.panel_lengths
    edges = edges_from_lines(lines, lengths, outward)
    # every candidate point of each panel, not only its piece's (a long panel's piece
    # may be a fragment of it: a bulge or the mixed returns at its ends cut it), twice
    for _ in range(GATHER_ROUNDS):
        own = [_gather(near, origin, edges.reshape(4, 2), k, panels[k], config) for k in range(3)]
        if any(len(p) < MIN_PANEL_POINTS for p in own):
            return None
        params, covs, _ = zip(*(panel_line(p, config.noise_m) for p in own), strict=True)
        lines = np.array(params)
        edges = edges_from_lines(lines, lengths, outward)
    xy4 = edges.reshape(4, 2)
    if not _angles_hold(xy4, design, covs):
        return None
    reach1, reach3 = _reaches(xy4[1], xy4[2], xy4[0], xy4[3], lengths, near, origin, panels,
                              config)  # fmt: skip
    middle = (own[1] - xy4[1]) @ ((xy4[2] - xy4[1]) / max(math.dist(xy4[1], xy4[2]), 1e-9))
    seen = [reach1, float(np.ptp(middle)) + 2 * END_MARGIN_M, reach3]
    if any(s < MIN_SHARE_SEEN * length for s, length in zip(seen, lengths, strict=True)):
        return None
    cov = edges_covariance(lines, covs, lengths, outward) + config.station_sigma_m**2 * np.eye(8)
    sig = np.sqrt(0.5 * (np.diag(cov)[0::2] + np.diag(cov)[1::2]))
    top, sigma_top = beacon_top([panels[k] for k in top_from])
    xy = edges.reshape(4, 2) + origin
    measured = np.array(seen)
    beacon = Beacon("?", xy, np.full(4, top), sig, design.design or design.id)
    return FoundBeacon(
        beacon, cov, sigma_top, panels, measured, lengths, tuple(len(p) for p in own)
    )


def _on_line(
    xyz: NDArray[np.float64],
    origin: NDArray[np.float64],
    start: NDArray[np.float64],
    toward: NDArray[np.float64],
    panel: Panel,
    config: SurveyInConfig,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Each point's position along a panel's line (from ``start``, unit ``toward``, both
    about ``origin``), and whether it is on the panel's face: within three noise sigmas
    and :data:`GATHER_SLACK_M` of the line, and within the panel's heights less
    :data:`END_MARGIN_M` at the top and bottom (their mixed returns)."""
    rel = xyz[:, :2] - origin - start
    t = rel @ toward
    off = rel @ np.array([-toward[1], toward[0]])
    z = xyz[:, 2]
    keep = (
        (np.abs(off) <= 3.0 * config.noise_m + GATHER_SLACK_M)
        & (z > panel.bottom_m + END_MARGIN_M)
        & (z < panel.top_m - END_MARGIN_M)
    )
    return t, keep


def _reach(
    xyz: NDArray[np.float64],
    origin: NDArray[np.float64],
    start: NDArray[np.float64],
    toward: NDArray[np.float64],
    limit: float,
    panel: Panel,
    config: SurveyInConfig,
) -> float:
    """How far a panel's points run from its inner edge ``start`` towards its free end
    (unit ``toward``, looked at up to ``limit``): the end of the first unbroken run (no
    gap wider than :data:`REACH_GAP_M`, or the scan's spacing on the panel), so rock
    met further along the line does not count."""
    t, keep = _on_line(xyz, origin, start, toward, panel, config)
    ts = np.sort(t[keep & (t > 0.0) & (t < limit)])
    gap = max(REACH_GAP_M, REACH_GAP_SPACINGS * column_spacing(panel))
    if ts.size == 0 or ts[0] > gap:
        return 0.0
    gaps = np.flatnonzero(np.diff(ts) > gap)
    return float(ts[gaps[0]] if gaps.size else ts[-1])


def column_spacing(panel: Panel) -> float:
    """The scan's spacing along a panel: the gaps between its piece's points along its
    line, their median weighted by their own widths. A near panel's points lie
    millimetres apart; an oblique one at 20 m is seen in columns centimetres apart; a
    gap where something shadows part of a panel is one gap, not the spacing."""
    seg = panel.segment
    gaps = np.sort(np.diff((seg.points - seg.centroid) @ seg.direction))
    if gaps.size == 0 or gaps[-1] <= 0.0:
        return 0.0
    cum = np.cumsum(gaps)
    return float(gaps[min(int(np.searchsorted(cum, 0.5 * cum[-1])), gaps.size - 1)])


def _end_tolerance(panel: Panel) -> float:
    """How far short of a design's free end a panel's points may stop and confirm it:
    :data:`END_TOLERANCE_M`, or the margin kept from the boundary and one of the scan's
    spacings on the panel where that is wider."""
    return max(END_TOLERANCE_M, END_MARGIN_M + column_spacing(panel))


def _reaches(
    e2: NDArray[np.float64],
    e3: NDArray[np.float64],
    e1: NDArray[np.float64],
    e4: NDArray[np.float64],
    lengths: NDArray[np.float64],
    xyz: NDArray[np.float64],
    origin: NDArray[np.float64],
    panels: tuple[Panel, ...],
    config: SurveyInConfig,
) -> tuple[float, float]:
    """How far P1's and P3's points run from e2 and e3 towards their free ends."""
    u1 = (e1 - e2) / max(math.dist(e1, e2), 1e-9)
    u3 = (e4 - e3) / max(math.dist(e4, e3), 1e-9)
    return (
        _reach(xyz, origin, e2, u1, lengths[0] + FREE_END_LOOK_M, panels[0], config),
        _reach(xyz, origin, e3, u3, lengths[2] + FREE_END_LOOK_M, panels[2], config),
    )


def _free_ends(
    held: list[int],
    reps: list[Beacon],
    lines: NDArray[np.float64],
    outward: NDArray[np.float64],
    xyz: NDArray[np.float64],
    origin: NDArray[np.float64],
    panels: tuple[Panel, ...],
    config: SurveyInConfig,
) -> Beacon | None:
    """Which of the designs that hold the shape it is, by where its free ends' points
    stop. A design is refuted when points run on past a free end of it by more than
    :data:`OVERRUN_M`, and a free end confirms it when its points stop within
    :func:`_end_tolerance` short of it; of the designs not refuted, the one that the
    most free ends confirm. None when none is left, or when two are left alike (a free
    end that would tell them apart is not seen): better no survey than a wrong design,
    whose free end is placed at the wrong length with a sigma that does not know it."""
    scored = []
    tols = (_end_tolerance(panels[0]), _end_tolerance(panels[2]))
    for k in held:
        lengths = reps[k].template.panel_lengths
        e = edges_from_lines(lines, lengths, outward).reshape(4, 2)
        reaches = _reaches(e[1], e[2], e[0], e[3], lengths, xyz, origin, panels, config)
        deficits = (lengths[0] - reaches[0], lengths[2] - reaches[1])
        if any(d < -OVERRUN_M for d in deficits):
            continue
        confirmed = sum(d <= tol for d, tol in zip(deficits, tols, strict=True))
        scored.append((confirmed, k, lengths))
    if not scored:
        return None
    scored.sort(key=lambda s: -s[0])
    best = scored[0]
    for other in scored[1:]:
        if other[0] == best[0] and np.max(np.abs(other[2] - best[2])) > END_TOLERANCE_M:
            return None  # two designs alike on what was seen: ambiguous
    return reps[best[1]]


def _gather(
    xyz: NDArray[np.float64],
    origin: NDArray[np.float64],
    edges: NDArray[np.float64],
    k: int,
    panel: Panel,
    config: SurveyInConfig,
) -> NDArray[np.float64]:
    """Panel ``k``'s points (plan, about ``origin``): within three noise sigmas and
    :data:`GATHER_SLACK_M` of its line, between its edges less :data:`END_MARGIN_M` at
    each (the corners' and free ends' mixed returns), and within its heights less as
    much at the top and bottom (:func:`~mast.cloud.beacon_fit.points_on_panel`)."""
    plan = xyz[:, :2] - origin
    keep = points_on_panel(
        plan,
        xyz[:, 2],
        edges[k],
        edges[k + 1],
        (panel.bottom_m, panel.top_m),
        3.0 * config.noise_m + GATHER_SLACK_M,
        END_MARGIN_M,
    )
    out: NDArray[np.float64] = plan[keep]
    return out


def _fits(
    edges: NDArray[np.float64],
    panels: tuple[Panel, ...],
    origin: NDArray[np.float64],
    lengths: NDArray[np.float64],
) -> bool:
    """Whether the edges a design gives hold its panels: the middle panel as long as the
    design's, and each panel's points between its two edges (a shape assembled from
    pieces of other beacons or rock has its points elsewhere)."""
    if abs(math.dist(edges[1], edges[2]) - lengths[1]) > LENGTH_SLACK_M + 0.02 * lengths[1]:
        return False
    for k, p in enumerate(panels):
        a, b = edges[k], edges[k + 1]
        d = (b - a) / max(math.dist(a, b), 1e-9)
        t = (p.segment.points - origin - a) @ d
        inside = (t > -PANEL_SLACK_M) & (t < lengths[k] + PANEL_SLACK_M)
        if np.mean(inside) < 0.9:
            return False
    return True


def _angles_hold(
    edges: NDArray[np.float64], design: Beacon, covs: Sequence[NDArray[np.float64]]
) -> bool:
    """Whether the fitted panels meet at their design's angles: Table 1's test of a
    corner (:class:`~mast.pipeline.identification.IdentificationConfig`: four sigmas of
    the two lines' angles, never under half a degree), on the lines fitted to all of a
    panel's points. A corner's pieces passed it; a middle panel seen edge-on, placed by
    its outer panels, has not, and a couple of columns with mixed returns in them turn
    its line by a degree while their scatter says a hundredth."""
    test = IdentificationConfig()
    fitted = BeaconTemplate.from_edges(edges).deflections
    for k in (0, 1):
        turn = math.remainder(float(fitted[k] - design.template.deflections[k]), math.tau)
        sigma = math.sqrt(float(covs[k][0, 0] + covs[k + 1][0, 0]))
        if abs(turn) > max(test.min_deflection_tol_rad, test.sigmas * sigma):
            return False
    return True


def _name(
    found: list[FoundBeacon], previous: Survey | None
) -> tuple[list[FoundBeacon], tuple[str, ...]]:
    """Ids: a previous beacon's within :data:`SAME_BEACON_M`, of the same design; new ones
    ``<design>-<n>`` along increasing easting, then northing (module, step 4)."""
    from scipy.stats import chi2

    limit = float(chi2.isf(MOVED_ALPHA, 2))
    taken: set[str] = set()
    out: list[FoundBeacon] = []
    order = sorted(
        found,
        key=lambda f: (float(f.beacon.edges[:, 0].mean()), float(f.beacon.edges[:, 1].mean())),
    )
    counters: dict[str, int] = {}
    names = set(previous.ids) if previous is not None else set()
    for f in order:
        b = f.beacon
        match = None
        if previous is not None:
            near = [
                p
                for p in previous
                if p.id not in taken
                and (p.design is None or p.design == b.design)
                and math.dist(p.edges.mean(axis=0), b.edges.mean(axis=0)) <= SAME_BEACON_M
            ]
            match = min(
                near,
                key=lambda p: math.dist(p.edges.mean(axis=0), b.edges.mean(axis=0)),
                default=None,
            )
        if match is not None:
            taken.add(match.id)
            d = b.edges - match.edges
            prev = match.edge_sigmas_m if match.edge_sigmas_m is not None else np.full(4, np.nan)
            moved: list[bool | None] = []
            for k in range(4):
                if not np.isfinite(prev[k]):
                    moved.append(None)  # the previous survey does not say how good it was
                    continue
                c = f.covariance[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] + prev[k] ** 2 * np.eye(2)
                moved.append(bool(d[k] @ np.linalg.solve(c, d[k]) > limit))
            renamed = Beacon(match.id, b.edges, b.elevations, b.edge_sigmas_m, b.design)
            displacement = np.hypot(d[:, 0], d[:, 1])
            out.append(replace(f, beacon=renamed, previous=match.id, moved=tuple(moved),
                               displacement_m=displacement))  # fmt: skip
            continue
        design = b.design or "beacon"
        n = counters.get(design, 0)
        while True:
            n += 1
            name = f"{design}-{n}"
            if name not in names:
                break
        counters[design] = n
        names.add(name)
        renamed = Beacon(name, b.edges, b.elevations, b.edge_sigmas_m, b.design)
        out.append(replace(f, beacon=renamed))
    missing = tuple(p.id for p in previous if p.id not in taken) if previous is not None else ()
    return out, missing
