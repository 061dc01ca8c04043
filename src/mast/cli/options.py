"""What the commands share: option types, the scan formats, reading the scans given,
the precisions and a prior from the options, progress lines and signals."""

from __future__ import annotations

import itertools
import math
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager
from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, TypeVar

import typer

from mast.cli.root import (
    MAX_PLAUSIBLE_ANGLE_SIGMA_RAD,
    MAX_PLAUSIBLE_SIGMA_M,
)
from mast.core.noise import DEFAULT_ANGLE_SIGMA_RAD, DEFAULT_RANGE_SIGMA_M, DEFAULT_SURVEY_SIGMA_M
from mast.core.scan import Scan
from mast.errors import InputError

T = TypeVar("T")

if TYPE_CHECKING:
    from mast.core.beacon import Survey
    from mast.io.crs import GridCrs
    from mast.pipeline.locator import LocatorConfig
    from mast.pipeline.tracking import Prior


class SimulatedFormat(StrEnum):
    csv = "csv"
    bag = "bag"
    ros2 = "ros2"
    mcap = "mcap"


class OutputFormat(StrEnum):
    text = "text"
    json = "json"


def load_scans(
    path: Path, *, topic: str | None, range_min: float | None, range_max: float | None
) -> tuple[Iterator[Scan], bool, str | None]:
    """The scans at a path (:func:`mast.io.scans.open_scans`: one for a CSV, a run for a
    bag or a folder of scan CSVs), read one at a time as they are located; whether it is
    a run; and the topic they come from (a bag's)."""
    from mast.io.scans import open_scans

    if path == Path("-"):
        return iter([read_stdin_scan(range_min, range_max)]), False, None
    run = open_scans(path, topic=topic, range_min_m=range_min, range_max_m=range_max)
    if not run.format.sequence:
        return run.scans, False, None
    first = next(run.scans, None)
    if first is None:
        raise InputError("bag holds no LaserScan message on that topic", path=path)
    return itertools.chain([first], run.scans), True, run.topic


def read_stdin_scan(range_min: float | None, range_max: float | None) -> Scan:
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


def parse_near(text: str, radius: float, az_tol_deg: float) -> Prior:
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


def check_range_limits(range_min: float | None, range_max: float | None) -> None:
    for name, value in (("--range-min", range_min), ("--range-max", range_max)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise InputError(f"{name} must be a non-negative number, got {value}")


def check_seconds(option: str, value: float) -> None:
    """A duration option must be a positive, finite number of seconds."""
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{option} must be a positive number of seconds, got {value}")


def grid_crs(text: str | None) -> GridCrs | None:
    """The ``--crs`` given, checked (:func:`mast.io.crs.parse_crs`); None without one."""
    if text is None:
        return None
    from mast.io.crs import parse_crs

    return parse_crs(text, option="--crs")


def default_text(value: float) -> str:
    return f"{value:g}"


BeaconsOption = Annotated[Path, typer.Option("--beacons", "-b", help="Beacon survey CSV.")]
TopicOption = Annotated[str | None, typer.Option("--topic", help="LaserScan topic in a bag.")]
RealDataOption = Annotated[
    Path, typer.Option("--data", help="Folder of real scans (../shared/data).")
]
LogBeaconsOption = Annotated[
    int, typer.Option("--beacon-count", min=2, help="Beacons mounted per log.")
]
#: The old ``--beacons`` of the benchmarks, a count: hidden, kept for a release (:func:`renamed`).
OldBeaconCountOption = Annotated[
    int | None, typer.Option("--beacons", hidden=True, help="Old name of --beacon-count.")
]
DesignSeedOption = Annotated[int, typer.Option("--seed", help="Seed of the designs and the noise.")]
RangeSigmaOption = Annotated[
    float | None,
    typer.Option(
        "--range-sigma",
        help="Range standard deviation, metres "
        f"[default: {default_text(DEFAULT_RANGE_SIGMA_M)}, or the --scanner's].",
    ),
]
AngleSigmaDegOption = Annotated[
    float | None,
    typer.Option(
        "--angle-sigma-deg",
        help="Beam angle standard deviation, degrees "
        f"[default: {default_text(math.degrees(DEFAULT_ANGLE_SIGMA_RAD))}, or the --scanner's].",
    ),
]
#: The old ``--angle-sigma``, in radians: hidden, kept for a release (:func:`angle_sigma_rad`).
AngleSigmaOption = Annotated[
    float | None,
    typer.Option("--angle-sigma", hidden=True, help="Old name: --angle-sigma-deg, in radians."),
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
CrsOption = Annotated[
    str | None,
    typer.Option(
        "--crs",
        help="The grid's coordinate reference system, written into the outputs: an EPSG "
        "code (EPSG:32735), a WKT file, a WKT or PROJ string, or local:NAME for a mine's "
        "local grid [default: none recorded].",
    ),
]
ForceOption = Annotated[
    bool,
    typer.Option("--force", help="Write into an --out folder that holds files already."),
]
SurveySigmaOption = Annotated[
    float | None,
    typer.Option(
        "--survey-sigma",
        help="Standard deviation of a surveyed edge coordinate, metres "
        f"[default: {default_text(DEFAULT_SURVEY_SIGMA_M)}].",
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
    typer.Option(
        "--azimuth-tolerance",
        help="With an azimuth in --near: how far the azimuth may be from it, degrees.",
    ),
]


#: A progress callback of a command: (done, total or None when unknown, a note shown after
#: the count, such as "12 fixed"); what :func:`work_progress` yields on a terminal.
WorkUpdate = Callable[[int, int | None, str], None]


@contextmanager
def work_progress(
    label: str, *, unit: str = "scans", counts: bool = True
) -> Iterator[WorkUpdate | None]:
    """A progress bar on standard error while a command works through a run, a bag or a
    cloud: done of the total where it is known (a bag's message count, a folder's files,
    a cloud's points), the time taken and the time left; None (nothing drawn) unless
    standard error is a terminal, so that a pipe or a log file never receives it.

    ``counts`` shows "done/total unit" (scans); without it a percentage (points). A new
    total (a cloud's next pass) starts the bar and its estimate of the time left again.
    """
    if not sys.stderr.isatty():
        yield None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        ProgressColumn,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    amount: list[ProgressColumn] = (
        [MofNCompleteColumn(), TextColumn(unit)] if counts else [TaskProgressColumn()]
    )
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        *amount,
        TextColumn("{task.fields[note]}"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        task = bar.add_task(label, total=None, note="")
        shown: list[int | None] = [None]

        def update(done: int, total: int | None, note: str = "") -> None:
            if total != shown[0]:
                shown[0] = total
                bar.reset(task, total=total, note=note)
            bar.update(task, completed=done, note=note)

        yield update


@contextmanager
def run_progress(label: str) -> Iterator[Callable[[int, int, int | None], None] | None]:
    """:func:`work_progress` for a run tracked scan by scan: the callback takes (scans so
    far, fixes so far, the run's scans or None), as :func:`mast.runs.run.track_run` calls
    it, and shows the fixes and the scans a second beside the count."""
    with work_progress(label) as bar:
        if bar is None:
            yield None
            return
        start = time.perf_counter()

        def update(scans: int, fixes: int, total: int | None) -> None:
            rate = scans / max(time.perf_counter() - start, 1e-9)
            bar(scans, total, f"{fixes} fixed, {rate:.0f} scans/s")

        yield update


@contextmanager
def signals_as_flag() -> Iterator[tuple[threading.Event, list[int]]]:
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


def renamed(
    value: T | None, old_value: T | None, *, new: str, old: str, default: T | None = None
) -> T | None:
    """The value of an option given by its name ``new`` or, for one release more, by its
    old name ``old`` (a hidden option of the command, forwarded here): the old name
    works with a one-line warning on standard error; both given is bad input.

    ``default`` is the new option's default, for an option that has one: the new name
    counts as given only when its value differs from it.
    """
    if old_value is None:
        return value
    if value is not None and value != default:
        raise InputError(f"{old} is the old name of {new} here: give {new} only")
    typer.echo(
        f"mast: warning: {old} is now {new} here; the old name goes in the next release",
        err=True,
    )
    return old_value


def angle_sigma_rad(degrees: float | None, radians: float | None) -> float | None:
    """The beam angle sigma, radians, from ``--angle-sigma-deg`` (degrees) or the old
    ``--angle-sigma`` (radians, warned of: see :func:`renamed`); None when neither is
    given. Both is bad input; a degree value no scanner has is warned of with its unit."""
    if degrees is not None and radians is not None:
        raise InputError(
            "--angle-sigma is the old name of --angle-sigma-deg (in radians): "
            "give --angle-sigma-deg only"
        )
    if radians is not None:
        typer.echo(
            "mast: warning: --angle-sigma (radians) is now --angle-sigma-deg (degrees): "
            f"--angle-sigma {radians:g} is --angle-sigma-deg {math.degrees(radians):.6g}; "
            "the old name goes in the next release",
            err=True,
        )
        return radians
    if degrees is None:
        return None
    if not (math.isfinite(degrees) and degrees >= 0):
        raise InputError(
            f"--angle-sigma-deg must be a non-negative number of degrees, got {degrees}"
        )
    if degrees > math.degrees(MAX_PLAUSIBLE_ANGLE_SIGMA_RAD):
        typer.echo(
            f"mast: warning: --angle-sigma-deg {degrees:g} degrees is more than any laser "
            "scanner has; it is in degrees (36 arc-seconds is 0.01)",
            err=True,
        )
    return math.radians(degrees)


#: The 3D lidars ``--scanner`` names (their rings and limits are
#: :data:`mast.sim.lidar3d.LIDARS`') and the range sigma (1σ, metres) each is weighted
#: with. Velodyne VLP-16: "±3 cm typical" range accuracy on its data sheet, a bound
#: rather than a sigma, taken as 1.5σ: 2 cm. Ouster OS1-64: range repeatability 1σ
#: ±1.5 cm at SNR above 250 and ±3 cm at SNR 100 on its data sheet; a drift wall a few
#: metres off lies between them: 2 cm. Both are the simulator's default (docs/3d.md).
LIDAR_RANGE_SIGMA_M: dict[str, float] = {"vlp16": 0.02, "os1-64": 0.02}

#: The 3D locator's range sigma when neither ``--range-sigma`` nor ``--scanner`` gives
#: one (:class:`mast.pipeline.locator3d.Locator3DConfig`'s default).
DEFAULT_LIDAR_RANGE_SIGMA_M = 0.02


def lidar_config(cfg: LocatorConfig, defaults: Collection[str]) -> LocatorConfig:
    """The settings a 3D lidar's frames are located with: ``cfg``, its range sigma the one
    given (option, settings file or a 3D ``--scanner``), else
    :data:`DEFAULT_LIDAR_RANGE_SIGMA_M` (a 2D scanner's default is not a 3D lidar's).
    The effective configuration (``config.toml``, each record's ``config_sha256``) is
    made of it, so that ``--config`` gives the same results again."""
    if "range_sigma_m" in defaults:
        return replace(cfg, range_sigma_m=DEFAULT_LIDAR_RANGE_SIGMA_M)
    return cfg


def precisions(
    range_sigma: float | None,
    angle_sigma: float | None,
    scanner: str | None,
    survey_sigma: float | None,
    *,
    angle_sigma_deg: float | None = None,
    base: LocatorConfig | None = None,
    given: Collection[str] = (),
) -> tuple[LocatorConfig, set[str]]:
    """The locator's configuration: ``base`` (a settings file's ``[locator]``, whose keys
    ``given`` names as ``locator.<key>``; defaults without one), then the precisions the
    options give; and which precisions were left at their defaults. ``angle_sigma`` is
    the old ``--angle-sigma`` (radians), ``angle_sigma_deg`` the ``--angle-sigma-deg``
    that replaces it (:func:`angle_sigma_rad`).

    A sigma no scanner or survey has gets a warning naming its unit.
    """
    from mast.pipeline.locator import LocatorConfig
    from mast.sim import scanner_model

    old_angle = angle_sigma
    angle_sigma = angle_sigma_rad(angle_sigma_deg, angle_sigma)
    cfg = LocatorConfig() if base is None else base
    defaults = {"range_sigma_m", "angle_sigma_rad", "survey_sigma_m"}
    defaults -= {key.removeprefix("locator.") for key in given}
    if scanner is not None and scanner in LIDAR_RANGE_SIGMA_M:  # a 3D lidar
        cfg = replace(cfg, range_sigma_m=LIDAR_RANGE_SIGMA_M[scanner])
        defaults -= {"range_sigma_m"}
    elif scanner is not None:
        try:
            noise = scanner_model(scanner).noise()
        except InputError as err:
            raise InputError(
                f"{err.problem}; 3D lidars: {', '.join(LIDAR_RANGE_SIGMA_M)}"
            ) from None
        cfg = replace(cfg, range_sigma_m=noise.range_sigma_m, angle_sigma_rad=noise.angle_sigma_rad)
        defaults -= {"range_sigma_m", "angle_sigma_rad"}
    given_here = {
        "range_sigma_m": ("--range-sigma", range_sigma),
        "angle_sigma_rad": ("--angle-sigma", angle_sigma),
        "survey_sigma_m": ("--survey-sigma", survey_sigma),
    }
    for key, (option, value) in given_here.items():
        if value is None:
            continue
        try:  # LocatorConfig checks the value; its message names the field first
            cfg = replace(cfg, **{key: value})  # type: ignore[arg-type]
        except ValueError as err:
            raise InputError(str(err).replace(key, option, 1)) from None
        defaults.discard(key)
    for name, value, limit, unit, example in (
        ("--range-sigma", range_sigma, MAX_PLAUSIBLE_SIGMA_M, "metres", "10 mm is 0.01"),
        ("--survey-sigma", survey_sigma, MAX_PLAUSIBLE_SIGMA_M, "metres", "3 mm is 0.003"),
        ("--angle-sigma", old_angle, MAX_PLAUSIBLE_ANGLE_SIGMA_RAD, "radians", "0.1° is 0.0017"),
    ):
        if value is not None and value > limit:
            typer.echo(
                f"mast: warning: {name} {value:g} {unit} is more than any laser scanner or "
                f"survey has; it is in {unit} ({example})",
                err=True,
            )
    return cfg, defaults


def warn_loose_edges(survey: Survey, default_m: float) -> None:
    """One warning line when some surveyed edges are far looser than the rest
    (:meth:`~mast.core.beacon.Survey.loose_edges`)."""
    loose = survey.loose_edges(default_m)
    if loose:
        more = f" and {len(loose) - 3} more" if len(loose) > 3 else ""
        typer.echo(
            f"mast: warning: survey edge sigma_m far above the rest: {', '.join(loose[:3])}"
            f"{more}; every beacon's identification widens to the largest (survey them "
            "again, or leave them out)",
            err=True,
        )


@contextmanager
def cell_progress(label: str, unit: str = "cells") -> Iterator[Callable[[int, int], None] | None]:
    """A progress bar over cells (``mast plan``) or inputs (``mast bench fuzz``) on a
    terminal, with the time left (:func:`work_progress`); nothing otherwise."""
    with work_progress(label, unit=unit) as bar:
        if bar is None:
            yield None
            return

        def update(done: int, total: int) -> None:
            bar(done, total, "")

        yield update
