"""The ``mast`` command line.

Each command loads its inputs, calls one library function and prints or
saves what it returns. Errors the library raises on purpose become one line
on stderr and an exit status: 2 bad input, 3 no fix.
"""

from __future__ import annotations

import sys
import tempfile
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from . import __version__
from .errors import InputError, MastError, NoFixError

EXIT_OK = 0
EXIT_BAD_INPUT = 2
EXIT_NO_FIX = 3

app = typer.Typer(
    name="mast",
    help=(
        "MAST: Mobile Automated Scanner Triangulateration. Fix a 2D laser scanner's "
        "position and azimuth in the mine grid from surveyed wall beacons.\n\n"
        "Exit status: 0 success (a fix), 2 bad input, 3 no fix."
    ),
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
        str, typer.Option("--scenario", help="Scenario name: paper or random.")
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
        bool, typer.Option("--noise/--no-noise", help="Add realistic range noise.")
    ] = False,
) -> None:
    """Simulate a scenario: per scene, beacons.csv, the scans and truth.csv."""
    from .sim import build_scenario, write_scenario

    scenes = build_scenario(scenario, seed, noise=noise)
    written = write_scenario(scenes, out, fmt=fmt.value, scenario=scenario, seed=seed)
    for w in written:
        typer.echo(f"{w.folder}: {w.count} scan(s), survey {w.survey.name}, truth {w.truth.name}")
    typer.echo(f"wrote {sum(w.count for w in written)} scan(s) in {len(written)} scene(s) to {out}")


@app.command()
def demo(
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Keep the simulated files here (default: a temporary folder)."),
    ] = None,
) -> None:
    """Simulate the paper's scenario and show what was written."""
    from .sim import build_scenario, write_scenario

    scenes = build_scenario("paper", 0)
    with tempfile.TemporaryDirectory(prefix="mast-demo-") as tmp:
        target = out if out is not None else Path(tmp)
        written = write_scenario(scenes, target, scenario="paper")
        for scene, w in zip(scenes, written, strict=True):
            typer.echo(f"{scene.name}: {scene.description}")
            typer.echo(
                f"  {w.survey}  ({len(scene.survey)} beacons: {', '.join(scene.survey.ids)})"
            )
            for shot, path in zip(scene.shots, w.scans, strict=True):
                typer.echo(
                    f"  {path.name}  {shot.label:<11} true {shot.pose}  [{shot.scanner.name}]"
                )
        typer.echo(f"wrote {sum(w.count for w in written)} scans to {target}")


def main() -> None:
    """Entry point: run the app, turning MAST's own errors into one line and an exit status."""
    try:
        app(standalone_mode=True)
    except NoFixError as err:
        print(f"mast: {err}", file=sys.stderr)
        sys.exit(EXIT_NO_FIX)
    except InputError as err:
        print(f"mast: error: {err}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except MastError as err:
        print(f"mast: error: {err}", file=sys.stderr)
        sys.exit(EXIT_BAD_INPUT)
    except KeyboardInterrupt:
        print("mast: interrupted", file=sys.stderr)
        sys.exit(130)
