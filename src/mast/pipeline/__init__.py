"""The locator's pipeline, one module per stage of the MAST paper.

1. :mod:`~mast.pipeline.segmentation` — PCA line segmentation;
2. :mod:`~mast.pipeline.identification` — panel identification (Table 1);
3. :mod:`~mast.pipeline.hypotheses` — template matching: pose hypotheses;
4. :mod:`~mast.pipeline.alignment` — similarity transform and point-to-line ICP;
5. :mod:`~mast.pipeline.adjustment` — least squares, covariance, tests;

with :mod:`~mast.pipeline.integrity` (data snooping, beacon tests),
:mod:`~mast.pipeline.bounds` (the Cramér–Rao bound) and
:mod:`~mast.pipeline.locator`, which chains them: ``locate(scan, survey) -> Fix``.
"""

from mast.pipeline.locator import (
    NO_FIX_REASONS,
    Fix,
    LocatorConfig,
    SequenceConfig,
    locate,
    locate_sequence,
)
from mast.pipeline.tracking import Prior

__all__ = [
    "NO_FIX_REASONS",
    "Fix",
    "LocatorConfig",
    "Prior",
    "SequenceConfig",
    "locate",
    "locate_sequence",
]
