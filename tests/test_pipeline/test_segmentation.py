import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from mast import Pose2D, Scan
from mast.core.lines import fit_line
from mast.pipeline.segmentation import SegmentationConfig, segment_scan
from mast.sim import ScannerModel, Surface, WorldBuilder, paper_scene, simulate_scan


@given(
    st.floats(-100, 100),
    st.floats(-100, 100),
    st.floats(0, 2 * math.pi),
    st.integers(3, 50),
    st.floats(0.1, 20),
)
def test_fit_line_recovers_an_exact_line(
    x0: float, y0: float, ang: float, n: int, length: float
) -> None:
    d = np.array([math.cos(ang), math.sin(ang)])
    t = np.linspace(0, length, n)
    pts = np.array([x0, y0]) + t[:, None] * d
    fit = fit_line(pts)
    assert_allclose(fit.direction, d, atol=1e-9)  # oriented first -> last
    assert fit.rms < 1e-9 * (1 + abs(x0) + abs(y0))
    assert_allclose(fit.normal, [-d[1], d[0]], atol=1e-9)


def test_noise_free_beacon_segments_are_pure_and_nodes_exact() -> None:
    scene = paper_scene("divergent")
    for shot, sim in zip(scene.shots, scene.simulate_all(), strict=True):
        seg = segment_scan(sim.scan)
        for s in seg.segments:
            labels = {sim.surfaces[i] for i in sim.surface_index[s.beams]}
            assert len(labels) == 1, (shot.label, s.index, labels)
        # every corner between two panels of one beacon lies on the surveyed edge
        for c in seg.corners:
            a, b = seg.segments[c.first], seg.segments[c.second]
            sa = sim.surfaces[sim.surface_index[a.beams[0]]]
            sb = sim.surfaces[sim.surface_index[b.beams[0]]]
            if sa.kind == sb.kind == "beacon" and sa.beacon == sb.beacon:
                edge = scene.survey[sa.beacon].edges[max(sa.panel, sb.panel) - 1]
                assert_allclose(shot.pose.scanner_to_mine(c.node[None, :])[0], edge, atol=1e-9)
                tpl = scene.survey[sa.beacon].template
                expected = tpl.deflections[min(sa.panel, sb.panel) - 1]
                # the scan meets this beacon e4 -> e1 or e1 -> e4; the turn has the matching sign
                assert abs(abs(c.deflection) - abs(expected)) < 1e-9


def test_straight_noisy_wall_is_not_cut() -> None:
    wb = WorldBuilder()
    wb.polyline([[-50.0, 4.0], [50.0, 4.0]], Surface("wall"))
    world = wb.build()
    model = ScannerModel("n", 150.0, 0.25, range_sigma_m=0.012)
    rng = np.random.default_rng(5)
    pieces = []
    for _ in range(40):
        sim = simulate_scan(world, Pose2D(0.0, 0.0, 0.0), model, rng=rng)
        pieces.append(len(segment_scan(sim.scan).segments))
    assert np.mean(np.array(pieces) == 1) >= 0.95


def test_noise_estimate_follows_the_noise() -> None:
    wb = WorldBuilder()
    wb.polyline([[-50.0, 6.0], [50.0, 6.0]], Surface("wall"))
    model = ScannerModel("n", 120.0, 0.1, range_sigma_m=0.01)
    sim = simulate_scan(wb.build(), Pose2D(0.0, 0.0, 0.0), model, rng=np.random.default_rng(1))
    # perpendicular noise on a wall seen within +-60 deg of its normal: 0.5 to 1 sigma
    assert 0.005 < segment_scan(sim.scan).noise_m < 0.012


def test_missing_returns_and_jumps_cut_runs() -> None:
    ranges = np.full(200, 5.0)
    ranges[100:103] = np.nan  # more than max_gap_beams missing
    ranges[150:] = 9.0  # a jump
    scan = Scan.from_laserscan(angle_min=-0.5, angle_increment=0.005, ranges=ranges)
    seg = segment_scan(scan, SegmentationConfig(max_gap_beams=2))
    assert len({s.run for s in seg.segments}) >= 3
    assert not seg.corners or all(
        seg.segments[c.first].run == seg.segments[c.second].run for c in seg.corners
    )


def test_empty_scan() -> None:
    scan = Scan.from_laserscan(angle_min=0.0, angle_increment=0.01, ranges=np.full(10, np.nan))
    seg = segment_scan(scan)
    assert seg.segments == ()
    assert seg.corners == ()


@pytest.mark.parametrize("res", [0.25, 0.5])
def test_segment_geometry_fields(res: float) -> None:
    scene = paper_scene("parallel", resolutions_deg=(res,))
    sim = scene.simulate_all()[1]
    for s in segment_scan(sim.scan).segments:
        assert s.length == pytest.approx(float(np.hypot(*(s.end - s.start))))
        assert s.spacing_start > 0
        assert s.first_beam <= s.last_beam
        assert abs(float(s.direction @ s.normal)) < 1e-12
