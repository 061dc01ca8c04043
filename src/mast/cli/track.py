"""``mast track``: a survey run (or a folder of runs) placed scan by scan: trajectory, map and
report."""

from __future__ import annotations

import signal
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from mast.cli.options import (
    AngleSigmaDegOption,
    AngleSigmaOption,
    BeaconsOption,
    CrsOption,
    ForceOption,
    RangeMaxOption,
    RangeMinOption,
    RangeSigmaOption,
    ScannerOption,
    SurveySigmaOption,
    TopicOption,
    check_range_limits,
    grid_crs,
    run_progress,
    signals_as_flag,
    warn_loose_edges,
)
from mast.cli.root import (
    EXIT_BAD_INPUT,
    EXIT_NO_FIX,
    app,
)
from mast.cli.settings import ConfigOption, effective, locator_settings, report_inputs
from mast.errors import InputError, shorten
from mast.io.outputs import check_output_folder

if TYPE_CHECKING:
    from mast.core.beacon import Survey
    from mast.pipeline.locator import LocatorConfig
    from mast.report.record import ReportInputs


@app.command()
def track(
    runs: Annotated[
        list[Path],
        typer.Argument(
            metavar="RUN...",
            help="ROS 1 bags, ROS 2 bag folders (sqlite3, MCAP), folders of scan CSVs, or "
            "folders holding bags.",
        ),
    ],
    beacons: BeaconsOption,
    out: Annotated[
        Path, typer.Option("--out", help="Folder for the run's files (created if missing).")
    ],
    topic: TopicOption = None,
    range_sigma: RangeSigmaOption = None,
    angle_sigma_deg: AngleSigmaDegOption = None,
    scanner: ScannerOption = None,
    survey_sigma: SurveySigmaOption = None,
    config: ConfigOption = None,
    range_min: RangeMinOption = None,
    range_max: RangeMaxOption = None,
    max_gap: Annotated[
        float | None,
        typer.Option(
            "--max-gap",
            min=0.0,
            help="Scans further apart in time, seconds, are not chained by odometry "
            "(a log kept a scan every metre or two: give its spacing; each such step is "
            "then matched over all the vehicle could have done, and slower) [default: 0.5].",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="With several runs: address of a Dask scheduler to run them on "
            "[default: a local cluster].",
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option("--workers", min=1, help="Processes of the local cluster [default: cores]."),
    ] = None,
    crs: CrsOption = None,
    force: ForceOption = False,
    angle_sigma: AngleSigmaOption = None,
) -> None:
    """Place every scan of a run in the mine grid: fixes from beacons, odometry between
    them, smoothed in a pose graph; writes fixes.jsonl, trajectory.csv and .tum, map.las,
    map.dxf, report.html, fixes.geojson, trajectory.geojson and fixes_points.csv into
    --out; --crs names the grid in the records, the map, the GeoJSON and the report.

    Several runs (or a folder of them) are tracked in parallel on Dask, one run per
    task, each into --out/<run name>/, with --out/index.csv listing them.

    A run's PointCloud2 topic (a 3D lidar) is tracked in six degrees of freedom, each
    frame fixed on its own (no odometry or smoothing in 3D: only the frames fixed are
    placed): fixes.jsonl with the 3D records, trajectory.csv with the elevation, roll
    and pitch, trajectory.tum with the elevation as z and the full quaternion, map.las
    with real z, fixes.geojson and fixes_points.csv (docs/3d.md).

    Exit status 0 when scans were placed (in every run), 3 when none could be, 2 for bad
    input, 4 when an output cannot be written, 130 when interrupted (the files then hold
    the scans read until then).

    \b
    Example: mast track examples/run.bag -b examples/beacons.csv --scanner lms1xx-0.25 --out run/
    """
    from mast.cli.options import lidar_config
    from mast.io import read_survey
    from mast.live.sources import cloud_topic
    from mast.runs.batch import expand_runs, track_runs
    from mast.runs.frames3d import check_elevations
    from mast.runs.run import track_run

    tables, cfg, defaults = locator_settings(
        "track",
        config,
        (range_sigma, angle_sigma, scanner, survey_sigma),
        angle_sigma_deg=angle_sigma_deg,
    )
    run_config = replace(
        tables["track"],
        locator=cfg,
        **({} if max_gap is None else {"max_gap_s": max_gap}),
    )
    settings = effective({"locator": cfg, "track": run_config}, "track")
    check_range_limits(range_min, range_max)
    grid = grid_crs(crs)
    for given in runs:
        if not given.exists():
            raise InputError("run not found", path=given)
    found = expand_runs(runs)
    check_output_folder(out, force=force)
    survey = read_survey(beacons)
    warn_loose_edges(survey, cfg.survey_sigma_m)
    clouds = cloud_topic(found[0], topic) if len(found) == 1 and scheduler is None else None
    if clouds is not None:  # a 3D lidar's frames: its settings are what config.toml holds
        check_elevations(survey, beacons)
        cfg = lidar_config(cfg, defaults)
        run_config = replace(run_config, locator=cfg)
        settings = effective({"locator": cfg, "track": run_config}, "track")
    if len(found) > 1 or scheduler is not None:
        three_d = [r for r in found if cloud_topic(r, topic) is not None]
        if three_d:
            raise InputError(
                "3D lidar runs (PointCloud2) are tracked one at a time, without --scheduler",
                path=three_d[0],
            )
    settings.write(out / "config.toml")  # once the inputs are read: a refused run leaves nothing
    inputs = report_inputs(
        beacons=beacons,
        survey=survey,
        locator=cfg,
        scanner=scanner,
        defaults=defaults,
        config=config,
        settings=settings,
        crs=grid,
    )
    if len(found) > 1 or scheduler is not None:
        outcomes = track_runs(
            found,
            beacons,
            out,
            options={
                "config": run_config,
                "topic": topic,
                "inputs": inputs,
            },
            scheduler=scheduler,
            workers=workers,
            echo=typer.echo,
        )
        typer.echo(f"{len(outcomes)} runs; index in {out / 'index.csv'}")
        if any(o.status == "error" for o in outcomes):
            raise typer.Exit(EXIT_BAD_INPUT)
        if not all(o.placed for o in outcomes):
            raise typer.Exit(EXIT_NO_FIX)
        return
    (run,) = found
    inputs = replace(inputs, scan_file=str(run))
    if clouds is not None:  # a 3D lidar's PointCloud2 topic
        for option, value in (("--range-min", range_min), ("--range-max", range_max)):
            if value is not None:
                typer.echo(
                    f"mast: warning: {option} applies to 2D scans; {run} is 3D frames", err=True
                )
        _track_frames(run, survey, out, clouds, inputs, cfg)
        return

    def warn(text: str) -> None:
        typer.echo(f"mast: warning: {shorten(text, 80)}", err=True)

    with signals_as_flag() as (interrupt, caught), run_progress(f"tracking {run.name}") as progress:
        result = track_run(
            run,
            survey,
            out,
            config=run_config,
            topic=topic,
            inputs=inputs,
            range_limits=(range_min, range_max),
            warn=warn,
            progress=progress,
            interrupt=interrupt,
        )
    s = result.summary
    typer.echo(
        f"{run}: {s.scans} scans, {s.fixes} fixed, {s.placed} placed"
        + (f", {s.skipped} messages skipped" if s.skipped else "")
        + (f", {s.coasted} carried at constant velocity" if s.coasted else "")
        + f" in {s.elapsed_s:.1f} s ({s.scans / max(s.elapsed_s, 1e-9):.0f} scans/s); "
        f"files in {out}"
    )
    for line in result.hints:
        typer.echo(f"mast: {line}", err=True)
    if s.gaps > s.scans // 2:
        typer.echo(
            f"mast: hint: {s.gaps} of {s.scans} scans came more than "
            f"{run_config.max_gap_s:g} s after the scan before and were not chained by "
            "odometry; if the log keeps a scan only every metre or so, give --max-gap its "
            "spacing",
            err=True,
        )
    if result.interrupted:
        typer.echo("mast: interrupted; the files hold the scans read until then", err=True)
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if s.placed == 0:
        raise typer.Exit(EXIT_NO_FIX)


def _track_frames(
    run: Path,
    survey: Survey,
    out: Path,
    topic: str,
    inputs: ReportInputs,
    cfg: LocatorConfig,
) -> None:
    """A 3D lidar's run (:func:`mast.runs.frames3d.track_run3d`), its summary and exit
    status as a 2D run's."""
    from mast.runs.frames3d import PER_FRAME_NOTE, FrameLocator, track_run3d

    locator = FrameLocator(
        survey,
        range_sigma_m=cfg.range_sigma_m,
        survey_sigma_m=cfg.survey_sigma_m,
    )

    def warn(text: str) -> None:
        typer.echo(f"mast: warning: {shorten(text, 80)}", err=True)

    with signals_as_flag() as (interrupt, caught), run_progress(f"tracking {run.name}") as progress:
        result = track_run3d(
            run,
            survey,
            out,
            locator=locator,
            topic=topic,
            inputs=replace(inputs, topic=topic),
            warn=warn,
            progress=progress,
            interrupt=interrupt,
        )
    s = result.summary
    typer.echo(
        f"{run}: {s.scans} 3D frames, {s.fixes} fixed, {s.placed} placed"
        + (f", {s.skipped} messages skipped" if s.skipped else "")
        + f" in {s.elapsed_s:.1f} s ({s.scans / max(s.elapsed_s, 1e-9):.1f} frames/s); "
        f"{PER_FRAME_NOTE}; files in {out}"
    )
    if result.interrupted:
        typer.echo("mast: interrupted; the files hold the frames read until then", err=True)
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if s.placed == 0:
        raise typer.Exit(EXIT_NO_FIX)
