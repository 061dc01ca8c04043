"""What a fix looks like to people and to other programs: JSON records and survey-style text."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mast.core.pose import format_dms
from mast.pipeline.locator import NO_FIX_REASONS, Fix

__all__ = ["fix_record", "fix_text"]


def _r(x: float, nd: int = 6) -> float | None:
    return None if not math.isfinite(x) else round(float(x), nd)


def fix_record(fix: Fix, *, source: str | None = None, index: int | None = None) -> dict[str, Any]:
    """The "A fix" JSON object of DESIGN.md (plus diagnostics), JSON-serialisable.

    Keys always present: ``status``, ``easting``, ``northing``, ``azimuth_deg``,
    ``sigma_easting_m``, ``sigma_northing_m``, ``sigma_azimuth_deg``,
    ``reference_variance``, ``beacons``, ``points_used``; ``reason`` and
    ``detail`` when there is no fix (values then ``null``).
    """
    rec: dict[str, Any] = {}
    if source is not None:
        rec["source"] = source
    if index is not None:
        rec["scan"] = index
    rec["status"] = fix.status
    adj = fix.adjustment
    if fix.ok and adj is not None and fix.pose is not None:
        sig = adj.sigma
        ci = adj.interval95()
        ell = adj.ellipse()
        rec.update(
            easting=_r(fix.pose.easting),
            northing=_r(fix.pose.northing),
            azimuth_deg=_r(fix.pose.azimuth_deg, 8),
            azimuth_dms=format_dms(fix.pose.azimuth_deg),
            sigma_easting_m=_r(sig[0], 7),
            sigma_northing_m=_r(sig[1], 7),
            sigma_azimuth_deg=_r(math.degrees(sig[2]), 8),
            ci95_easting_m=_r(ci[0], 7),
            ci95_northing_m=_r(ci[1], 7),
            ci95_azimuth_deg=_r(math.degrees(ci[2]), 8),
            ellipse95_semi_major_m=_r(ell.semi_major_m, 7),
            ellipse95_semi_minor_m=_r(ell.semi_minor_m, 7),
            ellipse95_azimuth_deg=_r(math.degrees(ell.azimuth_rad), 4),
            covariance=[[float(v) for v in row] for row in adj.covariance],
            reference_variance=_r(adj.reference_variance, 6),
            degrees_of_freedom=adj.dof,
            chi2_test=adj.test_verdict,
            chi2_bounds=[_r(adj.chi2_lower, 6), _r(adj.chi2_upper, 6)],
            covariance_scaled=adj.scaled,
        )
        if fix.crb is not None:
            crb = np.sqrt(np.diag(fix.crb))
            rec.update(
                crb_sigma_easting_m=_r(crb[0], 7),
                crb_sigma_northing_m=_r(crb[1], 7),
                crb_sigma_azimuth_deg=_r(math.degrees(crb[2]), 8),
            )
    else:
        rec.update(
            easting=None,
            northing=None,
            azimuth_deg=None,
            sigma_easting_m=None,
            sigma_northing_m=None,
            sigma_azimuth_deg=None,
            reference_variance=None,
            reason=fix.reason,
            detail=fix.detail,
        )
    rec["beacons"] = list(fix.beacons)
    rec["excluded_beacons"] = list(fix.excluded_beacons)
    rec["outliers_removed"] = fix.outliers_removed
    rec["panels"] = {b: sorted(p) for b, p in fix.panels.items()}
    rec["points_used"] = fix.points_used
    rec["segments"] = len(fix.segmentation.segments)
    rec["identified"] = [
        {"beacon": n.beacon, "edge": n.edge, "option": n.option, "segments": list(n.segments)}
        for n in fix.identification.nodes
    ]
    sim = fix.similarity
    if sim is not None:
        rec["similarity_scale"] = _r(sim.scale, 9)
        rec["icp_iterations"] = fix.icp_iterations
    noise = fix.config.noise
    rec["range_sigma_m"] = noise.range_sigma_m
    rec["angle_sigma_rad"] = noise.angle_sigma_rad
    rec["survey_sigma_m"] = noise.survey_sigma_m
    if fix.config.prior is not None:
        rec["prior"] = {
            "easting": fix.config.prior.pose.easting,
            "northing": fix.config.prior.pose.northing,
            "azimuth_deg": fix.config.prior.pose.azimuth_deg,
            "radius_m": fix.config.prior.radius_m,
        }
    rec["elapsed_ms"] = round(fix.elapsed_s * 1e3, 3)
    return rec


def fix_text(fix: Fix, *, source: str | None = None) -> str:
    """A short survey-style report of one fix."""
    lines: list[str] = []
    if source:
        lines.append(f"Scan      {source}")
    if not fix.ok or fix.pose is None or fix.adjustment is None:
        lines.append(f"NO FIX    {fix.reason}: {fix.detail}")
        lines.append(f"          ({NO_FIX_REASONS.get(fix.reason or '', '')})")
        return "\n".join(lines)
    adj = fix.adjustment
    sig = adj.sigma
    ci = adj.interval95()
    ell = adj.ellipse()
    p = fix.pose
    sig_az = format_dms(math.degrees(sig[2]), signed=True)
    ci_az = format_dms(math.degrees(ci[2]), signed=True)
    lines += [
        f"Easting   {p.easting:15.4f} m   σ {1e3 * sig[0]:7.2f} mm   95% ± {1e3 * ci[0]:7.2f} mm",
        f"Northing  {p.northing:15.4f} m   σ {1e3 * sig[1]:7.2f} mm   95% ± {1e3 * ci[1]:7.2f} mm",
        f"Azimuth   {format_dms(p.azimuth_deg):>15}     σ {sig_az:>10}   95% ± {ci_az}",
        f"Ellipse   95%: {1e3 * ell.semi_major_m:.2f} × {1e3 * ell.semi_minor_m:.2f} mm, "
        f"major axis at {math.degrees(ell.azimuth_rad):.1f}°",
        f"Ref. var. {adj.reference_variance:.3f} ({adj.dof} dof; 95% bounds "
        f"{adj.chi2_lower:.3f}–{adj.chi2_upper:.3f}): {adj.test_verdict}"
        + ("; covariance scaled by it" if adj.scaled else ""),
        "Beacons   "
        + ", ".join(
            f"{b} (panels {','.join(map(str, sorted(ps)))})" for b, ps in sorted(fix.panels.items())
        )
        + f"; {fix.points_used} returns",
    ]
    if fix.excluded_beacons:
        lines.append(
            f"WARNING   beacon(s) {', '.join(fix.excluded_beacons)} left out: their ranges "
            "disagree with the others (moved or mis-surveyed?)"
        )
    if fix.outliers_removed:
        lines.append(f"Outliers  {fix.outliers_removed} return(s) removed by data snooping")
    opts = sorted(
        {(n.beacon, n.edge, n.option) for n in fix.identification.nodes if n.beacon in fix.beacons}
    )
    if opts:
        lines.append("Corners   " + ", ".join(f"{b} e{e} (Table 1 option {o})" for b, e, o in opts))
    if fix.similarity is not None:
        lines.append(
            f"Alignment similarity scale {fix.similarity.scale:.6f}, "
            f"ICP {fix.icp_iterations} iterations, {1e3 * fix.elapsed_s:.1f} ms"
        )
    return "\n".join(lines)
