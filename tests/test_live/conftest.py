"""A short simulated drive with beacons in view, as a bag the emulators and replays serve."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from mast.core.beacon import Survey
from mast.io import write_survey
from mast.io.bags import write_laserscans
from mast.sim.drive import drive_scene

#: Scans of the test drive (50 Hz: 2.4 s), from its first beacons on.
DRIVE_SCANS = 120


@dataclass(frozen=True)
class Drive:
    survey: Survey
    beacons: Path
    bag: Path
    scans: int


@pytest.fixture(scope="session")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Drive:
    folder = tmp_path_factory.mktemp("drive")
    scene = drive_scene(0, scans=DRIVE_SCANS, rate_hz=50.0)
    beacons = folder / "beacons.csv"
    write_survey(beacons, scene.survey)
    bag = folder / "drive_mcap"
    write_laserscans(bag, (s.scan for s in scene.iter_simulated()), kind="mcap")
    return Drive(scene.survey, beacons, bag, DRIVE_SCANS)
