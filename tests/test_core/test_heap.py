"""The collector kept out of a loop: frozen after the first step and every so many."""

from __future__ import annotations

import gc

import pytest

from mast.core.heap import QuietCollector


def test_the_heap_is_frozen_after_the_first_step_and_given_back_at_the_end() -> None:
    assert gc.get_freeze_count() == 0
    kept: list[object] = []
    with QuietCollector(every=3) as heap:
        assert gc.get_freeze_count() == 0  # nothing frozen before a step is done
        for item in heap.each(range(7)):
            kept.append([item])  # a container the collector tracks, made in the step
        assert heap.steps == 7
        assert heap.freezes == 3  # after steps 1, 3 and 6
        assert gc.get_freeze_count() > 0
    assert gc.get_freeze_count() == 0


def test_a_loop_with_no_step_freezes_nothing() -> None:
    with QuietCollector() as heap:
        for _ in heap.each([]):
            pass
    assert heap.freezes == 0
    assert gc.get_freeze_count() == 0


def test_every_must_be_positive() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        QuietCollector(every=0)
