"""``mast locate``: each scan's fix (or why there is none) as a survey report or JSON."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

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
    grid_crs,
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


@app.command()
def locate(
    scan_paths: Annotated[
        list[Path],
        typer.Argument(
            metavar="SCAN...",
            help="Scan CSVs, ROS 1 bags or ROS 2 bag folders; '-' reads a scan CSV from "
            "standard input.",
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
