"""``mast georef``: a SLAM point cloud georeferenced on the beacons it shows."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.options import (
    BeaconsOption,
    CrsOption,
    ForceOption,
    SurveySigmaOption,
    WorkUpdate,
    grid_crs,
    work_progress,
)
from mast.cli.root import (
    EXIT_NO_FIX,
    app,
)
from mast.core.noise import DEFAULT_SURVEY_SIGMA_M
from mast.errors import InputError
from mast.io.outputs import check_output_folder


@app.command()
def georef(
    cloud: Annotated[
        Path, typer.Argument(metavar="CLOUD", help="Point cloud: LAS, LAZ, E57 or PLY, z up.")
    ],
    beacons: BeaconsOption,
    out: Annotated[
        Path, typer.Option("--out", help="Folder for the outputs (created if missing).")
    ],
    model: Annotated[
        str,
        typer.Option(
            "--model",
            help="4: easting, northing, elevation offset and rotation about the vertical "
            "(levelled SLAM clouds); helmert7: a 3D similarity.",
        ),
    ] = "4",
    check: Annotated[
        str | None,
        typer.Option(
            "--check", help="Beacons kept out of the solution as independent checks: B7,B9."
        ),
    ] = None,
    band: Annotated[
        str | None,
        typer.Option(
            "--band",
            help="Z0,Z1: search for panels between these heights of the cloud's frame "
            "[default: from the floor and roof found along the drift].",
        ),
    ] = None,
    trajectory: Annotated[
        Path | None,
        typer.Option(
            "--trajectory",
            help="The SLAM trajectory (TUM, or a mast track trajectory.csv), in the points' "
            "time base: corrects the drift between beacons with a pose graph.",
        ),
    ] = None,
    drift: Annotated[
        float,
        typer.Option(
            "--drift",
            min=1e-5,
            max=0.5,
            help="Drift model with --trajectory: standard deviation of the SLAM's motion "
            "as a fraction of each step in position; the heading walks a tenth of it "
            "per root metre.",
        ),
    ] = 0.01,
    max_drift: Annotated[
        float,
        typer.Option(
            "--max-drift",
            min=0.0,
            max=0.5,
            help="Largest drift, as a fraction of the distance between beacons, that "
            "matching allows for.",
        ),
    ] = 0.02,
    time_field: Annotated[
        str | None,
        typer.Option("--time-field", help="Point attribute holding time [default: gps_time]."),
    ] = None,
    noise: Annotated[
        float | None,
        typer.Option(
            "--noise", min=0.0, help="The cloud's noise, metres [default: estimated from it]."
        ),
    ] = None,
    survey_sigma: SurveySigmaOption = None,
    crs: CrsOption = None,
    force: ForceOption = False,
) -> None:
    """Put a 3D SLAM point cloud into the mine grid from the beacons it shows.

    Writes into --out: georeferenced.laz (every attribute kept), transform.json
    (docs/transform.schema.json), beacons_found.csv, report.txt, report.html and plan.png;
    --crs names the grid in the cloud, transform.json and the reports.

    Exit status 0 georeferenced, 3 refused (too few beacons, an ambiguous match, beacons
    that disagree: the reports and beacons_found.csv say why), 2 bad input, 4 an output
    cannot be written.

    \b
    Example: mast simulate --scenario cloud --out sim && \\
      mast georef sim/cloud.laz -b sim/beacons.csv --out geo --check B04,B09
    """
    from mast.cloud.detect import DetectConfig
    from mast.cloud.georef import MODELS, GeorefConfig
    from mast.cloud.match import MatchConfig
    from mast.cloud.run import run_georef

    if model not in MODELS:
        raise InputError(f"--model must be one of {', '.join(MODELS)}, got {model!r}")
    if survey_sigma is not None and not (math.isfinite(survey_sigma) and survey_sigma >= 0):
        raise InputError(f"--survey-sigma must be a non-negative number, got {survey_sigma}")
    config = GeorefConfig(
        model=model,
        checks=parse_checks(check),
        survey_sigma_m=DEFAULT_SURVEY_SIGMA_M if survey_sigma is None else survey_sigma,
        detect=DetectConfig(band=parse_band(band), noise_m=noise),
        match=MatchConfig(max_drift=max_drift),
        drift=drift,
    )
    if trajectory is not None and not trajectory.is_file():
        raise InputError("no such file", path=trajectory)
    if trajectory is not None and model == "helmert7":
        raise InputError(
            "--trajectory corrects drift in plan and height with the 4-parameter model; "
            "--model helmert7's tilt and scale would not be carried by the pose graph"
        )
    grid = grid_crs(crs)
    check_output_folder(out, force=force)
    with work_progress("georef", counts=False) as bar:
        run = run_georef(
            cloud,
            beacons,
            out,
            config,
            trajectory_path=trajectory,
            time_field=time_field,
            progress=None if bar is None else _staged(bar),
            crs=grid,
        )
    r = run.result
    roles = [b.role for b in r.beacons]
    typer.echo(
        f"{cloud}: {r.cloud.count} points; beacons: {roles.count('control')} control, "
        f"{roles.count('check')} check, {roles.count('excluded')} left out, "
        f"{roles.count('not_found')} not found"
    )
    if r.refusal is not None:
        typer.echo(f"mast: not georeferenced ({r.refusal.reason}): {r.refusal.detail}", err=True)
        typer.echo(f"report in {run.outputs.report_txt}", err=True)
        raise typer.Exit(EXIT_NO_FIX)
    sol = r.solution
    assert sol is not None
    t = sol.transformation
    typer.echo(
        f"transformation: rotation {t.rotation_deg:.6f} deg, reference variance "
        f"{sol.reference_variance:.3f} ({sol.chi2_test}); files in {out}"
    )
    for c in r.checks:
        typer.echo(f"check {c.beacon}: {1000 * c.horizontal_m:.1f} mm horizontal")


def _staged(bar: WorkUpdate) -> Callable[[str, int, int], None]:
    """The cloud's progress (a pass's name, points done, points in it) onto the bar."""

    def update(stage: str, done: int, total: int) -> None:
        bar(done, total, stage)

    return update


def parse_checks(text: str | None) -> tuple[str, ...]:
    """``B7,B9`` -> ``("B7", "B9")``; an empty name is bad input."""
    if text is None:
        return ()
    names = tuple(t.strip() for t in text.split(","))
    if any(not n for n in names):
        raise InputError(f"--check: an empty beacon name in {text!r}")
    return names


def parse_band(text: str | None) -> tuple[float, float] | None:
    """``Z0,Z1`` in the cloud's frame, ``Z0 < Z1``."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        z0, z1 = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"--band must be two heights Z0,Z1 in metres, got {text!r}") from None
    if not (math.isfinite(z0) and math.isfinite(z1)):
        raise InputError(f"--band: heights must be finite numbers, got {text!r}")
    if not z0 < z1:
        raise InputError(f"--band: Z0 must be below Z1, got {text!r}")
    return z0, z1
