"""Noise-free accuracy and fix rate of the locator over seeded random drifts (issue 3).

Not a test: prints figures. Run: .venv/bin/python benchmarks/noise_free.py [SEEDS]
A fix is owed when two beacons each show two panels (>= 3 returns, >= 10 deg incidence).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from mast.pipeline.locator import locate
from mast.sim import paper_scenario, random_scene
from mast.sim.owed import OWED


def main(seeds: int = 100) -> None:
    owed = owed_fixed = extra = wrong = 0
    pos, az, times = [], [], []
    reasons: dict[str, int] = {}
    per_res: dict[float, list[int]] = {}
    scenes = [s for seed in range(seeds) for s in (random_scene(seed, i) for i in range(4))]
    scenes += paper_scenario()
    for scene in scenes:
        for shot, sim in zip(scene.shots, scene.simulate_all(), strict=True):
            is_owed = sim.owes_fix(OWED)
            t0 = time.perf_counter()
            fix = locate(sim.scan, scene.survey)
            times.append(time.perf_counter() - t0)
            owed += is_owed
            stats = per_res.setdefault(shot.scanner.resolution_deg, [0, 0])
            stats[0] += is_owed
            if fix.ok and fix.pose is not None:
                d = math.hypot(
                    fix.pose.easting - shot.pose.easting, fix.pose.northing - shot.pose.northing
                )
                a = (
                    abs(
                        math.degrees(
                            math.remainder(fix.pose.azimuth - shot.pose.azimuth, 2 * math.pi)
                        )
                    )
                    * 3600
                )
                pos.append(d)
                az.append(a)
                owed_fixed += is_owed
                stats[1] += is_owed
                extra += not is_owed
                wrong += d > 1e-4 or a > 1.0
            else:
                reasons[fix.reason or "?"] = reasons.get(fix.reason or "?", 0) + 1
    p, a = np.array(pos), np.array(az)
    print(
        f"scans {len(times)}  owed {owed}  owed fixed {owed_fixed} "
        f"({100 * owed_fixed / owed:.2f} %)"
    )
    for res, (o, f) in sorted(per_res.items()):
        print(f"  resolution {res:g} deg: owed {o}, fixed {f}")
    print(
        f'fixes not owed (fewer panels, still exact): {extra}; fixes off by >0.1 mm or >1": {wrong}'
    )
    print(f"position error  max {p.max():.3e} m   median {np.median(p):.3e} m")
    print(f'azimuth error   max {a.max():.3e} "  median {np.median(a):.3e} "')
    print(f"no-fix reasons {reasons}")
    print(
        f"time per scan   median {1e3 * np.median(times):.2f} ms   "
        f"95th pct {1e3 * np.percentile(times, 95):.2f} ms"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100)
