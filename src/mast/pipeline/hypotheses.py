"""Stage 3: template matching — which surveyed edges the identified nodes are.

Every pair of identified nodes (on different beacons, or the two nodes of one
beacon) is a hypothesis: its scanned distance must equal the surveyed one,
and the rotation it implies must agree with the directions of the panels
each node was identified with. Geometric consistency between beacons decides,
never the order in which they appear in the scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mast.core.beacon import Survey
from mast.pipeline.alignment import Similarity, similarity_transform
from mast.pipeline.identification import NodeMatch, PanelIdentification
from mast.pipeline.segmentation import Segmentation

__all__ = ["Hypothesis", "MatchingConfig", "node_sigma", "pose_hypotheses"]


@dataclass(frozen=True, slots=True)
class MatchingConfig:
    """Tolerances of the consistency tests between nodes.

    Attributes
    ----------
    survey_sigma_m : float
        Standard deviation of a surveyed edge coordinate.
    sigmas : float
        Width of every test in standard deviations.
    min_rotation_tol_rad : float
        Floor on the rotation tolerance.
    min_node_separation_m : float
        Two nodes closer than this cannot fix a rotation.
    max_hypotheses : int
        Most hypotheses passed on to verification (best-consistent first).
    """

    survey_sigma_m: float = 0.003
    sigmas: float = 4.0
    min_rotation_tol_rad: float = math.radians(0.25)
    min_node_separation_m: float = 0.2
    max_hypotheses: int = 200


@dataclass(frozen=True, eq=False)
class Hypothesis:
    """A pose implied by two node correspondences.

    Attributes
    ----------
    nodes : tuple of NodeMatch
        The two identified nodes.
    similarity : Similarity
        The four-parameter transformation from their scanner to mine points.
    misfit : float
        Largest normalised disagreement of the consistency tests (<= 1 passes).
    """

    nodes: tuple[NodeMatch, NodeMatch]
    similarity: Similarity
    misfit: float

    @property
    def beacons(self) -> tuple[str, ...]:
        return tuple(sorted({n.beacon for n in self.nodes}))


def _wrap(a: float) -> float:
    return math.remainder(a, 2 * math.pi)


def _node_rotations(
    node: NodeMatch, seg: Segmentation, survey: Survey
) -> list[tuple[float, float]]:
    """(rotation, sigma) implied by each identified panel of a node: mine dir vs scan dir."""
    tpl = survey[node.beacon].template
    out = []
    for s_idx, panel, ok in zip(node.segments, node.panels, node.identified, strict=True):
        if not ok:
            continue
        s = seg.segments[s_idx]
        d_mine = tpl.directions[panel - 1] * (1.0 if node.forward else -1.0)
        rot = math.atan2(d_mine[1], d_mine[0]) - math.atan2(s.direction[1], s.direction[0])
        out.append((_wrap(rot), s.sigma_direction))
    return out


def node_sigma(node: NodeMatch, noise: float) -> float:
    """Standard deviation of an identified node's position: the noise over the corner's sine."""
    d = node.tests["deflection_rad"]
    return noise * (1.0 + 1.0 / max(abs(math.sin(d)), 1e-3))


def pose_hypotheses(
    identification: PanelIdentification,
    segmentation: Segmentation,
    survey: Survey,
    config: MatchingConfig = MatchingConfig(),
) -> list[Hypothesis]:
    """Every consistent pair of node correspondences, most consistent first."""
    nodes = identification.nodes
    noise = segmentation.noise_m
    mine = [survey[n.beacon].edges[n.edge - 1] for n in nodes]
    rots = [_node_rotations(n, segmentation, survey) for n in nodes]
    sig = [node_sigma(n, noise) for n in nodes]
    out: list[Hypothesis] = []
    for i in range(len(nodes)):
        for j in range(i + 1, len(nodes)):
            a, b = nodes[i], nodes[j]
            if set(a.segments) & set(b.segments) and a.beacon != b.beacon:
                continue
            if a.beacon == b.beacon and (a.edge == b.edge or a.forward != b.forward):
                continue
            dm_vec = mine[j] - mine[i]
            ds_vec = b.node_scanner - a.node_scanner
            dm, ds = float(np.hypot(*dm_vec)), float(np.hypot(*ds_vec))
            if dm < config.min_node_separation_m:
                continue
            s_d = math.sqrt(sig[i] ** 2 + sig[j] ** 2 + 2 * config.survey_sigma_m**2)
            tol_d = config.sigmas * s_d
            mis_d = abs(ds - dm) / tol_d
            if mis_d > 1.0:
                continue
            rot = _wrap(math.atan2(dm_vec[1], dm_vec[0]) - math.atan2(ds_vec[1], ds_vec[0]))
            s_rot = s_d / dm
            mis_r = 0.0
            for r_k, s_k in rots[i] + rots[j]:
                tol = max(config.min_rotation_tol_rad, config.sigmas * math.hypot(s_rot, s_k))
                mis_r = max(mis_r, abs(_wrap(r_k - rot)) / tol)
            if mis_r > 1.0:
                continue
            sim = similarity_transform(
                np.array([a.node_scanner, b.node_scanner]), np.array([mine[i], mine[j]])
            )
            out.append(Hypothesis((a, b), sim, max(mis_d, mis_r)))
    # Prefer hypotheses whose nodes were identified with more panels (lower Table 1 option).
    out.sort(key=lambda h: (sum(n.option for n in h.nodes), h.misfit))
    return out[: config.max_hypotheses]
