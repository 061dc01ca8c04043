"""One rule for when a scan is owed a fix, counted by named rules."""

from __future__ import annotations

from mast.sim import paper_scene
from mast.sim.owed import OWED, OWED_CLEAN, OWED_FIELD, OWED_REAL_WALLS, OwedRule, owes_fix


def test_two_beacons_with_two_panels_each_are_owed_a_fix() -> None:
    assert owes_fix({"B1": [1, 2], "B2": [2, 3]})
    assert owes_fix({"B1": [1, 2, 3], "B2": [1, 2], "B3": [1]})
    assert not owes_fix({"B1": [1, 2, 3], "B2": [3]})
    assert not owes_fix({"B1": [1, 2]})
    assert not owes_fix({})


def test_a_simulated_scan_counts_its_panels_by_the_rule_given() -> None:
    sim = paper_scene().simulate_all()[0]
    for rule in (OWED, OWED_FIELD, OWED_CLEAN, OWED_REAL_WALLS):
        seen = sim.panels_seen(rule)
        assert sim.owes_fix(rule) == owes_fix(seen)
    # No panel has a million returns: nothing is owed under that rule.
    assert not sim.owes_fix(OwedRule(min_points=1_000_000))
    assert sim.owes_fix() == sim.owes_fix(OWED)
