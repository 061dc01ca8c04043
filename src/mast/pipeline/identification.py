"""Stage 2: identify beacon panels among the segments (the paper's Table 1).

Every corner (two consecutive segments of one run) is tested against every
beacon's template, at both of its nodes (e2, e3) and in both directions of
travel (the scan sweeps counter-clockwise, so it meets a beacon's edges as
``e1 -> e4`` or ``e4 -> e1``). Four tests, as in the paper:

* ``p1`` and ``p2``: the lengths of the two panels (``P_j``, ``P_j+1`` in
  beacon order), measured from the node, since the node is found as the
  intersection of the lines and not from end points. One-sided: a scanned
  panel is shorter than the surveyed one by up to the beam spacing at its far
  end (a return rarely falls on an edge), never longer beyond the noise.
* ``theta``: the deflection angle at the node.
* ``c``: the distance between the two panels' centroids, allowing each
  centroid to shift by half the unseen length at each end.

The outcome is the paper's option 1-6; the deflection must always hold and
at least one panel length must. A segment longer than a middle panel is
excluded outright (it is not that panel); one longer than an outer panel is
only not identified, since the wall beyond the beacon's free end may run on in
that panel's line and the segmentation cannot part them.

Single segments are also tested against every panel length (reported for
diagnosis; a lone segment is too ambiguous to start a hypothesis).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon
from mast.core.pose import wrap_angles
from mast.pipeline.segmentation import Corner, Segment, Segmentation

__all__ = [
    "IdentificationConfig",
    "NodeMatch",
    "PanelIdentification",
    "SingleMatch",
    "identify_panels",
]

#: (p1, p2, theta, c) -> Table 1 option
_OPTIONS: dict[tuple[bool, bool, bool, bool], int] = {
    (True, True, True, True): 1,
    (True, True, True, False): 2,
    (False, True, True, True): 3,
    (True, False, True, True): 4,
    (True, False, True, False): 5,
    (False, True, True, False): 6,
}


@dataclass(frozen=True, slots=True)
class IdentificationConfig:
    """Tolerances of panel identification beyond what the scan's own noise gives.

    Attributes
    ----------
    sigmas : float
        Width of every test in standard deviations.
    min_deflection_tol_rad : float
        Floor on the deflection tolerance.
    """

    sigmas: float = 4.0
    min_deflection_tol_rad: float = math.radians(0.5)


@dataclass(frozen=True, slots=True)
class NodeMatch:
    """A corner identified as edge ``edge`` (2 or 3) of ``beacon``.

    Attributes
    ----------
    beacon : str
    edge : int
        2 (P1/P2) or 3 (P2/P3).
    forward : bool
        True when the scan meets the beacon in the order e1 -> e4.
    option : int
        The paper's Table 1 option (1-6).
    segments : tuple[int, int]
        Segment indices in scan order.
    panels : tuple[int, int]
        Beacon panel numbers of those segments, in scan order.
    identified : tuple[bool, bool]
        Whether each segment passed its length test (is an identified panel).
    node_scanner : ndarray, shape (2,)
        The edge in the scanner frame (intersection of the two lines).
    tests : dict
        Measured and design values of each test, for people debugging.
    """

    beacon: str
    edge: int
    forward: bool
    option: int
    segments: tuple[int, int]
    panels: tuple[int, int]
    identified: tuple[bool, bool]
    node_scanner: NDArray[np.float64]
    tests: dict[str, float]


@dataclass(frozen=True, slots=True)
class SingleMatch:
    """A lone segment whose length fits panel ``panel`` of ``beacon``."""

    beacon: str
    panel: int
    segment: int


@dataclass(frozen=True, eq=False)
class PanelIdentification:
    nodes: tuple[NodeMatch, ...]
    singles: tuple[SingleMatch, ...]

    @functools.cached_property
    def nodes_by_beacon(self) -> dict[str, tuple[NodeMatch, ...]]:
        """The nodes taken for each beacon, in their order."""
        groups: dict[str, list[NodeMatch]] = {}
        for node in self.nodes:
            groups.setdefault(node.beacon, []).append(node)
        return {b: tuple(nodes) for b, nodes in groups.items()}


def _extent_from_node(seg: Segment, node: NDArray[np.float64], before: bool) -> tuple[float, float]:
    """(near, far) distances of a segment's returns from the node along its line."""
    t = (seg.points - node) @ seg.direction
    if before:
        t = -t
    return float(t.min()), float(t.max())


@dataclass(frozen=True, slots=True)
class _CornerExtent:
    """What every beacon design's test of one corner shares: the two segments'
    extents from the node, the length tolerance, the centroid distance."""

    near_a: float
    far_a: float
    near_b: float
    far_b: float
    tol: float
    c_meas: float

    @classmethod
    def of(
        cls,
        corner: Corner,
        a: Segment,
        b: Segment,
        noise: float,
        survey_sigma_m: float,
        sigmas: float,
    ) -> _CornerExtent:
        near_a, far_a = _extent_from_node(a, corner.node, before=True)
        near_b, far_b = _extent_from_node(b, corner.node, before=False)
        sin_d = max(abs(math.sin(corner.deflection)), 1e-3)
        # Along-line uncertainty of the node and of the ends: noise over the corner's sine.
        sig_along = noise * (1.0 + 1.0 / sin_d) + survey_sigma_m
        # Centroid of the seen extent (mid-point), not the mean of the returns,
        # which crowd towards the scanner.
        c_meas = float(np.hypot(*(a.midpoint - b.midpoint)))
        return cls(near_a, far_a, near_b, far_b, sigmas * sig_along, c_meas)


def _test_corner(
    corner: Corner,
    a: Segment,
    b: Segment,
    beacon: Beacon,
    ext: _CornerExtent,
    survey_sigma_m: float,
    cfg: IdentificationConfig,
) -> list[NodeMatch]:
    tpl = beacon.template
    out: list[NodeMatch] = []
    # (the caller has left out corners whose lines meet inside a segment)
    near_a, far_a, near_b, far_b, tol = ext.near_a, ext.far_a, ext.near_b, ext.far_b, ext.tol
    sig_theta = math.hypot(a.sigma_direction, b.sigma_direction)
    for forward in (True, False):
        for edge in (2, 3):
            j = edge - 2  # pair (P_{j+1}, P_{j+2}) in 0-based panel numbers j, j+1
            design_theta = float(tpl.deflections[j])
            if forward:
                pa, pb = j, j + 1
                theta = design_theta
            else:
                pa, pb = j + 1, j
                theta = -design_theta
            la, lb = float(tpl.panel_lengths[pa]), float(tpl.panel_lengths[pb])
            survey_theta = survey_sigma_m * math.sqrt(2.0) * math.hypot(1 / la, 1 / lb)
            theta_tol = max(
                cfg.min_deflection_tol_rad, cfg.sigmas * math.hypot(sig_theta, survey_theta)
            )
            d_theta = math.remainder(corner.deflection - theta, 2 * math.pi)
            if abs(d_theta) > theta_tol:
                continue
            # One-sided length tests from the node: never longer, shorter by at most the
            # far-end beam spacing (plus the near gap at the node).
            # A segment longer than a middle panel is not that panel. An outer panel's
            # may run on past the beacon's free end into the wall it is mounted on
            # (in the panel's line within the noise): not an identified panel then,
            # but the corner stands on the deflection and the other panel's length.
            long_a, long_b = far_a > la + tol, far_b > lb + tol
            if (long_a and pa == 1) or (long_b and pb == 1) or (long_a and long_b):
                continue
            ok_a = not long_a and far_a >= la - a.spacing_start - tol
            ok_b = not long_b and far_b >= lb - b.spacing_end - tol
            c_meas = ext.c_meas
            c_design = float(tpl.centroid_distances[j])
            slack = 0.5 * (max(near_a, 0) + (la - far_a) + max(near_b, 0) + (lb - far_b))
            ok_c = abs(c_meas - c_design) <= abs(slack) + tol
            # beacon order: P_j is the first of the pair
            first_ok, second_ok = (ok_a, ok_b) if forward else (ok_b, ok_a)
            option = _OPTIONS.get((first_ok, second_ok, True, ok_c))
            if option is None:
                continue
            out.append(
                NodeMatch(
                    beacon=beacon.id,
                    edge=edge,
                    forward=forward,
                    option=option,
                    segments=(a.index, b.index),
                    panels=(pa + 1, pb + 1),
                    identified=(ok_a, ok_b),
                    node_scanner=corner.node,
                    tests={
                        "length_a_m": far_a,
                        "length_b_m": far_b,
                        "design_a_m": la,
                        "design_b_m": lb,
                        "deflection_rad": corner.deflection,
                        "design_deflection_rad": theta,
                        "deflection_tol_rad": theta_tol,
                        "centroid_distance_m": c_meas,
                        "design_centroid_distance_m": c_design,
                        "length_tol_m": tol,
                    },
                )
            )
    return out


def identify_panels(
    segmentation: Segmentation,
    beacons: Iterable[Beacon],
    config: IdentificationConfig = IdentificationConfig(),
    *,
    survey_sigma_m: float = 0.0,
) -> PanelIdentification:
    """Test every corner and every segment against every beacon template.

    ``beacons`` is a survey, or one beacon of each design (a survey index's
    representatives): beacons of one design identify alike. ``survey_sigma_m``
    is the standard deviation of a surveyed edge coordinate.

    Returns
    -------
    PanelIdentification
        ``nodes``: corners identified as a beacon edge with their Table 1
        option; ``singles``: lone segments whose length fits a panel.
    """
    segs = segmentation.segments
    nodes: list[NodeMatch] = []
    beacons = list(beacons)
    if not beacons:
        return PanelIdentification((), ())
    lengths = np.array([b.template.panel_lengths for b in beacons]).reshape(-1, 3)
    deflections = np.array([b.template.deflections for b in beacons]).reshape(-1, 2)
    # Loosest deflection tolerance of each design (the survey's share of it is largest
    # for its shortest panels): a corner is tested in full only against the designs it
    # may match, so a survey of a thousand designs costs little more than one of three.
    survey_theta = survey_sigma_m * math.sqrt(2.0) * math.hypot(1.0, 1.0) / lengths.min(axis=1)
    corners = segmentation.corners
    if corners:
        # Every corner against every design at once (corners x designs).
        sig_theta = np.array(
            [
                math.hypot(segs[c.first].sigma_direction, segs[c.second].sigma_direction)
                for c in corners
            ]
        )
        defl = np.array([c.deflection for c in corners])[:, None, None]
        loosest = np.maximum(
            config.min_deflection_tol_rad,
            config.sigmas * np.hypot(sig_theta[:, None], survey_theta[None, :]),
        )
        off = np.minimum(
            np.abs(wrap_angles(defl - deflections)), np.abs(wrap_angles(defl + deflections))
        ).min(axis=2)
        may = off <= loosest * (1 + 1e-9) + 1e-12
    for q, corner in enumerate(corners):
        designs = np.flatnonzero(may[q]).tolist()
        if not designs:
            continue
        a, b = segs[corner.first], segs[corner.second]
        ext = _CornerExtent.of(corner, a, b, segmentation.noise_m, survey_sigma_m, config.sigmas)
        if ext.near_a < -ext.tol or ext.near_b < -ext.tol:
            continue  # the lines meet inside a segment: not a corner of two panels
        for k in designs:
            nodes.extend(_test_corner(corner, a, b, beacons[k], ext, survey_sigma_m, config))
    singles: list[SingleMatch] = []
    noise = segmentation.noise_m
    tol = config.sigmas * (noise + survey_sigma_m)
    if segs:
        # Every segment against every design's panels at once (segments x designs x 3).
        length = np.array([g.length for g in segs])[:, None, None]
        start = np.array([g.spacing_start for g in segs])[:, None, None]
        end = np.array([g.spacing_end for g in segs])[:, None, None]
        lo = lengths[None] - start - end - tol
        fits = (lo <= length) & (length <= lengths[None] + tol)
        for q, k, panel in np.argwhere(fits).tolist():
            singles.append(SingleMatch(beacons[k].id, panel + 1, segs[q].index))
    return PanelIdentification(tuple(nodes), tuple(singles))
