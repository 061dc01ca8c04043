"""What ``mast georef`` writes: the georeferenced cloud, the transformation, the beacons
found, a report a surveyor signs (text and HTML) and a plan view.

``transform.json`` is published as ``docs/transform.schema.json``.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast import __version__
from mast.cloud.detect import BEACON_DENSITY_M2
from mast.cloud.drift import DriftCorrection
from mast.cloud.georef import SOUGHT, FoundBeacon, Georef, explain_missing, grid_origin
from mast.core.stats import variance_bounds
from mast.io.atomic import atomic_open, write_atomic
from mast.io.crs import GridCrs
from mast.report.html import CSS, axis_label, escape, inline_svg, new_figure, plot_origin

__all__ = ["ACCURACY_CLASSES", "Outputs", "accuracy_class", "write_outputs"]

#: ICSM SP1 (v1.7) horizontal classes: the 95 % semi-major axis, or a check's
#: misclose, may be at most ``c (d + 0.2)`` mm with ``d`` in km.
ACCURACY_CLASSES: tuple[tuple[str, float], ...] = (
    ("3A", 1.0),
    ("2A", 3.0),
    ("A", 7.5),
    ("B", 15.0),
    ("C", 30.0),
    ("D", 50.0),
    ("E", 100.0),
)

#: Points kept for the plan view (evenly thinned while the cloud is written).
PLAN_POINTS = 200_000


@dataclass(frozen=True, slots=True)
class Outputs:
    cloud: Path | None
    transform: Path | None
    beacons: Path
    report_txt: Path
    report_html: Path
    plan: Path | None
    points: int


def accuracy_class(misclose_m: float, distance_m: float) -> str | None:
    """The tightest ICSM SP1 class whose allowance ``c (d + 0.2)`` mm holds ``misclose_m``
    over ``distance_m``; ``None`` when even class E does not."""
    allowed = (distance_m / 1000.0 + 0.2) / 1000.0
    for name, c in ACCURACY_CLASSES:
        if misclose_m <= c * allowed:
            return name
    return None


def _mm(v: float) -> str:
    return "" if not math.isfinite(v) else f"{1000.0 * v:.1f}"


def _before_after(result: Georef, drift: DriftCorrection | None) -> dict[str, dict[str, Any]]:
    """Per found beacon: residuals (E, N, Z per edge) of the rigid solution and, with a
    drift correction, after it."""
    sol = result.solution
    out: dict[str, dict[str, Any]] = {}
    if sol is None:
        return out
    checks = {c.beacon: c for c in result.checks}
    for fb in result.beacons:
        if fb.obs is None:
            continue
        o = fb.obs
        k = len(o.edges)
        z = o.top if result.heights else 0.0
        moved = sol.transformation.apply(np.column_stack([o.cloud_xy, np.full(k, z)]))
        grid = np.column_stack([o.grid_xy, np.full(k, o.grid_top if result.heights else np.nan)])
        before = moved - grid
        rec: dict[str, Any] = {"fitted": moved, "before": before}
        if fb.beacon in sol.w:
            rec["w"] = float(np.max(np.abs(sol.w[fb.beacon])))
        if fb.beacon in checks:
            rec["w"] = checks[fb.beacon].max_abs_w
        if drift is not None and o.time is not None:
            after_pts = drift.at_beacon(o)
            rec["fitted"] = after_pts
            rec["after"] = after_pts - grid
        out[fb.beacon] = rec
    return out


def write_outputs(
    result: Georef,
    out: Path,
    *,
    progress: Callable[[str, int, int], None] | None = None,
    survey_file: str = "",
    crs: GridCrs | None = None,
) -> Outputs:
    """Write everything into ``out``; a refusal writes only the beacons and the reports.
    The grid's ``crs`` (``--crs``), given, goes into the cloud, ``transform.json`` and
    the reports."""
    drift = result.drift
    beacons = explain_missing(result)
    # refused: no fitted coordinates or residuals from a solution that is not given
    res = _before_after(result, drift) if result.refusal is None else {}
    sample: list[NDArray[np.float64]] = []
    cloud_path = transform_path = plan_path = None
    svg: str | None = None
    for stale in ("georeferenced.laz", "transform.json", "plan.png"):
        # a refusal must not leave an earlier run's result beside its report
        (out / stale).unlink(missing_ok=True)
    written = 0
    if result.solution is not None and result.refusal is None:
        trans = result.solution.transformation
        stride = max(1, result.cloud.count // PLAN_POINTS)

        def move(xyz: NDArray[np.float64], t: NDArray[np.float64] | None) -> NDArray[np.float64]:
            if drift is not None:
                if t is None:
                    raise ValueError("drift correction needs point times")
                g = drift.apply(xyz, t)
            else:
                g = trans.apply(xyz)
            sample.append(g[::stride, :2].copy())
            if progress:
                progress("writing", sum(len(s) for s in sample) * stride, result.cloud.count)
            return g

        cloud_path = out / "georeferenced.laz"
        written = result.cloud.write_georeferenced(
            cloud_path, move, grid_origin(result), result.config.detect.chunk_points, crs=crs
        )
        transform_path = out / "transform.json"
        write_atomic(
            transform_path,
            (json.dumps(transform_record(result, drift, res, crs=crs), indent=2) + "\n").encode(),
        )
        plan_path = out / "plan.png"
        pts = np.concatenate(sample) if sample else np.zeros((0, 2))
        plan = _plan_figure(result, beacons, res, pts, drift)
        plan.savefig(plan_path, dpi=130)
        svg = _svg_of(plan)
    beacons_path = out / "beacons_found.csv"
    _write_beacons(beacons_path, result, beacons, res)
    text = report_text(result, beacons, res, drift, survey_file=survey_file, crs=crs)
    txt_path = out / "report.txt"
    write_atomic(txt_path, text.encode("utf-8"))
    html_path = out / "report.html"
    write_atomic(html_path, report_html(text, svg, result).encode("utf-8"))
    return Outputs(
        cloud_path, transform_path, beacons_path, txt_path, html_path, plan_path, written
    )


def transform_record(
    result: Georef,
    drift: DriftCorrection | None,
    res: dict[str, dict[str, Any]],
    *,
    crs: GridCrs | None = None,
) -> dict[str, Any]:
    """The ``transform.json`` object (docs/transform.schema.json); ``crs`` (the grid's,
    :meth:`GridCrs.record`) only when given."""
    sol = result.solution
    assert sol is not None
    t = sol.transformation
    sig = np.sqrt(np.maximum(np.diag(t.covariance), 0.0))
    roles: dict[str, list[str]] = {"control": [], "check": [], "excluded": []}
    for fb in result.beacons:
        if fb.role in roles:
            roles[fb.role].append(fb.beacon)
    rec: dict[str, Any] = {
        "model": "4-parameter" if t.model == "4" else "helmert7",
        "heights_controlled": result.heights,
        "parameters": {n: float(v) for n, v in zip(t.names, t.params, strict=True)},
        "sigmas": {n: float(s) for n, s in zip(t.names, sig, strict=True)},
        "covariance": {"order": list(t.names), "matrix": t.covariance.tolist()},
        "rotation_deg": t.rotation_deg,
        "scale": t.scale,
        "centre_cloud": t.centre.tolist(),
        "matrix": t.matrix().tolist(),
        "reference_variance": sol.reference_variance,
        "dof": sol.dof,
        "chi2_test": sol.chi2_test,
        "chi2_bounds": list(sol.chi2_bounds),
        "sigmas_scaled": sol.scaled,
        "survey_sigma_m": result.config.survey_sigma_m,
        **(
            {"survey_sigmas": result.survey.sigma_text(result.config.survey_sigma_m)}
            if result.survey.edge_sigmas().size
            else {}
        ),
        "beacons": roles,
        "checks": [
            {
                "beacon": c.beacon,
                "horizontal_m": c.horizontal_m,
                "vertical_m": float(np.nanmax(np.abs(c.residuals[:, 2])))
                if result.heights
                else None,
                "max_abs_w": c.max_abs_w,
                "passed": not c.failed,
            }
            for c in result.checks
        ],
        "drift_correction": None,
        "cloud": str(result.cloud.path),
        "points": result.cloud.count,
        "mast_version": __version__,
        "computed_utc": datetime.now(tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    if crs is not None:
        rec["crs"] = crs.record()
    if drift is not None:
        after = [
            float(np.max(np.hypot(r["after"][:, 0], r["after"][:, 1])))
            for b, r in res.items()
            if "after" in r and b in roles["check"]
        ]
        rec["drift_correction"] = {
            "drift_per_m": drift.drift,
            "keyframe_step_m": drift.step_m,
            "keyframes": int(drift.time.size),
            "check_horizontal_after_m": after,
            "beacon_tests": [
                {
                    "beacon": t.beacon,
                    "role": t.role,
                    "statistic": t.statistic,
                    "dof": t.dof,
                    "critical": t.critical,
                    "passed": not t.failed,
                }
                for t in drift.tests
            ],
            "excluded": list(drift.excluded),
            "statistic_per_dof": drift.statistic_per_dof
            if math.isfinite(drift.statistic_per_dof)
            else None,
        }
    return rec


def _write_beacons(
    path: Path, result: Georef, beacons: list[FoundBeacon], res: dict[str, dict[str, Any]]
) -> None:
    cols = [
        "beacon",
        "role",
        "points",
        "edge",
        "cloud_x",
        "cloud_y",
        "cloud_top_z",
        "grid_easting",
        "grid_northing",
        "grid_elevation",
        "fitted_easting",
        "fitted_northing",
        "fitted_elevation",
        "residual_e_m",
        "residual_n_m",
        "residual_z_m",
        "residual_e_after_m",
        "residual_n_after_m",
        "residual_z_after_m",
        "max_abs_w",
        "why",
    ]
    with atomic_open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for fb in beacons:
            o = fb.obs
            if o is None:
                w.writerow([fb.beacon, fb.role, 0, *[""] * (len(cols) - 4), fb.why])
                continue
            r = res.get(fb.beacon, {})
            for i, e in enumerate(o.edges):
                before = r.get("before")
                after = r.get("after")
                fitted = r.get("fitted")

                def f(a: Any, j: int, i: int = i) -> str:
                    return "" if a is None or not math.isfinite(a[i, j]) else f"{a[i, j]:.4f}"

                w.writerow(
                    [
                        fb.beacon,
                        fb.role,
                        o.points,
                        e,
                        f"{o.cloud_xy[i, 0]:.4f}",
                        f"{o.cloud_xy[i, 1]:.4f}",
                        f"{o.top:.4f}",
                        f"{o.grid_xy[i, 0]:.4f}",
                        f"{o.grid_xy[i, 1]:.4f}",
                        "" if not math.isfinite(o.grid_top) else f"{o.grid_top:.4f}",
                        f(fitted, 0),
                        f(fitted, 1),
                        f(fitted, 2),
                        f(before, 0),
                        f(before, 1),
                        f(before, 2),
                        f(after, 0),
                        f(after, 1),
                        f(after, 2),
                        "" if "w" not in r else f"{r['w']:.2f}",
                        fb.why,
                    ]
                )


def _density(density_m2: float) -> str:
    """The walls' density, and whether beacons can be found at it."""
    if not math.isfinite(density_m2):
        return "not measured (too few points between the floor and the roof)"
    text = f"{density_m2:.0f} points/m² (beacons need about {BEACON_DENSITY_M2:.0f})"
    return text + (": TOO SPARSE for beacons" if density_m2 < BEACON_DENSITY_M2 else "")


def _class_line(result: Georef, res: dict[str, dict[str, Any]], key: str) -> str:
    """The class the check beacons' horizontal misclosures reach, each over its distance
    to the nearest control beacon."""
    controls = list(result.controls)
    checks = [fb for fb in result.beacons if fb.role == "check" and fb.obs is not None]
    if not checks or not controls:
        return "no check beacon: the class is not tested (give --check)"
    worst: str | None = "3A"
    names = [n for n, _ in ACCURACY_CLASSES]
    evaluated = 0
    for fb in checks:
        assert fb.obs is not None
        r = res.get(fb.beacon, {}).get(key)
        if r is None:
            continue
        evaluated += 1
        mis = float(np.max(np.hypot(r[:, 0], r[:, 1])))
        c = fb.obs.grid_xy.mean(axis=0)
        d = min(float(np.hypot(*(o.grid_xy.mean(axis=0) - c))) for o in controls)
        cls = accuracy_class(mis, d)
        if cls is None or worst is None:
            worst = None
        elif names.index(cls) > names.index(worst):
            worst = cls
    if evaluated == 0:
        return "no check beacon could be compared: the class is not tested"
    if worst is None:
        return "below ICSM SP1 class E (a check misclosure is beyond 100 mm x (d + 0.2 km))"
    return (
        f"ICSM SP1 class {worst} (horizontal: every check beacon's misclosure within "
        f"c (d + 0.2) mm, d its distance in km from the nearest control beacon)"
    )


def report_text(
    result: Georef,
    beacons: list[FoundBeacon],
    res: dict[str, dict[str, Any]],
    drift: DriftCorrection | None,
    *,
    survey_file: str = "",
    crs: GridCrs | None = None,
) -> str:
    """The adjustment report as plain text (the HTML page shows the same)."""
    lines: list[str] = []
    add = lines.append
    add("MAST georeference of a point cloud")
    add("=" * 34)
    add(f"cloud            {result.cloud.path}  ({result.cloud.count} points)")
    add(f"survey           {survey_file or '(given)'}  ({len(result.survey)} beacons)")
    if crs is not None:
        add(f"grid CRS         {crs.line()}")
    model = result.config.model
    add(
        "model            "
        + (
            "4-parameter (E, N, elevation offset, rotation about the vertical)"
            if model == "4"
            else "helmert7 (3D similarity)"
        )
    )
    add(f"survey sigma     {result.survey.sigma_text(result.config.survey_sigma_m)}")
    add(f"cloud noise      {1000 * result.pieces.segmentation.noise_m:.1f} mm (estimated in plan)")
    add(f"wall density     {_density(result.candidates.wall_density_m2)}")
    if not result.heights:
        add("heights          NOT CONTROLLED: the survey has no elevations; z is kept as it is")
    add("")
    add("Beacons")
    add("-------")
    counts: dict[str, int] = {}
    for fb in beacons:
        counts[fb.role] = counts.get(fb.role, 0) + 1
    sought = sum(fb.why == SOUGHT for fb in beacons)
    add(
        "  "
        + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(counts.items()))
        + f"; {len(result.detections)} beacon shape(s) found in the cloud, "
        f"{len(result.pieces.panels)} vertical panel(s)"
        + (f"; {sought} not detected on its own, found where the others put it" if sought else "")
    )
    for fb in beacons:
        pts = "" if fb.obs is None else f"{fb.obs.points:6d} pts"
        add(f"  {fb.beacon:<10} {fb.role:<10} {pts:>10}  {fb.why}")
    add("")
    if result.refusal is not None:
        add("NO GEOREFERENCE")
        add("---------------")
        add(f"  {result.refusal.reason}: {result.refusal.detail}")
        return "\n".join(lines) + "\n"
    sol = result.solution
    assert sol is not None
    t = sol.transformation
    add("Transformation (cloud to grid)")
    add("------------------------------")
    sig = np.sqrt(np.maximum(np.diag(t.covariance), 0.0))
    for name, v, s in zip(t.names, t.params, sig, strict=True):
        if name == "elevation_m" and not result.heights:
            add(f"  {name:<14} not estimated (no elevations)")
            continue
        if name.endswith("_rad"):
            label = name[:-4] + "_deg"
            sec = 3600 * math.degrees(s)
            add(f'  {label:<14} {math.degrees(v):16.6f}  ±{sec:.1f}"  (95 %: ±{1.96 * sec:.1f}")')
        elif name == "scale":
            add(f"  {name:<14} {v:16.9f}  ±{1e6 * s:.1f} ppm")
        else:
            add(f"  {name:<14} {v:16.4f}  ±{1000 * s:.1f} mm  (95 %: ±{1000 * 1.96 * s:.1f} mm)")
    add(f"  (at the cloud point {t.centre[0]:.3f}, {t.centre[1]:.3f}, {t.centre[2]:.3f})")
    add("")
    add("Statistics")
    add("----------")
    lo, hi = sol.chi2_bounds
    add(
        f"  reference variance {sol.reference_variance:.3f} on {sol.dof} degrees of freedom; "
        f"global test (5 %, accept {lo:.3f}..{hi:.3f}): {sol.chi2_test.upper()}"
    )
    if sol.scaled:
        add(
            "  the beacons scatter more than their precisions say, and no beacon is to "
            "blame: standard deviations scaled by the reference variance"
        )
    if sol.excluded and drift is None:
        add(f"  left out as outliers: {', '.join(sol.excluded)}")
    elif sol.excluded:
        add(
            f"  the rigid start left out {', '.join(sol.excluded)}; the drift correction "
            "tests every beacon again (below)"
        )
    add("")
    add("Residuals at control beacons (transformed minus surveyed, mm)")
    add("--------------------------------------------------------------")
    add(_residual_table(beacons, res, "control", drift is not None))
    add("")
    add("Check beacons (kept out of the solution)")
    add("----------------------------------------")
    if result.checks:
        add(_residual_table(beacons, res, "check", drift is not None))
    else:
        add("  none (give --check B7,B9 to keep beacons out as an independent check)")
    add("")
    if drift is not None:
        add("Drift correction")
        add("----------------")
        add(
            f"  pose graph over {drift.time.size} keyframes every {drift.step_m:g} m, "
            f"drift model {100 * drift.drift:g} % of distance"
        )
        add("  each control beacon against the graph solved without it; the left out")
        add("  and the checks against the final graph (chi-square of the plan edges,")
        add("  and of the top with heights):")
        for dt in drift.tests:
            verdict = "pass" if not dt.failed else "FAIL"
            add(
                f"  {dt.beacon:<10} {dt.role:<8} {dt.statistic:8.2f} on {dt.dof} dof, "
                f"bound {dt.critical:6.2f}  {verdict}"
            )
        if drift.excluded:
            add(f"  left out of the graph as outliers: {', '.join(drift.excluded)}")
        ratio, dof = drift.statistic_per_dof, drift.control_dof
        if math.isfinite(ratio):
            lo, hi = variance_bounds(dof)  # as the global test's, two-sided at 5 %
            add(
                f"  control statistics per degree of freedom: {ratio:.2f} on {dof} dof "
                f"(the drift model fits within {lo:.2f}..{hi:.2f})"
            )
            if ratio < lo:
                add("  the SLAM drifts less than the model: only moves well beyond the")
                add("  misclosures are caught")
            elif ratio > hi:
                add("  the SLAM drifts more than the model says (--drift)")
        add("")
    add("Accuracy")
    add("--------")
    add("  " + _class_line(result, res, "after" if drift is not None else "before"))
    add("")
    add(f"mast {__version__}, {datetime.now(tz=UTC).strftime('%Y-%m-%d %H:%M:%S UTC')}")
    return "\n".join(lines) + "\n"


def _residual_table(
    beacons: list[FoundBeacon], res: dict[str, dict[str, Any]], role: str, after: bool
) -> str:
    head = "  beacon     edge   dE      dN      dZ     |w|"
    if after:
        head += "   | after: dE      dN      dZ"
    rows = [head]
    for fb in beacons:
        shown = fb.role == role or (role == "control" and fb.role == "excluded")
        if not shown or fb.obs is None:
            continue
        r = res.get(fb.beacon, {})
        b = r.get("before")
        if b is None:
            continue
        a = r.get("after")
        for i, e in enumerate(fb.obs.edges):
            line = (
                f"  {fb.beacon:<10} e{e}  {_mm(b[i, 0]):>7} {_mm(b[i, 1]):>7} {_mm(b[i, 2]):>7}"
                f"  {r.get('w', math.nan):5.2f}"
            )
            if after and a is not None:
                line += f"   |   {_mm(a[i, 0]):>7} {_mm(a[i, 1]):>7} {_mm(a[i, 2]):>7}"
            if fb.role == "excluded":
                line += "  (left out)"
            rows.append(line)
    return "\n".join(rows)


def _plan_figure(
    result: Georef,
    beacons: list[FoundBeacon],
    res: dict[str, dict[str, Any]],
    pts: NDArray[np.float64],
    drift: DriftCorrection | None,
) -> Any:
    fig, axes = new_figure(9.0, 6.0)
    ax = axes[0]
    edges = np.array([b.edges for b in result.survey]).reshape(-1, 2)
    ox, oy = plot_origin(np.concatenate([pts, edges]) if len(pts) else edges)
    if len(pts):
        ax.scatter(pts[:, 0] - ox, pts[:, 1] - oy, s=0.2, c="0.6", lw=0, rasterized=True)
    key = "after" if drift is not None else "before"
    worst = max(
        (float(np.nanmax(np.abs(r[key][:, :2]))) for r in res.values() if key in r), default=0.0
    )
    scale = 1000.0 if worst < 0.005 else (100.0 if worst < 0.05 else 10.0)
    colours = {"control": "tab:green", "check": "tab:blue", "excluded": "tab:red"}
    for fb in beacons:
        b = result.survey[fb.beacon]
        col = colours.get(fb.role, "0.3")
        ax.plot(b.edges[:, 0] - ox, b.edges[:, 1] - oy, "-", color=col, lw=1.5)
        c = b.edges.mean(axis=0)
        ax.annotate(fb.beacon, (c[0] - ox, c[1] - oy), fontsize=7, color=col)
        r = res.get(fb.beacon, {}).get(key)
        if r is not None and fb.obs is not None:
            for i in range(len(fb.obs.edges)):
                g = fb.obs.grid_xy[i]
                ax.annotate(
                    "",
                    xy=(g[0] - ox + scale * r[i, 0], g[1] - oy + scale * r[i, 1]),
                    xytext=(g[0] - ox, g[1] - oy),
                    arrowprops={"arrowstyle": "->", "color": col, "lw": 1.0},
                )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(axis_label("Easting", ox))
    ax.set_ylabel(axis_label("Northing", oy))
    ax.set_title(
        f"Cloud in the grid; residual vectors x{scale:g} "
        "(green control, blue check, red left out, grey not found)",
        fontsize=9,
    )
    return fig


def _svg_of(fig: Any) -> str:
    return inline_svg(fig, "plan view")


def report_html(text: str, svg: str | None, result: Georef) -> str:
    """The report as one self-contained page: the text report and the plan view."""

    title = f"MAST georeference: {result.cloud.path.name}"
    buf = io.StringIO()
    buf.write("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>")
    buf.write(f"<title>{escape(title)}</title><style>{CSS} pre {{ font-size: 0.85em; }}</style>")
    buf.write(f"</head><body><h1>{escape(title)}</h1>")
    status = (
        "georeferenced" if result.refusal is None else f"not georeferenced: {result.refusal.reason}"
    )
    buf.write(f"<p class='sub' id='status'>{escape(status)}</p>")
    if svg is not None:
        buf.write(f"<h2>Plan view</h2><figure>{svg}<figcaption>Figure 1. The cloud in the grid ")
        buf.write(
            "(thinned), the surveyed beacons and their residual vectors.</figcaption></figure>"
        )
    buf.write(f"<h2>Adjustment report</h2><pre>{escape(text)}</pre></body></html>\n")
    return buf.getvalue()
