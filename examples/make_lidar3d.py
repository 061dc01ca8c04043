"""Write the README's 3D example: a few frames of a simulated Velodyne VLP-16 in a drift.

One seeded drift of :func:`mast.sim.lidar3d.random_drift_scene` (rough rock on a grade,
three-panel beacons on its walls, the vehicle rolled and pitched), its lidar a VLP-16
(16 rings, -15° to +15°, 2 cm range noise). Written here:

- ``beacons3d.csv``: the drift's survey with each edge's top ``elevation``;
- ``lidar3d.bag``: the frames as ``sensor_msgs/PointCloud2`` on ``/points`` (x, y, z
  FLOAT32 and ``ring``, as the Velodyne driver writes them; bz2-compressed ROS 1 bag).
  The coordinates are rounded to the millimetre (the VLP-16 reports its distances in
  2 mm steps), which halves the compressed bag: the examples stay under 1.5 MB;
- ``truth3d.csv``: each frame's true pose (stamp, easting, northing, elevation,
  azimuth, pitch and roll in degrees).

Run from the repository (the output is the same on every run):

    .venv/bin/python examples/make_lidar3d.py
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from mast.core.pose3d import Frame3D
from mast.io.beacons_csv import write_survey
from mast.io.pointclouds import write_pointclouds
from mast.sim.lidar3d import random_drift_scene

HERE = Path(__file__).parent
#: The drift's seed and the frames of it written (both owed a fix: two beacons show
#: two panels each to two rings).
SEED = 2
FRAMES = (0, 3)
#: The bag's first stamp (2023-11-14 22:13:20 UTC), frames 0.1 s apart as simulated.
T0_NS = 1_700_000_000 * 10**9


def main() -> None:
    scene = random_drift_scene(SEED, frames=max(FRAMES) + 1, lidar="vlp16", range_sigma_m=0.02)
    write_survey(HERE / "beacons3d.csv", scene.survey)
    sims = [scene.simulate(i) for i in FRAMES]
    frames = [
        Frame3D(
            np.round(s.frame.points, 3),
            ring=s.frame.ring,
            stamp_ns=T0_NS + k * 100_000_000,
            frame_id="velodyne",
        )
        for k, s in enumerate(sims)
    ]
    write_pointclouds(HERE / "lidar3d.bag", frames, topic="/points", compression="bz2")
    with (HERE / "truth3d.csv").open("w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh)
        out.writerow(
            ["stamp_ns", "easting", "northing", "elevation", "azimuth_deg", "pitch_deg", "roll_deg"]
        )
        for frame, s in zip(frames, sims, strict=True):
            p = s.pose
            out.writerow(
                [
                    frame.stamp_ns,
                    f"{p.easting:.6f}",
                    f"{p.northing:.6f}",
                    f"{p.elevation:.6f}",
                    f"{math.degrees(p.azimuth) % 360:.6f}",
                    f"{math.degrees(p.pitch):.6f}",
                    f"{math.degrees(p.roll):.6f}",
                ]
            )


if __name__ == "__main__":
    main()
