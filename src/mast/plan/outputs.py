"""What ``mast plan`` writes: plan.csv, plan.png, plan.dxf and summary.json."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core.quantiles import chi2_ppf
from mast.io.dxf import add_dxf_beacons, new_dxf, save_dxf
from mast.io.outputs import save_figure, write_bytes
from mast.pipeline.adjustment import position_ellipse
from mast.plan.predict import Plan

__all__ = [
    "PLAN_COLUMNS",
    "SIGMA_LEVELS_M",
    "longest_gap_m",
    "summary",
    "write_plan_csv",
    "write_plan_dxf",
    "write_plan_png",
    "write_summary",
]

#: plan.csv's columns: the issue's contract first, then more detail.
PLAN_COLUMNS = (
    "easting",
    "northing",
    "heading_deg",
    "beacons_in_view",
    "owed",
    "fix_rate",
    "sigma_easting_m",
    "sigma_northing_m",
    "sigma_azimuth_deg",
    "station_m",
    "offset_m",
    "panels_in_view",
    "beacons",
    "scans",
    "wrong_fixes",
    "ellipse95_major_m",
    "ellipse95_minor_m",
    "ellipse95_azimuth_deg",
)

#: Contours of the position sigma drawn in plan.dxf (those within the plan's range).
SIGMA_LEVELS_M = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)

#: Height of the beacons' ids in plan.dxf, metres.
DXF_TEXT_HEIGHT_M = 0.3
#: DXF layers and their ACI colours.
DXF_LAYERS = {
    "MAST_WALLS": 8,
    "MAST_BEACONS": 3,
    "MAST_PROPOSED": 6,
    "MAST_CENTRELINE": 9,
    "MAST_NO_FIX_ALONG": 1,
    "MAST_NO_FIX_AGAINST": 30,
}


def _ellipse(cov: NDArray[np.float64]) -> tuple[float, float, float]:
    """95 % position ellipse: semi-major, semi-minor (m) and the major axis' azimuth (deg)."""
    if not np.all(np.isfinite(cov[:2, :2])):
        return math.nan, math.nan, math.nan
    e = position_ellipse(cov, math.sqrt(chi2_ppf(0.95, 2)), 0.95)
    return e.semi_major_m, e.semi_minor_m, math.degrees(e.azimuth_rad)


def _num(value: float, digits: int = 6) -> str:
    return "" if not math.isfinite(value) else f"{value:.{digits}f}"


def write_plan_csv(path: Path, plan: Plan) -> int:
    """One row per planned cell and heading (:data:`PLAN_COLUMNS`); returns the rows."""
    grid = plan.grid
    cov = plan.covariance
    heading = np.degrees(plan.headings_rad())
    rate = plan.fix_rate
    lines = [",".join(PLAN_COLUMNS)]
    for r, c in zip(*np.nonzero(grid.inside), strict=True):
        for h in (0, 1):
            view = plan.views[r, c, h]
            k = cov[r, c, h]
            sd = np.sqrt(np.diag(k)) if np.all(np.isfinite(np.diag(k))) else np.full(3, np.nan)
            major, minor, az = _ellipse(k)
            e, n = grid.xy[r, c]
            lines.append(
                ",".join(
                    [
                        f"{e:.3f}",
                        f"{n:.3f}",
                        f"{heading[r, h]:.3f}",
                        str(len(view.panels)),
                        "1" if view.owed else "0",
                        _num(float(rate[r, c, h]), 3),
                        _num(float(sd[0])),
                        _num(float(sd[1])),
                        _num(math.degrees(float(sd[2])), 7),
                        f"{grid.stations_m[r]:.3f}",
                        f"{grid.offsets_m[c]:.3f}",
                        str(sum(len(p) for p in view.panels.values())),
                        " ".join(view.beacons),
                        str(int(plan.scans[r, c, h])),
                        str(int(plan.wrong[r, c, h])),
                        _num(major),
                        _num(minor),
                        _num(az, 2),
                    ]
                )
            )
    write_bytes(path, ("\n".join(lines) + "\n").encode("utf-8"))
    return len(lines) - 1


def longest_gap_m(covered: NDArray[np.bool_], step_m: float) -> float:
    """Longest run of uncovered stations (one row per station), in metres of centreline."""
    return max((last - first + 1 for first, last in _stretches(~covered)), default=0) * step_m


def summary(plan: Plan, *, before: Plan | None = None) -> dict[str, Any]:
    """The plan's figures (``summary.json``).

    ``covered_share`` is the share of the centreline's stations and both
    headings where the locator fixes at least ``min_fix_rate`` of the scans
    (and, with a target, the bound's 1-sigma position ellipse is within it);
    ``longest_gap_m`` the longest stretch of centreline without one, in either
    heading; ``worst_sigma_m`` the largest semi-major axis of the 1-sigma
    position ellipse over every covered cell (None when none is).
    """
    grid = plan.grid
    c = grid.centre
    covered = plan.covered
    line = covered[:, c, :]
    sig = plan.sigma_position
    worst = float(np.max(sig[covered])) if np.any(covered) else None
    inside = plan.inside
    out: dict[str, Any] = {
        "covered_share": round(float(np.mean(line)), 4),
        "worst_sigma_m": None if worst is None else round(worst, 6),
        "longest_gap_m": round(max(longest_gap_m(line[:, h], grid.step_m) for h in (0, 1)), 3),
        "fix_share": round(float(np.mean(plan.has_fix[:, c, :])), 4),
        "owed_share": round(float(np.mean(plan.owed[:, c, :])), 4),
        "covered_cells_share": round(int(np.sum(covered)) / max(1, int(np.sum(inside))), 4),
        "wrong_fixes": int(plan.wrong.sum()),
        "centreline_length_m": round(grid.length_m, 3),
        "stations": len(grid.stations_m),
        "cells": int(np.sum(grid.inside)),
        "scans_located": int(plan.scans.sum()),
        "step_m": grid.step_m,
        "across_step_m": plan.settings.across,
        "margin_m": plan.settings.margin_m,
        "scans_per_cell": plan.settings.scans_per_cell,
        "min_fix_rate": plan.settings.min_fix_rate,
        "target_sigma_m": plan.settings.target_sigma_m,
        "roughness_m": plan.settings.roughness_m,
        "seed": plan.settings.seed,
        "scanner": {
            "name": plan.scanner.name,
            "fov_deg": plan.scanner.fov_deg,
            "resolution_deg": plan.scanner.resolution_deg,
            "range_sigma_m": plan.scanner.range_sigma_m,
            "range_max_m": plan.scanner.range_max_m,
        },
        "beacons": [b.id for b in plan.survey],
        "proposed_beacons": list(plan.proposed),
    }
    if before is not None:
        out["before"] = {
            k: v
            for k, v in summary(before).items()
            if k in ("covered_share", "worst_sigma_m", "longest_gap_m", "fix_share", "beacons")
        }
    return out


def write_summary(path: Path, figures: dict[str, Any]) -> None:
    write_bytes(path, (json.dumps(figures, indent=2) + "\n").encode("utf-8"))


def _mapped(plan: Plan) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(s, o) fix rate over both headings, and the larger position sigma of the headings
    with a fix (NaN where neither has one, and outside the drift)."""
    rate = np.mean(plan.fix_rate, axis=2)
    sig = np.max(np.where(plan.has_fix, plan.sigma_position, -np.inf), axis=2)
    sig = np.where(np.isfinite(sig), sig, np.nan)
    rate = np.where(plan.grid.inside, rate, np.nan)
    return rate, np.where(plan.grid.inside, sig, np.nan)


def write_plan_png(path: Path, plan: Plan, *, title: str = "") -> None:
    """Availability and precision over the drift (the worse of the two headings)."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    grid = plan.grid
    rate, sig = _mapped(plan)
    pts = np.vstack([w.points for w in plan.drift.walls])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    span = np.maximum(hi - lo, 1.0)
    aspect = float(span[1] / span[0])
    width = 11.0
    panel_h = float(np.clip(width * aspect, 2.2, 7.0))
    fig = Figure(figsize=(width, 2 * panel_h + 1.2), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True, sharey=True)
    corners = grid.corners()
    x, y = corners[..., 0], corners[..., 1]
    coords = FuncFormatter(lambda v, _: f"{v:,.0f}".replace(",", "\u2009"))
    sig_mm = sig * 1000.0
    vmax = float(np.nanmax(sig_mm)) if np.any(np.isfinite(sig_mm)) else 10.0
    for ax, data, cmap, label, vmin, top in (
        (axes[0], rate, "RdYlGn", "fix rate (both headings)", 0.0, 1.0),
        (axes[1], sig_mm, "viridis", "position σ, semi-major axis (mm)", 0.0, max(vmax, 1.0)),
    ):
        ax.set_facecolor("0.93")
        mesh = ax.pcolormesh(
            x, y, np.ma.masked_invalid(data), cmap=cmap, vmin=vmin, vmax=top, shading="flat"
        )
        fig.colorbar(mesh, ax=ax, label=label, shrink=0.9)
        for w in plan.drift.walls:
            ax.plot(w.points[:, 0], w.points[:, 1], color="0.15", lw=1.2)
        ax.plot(grid.centreline[:, 0], grid.centreline[:, 1], color="0.4", lw=0.6, ls="--")
        for b in plan.survey:
            new = b.id in plan.proposed
            colour = "tab:purple" if new else "tab:blue"
            ax.plot(b.edges[:, 0], b.edges[:, 1], color=colour, lw=2.5, solid_capstyle="butt")
            ax.annotate(
                b.id + (" (new)" if new else ""),
                b.centroid,
                fontsize=7,
                color=colour,
                xytext=(0, 6),
                textcoords="offset points",
                ha="center",
            )
        ax.set_aspect("equal")
        ax.xaxis.set_major_formatter(coords)
        ax.yaxis.set_major_formatter(coords)
        ax.set_ylabel("Northing (m)")
        ax.grid(True, color="0.8", lw=0.4)
    axes[0].set_title("share of simulated scans located, both headings", fontsize=9)
    axes[1].set_title(
        "Cramér–Rao position σ where a heading has a fix (the worse of them; grey: no fix)",
        fontsize=9,
    )
    axes[1].set_xlabel("Easting (m)")
    if title:
        fig.suptitle(title, fontsize=10)
    save_figure(fig, path, dpi=130)


def _stretches(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Runs of True as (first, last) indices."""
    out = []
    start = None
    for k, f in enumerate(flags):
        if f and start is None:
            start = k
        if not f and start is not None:
            out.append((start, k - 1))
            start = None
    if start is not None:
        out.append((start, len(flags) - 1))
    return out


def _contours(plan: Plan, levels: Sequence[float]) -> dict[float, list[NDArray[np.float64]]]:
    import contourpy

    _, sig = _mapped(plan)
    z = np.ma.masked_invalid(sig)
    if z.count() < 4 or min(z.shape) < 2:
        return {}
    gen = contourpy.contour_generator(plan.grid.xy[..., 0], plan.grid.xy[..., 1], z)
    out: dict[float, list[NDArray[np.float64]]] = {}
    for level in levels:
        lines = [np.asarray(p) for p in gen.lines(level) if len(p) >= 2]
        if lines:
            out[level] = lines
    return out


def write_plan_dxf(path: Path, plan: Plan) -> None:
    """plan.dxf: walls, beacons (surveyed and proposed), the centreline, the stretches of
    centreline without a fix (one layer per heading: along the centreline's direction and
    against it), and the position sigma's contours, one layer per level
    (``MAST_SIGMA_005MM`` ...). DXF R2010, metres, full doubles."""
    grid = plan.grid
    doc, msp = new_dxf(DXF_LAYERS)
    for w in plan.drift.walls:
        msp.add_lwpolyline(w.points.tolist(), dxfattribs={"layer": "MAST_WALLS"})
    proposed = [b for b in plan.survey if b.id in plan.proposed]
    surveyed = [b for b in plan.survey if b.id not in plan.proposed]
    add_dxf_beacons(msp, surveyed, "MAST_BEACONS", text_height_m=DXF_TEXT_HEIGHT_M)
    add_dxf_beacons(msp, proposed, "MAST_PROPOSED", text_height_m=DXF_TEXT_HEIGHT_M)
    msp.add_lwpolyline(grid.centreline.tolist(), dxfattribs={"layer": "MAST_CENTRELINE"})
    line_s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(grid.centreline, axis=0).T))])
    stretches = [
        (layer, run)
        for h, layer in enumerate(("MAST_NO_FIX_ALONG", "MAST_NO_FIX_AGAINST"))
        for run in _stretches(~plan.has_fix[:, grid.centre, h])
    ]
    for layer, (first, last) in stretches:
        s0 = max(0.0, grid.stations_m[first] - grid.step_m / 2)
        s1 = min(line_s[-1], grid.stations_m[last] + grid.step_m / 2)
        inner = (line_s > s0) & (line_s < s1)
        pts = np.vstack(
            [
                [np.interp(s0, line_s, grid.centreline[:, k]) for k in (0, 1)],
                grid.centreline[inner],
                [np.interp(s1, line_s, grid.centreline[:, k]) for k in (0, 1)],
            ]
        )
        msp.add_lwpolyline(pts.tolist(), dxfattribs={"layer": layer})
    for level, lines in _contours(plan, SIGMA_LEVELS_M).items():
        name = f"MAST_SIGMA_{level * 1000:03.0f}MM" if level >= 0.001 else "MAST_SIGMA"
        if name not in doc.layers:
            doc.layers.add(name, color=5)
        for p in lines:
            msp.add_lwpolyline(p.tolist(), dxfattribs={"layer": name})
    save_dxf(doc, path)
