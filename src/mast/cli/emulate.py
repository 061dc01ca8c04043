"""``mast emulate``: a recorded run served as a SICK or Hokuyo scanner would, over TCP."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.root import (
    app,
)
from mast.errors import InputError


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

    \b
    Example: mast emulate sick --from examples/run.bag --port 2111
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
