"""``mast plan`` as one call: read the drift, predict the layout (and suggest beacons), write
the outputs; as :mod:`mast.runs.run` is for ``mast track``."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mast.core.beacon import Survey
from mast.errors import OutputError
from mast.io.beacons_csv import write_survey
from mast.io.crs import GridCrs
from mast.io.drift import read_drift
from mast.plan.predict import Plan, PlanSettings, predict
from mast.plan.suggest import suggest
from mast.sim.scanner import ScannerModel

__all__ = ["PLAN_FILES", "PlanResult", "run_plan"]

#: The files ``mast plan`` writes into its folder (and proposed_beacons.csv with --suggest).
PLAN_FILES = ("plan.csv", "plan.png", "plan.dxf", "summary.json")


@dataclass(frozen=True, eq=False)
class PlanResult:
    """The layout predicted (after any suggested beacons), the one before them, the
    summary's figures and the files written."""

    plan: Plan
    before: Plan | None
    figures: dict[str, Any]
    written: tuple[Path, ...]


def run_plan(
    drift_path: Path,
    survey: Survey,
    scanner: ScannerModel,
    settings: PlanSettings,
    out: Path,
    *,
    layers: tuple[str, ...] = (),
    suggest_count: int = 0,
    candidate_step_m: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    echo: Callable[[str], None] = print,
    crs: GridCrs | None = None,
) -> PlanResult:
    """Read the drift, predict (and improve) the layout, write the outputs into ``out``;
    ``summary.json`` names the grid's ``crs`` when given."""
    from mast.plan.outputs import (
        summary,
        write_plan_csv,
        write_plan_dxf,
        write_plan_png,
        write_summary,
    )

    drift = read_drift(drift_path, layers=layers)
    plan = predict(drift, survey, scanner, settings, progress=progress)
    before = None
    written = []
    if suggest_count > 0:
        found = suggest(
            plan,
            suggest_count,
            candidate_step_m=candidate_step_m,
            progress=lambda text: echo(f"suggest: {text}"),
        )
        before, plan = plan, found.after
        path = out / "proposed_beacons.csv"
        try:
            write_survey(path, plan.survey)
        except OSError as err:
            raise OutputError(f"cannot write: {err.strerror or err}", path=path) from None
        written.append(path)
    figures = summary(plan, before=before)
    if crs is not None:
        figures["crs"] = crs.record()
    write_plan_csv(out / "plan.csv", plan)
    title = f"{drift_path.name}: {scanner.name}, {len(plan.survey)} beacons"
    if plan.proposed:
        title += f" ({len(plan.proposed)} proposed)"
    write_plan_png(out / "plan.png", plan, title=title)
    write_plan_dxf(out / "plan.dxf", plan)
    write_summary(out / "summary.json", figures)
    written += [out / name for name in PLAN_FILES]
    return PlanResult(plan, before, figures, tuple(written))
