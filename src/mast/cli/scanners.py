"""``mast scanners``: the scanner models MAST knows."""

from __future__ import annotations

import typer

from mast.cli.root import (
    app,
)


@app.command()
def scanners() -> None:
    """List the named scanner models (field of view, resolution, range noise)."""
    from mast.sim import SCANNERS

    for m in SCANNERS.values():
        typer.echo(
            f"{m.name:<18} {m.fov_deg:5.0f}° at {m.resolution_deg:.4g}°, "
            f"{m.range_min_m:g}–{m.range_max_m:g} m, σ {1e3 * m.range_sigma_m:g} mm"
        )
