"""``mast live``: a scanner's stream (SICK, Hokuyo or a replay) located as it comes, the newest
scan first."""

from __future__ import annotations

import contextlib
import math
import signal
import sys
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.options import (
    AngleSigmaOption,
    AzimuthToleranceOption,
    BeaconsOption,
    NearOption,
    RadiusOption,
    RangeMaxOption,
    RangeMinOption,
    RangeSigmaOption,
    ScannerOption,
    SurveySigmaOption,
    check_range_limits,
    parse_near,
    precisions,
    signals_as_flag,
    warn_loose_edges,
)
from mast.cli.root import (
    EXIT_NO_FIX,
    app,
    silence_stdout,
)
from mast.cli.settings import ConfigOption, effective, read_config
from mast.errors import InputError
from mast.io.outputs import check_output_file


@app.command()
def live(
    source: Annotated[
        str,
        typer.Argument(
            metavar="SOURCE",
            help="sick://HOST[:PORT] (CoLa-A, port 2111), hokuyo://HOST[:PORT] (SCIP 2.0, "
            "port 10940) or replay://RUN[?rate=F] (a bag or a folder of scan CSVs).",
        ),
    ],
    beacons: BeaconsOption,
    range_sigma: RangeSigmaOption = None,
    angle_sigma: AngleSigmaOption = None,
    scanner: ScannerOption = None,
    survey_sigma: SurveySigmaOption = None,
    config: ConfigOption = None,
    range_min: RangeMinOption = None,
    range_max: RangeMaxOption = None,
    near: NearOption = None,
    radius: RadiusOption = 10.0,
    azimuth_tolerance: AzimuthToleranceOption = 30.0,
    record: Annotated[
        Path | None,
        typer.Option(
            "--record",
            help="Write the received scans and the poses to this ROS 2 MCAP file (.mcap).",
        ),
    ] = None,
    view: Annotated[
        bool, typer.Option("--view", help="Serve a live view for Foxglove (WebSocket).")
    ] = False,
    view_port: Annotated[
        int, typer.Option("--view-port", min=0, max=65535, help="Port of the --view server.")
    ] = 8765,
    view_host: Annotated[
        str, typer.Option("--view-host", help="Address the --view server listens on.")
    ] = "127.0.0.1",
    timeout: Annotated[
        float,
        typer.Option("--timeout", help="Seconds without a scan before reconnecting."),
    ] = 2.0,
    give_up: Annotated[
        float,
        typer.Option("--give-up", help="Seconds without a scan (or a connection) before ending."),
    ] = 60.0,
    max_scans: Annotated[
        int | None,
        typer.Option("--max-scans", min=1, help="End after this many scans received."),
    ] = None,
) -> None:
    """Locate a scanner's stream as it arrives: one JSON record per located scan on standard
    output, flushed as it is written; the newest scan is located first when locating falls
    behind (the others counted as dropped).

    Ends when the source ends (a replay), after --max-scans, when standard output is closed
    (status 0), on Ctrl-C or SIGTERM (status 130 or 143; a --record file is closed
    complete) or when the scanner cannot be reached (status 2). Exit status 3 when no
    scan was fixed, 4 when an output cannot be written.
    """
    import json

    from mast.io import read_survey
    from mast.live.session import Sink, run_live
    from mast.live.sources import ReplaySource, open_source
    from mast.live.stream import SourceOptions
    from mast.report.record import ReportInputs, survey_weighing

    tables, given = read_config(config, "live")
    cfg, defaults = precisions(
        range_sigma, angle_sigma, scanner, survey_sigma, base=tables["locator"], given=given
    )
    settings = effective({"locator": cfg, "sequence": tables["sequence"]}, "live")
    if near is not None:
        cfg = replace(cfg, prior=parse_near(near, radius, azimuth_tolerance))
    check_range_limits(range_min, range_max)
    for name, value in (("--timeout", timeout), ("--give-up", give_up)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number of seconds, got {value}")
    survey = read_survey(beacons)
    warn_loose_edges(survey, cfg.survey_sigma_m)
    options = SourceOptions(
        range_min_m=range_min, range_max_m=range_max, timeout_s=timeout, give_up_s=give_up
    )
    stream = open_source(source, options)
    if record is not None:
        if record.suffix != ".mcap":
            raise InputError("--record: name the recording *.mcap (lower case)", path=record)
        replayed = [stream.path] if isinstance(stream, ReplaySource) else []
        check_output_file(record, suffixes=(".mcap",), option="--record", inputs=replayed)
    inputs = ReportInputs(
        scan_file=source,
        survey_file=str(beacons),
        scanner=scanner,
        defaults=frozenset(defaults),
        config_file=None if config is None else str(config),
        config_sha256=settings.sha256,
        survey_sigmas=survey_weighing(survey, cfg.survey_sigma_m),
    )

    def warn(text: str) -> None:
        typer.echo(f"mast: warning: {text}", err=True)

    def emit(record_: dict[str, object]) -> None:
        sys.stdout.write(json.dumps(record_) + "\n")
        sys.stdout.flush()

    from mast.cli.warmup import compile_all

    compile_all()  # the first scan is located as fast as the rest
    sinks: list[Sink] = []
    with contextlib.ExitStack() as stack:
        # Ctrl-C and SIGTERM (a vehicle's service manager) only ask the run to end between
        # two scans: never in the middle of writing the recording, nor while closing it
        # (the handlers are restored last, after the recording is closed).
        interrupt, caught = stack.enter_context(signals_as_flag())
        if record is not None:
            from mast.live.record import McapRecorder

            recorder = McapRecorder(record)
            stack.callback(recorder.close)
            sinks.append(recorder)
        if view:
            from mast.live.view import LiveView

            try:
                viewer = LiveView(survey, host=view_host, port=view_port)
            except Exception as err:  # foxglove raises its own kinds for a port in use
                raise InputError(
                    f"--view: cannot serve on {view_host}:{view_port}: {err}"
                ) from None
            stack.callback(viewer.close)
            sinks.append(viewer)
            warn(f"live view for Foxglove on ws://{view_host}:{viewer.port}")
        summary = run_live(
            stream,
            survey,
            emit=emit,
            config=cfg,
            sequence=tables["sequence"],
            inputs=inputs,
            sinks=tuple(sinks),
            max_scans=max_scans,
            warn=warn,
            interrupt=interrupt,
        )
    typer.echo(
        f"mast: {source}: {summary.received} scans received, {summary.located} located, "
        f"{summary.fixed} fixed, {summary.dropped} dropped"
        + (f", {summary.malformed} malformed skipped" if summary.malformed else "")
        + (f", {summary.reconnects} reconnections" if summary.reconnects else "")
        + f" in {summary.elapsed_s:.1f} s",
        err=True,
    )
    if summary.pipe_closed:
        silence_stdout()
        return
    if summary.interrupted:
        typer.echo(
            "mast: interrupted" + (f"; {record} holds the scans received" if record else ""),
            err=True,
        )
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if summary.fixed == 0:
        raise typer.Exit(EXIT_NO_FIX)
