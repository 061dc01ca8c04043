"""The undamaged inputs every case damages: a survey, scan CSVs, ROS 1 and ROS 2 bags, drifts."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mast.bench.fuzz.mutations import bz2_bomb_bag

__all__ = ["BaseRun", "Seeds", "make_seeds"]


#: An undamaged run: its processor seconds, its peak bytes, its fixes by stamp, and the
#: true poses (E, N, azimuth in degrees) of the scans it holds.
BaseRun = tuple[float, int, dict[int, tuple[float, ...]], list[tuple[float, float, float]]]


@dataclass(frozen=True, slots=True)
class Seeds:
    root: Path
    survey: Path
    scans: tuple[Path, ...]
    bag1: Path
    bag1_bz2: Path
    ros2_sqlite: Path
    ros2_mcap: Path
    drift_csv: Path
    drift_dxf: Path
    bomb: Path
    truth: tuple[tuple[float, float, float], ...]


def make_seeds(root: Path) -> Seeds:
    from dataclasses import replace

    from mast.io.bags import write_laserscans
    from mast.io.scan_csv import read_scan_csv
    from mast.sim.scenarios import build_scenario, write_scenario

    written = write_scenario(build_scenario("paper", 0, noise=True)[:1], root / "sim")
    scene = written[0]
    scans = tuple(scene.scans[:3])
    loaded = [read_scan_csv(p) for p in scene.scans]
    stamped = [replace(s, stamp_ns=i * 40_000_000) for i, s in enumerate(loaded)]
    bag1 = root / "run.bag"
    write_laserscans(bag1, stamped, kind="rosbag1")
    bag1_bz2 = root / "run_bz2.bag"
    write_laserscans(bag1_bz2, stamped, kind="rosbag1", compression="bz2")
    ros2_sqlite = root / "run_db3"
    write_laserscans(ros2_sqlite, stamped, kind="sqlite3")
    ros2_mcap = root / "run_mcap"
    write_laserscans(ros2_mcap, stamped, kind="mcap")
    drift_csv = root / "drift.csv"
    drift_csv.write_text(
        "wall,vertex,easting,northing\n"
        "L,1,500000.0,7000000.0\nL,2,500040.0,7000000.0\n"
        "R,1,500000.0,7000005.0\nR,2,500040.0,7000005.0\n",
        encoding="utf-8",
    )
    drift_dxf = root / "drift.dxf"
    _write_drift_dxf(drift_dxf)
    bomb = root / "bomb.bag"
    bz2_bomb_bag(bomb, 1536 << 20)
    return Seeds(
        root,
        scene.survey,
        scans,
        bag1,
        bag1_bz2,
        ros2_sqlite,
        ros2_mcap,
        drift_csv,
        drift_dxf,
        bomb,
        _truth(scene.truth),
    )


def _truth(path: Path) -> tuple[tuple[float, float, float], ...]:
    import csv

    with path.open(encoding="utf-8", newline="") as fh:
        return tuple(
            (float(r["easting"]), float(r["northing"]), float(r["azimuth_deg"]))
            for r in csv.DictReader(fh)
        )


def _write_drift_dxf(path: Path) -> None:
    from mast.io.dxf import new_dxf, save_dxf

    doc, msp = new_dxf({"W": 7})
    msp.add_lwpolyline([(500000.0, 7000000.0), (500040.0, 7000000.0)], dxfattribs={"layer": "W"})
    msp.add_lwpolyline([(500000.0, 7000005.0), (500040.0, 7000005.0)], dxfattribs={"layer": "W"})
    save_dxf(doc, path)
