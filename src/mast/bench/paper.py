"""``mast reproduce paper``: the MAST paper's simulation experiments, re-run and reported.

Experiments (the paper's "Simulation Results"): the seven scanner positions of
Table 2 at 0.25 and 0.5 degree resolution; Beacon 1 convergent, parallel and
divergent (yawed -10, 0, +10 degrees); beacon lengths 0.499 to 1.996 m with
depths 0.100 to 0.400 m. Each is run noise-free, as in the paper, and with
realistic range noise (many draws), and written as a Markdown report with
figures, beside the paper's published values (``data/paper_table2.csv``).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from importlib.resources import files
from pathlib import Path

import numpy as np

from mast.core.pose import format_dms, parse_azimuth
from mast.io.atomic import atomic_open, write_atomic
from mast.io.outputs import save_figure
from mast.pipeline.locator import LocatorConfig, locate
from mast.sim import PAPER_VARIANTS, Scene, paper_scene, simulate_scan

__all__ = ["PaperRow", "load_paper_table2", "reproduce_paper"]

SIZES = ((0.499, 0.100), (0.998, 0.200), (1.497, 0.300), (1.996, 0.400))
NOISE_M = 0.012


@dataclass(frozen=True, slots=True)
class PaperRow:
    """One row of the paper's Table 2 as transcribed (``None`` where illegible)."""

    resolution_deg: float
    row: int
    position: str
    true_e: float
    true_n: float
    err_e_m: float | None
    err_n_m: float | None
    az_err_arcsec: float | None
    ci95_az_arcsec: float | None
    note: str


def _num(text: str) -> float | None:
    text = text.strip()
    return float(text) if text else None


def _dms(text: str) -> float | None:
    text = text.strip()
    return None if not text else parse_azimuth(text)


def load_paper_table2() -> list[PaperRow]:
    """The paper's Table 2 from the packaged transcription (source named in the file)."""
    raw = files("mast").joinpath("data/paper_table2.csv").read_text(encoding="utf-8")
    lines = [ln for ln in raw.splitlines() if ln and not ln.startswith("#")]
    out = []
    for r in csv.DictReader(lines):
        az_err = _dms(r["az_err"])
        ci = _dms(r["ci95_az"])
        out.append(
            PaperRow(
                resolution_deg=float(r["resolution_deg"]),
                row=int(r["row"]),
                position=f"P{r['position']}" if r["position"] else "?",
                true_e=float(r["true_e"]),
                true_n=float(r["true_n"]),
                err_e_m=_num(r["err_e"]),
                err_n_m=_num(r["err_n"]),
                az_err_arcsec=None if az_err is None else _signed_small(az_err) * 3600,
                ci95_az_arcsec=None if ci is None else ci * 3600,
                note=r["note"],
            )
        )
    return out


def _signed_small(deg: float) -> float:
    """An error written as an azimuth (e.g. 359 59 38.5) as a small signed angle."""
    return math.remainder(deg, 360.0)


@dataclass
class ShotResult:
    scene: str
    variant: str
    label: str
    position: str
    resolution_deg: float
    chord_m: float
    depth_m: float
    exact_err_mm: float
    exact_az_err_arcsec: float
    exact_fixed: bool
    options: str
    noisy_fix_rate: float
    noisy_rms_pos_mm: float
    noisy_rms_az_arcsec: float
    noisy_mean_sigma_az_arcsec: float
    noisy_coverage_az: float
    points_used: float


def _run_shot(scene: Scene, k: int, draws: int, seed: int) -> ShotResult:
    shot = scene.shots[k]
    exact = simulate_scan(scene.world, shot.pose, shot.scanner.noise_free())
    fix = locate(
        exact.scan, scene.survey, config=LocatorConfig(range_sigma_m=NOISE_M, survey_sigma_m=0.0)
    )
    e_pos = e_az = math.nan
    opts = ""
    if fix.ok and fix.pose is not None:
        e_pos = 1e3 * math.hypot(
            fix.pose.easting - shot.pose.easting, fix.pose.northing - shot.pose.northing
        )
        e_az = (
            math.degrees(math.remainder(fix.pose.azimuth - shot.pose.azimuth, 2 * math.pi)) * 3600
        )
        opts = " ".join(
            sorted(
                {f"{n.beacon}e{n.edge}:{n.option}" for n in fix.nodes if n.beacon in fix.beacons}
            )
        )
    noisy = replace(shot.scanner, range_sigma_m=NOISE_M)
    rng = np.random.default_rng([seed, k, int(shot.scanner.resolution_deg * 1000)])
    pos, az, sig, cover, pts = [], [], [], [], []
    for _ in range(draws):
        sim = simulate_scan(scene.world, shot.pose, noisy, rng=rng)
        f = locate(
            sim.scan, scene.survey, config=LocatorConfig(range_sigma_m=NOISE_M, survey_sigma_m=0.0)
        )
        if not f.ok or f.pose is None or f.adjustment is None:
            continue
        pos.append(
            math.hypot(f.pose.easting - shot.pose.easting, f.pose.northing - shot.pose.northing)
        )
        a = math.remainder(f.pose.azimuth - shot.pose.azimuth, 2 * math.pi)
        az.append(a)
        sig.append(f.adjustment.sigma[2])
        cover.append(abs(a) <= f.adjustment.interval95()[2])
        pts.append(f.points_used)
    n = len(pos)
    return ShotResult(
        scene=scene.name,
        variant=str(scene.params["variant"]),
        label=shot.label,
        position=shot.label.split("@")[0],
        resolution_deg=shot.scanner.resolution_deg,
        chord_m=float(scene.params["chord_m"]),  # type: ignore[arg-type]
        depth_m=float(scene.params["depth_m"]),  # type: ignore[arg-type]
        exact_err_mm=e_pos,
        exact_az_err_arcsec=e_az,
        exact_fixed=fix.ok,
        options=opts,
        noisy_fix_rate=n / draws if draws else math.nan,
        noisy_rms_pos_mm=1e3 * float(np.sqrt(np.mean(np.square(pos)))) if n else math.nan,
        noisy_rms_az_arcsec=math.degrees(float(np.sqrt(np.mean(np.square(az))))) * 3600
        if n
        else math.nan,
        noisy_mean_sigma_az_arcsec=math.degrees(float(np.mean(sig))) * 3600 if n else math.nan,
        noisy_coverage_az=float(np.mean(cover)) if n else math.nan,
        points_used=float(np.mean(pts)) if n else math.nan,
    )


def reproduce_paper(
    out_dir: Path, *, draws: int = 30, seed: int = 0, echo: Callable[[str], object] = print
) -> Path:
    """Run the paper's experiments and write ``report.md``, figures and ``results.csv``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    results: list[ShotResult] = []
    for chord, depth in SIZES:
        for variant in PAPER_VARIANTS:
            scene = paper_scene(variant, chord_m=chord, depth_m=depth)
            for k in range(len(scene.shots)):
                results.append(_run_shot(scene, k, draws, seed))
        echo(f"beacons {chord:.3f} m × {depth:.3f} m: done")
    _write_csv(out_dir / "results.csv", results)
    _figures(out_dir, results)
    report = out_dir / "report.md"
    write_atomic(report, _report(results, draws).encode("utf-8"))
    echo(f"wrote {report}")
    return report


def _write_csv(path: Path, rows: list[ShotResult]) -> None:
    from dataclasses import asdict

    with atomic_open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(asdict(rows[0])))
        w.writeheader()
        for r in rows:
            w.writerow(asdict(r))


POSITIONS = ("P1", "P2", "P3", "P4", "P5", "P6", "P7")


def _figures(out: Path, rows: list[ShotResult]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mast.report.plot import plot_fix

    # Figure 3 panels: the default beacons, P1 and P4 at 0.25 deg, parallel walls.
    scene = paper_scene("parallel", chord_m=0.998, depth_m=0.2)
    for k in (0, 1):
        shot = scene.shots[k]
        sim = simulate_scan(scene.world, shot.pose, shot.scanner)
        fix = locate(
            sim.scan, scene.survey, config=LocatorConfig(range_sigma_m=NOISE_M, survey_sigma_m=0.0)
        )
        plot_fix(
            sim.scan,
            scene.survey,
            fix,
            out / f"figure3_{shot.label.split('@')[0]}.png",
            title=f"{scene.name} {shot.label}",
        )

    default = [r for r in rows if abs(r.chord_m - 0.998) < 1e-9]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    width = 0.38
    for j, res in enumerate((0.25, 0.5)):
        pos_rms, az_rms = [], []
        for p in POSITIONS:
            sel = [r for r in default if r.position == p and r.resolution_deg == res]
            pos_rms.append(_mean([r.noisy_rms_pos_mm for r in sel]))
            az_rms.append(_mean([r.noisy_rms_az_arcsec for r in sel]))
        x = np.arange(len(POSITIONS)) + (j - 0.5) * width
        axes[0].bar(x, pos_rms, width, label=f"{res}°")
        axes[1].bar(x, az_rms, width, label=f"{res}°")
    for ax, lab in zip(
        axes, ("RMS position error (mm)", "RMS azimuth error (arc-seconds)"), strict=True
    ):
        ax.set_xticks(np.arange(len(POSITIONS)), POSITIONS)
        ax.set_ylabel(lab)
        ax.legend(title="resolution")
    fig.suptitle(f"Errors by position, {1000 * NOISE_M:g} mm range noise, beacons 0.998 m × 0.2 m")
    fig.tight_layout()
    save_figure(fig, out / "errors_by_position.png", dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for res in (0.25, 0.5):
        xs, ps, zs = [], [], []
        for chord, _ in SIZES:
            sel = [r for r in rows if abs(r.chord_m - chord) < 1e-9 and r.resolution_deg == res]
            xs.append(chord)
            ps.append(_mean([r.noisy_rms_pos_mm for r in sel]))
            zs.append(_mean([r.noisy_rms_az_arcsec for r in sel]))
        axes[0].plot(xs, ps, "o-", label=f"{res}°")
        axes[1].plot(xs, zs, "o-", label=f"{res}°")
    axes[0].set_ylabel("RMS position error (mm)")
    axes[1].set_ylabel("RMS azimuth error (arc-seconds)")
    for ax in axes:
        ax.set_xlabel("beacon length (m), depth = length / 5")
        ax.legend(title="resolution")
    fig.suptitle(f"Errors by beacon size and resolution, {1000 * NOISE_M:g} mm range noise")
    fig.tight_layout()
    save_figure(fig, out / "errors_by_size.png", dpi=110)
    plt.close(fig)


def _mean(values: list[float]) -> float:
    """Mean of the finite values; nan when there are none (no fix in any draw)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else math.nan


def _f(x: float, nd: int = 2) -> str:
    return "—" if not math.isfinite(x) else f"{x:.{nd}f}"


def _report(rows: list[ShotResult], draws: int) -> str:
    paper = load_paper_table2()
    default = [r for r in rows if abs(r.chord_m - 0.998) < 1e-9]
    lines = [
        "# The MAST paper's experiments, reproduced",
        "",
        "Generated by `mast reproduce paper`. Layout reconstructed from the paper's Table 2 "
        "(see `mast.sim.scenarios.PAPER_VARIANTS`): Beacon 2 on the west wall at (6, 7); "
        "Beacon 1 9 m east of P1 = (7, 7), turned about P1 by −10° / 0° / +10° "
        "(convergent / parallel / divergent walls); P5/P6/P7 1 m west of Beacon 1, "
        "P2/P3/P4 halfway, facing the mean wall direction. Beacons: the paper's 2:3:1 "
        "hat (`mast.sim.paper_design`), lengths 0.499–1.996 m with depths 0.100–0.400 m. "
        "Scanner: 270° field of view at 0.25° and 0.5°.",
        "",
        f"*Noise-free* runs are as in the paper. *Noisy* runs add {1000 * NOISE_M:g} mm Gaussian "
        f"range noise, {draws} draws per shot; the adjustment is told that σ.",
        "",
        "## Table 2: ours beside the paper's",
        "",
        "Paper values transcribed from Table 2 (`src/mast/data/paper_table2.csv`; the "
        "extracted table is garbled, rows with illegible cells are marked). Ours: beacons "
        "0.998 m × 0.2 m, the wall configuration that matches each position (P2/P5 divergent, "
        "P3/P6 convergent, P4/P7 parallel, P1 all three).",
        "",
        "| res. | pos. | paper ΔE, ΔN (mm) | paper az. error | paper 95 % CI az. | ours noise-free ΔE,N (mm) | "
        "ours noise-free az. error | ours noisy RMS pos. (mm) | ours noisy RMS az. | ours noisy 95 % CI az. (mean) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for p in paper:
        ours = [
            r for r in default if r.position == p.position and r.resolution_deg == p.resolution_deg
        ]
        if p.err_e_m is None or p.err_n_m is None:
            perr = "illegible"
        else:
            perr = f"{1e3 * p.err_e_m:+.0f}, {1e3 * p.err_n_m:+.0f}"
        paz = (
            "illegible"
            if p.az_err_arcsec is None
            else format_dms(p.az_err_arcsec / 3600, signed=True)
        )
        pci = (
            "illegible"
            if p.ci95_az_arcsec is None
            else "±" + format_dms(p.ci95_az_arcsec / 3600, signed=True)
        )
        if ours:
            ex = max(r.exact_err_mm for r in ours)
            exa = max(abs(r.exact_az_err_arcsec) for r in ours)
            nrp = _mean([r.noisy_rms_pos_mm for r in ours])
            nra = _mean([r.noisy_rms_az_arcsec for r in ours])
            nci = 1.96 * (_mean([r.noisy_mean_sigma_az_arcsec for r in ours]))
            o = (
                f"{ex:.1e}",
                format_dms(exa / 3600, signed=True, decimals=4),
                _f(nrp),
                format_dms(nra / 3600, signed=True),
                "±" + format_dms(nci / 3600, signed=True),
            )
        else:
            o = ("—",) * 5
        lines.append(
            f"| {p.resolution_deg:g}° | {p.position} | {perr} | {paz} | {pci} | "
            + " | ".join(o)
            + " |"
        )
    lines += [
        "",
        "## All positions, resolutions and wall configurations (beacons 0.998 m × 0.2 m)",
        "",
        '| walls | shot | noise-free fixed | noise-free pos. error (m) | noise-free az. error (") | '
        "corners used (beacon, edge: Table 1 option) | noisy fix rate | noisy RMS pos. (mm) | "
        'noisy RMS az. (") | mean σ az. (") | az. 95 % coverage | returns used |',
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in default:
        lines.append(
            f"| {r.variant} | {r.label} | {'yes' if r.exact_fixed else 'no'} | {r.exact_err_mm / 1e3:.1e} | "
            f"{r.exact_az_err_arcsec:.1e} | {r.options} | {r.noisy_fix_rate:.2f} | {_f(r.noisy_rms_pos_mm)} | "
            f"{_f(r.noisy_rms_az_arcsec, 1)} | {_f(r.noisy_mean_sigma_az_arcsec, 1)} | {_f(r.noisy_coverage_az)} | "
            f"{_f(r.points_used, 0)} |"
        )
    lines += [
        "",
        "## Beacon size",
        "",
        '| length × depth (m) | resolution | noise-free max pos. error (m) | noise-free max az. error (") | '
        'noisy fix rate | noisy RMS pos. (mm) | noisy RMS az. (") | returns used |',
        "|---|---|---|---|---|---|---|---|",
    ]
    for chord, depth in SIZES:
        for res in (0.25, 0.5):
            sel = [r for r in rows if abs(r.chord_m - chord) < 1e-9 and r.resolution_deg == res]
            lines.append(
                f"| {chord:.3f} × {depth:.3f} | {res}° | {max(r.exact_err_mm for r in sel) / 1e3:.1e} | "
                f"{max(abs(r.exact_az_err_arcsec) for r in sel):.1e} | "
                f"{np.mean([r.noisy_fix_rate for r in sel]):.2f} | {_f(_mean([r.noisy_rms_pos_mm for r in sel]))} | "
                f"{_f((_mean([r.noisy_rms_az_arcsec for r in sel])), 1)} | {_f((_mean([r.points_used for r in sel])), 0)} |"
            )
    exact_all = [r for r in rows if r.exact_fixed]
    max_pos = max(r.exact_err_mm for r in exact_all) / 1e3
    max_az = max(abs(r.exact_az_err_arcsec) for r in exact_all)
    az25 = _mean([r.noisy_rms_az_arcsec for r in rows if r.resolution_deg == 0.25])
    az50 = _mean([r.noisy_rms_az_arcsec for r in rows if r.resolution_deg == 0.5])
    pos_noisy = np.nanmax([r.noisy_rms_pos_mm for r in rows])
    by_size = {chord: [r for r in rows if abs(r.chord_m - chord) < 1e-9] for chord, _ in SIZES}
    size_text = "; ".join(
        f"{chord:.3f} m: fixed in {100 * _mean([r.noisy_fix_rate for r in sel]):.0f} % of noisy scans, "
        f'RMS azimuth error {_f(_mean([r.noisy_rms_az_arcsec for r in sel]), 0)}"'
        for chord, sel in by_size.items()
    )
    default_ok = [r for r in default if math.isfinite(r.points_used)]
    dense = [r for r in default_ok if r.position in ("P1", "P5", "P6", "P7")]
    sparse = [r for r in default_ok if r.position in ("P2", "P3", "P4")]
    dense_pts, sparse_pts = (
        _mean([r.points_used for r in dense]),
        _mean([r.points_used for r in sparse]),
    )
    dense_pos, sparse_pos = (
        _mean([r.noisy_rms_pos_mm for r in dense]),
        _mean([r.noisy_rms_pos_mm for r in sparse]),
    )
    dense_az, sparse_az = (
        _mean([r.noisy_rms_az_arcsec for r in dense]),
        _mean([r.noisy_rms_az_arcsec for r in sparse]),
    )
    exact_missed = [r for r in rows if not r.exact_fixed]
    missed_text = (
        "; the one missed shot ("
        + ", ".join(f"{r.scene} {r.label}, {r.chord_m:.3f} m beacons" for r in exact_missed)
        + ") shows the far beacon with two returns on one panel, which owes no fix"
        if exact_missed
        else ""
    )
    fixed_exact = sum(r.exact_fixed for r in rows)
    lines += [
        "",
        "## Figures",
        "",
        "![Figure 3, P1](figure3_P1.png)",
        "",
        "![Figure 3, P4](figure3_P4.png)",
        "",
        "![Errors by position](errors_by_position.png)",
        "",
        "![Errors by size](errors_by_size.png)",
        "",
        "## The paper's conclusions, checked",
        "",
        f"- **Positions are sub-centimetre everywhere: agree.** Noise-free, {fixed_exact} of {len(rows)} "
        f"shots fix, with position errors at most {max_pos:.1e} m (the paper: up to 3 mm){missed_text}. With "
        f"{1000 * NOISE_M:g} mm range noise the worst RMS position error of any shot is {pos_noisy:.1f} mm.",
        f"- **Azimuth error is driven by angular resolution: not in the paper's sense.** The paper's "
        f"noise-free orientation errors of 0°00'21\" to 0°14'44\" come from its method, not from the "
        f'geometry: an exact scan admits an exact answer, and ours is within {max_az:.1e}" at both '
        f"resolutions. With noise, resolution matters only through the number of returns: RMS azimuth "
        f'error {az25:.1f}" at 0.25° against {az50:.1f}" at 0.5° (ratio {az50 / az25:.2f}; '
        f"√2 = 1.41 for twice the returns).",
        "- **Beacon size is not a major factor: true without noise, not with it.** Noise-free every "
        f"size fixes exactly. With {1000 * NOISE_M:g} mm noise, size decides whether the beacons can be "
        f"identified at all: {size_text}. The 0.499 m beacon's panels (0.08–0.25 m, a few returns "
        "each at 9 m) bend by hardly more than the noise can show: where no corner is identified "
        "or the beams cannot tell its shape from a straight wall, the locator (rightly) gives no "
        "fix; the paper, noise-free, could not see this.",
        "- **Point density is not a major factor: agree.** Near one beacon (P1, P5–P7) the scan "
        f"holds about {_f(dense_pts, 0)} returns on the beacons, midway (P2–P4) about {_f(sparse_pts, 0)}; "
        f"RMS position error {_f(dense_pos, 1)} mm against {_f(sparse_pos, 1)} mm, RMS azimuth error "
        f'{_f(dense_az, 0)}" against {_f(sparse_az, 0)}". Which panels are seen, and at what '
        "incidence and range, matters more than how many returns fall on them (per-position figure above).",
        "- **The paper's 95 % intervals for X and Y read 0.0000 m** while its errors reach 3 mm: they "
        "cannot have covered the truth. Ours cover it about 95 % of the time (table above, and "
        "docs/accuracy.md over many scenes).",
        "",
    ]
    return "\n".join(lines)
