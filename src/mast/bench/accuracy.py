"""Accuracy benchmark: Monte Carlo of the locator against the Cramer-Rao bound.

For every scanner configuration: seeded random drifts give poses where a fix
is owed (two beacons each show two panels); every pose is scanned many times
with fresh noise. Reported per configuration: fix rate, median and 95th
percentile errors, RMS error over the bound for E, N and A (errors are
normalised by each pose's own bound, then pooled), coverage of the reported
95 % intervals (per coordinate and by the 95 % ellipse), and the reference
variance against its chi-square distribution. Every draw also carries the
evidence its pose's noise-free scan holds (:mod:`mast.bench.detection`),
and the draws binned by it show where the fix rate falls off (``detection.csv``).

The bound comes from the simulator's truth: every beam that really hit a
beacon panel, so returns the locator failed to use count as lost efficiency.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from mast.bench.detection import (
    detection_bins,
    detection_evidence,
    detection_rows,
    detection_table,
)
from mast.bench.robustness import is_wrong, pose_error
from mast.bench.rows import write_rows
from mast.pipeline.bounds import truth_bound
from mast.pipeline.locator import LocatorConfig, locate
from mast.sim import ScannerModel, Scene, Shot, random_scene, simulate_scan
from mast.sim.owed import OWED

__all__ = ["ACCURACY_CONFIGS", "AccuracySummary", "owed_poses", "run_accuracy"]

#: The issue's four scanner configurations.
ACCURACY_CONFIGS: tuple[ScannerModel, ...] = (
    ScannerModel("270deg-0.5deg-12mm", 270.0, 0.5, range_max_m=30.0, range_sigma_m=0.012),
    ScannerModel("270deg-0.25deg-12mm", 270.0, 0.25, range_max_m=30.0, range_sigma_m=0.012),
    ScannerModel("190deg-0.1667deg-8mm", 190.0, 1.0 / 6.0, range_max_m=30.0, range_sigma_m=0.008),
    ScannerModel("360deg-0.2deg-20mm", 360.0, 0.2, range_max_m=30.0, range_sigma_m=0.020),
)


@dataclass(frozen=True, slots=True)
class AccuracySummary:
    config: str
    poses: int
    draws: int
    fix_rate: float
    pos_err_median_mm: float
    pos_err_p95_mm: float
    az_err_median_arcsec: float
    az_err_p95_arcsec: float
    ratio_e: float
    ratio_n: float
    ratio_a: float
    coverage_e: float
    coverage_n: float
    coverage_a: float
    coverage_ellipse: float
    mean_reference_variance: float
    chi2_test_pass: float
    chi2_ks_pvalue: float
    seconds: float
    wrong: int = 0


def owed_poses(model: ScannerModel, count: int, seed0: int) -> list[tuple[Scene, Shot]]:
    """(scene, shot) pairs where, noise-free, two beacons each show two panels."""
    out: list[tuple[Scene, Shot]] = []
    seed = seed0
    exact = model.noise_free()
    while len(out) < count and seed < seed0 + 10_000:
        for idx in range(4):
            scene = random_scene(seed, idx)
            for shot in scene.shots:
                sim = simulate_scan(scene.world, shot.pose, exact)
                if sim.owes_fix(OWED):
                    out.append((scene, replace(shot, scanner=model)))
                    if len(out) == count:
                        return out
        seed += 1
    return out


def run_accuracy(
    *,
    configs: Sequence[ScannerModel] = ACCURACY_CONFIGS,
    poses: int = 40,
    draws: int = 30,
    seed: int = 0,
    out_dir: Path | None = None,
    echo: Callable[[str], object] = print,
) -> list[AccuracySummary]:
    """Run the Monte Carlo; write ``accuracy_<config>.csv`` (one row per draw),
    ``accuracy_summary.csv`` and ``detection.csv`` into ``out_dir`` when given.

    Besides its errors, each draw's row holds its pose's evidence
    (:class:`~mast.bench.detection.DetectionEvidence`, from the noise-free
    scan): ``evidence_returns``, ``evidence_range_m`` and
    ``evidence_direction_sigma_deg``. After the configurations' summary lines,
    the detection tables (draws binned by that evidence) are echoed.
    """
    summaries: list[AccuracySummary] = []
    rows_by_config: dict[str, list[dict[str, object]]] = {}
    for model in configs:
        t0 = time.perf_counter()
        # The simulated survey is exact: no survey error to add to the covariance.
        cfg = LocatorConfig(
            range_sigma_m=model.range_sigma_m,
            angle_sigma_rad=model.angle_sigma_rad,
            survey_sigma_m=0.0,
        )
        rows: list[dict[str, object]] = []
        for p_idx, (scene, shot) in enumerate(owed_poses(model, poses, seed)):
            truth = simulate_scan(scene.world, shot.pose, model.noise_free())
            bound = truth_bound(
                shot.pose,
                truth.scan.angles_rad,
                truth.scan.valid,
                scene.survey,
                noise=cfg.noise,
                beacon_beams=truth.beacon_mask(),
            )
            crb = np.sqrt(np.diag(bound))
            evidence = detection_evidence(truth, scene.survey, range_sigma_m=model.range_sigma_m)
            rng = np.random.default_rng([seed, p_idx, 7])
            for d in range(draws):
                sim = simulate_scan(scene.world, shot.pose, model, rng=rng)
                fix = locate(sim.scan, scene.survey, config=cfg)
                row: dict[str, object] = {
                    "config": model.name,
                    "scene": scene.name,
                    "pose": p_idx,
                    "draw": d,
                    "fixed": int(fix.ok),
                    "wrong": int(is_wrong(fix, shot.pose)),
                    "reason": fix.reason or "",
                    "crb_e_m": crb[0],
                    "crb_n_m": crb[1],
                    "crb_a_rad": crb[2],
                    "evidence_returns": evidence.returns,
                    "evidence_range_m": evidence.range_m,
                    "evidence_direction_sigma_deg": evidence.direction_sigma_deg,
                }
                if fix.ok and fix.pose is not None and fix.adjustment is not None:
                    adj = fix.adjustment
                    err = pose_error(fix.pose, shot.pose)
                    ci = adj.interval95()
                    # the ellipse's own scale: semi-major = k * sqrt(largest eigenvalue)
                    ell = adj.ellipse()
                    big = max(float(np.linalg.eigvalsh(adj.covariance[:2, :2])[1]), 1e-300)
                    k2 = ell.semi_major_m**2 / big
                    d2 = float(err[:2] @ np.linalg.solve(adj.covariance[:2, :2], err[:2]))
                    row.update(
                        err_e_m=err[0],
                        err_n_m=err[1],
                        err_a_rad=err[2],
                        sigma_e_m=adj.sigma[0],
                        sigma_n_m=adj.sigma[1],
                        sigma_a_rad=adj.sigma[2],
                        in_ci_e=int(abs(err[0]) <= ci[0]),
                        in_ci_n=int(abs(err[1]) <= ci[1]),
                        in_ci_a=int(abs(err[2]) <= ci[2]),
                        in_ellipse=int(d2 <= k2),
                        reference_variance=adj.reference_variance,
                        dof=adj.dof,
                        chi2_pass=int(adj.test_passed),
                        points_used=fix.points_used,
                    )
                rows.append(row)
        rows_by_config[model.name] = rows
        summaries.append(_summarise(model.name, rows, poses, draws, time.perf_counter() - t0))
        if out_dir is not None:
            write_rows(out_dir / f"accuracy_{model.name}.csv", rows)
        echo(_line(summaries[-1]))
    echo(detection_table(rows_by_config))
    if out_dir is not None:
        write_rows(out_dir / "accuracy_summary.csv", [asdict(s) for s in summaries])
        write_rows(out_dir / "detection.csv", detection_rows(detection_bins(rows_by_config)))
    return summaries


def _summarise(
    name: str, rows: list[dict[str, object]], poses: int, draws: int, secs: float
) -> AccuracySummary:
    fixed = [r for r in rows if r["fixed"]]

    def col(key: str) -> NDArray[np.float64]:
        return np.array([float(r[key]) for r in fixed])  # type: ignore[arg-type]

    if not fixed:
        empty: dict[str, object] = {
            f: math.nan for f in AccuracySummary.__dataclass_fields__ if f not in ("config",)
        }
        empty.update(config=name, poses=poses, draws=len(rows), fix_rate=0.0, seconds=secs, wrong=0)
        return AccuracySummary(**empty)  # type: ignore[arg-type]
    ee, en, ea = col("err_e_m"), col("err_n_m"), col("err_a_rad")
    pos = np.hypot(ee, en)
    az = np.abs(np.degrees(ea)) * 3600
    s0, dof = col("reference_variance"), col("dof")
    pit = stats.chi2.cdf(s0 * dof, dof)
    return AccuracySummary(
        config=name,
        poses=len({r["pose"] for r in rows}),
        draws=len(rows),
        fix_rate=len(fixed) / len(rows),
        pos_err_median_mm=float(np.median(pos) * 1e3),
        pos_err_p95_mm=float(np.percentile(pos, 95) * 1e3),
        az_err_median_arcsec=float(np.median(az)),
        az_err_p95_arcsec=float(np.percentile(az, 95)),
        ratio_e=float(np.sqrt(np.mean((ee / col("crb_e_m")) ** 2))),
        ratio_n=float(np.sqrt(np.mean((en / col("crb_n_m")) ** 2))),
        ratio_a=float(np.sqrt(np.mean((ea / col("crb_a_rad")) ** 2))),
        coverage_e=float(np.mean(col("in_ci_e"))),
        coverage_n=float(np.mean(col("in_ci_n"))),
        coverage_a=float(np.mean(col("in_ci_a"))),
        coverage_ellipse=float(np.mean(col("in_ellipse"))),
        mean_reference_variance=float(np.mean(s0)),
        chi2_test_pass=float(np.mean(col("chi2_pass"))),
        chi2_ks_pvalue=float(stats.kstest(pit, "uniform").pvalue),
        seconds=secs,
        wrong=int(col("wrong").sum()),
    )


def _line(s: AccuracySummary) -> str:
    return (
        f"{s.config:<22} fix {100 * s.fix_rate:5.1f}%  WRONG {s.wrong}  "
        f"pos med {s.pos_err_median_mm:6.2f} p95 {s.pos_err_p95_mm:6.2f} mm  "
        f'az med {s.az_err_median_arcsec:6.1f} p95 {s.az_err_p95_arcsec:6.1f}"  '
        f"RMS/CRB E {s.ratio_e:.3f} N {s.ratio_n:.3f} A {s.ratio_a:.3f}  "
        f"cover E {s.coverage_e:.3f} N {s.coverage_n:.3f} A {s.coverage_a:.3f} "
        f"ell {s.coverage_ellipse:.3f}  s0² {s.mean_reference_variance:.3f} "
        f"test-pass {s.chi2_test_pass:.3f} KS p {s.chi2_ks_pvalue:.3f}  "
        f"({s.draws} draws, {s.seconds:.0f} s)"
    )
