"""The ``mast`` program's root: the Typer application every command module registers on,
the exit statuses, and :func:`main`, through which every way a run can end is one line
and a documented status."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Callable
from typing import Annotated

import typer

from mast import __version__
from mast.errors import MastError, NoFixError, OutputError, describe, shorten

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
            silence_stdout()
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
        _say(f"mast: error: {describe(err, 80)}")
        sys.exit(EXIT_CANNOT_WRITE)
    except MastError as err:  # InputError and the rest: what was given is wrong
        _say(f"mast: error: {describe(err, 80)}")
        sys.exit(EXIT_BAD_INPUT)
    except BrokenPipeError:
        # The reader of standard output went away (``mast locate ... | head``): stop
        # quietly, as command-line tools do, with the status of a write that failed.
        silence_stdout()
        sys.exit(EXIT_CANNOT_WRITE)
    except OSError as err:
        silence_stdout()
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


def silence_stdout() -> None:
    """Point standard output at /dev/null so that the interpreter's final flush is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
