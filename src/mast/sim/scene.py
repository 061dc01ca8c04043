"""A simulated site: its surfaces, its beacon survey and the shots (true pose, scanner)
taken in it; every scenario (:mod:`mast.sim.scenarios`, :mod:`mast.sim.hard`,
:mod:`mast.sim.drive`) is a list of them."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from mast.core.beacon import Survey
from mast.core.pose import Pose2D
from mast.sim.scanner import ScannerModel, SimulatedScan, simulate_scan
from mast.sim.world import World

__all__ = ["Scene", "Shot"]


@dataclass(frozen=True, slots=True)
class Shot:
    """One scan to simulate: a label, the true pose and the scanner."""

    label: str
    pose: Pose2D
    scanner: ScannerModel


@dataclass(frozen=True, eq=False)
class Scene:
    """A site: its surfaces, its beacon survey, and the shots taken in it."""

    name: str
    world: World
    survey: Survey
    shots: tuple[Shot, ...]
    description: str = ""
    seed: int = 0
    params: dict[str, object] = field(default_factory=dict)

    def simulate(
        self, shot: Shot, *, rng: np.random.Generator | None = None, stamp_ns: int = 0
    ) -> SimulatedScan:
        return simulate_scan(self.world, shot.pose, shot.scanner, rng=rng, stamp_ns=stamp_ns)

    def iter_simulated(self) -> Iterator[SimulatedScan]:
        """Every shot in order, one at a time, with noise drawn from a generator seeded
        by the scene's seed (stamps 0.1 s apart)."""
        rng = np.random.default_rng(self.seed)
        for i, s in enumerate(self.shots):
            yield self.simulate(s, rng=rng, stamp_ns=i * 100_000_000)

    def simulate_all(self) -> list[SimulatedScan]:
        """Every shot, as :meth:`iter_simulated` gives them."""
        return list(self.iter_simulated())
