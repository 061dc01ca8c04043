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
        str,
        typer.Argument(
            metavar="KIND",
            help="sick (CoLa-A), hokuyo (SCIP 2.0) or ros2 (a LaserScan topic over DDS).",
        ),
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
    scan_topic: Annotated[
        str, typer.Option("--scan-topic", help="ros2: the LaserScan topic to publish on.")
    ] = "/scan",
    domain_id: Annotated[
        int | None,
        typer.Option(
            "--domain-id",
            help="ros2: the DDS domain [default: $ROS_DOMAIN_ID, else 0].",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Serve a recorded or simulated run as a SICK LMS1xx (CoLa-A) or Hokuyo UST (SCIP 2.0)
    scanner on TCP, at the run's rate, for `mast live` (tests, demos, benchmarks); or,
    as ros2, publish it on a ROS 2 LaserScan topic over DDS as a robot's driver does
    (best effort, stamps as recorded), for `mast ros2`.

    Prints the address served on, then serves until every scan is sent. Exit status 0
    when the run was served, 2 for bad input, 130 when interrupted.

    \b
    Example: mast emulate sick --from examples/run.bag --port 2111
    """
    from mast.live.emulate import Emulator, EmulatorFaults
    from mast.live.sources import read_run

    if hz is not None and not (math.isfinite(hz) and hz > 0):
        raise InputError(f"--hz must be a positive number, got {hz}")
    if kind == "ros2":
        if drop_after or stall_after or corrupt_every:
            raise InputError("ros2: the faults (--drop-after, ...) are TCP scanners' own")
        _publish(run, scan_topic, domain_id, hz)
        return
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


#: After a subscriber matched, how long its side takes to learn of the writer (discovery
#: is not symmetric in time): a scan sent before would be lost to it, seconds.
SETTLE_S = 0.3


def _publish(run: Path, topic: str, domain_id: int | None, hz: float | None) -> None:
    """``mast emulate ros2``: the run's scans published on ``topic`` at its rate."""
    from mast.cli.options import signals_as_flag
    from mast.live.ros2 import ScanPublisher, leave, participant, play, ros2_domain
    from mast.live.sources import read_run

    domain = ros2_domain() if domain_id is None else domain_id
    scans = read_run(run)
    dp = participant(domain)
    publisher = ScanPublisher(dp, topic)
    try:
        with signals_as_flag() as (interrupt, caught):
            # best effort: a scan sent before anyone listens is lost, so wait for one
            typer.echo(
                f"mast: waiting for a subscriber of {topic} in DDS domain {domain}", err=True
            )
            while not publisher.matched() and not interrupt.wait(0.05):
                pass
            interrupt.wait(SETTLE_S)  # its reader learns of this writer a moment later
            typer.echo(f"mast: publishing {run} on {topic}", err=True)
            sent = play(scans, publisher, stop=interrupt, hz=hz)
    finally:
        leave(dp)
    typer.echo(f"mast: published {sent} scans", err=True)
    if interrupt.is_set():
        raise typer.Exit(128 + caught[0])
