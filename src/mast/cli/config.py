"""``mast config``: the settings a command would run with, as the TOML file ``--config``
reads (the defaults, or a settings file checked and completed)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.root import app
from mast.cli.settings import ConfigOption, effective, read_config


class Command(StrEnum):
    locate = "locate"
    track = "track"
    live = "live"
    ros2 = "ros2"


@app.command()
def config(
    command: Annotated[
        Command,
        typer.Option("--for", case_sensitive=False, help="The command whose settings to print."),
    ] = Command.track,
    config: ConfigOption = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write the settings to this file instead of standard output."),
    ] = None,
) -> None:
    """Print the settings a command runs with, as a TOML file for --config: every
    setting with its default, or those of a --config file (checked, and completed with
    the defaults it leaves out). Edit a copy and give it to locate, track, live or ros2 with
    --config; their JSON records name it by the SHA-256 printed in its first lines.

    Example: mast config --for track --out site.toml
    """
    tables, _ = read_config(config, command.value)
    settings = effective(tables, command.value)
    if out is None:
        typer.echo(settings.text, nl=False)
        return
    from mast.io.outputs import check_output_file

    check_output_file(
        out, suffixes=(".toml",), option="--out", inputs=[] if config is None else [config]
    )
    settings.write(out)
