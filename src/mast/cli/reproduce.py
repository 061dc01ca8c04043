"""``mast reproduce paper``: the paper's experiments beside its Table 2."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from mast.cli.root import (
    CONTEXT,
    app,
)
from mast.io.outputs import check_output_folder

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
