"""Write the README's example data: a survey, a scan, a folder of scans and small bags.

Everything comes from one simulated drive (:func:`mast.sim.drive.drive_scene`, seed
below): a vehicle driving a drift with beacons on its walls, its scanner LMS1xx-like
(270° at 0.25°, 25 Hz, 12 mm range noise, as a SICK LMS1xx's data sheet gives its
statistical error), so that the data is as noisy as the field's. Written here:

- ``beacons.csv``: the drift's survey (the survey contract: beacon,edge,easting,northing);
- ``scan.csv``: one scan (the scan CSV contract) that sees two beacons;
- ``scans/``: the first eight scans of the drive as scan CSVs (a run at 25 Hz);
- ``run.bag``: the first 80 scans as a ROS 1 bag (``sensor_msgs/LaserScan`` on /scan);
- ``runs/``: two more short runs of the same drive, a ROS 1 bag each;
- ``log.bag``: a sparse log, one scan a second over the whole drive (``--max-gap``);
- ``truth.csv``: the true pose of every scan written (file, scan index in it, stamp).

Run from the repository (the output is the same on every run):

    .venv/bin/python examples/make_examples.py
"""

from __future__ import annotations

import csv
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from mast.core.beacon import Beacon, Survey
from mast.core.scan import Scan
from mast.io.bags import write_laserscans
from mast.io.beacons_csv import write_survey
from mast.io.scan_csv import write_scan_csv
from mast.sim.drive import drive_scene
from mast.sim.owed import OWED

HERE = Path(__file__).parent
#: The drive: its seed and its length (24 s at 25 Hz, some 50 m of drift).
SEED = 3
SCANS = 600
#: Which of the drive's scans each file holds.
RUN = range(0, 80)
SCAN_FOLDER = range(0, 8)
RUNS = {"runs/drive_a.bag": range(80, 110), "runs/drive_b.bag": range(110, 140)}
LOG_EVERY = 25
#: The scan written as scan.csv.
ONE_SCAN = 20


def main() -> None:
    drive = drive_scene(SEED, scans=SCANS, rate_hz=25.0, noise=True)
    sims = list(drive.iter_simulated())
    scans = [s.scan for s in sims]
    for old in ("scans", "runs"):
        shutil.rmtree(HERE / old, ignore_errors=True)
    (HERE / "scans").mkdir()
    (HERE / "runs").mkdir()
    # to the millimetre, as a survey file gives them (0.3 mm beside the 3 mm survey sigma)
    surveyed = [Beacon(b.id, np.round(b.edges, 3)) for b in drive.survey]
    write_survey(HERE / "beacons.csv", Survey(surveyed))
    truth: list[tuple[str, int, int]] = [("scan.csv", 0, ONE_SCAN)]
    write_scan_csv(HERE / "scan.csv", _exported(scans[ONE_SCAN]))
    for k, i in enumerate(SCAN_FOLDER):
        name = f"scans/scan_{k:03d}.csv"
        write_scan_csv(HERE / name, _exported(scans[i]))
        truth.append((name, 0, i))
    bags = {"run.bag": RUN, **RUNS, "log.bag": range(0, SCANS, LOG_EVERY)}
    for name, which in bags.items():
        (HERE / name).unlink(missing_ok=True)
        write_laserscans(HERE / name, (scans[i] for i in which), kind="rosbag1")
        truth += [(name, k, i) for k, i in enumerate(which)]
    with (HERE / "truth.csv").open("w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(
            ["file", "scan", "stamp_ns", "easting", "northing", "azimuth_deg", "beacons_seen"]
        )
        for name, k, i in truth:
            pose = sims[i].pose
            seen = " ".join(sorted(sims[i].panels_seen(OWED)))
            out.writerow(
                [
                    name,
                    k,
                    scans[i].stamp_ns,
                    f"{pose.easting:.4f}",
                    f"{pose.northing:.4f}",
                    f"{pose.azimuth_deg:.4f}",
                    seen,
                ]
            )


def _exported(scan: Scan) -> Scan:
    """A scan as a vendor's export gives it: ranges to a tenth of a millimetre (a third
    of the file's size; the quantisation, 0.03 mm, is nothing beside the 12 mm noise)."""
    return replace(scan, ranges_m=np.round(scan.ranges_m, 4))


if __name__ == "__main__":
    main()
