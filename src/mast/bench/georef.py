"""Georeference benchmark: simulated SLAM clouds put into the grid by ``mast georef``.

Three parts, each printed as a table (and written as CSV with ``--out``):

* **accuracy** (no drift): ``clouds`` clouds of 300-1000 m with 10-40 beacons
  (:func:`mast.sim.cloud.simulate_cloud`, 1 cm noise, 3 mm survey); every
  fourth beacon, inner ones only, is a check. Per cloud: beacons with enough
  points (every panel 50 or more) found and correctly identified (each
  detected edge within 5 cm of the truth of the beacon it was taken for), wrong
  identifications (a detection taken for a beacon it is not, or not at a beacon
  at all), right beacons with an edge more than 5 cm off, the largest
  check-beacon misclosure (horizontal and
  vertical), and whether the true transformation lies inside the estimate's
  own 95 % region (chi-square with 4 degrees of freedom on the parameters at
  the estimate's centre point).
* **drift** (1 % SLAM drift, with the trajectory): the largest inner check-beacon
  misclosure before (rigid) and after the pose-graph correction.
* **large**: one cloud of about ``large_points`` points processed by ``mast georef``
  in a child process: wall time and peak resident memory.

Run: ``mast bench georef [--clouds 20] [--drift-clouds 6] [--large-points 50000000]``.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

__all__ = ["CloudFigures", "run_georef_bench"]

#: A panel needs this many points for its beacon to count as one that must be found.
ENOUGH_PANEL_POINTS = 50
#: A detected edge farther than this from the truth of its beacon is a wrong identification.
WRONG_ID_M = 0.05


@dataclass(frozen=True, slots=True)
class CloudFigures:
    seed: int
    length_m: float
    beacons: int
    drift: float
    points: int
    eligible: int
    found_correct: int
    wrong: int
    edge_off: int
    status: str
    check_h: float
    check_v: float
    check_h_before_mm: float
    check_h_true: float
    inside_95: bool | None
    seconds: float
    checks_h: tuple[float, ...] = ()
    """Each check beacon's misclosure against the survey (its worst edge), mm."""
    checks_h_true: tuple[float, ...] = ()
    """The same against where the check truly is (georef's error, the survey's aside)."""


def _truth_grid(truth: dict[str, object], xyz: np.ndarray) -> np.ndarray:
    rot = math.radians(float(truth["rotation_deg"]))  # type: ignore[arg-type]
    c, s = math.cos(rot), math.sin(rot)
    out = np.empty_like(xyz)
    out[:, 0] = c * xyz[:, 0] - s * xyz[:, 1] + float(truth["easting_m"])  # type: ignore[arg-type]
    out[:, 1] = s * xyz[:, 0] + c * xyz[:, 1] + float(truth["northing_m"])  # type: ignore[arg-type]
    out[:, 2] = xyz[:, 2] + float(truth["elevation_m"])  # type: ignore[arg-type]
    return out


#: ``--hard``: the density falls with range beyond this (a scanner's, near the walls).
HARD_FALLOFF_M = 4.0
#: ``--hard``: beacon designs in turn (the paper's hat, then shallow random hats).
HARD_DESIGNS = 3


def one_cloud(
    folder: Path,
    seed: int,
    length_m: float,
    beacons: int,
    drift: float,
    density: float,
    hard: bool = False,
) -> CloudFigures:
    """Simulate one cloud, georeference it (with the trajectory when it drifts), score it."""
    from mast.cloud.adjust import rigid_solution
    from mast.cloud.georef import GeorefConfig, georeference
    from mast.cloud.io import open_cloud
    from mast.core.quantiles import chi2_isf
    from mast.io import read_survey
    from mast.io.trajectory import read_trajectory
    from mast.sim.cloud import CloudOptions, simulate_cloud

    options = CloudOptions(
        length_m=length_m,
        beacons=beacons,
        drift=drift,
        density=density,
        falloff_m=HARD_FALLOFF_M if hard else None,
        rock_behind_beacons=hard,
        designs=HARD_DESIGNS if hard else 1,
    )
    sim = simulate_cloud(folder, seed, options)
    truth = json.loads(sim.truth.read_text())
    ids = [b["id"] for b in truth["beacons"]]
    checks = tuple(ids[k] for k in range(2, len(ids) - 1, 4))
    survey = read_survey(sim.survey)
    start = time.perf_counter()
    result = georeference(
        open_cloud(sim.cloud),
        survey,
        GeorefConfig(checks=checks),
        trajectory=read_trajectory(sim.trajectory) if drift > 0 else None,
    )
    seconds = time.perf_counter() - start
    true_local = {b["id"]: np.array(b["edges_local"]) for b in truth["beacons"]}
    eligible = {b["id"] for b in truth["beacons"] if min(b["panel_points"]) >= ENOUGH_PANEL_POINTS}
    found_correct = wrong = off = 0
    centres = {b: v[1:3, :2].mean(axis=0) for b, v in true_local.items()}
    for fb in result.beacons:
        if fb.obs is None:
            continue
        here = fb.obs.cloud_xy.mean(axis=0)
        nearest = min(centres, key=lambda b: float(np.hypot(*(centres[b] - here))))
        e = true_local[fb.beacon][[k - 1 for k in fb.obs.edges], :2]
        if nearest != fb.beacon or float(np.hypot(*(centres[nearest] - here))) > 0.5:
            wrong += 1  # taken for another beacon, or not at a beacon at all
        elif float(np.max(np.hypot(*(fb.obs.cloud_xy - e).T))) > WRONG_ID_M:
            off += 1  # the right beacon, an edge found more than 5 cm off
        else:
            found_correct += fb.beacon in eligible
    status = "georeferenced" if result.refusal is None else result.refusal.reason
    check_h = check_v = before_h = true_h = math.nan
    checks_h: list[float] = []
    checks_true: list[float] = []
    inside: bool | None = None
    sol = result.solution
    true_grid = {b["id"]: np.array(b["edges_grid"]) for b in truth["beacons"]}
    if sol is not None:
        checks_found = [fb.obs for fb in result.beacons if fb.role == "check" and fb.obs]
        # the checks against where they truly are: georef's own error, the survey's aside
        placed = [
            result.drift.at_beacon(o)
            if result.drift is not None
            else sol.transformation.apply(
                np.column_stack([o.cloud_xy, np.full(len(o.edges), o.top)])
            )
            for o in checks_found
        ]
        checks_true = [
            1000
            * float(
                np.max(np.hypot(*(p[:, :2] - true_grid[o.beacon][[e - 1 for e in o.edges], :2]).T))
            )
            for p, o in zip(placed, checks_found, strict=True)
        ]
        if checks_true:
            true_h = max(checks_true)
        if result.drift is not None:
            after = [result.drift.at_beacon(o) for o in checks_found]
            grid = [
                np.column_stack([o.grid_xy, np.full(len(o.edges), o.grid_top)])
                for o in checks_found
            ]
            checks_h = [
                1000 * float(np.max(np.hypot(*(a - g)[:, :2].T)))
                for a, g in zip(after, grid, strict=True)
            ]
            if after:
                d = np.concatenate([a - g for a, g in zip(after, grid, strict=True)])
                check_h = max(checks_h)
                check_v = 1000 * float(np.max(np.abs(d[:, 2])))
            rigid = rigid_solution(list(result.controls), "4", result.config.survey_sigma_m, True)
            moved = [
                rigid.transformation.apply(
                    np.column_stack([o.cloud_xy, np.full(len(o.edges), o.top)])
                )
                for o in checks_found
            ]
            if moved:
                d = np.concatenate([m - g for m, g in zip(moved, grid, strict=True)])
                before_h = 1000 * float(np.max(np.hypot(d[:, 0], d[:, 1])))
        else:
            checks_h = [1000 * c.horizontal_m for c in result.checks]
            if result.checks:
                check_h = max(checks_h)
                check_v = 1000 * max(
                    float(np.max(np.abs(c.residuals[:, 2]))) for c in result.checks
                )
            t = sol.transformation
            centre = t.centre[None, :]
            true_c = _truth_grid(truth, centre)[0]
            diff = np.array(
                [
                    t.params[0] - true_c[0],
                    t.params[1] - true_c[1],
                    t.params[2] - true_c[2],
                    math.remainder(t.params[3] - math.radians(truth["rotation_deg"]), math.tau),
                ]
            )
            stat = float(diff @ np.linalg.solve(t.covariance, diff))
            inside = stat <= chi2_isf(0.05, 4)
    return CloudFigures(
        seed,
        length_m,
        len(ids),
        drift,
        sim.points,
        len(eligible),
        found_correct,
        wrong,
        off,
        status,
        check_h,
        check_v,
        before_h,
        true_h,
        inside,
        seconds,
        tuple(checks_h),
        tuple(checks_true),
    )


def _large(folder: Path, points: int, echo: Callable[[str], None]) -> dict[str, float]:
    """Simulate about ``points`` points (1000 m) and time ``mast georef`` on them in a child."""
    from mast.sim.cloud import CloudOptions, simulate_cloud

    density = points / (1000.0 * 19.0)
    sim = simulate_cloud(
        folder, 7, CloudOptions(length_m=1000.0, beacons=40, density=density, max_points=points)
    )
    echo(f"large cloud: {sim.points} points, {sim.cloud.stat().st_size / 1e6:.0f} MB LAZ")
    code = (
        "import sys, time; t = time.perf_counter(); from mast.program import main\n"
        "sys.argv = ['mast', 'georef', sys.argv[1], '-b', sys.argv[2], '--out', sys.argv[3]]\n"
        "try:\n    main()\nexcept SystemExit as e:\n    code = e.code\n"
        "from mast.bench.rss import peak_rss_mb\n"
        "print('FIGURES', time.perf_counter() - t, peak_rss_mb(), code, flush=True)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(sim.cloud), str(sim.survey), str(folder / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    line = next((ln for ln in done.stdout.splitlines() if ln.startswith("FIGURES")), None)
    if line is None:
        raise RuntimeError(f"mast georef failed: {done.stderr[-500:]}")
    _, secs, rss, _code = line.split()
    return {"points": float(sim.points), "seconds": float(secs), "peak_rss_mb": float(rss)}


def run_georef_bench(
    *,
    clouds: int = 20,
    drift_clouds: int = 6,
    large_points: int = 0,
    density: float = 2000.0,
    hard: bool = False,
    out: Path | None = None,
    echo: Callable[[str], None] = print,
) -> list[CloudFigures]:
    """Run the benchmark (module docstring) and print its tables."""
    rng = np.random.default_rng(2026)
    rows: list[CloudFigures] = []
    with tempfile.TemporaryDirectory(prefix="mast-bench-georef-") as tmp:
        for k in range(clouds + drift_clouds):
            drift = 0.0 if k < clouds else 0.01
            length = float(rng.uniform(300.0, 1000.0))
            beacons = int(np.clip(round(length / rng.uniform(22.0, 30.0)), 10, 40))
            fig = one_cloud(Path(tmp) / f"c{k}", 100 + k, length, beacons, drift, density, hard)
            rows.append(fig)
            echo(
                f"{k:3d} {length:6.0f} m {fig.beacons:3d} beacons drift {100 * drift:.0f} %: "
                f"{fig.status}, {fig.found_correct}/{fig.eligible} found, {fig.wrong} wrong, "
                f"{fig.edge_off} edges > 5 cm off, "
                f"check {fig.check_h:.1f} mm h (before {fig.check_h_before_mm:.1f}, "
                f"against the truth {fig.check_h_true:.1f}), "
                f"{fig.check_v:.1f} mm v, inside 95 %: {fig.inside_95}, {fig.seconds:.0f} s"
            )
            shutil.rmtree(Path(tmp) / f"c{k}", ignore_errors=True)
        large = _large(Path(tmp) / "large", large_points, echo) if large_points else None
    _summary(rows, large, echo)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        with out.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(asdict(rows[0]).keys()))
            w.writeheader()
            for r in rows:
                w.writerow(
                    {
                        k: ";".join(f"{x:.2f}" for x in v) if isinstance(v, tuple) else v
                        for k, v in asdict(r).items()
                    }
                )
    return rows


def _summary(
    rows: list[CloudFigures], large: dict[str, float] | None, echo: Callable[[str], None]
) -> None:
    still = [r for r in rows if r.drift == 0]
    moving = [r for r in rows if r.drift > 0]
    if still:
        inside = [r.inside_95 for r in still if r.inside_95 is not None]
        echo(
            f"no drift, {len(still)} clouds: found {sum(r.found_correct for r in still)}/"
            f"{sum(r.eligible for r in still)} eligible beacons, "
            f"{sum(r.wrong for r in still)} wrong identifications, "
            f"georeferenced {sum(r.status == 'georeferenced' for r in still)}; "
            f"check misclosure max {np.nanmax([r.check_h for r in still]):.1f} mm horizontal, "
            f"{np.nanmax([r.check_v for r in still]):.1f} mm vertical (median "
            f"{np.nanmedian([r.check_h for r in still]):.1f} / "
            f"{np.nanmedian([r.check_v for r in still]):.1f}); against the checks' true "
            f"edges max {np.nanmax([r.check_h_true for r in still]):.1f}, median "
            f"{np.nanmedian([r.check_h_true for r in still]):.1f} mm horizontal; "
            f"truth inside its 95 % region in {sum(inside)}/{len(inside)}"
        )
        each = [h for r in still for h in r.checks_h]
        true = [h for r in still for h in r.checks_h_true]
        if each:
            echo(
                f"  each check beacon (its worst edge), {len(each)} checks: against the survey "
                f"median {np.median(each):.1f}, worst {max(each):.1f} mm; against the truth "
                f"median {np.median(true):.1f}, worst {max(true):.1f} mm"
            )
    if moving:
        echo(
            f"1 % drift, {len(moving)} clouds: inner check misclosure after correction max "
            f"{np.nanmax([r.check_h for r in moving]):.1f} mm horizontal "
            f"({np.nanmax([r.check_v for r in moving]):.1f} mm vertical); before "
            f"{np.nanmin([r.check_h_before_mm for r in moving]):.0f}-"
            f"{np.nanmax([r.check_h_before_mm for r in moving]):.0f} mm; against the checks' "
            f"true edges max {np.nanmax([r.check_h_true for r in moving]):.1f} mm; "
            f"{sum(r.wrong for r in moving)} wrong identifications"
        )
    if large is not None:
        echo(
            f"large: {large['points'] / 1e6:.1f} M points in {large['seconds']:.0f} s, "
            f"peak {large['peak_rss_mb'] / 1024:.2f} GB"
        )
