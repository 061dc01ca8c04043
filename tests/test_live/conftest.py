"""A short simulated drive with beacons in view, as a bag the emulators and replays serve."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from mast.core.beacon import Survey
from mast.sim import write_scenario
from mast.sim.drive import drive_scene

#: Scans of the test drive (50 Hz: 2.4 s), from its first beacons on.
DRIVE_SCANS = 120


@dataclass(frozen=True)
class Drive:
    survey: Survey
    beacons: Path
    bag: Path
    scans: int
    owed: tuple[bool, ...] = ()
    """Per scan of the bag, in order: whether it owes a fix (two beacons, two panels each)."""


@pytest.fixture(scope="session")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    scene = drive_scene(0, scans=DRIVE_SCANS, rate_hz=50.0)
    (written,) = write_scenario([scene], tmp_path_factory.mktemp("drive"), fmt="mcap")
    owed = tuple(sim.owes_fix() for sim in scene.iter_simulated())
    return Drive(scene.survey, written.survey, written.scans[0], DRIVE_SCANS, owed)
