"""``mast plan``: where a drift's scans will fix, and where more beacons would help."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.options import (
    AngleSigmaDegOption,
    AngleSigmaOption,
    BeaconsOption,
    CrsOption,
    ForceOption,
    RangeSigmaOption,
    SurveySigmaOption,
    angle_sigma_rad,
    cell_progress,
    grid_crs,
    renamed,
)
from mast.cli.root import (
    app,
)
from mast.errors import InputError
from mast.io.outputs import check_output_folder


@app.command()
def plan(
    beacons: BeaconsOption,
    out: Annotated[
        Path, typer.Option("--out", help="Folder for the outputs (created if missing).")
    ],
    walls: Annotated[
        Path | None,
        typer.Option(
            "--walls",
            help="The drift's walls: a CSV wall,vertex,easting,northing or a DXF of polylines "
            "[required].",
        ),
    ] = None,
    scanner: Annotated[
        str | None,
        typer.Option("--scanner", help="Named scanner model (see mast scanners)."),
    ] = None,
    fov: Annotated[
        float | None,
        typer.Option("--fov", help="Field of view, degrees [default: the --scanner's]."),
    ] = None,
    resolution: Annotated[
        float | None,
        typer.Option("--resolution", help="Beam spacing, degrees [default: the --scanner's]."),
    ] = None,
    range_sigma: RangeSigmaOption = None,
    angle_sigma_deg: AngleSigmaDegOption = None,
    range_max: Annotated[
        float | None,
        typer.Option(
            "--range-max", help="Longest range, metres [default: the --scanner's, or 30]."
        ),
    ] = None,
    step: Annotated[
        float, typer.Option("--step", help="Cell spacing along the centreline, metres.")
    ] = 2.0,
    across: Annotated[
        float | None,
        typer.Option("--across", help="Cell spacing across the drift, metres [default: --step]."),
    ] = None,
    margin: Annotated[
        float, typer.Option("--margin", help="No cell closer than this to a wall, metres.")
    ] = 0.5,
    scans_per_cell: Annotated[
        int,
        typer.Option(
            "--scans-per-cell", min=1, max=1000, help="Noisy scans located per cell and heading."
        ),
    ] = 3,
    min_fix_rate: Annotated[
        float,
        typer.Option(
            "--min-fix-rate", help="Share of a cell's scans that must fix for it to count."
        ),
    ] = 0.5,
    target_sigma: Annotated[
        float | None,
        typer.Option(
            "--target-sigma",
            help="Position sigma a covered cell must meet too, metres "
            "(Cramér–Rao, semi-major axis).",
        ),
    ] = None,
    suggest: Annotated[
        int,
        typer.Option(
            "--suggest", min=0, max=100, help="Propose up to N new beacons (proposed_beacons.csv)."
        ),
    ] = 0,
    candidate_step: Annotated[
        float | None,
        typer.Option(
            "--candidate-step",
            help="With --suggest: spacing of candidate positions on the walls [default: --step].",
        ),
    ] = None,
    roughness: Annotated[
        float,
        typer.Option("--roughness", help="Peak rock texture added to the walls, metres (0: none)."),
    ] = 0.03,
    survey_sigma: SurveySigmaOption = None,
    layer: Annotated[
        list[str] | None,
        typer.Option("--layer", help="DXF drift: read walls from this layer only (repeatable)."),
    ] = None,
    seed: Annotated[
        int, typer.Option("--seed", help="Seed of the noise and the rock texture.")
    ] = 0,
    dry_run: Annotated[
        bool,
        typer.Option(
            "--dry-run",
            help="Only read and check the walls and the survey, and say how large "
            "the job is; write nothing.",
        ),
    ] = False,
    crs: CrsOption = None,
    force: ForceOption = False,
    old_drift: Annotated[
        Path | None, typer.Option("--drift", hidden=True, help="Old name of --walls.")
    ] = None,
    old_check: Annotated[
        bool, typer.Option("--check", hidden=True, help="Old name of --dry-run.")
    ] = False,
    angle_sigma: AngleSigmaOption = None,
) -> None:
    """Predict where along a drift a scanner gets a fix, how precise, and where beacons help.

    Writes plan.csv (one row per cell and heading), plan.png, plan.dxf and
    summary.json into --out; with --suggest also proposed_beacons.csv (the
    survey with the new beacons, for mast plan and mast locate); --crs names the grid
    in summary.json.
    Exit status 0, 2 for bad input, 4 when an output cannot be written.

    \b
    Example: mast plan --walls examples/plan/drift.csv -b examples/plan/beacons.csv \\
      --scanner lms1xx-0.25 --out plan/
    """
    from mast.io import read_survey
    from mast.plan.predict import PlanSettings
    from mast.plan.run import run_plan
    from mast.sim.scanner import scanner_for

    drift = renamed(walls, old_drift, new="--walls", old="--drift")
    if drift is None:
        raise InputError("give the drift's walls with --walls (a CSV or a DXF)")
    check = bool(renamed(dry_run or None, old_check or None, new="--dry-run", old="--check"))
    for name, value in (
        ("--step", step),
        ("--across", across),
        ("--candidate-step", candidate_step),
    ):
        if value is not None and not (math.isfinite(value) and value >= 0.1):
            raise InputError(f"{name} must be at least 0.1 m, got {value:g}")
    if not 0.0 < min_fix_rate <= 1.0:
        raise InputError(f"--min-fix-rate must be in (0, 1], got {min_fix_rate:g}")
    if suggest and target_sigma is None:
        typer.echo(
            "mast: note: --suggest without --target-sigma improves availability only", err=True
        )
    model = scanner_for(
        scanner,
        fov_deg=fov,
        resolution_deg=resolution,
        range_sigma_m=range_sigma,
        range_max_m=range_max,
        angle_sigma_rad=angle_sigma_rad(angle_sigma_deg, angle_sigma),
    )
    settings = PlanSettings(
        step_m=step,
        across_m=across,
        margin_m=margin,
        scans_per_cell=scans_per_cell,
        min_fix_rate=min_fix_rate,
        target_sigma_m=target_sigma,
        roughness_m=roughness,
        seed=seed,
        **({} if survey_sigma is None else {"survey_sigma_m": survey_sigma}),
    )
    grid = grid_crs(crs)
    survey = read_survey(beacons)
    if check:
        from mast.io.drift import read_drift

        outline = read_drift(drift, layers=tuple(layer or ()))
        along = outline.length_m / 2  # two walls to a drift
        stations = math.ceil(along / settings.step_m) + 1
        typer.echo(
            f"{drift}: {len(outline.walls)} walls, {outline.length_m:.0f} m of wall (about "
            f"{along:.0f} m of drift, {stations} stations); {beacons}: {len(survey)} beacons"
        )
        return
    check_output_folder(out, force=force)
    with cell_progress("plan") as update:
        result = run_plan(
            drift,
            survey,
            model,
            settings,
            out,
            layers=tuple(layer or ()),
            suggest_count=suggest,
            candidate_step_m=candidate_step,
            progress=update,
            echo=lambda text: typer.echo(text, err=True),
            crs=grid,
        )
    f = result.figures
    worst = "none" if f["worst_sigma_m"] is None else f"{1000 * f['worst_sigma_m']:.1f} mm"
    line = (
        f"covered {100 * f['covered_share']:.1f} % of {f['centreline_length_m']:.0f} m of "
        f"centreline (both headings), longest gap {f['longest_gap_m']:.0f} m, worst sigma {worst}"
    )
    if "before" in f:
        b = f["before"]
        line += (
            f"; before the {len(f['proposed_beacons'])} proposed beacon(s): "
            f"{100 * b['covered_share']:.1f} %, gap {b['longest_gap_m']:.0f} m"
        )
    typer.echo(line)
    typer.echo("wrote " + ", ".join(str(p) for p in result.written))
