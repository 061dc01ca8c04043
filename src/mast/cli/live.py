"""``mast live``: a scanner's stream (SICK, Hokuyo or a replay) located as it comes, the newest
scan first."""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from mast.cli.options import (
    AngleSigmaDegOption,
    AngleSigmaOption,
    AzimuthToleranceOption,
    BeaconsOption,
    CrsOption,
    NearOption,
    RadiusOption,
    RangeMaxOption,
    RangeMinOption,
    RangeSigmaOption,
    ScannerOption,
    SurveySigmaOption,
    check_range_limits,
    check_seconds,
    grid_crs,
    parse_near,
    signals_as_flag,
    warn_loose_edges,
)
from mast.cli.root import (
    EXIT_NO_FIX,
    app,
    silence_stdout,
)
from mast.cli.settings import ConfigOption, effective, locator_settings, report_inputs
from mast.errors import InputError
from mast.io.outputs import check_output_file

if TYPE_CHECKING:
    from mast.core.beacon import Survey
    from mast.core.pose3d import Frame3D
    from mast.live.session import Sink
    from mast.live.sources import FrameReplaySource
    from mast.live.stream import Source
    from mast.pipeline.locator import LocatorConfig, SequenceConfig
    from mast.pipeline.locator3d import Fix3D
    from mast.report.record import ReportInputs


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
    angle_sigma_deg: AngleSigmaDegOption = None,
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
    crs: CrsOption = None,
    angle_sigma: AngleSigmaOption = None,
) -> None:
    """Locate a scanner's stream as it arrives: one JSON record per located scan on standard
    output, flushed as it is written; the newest scan is located first when locating falls
    behind (the others counted as dropped).

    A replay of a bag's PointCloud2 topic (replay://RUN?topic=/points) locates a 3D
    lidar's frames in six degrees of freedom, each on its own, with the 3D record
    (docs/3d.md); the survey must give the edges' elevations.

    Ends when the source ends (a replay), after --max-scans, when standard output is closed
    (status 0), on Ctrl-C or SIGTERM (status 130 or 143; a --record file is closed
    complete) or when the scanner cannot be reached (status 2). Exit status 3 when no
    scan was fixed, 4 when an output cannot be written.

    \b
    Example: mast live "replay://examples/run.bag?rate=2" -b examples/beacons.csv \\
      --scanner lms1xx-0.25
    """
    from mast.live.sources import ReplaySource, open_frame_source, open_source
    from mast.live.stream import SourceOptions

    setup = stream_setup(
        "live",
        source,
        beacons,
        config=config,
        precision=(range_sigma, angle_sigma, scanner, survey_sigma),
        angle_sigma_deg=angle_sigma_deg,
        near=(near, radius, azimuth_tolerance),
        range_limits=(range_min, range_max),
        crs=crs,
    )
    check_seconds("--timeout", timeout)
    check_seconds("--give-up", give_up)
    options = SourceOptions(
        range_min_m=range_min, range_max_m=range_max, timeout_s=timeout, give_up_s=give_up
    )
    frames = open_frame_source(source)
    if frames is not None:  # a replayed PointCloud2 topic: a 3D lidar's frames
        for option, given in (("--record", record is not None), ("--view", view)):
            if given:
                raise InputError(f"{option} takes 2D scans; {source} replays 3D lidar frames")
        run_frames(setup, frames, beacons, max_scans=max_scans, near=near)
        return
    stream = open_source(source, options)
    if record is not None:
        if record.suffix != ".mcap":
            raise InputError("--record: name the recording *.mcap (lower case)", path=record)
        replayed = [stream.path] if isinstance(stream, ReplaySource) else []
        check_output_file(record, suffixes=(".mcap",), option="--record", inputs=replayed)

    def open_sinks(stack: contextlib.ExitStack[bool | None]) -> list[Sink]:
        sinks: list[Sink] = []
        if record is not None:
            from mast.live.record import McapRecorder

            recorder = McapRecorder(record)
            stack.callback(recorder.close)
            sinks.append(recorder)
        if view:
            from mast.live.view import LiveView

            try:
                viewer = LiveView(setup.survey, host=view_host, port=view_port)
            except Exception as err:  # foxglove raises its own kinds for a port in use
                raise InputError(
                    f"--view: cannot serve on {view_host}:{view_port}: {err}"
                ) from None
            stack.callback(viewer.close)
            sinks.append(viewer)
            _warn(f"live view for Foxglove on ws://{view_host}:{viewer.port}")
        return sinks

    run_stream(
        setup,
        stream,
        open_sinks,
        max_scans=max_scans,
        interrupted=f"; {record} holds the scans received" if record else "",
    )


@dataclass(frozen=True, slots=True)
class StreamSetup:
    """What a command that locates a stream (``live``, ``ros2``) was asked for."""

    source: str
    survey: Survey
    config: LocatorConfig
    sequence: SequenceConfig
    inputs: ReportInputs


def stream_setup(
    command: str,
    source: str,
    beacons: Path,
    *,
    config: Path | None,
    precision: tuple[float | None, float | None, str | None, float | None],
    near: tuple[str | None, float, float],
    range_limits: tuple[float | None, float | None],
    crs: str | None = None,
    angle_sigma_deg: float | None = None,
) -> StreamSetup:
    """The locator's settings (the config file's, then the options'), the survey and the
    report's inputs of a stream command; bad options are InputErrors. ``precision``'s
    angle sigma is the old ``--angle-sigma`` (radians), ``angle_sigma_deg`` the
    ``--angle-sigma-deg`` that replaces it (:func:`mast.cli.options.angle_sigma_rad`)."""
    from mast.io import read_survey

    tables, cfg, defaults = locator_settings(
        command, config, precision, angle_sigma_deg=angle_sigma_deg
    )
    settings = effective({"locator": cfg, "sequence": tables["sequence"]}, command)
    near_text, radius, azimuth_tolerance = near
    if near_text is not None:
        cfg = replace(cfg, prior=parse_near(near_text, radius, azimuth_tolerance))
    check_range_limits(*range_limits)
    grid = grid_crs(crs)
    survey = read_survey(beacons)
    warn_loose_edges(survey, cfg.survey_sigma_m)
    inputs = report_inputs(
        beacons=beacons,
        survey=survey,
        locator=cfg,
        scanner=precision[2],
        defaults=defaults,
        config=config,
        settings=settings,
        crs=grid,
        scan_file=source,
    )
    return StreamSetup(source, survey, cfg, tables["sequence"], inputs)


def _warn(text: str) -> None:
    typer.echo(f"mast: warning: {text}", err=True)


def run_frames(
    setup: StreamSetup,
    frames: FrameReplaySource,
    beacons: Path,
    *,
    max_scans: int | None,
    near: str | None,
) -> None:
    """Locate a replayed 3D lidar's frames as they come (:func:`mast.live.session.
    run_live3d`): records on standard output, the summary on standard error, the exit
    status of ``mast live --help``."""
    import json

    from mast.cli.options import lidar_config
    from mast.cli.warmup import compile_3d
    from mast.live.session import run_live3d
    from mast.runs.frames3d import FrameLocator, check_elevations

    check_elevations(setup.survey, beacons)
    if near is not None:
        _warn(f"--near applies to 2D scans; {setup.source} replays 3D lidar frames")
    cfg = lidar_config(setup.config, setup.inputs.defaults)
    locator = FrameLocator(
        setup.survey, range_sigma_m=cfg.range_sigma_m, survey_sigma_m=cfg.survey_sigma_m
    )
    settings = effective({"locator": cfg, "sequence": setup.sequence}, "live")
    inputs = replace(setup.inputs, topic=frames.topic, config_sha256=settings.sha256)

    def emit(record_: dict[str, object]) -> None:
        sys.stdout.write(json.dumps(record_) + "\n")
        sys.stdout.flush()

    def record(fix: Fix3D, index: int, frame: Frame3D, now: ReportInputs) -> dict[str, Any]:
        return locator.record(fix, source=setup.source, index=index, frame=frame, inputs=now)

    compile_3d()  # the first frame is located as fast as the rest
    with signals_as_flag() as (interrupt, caught):
        summary = run_live3d(
            frames,
            locate=locator.locate,
            record=record,
            emit=emit,
            inputs=inputs,
            max_scans=max_scans,
            warn=_warn,
            interrupt=interrupt,
        )
    typer.echo(
        f"mast: {setup.source}: {summary.received} frames received, {summary.located} "
        f"located in 3D, {summary.fixed} fixed, {summary.dropped} dropped"
        + (f", {summary.malformed} malformed skipped" if summary.malformed else "")
        + f" in {summary.elapsed_s:.1f} s (each frame fixed on its own)",
        err=True,
    )
    if summary.pipe_closed:
        silence_stdout()
        return
    if summary.interrupted:
        typer.echo("mast: interrupted", err=True)
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if summary.fixed == 0:
        raise typer.Exit(EXIT_NO_FIX)


def run_stream(
    setup: StreamSetup,
    stream: Source,
    open_sinks: Callable[[contextlib.ExitStack[bool | None]], list[Sink]],
    *,
    max_scans: int | None,
    interrupted: str = "",
    ready: Callable[[], None] | None = None,
) -> None:
    """Locate ``stream`` as it arrives (:func:`mast.live.session.run_live`): records on
    standard output, the sinks ``open_sinks`` opens fed and closed, the summary on
    standard error and the exit status of ``mast live --help``. ``ready`` is called once
    Ctrl-C and SIGTERM are handled and the sinks are open, before the first scan."""
    import json

    from mast.cli.warmup import compile_all
    from mast.live.session import run_live

    def emit(record_: dict[str, object]) -> None:
        sys.stdout.write(json.dumps(record_) + "\n")
        sys.stdout.flush()

    compile_all()  # the first scan is located as fast as the rest
    with contextlib.ExitStack() as stack:
        # Ctrl-C and SIGTERM (a vehicle's service manager) only ask the run to end between
        # two scans: never in the middle of writing a recording, nor while closing it
        # (the handlers are restored last, after the sinks are closed).
        interrupt, caught = stack.enter_context(signals_as_flag())
        sinks = open_sinks(stack)
        if ready is not None:
            ready()
        summary = run_live(
            stream,
            setup.survey,
            emit=emit,
            config=setup.config,
            sequence=setup.sequence,
            inputs=setup.inputs,
            sinks=tuple(sinks),
            max_scans=max_scans,
            warn=_warn,
            interrupt=interrupt,
        )
    typer.echo(
        f"mast: {setup.source}: {summary.received} scans received, {summary.located} located, "
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
        typer.echo("mast: interrupted" + interrupted, err=True)
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if summary.fixed == 0:
        raise typer.Exit(EXIT_NO_FIX)
