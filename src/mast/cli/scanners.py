"""``mast scanners``: the scanner models MAST knows."""

from __future__ import annotations

import typer

from mast.cli.root import (
    app,
)

#: The ``mast live`` source each model is reached by (the protocol its vendor's Ethernet
#: models speak; docs/live.md): SICK CoLa-A on port 2111, Hokuyo SCIP 2.0 on port 10940.
LIVE_SOURCES = {
    "lms1xx-0.5": "sick://",
    "lms1xx-0.25": "sick://",
    "tim551": "sick://",
    "tim561": "sick://",
    "tim571": "sick://",
    "tim781": "sick://",
    "ust-10lx": "hokuyo://",
    "ust-20lx": "hokuyo://",
}


@app.command()
def scanners() -> None:
    """List the named scanner models (field of view, resolution, range limits, range
    noise) and the mast live source that reaches each (sick:// for SICK CoLa-A,
    hokuyo:// for Hokuyo SCIP 2.0; '-' when live has no protocol for it), then the 3D
    lidars (rings, vertical field, range limits, the range sigma their PointCloud2
    frames are weighted with; live replays their bags). Give a name to --scanner of
    locate, track, live and plan (the 3D lidars: locate, track and live).

    \b
    Example: mast scanners
    """
    from mast.cli.options import LIDAR_RANGE_SIGMA_M
    from mast.sim import SCANNERS
    from mast.sim.lidar3d import LIDARS

    for m in SCANNERS.values():
        typer.echo(
            f"{m.name:<18} {m.fov_deg:5.0f}° at {m.resolution_deg:.4g}°, "
            f"{m.range_min_m:g}–{m.range_max_m:g} m, σ {1e3 * m.range_sigma_m:g} mm, "
            f"live {LIVE_SOURCES.get(m.name, '-')}"
        )
    for name, sigma in LIDAR_RANGE_SIGMA_M.items():
        lidar = LIDARS[name]
        low, high = min(lidar.ring_elevations_deg), max(lidar.ring_elevations_deg)
        typer.echo(
            f"{name:<18} 3D, {lidar.rings} rings {low:+.1f}° to {high:+.1f}°, "
            f"{lidar.range_min_m:g}–{lidar.range_max_m:g} m, σ {1e3 * sigma:g} mm, "
            "live replay://"
        )
