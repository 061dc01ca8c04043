"""Write the example drift for ``mast plan``: drift.csv, drift.dxf and beacons.csv.

A 161 m drift, 5 m wide, in a local mine grid: 60 m at azimuth 70 degrees, a
30 m bend to 110 degrees, then 70 m straight. Five beacons are installed near
its start and middle; the last 75 m have none. Run from the repository:

    .venv/bin/python examples/plan/make_example.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mast.core.beacon import Survey
from mast.io.beacons_csv import write_survey
from mast.sim.design import paper_design, polyline_design
from mast.sim.tunnel import Tunnel

HERE = Path(__file__).parent
ORIGIN = np.array([15_200.0, 42_800.0])


def main() -> None:
    az = np.radians(np.concatenate([np.full(60, 70.0), np.linspace(70, 110, 31), np.full(70, 110.0)]))
    steps = np.stack([np.sin(az), np.cos(az)], axis=1)
    centre = ORIGIN + np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])
    tunnel = Tunnel(centre[::2], 5.0)  # wall vertices every 2 m
    left, right = tunnel.walls()
    with (HERE / "drift.csv").open("w", encoding="utf-8") as fh:
        fh.write("wall,vertex,easting,northing\n")
        for name, wall in (("north", left), ("south", right)):
            for k, (e, n) in enumerate(wall):
                fh.write(f"{name},{k + 1},{e:.3f},{n:.3f}\n")

    import ezdxf

    doc = ezdxf.new("R2010")
    doc.layers.add("WALLS")
    msp = doc.modelspace()
    for wall in (left, right):
        msp.add_lwpolyline(np.round(wall, 3).tolist(), dxfattribs={"layer": "WALLS"})
    doc.saveas(HERE / "drift.dxf")

    designs = {
        "hat-1.2": paper_design(1.2, 0.2),
        "hat-1.5": paper_design(1.5, 0.25),
        "chevron": polyline_design((0.5, 0.35, 0.7), (-0.7, -0.9), name="chevron"),
    }
    layout = [
        ("B1", 8.0, "left", "hat-1.2"),
        ("B2", 16.0, "right", "hat-1.5"),
        ("B3", 25.0, "left", "chevron"),
        ("B4", 68.0, "right", "hat-1.2"),
        ("B5", 77.0, "left", "chevron"),
    ]
    beacons = []
    for bid, station, side, design in layout:
        point, tangent, tunnel_side = tunnel.wall_point(side, station)
        # round to the millimetre, as a survey file would give them
        b = designs[design].beacon(bid, point, tangent, tunnel_side=tunnel_side)
        beacons.append(type(b)(bid, np.round(b.edges, 3)))
    write_survey(HERE / "beacons.csv", Survey(beacons))


if __name__ == "__main__":
    main()
