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
    hokuyo:// for Hokuyo SCIP 2.0; '-' when live has no protocol for it). Give a name to
    --scanner of locate, track, live and plan.

    \b
    Example: mast scanners
    """
    from mast.sim import SCANNERS

    for m in SCANNERS.values():
        typer.echo(
            f"{m.name:<18} {m.fov_deg:5.0f}° at {m.resolution_deg:.4g}°, "
            f"{m.range_min_m:g}–{m.range_max_m:g} m, σ {1e3 * m.range_sigma_m:g} mm, "
            f"live {LIVE_SOURCES.get(m.name, '-')}"
        )
