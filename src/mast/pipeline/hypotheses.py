"""Stage 3: template matching — pose hypotheses from the identified nodes.

Identification may be generous; acceptance stays strict (verification and the
adjustment decide). Two kinds of hypothesis come out of here:

* a **node pair**: two identified nodes whose scanned distance equals the
  surveyed one within the nodes' own covariance (the intersection of two
  total-least-squares lines, each with its offset and direction uncertainty),
  and whose implied rotation agrees with the panels each node was identified
  with. Candidate surveyed edge pairs come from the survey's index, a lookup
  by design and distance, never a loop over every pair of beacons;
* a **single node**: one identified node and the panels it was identified
  with fix a whole pose on their own (a point and a direction). Weaker, so it
  is offered after the pairs; verification against every beam must then find
  a second beacon where the pose says it is;
* a **panel pair** (:func:`panel_hypotheses`), only when the nodes give no fix:
  two straight segments of the scan as long as two surveyed beacons' middle
  panels, as far apart and turned as those panels are. A short outer panel
  seen obliquely is often fitted into one line with the rock beside it, so
  that no corner lands on its edge, while the middle panel between two nodes
  is a segment of its own.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from mast.core.index import SurveyIndex
from mast.core.pose import wrap_angles
from mast.pipeline.alignment import Similarity, similarity_transforms
from mast.pipeline.identification import NodeMatch, PanelIdentification
from mast.pipeline.segmentation import Segment, Segmentation

__all__ = [
    "Hypothesis",
    "HypothesisConfig",
    "corner_covariance",
    "node_covariance",
    "node_sigma",
    "panel_hypotheses",
    "pose_hypotheses",
]


@dataclass(frozen=True, slots=True)
class HypothesisConfig:
    """Tolerances of the consistency tests between nodes.

    Attributes
    ----------
    sigmas : float
        Width of every test in standard deviations: generous, since every
        hypothesis is verified against all the beams afterwards.
    min_rotation_tol_rad : float
        Floor on the rotation tolerance.
    min_node_separation_m : float
        Two nodes closer than this cannot fix a rotation.
    max_pair_hypotheses : int
        Most node-pair hypotheses passed on to verification (best first).
    max_single_hypotheses : int
        Most single-node hypotheses passed on (lowest Table 1 option first).
    panel_min_points : int
        Returns a segment needs to be taken for a middle panel
        (:func:`panel_hypotheses`).
    panel_short_fraction, panel_long_m : float
        A segment is taken for a middle panel of length ``L`` when it is at
        least ``panel_short_fraction * L`` long (the returns at both ends fall
        short of the nodes, and a node's neighbour may take a few of them) and
        at most ``L + panel_long_m`` (a shallow outer panel fitted into it). On
        the shared independent scenes the middle panels' segments were 0.77 to
        1.35 times their panels' lengths, 0.1 m longer at most.
    min_panel_pair_m : float
        Two segments closer than this are not taken for two beacons.
    max_panel_segments : int
        Most segments tried as middle panels (those with most returns first):
        the search costs nothing where the scan shows no beacon.
    max_panel_hypotheses : int
        Most panel-pair hypotheses passed on (best agreement first).
    """

    sigmas: float = 5.0
    min_rotation_tol_rad: float = math.radians(0.25)
    min_node_separation_m: float = 0.2
    max_pair_hypotheses: int = 200
    max_single_hypotheses: int = 60
    panel_min_points: int = 5
    panel_short_fraction: float = 0.6
    panel_long_m: float = 0.15
    min_panel_pair_m: float = 1.0
    max_panel_segments: int = 24
    max_panel_hypotheses: int = 60


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """A pose implied by one or two node correspondences.

    Attributes
    ----------
    nodes : tuple of NodeMatch
        The identified node(s), each with the beacon edge it is taken for.
    similarity : Similarity
        Scanner to mine transformation they imply.
    misfit : float
        Largest normalised disagreement of the consistency tests (<= 1 passes).
    kind : str
        ``"pair"`` (two nodes), ``"single"`` (one node and its panels),
        ``"panels"`` (two beacons' middle panels, no node) or ``"prior"`` (a
        prior pose searched by the tracker).
    spread_m : float
        Standard deviation of where the hypothesis puts a return: its node's
        position error plus its rotation error over twice the node's range
        (a return as far beyond the node as the scanner is before it). ICP
        starts with a gate this wide (see :class:`VerificationConfig`).
    """

    nodes: tuple[NodeMatch, ...]
    similarity: Similarity
    misfit: float
    kind: str = "pair"
    spread_m: float = 0.0

    @property
    def beacons(self) -> tuple[str, ...]:
        return tuple(sorted({n.beacon for n in self.nodes}))


def _wrap(a: float) -> float:
    return math.remainder(a, 2 * math.pi)


def _line_variances(seg: Segment, noise: float, node: NDArray[np.float64]) -> float:
    """Variance of a fitted line's offset at the node: offset and direction errors.

    For a TLS line through ``n`` returns with noise ``s`` across it, the offset
    at the centroid has variance ``s^2 / n`` and the direction
    ``sigma_direction^2``; at a distance ``t`` from the centroid along the
    line the offset varies by ``s^2/n + t^2 sigma_direction^2``.
    """
    c, d = seg.centroid, seg.direction
    t = float((node[0] - c[0]) * d[0] + (node[1] - c[1]) * d[1])
    return noise**2 / max(len(seg), 1) + (t * seg.sigma_direction) ** 2


def corner_covariance(
    first: Segment, second: Segment, at: NDArray[np.float64], noise_m: float
) -> NDArray[np.float64]:
    """2x2 covariance, scanner frame, of where two fitted lines meet (near ``at``).

    The intersection solves ``n_k . x = o_k`` for the two lines ``k``; a
    perturbation ``d o_k`` of each line's offset there moves it by
    ``N^-1 d o`` (``N`` the rows ``n_k``), so ``C = N^-1 diag(var_k) N^-T``.
    Shallow corners are poorly placed along their lines, as they should be.
    """
    (a, b), (c, d) = first.normal.tolist(), second.normal.tolist()
    if abs(a * d - b * c) < 1e-3:
        c += 1e-3  # nearly parallel lines: a finite, very long ellipse along them
    det = a * d - b * c
    # N^-1 = [[d, -b], [-c, a]] / det, by hand (a 2x2 is cheaper so than through LAPACK)
    i00, i01, i10, i11 = d / det, -b / det, -c / det, a / det
    v0 = _line_variances(first, noise_m, at)
    v1 = _line_variances(second, noise_m, at)
    cxx = i00 * i00 * v0 + i01 * i01 * v1
    cxy = i00 * i10 * v0 + i01 * i11 * v1
    cyy = i10 * i10 * v0 + i11 * i11 * v1
    return np.array([[cxx, cxy], [cxy, cyy]])


def node_covariance(node: NodeMatch, segmentation: Segmentation) -> NDArray[np.float64]:
    """2x2 covariance of an identified node, scanner frame (:func:`corner_covariance`)."""
    a, b = (segmentation.segments[i] for i in node.segments)
    return corner_covariance(a, b, node.node_scanner, segmentation.noise_m)


def node_sigma(node: NodeMatch, segmentation: Segmentation) -> float:
    """Largest standard deviation of an identified node's position (the ellipse's major axis)."""
    return major_sigma(node_covariance(node, segmentation))


def _largest_eigenvalues(covs: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each 2x2 covariance's largest eigenvalue (never below 0), shape (n,)."""
    a, b, c = covs[:, 0, 0], covs[:, 0, 1], covs[:, 1, 1]
    return np.maximum(0.5 * (a + c) + np.hypot(0.5 * (a - c), b), 0.0)


def major_sigma(cov: NDArray[np.float64]) -> float:
    """Square root of a 2x2 covariance's largest eigenvalue (the ellipse's semi-major axis)."""
    (a, b), (_, c) = cov.tolist()
    return math.sqrt(max(0.5 * (a + c) + math.hypot(0.5 * (a - c), b), 0.0))


def _singles(
    nodes: Sequence[NodeMatch],
    panels: _PanelsOfNodes,
    which: NDArray[np.intp],
    beacons: NDArray[np.intp],
    index: SurveyIndex,
) -> list[Hypothesis | None]:
    """The pose each node ``which[r]`` and its identified panels (``panels``) imply on
    their own, the node taken for beacon ``beacons[r]`` (survey positions; of its
    design): the panels' rotations (mine vs scanner) averaged, weighted by their
    directions' variances, and the node put on that beacon's edge; None for a node
    without an identified panel. Its spread is the node's position error plus that
    rotation's error over twice its range."""
    r, _, ok = panels.rotations(index, which, beacons)
    if r.shape[1] == 0:
        return [None] * which.size
    w = panels.weight[which]
    ref = r[:, 0]
    rot = ref + np.sum(w * wrap_angles(r - ref[:, None]), axis=1) / panels.sum_weight[which]
    xy = np.array([nodes[k].node_scanner for k in which.tolist()], dtype=float).reshape(-1, 2)
    edge = index.edge_xy(beacons, np.array([nodes[k].edge for k in which.tolist()]))
    c, s = np.cos(rot), np.sin(rot)
    tx = edge[:, 0] - (c * xy[:, 0] - s * xy[:, 1])
    ty = edge[:, 1] - (s * xy[:, 0] + c * xy[:, 1])
    sigma_rot = 1.0 / np.sqrt(panels.sum_weight[which])
    spread = panels.major[which] + 2.0 * np.hypot(xy[:, 0], xy[:, 1]) * sigma_rot
    return [
        Hypothesis(
            (_renamed(nodes[k], index.beacon_id(b)),),
            Similarity(1.0, _wrap(a), np.array([x, y]), 0.0),
            0.0,
            "single",
            sp,
        )
        if any_panel
        else None
        for k, b, a, x, y, sp, any_panel in zip(
            which.tolist(),
            beacons.tolist(),
            rot.tolist(),
            tx.tolist(),
            ty.tolist(),
            spread.tolist(),
            np.asarray(ok.any(axis=1), dtype=bool).tolist(),
            strict=True,
        )
    ]


#: A node's single-node hypotheses for the beacons of its design computed together
#: after its first (a mine's design may have thousands of look-alikes, of which a scan
#: asks for a few).
_SINGLES_AT_ONCE = 16


def _renamed(node: NodeMatch, beacon: str) -> NodeMatch:
    """The same identified node, taken for a beacon of the same design (itself if it is)."""
    return node if node.beacon == beacon else replace(node, beacon=beacon)


@dataclass(frozen=True, slots=True)
class _PanelsSeen:
    """A node's identified panels: their numbers (from 0), the direction of each
    one's fitted line in the scanner frame and that direction's standard deviation."""

    panel: NDArray[np.intp]
    angle: NDArray[np.float64]
    sigma: NDArray[np.float64]
    turn: float  # pi when the scan meets the beacon from e4 to e1

    @classmethod
    def of(cls, node: NodeMatch, seg: Segmentation) -> _PanelsSeen:
        kept = [
            (panel - 1, seg.segments[s])
            for s, panel, ok in zip(node.segments, node.panels, node.identified, strict=True)
            if ok
        ]
        return cls(
            np.array([p for p, _ in kept], dtype=np.intp),
            np.array([math.atan2(s.direction[1], s.direction[0]) for _, s in kept]),
            np.array([s.sigma_direction for _, s in kept]),
            0.0 if node.forward else math.pi,
        )

    def rotations(self, index: SurveyIndex, beacons: NDArray[np.intp]) -> NDArray[np.float64]:
        """(k, panels) rotation, mine vs scanner, each panel implies were the node on
        each of ``beacons`` (survey positions): look-alikes may face any way."""
        mine = index.panel_angles(beacons)[:, self.panel] + self.turn
        return wrap_angles(mine - self.angle[None, :])


def pose_hypotheses(
    identification: PanelIdentification,
    segmentation: Segmentation,
    index: SurveyIndex,
    config: HypothesisConfig = HypothesisConfig(),
    *,
    survey_sigma_m: float = 0.0,
) -> list[Hypothesis]:
    """Pose hypotheses from the identified nodes: consistent pairs first, then single nodes.

    Parameters
    ----------
    identification, segmentation
        Stages 1 and 2 of this scan.
    index : SurveyIndex
        The survey's design and edge-pair index (edge pairs no scan can see
        both of are not in it).
    config : HypothesisConfig
    survey_sigma_m : float
        Standard deviation of a surveyed edge coordinate.
    """
    nodes = identification.nodes
    # Every node's covariance, which is its corner's: one computed per corner, however
    # many designs read it (a survey of many designs identifies many nodes of each).
    corner_covs: dict[tuple[tuple[int, ...], bytes], NDArray[np.float64]] = {}
    node_covs = []
    for n in nodes:
        at = (tuple(n.segments), n.node_scanner.tobytes())
        if at not in corner_covs:
            corner_covs[at] = node_covariance(n, segmentation)
        node_covs.append(corner_covs[at])
    covs = np.array(node_covs, dtype=float).reshape(-1, 2, 2)
    # The panels of the nodes that are looked up.
    seen = functools.cache(lambda k: _PanelsSeen.of(nodes[k], segmentation))
    # Per node pair, the survey's readings of it that fit (:func:`_readings`).
    readings = _readings(nodes, covs, seen, index, config, survey_sigma_m)
    xy = np.array([n.node_scanner for n in nodes], dtype=float).reshape(-1, 2)
    # Prefer two beacons to one beacon's two edges (every look-alike of a beacon shows
    # the same two edges; two beacons' relative place is the mine's own), then nodes
    # identified with more panels (lower Table 1 option), then the better fit, in the
    # order found on a tie; only those kept are solved (a mine's look-alikes past the
    # cap never are).
    one_k, opt_k, mis_k, i_k, j_k, ka_k, kb_k, ea_k, eb_k, sp_k = readings
    order = np.lexsort((mis_k, opt_k, one_k))[: config.max_pair_hypotheses]
    sims = similarity_transforms(
        np.stack([xy[i_k[order]], xy[j_k[order]]], axis=1),
        np.stack([ea_k[order], eb_k[order]], axis=1),
    )
    pairs = [
        Hypothesis(
            (
                _renamed(nodes[i], index.beacon_id(ka)),
                _renamed(nodes[j], index.beacon_id(kb)),
            ),
            sim,
            mis,
            "pair",
            spread,
        )
        for i, j, ka, kb, mis, spread, sim in zip(
            i_k[order].tolist(),
            j_k[order].tolist(),
            ka_k[order].tolist(),
            kb_k[order].tolist(),
            mis_k[order].tolist(),
            sp_k[order].tolist(),
            sims,
            strict=True,
        )
    ]

    # Single nodes take turns (lowest Table 1 option first), so that one corner's
    # many look-alikes in a mine-wide survey cannot crowd out another corner's beacon.
    # Made lazily: a whole mine's look-alikes past the cap are never computed.
    # The first round takes each node's first beacon of its design, all at once, for
    # as many nodes as it can reach; a node asked again takes the rest a few at a time.
    by_option = sorted(range(len(nodes)), key=lambda k: nodes[k].option)
    # (a node without an identified panel implies no pose: it takes no turn)
    with_panels = [k for k in by_option if any(nodes[k].identified)]
    reached = np.array(with_panels[: max(config.max_single_hypotheses, 0)], dtype=np.intp)
    panels_reached = _PanelsOfNodes.of(seen, covs, reached)
    firsts = np.array(
        [index.number(index.beacons_like(nodes[k].beacon)[0]) for k in reached.tolist()],
        dtype=np.intp,
    )
    first_of = dict(
        zip(
            reached.tolist(),
            _singles(nodes, panels_reached, reached, firsts, index),
            strict=True,
        )
    )

    def singles_of(k: int) -> Iterator[Hypothesis]:
        first = first_of.get(k)
        if first is None:
            return
        yield first
        rest = iter(index.beacons_like(nodes[k].beacon)[1:])
        while chunk := [index.number(b) for b in itertools.islice(rest, _SINGLES_AT_ONCE)]:
            at = np.full(len(chunk), k, dtype=np.intp)
            made = _singles(nodes, panels_reached, at, np.array(chunk, dtype=np.intp), index)
            yield from (h for h in made if h is not None)

    singles = itertools.islice(
        _taking_turns(singles_of(k) for k in by_option), config.max_single_hypotheses
    )
    return pairs + list(singles)


#: The survey's readings of a scan's node pairs (:func:`_readings`): arrays, one row per
#: reading, of whether it is one beacon's two edges, the nodes' Table 1 options summed,
#: the misfit, the two nodes, their beacons (survey positions), their surveyed edges
#: (E, N) and the spread.
_Readings = tuple[
    NDArray[np.bool_],
    NDArray[np.intp],
    NDArray[np.float64],
    NDArray[np.intp],
    NDArray[np.intp],
    NDArray[np.intp],
    NDArray[np.intp],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
]


def _node_pairs(
    nodes: Sequence[NodeMatch],
    covs: NDArray[np.float64],
    index: SurveyIndex,
    config: HypothesisConfig,
    survey_sigma_m: float,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
    """The nodes' keys (:meth:`~mast.core.index.SurveyIndex.node_key`) and places, and
    the pairs ``i < j`` of them to look up: only node pairs whose designs and edges are
    surveyed within reach of each other, about as far apart as some surveyed pair of
    their keys (each node's share of the widest distance tolerance of :func:`_readings`:
    the square root of a sum is at most the sum of the square roots)."""
    keys = np.array([index.node_key(n.beacon, n.edge) for n in nodes], dtype=np.int64)
    xy = np.array([n.node_scanner for n in nodes], dtype=float).reshape(-1, 2)
    share = config.sigmas * np.sqrt(_largest_eigenvalues(covs) + survey_sigma_m**2)
    first, second = index.pairs_to_look_up(keys, xy, share)
    return keys, xy, first, second


def _quadratic(u: NDArray[np.float64], m: NDArray[np.float64]) -> NDArray[np.float64]:
    """``u[k] @ m[k] @ u[k]`` for each row of ``u`` (k, 2) and 2x2 ``m`` (k, 2, 2)."""
    u0, u1 = u[:, 0], u[:, 1]
    return np.asarray(
        (u0 * m[:, 0, 0] + u1 * m[:, 1, 0]) * u0 + (u0 * m[:, 0, 1] + u1 * m[:, 1, 1]) * u1
    )


def _readings(
    nodes: Sequence[NodeMatch],
    covs: NDArray[np.float64],
    seen: Callable[[int], _PanelsSeen],
    index: SurveyIndex,
    config: HypothesisConfig,
    survey_sigma_m: float,
) -> _Readings:
    """Per pair of the scan's ``nodes`` (covariances ``covs``, panels ``seen``), the
    surveyed edge pairs that fit it, in the order of the pairs (:func:`_node_pairs`),
    then of each one's surveyed edge pairs (distance, rows): the two nodes as far apart
    as the two edges within ``sigmas`` of their distance's standard deviation, and the
    rotation that carries one onto the other agreeing with each panel the nodes were
    identified with (the misfit is the larger of the two tests' ratios to their
    tolerances). One beacon's two edges are distinct edges met in one direction, and
    only when both nodes are of its design; two beacons' nodes share no segment.

    Every pair at once (:func:`_readings_reference` takes them one at a time: the tests
    compare the two)."""
    keys, xy, first, second = _node_pairs(nodes, covs, index, config, survey_sigma_m)
    segments = np.array([n.segments for n in nodes], dtype=np.intp).reshape(-1, 2)
    number = np.array([index.number(n.beacon) for n in nodes], dtype=np.intp)
    design = np.array([index.design_of(n.beacon) for n in nodes], dtype=np.intp)
    edge = np.array([n.edge for n in nodes], dtype=np.intp)
    forward = np.array([n.forward for n in nodes], dtype=bool)
    option = np.array([n.option for n in nodes], dtype=np.intp)
    sa, sb = segments[first], segments[second]
    shared = (sa[:, :, None] == sb[:, None, :]).any(axis=(1, 2))
    ds_vec = xy[second] - xy[first]
    ds = np.hypot(ds_vec[:, 0], ds_vec[:, 1])
    go = ~(shared & (number[first] != number[second])) & (ds >= config.min_node_separation_m)
    go &= ds > 0.0  # two nodes at one place have no direction: no reading fits them
    first, second, shared, ds_vec, ds = first[go], second[go], shared[go], ds_vec[go], ds[go]
    u = ds_vec / ds[:, None]
    both = covs[first] + covs[second]
    tol_d = config.sigmas * np.sqrt(_quadratic(u, both) + 2 * survey_sigma_m**2)
    which, ra, rb = index.pairs_rows(keys[first], keys[second], ds, tol_d)
    ba, bb = index.row_beacon(ra), index.row_beacon(rb)
    one = ba == bb
    twin = (edge[first] == edge[second]) | (forward[first] != forward[second])
    same_design = design[first] == design[second]
    keep = np.where(same_design[which], ~(one & twin[which]), ~one) & (one | ~shared[which])
    which, ra, rb, ba, bb, one = which[keep], ra[keep], rb[keep], ba[keep], bb[keep], one[keep]
    edge_a, edge_b = index.row_xy(ra), index.row_xy(rb)
    dm_vec = edge_b - edge_a
    dm = np.hypot(dm_vec[:, 0], dm_vec[:, 1])
    mis_d = np.abs(ds[which] - dm) / tol_d[which]
    turned = np.arctan2(ds_vec[:, 1], ds_vec[:, 0])
    rot = wrap_angles(np.arctan2(dm_vec[:, 1], dm_vec[:, 0]) - turned[which])
    v_perp = np.stack([-u[:, 1], u[:, 0]], axis=1)
    s_rot = np.sqrt(_quadratic(v_perp, both))[which] / dm
    i_row, j_row = first[which], second[which]
    # Each surveyed beacon's own panel directions must agree with the pair's rotation.
    panels = _PanelsOfNodes.of(seen, covs, np.concatenate([first, second]))
    r_a, s_a, ok_a = panels.rotations(index, i_row, ba)
    r_b, s_b, ok_b = panels.rotations(index, j_row, bb)
    r_k, s_k = np.concatenate([r_a, r_b], 1), np.concatenate([s_a, s_b], 1)
    tol = np.maximum(config.min_rotation_tol_rad, config.sigmas * np.hypot(s_rot[:, None], s_k))
    mis = np.abs(wrap_angles(r_k - rot[:, None])) / tol
    mis_r = np.where(np.concatenate([ok_a, ok_b], 1), mis, 0.0).max(axis=1, initial=0.0)
    ranges = np.hypot(xy[:, 0], xy[:, 1])
    spread = panels.major[i_row] + 2.0 * ranges[i_row] * np.minimum(s_rot, math.pi)
    misfit = np.maximum(mis_d, mis_r)
    fits = mis_r <= 1.0
    return (
        one[fits],
        (option[i_row] + option[j_row])[fits],
        misfit[fits],
        i_row[fits],
        j_row[fits],
        ba[fits],
        bb[fits],
        edge_a[fits],
        edge_b[fits],
        spread[fits],
    )


@dataclass(frozen=True, slots=True)
class _PanelsOfNodes:
    """The identified panels (:class:`_PanelsSeen`) of some of a scan's nodes, padded to
    one width: their numbers, directions, directions' sigmas and which are panels, per
    node (a row each), each node's turn and its ellipse's semi-major axis, and the
    weights of its panels' directions (their inverse variances; 0 where no panel) and
    their sum (1 for a node without panels, whose rows are all padding)."""

    panel: NDArray[np.intp]
    angle: NDArray[np.float64]
    sigma: NDArray[np.float64]
    ok: NDArray[np.bool_]
    turn: NDArray[np.float64]
    major: NDArray[np.float64]
    weight: NDArray[np.float64]
    sum_weight: NDArray[np.float64]

    @classmethod
    def of(
        cls, seen: Callable[[int], _PanelsSeen], covs: NDArray[np.float64], which: NDArray[np.intp]
    ) -> _PanelsOfNodes:
        """The panels of the nodes ``which`` (of those whose covariances are ``covs``;
        the others' rows empty)."""
        count = covs.shape[0]
        looked = [(k, seen(k)) for k in np.unique(which).tolist()]
        width = max((s.panel.size for _, s in looked), default=0)
        out = cls(
            np.zeros((count, width), dtype=np.intp),
            np.zeros((count, width)),
            np.ones((count, width)),
            np.zeros((count, width), dtype=bool),
            np.zeros(count),
            np.zeros(count),
            np.zeros((count, width)),
            np.ones(count),
        )
        for k, s in looked:
            m = s.panel.size
            out.panel[k, :m], out.angle[k, :m], out.sigma[k, :m] = s.panel, s.angle, s.sigma
            out.ok[k, :m] = True
            out.turn[k] = s.turn
            out.major[k] = major_sigma(covs[k])
            if m:
                w = 1.0 / np.maximum(s.sigma, 1e-9) ** 2
                out.weight[k, :m] = w
                out.sum_weight[k] = np.sum(w)
        return out

    def rotations(
        self, index: SurveyIndex, which: NDArray[np.intp], beacons: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
        """Per row, the rotation (mine vs scanner) each of node ``which[r]``'s panels
        implies were it on beacon ``beacons[r]`` (:meth:`_PanelsSeen.rotations`), the
        panels' direction sigmas and which columns are panels."""
        mine = np.take_along_axis(index.panel_angles(beacons), self.panel[which], axis=1)
        rot = wrap_angles(mine + self.turn[which][:, None] - self.angle[which])
        return rot, self.sigma[which], self.ok[which]


def _readings_reference(
    nodes: Sequence[NodeMatch],
    covs: NDArray[np.float64],
    seen: Callable[[int], _PanelsSeen],
    index: SurveyIndex,
    config: HypothesisConfig,
    survey_sigma_m: float,
) -> _Readings:
    """:func:`_readings`, one node pair at a time (the tests compare the two)."""
    _, _, first, second = _node_pairs(nodes, covs, index, config, survey_sigma_m)
    found: list[tuple[NDArray[Any], ...]] = []
    for i, j in zip(first.tolist(), second.tolist(), strict=True):
        a, b = nodes[i], nodes[j]
        shared = bool(set(a.segments) & set(b.segments))
        if shared and a.beacon != b.beacon:
            continue
        same_design = index.design_of(a.beacon) == index.design_of(b.beacon)
        ds_vec = b.node_scanner - a.node_scanner
        ds = float(np.hypot(*ds_vec))
        if ds < config.min_node_separation_m:
            continue
        u = ds_vec / ds
        s_d = math.sqrt(float(u @ (covs[i] + covs[j]) @ u) + 2 * survey_sigma_m**2)
        tol_d = config.sigmas * s_d
        ra, rb = index.pair_rows(a.beacon, a.edge, b.beacon, b.edge, ds, tol_d)
        ba, bb = index.row_beacon(ra), index.row_beacon(rb)
        one = ba == bb
        # One beacon's two edges: distinct edges met in one direction, and only when
        # both nodes are of its design; two beacons: no segment shared.
        twin = a.edge == b.edge or a.forward != b.forward
        keep = ~one if not same_design else ~(one & twin)
        if shared:
            keep &= one
        ra, rb, ba, bb, one = ra[keep], rb[keep], ba[keep], bb[keep], one[keep]
        if ra.size == 0:
            continue
        edge_a, edge_b = index.row_xy(ra), index.row_xy(rb)
        dm_vec = edge_b - edge_a
        dm = np.hypot(dm_vec[:, 0], dm_vec[:, 1])
        mis_d = np.abs(ds - dm) / tol_d
        rot = np.arctan2(dm_vec[:, 1], dm_vec[:, 0]) - math.atan2(ds_vec[1], ds_vec[0])
        rot = wrap_angles(rot)
        v_perp = np.array([-u[1], u[0]])
        s_rot = math.sqrt(float(v_perp @ (covs[i] + covs[j]) @ v_perp)) / dm
        # Each surveyed beacon's own panel directions must agree with the pair's rotation.
        r_k = np.concatenate([seen(i).rotations(index, ba), seen(j).rotations(index, bb)], 1)
        s_k = np.concatenate([seen(i).sigma, seen(j).sigma])
        tol = np.maximum(
            config.min_rotation_tol_rad, config.sigmas * np.hypot(s_rot[:, None], s_k[None, :])
        )
        mis_r = (np.abs(wrap_angles(r_k - rot[:, None])) / tol).max(axis=1, initial=0.0)
        spread = major_sigma(covs[i]) + 2.0 * float(np.hypot(*a.node_scanner)) * np.minimum(
            s_rot, math.pi
        )
        misfit = np.maximum(mis_d, mis_r)
        fits = np.flatnonzero(mis_r <= 1.0)
        if fits.size:
            found.append(
                (
                    one[fits],
                    np.full(fits.size, a.option + b.option),
                    misfit[fits],
                    np.full(fits.size, i),
                    np.full(fits.size, j),
                    ba[fits],
                    bb[fits],
                    edge_a[fits],
                    edge_b[fits],
                    spread[fits],
                )
            )
    if not found:
        return _no_readings()
    return cast(_Readings, tuple(np.concatenate(column) for column in zip(*found, strict=True)))


def _no_readings() -> _Readings:
    no, none, nowhere = np.zeros(0, dtype=np.intp), np.zeros(0), np.zeros((0, 2))
    return (np.zeros(0, dtype=bool), no, none, no, no, no, no, nowhere, nowhere, none)


def _taking_turns(sources: Iterable[Iterator[Hypothesis]]) -> Iterator[Hypothesis]:
    """The first of each source, then the second of each, and so on, leaving out sources
    that have run dry; each item, and each source, made only when it is asked for (a
    scan read as thousands of nodes of a mine's many designs makes a few dozen singles,
    not one from every node first)."""
    active = []
    for source in sources:  # the first round takes the sources as they come
        item = next(source, None)
        if item is not None:
            yield item
            active.append(source)
    while active:
        still = []
        for source in active:
            item = next(source, None)
            if item is not None:
                yield item
                still.append(source)
        active = still


def panel_hypotheses(
    segmentation: Segmentation,
    index: SurveyIndex,
    config: HypothesisConfig = HypothesisConfig(),
) -> list[Hypothesis]:
    """Poses from two segments taken for two surveyed beacons' middle panels, no node.

    A segment as long as a design's middle panel (within ``panel_short_fraction``
    and ``panel_long_m``) may be that panel, its midpoint the panel's within half
    the difference of their lengths. Two such segments make a hypothesis for two
    surveyed beacons of those designs whose middle panels' midpoints lie as far
    apart as the segments' (candidate pairs from the survey's index: their node
    edges 2 lie within the panels' half lengths of that), when the rotation each
    segment's direction implies (facing either way) agrees with the one the
    vector between the two midpoints implies, within ``sigmas`` of the direction's
    standard deviation and what the midpoints' slack turns it by. The pose
    averages the two segments' rotations (weighted) and puts both midpoints on
    their panels' midpoints. The beacons must then prove their shape at the
    refined pose (:func:`~mast.pipeline.locator`), since no corner names them.

    Bounded: at most ``max_panel_segments`` segments (most returns first), and
    only the design pairs surveyed within reach of each other are looked up.
    """
    lengths, keys = index.middle_panels
    # Each segment that may be a middle panel (most returns first), and the designs
    # whose it may be.
    segments = segmentation.segments
    size = np.array([len(seg) for seg in segments], dtype=np.intp)
    order = np.argsort(-size, kind="stable")
    order = order[size[order] >= config.panel_min_points]
    seg_length = np.array([segments[i].length for i in order.tolist()], dtype=float)
    fit = (config.panel_short_fraction * lengths[None, :] <= seg_length[:, None]) & (
        seg_length[:, None] <= (lengths + config.panel_long_m)[None, :]
    )
    some_fit = np.flatnonzero(fit.any(axis=1))
    if config.max_panel_segments > 0:  # (none or fewer: no cap)
        some_fit = some_fit[: config.max_panel_segments]
    cands: list[tuple[Segment, NDArray[np.intp]]] = [
        (segments[int(order[r])], np.flatnonzero(fit[r])) for r in some_fit.tolist()
    ]
    survey, ids = index.survey, index.survey.ids
    found: list[Hypothesis] = []
    # Every pair of candidates far enough apart, and each pair of their designs surveyed
    # within reach of each other (one look-up for all), in the order of the pairs.
    pairs = list(itertools.combinations(range(len(cands)), 2))
    mids = np.array([c[0].midpoint for c in cands]).reshape(-1, 2)
    p_i = np.array([i for i, _ in pairs], dtype=np.intp)
    p_j = np.array([j for _, j in pairs], dtype=np.intp)
    gaps = np.hypot(mids[p_j, 0] - mids[p_i, 0], mids[p_j, 1] - mids[p_i, 1])
    kept = np.flatnonzero(gaps >= config.min_panel_pair_m)
    apart = [
        (i, j, ds)
        for i, j, ds in zip(
            p_i[kept].tolist(), p_j[kept].tolist(), gaps[kept].tolist(), strict=True
        )
    ]
    if not apart:
        return []
    owner, ka_all, kb_all = _design_pairs(apart, cands, index, config.sigmas * segmentation.noise_m)
    # Each candidate pair's tolerance, and the surveyed pairs within it (one search for
    # all), each tried in the order of the candidate pairs.
    seg_len = np.array([c[0].length for c in cands])
    sp_start = np.array([c[0].spacing_start for c in cands])
    sp_end = np.array([c[0].spacing_end for c in cands])
    first = np.array([a[0] for a in apart], dtype=np.intp)[owner]
    second = np.array([a[1] for a in apart], dtype=np.intp)[owner]
    gap = np.array([a[2] for a in apart])[owner]
    la, lb = lengths[ka_all], lengths[kb_all]
    # (in the order of the scalar expressions below: the same roundings)
    slack_a = 0.5 * np.abs(seg_len[first] - la) + sp_start[first] + sp_end[first]
    slack_b = 0.5 * np.abs(seg_len[second] - lb) + sp_start[second] + sp_end[second]
    tol_d = slack_a + slack_b + config.sigmas * segmentation.noise_m
    reach = 0.5 * (la + lb) + tol_d
    which, rows_a, rows_b = index.pairs_rows(keys[ka_all], keys[kb_all], gap, reach)
    slack = np.maximum(slack_a, slack_b)
    for w, ba, bb in zip(
        which.tolist(),
        index.row_beacon(rows_a).tolist(),
        index.row_beacon(rows_b).tolist(),
        strict=True,
    ):
        if ba == bb:
            continue  # one beacon's own edge 2 twice
        i, j, ds = apart[int(owner[w])]
        ea, eb = survey[ids[ba]].edges, survey[ids[bb]].edges
        h = _panel_pair(
            cands[i][0], cands[j][0], ea, eb, ds, float(tol_d[w]), float(slack[w]), config
        )
        if h is not None:
            found.append(h)
    found.sort(key=lambda h: h.misfit)
    return found[: config.max_panel_hypotheses]


def _design_pairs(
    apart: list[tuple[int, int, float]],
    cands: list[tuple[Segment, NDArray[np.intp]]],
    index: SurveyIndex,
    noise_m: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """For each pair of candidate middle panels (``apart``: candidates ``i``, ``j`` and
    their midpoints' distance), the pairs of designs (``k_a`` of candidate ``i``, ``k_b``
    of ``j``) whose middle panels' edges are surveyed within reach of each other at
    about that distance: ``(owner, k_a, k_b)``, one row per such design pair, by pair
    of candidates (``owner``, its place in ``apart``), then ``k_a``, then ``k_b``.

    Found from the index's pairs of keys, not from every pair of designs (a mine of
    many designs fits a segment to hundreds of them), for every pair of candidates at
    once (:func:`_design_pairs_reference` takes them one at a time: the tests compare
    the two). A design pair counts when the surveyed pairs of its keys span the
    candidates' distance widened by at least the widest reach any of their designs
    gets (:func:`_widest_reach`)."""
    lengths, keys = index.middle_panels
    d_low, d_high, span_lo, span_hi = _surveyed_design_pairs(cands, index)
    if not apart or d_low.size == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    # Which designs each candidate may be, and each candidate's share of the reach (the
    # sum _widest_reach makes, in its order: the same roundings).
    fits_design = np.zeros((len(cands), keys.size), dtype=bool)
    share = np.empty(len(cands))
    for c, (seg, fits) in enumerate(cands):
        fits_design[c, fits] = True
        share[c] = _reach_share(seg, lengths[fits])
    first = np.array([i for i, _, _ in apart], dtype=np.intp)
    second = np.array([j for _, j, _ in apart], dtype=np.intp)
    ds = np.array([d for _, _, d in apart])
    far = ((noise_m + share[first]) + share[second]) * (1.0 + 1e-9) + 1e-9
    spanned = (span_lo[None, :] <= (ds + far)[:, None]) & (span_hi[None, :] >= (ds - far)[:, None])
    forward = fits_design[first][:, d_low] & fits_design[second][:, d_high] & spanned
    backward = (
        fits_design[first][:, d_high]
        & fits_design[second][:, d_low]
        & (d_low != d_high)[None, :]
        & spanned
    )
    p_fwd, q_fwd = np.nonzero(forward)
    p_bwd, q_bwd = np.nonzero(backward)
    owner = np.concatenate([p_fwd, p_bwd]).astype(np.int64)
    k_a = np.concatenate([d_low[q_fwd], d_high[q_bwd]])
    k_b = np.concatenate([d_high[q_fwd], d_low[q_bwd]])
    # by pair, then k_a, then k_b; a tie keeps the forward row first (a stable sort)
    by = np.lexsort((k_b, k_a, owner))
    return owner[by], k_a[by], k_b[by]


def _surveyed_design_pairs(
    cands: list[tuple[Segment, NDArray[np.intp]]], index: SurveyIndex
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """The pairs of designs (positions in ``index.middle_panels``) whose middle panels'
    edges are surveyed within reach of each other, both of which some candidate may be,
    and the span of distances their surveyed pairs lie at: ``(low, high, lo, hi)``."""
    _, keys = index.middle_panels
    design_of_key = np.full(int(keys.max(initial=0)) + 1, -1, dtype=np.int64)
    design_of_key[keys] = np.arange(keys.size)
    low, high = index.key_pairs
    known = (low < design_of_key.size) & (high < design_of_key.size)
    d_low, d_high = design_of_key[low[known]], design_of_key[high[known]]
    # Only design pairs both of whose designs some candidate may be (the others match
    # no pair of candidates): a mine of many designs surveys many such pairs.
    fit_any = np.zeros(keys.size, dtype=bool)
    for _, fits in cands:
        fit_any[fits] = True
    pair_ok = (d_low >= 0) & (d_high >= 0)
    pair_ok[pair_ok] = fit_any[d_low[pair_ok]] & fit_any[d_high[pair_ok]]
    span_lo, span_hi = (span[known][pair_ok] for span in index.key_pair_spans)
    return d_low[pair_ok], d_high[pair_ok], span_lo, span_hi


def _design_pairs_reference(
    apart: list[tuple[int, int, float]],
    cands: list[tuple[Segment, NDArray[np.intp]]],
    index: SurveyIndex,
    noise_m: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """:func:`_design_pairs` one pair of candidates at a time (the tests compare the two)."""
    lengths, keys = index.middle_panels
    d_low, d_high, span_lo, span_hi = _surveyed_design_pairs(cands, index)
    owners, kas, kbs = [np.zeros(0, dtype=np.int64)], [d_low[:0]], [d_low[:0]]
    for at, (i, j, ds) in enumerate(apart):
        in_i = np.zeros(keys.size, dtype=bool)
        in_j = np.zeros(keys.size, dtype=bool)
        in_i[cands[i][1]] = True
        in_j[cands[j][1]] = True
        far = _widest_reach(cands[i], cands[j], lengths, noise_m)
        spanned = (span_lo <= ds + far) & (span_hi >= ds - far)
        forward = in_i[d_low] & in_j[d_high] & spanned
        backward = in_i[d_high] & in_j[d_low] & (d_low != d_high) & spanned
        k_a = np.concatenate([d_low[forward], d_high[backward]])
        k_b = np.concatenate([d_high[forward], d_low[backward]])
        by = np.lexsort((k_b, k_a))
        owners.append(np.full(by.size, at, dtype=np.int64))
        kas.append(k_a[by])
        kbs.append(k_b[by])
    return np.concatenate(owners), np.concatenate(kas), np.concatenate(kbs)


def _widest_reach(
    a: tuple[Segment, NDArray[np.intp]],
    b: tuple[Segment, NDArray[np.intp]],
    lengths: NDArray[np.float64],
    noise_m: float,
) -> float:
    """At least the reach :func:`panel_hypotheses` gives two candidate middle panels
    (segment and designs each) for any of their designs (``lengths``: the designs'
    middle panels' lengths), a hair more against rounding."""
    total = noise_m
    for seg, fits in (a, b):
        total += _reach_share(seg, lengths[fits])
    return total * (1.0 + 1e-9) + 1e-9


def _reach_share(seg: Segment, lengths: NDArray[np.float64]) -> float:
    """One candidate middle panel's share of :func:`_widest_reach`: half the longest of
    its designs' middle panels (``lengths``), half its length's largest difference from
    theirs, and its spacings at both ends."""
    off = max(abs(seg.length - float(lengths.min())), abs(seg.length - float(lengths.max())))
    return 0.5 * float(lengths.max()) + 0.5 * off + seg.spacing_start + seg.spacing_end


def _panel_pair(
    sa: Segment,
    sb: Segment,
    ea: NDArray[np.float64],
    eb: NDArray[np.float64],
    ds: float,
    tol_d: float,
    slack_m: float,
    config: HypothesisConfig,
) -> Hypothesis | None:
    """The pose that puts segments ``sa``, ``sb`` (midpoints ``ds`` apart) on the middle
    panels of beacons with edges ``ea``, ``eb``, or None when the panels' midpoints are
    not as far apart within ``tol_d`` or the directions disagree. Its ``spread_m`` is
    how far a midpoint may lie along its panel (``slack_m``) and what the rotation's
    slack moves the far returns by."""
    pa, pb = 0.5 * (ea[1] + ea[2]), 0.5 * (eb[1] + eb[2])
    m_vec = pb - pa
    dm = float(np.hypot(*m_vec))
    if abs(dm - ds) > tol_d:
        return None
    d_vec = sb.midpoint - sa.midpoint
    turn = math.atan2(m_vec[1], m_vec[0]) - math.atan2(d_vec[1], d_vec[0])
    slack_rot = math.atan2(tol_d, ds)
    rots, weights = [], []
    for seg_k, edges in ((sa, ea), (sb, eb)):
        step = edges[2] - edges[1]
        base = math.atan2(step[1], step[0]) - math.atan2(seg_k.direction[1], seg_k.direction[0])
        # The segment's direction has no sign: the rotation nearer the vector's.
        off = min((_wrap(base - turn), _wrap(base + math.pi - turn)), key=abs)
        tol = config.sigmas * seg_k.sigma_direction + slack_rot
        if abs(off) > max(config.min_rotation_tol_rad, tol):
            return None
        rots.append(turn + off)
        weights.append(1.0 / max(seg_k.sigma_direction, 1e-4) ** 2)
    rot = float(np.average(rots, weights=weights))
    c, s = math.cos(rot), math.sin(rot)
    rmat = np.array([[c, -s], [s, c]])
    t = 0.5 * ((pa - rmat @ sa.midpoint) + (pb - rmat @ sb.midpoint))
    sim = Similarity(1.0, _wrap(rot), np.asarray(t, dtype=float), 0.0)
    return Hypothesis((), sim, abs(dm - ds) / tol_d, "panels", slack_m + 2.0 * ds * slack_rot)
