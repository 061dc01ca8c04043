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
  a second beacon where the pose says it is.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.index import SurveyIndex
from mast.pipeline.alignment import Similarity, similarity_transform
from mast.pipeline.identification import NodeMatch, PanelIdentification
from mast.pipeline.segmentation import Segment, Segmentation

__all__ = [
    "Hypothesis",
    "HypothesisConfig",
    "corner_covariance",
    "node_covariance",
    "node_sigma",
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
    """

    sigmas: float = 5.0
    min_rotation_tol_rad: float = math.radians(0.25)
    min_node_separation_m: float = 0.2
    max_pair_hypotheses: int = 200
    max_single_hypotheses: int = 60


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
        ``"pair"`` (two nodes), ``"single"`` (one node and its panels) or
        ``"prior"`` (a prior pose searched by the tracker).
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


def major_sigma(cov: NDArray[np.float64]) -> float:
    """Square root of a 2x2 covariance's largest eigenvalue (the ellipse's semi-major axis)."""
    (a, b), (_, c) = cov.tolist()
    return math.sqrt(max(0.5 * (a + c) + math.hypot(0.5 * (a - c), b), 0.0))


def _node_rotations(
    node: NodeMatch, seg: Segmentation, index: SurveyIndex
) -> list[tuple[float, float]]:
    """(rotation, sigma) implied by each identified panel of a node: mine dir vs scan dir."""
    tpl = index.survey[node.beacon].template
    out = []
    for s_idx, panel, ok in zip(node.segments, node.panels, node.identified, strict=True):
        if not ok:
            continue
        s = seg.segments[s_idx]
        d_mine = tpl.directions[panel - 1] * (1.0 if node.forward else -1.0)
        rot = math.atan2(d_mine[1], d_mine[0]) - math.atan2(s.direction[1], s.direction[0])
        out.append((_wrap(rot), s.sigma_direction))
    return out


def _single_hypothesis(
    node: NodeMatch, beacon: str, seg: Segmentation, index: SurveyIndex
) -> Hypothesis | None:
    """The pose one node and its identified panels imply on their own."""
    if node.beacon != beacon:
        node = _rename(node, beacon)
    rots = _node_rotations(node, seg, index)
    if not rots:
        return None
    w = np.array([1.0 / max(s, 1e-9) ** 2 for _, s in rots])
    ref = rots[0][0]
    rot = ref + float(np.sum(w * np.array([_wrap(r - ref) for r, _ in rots])) / np.sum(w))
    sigma_rot = 1.0 / math.sqrt(float(np.sum(w)))
    spread = node_sigma(node, seg) + 2.0 * float(np.hypot(*node.node_scanner)) * sigma_rot
    c, s = math.cos(rot), math.sin(rot)
    edge = index.survey[beacon].edges[node.edge - 1]
    t = edge - np.array([[c, -s], [s, c]]) @ node.node_scanner
    sim = Similarity(1.0, _wrap(rot), np.asarray(t, dtype=float), 0.0)
    return Hypothesis((node,), sim, 0.0, "single", spread)


def _rename(node: NodeMatch, beacon: str) -> NodeMatch:
    """The same identified node, taken for a beacon of the same design."""
    return replace(node, beacon=beacon)


def pose_hypotheses(
    identification: PanelIdentification,
    segmentation: Segmentation,
    index: SurveyIndex,
    config: HypothesisConfig = HypothesisConfig(),
    *,
    survey_sigma_m: float = 0.0,
    max_range_m: float = math.inf,
) -> list[Hypothesis]:
    """Pose hypotheses from the identified nodes: consistent pairs first, then single nodes.

    Parameters
    ----------
    identification, segmentation
        Stages 1 and 2 of this scan.
    index : SurveyIndex
        The survey's design and edge-pair index.
    config : HypothesisConfig
    survey_sigma_m : float
        Standard deviation of a surveyed edge coordinate.
    max_range_m : float
        Longest range of the scanner: surveyed edge pairs farther apart than
        twice this cannot both be in one scan.
    """
    nodes = identification.nodes
    cov = [node_covariance(n, segmentation) for n in nodes]
    rots = [_node_rotations(n, segmentation, index) for n in nodes]
    Found = tuple[NodeMatch, NodeMatch, NDArray[np.float64], NDArray[np.float64], float]
    found: list[tuple[tuple[int, float], Found]] = []
    for i in range(len(nodes)):
        for j in range(i + 1, len(nodes)):
            a, b = nodes[i], nodes[j]
            if set(a.segments) & set(b.segments) and a.beacon != b.beacon:
                continue
            same_design = index.design_of(a.beacon) == index.design_of(b.beacon)
            ds_vec = b.node_scanner - a.node_scanner
            ds = float(np.hypot(*ds_vec))
            if ds < config.min_node_separation_m:
                continue
            u = ds_vec / ds
            s_d = math.sqrt(float(u @ (cov[i] + cov[j]) @ u) + 2 * survey_sigma_m**2)
            tol_d = config.sigmas * s_d
            for ba, bb, edge_a, edge_b in index.edge_pairs(
                a.beacon, a.edge, b.beacon, b.edge, ds, tol_d, same_beacon=same_design
            ):
                if ba == bb and (a.edge == b.edge or a.forward != b.forward):
                    continue
                if ba != bb and set(a.segments) & set(b.segments):
                    continue
                dm_vec = edge_b - edge_a
                dm = float(np.hypot(*dm_vec))
                mis_d = abs(ds - dm) / tol_d
                rot = _wrap(math.atan2(dm_vec[1], dm_vec[0]) - math.atan2(ds_vec[1], ds_vec[0]))
                v_perp = np.array([-u[1], u[0]])
                s_rot = math.sqrt(float(v_perp @ (cov[i] + cov[j]) @ v_perp)) / dm
                na = a if ba == a.beacon else _rename(a, ba)
                nb = b if bb == b.beacon else _rename(b, bb)
                # Each surveyed beacon's own panel directions: look-alikes may face any way.
                rots_ab = (rots[i] if na is a else _node_rotations(na, segmentation, index)) + (
                    rots[j] if nb is b else _node_rotations(nb, segmentation, index)
                )
                mis_r = 0.0
                for r_k, s_k in rots_ab:
                    tol = max(config.min_rotation_tol_rad, config.sigmas * math.hypot(s_rot, s_k))
                    mis_r = max(mis_r, abs(_wrap(r_k - rot)) / tol)
                if mis_r > 1.0:
                    continue
                spread = major_sigma(cov[i]) + 2.0 * float(np.hypot(*a.node_scanner)) * min(
                    s_rot, math.pi
                )
                misfit = max(mis_d, mis_r)
                found.append(((na.option + nb.option, misfit), (na, nb, edge_a, edge_b, spread)))
    # Prefer hypotheses whose nodes were identified with more panels (lower Table 1 option);
    # only those kept are solved (a mine's look-alikes past the cap never are).
    found.sort(key=lambda f: f[0])
    pairs = [
        Hypothesis(
            (na, nb),
            similarity_transform(
                np.array([na.node_scanner, nb.node_scanner]), np.array([edge_a, edge_b])
            ),
            rank[1],
            "pair",
            spread,
        )
        for rank, (na, nb, edge_a, edge_b, spread) in found[: config.max_pair_hypotheses]
    ]

    # Single nodes take turns (lowest Table 1 option first), so that one corner's
    # many look-alikes in a mine-wide survey cannot crowd out another corner's beacon.
    # Made lazily: a whole mine's look-alikes past the cap are never computed.
    def singles_of(n: NodeMatch) -> Iterator[Hypothesis]:
        for b in index.beacons_like(n.beacon):
            h = _single_hypothesis(n, b, segmentation, index)
            if h is not None:
                yield h

    per_node = [singles_of(n) for n in sorted(nodes, key=lambda n: n.option)]
    turns = itertools.chain.from_iterable(itertools.zip_longest(*per_node))
    singles = itertools.islice((h for h in turns if h is not None), config.max_single_hypotheses)
    return pairs + list(singles)
