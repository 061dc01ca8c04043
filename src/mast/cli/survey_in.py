"""``mast survey-in``: beacon edges from terrestrial laser scans already in the mine grid."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from mast.cli.options import CrsOption, ForceOption, grid_crs, work_progress
from mast.cli.root import EXIT_NO_FIX, app
from mast.errors import InputError
from mast.io.outputs import check_output_folder


@app.command("survey-in")
def survey_in(
    clouds: Annotated[
        list[Path],
        typer.Argument(
            metavar="CLOUD...",
            help="Terrestrial scans in the mine grid: E57 (several scans with their poses), "
            "LAS, LAZ or PLY; z up, metres.",
        ),
    ],
    designs: Annotated[
        Path,
        typer.Option(
            "--designs",
            help="The designs bolted up: the survey contract, one beacon per design in any "
            "frame, its id the design's name.",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", help="Folder for the outputs (created).")],
    previous: Annotated[
        Path | None,
        typer.Option(
            "--previous",
            help="An earlier survey: a beacon found within 0.5 m of one of its beacons of "
            "the same design keeps that id, and each edge is tested for movement.",
        ),
    ] = None,
    noise: Annotated[
        float,
        typer.Option("--noise", help="The scanner's range noise, metres (1-2 mm phase-based)."),
    ] = 0.002,
    station_sigma: Annotated[
        float,
        typer.Option(
            "--station-sigma",
            help="Standard deviation of a station's setup per horizontal coordinate, "
            "metres, added to every edge's sigma_m.",
        ),
    ] = 0.001,
    crs: CrsOption = None,
    force: ForceOption = False,
) -> None:
    """Survey beacons in from terrestrial laser scans already in the mine grid: each
    beacon's design found, its four edges and top fitted from its panels' points.

    Writes into --out: beacons.csv (the survey contract with elevation, sigma_m and
    design), report.txt and report.html; --crs names the grid in the reports.

    Exit status 0 with beacons surveyed, 3 when no beacon is found, 2 for bad input, 4
    when an output cannot be written.

    \b
    Example: mast simulate --scenario tls --out tls && \\
      mast survey-in tls/scans.e57 --designs tls/designs.csv --out tls-survey
    """
    from mast.cloud.survey_in import SurveyInConfig
    from mast.cloud.survey_in import survey_in as run
    from mast.cloud.survey_in_outputs import write_survey_in
    from mast.io import read_survey

    try:
        config = SurveyInConfig(noise_m=noise, station_sigma_m=station_sigma)
    except ValueError as err:
        raise InputError(str(err).replace("noise_m", "--noise", 1).replace(
            "station_sigma_m", "--station-sigma", 1)) from None  # fmt: skip
    grid = grid_crs(crs)
    the_designs = read_survey(designs, apart=False)
    before = read_survey(previous) if previous is not None else None
    check_output_folder(out, force=force)
    with work_progress("survey-in", counts=False) as bar:
        result = run(
            clouds,
            the_designs,
            config,
            previous=before,
            progress=None if bar is None else lambda stage, done, total: bar(done, total, stage),
        )
    files = write_survey_in(result, out, clouds=clouds, designs_file=designs, crs=grid)
    edge_on = len(result.edge_on)
    typer.echo(
        f"{len(result.beacons)} beacon(s) surveyed in, {result.partial} seen in part"
        + (f", {edge_on} refused with a middle panel seen edge-on" if edge_on else "")
        + f"; report in {files.report_txt}"
    )
    for f in result.beacons:
        b = f.beacon
        worst = 1000 * float(max(b.edge_sigmas_m)) if b.edge_sigmas_m is not None else 0.0
        moved = [k + 1 for k, m in enumerate(f.moved) if m]
        note = f"; MOVED at edge(s) {', '.join(map(str, moved))}" if moved else ""
        if any(m is None for m in f.moved):
            note += "; movement untested (the previous survey gives no sigma_m)"
        typer.echo(f"  {b.id} ({b.design}): edges to {worst:.2f} mm{note}")
    if not result.beacons:
        typer.echo("mast: no beacon found in the scans", err=True)
        raise typer.Exit(EXIT_NO_FIX)
