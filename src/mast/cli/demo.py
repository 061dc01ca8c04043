"""``mast demo``: the paper's layout simulated and located, beside its Table 2."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.root import (
    app,
)
from mast.io.outputs import check_output_folder


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
