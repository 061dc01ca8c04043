"""The ``mast`` command line.

Each command loads its inputs, calls one library function and prints or
saves what it returns. Errors the library raises on purpose become one line
on stderr and an exit status: 2 bad input, 3 no fix.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import math
import os
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from mast import __version__
from mast.apps.outputs import PLOT_SUFFIXES, check_output_file, check_output_folder
from mast.core.heap import QuietCollector
from mast.core.noise import DEFAULT_ANGLE_SIGMA_RAD, DEFAULT_RANGE_SIGMA_M, DEFAULT_SURVEY_SIGMA_M
from mast.core.scan import Scan
from mast.errors import InputError, MastError, NoFixError, OutputError, shorten

if TYPE_CHECKING:
    from mast.pipeline.locator import LocatorConfig
    from mast.pipeline.tracking import Prior

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NO_FIX = 3
EXIT_CANNOT_WRITE = 4
#: A bug in MAST itself (BSD sysexits EX_SOFTWARE): one line, never a traceback.
EXIT_INTERNAL = 70

#: Sigmas above these get a warning naming the unit (millimetres or degrees typed).
MAX_PLAUSIBLE_SIGMA_M = 0.5
MAX_PLAUSIBLE_ANGLE_SIGMA_RAD = 0.05

#: -h as well as --help, on every command.
CONTEXT = {"help_option_names": ["-h", "--help"]}

app = typer.Typer(
    name="mast",
    help=(
        "MAST: Mobile Automated Scanner Triangulateration. Fix a 2D laser scanner's "
        "position and azimuth in the mine grid from surveyed wall beacons.\n\n"
        "Exit status: 0 success (a fix), 2 bad input, 3 no fix, 4 an output cannot be "
        "written, 70 an internal error (please report it)."
    ),
    context_settings=CONTEXT,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"mast {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Show the version and exit."
        ),
    ] = False,
) -> None:
    """MAST command line."""


class ScanFormat(StrEnum):
    csv = "csv"
    bag = "bag"
    ros2 = "ros2"
    mcap = "mcap"


@app.command()
def simulate(
    out: Annotated[Path, typer.Option("--out", help="Folder to write into (created if missing).")],
    scenario: Annotated[
        str,
        typer.Option(
            "--scenario",
            help=(
                "Scenario name: paper, random, drive (a vehicle driving a drift at the "
                "scanner's rate, beacons in stretches with 30-60 m gaps between; streamed), "
                "or cloud (a 3D SLAM point cloud of a drift with beacons, for mast georef)."
            ),
        ),
    ] = "paper",
    seed: Annotated[int, typer.Option("--seed", help="Random seed (noise, random scenes).")] = 0,
    fmt: Annotated[
        ScanFormat,
        typer.Option(
            "--format",
            help=(
                "csv: one file per scan; bag: ROS 1 bag; "
                "ros2: ROS 2 sqlite3 bag; mcap: ROS 2 MCAP bag."
            ),
        ),
    ] = ScanFormat.csv,
    noise: Annotated[
        bool | None,
        typer.Option(
            "--noise/--no-noise",
            help="Add realistic range noise (default: none for paper and random, 12 mm for drive).",
            show_default=False,
        ),
    ] = None,
    scans: Annotated[
        int | None,
        typer.Option(
            "--scans", min=1, help="drive: number of scans (default 500; 10000 is ~800 m)."
        ),
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(
            "--rate", help="drive: scans per second, Hz (default 25 at 0.25°; 50 gives 0.5°)."
        ),
    ] = None,
    length: Annotated[
        float | None,
        typer.Option("--length", min=40.0, help="cloud: drift length, metres (default 300)."),
    ] = None,
    beacon_count: Annotated[
        int | None,
        typer.Option("--beacon-count", min=2, help="cloud: beacons mounted (default 12)."),
    ] = None,
    drift: Annotated[
        float | None,
        typer.Option(
            "--drift",
            min=0.0,
            max=0.2,
            help="cloud: SLAM drift, fraction of distance (0.01 = 1 %).",
        ),
    ] = None,
    density: Annotated[
        float | None,
        typer.Option("--density", min=1.0, help="cloud: points per square metre (default 600)."),
    ] = None,
) -> None:
    """Simulate a scenario: per scene, beacons.csv, the scans and truth.csv; or, with
    --scenario cloud, a 3D SLAM cloud of a drift (cloud.laz, beacons.csv with elevations,
    trajectory.tum, truth.json)."""
    from mast.sim import build_scenario, write_scenario

    options = {k: v for k, v in (("scans", scans), ("rate_hz", rate)) if v is not None}
    cloud_options = {
        k: v
        for k, v in (
            ("length_m", length),
            ("beacons", beacon_count),
            ("drift", drift),
            ("density", density),
        )
        if v is not None
    }
    if options and scenario != "drive":
        raise InputError("--scans and --rate apply to --scenario drive only")
    if cloud_options and scenario != "cloud":
        raise InputError(
            "--length, --beacon-count, --drift and --density apply to --scenario cloud"
        )
    check_output_folder(out)
    if scenario == "cloud":
        from mast.sim.cloud import CloudOptions, simulate_cloud

        noise_m = None if noise is None else (0.01 if noise else 0.0)
        opts = CloudOptions(**cloud_options)  # type: ignore[arg-type]
        if noise_m is not None:
            opts = replace(opts, noise_m=noise_m)
        sim = simulate_cloud(out, seed, opts)
        typer.echo(
            f"{sim.cloud}: {sim.points} points, {sim.beacons} beacons in {sim.survey.name}, "
            f"trajectory {sim.trajectory.name}, truth {sim.truth.name}"
        )
        return
    scenes = build_scenario(scenario, seed, noise=noise, **options)
    written = write_scenario(scenes, out, fmt=fmt.value, scenario=scenario, seed=seed)
    for w in written:
        typer.echo(f"{w.folder}: {w.count} scan(s), survey {w.survey.name}, truth {w.truth.name}")
    typer.echo(f"wrote {sum(w.count for w in written)} scan(s) in {len(written)} scene(s) to {out}")


class OutputFormat(StrEnum):
    text = "text"
    json = "json"


def _load_scans(
    path: Path, *, topic: str | None, range_min: float | None, range_max: float | None
) -> tuple[Iterator[Scan], bool]:
    """The scans in a file: one for a CSV, the LaserScans of a topic for a bag, read one
    at a time as they are located (a bag's scans are never all in memory at once)."""
    from mast.io import read_laserscans, read_scan_csv
    from mast.io.bags import bag_kind

    if path == Path("-"):
        return iter([_read_stdin_scan(range_min, range_max)]), False
    if not path.exists():
        raise InputError("scan file not found", path=path)
    if path.is_file() and path.suffix.lower() in {".csv", ".txt"}:
        scan = read_scan_csv(path, range_min_m=range_min or 0.0, range_max_m=range_max or math.inf)
        return iter([scan]), False
    bag_kind(path)  # a clear error for anything that is neither
    scans = (s.with_range_limits(range_min, range_max) for s in read_laserscans(path, topic=topic))
    first = next(scans, None)
    if first is None:
        raise InputError("bag holds no LaserScan message on that topic", path=path)
    return itertools.chain([first], scans), True


def _read_stdin_scan(range_min: float | None, range_max: float | None) -> Scan:
    """A scan CSV from standard input, spooled to a temporary file and named ``<stdin>``."""
    from mast.io import read_scan_csv
    from mast.limits import read_stream

    with tempfile.TemporaryDirectory(prefix="mast-stdin-") as tmp:
        spool = Path(tmp) / "stdin.csv"
        data = read_stream(sys.stdin.buffer, "<stdin>")
        spool.write_bytes(data)
        try:
            return read_scan_csv(
                spool, range_min_m=range_min or 0.0, range_max_m=range_max or math.inf
            )
        except InputError as err:
            raise InputError(err.problem, path="<stdin>", line=err.line) from None


def _parse_near(text: str, radius: float, az_tol_deg: float) -> Prior:
    from mast.core.pose import Pose2D, parse_azimuth
    from mast.pipeline.tracking import Prior

    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (2, 3):
        raise InputError(f"--near {text!r}: expected E,N or E,N,AZ")
    try:
        e, n = float(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"--near {text!r}: easting and northing must be numbers") from None
    if not (math.isfinite(e) and math.isfinite(n)):
        raise InputError(f"--near {text!r}: easting and northing must be finite")
    if not (math.isfinite(radius) and radius > 0):
        raise InputError("--radius must be a positive number")
    if not (math.isfinite(az_tol_deg) and 0 < az_tol_deg <= 180):
        raise InputError("--azimuth-tolerance must be a number of degrees in (0, 180]")
    az = parse_azimuth(parts[2]) if len(parts) == 3 else 0.0
    return Prior(
        Pose2D.from_degrees(e, n, az),
        radius,
        math.radians(az_tol_deg) if len(parts) == 3 else None,
    )


def _check_range_limits(range_min: float | None, range_max: float | None) -> None:
    for name, value in (("--range-min", range_min), ("--range-max", range_max)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise InputError(f"{name} must be a non-negative number, got {value}")


def _default(value: float) -> str:
    return f"{value:g}"


BeaconsOption = Annotated[Path, typer.Option("--beacons", "-b", help="Beacon survey CSV.")]
TopicOption = Annotated[str | None, typer.Option("--topic", help="LaserScan topic in a bag.")]
RealDataOption = Annotated[
    Path, typer.Option("--data", help="Folder of real scans (../shared/data).")
]
LogBeaconsOption = Annotated[int, typer.Option("--beacons", min=2, help="Beacons mounted per log.")]
DesignSeedOption = Annotated[int, typer.Option("--seed", help="Seed of the designs and the noise.")]
RangeSigmaOption = Annotated[
    float | None,
    typer.Option(
        "--range-sigma",
        help="Range standard deviation, metres "
        f"[default: {_default(DEFAULT_RANGE_SIGMA_M)}, or the --scanner's].",
    ),
]
AngleSigmaOption = Annotated[
    float | None,
    typer.Option(
        "--angle-sigma",
        help="Beam angle standard deviation, radians "
        f"[default: {_default(DEFAULT_ANGLE_SIGMA_RAD)}, or the --scanner's].",
    ),
]
ScannerOption = Annotated[
    str | None,
    typer.Option(
        "--scanner", help="Named scanner model giving the default sigmas (see mast scanners)."
    ),
]
RangeMinOption = Annotated[
    float | None,
    typer.Option("--range-min", help="Shortest valid range, metres [default: the bag's, or 0]."),
]
RangeMaxOption = Annotated[
    float | None,
    typer.Option("--range-max", help="Longest valid range, metres [default: the bag's, or none]."),
]
SurveySigmaOption = Annotated[
    float | None,
    typer.Option(
        "--survey-sigma",
        help="Standard deviation of a surveyed edge coordinate, metres "
        f"[default: {_default(DEFAULT_SURVEY_SIGMA_M)}].",
    ),
]

NearOption = Annotated[
    str | None,
    typer.Option(
        "--near",
        help="Prior position E,N[,AZ] (azimuth in degrees or D°M'S): narrows the search.",
    ),
]
RadiusOption = Annotated[
    float, typer.Option("--radius", help="Radius of the --near prior, metres.")
]
AzimuthToleranceOption = Annotated[
    float,
    typer.Option("--azimuth-tolerance", help="With an azimuth in --near: degrees allowed."),
]


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
    angle_sigma: AngleSigmaOption = None,
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
) -> None:
    """Fix position and azimuth from one scan, several, or every scan of a bag.

    Exit status 0 when a scan is fixed (with several scans or a bag: at least
    one), 3 when none is, 2 for bad input, 4 when an output cannot be written.
    """
    import json

    from mast.apps.report import ReportInputs, fix_record, fix_text
    from mast.io import read_survey
    from mast.io.bags import laserscan_topic
    from mast.pipeline.locator import SequenceLocator

    cfg, defaults = _precisions(range_sigma, angle_sigma, scanner, survey_sigma)
    if near is not None:
        cfg = replace(cfg, prior=_parse_near(near, radius, azimuth_tolerance))
    if scan_paths.count(Path("-")) > 1:
        raise InputError("standard input ('-') can be read only once")
    if plot is not None:
        check_output_file(plot, suffixes=PLOT_SUFFIXES, inputs=[*scan_paths, beacons])
    survey = read_survey(beacons)
    numbered = len(scan_paths) > 1
    fixed = located = 0
    # What is alive once a scan is located is frozen, out of the collector's full
    # passes over it (mast.core.heap): they were a run's slowest scans.
    with QuietCollector() as heap:
        for scan_path in scan_paths:
            scans, many = _load_scans(
                scan_path, topic=topic, range_min=range_min, range_max=range_max
            )
            numbered = numbered or many
            inputs = ReportInputs(
                scan_file="<stdin>" if scan_path == Path("-") else str(scan_path),
                survey_file=str(beacons),
                scanner=scanner,
                topic=laserscan_topic(scan_path, topic) if many else None,
                defaults=frozenset(defaults),
            )
            source = inputs.scan_file or str(scan_path)
            tracker = SequenceLocator(survey, config=cfg)
            for i, scan in enumerate(heap.each(scans)):
                step = tracker.step(scan)
                fix = step.fix
                fixed += fix.ok
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
                    from mast.apps.plot import plot_fix

                    target = plot.with_name(f"{plot.stem}_{located:04d}{plot.suffix}")
                    plot_fix(scan, survey, fix, target if numbered else plot, title=label)
                located += 1
    if fixed == 0:
        raise typer.Exit(EXIT_NO_FIX)


@app.command()
def track(
    runs: Annotated[
        list[Path],
        typer.Argument(
            metavar="RUN...",
            help="ROS 1 bags, ROS 2 bag folders (sqlite3, MCAP), or folders holding them.",
        ),
    ],
    beacons: BeaconsOption,
    out: Annotated[
        Path, typer.Option("--out", help="Folder for the run's files (created if missing).")
    ],
    topic: TopicOption = None,
    range_sigma: RangeSigmaOption = None,
    angle_sigma: AngleSigmaOption = None,
    scanner: ScannerOption = None,
    survey_sigma: SurveySigmaOption = None,
    range_min: RangeMinOption = None,
    range_max: RangeMaxOption = None,
    max_gap: Annotated[
        float,
        typer.Option(
            "--max-gap",
            min=0.0,
            help="Scans further apart in time, seconds, are not chained by odometry "
            "(a log kept a scan every metre or two: give its spacing; each such step is "
            "then matched over all the vehicle could have done, and slower).",
        ),
    ] = 0.5,
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
) -> None:
    """Place every scan of a run in the mine grid: fixes from beacons, odometry between
    them, smoothed in a pose graph; writes fixes.jsonl, trajectory.csv and .tum, map.las,
    map.dxf and report.html into --out.

    Several runs (or a folder of them) are tracked in parallel on Dask, one run per
    task, each into --out/<run name>/, with --out/index.csv listing them.

    Exit status 0 when scans were placed (in every run), 3 when none could be, 2 for bad
    input, 4 when an output cannot be written, 130 when interrupted (the files then hold
    the scans read until then).
    """
    from mast.apps.report import ReportInputs
    from mast.io import read_survey
    from mast.io.bags import bag_kind, laserscan_topic
    from mast.runs.batch import expand_runs, track_runs
    from mast.runs.run import track_run
    from mast.runs.track import TrackConfig

    cfg, defaults = _precisions(range_sigma, angle_sigma, scanner, survey_sigma)
    _check_range_limits(range_min, range_max)
    for given in runs:
        if not given.exists():
            raise InputError("run not found", path=given)
    found = expand_runs(runs)
    for r in found:
        bag_kind(r)
    check_output_folder(out)
    survey = read_survey(beacons)
    if len(found) > 1 or scheduler is not None:
        outcomes = track_runs(
            found,
            beacons,
            out,
            options={
                "config": TrackConfig(locator=cfg, max_gap_s=max_gap),
                "topic": topic,
                "inputs": ReportInputs(
                    survey_file=str(beacons), scanner=scanner, defaults=frozenset(defaults)
                ),
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
    inputs = ReportInputs(
        scan_file=str(run),
        survey_file=str(beacons),
        scanner=scanner,
        topic=laserscan_topic(run, topic),
        defaults=frozenset(defaults),
    )

    def warn(text: str) -> None:
        typer.echo(f"mast: warning: {shorten(text, 80)}", err=True)

    with _signals_as_flag() as (interrupt, caught), _progress(f"tracking {run.name}") as progress:
        result = track_run(
            run,
            survey,
            out,
            config=TrackConfig(locator=cfg, max_gap_s=max_gap),
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
    if s.gaps > s.scans // 2:
        typer.echo(
            f"mast: hint: {s.gaps} of {s.scans} scans came more than {max_gap:g} s after the "
            "scan before and were not chained by odometry; if the log keeps a scan only "
            "every metre or so, give --max-gap its spacing",
            err=True,
        )
    if result.interrupted:
        typer.echo("mast: interrupted; the files hold the scans read until then", err=True)
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if s.placed == 0:
        raise typer.Exit(EXIT_NO_FIX)


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

    from mast.apps.report import ReportInputs
    from mast.io import read_survey
    from mast.live.session import Sink, run_live
    from mast.live.sources import ReplaySource, SourceOptions, open_source

    cfg, defaults = _precisions(range_sigma, angle_sigma, scanner, survey_sigma)
    if near is not None:
        cfg = replace(cfg, prior=_parse_near(near, radius, azimuth_tolerance))
    _check_range_limits(range_min, range_max)
    for name, value in (("--timeout", timeout), ("--give-up", give_up)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{name} must be a positive number of seconds, got {value}")
    survey = read_survey(beacons)
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
        scan_file=source, survey_file=str(beacons), scanner=scanner, defaults=frozenset(defaults)
    )

    def warn(text: str) -> None:
        typer.echo(f"mast: warning: {text}", err=True)

    def emit(record_: dict[str, object]) -> None:
        sys.stdout.write(json.dumps(record_) + "\n")
        sys.stdout.flush()

    from mast.apps.bench.warmup import compile_all

    compile_all()  # the first scan is located as fast as the rest
    sinks: list[Sink] = []
    with contextlib.ExitStack() as stack:
        # Ctrl-C and SIGTERM (a vehicle's service manager) only ask the run to end between
        # two scans: never in the middle of writing the recording, nor while closing it
        # (the handlers are restored last, after the recording is closed).
        interrupt, caught = stack.enter_context(_signals_as_flag())
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
        _silence_stdout()
        return
    if summary.interrupted:
        typer.echo(
            "mast: interrupted" + (f"; {record} holds the scans received" if record else ""),
            err=True,
        )
        raise typer.Exit(128 + (caught[0] if caught else signal.SIGINT))
    if summary.fixed == 0:
        raise typer.Exit(EXIT_NO_FIX)


@app.command()
def emulate(
    kind: Annotated[
        str, typer.Argument(metavar="KIND", help="sick (CoLa-A) or hokuyo (SCIP 2.0).")
    ],
    run: Annotated[
        Path,
        typer.Option("--from", help="The run to serve: a bag, or a folder of scan CSVs."),
    ],
    port: Annotated[
        int, typer.Option("--port", min=0, max=65535, help="TCP port (0: any free one).")
    ] = 0,
    host: Annotated[str, typer.Option("--host", help="Address to listen on.")] = "127.0.0.1",
    hz: Annotated[
        float | None,
        typer.Option("--hz", help="Scans a second [default: the run's own spacing]."),
    ] = None,
    drop_after: Annotated[
        int | None,
        typer.Option("--drop-after", min=1, help="Fault: close the connection after N scans."),
    ] = None,
    stall_after: Annotated[
        int | None,
        typer.Option("--stall-after", min=1, help="Fault: stop sending after N scans."),
    ] = None,
    corrupt_every: Annotated[
        int | None,
        typer.Option("--corrupt-every", min=1, help="Fault: every N-th telegram malformed."),
    ] = None,
) -> None:
    """Serve a recorded or simulated run as a SICK LMS1xx (CoLa-A) or Hokuyo UST (SCIP 2.0)
    scanner on TCP, at the run's rate, for `mast live` (tests, demos, benchmarks).

    Prints the address served on, then serves until every scan is sent. Exit status 0
    when the run was served, 2 for bad input, 130 when interrupted.
    """
    from mast.live.emulate import Emulator, EmulatorFaults
    from mast.live.sources import read_run

    if hz is not None and not (math.isfinite(hz) and hz > 0):
        raise InputError(f"--hz must be a positive number, got {hz}")
    faults = EmulatorFaults(
        drop_after=drop_after, stall_after=stall_after, corrupt_every=corrupt_every
    )
    emulator = Emulator(kind, read_run(run), host=host, port=port, hz=hz, faults=faults)
    with emulator:
        typer.echo(f"mast: serving {run} as a {kind} scanner on {host}:{emulator.port}", err=True)
        while not emulator.wait(0.2):
            pass
    if emulator.error is not None:
        raise emulator.error
    typer.echo(f"mast: served {emulator.sent} scans", err=True)


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
) -> None:
    """Put a 3D SLAM point cloud into the mine grid from the beacons it shows.

    Writes into --out: georeferenced.laz (every attribute kept), transform.json
    (docs/transform.schema.json), beacons_found.csv, report.txt, report.html and plan.png.

    Exit status 0 georeferenced, 3 refused (too few beacons, an ambiguous match, beacons
    that disagree: the reports and beacons_found.csv say why), 2 bad input, 4 an output
    cannot be written.
    """
    from mast.apps.georef import parse_band, parse_checks, run_georef
    from mast.cloud.detect import DetectConfig
    from mast.cloud.georef import MODELS, GeorefConfig
    from mast.cloud.match import MatchConfig

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
    check_output_folder(out)
    run = run_georef(cloud, beacons, out, config, trajectory_path=trajectory, time_field=time_field)
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


@contextmanager
def _progress(label: str) -> Iterator[Callable[[int, int], None] | None]:
    """A progress line on a terminal (scans, fixes, scans per second); nothing otherwise."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TextColumn("{task.completed} scans, {task.fields[fixes]} fixed, {task.fields[rate]}"),
        TimeElapsedColumn(),
        transient=True,
    ) as bar:
        task = bar.add_task(label, total=None, fixes=0, rate="")
        start = time.perf_counter()

        def update(scans: int, fixes: int) -> None:
            rate = scans / max(time.perf_counter() - start, 1e-9)
            bar.update(task, completed=scans, fixes=fixes, rate=f"{rate:.0f} scans/s")

        yield update


@contextmanager
def _signals_as_flag() -> Iterator[tuple[threading.Event, list[int]]]:
    """Ctrl-C and SIGTERM (a vehicle's service manager) only set a flag while inside:
    the run checks it between two scans, so a signal never lands inside a compiled
    kernel or a half-written file. Yields the flag and the signals caught; the
    handlers before it are restored on leaving."""
    interrupt = threading.Event()
    caught: list[int] = []

    def on_signal(signum: int, _frame: object) -> None:
        caught.append(signum)
        interrupt.set()

    before = {
        signum: signal.signal(signum, on_signal) for signum in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield interrupt, caught
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)


def _precisions(
    range_sigma: float | None,
    angle_sigma: float | None,
    scanner: str | None,
    survey_sigma: float | None,
) -> tuple[LocatorConfig, set[str]]:
    """The locator's precisions from the options, and which were left at their defaults.

    A sigma no scanner or survey has gets a warning naming its unit.
    """
    from mast.pipeline.locator import LocatorConfig
    from mast.sim import scanner_model

    cfg = LocatorConfig()
    defaults = {"range_sigma_m", "angle_sigma_rad", "survey_sigma_m"}
    if scanner is not None:
        noise = scanner_model(scanner).noise()
        cfg = replace(cfg, range_sigma_m=noise.range_sigma_m, angle_sigma_rad=noise.angle_sigma_rad)
        defaults -= {"range_sigma_m", "angle_sigma_rad"}
    checks = (
        ("--range-sigma", range_sigma),
        ("--angle-sigma", angle_sigma),
        ("--survey-sigma", survey_sigma),
    )
    for name, value in checks:
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise InputError(f"{name} must be a non-negative number, got {value}")
    for name, value, limit, unit, example in (
        ("--range-sigma", range_sigma, MAX_PLAUSIBLE_SIGMA_M, "metres", "10 mm is 0.01"),
        ("--survey-sigma", survey_sigma, MAX_PLAUSIBLE_SIGMA_M, "metres", "3 mm is 0.003"),
        ("--angle-sigma", angle_sigma, MAX_PLAUSIBLE_ANGLE_SIGMA_RAD, "radians", "0.1° is 0.0017"),
    ):
        if value is not None and value > limit:
            typer.echo(
                f"mast: warning: {name} {value:g} {unit} is more than any laser scanner or "
                f"survey has; it is in {unit} ({example})",
                err=True,
            )
    if range_sigma is not None:
        if range_sigma <= 0:
            raise InputError("--range-sigma must be positive")
        cfg = replace(cfg, range_sigma_m=range_sigma)
        defaults.discard("range_sigma_m")
    if angle_sigma is not None:
        cfg = replace(cfg, angle_sigma_rad=angle_sigma)
        defaults.discard("angle_sigma_rad")
    if survey_sigma is not None:
        cfg = replace(cfg, survey_sigma_m=survey_sigma)
        defaults.discard("survey_sigma_m")
    return cfg, defaults


bench_app = typer.Typer(
    help="Benchmarks that print figures (not timed tests).",
    no_args_is_help=True,
    context_settings=CONTEXT,
)
app.add_typer(bench_app, name="bench")


@bench_app.command("accuracy")
def bench_accuracy(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    poses: Annotated[
        int, typer.Option("--poses", min=1, help="Owed poses per configuration.")
    ] = 40,
    draws: Annotated[int, typer.Option("--draws", min=1, help="Noise draws per pose.")] = 30,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """RMS error against the Cramer-Rao bound and coverage of the 95 % intervals,
    for the four scanner configurations (270° at 0.5° and 0.25°, 190° at 1/6°, 360° at 0.2°)."""
    from mast.apps.bench import run_accuracy

    if out is not None:
        check_output_folder(out)
    run_accuracy(poses=poses, draws=draws, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("survey")
def bench_survey(
    beacons: Annotated[
        int, typer.Option("--beacons", min=1, help="Beacons in the mine's survey.")
    ] = 10_000,
    range_max: Annotated[
        float,
        typer.Option(
            "--range-max", min=0.1, help="Scanner's longest range, metres (sets the index's reach)."
        ),
    ] = 80.0,
) -> None:
    """A whole mine's survey read, checked and indexed: seconds, with a few designs and with
    every beacon its own."""
    from mast.apps.bench.surveyload import run_survey_load

    run_survey_load(beacons=beacons, range_max_m=range_max, echo=typer.echo)


@bench_app.command("fuzz")
def bench_fuzz(
    inputs: Annotated[
        int, typer.Option("--inputs", min=1, help="Damaged or crafted inputs to run.")
    ] = 10_000,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the mutations.")] = 0,
    keep: Annotated[
        Path | None, typer.Option("--keep", help="Folder to copy failing cases into.")
    ] = None,
) -> None:
    """Damaged and crafted files through every reader and output path, each run in a
    child with memory, file-size and time limits: tracebacks, undocumented exit
    statuses, memory and time beyond bounds, fixes that differ, half-written outputs."""
    from mast.apps.bench.fuzz import run_fuzz

    if keep is not None:
        check_output_folder(keep, option="--keep")
    with _cell_progress("fuzzing") as progress:
        run_fuzz(inputs=inputs, seed=seed, echo=typer.echo, progress=progress, keep_failures=keep)


@bench_app.command("robustness")
def bench_robustness(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    hard: Annotated[
        int, typer.Option("--hard", min=0, help="Hostile scenes (5 scans each).")
    ] = 200,
    drift: Annotated[
        int, typer.Option("--drift", min=0, help="Many-beacon drifts (10 scans each).")
    ] = 40,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """Fix rate where two beacons each show two clean panels, wrong fixes and no-fix
    reasons, over hostile scenes and a many-beacon drift."""
    from mast.apps.bench.robustness import run_robustness

    if out is not None:
        check_output_folder(out)
    run_robustness(hard_scenes=hard, drift_scenes=drift, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("field")
def bench_field(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    scenes: Annotated[
        int, typer.Option("--scenes", min=1, help="Scenes per family (noisy, hostile).")
    ] = 200,
    poses: Annotated[int, typer.Option("--poses", min=1, help="Shots per scene.")] = 4,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """Scenes drawn as widely as the field (beacons of any shape bolted askew onto rough
    rock, five scanners from 8 to 20 mm, clutter shaped like panels, mixed pixels),
    scored as the independent scenes are: owed scans fixed, wrong fixes, RMS/CRB and
    95 % coverage."""
    from mast.apps.bench.field import run_field

    if out is not None:
        check_output_folder(out)
    run_field(scenes=scenes, poses=poses, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("minewide")
def bench_minewide(
    poses: Annotated[int, typer.Option("--poses", min=1, help="Owed scans located.")] = 40,
    copies: Annotated[
        int, typer.Option("--copies", min=0, help="Copies of the designs surveyed elsewhere.")
    ] = 184,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
    distinct: Annotated[
        bool,
        typer.Option(
            "--distinct", help="Each added beacon of a random design of its own, not a copy."
        ),
    ] = False,
) -> None:
    """The same scans against their local survey and a mine-wide one (the local beacons
    plus copies of their designs in other drifts): same fixes, and the time it costs."""
    from mast.apps.bench.minewide import run_minewide

    run_minewide(poses=poses, copies=copies, seed=seed, distinct=distinct, echo=typer.echo)


@bench_app.command("tracking")
def bench_tracking(
    poses: Annotated[
        int, typer.Option("--poses", min=1, help="Owed poses per configuration.")
    ] = 40,
    draws: Annotated[int, typer.Option("--draws", min=1, help="Noise draws per pose.")] = 3,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """Tracking: the accuracy benchmark's owed scans with a prior within 0.5 m and 5 degrees
    (a fix owed on every one), and with a prior 1.5 m off (no fix owed)."""
    from mast.apps.bench.tracking import run_tracking

    run_tracking(poses=poses, draws=draws, seed=seed, echo=typer.echo)


@bench_app.command("live")
def bench_live(
    scans: Annotated[int, typer.Option("--scans", min=100, help="Scans per scanner.")] = 30_000,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drive.")] = 0,
    kind: Annotated[
        list[str] | None, typer.Option("--kind", help="sick, hokuyo [default: both].")
    ] = None,
) -> None:
    """Live: a simulated drive with beacon gaps served by the SICK (50 Hz) and Hokuyo (40 Hz)
    emulators and located as it arrives (latency, drops, memory, CPU, owed scans fixed,
    recovery from a wrong prior)."""
    from mast.apps.bench.live import run_live_bench

    run_live_bench(scans=scans, seed=seed, kinds=tuple(kind or ("sick", "hokuyo")), echo=typer.echo)


@bench_app.command("longdrive")
def bench_longdrive(
    scans: Annotated[int, typer.Option("--scans", min=100, help="Scans per drive.")] = 10_000,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="Drives per scanner.")] = 5,
    workers: Annotated[int, typer.Option("--workers", min=1, help="Processes.")] = 2,
    out: Annotated[
        Path | None, typer.Option("--out", help="Folder for every scan's outcome (CSV).")
    ] = None,
) -> None:
    """Long drives: SICK (50 Hz) and Hokuyo (40 Hz) drives sent through their protocols and
    located in sequence as `mast locate RUN` and `mast live` do (owed scans fixed, wrong
    fixes listed, fixes outside their own 99 % ellipse, time a scan)."""
    from mast.apps.bench.longdrive import run_longdrive

    if out is not None:
        check_output_folder(out)
    run_longdrive(scans=scans, seeds=seeds, workers=workers, out_dir=out, echo=typer.echo)


@bench_app.command("georef")
def bench_georef(
    clouds: Annotated[int, typer.Option("--clouds", min=0, help="Clouds without drift.")] = 20,
    drift_clouds: Annotated[
        int, typer.Option("--drift-clouds", min=0, help="Clouds with 1 % drift.")
    ] = 6,
    large_points: Annotated[
        int, typer.Option("--large-points", min=0, help="Points of the large cloud (0: none).")
    ] = 50_000_000,
    density: Annotated[
        float, typer.Option("--density", min=100.0, help="Points per square metre.")
    ] = 1000.0,
    out: Annotated[Path | None, typer.Option("--out", help="CSV of every cloud.")] = None,
) -> None:
    """Simulated SLAM clouds through mast georef: beacons found, check misclosures, honest
    bounds, drift corrected, and a large LAZ's time and memory."""
    from mast.apps.bench.georef import run_georef_bench

    run_georef_bench(
        clouds=clouds,
        drift_clouds=drift_clouds,
        large_points=large_points,
        density=density,
        out=out,
        echo=typer.echo,
    )


@bench_app.command("dense")
def bench_dense(
    beams: Annotated[
        list[int] | None,
        typer.Argument(help="Beam counts to measure [default: 1081 10000 100000 1000000]."),
    ] = None,
    range_sigma: Annotated[
        float, typer.Option("--range-sigma", help="Range noise of the scans, metres.")
    ] = 0.0,
) -> None:
    """Dense scans: read and locate time and peak memory (each in a fresh process)
    against the beams of a scan, from a normal scan to a million beams."""
    from mast.apps.bench.dense import DEFAULT_BEAMS, run_dense

    run_dense(tuple(beams) if beams else DEFAULT_BEAMS, range_sigma_m=range_sigma, echo=typer.echo)


@bench_app.command("run")
def bench_run(
    scans: Annotated[
        list[int] | None,
        typer.Argument(help="Drive lengths in scans [default: 1000 10000]."),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drive.")] = 0,
) -> None:
    """Survey runs: simulated drives read and tracked (throughput, peak memory), the placed
    scans against the truth (fixed and carried by odometry) and their 95 % coverage."""
    from mast.apps.bench.runs import DEFAULT_SCANS, run_runs

    run_runs(tuple(scans) if scans else DEFAULT_SCANS, seed=seed, echo=typer.echo)


@bench_app.command("speed")
def bench_speed(
    scans: Annotated[
        int, typer.Option("--scans", min=0, help="Scans located at 1081 beams (0: skip).")
    ] = 300,
    scans_360: Annotated[
        int, typer.Option("--scans-360", min=0, help="Scans located at 1800 beams (0: skip).")
    ] = 100,
    bag: Annotated[
        list[int] | None,
        typer.Option(
            "--bag",
            min=0,
            help="Bag length read and located by mast locate, repeatable; 0 skips "
            "[default: 1000 3000].",
        ),
    ] = None,
    track: Annotated[
        list[int] | None,
        typer.Option(
            "--track",
            min=0,
            help="Bag length tracked by mast track, repeatable; 0 skips [default: 1000].",
        ),
    ] = None,
    minewide_poses: Annotated[
        int, typer.Option("--minewide-poses", min=0, help="Mine-wide scans (0: skip).")
    ] = 40,
    beacons: Annotated[
        int, typer.Option("--beacons", min=3, help="Beacons of the mine-wide survey.")
    ] = 200,
    startup_runs: Annotated[
        int, typer.Option("--startup-runs", min=0, help="Fresh 'mast --help' runs (0: skip).")
    ] = 5,
    tracked_scans: Annotated[
        int,
        typer.Option("--tracked-scans", min=0, help="Drive scans located in sequence (0: skip)."),
    ] = 600,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drives and scenes.")] = 0,
    out: Annotated[
        Path | None, typer.Option("--out", help="Also write the figures to this text file.")
    ] = None,
) -> None:
    """Speed: locate per scan and per stage (1081 and 1800 beams), bags read, located and
    tracked (each in a fresh process: throughput, peak memory), a 200-beacon survey,
    start-up, a peer (small_gicp point-to-plane ICP) on the same scans, and tracked
    scans (a drive located in sequence) per stage beside the peer from their priors."""
    from mast.apps.bench.speed import DEFAULT_BAG_SCANS, DEFAULT_TRACK_SCANS, run_speed

    if out is not None:
        check_output_file(out, suffixes=(".txt", ".md", ".log"), option="--out")
    run_speed(
        scans=scans,
        scans_360=scans_360,
        bag_scans=tuple(n for n in bag if n) if bag else DEFAULT_BAG_SCANS,
        track_scans=tuple(n for n in track if n) if track else DEFAULT_TRACK_SCANS,
        minewide_poses=minewide_poses,
        survey_beacons=beacons,
        startup_runs=startup_runs,
        tracked_scans=tracked_scans,
        seed=seed,
        out=out,
        echo=typer.echo,
    )


@bench_app.command("clutter")
def bench_clutter(
    data: RealDataOption = Path("../shared/data"),
    beacons: LogBeaconsOption = 29,
    seed: DesignSeedOption = 0,
    priors: Annotated[
        bool,
        typer.Option(
            "--priors/--no-priors",
            help="Also locate every scan with a good prior (0.5 m, 5 deg) and a wrong one.",
        ),
    ] = True,
) -> None:
    """Real clutter: beacons mounted on the real walls of CARMEN logs with corrected
    poses, ray-cast into every scan; fixes where owed and wrong fixes per log, also
    when tracking from a good or a wrong prior."""
    from mast.apps.bench.clutter import run_real_clutter

    if not data.is_dir():
        raise InputError("folder of real scans not found", path=data)
    run_real_clutter(data, beacons=beacons, seed=seed, priors=priors, echo=typer.echo)


@bench_app.command("reallog")
def bench_reallog(
    data: RealDataOption = Path("../shared/data"),
    beacons: LogBeaconsOption = 29,
    seed: DesignSeedOption = 0,
    max_gap: Annotated[
        float, typer.Option("--max-gap", min=0.0, help="As mast track's --max-gap, seconds.")
    ] = 3.0,
) -> None:
    """Runs on real logs: beacons mounted on the real walls of CARMEN logs, the logs
    tracked as mast track does; error and 95 % coverage of the scans placed by odometry."""
    from mast.apps.bench.reallog import run_real_logs

    if not data.is_dir():
        raise InputError("folder of real scans not found", path=data)
    run_real_logs(data, beacons=beacons, seed=seed, max_gap_s=max_gap, echo=typer.echo)


@bench_app.command("real")
def bench_real(
    data: RealDataOption = Path("../shared/data"),
    every: Annotated[
        int, typer.Option("--every", min=1, help="Insert beacons into every Nth scan.")
    ] = 10,
) -> None:
    """Real scans by others: no fix without beacons; fixes with beacons ray-cast into them."""
    from mast.apps.bench.realscans import run_real_scans

    if not data.is_dir():
        raise InputError("folder of real scans not found", path=data)
    run_real_scans(data, every=every, echo=typer.echo)


reproduce_app = typer.Typer(
    help="Re-run published experiments.", no_args_is_help=True, context_settings=CONTEXT
)
app.add_typer(reproduce_app, name="reproduce")


@reproduce_app.command("paper")
def reproduce_paper_cmd(
    out: Annotated[
        Path, typer.Option("--out", help="Folder for report.md, figures and results.csv.")
    ],
    draws: Annotated[int, typer.Option("--draws", min=1, help="Noisy draws per shot.")] = 30,
    seed: Annotated[int, typer.Option("--seed", help="Noise seed.")] = 0,
) -> None:
    """The MAST paper's experiments (Table 2 positions, wall yaws, beacon sizes), noise-free
    and with 12 mm range noise, reported beside the paper's published values."""
    from mast.apps.reproduce import reproduce_paper

    check_output_folder(out)
    reproduce_paper(out, draws=draws, seed=seed, echo=typer.echo)


@app.command()
def plan(
    drift: Annotated[
        Path,
        typer.Option(
            "--drift",
            help="The drift's walls: a CSV wall,vertex,easting,northing or a DXF of polylines.",
        ),
    ],
    beacons: BeaconsOption,
    out: Annotated[
        Path, typer.Option("--out", help="Folder for the outputs (created if missing).")
    ],
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
    angle_sigma: AngleSigmaOption = None,
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
    check: Annotated[
        bool,
        typer.Option(
            "--check",
            help="Only read and check the drift and the survey, and say how large "
            "the job is; write nothing.",
        ),
    ] = False,
) -> None:
    """Predict where along a drift a scanner gets a fix, how precise, and where beacons help.

    Writes plan.csv (one row per cell and heading), plan.png, plan.dxf and
    summary.json into --out; with --suggest also proposed_beacons.csv (the
    survey with the new beacons, for mast plan and mast locate).
    Exit status 0, 2 for bad input, 4 when an output cannot be written.
    """
    from mast.apps.plan import run_plan, scanner_for
    from mast.io import read_survey
    from mast.plan.predict import PlanSettings

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
        angle_sigma_rad=angle_sigma,
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
    survey = read_survey(beacons)
    if check:
        from mast.io.drift import read_drift

        walls = read_drift(drift, layers=tuple(layer or ()))
        along = walls.length_m / 2  # two walls to a drift
        stations = math.ceil(along / settings.step_m) + 1
        typer.echo(
            f"{drift}: {len(walls.walls)} walls, {walls.length_m:.0f} m of wall (about "
            f"{along:.0f} m of drift, {stations} stations); {beacons}: {len(survey)} beacons"
        )
        return
    check_output_folder(out)
    with _cell_progress("plan") as update:
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


@contextmanager
def _cell_progress(label: str) -> Iterator[Callable[[int, int], None] | None]:
    """A progress bar over cells on a terminal; nothing otherwise."""
    if not sys.stderr.isatty():
        yield None
        return
    from rich.progress import Progress

    with Progress(transient=True) as bar:
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


@app.command()
def scanners() -> None:
    """List the named scanner models (field of view, resolution, range noise)."""
    from mast.sim import SCANNERS

    for m in SCANNERS.values():
        typer.echo(
            f"{m.name:<18} {m.fov_deg:5.0f}° at {m.resolution_deg:.4g}°, "
            f"{m.range_min_m:g}–{m.range_max_m:g} m, σ {1e3 * m.range_sigma_m:g} mm"
        )


@app.command()
def demo(
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Keep the simulated files here (default: a temporary folder)."),
    ] = None,
) -> None:
    """Simulate the paper's layout, locate every scan, and compare with the truth (Table 2)."""
    from mast.apps.demo import run_demo

    if out is not None:
        check_output_folder(out)
    with tempfile.TemporaryDirectory(prefix="mast-demo-") as tmp:
        run_demo(out if out is not None else Path(tmp), echo=typer.echo, keep=out is not None)


def main() -> None:
    """Entry point: every way the command can end is one line and a documented exit status."""
    try:  # typer carries its own click (0.20 and later); earlier ones use click itself
        from typer._click import exceptions as click
    except ImportError:  # pragma: no cover - depends on the installed typer
        import click  # type: ignore[no-redef]

    # Libraries' log records (ezdxf's recoveries, rosbags') never reach the terminal as
    # stray lines: MAST reports what matters itself, one line each.
    logging.getLogger().addHandler(logging.NullHandler())
    try:
        try:
            status = app(standalone_mode=False)
        finally:
            sys.stdout.flush()
    except SystemExit as exc:
        # click ends a run whose standard output was closed (EPIPE) with status 1: that is
        # a write that failed, quietly, like BrokenPipeError below.
        if exc.code == 1:
            _silence_stdout()
            sys.exit(EXIT_CANNOT_WRITE)
        raise
    except click.UsageError as err:
        # A bad option or value: click's message, with a long value cut short.
        if type(err).__name__ == "NoArgsIsHelpError":
            _say_error(err.show)
        else:
            _say_error(click.UsageError(shorten(err.format_message(), 80), ctx=err.ctx).show)
        sys.exit(err.exit_code)
    except click.ClickException as err:
        _say(f"mast: error: {shorten(err.format_message(), 80)}")
        sys.exit(EXIT_BAD_INPUT)
    except (typer.Abort, KeyboardInterrupt):
        _say("mast: interrupted")
        sys.exit(130)
    except NoFixError as err:
        _say(f"mast: {shorten(str(err), 80)}")
        sys.exit(EXIT_NO_FIX)
    except OutputError as err:
        _say(f"mast: error: {shorten(str(err), 80)}")
        sys.exit(EXIT_CANNOT_WRITE)
    except MastError as err:  # InputError and the rest: what was given is wrong
        _say(f"mast: error: {shorten(str(err), 80)}")
        sys.exit(EXIT_BAD_INPUT)
    except BrokenPipeError:
        # The reader of standard output went away (``mast locate ... | head``): stop
        # quietly, as command-line tools do, with the status of a write that failed.
        _silence_stdout()
        sys.exit(EXIT_CANNOT_WRITE)
    except OSError as err:
        _silence_stdout()
        where = f"{err.filename}: " if err.filename else "standard output: "
        _say(f"mast: error: cannot write {where}{err.strerror or err}")
        sys.exit(EXIT_CANNOT_WRITE)
    except MemoryError:
        _say("mast: error: out of memory (the input is too large for this machine)")
        sys.exit(EXIT_BAD_INPUT)
    except Exception as err:
        if os.environ.get("MAST_DEBUG"):
            raise
        text = str(err).splitlines()[0][:200] if str(err) else ""
        _say(
            f"mast: internal error: {type(err).__name__}: {shorten(text, 80)} (a bug in MAST: "
            "please report it with the command; MAST_DEBUG=1 shows the traceback)"
        )
        sys.exit(EXIT_INTERNAL)
    sys.exit(status if isinstance(status, int) else EXIT_OK)


def _say(line: str) -> None:
    """One line on standard error; nothing if standard error itself is gone."""
    _say_error(lambda: print(line, file=sys.stderr, flush=True))


def _say_error(show: Callable[[], object]) -> None:
    with contextlib.suppress(OSError, ValueError):
        show()


def _silence_stdout() -> None:
    """Point standard output at /dev/null so that the interpreter's final flush is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
