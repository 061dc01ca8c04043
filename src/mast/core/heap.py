"""Python's cyclic garbage collector kept out of a long loop's latency.

A full collection visits every object alive: about 250 000 once a survey, the
compiled kernels and a run's state are loaded, 50-130 ms on a 2-core machine. It
comes round whenever enough objects have survived since the last one, in the middle
of whichever scan is being located then (the largest latencies of ``mast bench live``
and the slowest scans of ``mast bench speed`` were such collections). Locating scans
makes no cyclic garbage (none in 300 drive scans located in sequence, collector off,
then collected), so what is alive once a loop has located its first scan is either
alive for good or freed by reference counting. Frozen (:func:`gc.freeze`), the
collector never visits it again, and a collection costs what the loop allocated
since; freezing again every so many scans keeps that small on a long run. Reference
counting still frees frozen objects; only a cycle among them would outlive the loop.
"""

from __future__ import annotations

import gc
from collections.abc import Iterable, Iterator
from types import TracebackType
from typing import TypeVar

_T = TypeVar("_T")

__all__ = ["QuietCollector"]


class QuietCollector:
    """Freeze the heap after a loop's first step and every ``every`` steps after it, and
    give the process's frozen objects back to the collector when the loop ends (loops
    using it are not nested).

    Use as a context manager around the loop, its items through :meth:`each` (or
    :meth:`step` called after each)::

        with QuietCollector() as heap:
            for scan in heap.each(scans):
                locate(scan)
    """

    def __init__(self, every: int = 1000) -> None:
        if every < 1:
            raise ValueError(f"every must be at least 1, not {every}")
        self.every = every
        self.steps = 0
        self.freezes = 0

    def __enter__(self) -> QuietCollector:
        return self

    def step(self) -> None:
        """One step of the loop done: after the first, and every ``every``-th, what is
        alive is frozen."""
        self.steps += 1
        if self.steps == 1 or self.steps % self.every == 0:
            gc.freeze()
            self.freezes += 1

    def each(self, items: Iterable[_T]) -> Iterator[_T]:
        """``items``, one :meth:`step` counted after each is handled (when the next is
        asked for, or the loop ends)."""
        for item in items:
            yield item
            self.step()

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if self.freezes:
            gc.unfreeze()
