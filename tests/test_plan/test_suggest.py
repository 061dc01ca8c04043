"""Suggested beacons: on the walls, identifiable, and each one adds coverage."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mast.io import read_survey
from mast.io.beacons_csv import write_survey
from mast.pipeline.locator import locate
from mast.plan.drift import wall_distance
from mast.plan.predict import PlanSettings, locator_config, plan_world, predict
from mast.plan.suggest import centreline_share, designs_of, suggest
from mast.sim.scanner import scanner_model, simulate_scan
from tests.test_plan._scenes import pair_scene

SCANNER = scanner_model("lms1xx-0.25")


def test_designs_of_a_survey_are_its_distinct_shapes() -> None:
    _, _, survey = pair_scene()
    designs = designs_of(survey)
    assert len(designs) == 2
    for d, b in zip(designs, survey, strict=True):
        assert d.chord_m == np.hypot(*(b.edges[3] - b.edges[0]))
        assert d.edges_local[1:3, 1].mean() > 0  # stands out of the wall


def test_suggestions_cover_more_of_the_drift(tmp_path: Path) -> None:
    _, drift, survey = pair_scene()
    settings = PlanSettings(step_m=4.0, scans_per_cell=2, roughness_m=0.0, target_sigma_m=0.02)
    plan = predict(drift, survey, SCANNER, settings)
    found = suggest(plan, 2)
    assert 1 <= len(found.added) <= 2
    assert centreline_share(found.after) > centreline_share(plan)
    assert list(found.shares) == sorted(found.shares)
    assert found.shares[-1] == centreline_share(found.after)
    assert found.after.proposed == tuple(b.id for b in found.added)
    ids = [b.id for b in found.after.survey]
    assert len(set(ids)) == len(ids)
    for b in found.added:
        b.check_identifiable()
        assert wall_distance(drift, b.edges[[0, 3]]).max() < 0.02  # mounted on a wall
        assert wall_distance(drift, b.edges[1:3]).min() > 0.05  # standing out of it
    # the proposal is a survey file mast locate reads, and a fix there uses a new beacon
    path = tmp_path / "proposed_beacons.csv"
    write_survey(path, found.after.survey)
    proposed = read_survey(path)
    assert proposed.ids == ids
    grid = found.after.grid
    world = plan_world(drift, proposed)
    rows, cols, heads = np.nonzero(found.after.has_fix & ~plan.has_fix)
    assert len(rows) > 0
    from mast.plan.predict import cell_pose

    pose = cell_pose(grid, int(rows[0]), int(cols[0]), int(heads[0]))
    cfg = locator_config(SCANNER, settings)
    rng = np.random.default_rng(5)
    used = set()
    for _ in range(5):
        fix = locate(simulate_scan(world, pose, SCANNER, rng=rng).scan, proposed, config=cfg)
        if fix.ok:
            used |= set(fix.beacons)
            assert (
                np.hypot(fix.pose.easting - pose.easting, fix.pose.northing - pose.northing) < 0.05
            )
    assert used & set(found.after.proposed)


def test_no_suggestion_when_nothing_helps() -> None:
    _, drift, survey = pair_scene()
    # a target no layout meets: nothing is ever covered, so nothing is proposed
    settings = PlanSettings(step_m=8.0, scans_per_cell=1, roughness_m=0.0, target_sigma_m=1e-6)
    plan = predict(drift, survey, SCANNER, settings)
    found = suggest(plan, 3)
    assert found.added == ()
    assert found.after is plan
