"""A corner beside a beacon's node edge refuses the beacon only where the scan shows it."""

import math
from collections.abc import Callable

import numpy as np

from mast.core.noise import NoiseModel
from mast.core.scan import Scan
from mast.pipeline.segmentation import SegmentationConfig, segment_scan
from mast.pipeline.verification import VerificationConfig, _stray_corner


def _wall(second_x: Callable[[float], float]) -> tuple[bool, float]:
    """Whether a corner of a wall of two pieces (y <= -0.3 on x = 5, then the
    ``second_x`` of y above) refuses a beacon whose node edge lies 0.2 m square in
    front of where the two pieces' lines meet; and how far that is from the returns."""
    angles = np.radians(np.arange(-20.0, 12.0, 0.1))
    # Each beam's range to piece one (x = 5) or piece two (x = f(y), solved along the beam).
    ranges = []
    for a in angles:
        c, s = math.cos(a), math.sin(a)
        r = 5.0 / c
        if r * s > -0.3:
            lo, hi = 0.0, 20.0  # bisection on x(r) - f(y(r))
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if mid * c < second_x(mid * s) else (lo, mid)
            r = 0.5 * (lo + hi)
        ranges.append(r)
    scan = Scan(angles, np.array(ranges))
    seg = segment_scan(scan, SegmentationConfig(noise_m=0.002))
    (corner,) = seg.corners
    gap = min(
        math.dist(corner.node, seg.segments[corner.first].end),
        math.dist(corner.node, seg.segments[corner.second].start),
    )
    node = corner.node + np.array([-0.2, 0.0])  # the beacon's node edge, 0.2 m in front
    edges = np.array([node + [0.0, -0.6], node, node + [0.0, 0.6], node + [0.0, 1.2]])
    noise = NoiseModel(range_sigma_m=0.002, angle_sigma_rad=0.0, survey_sigma_m=0.0)
    cfg = VerificationConfig()
    gate = cfg.gate_sigmas * noise.gate_sigma_m
    return _stray_corner(edges, seg, gate, noise, cfg), gap


def test_a_corner_where_two_surfaces_meet_refuses_a_beacon_beside_it() -> None:
    # The wall turns by 17 degrees at y = -0.3: its corner is among the returns.
    stray, gap = _wall(lambda y: 5.0 + 0.3 * (y + 0.3))
    assert gap < 0.05
    assert stray


def test_lines_nearly_straight_on_meeting_away_from_their_ends_are_no_corner() -> None:
    # A 3 cm step, then 3 degrees off: the two lines meet 0.6 m back along the first
    # piece, where the scan shows a straight wall (shared noisy 0071, field 1-1 pose 2).
    stray, gap = _wall(lambda y: 5.03 + 0.05 * (y + 0.3))
    assert gap > 0.5
    assert not stray
