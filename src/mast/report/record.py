"""What a fix looks like to people and to other programs: JSON records and a survey report.

The JSON record is published as ``docs/fix.schema.json``; the text report is
laid out like the least-squares adjustment reports surveyors sign (inputs,
result, statistics, residuals, how the solution was found).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast import __version__
from mast.core.beacon import Survey
from mast.core.pose import format_dms
from mast.core.pose3d import Frame3D
from mast.core.quantiles import chi2_ppf, f_ppf, norm_ppf, t_ppf
from mast.core.scan import Scan
from mast.core.stats import variance_bounds
from mast.io.crs import GridCrs
from mast.pipeline.adjust3d import PARAMETERS, UNBRACKETED, Adjustment3D
from mast.pipeline.adjustment import ErrorEllipse, position_ellipse
from mast.pipeline.integrity import Residuals
from mast.pipeline.locator import NO_FIX_REASONS, Fix
from mast.pipeline.locator3d import Fix3D

__all__ = [
    "COVARIANCE_ORDER",
    "COVARIANCE_ORDER_3D",
    "OPTION_WORDS",
    "ReportInputs",
    "Stats3D",
    "fix3d_record",
    "fix3d_text",
    "fix_record",
    "fix_text",
]

#: Row and column order of ``covariance`` in a record, with units.
COVARIANCE_ORDER = ("easting_m", "northing_m", "azimuth_rad")

#: The MAST paper's Table 1 options in words: which tests a pair of segments passed.
OPTION_WORDS: dict[int, str] = {
    1: "both panel lengths, the angle between them and their spacing",
    2: "both panel lengths and the angle between them",
    3: "the second panel's length, the angle and the spacing",
    4: "the first panel's length, the angle and the spacing",
    5: "the first panel's length and the angle",
    6: "the second panel's length and the angle",
}

_TEST_WORDS = {
    "pass": "PASS",
    "too_small": "FAIL (too small: the returns fit better than the precisions say)",
    "too_large": "FAIL (too large: the returns fit worse than the precisions say; "
    "standard deviations scaled by it)",
}


@dataclass(frozen=True, slots=True)
class ReportInputs:
    """What a fix was computed from, for the record (the report a surveyor signs).

    Attributes
    ----------
    scan_file, survey_file : str, optional
        The files as given on the command line.
    scanner : str, optional
        The named scanner model the precisions came from.
    topic : str, optional
        The bag topic the scan was read from.
    defaults : frozenset of str
        Which of ``range_sigma_m``, ``angle_sigma_rad``, ``survey_sigma_m``
        were left at their defaults (neither given nor from ``scanner``).
    computed_utc : datetime
        When the report was made.
    config_file : str, optional
        The settings file given (``--config``).
    config_sha256 : str, optional
        The SHA-256 of the effective configuration's settings text
        (:mod:`mast.io.settings`): what ``config.toml`` beside a run's results holds.
    survey_sigmas : str, optional
        How the survey weighs its edges when it gives its own ``sigma_m``
        (:meth:`~mast.core.beacon.Survey.sigma_text`); None: one sigma for all.
    crs : GridCrs, optional
        The grid's coordinate reference system (``--crs``): the record's ``crs``
        object and a line of the report; None: none recorded.
    """

    scan_file: str | None = None
    survey_file: str | None = None
    scanner: str | None = None
    topic: str | None = None
    defaults: frozenset[str] = frozenset()
    computed_utc: datetime = field(default_factory=lambda: datetime.now(UTC))
    config_file: str | None = None
    config_sha256: str | None = None
    survey_sigmas: str | None = None
    crs: GridCrs | None = None


def _r(x: float, nd: int = 6) -> float | None:
    return None if not math.isfinite(x) else round(float(x), nd)


def _residuals_record(res: Residuals) -> dict[str, Any]:
    per_beacon: dict[str, Any] = {}
    for b, g in res.per_beacon.items():
        entry: dict[str, Any] = {
            "returns": g.returns,
            "rms_m": _r(g.rms_m, 7),
            "max_abs_w": _r(g.max_abs_w, 3),
        }
        t = res.beacon_tests.get(b)
        if t is not None:
            entry["test"] = {
                "statistic": _r(t.statistic, 3),
                "dof": t.dof,
                "critical": _r(t.critical, 3),
                "passed": not t.failed,
            }
        per_beacon[b] = entry
    return {
        "rms_m": _r(res.rms_m, 7),
        "max_abs_w": _r(res.max_abs_w, 3),
        "w_critical": _r(res.w_critical, 3),
        "per_beacon": per_beacon,
        "per_panel": [
            {
                "beacon": b,
                "panel": p,
                "returns": g.returns,
                "rms_m": _r(g.rms_m, 7),
                "max_abs_w": _r(g.max_abs_w, 3),
            }
            for (b, p), g in sorted(res.per_panel.items())
        ],
    }


def _inputs_record(fix: Fix, scan: Scan | None, inputs: ReportInputs) -> dict[str, Any]:
    rec: dict[str, Any] = {
        "scan_file": inputs.scan_file,
        "survey_file": inputs.survey_file,
        "scanner": inputs.scanner,
        "defaults": sorted(inputs.defaults),
    }
    if inputs.topic is not None:
        rec["topic"] = inputs.topic
    if inputs.survey_sigmas is not None:
        rec["survey_sigmas"] = inputs.survey_sigmas
    if inputs.config_sha256 is not None:
        rec.update(config_file=inputs.config_file, config_sha256=inputs.config_sha256)
    if scan is not None:
        rec.update(
            beams=len(scan),
            valid_beams=int(np.count_nonzero(scan.valid)),
            range_min_m=_r(scan.range_min_m),
            range_max_m=_r(scan.range_max_m),
        )
    return rec


def _corners(fix: Fix) -> list[tuple[str, int, int]]:
    """(beacon, edge, best option) of each identified corner of the beacons used, once each."""
    best: dict[tuple[str, int], int] = {}
    for n in fix.nodes:
        if n.beacon in fix.beacons:
            key = (n.beacon, n.edge)
            best[key] = min(best.get(key, n.option), n.option)
    return [(b, e, o) for (b, e), o in sorted(best.items())]


def _record_head(
    source: str | None, index: int | None, taken: Scan | Frame3D | None, inputs: ReportInputs
) -> dict[str, Any]:
    """A record's first keys: its ``source``; in a sequence (``index`` given) the scan's
    or frame's number, ``stamp_ns`` and ``frame_id`` (where it is given) and the topic."""
    rec: dict[str, Any] = {}
    if source is not None:
        rec["source"] = source
    if index is not None:
        rec["scan"] = index
        if taken is not None:
            rec["stamp_ns"] = taken.stamp_ns
            rec["frame_id"] = taken.frame_id
        if inputs.topic is not None:
            rec["topic"] = inputs.topic
    return rec


def fix_record(
    fix: Fix,
    *,
    source: str | None = None,
    index: int | None = None,
    scan: Scan | None = None,
    inputs: ReportInputs | None = None,
) -> dict[str, Any]:
    """The "A fix" JSON object of DESIGN.md, described by ``docs/fix.schema.json``.

    Keys always present: ``status``, ``easting``, ``northing``, ``azimuth_deg``,
    ``sigma_easting_m``, ``sigma_northing_m``, ``sigma_azimuth_deg``,
    ``reference_variance``, ``beacons``, ``points_used``, the precisions used
    and ``software``; ``reason`` and ``detail`` when there is no fix (values
    then ``null``). In a sequence (``index`` given) the scan's ``stamp_ns`` and
    ``frame_id`` are added when ``scan`` is; ``crs`` when the inputs name one.
    """
    inputs = inputs or ReportInputs()
    rec = _record_head(source, index, scan, inputs)
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
            covariance=[[float(v) for v in row] for row in (adj.covariance + adj.covariance.T) / 2],
            covariance_order=list(COVARIANCE_ORDER),
            reference_variance=_r(adj.reference_variance, 6),
            degrees_of_freedom=adj.dof,
            chi2_test=adj.test_code,
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
            reason_text=NO_FIX_REASONS.get(fix.reason or "", ""),
            detail=fix.detail,
        )
    if fix.residuals is not None:
        rec["residuals"] = _residuals_record(fix.residuals)
    rec["beacons"] = list(fix.beacons)
    rec["excluded_beacons"] = list(fix.excluded_beacons)
    rec["outliers_removed"] = fix.outliers_removed
    rec["panels"] = {b: sorted(p) for b, p in fix.panels.items()}
    rec["points_used"] = fix.points_used
    # None for a scan fixed near a prior, which is not segmented (its corners not sought)
    seg, ident = fix.segmentation, fix.identification
    rec["segments"] = None if seg is None else len(seg.segments)
    rec["identified"] = (
        None
        if ident is None
        else [
            {"beacon": n.beacon, "edge": n.edge, "option": n.option, "segments": list(n.segments)}
            for n in ident.nodes
        ]
    )
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
    if inputs.crs is not None:
        rec["crs"] = inputs.crs.brief()
    rec["inputs"] = _inputs_record(fix, scan, inputs)
    rec["software"] = f"mast {__version__}"
    rec["computed_utc"] = inputs.computed_utc.isoformat(timespec="seconds").replace("+00:00", "Z")
    rec["elapsed_ms"] = round(fix.elapsed_s * 1e3, 3)
    return rec


def _mm(x: float) -> str:
    return f"{1e3 * x:.1f}"


def _mm2(x: float) -> str:
    return f"{1e3 * x:7.2f}"


def _residual_lines(res: Residuals) -> list[str]:
    lines = [
        "Residuals (measured minus computed range; w: standardised residual, Baarda's w-test)",
        f"  {'beacon':<10} {'panel':>5} {'returns':>7} {'RMS mm':>8} {'max |w|':>8}",
    ]
    for b, g in sorted(res.per_beacon.items()):
        for (pb, p), pg in sorted(res.per_panel.items()):
            if pb == b:
                lines.append(
                    f"  {b:<10} {p:>5} {pg.returns:>7} {_mm(pg.rms_m):>8} {pg.max_abs_w:>8.2f}"
                )
        lines.append(f"  {b:<10} {'all':>5} {g.returns:>7} {_mm(g.rms_m):>8} {g.max_abs_w:>8.2f}")
    n = sum(g.returns for g in res.per_beacon.values())
    lines.append(f"  {'all':<10} {'':>5} {n:>7} {_mm(res.rms_m):>8} {res.max_abs_w:>8.2f}")
    verdict = "no outlier" if res.max_abs_w <= res.w_critical else "an outlier remains"
    lines.append(
        f"  largest |w| {res.max_abs_w:.2f} against the critical {res.w_critical:.2f} "
        f"(0.1 % over all returns): {verdict}"
    )
    if res.beacon_tests:
        lines.append(
            "Beacon tests (each beacon's ranges against the pose the others give; chi-square, "
            "0.1 %)"
        )
        for b, t in sorted(res.beacon_tests.items()):
            verdict = "FAIL: moved or mis-surveyed?" if t.failed else "pass"
            lines.append(
                f"  {b:<10} statistic {t.statistic:9.1f} on {t.dof:>4} returns, "
                f"critical {t.critical:7.1f}: {verdict}"
            )
    return lines


def _input_lines(fix: Fix, scan: Scan | None, inputs: ReportInputs) -> list[str]:
    noise = fix.config.noise
    when = inputs.computed_utc.strftime("%Y-%m-%d %H:%M:%S UTC")
    lines = [f"MAST fix report                          mast {__version__}, {when}", "Inputs"]
    if inputs.scan_file is not None:
        lines.append(f"  Scan file     {inputs.scan_file}")
    if scan is not None:
        valid = int(np.count_nonzero(scan.valid))
        upper = f"{scan.range_max_m:g} m" if math.isfinite(scan.range_max_m) else "no limit"
        lines.append(
            f"  Beams         {len(scan)} read, {valid} with a valid return "
            f"(valid ranges {scan.range_min_m:g} m to {upper})"
        )
    if inputs.survey_file is not None:
        lines.append(f"  Survey file   {inputs.survey_file}")
    if inputs.crs is not None:
        lines.append(f"  Grid CRS      {inputs.crs.line()}")
    if inputs.scanner is not None:
        lines.append(f"  Scanner       {inputs.scanner}")
    if inputs.config_sha256 is not None:
        source = inputs.config_file or "defaults and options"
        lines.append(f"  Settings      {source} (SHA-256 {inputs.config_sha256[:12]})")

    def tag(key: str) -> str:
        if key in inputs.defaults:
            return " (default)"
        return f" (from {inputs.scanner})" if inputs.scanner and key != "survey_sigma_m" else ""

    surveyed = (
        f"{_mm(noise.survey_sigma_m)} mm per edge coordinate{tag('survey_sigma_m')}"
        if inputs.survey_sigmas is None
        else inputs.survey_sigmas
    )
    lines += [
        f"  Range σ       {_mm(noise.range_sigma_m)} mm{tag('range_sigma_m')}",
        f"  Angle σ       {math.degrees(noise.angle_sigma_rad):.6g}° "
        f"({noise.angle_sigma_rad:g} rad){tag('angle_sigma_rad')}",
        f"  Survey σ      {surveyed}",
    ]
    prior = fix.config.prior
    if prior is not None:
        lines.append(f"  Prior         {prior.pose}, radius {prior.radius_m:g} m")
    return lines


def survey_weighing(survey: Survey, default_m: float) -> str | None:
    """:attr:`ReportInputs.survey_sigmas` for a survey: None when it gives no
    ``sigma_m`` of its own (the report then names the one sigma for all)."""
    return survey.sigma_text(default_m) if survey.edge_sigmas().size else None


def fix_text(
    fix: Fix,
    *,
    source: str | None = None,
    scan: Scan | None = None,
    inputs: ReportInputs | None = None,
) -> str:
    """A survey-style report of one fix (or of why there is none)."""
    inputs = inputs or ReportInputs(scan_file=source)
    lines = _input_lines(fix, scan, inputs)
    if source is not None and source != inputs.scan_file:
        lines.append(f"  Scan          {source}")
    if not fix.ok or fix.pose is None or fix.adjustment is None:
        lines += [
            f"Result        NO FIX ({fix.reason}): {NO_FIX_REASONS.get(fix.reason or '', '')}",
            f"  {fix.detail}",
        ]
        if fix.residuals is not None:
            lines += _residual_lines(fix.residuals)
        return "\n".join(lines)
    adj = fix.adjustment
    sig = adj.sigma
    ci = adj.interval95()
    ell = adj.ellipse()
    p = fix.pose
    sig_az = format_dms(math.degrees(sig[2]), signed=True)
    ci_az = format_dms(math.degrees(ci[2]), signed=True)
    lines += [
        "Result        FIX",
        f"  Easting   {p.easting:15.4f} m   σ {_mm2(sig[0])} mm   95% ± {_mm2(ci[0])} mm",
        f"  Northing  {p.northing:15.4f} m   σ {_mm2(sig[1])} mm   95% ± {_mm2(ci[1])} mm",
        f"  Azimuth   {format_dms(p.azimuth_deg):>15}     σ {sig_az:>10}   95% ± {ci_az}",
        f"  Error ellipse (95 %): semi-major {1e3 * ell.semi_major_m:.2f} mm, semi-minor "
        f"{1e3 * ell.semi_minor_m:.2f} mm, major axis at azimuth "
        f"{math.degrees(ell.azimuth_rad):.1f}° (clockwise from grid north)",
        "Statistics",
        f"  Reference variance {adj.reference_variance:.3f} on {adj.dof} degrees of freedom; "
        f"chi-square test at 5 % (accept {adj.chi2_lower:.3f} to {adj.chi2_upper:.3f}): "
        f"{_TEST_WORDS[adj.test_code]}",
        "  Beacons used  "
        + ", ".join(
            f"{b} (panels {','.join(map(str, sorted(ps)))})" for b, ps in sorted(fix.panels.items())
        )
        + f"; {fix.points_used} returns",
    ]
    if fix.excluded_beacons:
        lines.append(
            f"  WARNING: beacon(s) {', '.join(fix.excluded_beacons)} left out: their ranges "
            "disagree with the others (moved or mis-surveyed?)"
        )
    if fix.outliers_removed:
        lines.append(f"  {fix.outliers_removed} return(s) removed as outliers (w-test)")
    if fix.residuals is not None:
        lines += _residual_lines(fix.residuals)
    lines.append("How it was found")
    for b, e, o in _corners(fix):
        lines.append(
            f"  {b} edge {e}: corner identified by {OPTION_WORDS.get(o, '?')} "
            f"(MAST paper, Table 1 option {o})"
        )
    refined = (
        f"refined by fitting the returns to the surveyed panels ({fix.icp_iterations} "
        f"iterations), {1e3 * fix.elapsed_s:.1f} ms in all"
    )
    prior = fix.config.prior
    if fix.chosen is not None and fix.chosen.hypothesis.kind == "prior" and prior is not None:
        lines.append(
            f"  First pose from a search of the prior's window ({prior.radius_m:g} m around "
            f"E {prior.pose.easting:.3f}, N {prior.pose.northing:.3f}), {refined}"
        )
    elif fix.similarity is not None:
        lines.append(
            f"  First pose from the matched corners (scan-to-survey scale "
            f"{fix.similarity.scale:.6f}; 1 when they agree in size), {refined}"
        )
    return "\n".join(lines)


# --------------------------------------------------------------------------- 3D frames

#: Row and column order of ``covariance`` in a 3D record (:data:`adjust3d.PARAMETERS`).
COVARIANCE_ORDER_3D = PARAMETERS


@dataclass(frozen=True, slots=True)
class Stats3D:
    """The statistics of a 3D adjustment as a record states them, on the 2D rules: the
    global test at 5 % two-sided (:func:`mast.core.stats.variance_bounds`), the
    covariance scaled by the reference variance when it is too large, and 95 %
    intervals from the normal (Student t when scaled). An elevation no top edge
    bracketed (variance :data:`~mast.pipeline.adjust3d.UNBRACKETED`) is not observed:
    ``elevation_observed`` False, its sigma and interval None."""

    covariance: NDArray[np.float64]
    sigma: NDArray[np.float64]
    ci95: NDArray[np.float64]
    test_code: str
    chi2_lower: float
    chi2_upper: float
    scaled: bool
    elevation_observed: bool

    @classmethod
    def of(cls, adj: Adjustment3D) -> Stats3D:
        lo, hi = variance_bounds(adj.dof)
        s0 = adj.reference_variance
        code = "too_small" if s0 < lo else "too_large" if s0 > hi else "pass"
        scaled = code == "too_large"
        cov = (adj.covariance + adj.covariance.T) / 2
        observed = bool(adj.top_edges > 0 and cov[2, 2] < UNBRACKETED / 2)
        if scaled:
            cov = cov * s0
            if not observed:  # the unobserved elevation's variance stays the marker
                cov[2, 2] = adj.covariance[2, 2]
        sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
        q = t_ppf(0.975, max(adj.dof, 1)) if scaled else norm_ppf(0.975)
        return cls(cov, sigma, q * sigma, code, lo, hi, scaled, observed)

    def ellipse(self, dof: int) -> ErrorEllipse:
        """The 95 % position ellipse of (easting, northing), as 2D's."""
        if self.scaled:
            k = math.sqrt(2 * f_ppf(0.95, 2, max(dof, 1)))
        else:
            k = math.sqrt(chi2_ppf(0.95, 2))
        return position_ellipse(self.covariance, k, 0.95)


#: The keys a 3D record adds to 2D's, null without a fix.
KEYS_3D = (
    "elevation_m",
    "roll_deg",
    "pitch_deg",
    "sigma_elevation_m",
    "sigma_roll_deg",
    "sigma_pitch_deg",
)


def fix3d_record(
    fix: Fix3D,
    *,
    source: str | None = None,
    index: int | None = None,
    frame: Frame3D | None = None,
    inputs: ReportInputs | None = None,
    range_sigma_m: float,
    survey_sigma_m: float,
) -> dict[str, Any]:
    """The record of one 3D lidar frame (``docs/fix.schema.json``, ``"dimensions": 3``):
    ``locate``'s keys, with the pose's elevation, roll and pitch and their sigmas, and
    the 6×6 covariance in :data:`COVARIANCE_ORDER_3D` order.

    ``azimuth_deg`` is the heading of the sensor's x axis projected on the horizontal.
    The corners identified, the segments and the excluded beacons are the plan view's
    (the 2D locate the 3D one starts from, :attr:`Fix3D.plan`: its fix, or for a fix
    started from one beacon its ``one_beacon`` refusal), given also as ``plan_view``;
    ``panels`` are those whose returns the 3D adjustment used. An elevation no beacon's
    top edges bracketed, or that they held no better than
    :data:`mast.pipeline.locator3d.MAX_ELEVATION_SIGMA_M`, is reported with
    ``elevation_observed`` false and null ``sigma_elevation_m``: its value is then not
    to survey precision. Without a fix the pose keys are
    null, as in 2D, with the reason and detail.
    """
    inputs = inputs or ReportInputs()
    plan = fix.plan
    rec = _record_head(source, index, frame, inputs)
    rec["status"] = fix.status
    rec["dimensions"] = 3
    adj = fix.adjustment
    if fix.ok and adj is not None and fix.pose is not None:
        p = fix.pose
        st = Stats3D.of(adj)
        sig, ci = st.sigma, st.ci95
        ell = st.ellipse(adj.dof)
        az = math.degrees(p.azimuth) % 360.0
        z_sigma = _r(sig[2], 7) if st.elevation_observed else None
        z_ci = _r(ci[2], 7) if st.elevation_observed else None
        rec.update(
            easting=_r(p.easting),
            northing=_r(p.northing),
            elevation_m=_r(p.elevation),
            azimuth_deg=_r(az, 8),
            azimuth_dms=format_dms(az),
            roll_deg=_r(math.degrees(p.roll), 8),
            pitch_deg=_r(math.degrees(p.pitch), 8),
            sigma_easting_m=_r(sig[0], 7),
            sigma_northing_m=_r(sig[1], 7),
            sigma_elevation_m=z_sigma,
            sigma_roll_deg=_r(math.degrees(sig[3]), 8),
            sigma_pitch_deg=_r(math.degrees(sig[4]), 8),
            sigma_azimuth_deg=_r(math.degrees(sig[5]), 8),
            elevation_observed=st.elevation_observed,
            ci95_easting_m=_r(ci[0], 7),
            ci95_northing_m=_r(ci[1], 7),
            ci95_elevation_m=z_ci,
            ci95_roll_deg=_r(math.degrees(ci[3]), 8),
            ci95_pitch_deg=_r(math.degrees(ci[4]), 8),
            ci95_azimuth_deg=_r(math.degrees(ci[5]), 8),
            ellipse95_semi_major_m=_r(ell.semi_major_m, 7),
            ellipse95_semi_minor_m=_r(ell.semi_minor_m, 7),
            ellipse95_azimuth_deg=_r(math.degrees(ell.azimuth_rad), 4),
            covariance=[[float(v) for v in row] for row in st.covariance],
            covariance_order=list(COVARIANCE_ORDER_3D),
            reference_variance=_r(adj.reference_variance, 6),
            degrees_of_freedom=adj.dof,
            chi2_test=st.test_code,
            chi2_bounds=[_r(st.chi2_lower, 6), _r(st.chi2_upper, 6)],
            covariance_scaled=st.scaled,
            global_test_p=_r(adj.test_p, 9),
            top_edges=adj.top_edges,
        )
    else:
        rec.update(
            easting=None,
            northing=None,
            elevation_m=None,
            azimuth_deg=None,
            roll_deg=None,
            pitch_deg=None,
            sigma_easting_m=None,
            sigma_northing_m=None,
            sigma_elevation_m=None,
            sigma_roll_deg=None,
            sigma_pitch_deg=None,
            sigma_azimuth_deg=None,
            reference_variance=None,
            reason=fix.reason,
            reason_text=NO_FIX_REASONS.get(fix.reason or "", ""),
            detail=fix.detail,
        )
    rec["beacons"] = list(fix.beacons)
    rec["excluded_beacons"] = list(plan.excluded_beacons)
    rec["panels"] = {b: list(ps) for b, ps in fix.panels.items() if b in fix.beacons}
    rec["points_used"] = adj.returns if fix.ok and adj is not None else 0
    seg, ident = plan.segmentation, plan.identification
    rec["segments"] = None if seg is None else len(seg.segments)
    rec["identified"] = (
        None
        if ident is None
        else [
            {"beacon": n.beacon, "edge": n.edge, "option": n.option, "segments": list(n.segments)}
            for n in ident.nodes
        ]
    )
    rec["plan_view"] = _plan_record(plan)
    rec["range_sigma_m"] = range_sigma_m
    rec["angle_sigma_rad"] = plan.config.noise.angle_sigma_rad
    rec["survey_sigma_m"] = survey_sigma_m
    if inputs.crs is not None:
        rec["crs"] = inputs.crs.brief()
    rec["inputs"] = _frame_inputs(frame, inputs)
    rec["software"] = f"mast {__version__}"
    rec["computed_utc"] = inputs.computed_utc.isoformat(timespec="seconds").replace("+00:00", "Z")
    rec["elapsed_ms"] = round(fix.elapsed_s * 1e3, 3)
    return rec


def _plan_record(plan: Fix) -> dict[str, Any]:
    """The plan view's 2D fix, in brief: what the 3D fix started from."""
    if plan.ok and plan.pose is not None and plan.adjustment is not None:
        return {
            "status": plan.status,
            "easting": _r(plan.pose.easting),
            "northing": _r(plan.pose.northing),
            "azimuth_deg": _r(plan.pose.azimuth_deg, 8),
            "reference_variance": _r(plan.adjustment.reference_variance, 6),
            "points_used": plan.points_used,
        }
    return {"status": plan.status, "reason": plan.reason}


def _frame_inputs(frame: Frame3D | None, inputs: ReportInputs) -> dict[str, Any]:
    rec: dict[str, Any] = {
        "scan_file": inputs.scan_file,
        "survey_file": inputs.survey_file,
        "scanner": inputs.scanner,
        "defaults": sorted(inputs.defaults - {"angle_sigma_rad"}),
    }
    if inputs.topic is not None:
        rec["topic"] = inputs.topic
    if inputs.survey_sigmas is not None:
        rec["survey_sigmas"] = inputs.survey_sigmas
    if inputs.config_sha256 is not None:
        rec.update(config_file=inputs.config_file, config_sha256=inputs.config_sha256)
    if frame is not None:
        rec["points"] = len(frame)
        if frame.ring is not None and len(frame):
            rec["rings"] = int(np.unique(frame.ring).size)
    return rec


def fix3d_text(
    fix: Fix3D,
    *,
    source: str | None = None,
    frame: Frame3D | None = None,
    inputs: ReportInputs | None = None,
    range_sigma_m: float,
    survey_sigma_m: float,
) -> str:
    """A survey-style report of one 3D frame's fix (or of why there is none)."""
    inputs = inputs or ReportInputs(scan_file=source)
    when = inputs.computed_utc.strftime("%Y-%m-%d %H:%M:%S UTC")
    lines = [f"MAST 3D fix report                       mast {__version__}, {when}", "Inputs"]
    if inputs.scan_file is not None:
        lines.append(f"  Scan file     {inputs.scan_file}")
    if source is not None and source != inputs.scan_file:
        lines.append(f"  Frame         {source}")
    if frame is not None:
        rings = "" if frame.ring is None else f", {np.unique(frame.ring).size} rings"
        lines.append(f"  Points        {len(frame)}{rings}")
    if inputs.survey_file is not None:
        lines.append(f"  Survey file   {inputs.survey_file}")
    if inputs.crs is not None:
        lines.append(f"  Grid CRS      {inputs.crs.line()}")
    if inputs.scanner is not None:
        lines.append(f"  Scanner       {inputs.scanner}")
    surveyed = inputs.survey_sigmas or f"{_mm(survey_sigma_m)} mm per edge coordinate"
    lines += [f"  Range σ       {_mm(range_sigma_m)} mm", f"  Survey σ      {surveyed}"]
    adj = fix.adjustment
    if not fix.ok or fix.pose is None or adj is None:
        lines += [
            f"Result        NO FIX ({fix.reason}): {NO_FIX_REASONS.get(fix.reason or '', '')}",
            f"  {fix.detail}",
        ]
        return "\n".join(lines)
    p = fix.pose
    st = Stats3D.of(adj)
    sig, ci = st.sigma, st.ci95
    az = math.degrees(p.azimuth) % 360.0

    def angle(name: str, value_deg: str, k: int) -> str:
        s = format_dms(math.degrees(sig[k]), signed=True)
        c = format_dms(math.degrees(ci[k]), signed=True)
        return f"  {name:<9} {value_deg:>15}     σ {s:>10}   95% ± {c}"

    z_line = (
        f"  Elevation {p.elevation:15.4f} m   σ {_mm2(sig[2])} mm   95% ± {_mm2(ci[2])} mm"
        if st.elevation_observed
        else f"  Elevation {p.elevation:15.4f} m   NOT OBSERVED (no beacon's top edges "
        "bracketed it to 5 cm): not to survey precision"
    )
    lines += [
        "Result        FIX (six degrees of freedom)",
        f"  Easting   {p.easting:15.4f} m   σ {_mm2(sig[0])} mm   95% ± {_mm2(ci[0])} mm",
        f"  Northing  {p.northing:15.4f} m   σ {_mm2(sig[1])} mm   95% ± {_mm2(ci[1])} mm",
        z_line,
        angle("Azimuth", format_dms(az), 5),
        angle("Roll", f"{math.degrees(p.roll):+.4f}°", 3),
        angle("Pitch", f"{math.degrees(p.pitch):+.4f}°", 4),
        "Statistics",
        f"  Reference variance {adj.reference_variance:.3f} on {adj.dof} degrees of freedom; "
        f"chi-square test at 5 % (accept {st.chi2_lower:.3f} to {st.chi2_upper:.3f}): "
        f"{_TEST_WORDS[st.test_code]}",
        f"  Beacons used  {', '.join(fix.beacons)}; {adj.returns} returns on their panels, "
        f"{adj.top_edges} beacon(s) whose top edges bracket the elevation",
        f"How it was found: the plan view's 2D fix (E {fix.plan.pose.easting:.3f}, "
        f"N {fix.plan.pose.northing:.3f}) refined in six parameters, "
        f"{1e3 * fix.elapsed_s:.1f} ms in all"
        if fix.plan.pose is not None
        else f"How it was found: a plan view confirming one beacon started the six "
        f"parameters, which found the others where it put them, "
        f"{1e3 * fix.elapsed_s:.1f} ms in all",
    ]
    return "\n".join(line for line in lines if line)
