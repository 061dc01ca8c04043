"""``mast locate``: each scan's fix (or why there is none) as a survey report or JSON."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from mast.cli.options import (
    AngleSigmaDegOption,
    AngleSigmaOption,
    AzimuthToleranceOption,
    BeaconsOption,
    CrsOption,
    NearOption,
    OutputFormat,
    RadiusOption,
    RangeMaxOption,
    RangeMinOption,
    RangeSigmaOption,
    ScannerOption,
    SurveySigmaOption,
    TopicOption,
    WorkUpdate,
    grid_crs,
    lidar_config,
    load_scans,
    parse_near,
    warn_loose_edges,
    work_progress,
)
from mast.cli.root import (
    EXIT_NO_FIX,
    app,
)
from mast.cli.settings import ConfigOption, effective, locator_settings, report_inputs
from mast.core.heap import QuietCollector
from mast.errors import InputError
from mast.io.outputs import PLOT_SUFFIXES, check_output_file

if TYPE_CHECKING:
    from mast.core.beacon import Survey
    from mast.pipeline.locator import LocatorConfig
    from mast.report.record import ReportInputs


@app.command()
def locate(
    scan_paths: Annotated[
        list[Path],
        typer.Argument(
            metavar="SCAN...",
            help="Scan CSVs, ROS 1 bags, ROS 2 bag folders or MCAP files (LaserScan, or a 3D "
            "lidar's PointCloud2); '-' reads a scan CSV from standard input.",
        ),
    ],
    beacons: BeaconsOption,
    range_sigma: RangeSigmaOption = None,
    angle_sigma_deg: AngleSigmaDegOption = None,
    scanner: ScannerOption = None,
    fmt: Annotated[
        OutputFormat,
        typer.Option("--format", help="text report, or JSON Lines (one record per scan)."),
    ] = OutputFormat.text,
    plot: Annotated[
        Path | None,
        typer.Option(
            "--plot",
            help="Write the paper's Figure 3 for the scan (.png, .pdf, .svg ...); numbered "
            "per scan when there are several. A missing folder is created.",
        ),
    ] = None,
    topic: TopicOption = None,
    range_min: RangeMinOption = None,
    range_max: RangeMaxOption = None,
    near: NearOption = None,
    radius: RadiusOption = 10.0,
    azimuth_tolerance: AzimuthToleranceOption = 30.0,
    survey_sigma: SurveySigmaOption = None,
    config: ConfigOption = None,
    crs: CrsOption = None,
    angle_sigma: AngleSigmaOption = None,
) -> None:
    """Fix position and azimuth from one scan, several, or every scan of a bag.

    --crs names the grid in each JSON record (its crs object) and in the report.

    A bag topic of sensor_msgs/PointCloud2 (a 3D lidar: --topic, or a bag's only
    topic) is located in six degrees of freedom, frame by frame: each record adds the
    elevation, roll, pitch and their sigmas (docs/3d.md); the survey must give the
    edges' elevations. --near and --plot apply to 2D scans only.

    Exit status 0 when a scan is fixed (with several scans or a bag: at least
    one), 3 when none is, 2 for bad input, 4 when an output cannot be written.
    Scans refused in a way a setting explains end with a one-line hint on stderr
    (a range sigma below the returns' scatter; a survey with easting and northing
    exchanged).

    \b
    Example: mast locate examples/scan.csv -b examples/beacons.csv --scanner lms1xx-0.25
    """
    import json

    from mast.io import read_survey
    from mast.live.sources import cloud_topic
    from mast.pipeline.locator import SequenceLocator
    from mast.report.hints import Hints
    from mast.report.record import fix_record, fix_text

    tables, cfg, defaults = locator_settings(
        "locate",
        config,
        (range_sigma, angle_sigma, scanner, survey_sigma),
        angle_sigma_deg=angle_sigma_deg,
    )
    settings = effective({"locator": cfg, "sequence": tables["sequence"]}, "locate")
    if near is not None:
        cfg = replace(cfg, prior=parse_near(near, radius, azimuth_tolerance))
    grid = grid_crs(crs)
    if scan_paths.count(Path("-")) > 1:
        raise InputError("standard input ('-') can be read only once")
    if plot is not None:
        check_output_file(plot, suffixes=PLOT_SUFFIXES, inputs=[*scan_paths, beacons])
    survey = read_survey(beacons)
    warn_loose_edges(survey, cfg.survey_sigma_m)
    numbered = len(scan_paths) > 1
    fixed = located = 0
    hints = Hints(survey, cfg)
    # What is alive once a scan is located is frozen, out of the collector's full
    # passes over it (mast.core.heap): they were a run's slowest scans.
    with QuietCollector() as heap, work_progress("locating") as bar:
        total = _scan_total(scan_paths, topic) if bar is not None else None
        for scan_path in scan_paths:
            clouds = None if scan_path == Path("-") else cloud_topic(scan_path, topic)
            if clouds is not None:
                located, fixed = _locate_frames(
                    scan_path,
                    clouds,
                    fmt=fmt,
                    located=located,
                    fixed=fixed,
                    survey=survey,
                    beacons=beacons,
                    cfg=cfg,
                    defaults=defaults,
                    inputs=report_inputs(
                        beacons=beacons,
                        survey=survey,
                        locator=lidar_config(cfg, defaults),
                        scanner=scanner,
                        defaults=defaults,
                        config=config,
                        settings=effective(
                            {
                                "locator": lidar_config(cfg, defaults),
                                "sequence": tables["sequence"],
                            },
                            "locate",
                        ),
                        crs=grid,
                        scan_file=str(scan_path),
                        topic=clouds,
                    ),
                    ignored=[
                        o
                        for o, v in (
                            ("--near", near),
                            ("--plot", plot),
                            ("--range-min", range_min),
                            ("--range-max", range_max),
                        )
                        if v is not None
                    ],
                    bar=bar,
                )
                numbered = True
                continue
            scans, many, scan_topic = load_scans(
                scan_path, topic=topic, range_min=range_min, range_max=range_max
            )
            numbered = numbered or many
            inputs = report_inputs(
                beacons=beacons,
                survey=survey,
                locator=cfg,
                scanner=scanner,
                defaults=defaults,
                config=config,
                settings=settings,
                crs=grid,
                scan_file="<stdin>" if scan_path == Path("-") else str(scan_path),
                topic=scan_topic,
            )
            source = inputs.scan_file or str(scan_path)
            tracker = SequenceLocator(survey, config=cfg, sequence=tables["sequence"])
            for i, scan in enumerate(heap.each(scans)):
                step = tracker.step(scan)
                fix = step.fix
                fixed += fix.ok
                hints.add(scan, fix)
                label = f"{source}#{i}" if many else source
                if fmt is OutputFormat.json:
                    record = fix_record(
                        fix, source=source, index=i if many else None, scan=scan, inputs=inputs
                    )
                    if many:
                        record.update(tracking=step.tracked, track_lost=step.track_lost)
                    typer.echo(json.dumps(record))
                else:
                    if located:
                        typer.echo("")
                    typer.echo(fix_text(fix, source=label, scan=scan, inputs=inputs))
                if plot is not None:
                    from mast.report.plot import plot_fix

                    target = plot.with_name(f"{plot.stem}_{located:04d}{plot.suffix}")
                    plot_fix(scan, survey, fix, target if numbered else plot, title=label)
                located += 1
                if bar is not None and total != 1:
                    bar(located, total, f"{fixed} fixed")
    for line in hints.lines():
        typer.echo(f"mast: {line}", err=True)
    if fixed == 0:
        raise typer.Exit(EXIT_NO_FIX)


def _locate_frames(
    path: Path,
    topic: str,
    *,
    fmt: OutputFormat,
    located: int,
    fixed: int,
    survey: Survey,
    beacons: Path,
    cfg: LocatorConfig,
    defaults: set[str],
    inputs: ReportInputs,
    ignored: list[str],
    bar: WorkUpdate | None,
) -> tuple[int, int]:
    """Every PointCloud2 frame of ``topic`` located in 3D (:mod:`mast.runs.frames3d`),
    one record or report each; the counts of frames located and fixed, carried on."""
    import json

    from mast.io.pointclouds import pointcloud_count, read_pointclouds
    from mast.report.record import fix3d_text
    from mast.runs.frames3d import FrameLocator, check_elevations

    check_elevations(survey, beacons)
    for option in ignored:
        typer.echo(f"mast: warning: {option} applies to 2D scans; {path} is 3D frames", err=True)
    locator = FrameLocator(
        survey,
        range_sigma_m=lidar_config(cfg, defaults).range_sigma_m,
        survey_sigma_m=cfg.survey_sigma_m,
    )
    total = pointcloud_count(path, topic) if bar is not None else None
    source = str(path)
    for i, frame in enumerate(read_pointclouds(path, topic)):
        fix = locator.locate(frame)
        fixed += fix.ok
        if fmt is OutputFormat.json:
            record = locator.record(fix, source=source, index=i, frame=frame, inputs=inputs)
            typer.echo(json.dumps(record))
        else:
            if located:
                typer.echo("")
            typer.echo(
                fix3d_text(
                    fix,
                    source=f"{source}#{i}",
                    frame=frame,
                    inputs=inputs,
                    range_sigma_m=locator.config.range_sigma_m,
                    survey_sigma_m=locator.config.survey_sigma_m,
                )
            )
        located += 1
        if bar is not None:
            bar(i + 1, total, f"{fixed} fixed")
    return located, fixed


def _scan_total(paths: list[Path], topic: str | None) -> int | None:
    """The scans the paths hold (a bag's from its index, a folder's files, one a CSV or
    standard input), for the progress bar; None when one of them does not say (a path
    that is no scan file is the reading's error to report, in its turn)."""
    from mast.io.scans import scan_count

    total = 0
    for path in paths:
        try:
            n = 1 if path == Path("-") else scan_count(path, topic=topic)
        except InputError:
            n = None
        if n is None:
            return None
        total += n
    return total
