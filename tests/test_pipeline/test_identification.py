import numpy as np

from mast import Pose2D
from mast.pipeline.identification import identify_panels
from mast.pipeline.segmentation import segment_scan
from mast.sim import (
    Surface,
    WorldBuilder,
    paper_design,
    paper_scene,
    polyline_design,
    simulate_scan,
)


def test_fully_seen_pairs_are_option_1() -> None:
    scene = paper_scene("parallel")
    sim = scene.simulate_all()[1]  # P4, both beacons in full view
    ident = identify_panels(segment_scan(sim.scan), scene.survey)
    best = {(n.beacon, n.edge): n.option for n in ident.nodes if n.option == 1}
    assert ("B1", 2) in best
    assert ("B2", 2) in best
    # the scan meets B1 (east wall, e1 south) e1 -> e4 and the mirrored B2 e4 -> e1
    forward = {n.beacon: n.forward for n in ident.nodes if n.option == 1}
    assert forward == {"B1": True, "B2": False}


def _scene_with_occluder(fraction: float):  # type: ignore[no-untyped-def]
    scene = paper_scene("parallel", resolutions_deg=(0.25,))
    shot = scene.shots[1]
    wb = WorldBuilder()
    wb._a.append(scene.world.seg_a)
    wb._b.append(scene.world.seg_b)
    wb._seg_s.extend(scene.world.seg_surface.tolist())
    wb._surfaces.extend(scene.world.surfaces)
    e1, e2 = scene.survey["B2"].edges[:2]
    p = shot.pose.position
    target = e1 + fraction * (e2 - e1)
    wb.polyline(
        [p + 0.5 * (e1 - p) - 0.01 * (target - e1), p + 0.5 * (target - p)], Surface("clutter")
    )
    return scene, shot, simulate_scan(wb.build(), shot.pose, shot.scanner)


def test_partly_hidden_panel_gives_a_one_panel_option() -> None:
    scene, _shot, sim = _scene_with_occluder(0.6)
    ident = identify_panels(segment_scan(sim.scan), scene.survey)
    b2 = [n for n in ident.nodes if n.beacon == "B2" and n.edge == 2]
    assert b2
    assert all(n.option in (3, 4, 5, 6) for n in b2)
    # the panel that passed its length test is the unoccluded P2
    n = b2[0]
    assert dict(zip(n.panels, n.identified, strict=True))[2] is True
    assert dict(zip(n.panels, n.identified, strict=True))[1] is False


def test_a_look_alike_with_other_angles_is_not_identified() -> None:
    survey_design = paper_design(1.0, 0.2)
    fake = polyline_design((0.41, 0.61, 0.2), (-1.2, -0.4))  # same lengths, other deflections
    wb = WorldBuilder()
    wb.polyline([[-30.0, 3.0], [30.0, 3.0]], Surface("wall"))
    wb.panels(fake.mounted([0.0, 3.0], [1.0, 0.0], tunnel_side=-1), "fake", kind="lookalike")
    from mast import Survey

    survey = Survey([survey_design.beacon("B", [100.0, 100.0], [1.0, 0.0])])
    from mast.sim import ScannerModel

    sim = simulate_scan(wb.build(), Pose2D(0.0, 0.0, 0.0), ScannerModel("s", 270.0, 0.25))
    ident = identify_panels(segment_scan(sim.scan), survey)
    assert not [n for n in ident.nodes if n.option in (1, 2)]


def test_single_segments_report_fitting_panels() -> None:
    scene = paper_scene("parallel")
    sim = scene.simulate_all()[1]
    ident = identify_panels(segment_scan(sim.scan), scene.survey)
    assert {(s.beacon, s.panel) for s in ident.singles} >= {("B1", 2), ("B2", 2)}
    assert np.all([s.panel in (1, 2, 3) for s in ident.singles])


def test_many_designs_identify_as_testing_each_in_full() -> None:
    """The deflection screen over a thousand designs drops only designs the full test
    would refuse: the same nodes and singles, in the same order, as testing every one."""
    from mast.core.beacon import Beacon
    from mast.pipeline.identification import (
        IdentificationConfig,
        SingleMatch,
        _CornerExtent,
        _test_corner,
    )
    from mast.sim.design import random_design

    rng = np.random.default_rng(3)
    scene = paper_scene("parallel")
    others = [Beacon(f"D{k}", random_design(rng).edges_local) for k in range(1000)]
    beacons = [*scene.survey, *others]
    cfg = IdentificationConfig()
    compared = 0
    for sim in scene.simulate_all():
        seg = segment_scan(sim.scan)
        for sigma in (0.0, 0.01):
            got = identify_panels(seg, beacons, cfg, survey_sigma_m=sigma)
            nodes = []
            for corner in seg.corners:
                a, b = seg.segments[corner.first], seg.segments[corner.second]
                ext = _CornerExtent.of(corner, a, b, seg.noise_m, sigma, cfg.sigmas)
                if ext.near_a < -ext.tol or ext.near_b < -ext.tol:
                    continue
                for beacon in beacons:
                    nodes.extend(_test_corner(corner, a, b, beacon, ext, sigma, cfg))
            tol = cfg.sigmas * (seg.noise_m + sigma)
            singles = [
                SingleMatch(beacon.id, k + 1, s.index)
                for s in seg.segments
                for beacon in beacons
                for k, length in enumerate(beacon.template.panel_lengths)
                if length - s.spacing_start - s.spacing_end - tol <= s.length <= length + tol
            ]
            assert [(n.beacon, n.edge, n.forward, n.option, n.segments) for n in got.nodes] == [
                (n.beacon, n.edge, n.forward, n.option, n.segments) for n in nodes
            ]
            assert list(got.singles) == singles
            compared += len(nodes)
    assert compared > 20  # the scenes' own beacons and look-alike designs were identified


def test_an_outer_panel_running_on_into_the_wall_still_identifies_its_node() -> None:
    # Issue 31 (shared noisy scene 0026, hostile 0009): the rock past a beacon's free end
    # e4 lies in the line of its third panel, and the segmentation cannot part them: the
    # segment is longer than P3. The node e3 is still where the two lines meet; it is
    # identified on the deflection and P2's length, with P3 not an identified panel.
    from mast import Beacon, Survey
    from mast.sim import ScannerModel

    edges = np.array([[-0.8, 3.0], [-0.42, 2.7], [0.1, 3.0], [0.5, 3.0]])  # P3 on the wall
    wb = WorldBuilder()
    wb.polyline([[-30.0, 3.0], edges[0]], Surface("wall"))
    wb.panels(edges, "B")
    wb.polyline([edges[3], [30.0, 3.0]], Surface("wall"))
    survey = Survey([Beacon("B", edges)])
    sim = simulate_scan(wb.build(), Pose2D(0.0, 0.0, 0.0), ScannerModel("s", 270.0, 0.25))
    seg = segment_scan(sim.scan)
    e3 = [n for n in identify_panels(seg, survey).nodes if n.beacon == "B" and n.edge == 3]
    assert e3
    node = e3[0]
    assert dict(zip(node.panels, node.identified, strict=True)) == {2: True, 3: False}
    assert seg.segments[node.segments[node.panels.index(3)]].length > 10.0  # P3 and the wall
    expected = Pose2D(0.0, 0.0, 0.0).mine_to_scanner(edges[2][None, :])[0]
    assert np.hypot(*(node.node_scanner - expected)) < 1e-6
