"""Beacons from identified corners, and which surveyed beacon each one is.

Identification (the same Table 1 tests as ``mast locate``) labels corners as
edge e2 or e3 of a beacon design, met forwards (e1 to e4) or backwards. Two
corners of one design sharing their middle panel as P2 are a whole beacon
(both inner edges); a corner whose two panels both passed their length test
is a beacon seen in part (one edge and two panel directions).

A cloud spans hundreds of metres and may drift, so no one transformation
places every beacon at once. Matching grows from a seed: a detected beacon
taken for a surveyed beacon of its design gives a transformation; the nearest
unmatched detection is predicted by the transformation of its nearest matched
neighbours, and taken for the one surveyed beacon of its design within a
tolerance that grows with the distance from them (drift). The seed that
explains the most detections wins, and only if no other seed explains as
many with a different assignment: a survey that repeats itself within the
tolerance is refused as ambiguous, never guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.cloud.detect import PlanPieces
from mast.core.beacon import Survey
from mast.core.index import SurveyIndex
from mast.pipeline.hypotheses import corner_covariance
from mast.pipeline.identification import NodeMatch, PanelIdentification
from mast.pipeline.segmentation import Segmentation

__all__ = ["Detection", "Match", "MatchConfig", "detect_beacons", "match_beacons"]


@dataclass(frozen=True, slots=True)
class MatchConfig:
    """Tolerances of matching detections to the survey.

    Attributes
    ----------
    base_m : float
        Position tolerance next to a matched beacon.
    max_drift : float
        Largest drift of the cloud, as a fraction of the distance from the
        nearest matched beacon, that matching allows for.
    rotation_tol_deg : float
        Tolerance on a detection's own orientation, beyond drift.
    max_seeds : int
        Detections (best identified first) tried as seeds.
    same_place_m : float
        Detections closer than this are one beacon (the best identified kept).
    """

    base_m: float = 0.15
    max_drift: float = 0.02
    rotation_tol_deg: float = 5.0
    max_seeds: int = 8
    same_place_m: float = 0.5


@dataclass(frozen=True, eq=False)
class Detection:
    """A beacon found in the cloud (its design, not yet which one).

    Attributes
    ----------
    designs : frozenset of int
        Design numbers of the survey index its shape fits.
    nodes : dict[int, ndarray]
        Edge number (2, 3) -> the edge in the cloud's plan.
    covariances : dict[int, ndarray]
        Their 2x2 covariances.
    panels : dict[int, int]
        Beacon panel number (1-3) -> index into :attr:`PlanPieces.panels`.
    option : int
        Best Table 1 option of its corners.
    angle : float
        Direction in the cloud (radians) of one identified panel, in beacon order
        (from its lower-numbered edge), and
    angle_panel : int
        which panel it is (1-3), and
    sigma_angle : float
        its standard deviation.
    """

    designs: frozenset[int]
    nodes: dict[int, NDArray[np.float64]]
    covariances: dict[int, NDArray[np.float64]]
    panels: dict[int, int]
    option: int
    angle: float
    angle_panel: int
    sigma_angle: float

    @property
    def centre(self) -> NDArray[np.float64]:
        return np.asarray(np.mean(list(self.nodes.values()), axis=0), dtype=float)

    @property
    def whole(self) -> bool:
        return len(self.nodes) == 2


def _p2_direction(m: NodeMatch, seg: Segmentation) -> NDArray[np.float64]:
    """P2's direction from e2 towards e3 as a corner reads it (oriented pieces: the
    first ends at the node, the second starts there)."""
    s = m.segments[m.panels.index(2)]
    d = seg.segments[s].direction
    return np.asarray(d if m.forward else -d, dtype=float)


def _base(i: int, n: int) -> int:
    return i - n if i >= n else i


def detect_beacons(
    pieces: PlanPieces, ident: PanelIdentification, index: SurveyIndex
) -> list[Detection]:
    """Whole beacons (e2 and e3 sharing P2) and beacons seen in part (one corner whose
    two panels passed), from the identified corners.

    One corner identifies alike against every design its shape fits (a survey's
    beacons of one design differ by the survey's noise, and may be indexed as
    several designs): a detection keeps all of them.
    """
    seg = pieces.segmentation
    n = len(pieces.panels)
    groups: dict[tuple[tuple[int, int], int, bool], list[NodeMatch]] = {}
    for m in ident.nodes:
        groups.setdefault((m.segments, m.edge, m.forward), []).append(m)
    corners = list(groups.values())

    def designs(members: list[list[NodeMatch]]) -> frozenset[int]:
        # the union: beacons of one shape whose surveys differ by their noise fall into
        # neighbouring designs, and either corner may fit only some of them
        return frozenset(index.design_of(m.beacon) for g in members for m in g)

    def detection(members: list[list[NodeMatch]]) -> Detection:
        panels: dict[int, int] = {}
        nodes_xy: dict[int, NDArray[np.float64]] = {}
        covs: dict[int, NDArray[np.float64]] = {}
        best = (math.inf, 0, 0.0)
        for g in members:
            m = g[0]
            a, b = (seg.segments[s] for s in m.segments)
            nodes_xy[m.edge] = m.node_scanner
            covs[m.edge] = corner_covariance(a, b, m.node_scanner, seg.noise_m)
            for s, panel, ok in zip(m.segments, m.panels, m.identified, strict=True):
                panels[panel] = _base(s, n)
                sg = seg.segments[s]
                if ok and sg.sigma_direction < best[0]:
                    # its direction in beacon order (e_k to e_k+1): reversed when the
                    # corner was met from e4 towards e1
                    along = math.atan2(sg.direction[1], sg.direction[0])
                    best = (sg.sigma_direction, panel, along + (0.0 if m.forward else math.pi))
        return Detection(
            designs(members),
            nodes_xy,
            covs,
            panels,
            min(m.option for g in members for m in g),
            best[2],
            best[1],
            best[0],
        )

    out: list[Detection] = []
    used: set[int] = set()
    for i, a in enumerate(corners):
        for j in range(i + 1, len(corners)):
            b = corners[j]
            ma, mb = a[0], b[0]
            if {ma.edge, mb.edge} != {2, 3}:
                continue
            mid_a = {_base(s, n) for s, p in zip(ma.segments, ma.panels, strict=True) if p == 2}
            mid_b = {_base(s, n) for s, p in zip(mb.segments, mb.panels, strict=True) if p == 2}
            if not mid_a or mid_a != mid_b or not designs([a, b]):
                continue
            # both corners must read P2 the same way round (e2 towards e3)
            if float(_p2_direction(ma, seg) @ _p2_direction(mb, seg)) <= 0:
                continue
            out.append(detection([a, b] if ma.edge == 2 else [b, a]))
            used |= {i, j}
    for i, a in enumerate(corners):
        if i not in used and all(a[0].identified):
            out.append(detection([a]))
    return out


@dataclass(frozen=True, eq=False)
class Match:
    """Which surveyed beacon each detection is.

    Attributes
    ----------
    assigned : dict[int, str]
        Detection index -> surveyed beacon id.
    score, runner_up : int
        Detections the winning seed explains, and the most any seed with a
        different assignment explains.
    reason : str
        Empty when matched; otherwise why not (``too_few``, ``ambiguous``).
    """

    assigned: dict[int, str]
    score: int
    runner_up: int
    reason: str = ""


def _edges_of(survey: Survey, beacon: str, det: Detection) -> NDArray[np.float64]:
    return np.array([survey[beacon].edges[e - 1] for e in sorted(det.nodes)])


def _points_of(det: Detection) -> NDArray[np.float64]:
    return np.array([det.nodes[e] for e in sorted(det.nodes)])


def _panel_angle(survey: Survey, beacon: str, panel: int) -> float:
    e = survey[beacon].edges
    d = e[panel] - e[panel - 1]
    return math.atan2(d[1], d[0])


def _rigid(
    src: NDArray[np.float64], dst: NDArray[np.float64], rotation: float | None = None
) -> tuple[float, NDArray[np.float64]]:
    """Rotation and translation taking ``src`` onto ``dst`` (least squares); a given
    rotation is used as it is (one point)."""
    ps, qs = src.mean(axis=0), dst.mean(axis=0)
    if rotation is None:
        a, b = src - ps, dst - qs
        rotation = math.atan2(
            float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])), float(np.sum(a * b))
        )
    c, s = math.cos(rotation), math.sin(rotation)
    return rotation, qs - np.array([[c, -s], [s, c]]) @ ps


def _hypothesis(
    survey: Survey, det: Detection, beacon: str
) -> tuple[float, NDArray[np.float64]] | None:
    """The rigid transformation cloud -> grid were ``det`` surveyed ``beacon``; ``None``
    when its own shape disagrees (a whole beacon's inner edges at another distance)."""
    src, dst = _points_of(det), _edges_of(survey, beacon, det)
    if det.whole:
        ds, dm = float(np.hypot(*(src[1] - src[0]))), float(np.hypot(*(dst[1] - dst[0])))
        sd = math.sqrt(float(np.trace(det.covariances[2] + det.covariances[3])))
        if abs(ds - dm) > 5.0 * sd + 0.01:
            return None
        rot, t = _rigid(src, dst)
        own = _panel_angle(survey, beacon, det.angle_panel) - det.angle
        if abs(math.remainder(own - rot, math.tau)) > math.radians(10.0):
            return None
        return rot, t
    rot = _panel_angle(survey, beacon, det.angle_panel) - det.angle
    return _rigid(src, dst, rot)


def _apply(rot: float, t: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s = math.cos(rot), math.sin(rot)
    out: NDArray[np.float64] = p @ np.array([[c, -s], [s, c]]).T + t
    return out


def _candidates(index: SurveyIndex, det: Detection) -> list[str]:
    return [b for k in sorted(det.designs) for b in index.designs[k]]


def _grow(
    seed: int,
    beacon: str,
    dets: list[Detection],
    usable: list[int],
    survey: Survey,
    index: SurveyIndex,
    cfg: MatchConfig,
) -> dict[int, str]:
    """Every detection that one seed's assignment explains (module docstring)."""
    assigned = {seed: beacon}
    taken = {beacon}
    centres = np.array([d.centre for d in dets])
    left = set(usable) - {seed}
    # a detection's panels may be another's too: the first assigned keeps them
    panels_used = set(dets[seed].panels.values())
    # a detection tried too early (its neighbours not yet matched, the tolerance from
    # far ones too loose to be unique) is tried again once they are: until no change
    tried: set[int] = set()
    while left - tried:
        have = np.array(sorted(assigned))
        rest = np.array(sorted(left - tried))
        dist = np.hypot(*(centres[rest][:, None, :] - centres[have][None, :, :]).transpose(2, 0, 1))
        k = int(np.argmin(dist.min(axis=1)))
        d = int(rest[k])
        tried.add(d)
        near = have[np.argsort(dist[k])[:3]]
        reach = float(dist[k].min())
        src = np.concatenate([_points_of(dets[i]) for i in near])
        dst = np.concatenate([_edges_of(survey, assigned[int(i)], dets[i]) for i in near])
        if src.shape[0] >= 2:
            rot, t = _rigid(src, dst)
        else:
            h = _hypothesis(survey, dets[int(near[0])], assigned[int(near[0])])
            if h is None:
                continue
            rot, t = h
        det = dets[d]
        if panels_used & set(det.panels.values()):
            continue
        pred = _apply(rot, t, _points_of(det))
        tol = cfg.base_m + cfg.max_drift * reach
        found = []
        for b in _candidates(index, det):
            if b in taken:
                continue
            err = float(np.max(np.hypot(*(pred - _edges_of(survey, b, det)).T)))
            if err <= tol:
                own = _hypothesis(survey, det, b)
                if own is None:
                    continue
                if (
                    abs(math.remainder(own[0] - rot, math.tau))
                    > math.radians(cfg.rotation_tol_deg) + cfg.max_drift * reach / 10.0
                ):
                    continue
                found.append(b)
        if len(found) == 1:
            assigned[d] = found[0]
            taken.add(found[0])
            panels_used |= set(det.panels.values())
            left.discard(d)
            tried.clear()
    return assigned


def match_beacons(
    dets: list[Detection],
    survey: Survey,
    index: SurveyIndex,
    cfg: MatchConfig = MatchConfig(),
) -> Match:
    """Assign detections to surveyed beacons (module docstring)."""
    if not dets:
        return Match({}, 0, 0, "too_few")
    # one place, one beacon: of detections within a beacon's reach of each other (a
    # panel found twice, a corner met against several designs) the best stands for all
    order = sorted(range(len(dets)), key=lambda i: (not dets[i].whole, dets[i].option))
    kept: list[int] = []
    for i in order:
        if all(np.hypot(*(dets[i].centre - dets[k].centre)) > cfg.same_place_m for k in kept):
            kept.append(i)
    order = kept
    seeds = order[: cfg.max_seeds]
    results: list[tuple[int, int, str, dict[int, str]]] = []
    for d in seeds:
        for b in _candidates(index, dets[d]):
            if _hypothesis(survey, dets[d], b) is None:
                continue
            assigned = _grow(d, b, dets, order, survey, index, cfg)
            results.append((len(assigned), d, b, assigned))
    if not results:
        return Match({}, 0, 0, "too_few")
    results.sort(key=lambda r: -r[0])
    best = results[0]
    centres = {d: dets[d].centre for d in order}

    def conflicts(other: dict[int, str]) -> bool:
        """Whether ``other`` places some beacon elsewhere than the winner, or takes a
        detection the winner has for another beacon."""
        where = {b: d for d, b in best[3].items()}
        for d, b in other.items():
            if d in best[3] and best[3][d] != b:
                return True
            if b in where and np.hypot(*(centres[where[b]] - centres[d])) > cfg.same_place_m * 3:
                return True
        return False

    if best[0] < 2:
        # one beacon alone cannot say which of its look-alikes it is, nor place a cloud
        return Match({}, best[0], 0, "too_few")
    rival = max((r[0] for r in results[1:] if conflicts(r[3])), default=0)
    if best[0] <= rival:
        return Match({}, best[0], rival, "ambiguous")
    return Match(best[3], best[0], rival)
