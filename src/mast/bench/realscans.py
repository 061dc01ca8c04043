"""Real scans recorded by others (``../shared/data``): no beacon must be found in them,
and beacons ray-cast into their real ranges must be.

1. *Zero fixes*: every scan of each data set is located against a survey of
   three beacons mounted on walls seen in that data set's first scan, in its
   frame. The scans contain no MAST beacon: any fix is a false one.
2. *Inserted beacons*: for every tenth scan, two of the paper's 2:3:1 beacons
   (1.0 m x 0.2 m) are mounted on straight stretches (0.3 m or more) of that scan's surfaces,
   1-4 m away, and ray-cast into the real ranges (a beam that meets a panel
   before the real surface returns the panel, with the scan's own noise; the rest of the
   real clutter stays). The scanner pose is set to (1000 m, 2000 m, 30 deg).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast.bench.clutter import cast_beacons
from mast.bench.robustness import is_wrong
from mast.core.beacon import Beacon, Survey
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.io import read_laserscans
from mast.io.urg_log import read_urg_log
from mast.pipeline.locator import LocatorConfig, locate
from mast.pipeline.segmentation import segment_scan
from mast.sim import paper_design

__all__ = ["RealScanSummary", "real_datasets", "run_real_scans"]

POSE = Pose2D.from_degrees(1000.0, 2000.0, 30.0)
DESIGN = paper_design(1.0, 0.2)


@dataclass
class RealScanSummary:
    dataset: str
    scans: int = 0
    false_fixes: int = 0
    inserted: int = 0
    inserted_fixed: int = 0
    inserted_wrong: int = 0
    max_error_mm: float = 0.0
    errors_mm: list[float] = field(default_factory=list)

    def line(self) -> str:
        med = float(np.median(self.errors_mm)) if self.errors_mm else math.nan
        return (
            f"{self.dataset:<12} scans {self.scans:4d}: fixes without beacons {self.false_fixes}; "
            f"with 2 inserted beacons {self.inserted_fixed}/{self.inserted} fixed, "
            f"wrong {self.inserted_wrong}, position error median {med:.1f} mm "
            f"max {self.max_error_mm:.1f} mm"
        )


def real_datasets(data_dir: Path) -> Iterator[tuple[str, list[Scan]]]:
    urg = data_dir / "breezyslam_urg04lx"
    for name in ("exp1", "exp2"):
        if (urg / f"{name}.dat").is_file():
            yield f"urg04lx-{name}", list(read_urg_log(urg / f"{name}.dat"))
    bag = data_dir / "ccny_hokuyo_rosbag" / "demo.bag"
    if bag.is_file():
        yield "ccny-bag", list(read_laserscans(bag))


def _wall_sites(
    scan: Scan, count: int, min_len: float = 0.3
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """(midpoint, direction) of straight stretches 1-4 m away, well apart, in the scanner frame."""
    seg = segment_scan(scan)
    sites: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    for s in sorted(seg.segments, key=lambda s: -s.length):
        mid = s.midpoint
        r = float(np.hypot(*mid))
        if s.length < min_len or not 1.0 <= r <= 4.0:
            continue
        # the stretch must face the scanner reasonably (not seen edge-on)
        if abs(float(s.normal @ (mid / r))) < 0.5:
            continue
        if all(np.hypot(*(mid - m)) > 1.5 for m, _ in sites):
            sites.append((mid, s.direction))
        if len(sites) == count:
            break
    return sites


def _mount(mid: NDArray[np.float64], direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """Beacon edges on the wall line through ``mid``, standing out towards the scanner."""
    side = 1 if float(np.array([-direction[1], direction[0]]) @ -mid) > 0 else -1
    return DESIGN.mounted(mid, direction, tunnel_side=side)


def run_real_scans(
    data_dir: Path, *, every: int = 10, echo: Callable[[str], object] = print
) -> list[RealScanSummary]:
    cfg = LocatorConfig(range_sigma_m=0.01)
    out = []
    rng = np.random.default_rng(0)
    for name, scans in real_datasets(data_dir):
        s = RealScanSummary(name)
        sites = _wall_sites(scans[0], 3)
        survey = Survey(
            [
                Beacon(f"R{k + 1}", POSE.scanner_to_mine(_mount(m, d)))
                for k, (m, d) in enumerate(sites)
            ]
        )
        for i, scan in enumerate(scans):
            s.scans += 1
            if len(survey) >= 2:
                s.false_fixes += locate(scan, survey, config=cfg).ok
            if i % every:
                continue
            found = _wall_sites(scan, 2)
            if len(found) < 2:
                continue
            edges = [_mount(m, d) for m, d in found]
            local = Survey(
                [Beacon(f"I{k + 1}", POSE.scanner_to_mine(e)) for k, e in enumerate(edges)]
            )
            # The panels are measured by the same scanner: its own noise level, from the scan.
            noise = segment_scan(scan).noise_m
            inserted = cast_beacons(scan, POSE, local, rng, noise_m=noise).scan
            fix = locate(inserted, local, config=cfg)
            s.inserted += 1
            if fix.ok and fix.pose is not None and fix.adjustment is not None:
                s.inserted_fixed += 1
                err = math.hypot(fix.pose.easting - POSE.easting, fix.pose.northing - POSE.northing)
                s.errors_mm.append(1e3 * err)
                s.max_error_mm = max(s.max_error_mm, 1e3 * err)
                s.inserted_wrong += is_wrong(fix, POSE)
        echo(s.line())
        out.append(s)
    return out
