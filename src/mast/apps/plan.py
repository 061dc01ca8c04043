"""``mast plan``: predict a layout over a drift, suggest beacons, write the four outputs."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from mast.core.beacon import Survey
from mast.errors import OutputError
from mast.io.beacons_csv import write_survey
from mast.io.drift import read_drift
from mast.plan.predict import Plan, PlanSettings, predict
from mast.plan.suggest import suggest
from mast.sim.scanner import ScannerModel

__all__ = ["PLAN_FILES", "PlanResult", "run_plan"]

#: The files ``mast plan`` writes into its folder (and proposed_beacons.csv with --suggest).
PLAN_FILES = ("plan.csv", "plan.png", "plan.dxf", "summary.json")


@dataclass(frozen=True, eq=False)
class PlanResult:
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
) -> PlanResult:
    """Read the drift, predict (and improve) the layout, write the outputs into ``out``."""
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
    write_plan_csv(out / "plan.csv", plan)
    title = f"{drift_path.name}: {scanner.name}, {len(plan.survey)} beacons"
    if plan.proposed:
        title += f" ({len(plan.proposed)} proposed)"
    write_plan_png(out / "plan.png", plan, title=title)
    write_plan_dxf(out / "plan.dxf", plan)
    write_summary(out / "summary.json", figures)
    written += [out / name for name in PLAN_FILES]
    return PlanResult(plan, before, figures, tuple(written))


def scanner_for(
    name: str | None,
    *,
    fov_deg: float | None,
    resolution_deg: float | None,
    range_sigma_m: float | None,
    range_max_m: float | None,
    angle_sigma_rad: float | None,
) -> ScannerModel:
    """A named scanner model with any explicit figure replacing its own, or one built from
    the explicit figures (field of view and resolution required)."""
    from mast.core.noise import DEFAULT_RANGE_SIGMA_M
    from mast.errors import InputError
    from mast.sim.scanner import scanner_model

    options = {
        "fov_deg": fov_deg,
        "resolution_deg": resolution_deg,
        "range_sigma_m": range_sigma_m,
        "range_max_m": range_max_m,
        "angle_sigma_rad": angle_sigma_rad,
    }
    given: dict[str, float] = {k: v for k, v in options.items() if v is not None}
    if name is not None:
        model = scanner_model(name)
        return replace(model, name=model.name if not given else model.name + "-custom", **given)
    if fov_deg is None or resolution_deg is None:
        raise InputError(
            "give --scanner NAME (see mast scanners) or the scanner's --fov and --resolution"
        )
    given.setdefault("range_sigma_m", DEFAULT_RANGE_SIGMA_M)
    return ScannerModel("custom", **given)
