"""The accuracy benchmark's 3D configurations: the 3D locator on simulated lidar frames
against the six-parameter bound (issue 36).

Each configuration is a lidar (VLP-16, OS1-64), a range sigma (1, 2, 3 cm) and the
drifts with or without look-alikes (brackets and boards on stand-offs). Its frames come
from :func:`mast.sim.lidar3d.simulate_frames` with the benchmark's seed (the same drifts
and poses for every range sigma), one after another until ``frames`` of them are owed a
fix (:data:`mast.sim.lidar3d.OWED_3D`); every frame simulated is located, owed or not.

Per configuration:

- **fix rate** over the owed frames, and the fixes of frames not owed; and over the
  owed frames whose panel points' own bound (no top-edge bracket) holds roll and pitch
  within :data:`mast.pipeline.locator3d.MAX_TILT_SIGMA_DEG`, the loosest tilt a fix is
  given with (the others' tilt rests on their top edges' brackets, if on anything: the
  rule owes them a fix their panels alone cannot give);
- **wrong fixes**, owed or not (:func:`is_wrong_3d`): confidently wrong, as in 2D
  (:func:`mast.bench.robustness.is_wrong`): more than 5 cm off in position (in 3D where
  the fix observes its elevation, in plan otherwise) or more than 0.25° in azimuth,
  roll or pitch, and outside five of its own sigmas in one of them; and the fixes **far
  off** (:func:`is_far_3d`: more than 0.1 m or 1°, whatever their sigmas), which a fix
  whose tilt the panels hold loosely may be and say so;
- over the owed frames' fixes, per parameter: **RMS/CRB** (each error over its frame's
  own bound, :func:`mast.pipeline.bounds3d.cramer_rao_bound3d` at the true pose from the
  simulator's noise-free returns on the beacon panels, then pooled), **coverage** (the
  share with ``|error| <= 1.96 sigma``, sigma from the fix's own covariance), and the
  median **sigma/CRB** (how much of the bound the returns the locator kept can reach);
  the elevation's are against the top-edge bracket's reference, not a bound (see
  :mod:`mast.pipeline.bounds3d`), over frames where both the truth and the fix have a
  bracket;
- median and 95th percentile errors: plan position and elevation in mm, roll, pitch and
  azimuth in degrees;
- time to locate a frame (:attr:`mast.pipeline.locator3d.Fix3D.elapsed_s`), median and
  95th percentile over every frame located, and the median per 1000 points.

The simulated survey is exact, so the locator and the bound are given no survey sigma.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast.bench.robustness import WRONG_AZIMUTH_RAD, WRONG_POSITION_M, WRONG_SIGMAS
from mast.bench.rows import write_rows
from mast.core.beacon import Survey
from mast.core.pose3d import Frame3D, Pose3D
from mast.pipeline.adjust3d import UNBRACKETED, PanelPlanes
from mast.pipeline.bounds3d import Bound3D, cramer_rao_bound3d
from mast.pipeline.locator3d import MAX_TILT_SIGMA_DEG, Fix3D, Locator3DConfig, locate3d
from mast.sim.lidar3d import SimulatedFrame3D, simulate_frames

__all__ = [
    "ACCURACY3D_CONFIGS",
    "FAR_ANGLE_DEG",
    "FAR_POSITION_M",
    "WRONG_ANGLE_DEG",
    "WRONG_POSITION_M",
    "WRONG_SIGMAS",
    "Accuracy3DConfig",
    "Accuracy3DSummary",
    "errors_3d",
    "is_far_3d",
    "is_wrong_3d",
    "run_accuracy3d",
    "truth_bound_3d",
]

#: A fix further off than this in position, metres, or in azimuth, roll or pitch,
#: degrees, and outside WRONG_SIGMAS of its own sigmas in one of the six, is wrong: the
#: 2D benchmarks' rule and thresholds (:func:`mast.bench.robustness.is_wrong`).
WRONG_ANGLE_DEG = math.degrees(WRONG_AZIMUTH_RAD)
#: A fix further off than this in position, metres, or in an angle, degrees, is far off,
#: whatever its sigmas (counted beside the wrong fixes).
FAR_POSITION_M = 0.1
FAR_ANGLE_DEG = 1.0
#: Short names of :data:`mast.pipeline.adjust3d.PARAMETERS`, in its order.
SHORT = ("E", "N", "Z", "roll", "pitch", "A")
#: Frames simulated for a configuration at most, per owed frame asked for.
MAX_FRAMES_PER_OWED = 20


@dataclass(frozen=True, slots=True)
class Accuracy3DConfig:
    """One configuration: a lidar of :data:`mast.sim.lidar3d.LIDARS`, its range sigma
    and whether the drifts have look-alikes."""

    lidar: str
    range_sigma_m: float
    lookalikes: bool = False

    @property
    def name(self) -> str:
        cm = f"{100 * self.range_sigma_m:g}cm"
        return f"{self.lidar}-{cm}" + ("-lookalikes" if self.lookalikes else "")


#: The issue's configurations: two lidars, three range sigmas, with and without look-alikes.
ACCURACY3D_CONFIGS: tuple[Accuracy3DConfig, ...] = tuple(
    Accuracy3DConfig(lidar, sigma, clutter)
    for lidar in ("vlp16", "os1-64")
    for sigma in (0.01, 0.02, 0.03)
    for clutter in (False, True)
)


@dataclass(frozen=True, slots=True)
class Accuracy3DSummary:
    """One configuration's figures (see the module); per-parameter figures are in
    :data:`~mast.pipeline.adjust3d.PARAMETERS` order, NaN where there is nothing to
    count."""

    config: str
    frames: int
    owed: int
    owed_fixed: int
    fix_rate: float
    owed_tilt_held: int
    """Owed frames whose panel points' own bound holds roll and pitch within
    :data:`~mast.pipeline.locator3d.MAX_TILT_SIGMA_DEG` (the loosest tilt a fix is given
    with): the others are owed by the rule a fix that their panels alone cannot give,
    and only their top edges' brackets may."""
    tilt_held_fix_rate: float
    fixed_not_owed: int
    wrong: int
    far: int
    """Fixes (owed or not) more than 0.1 m or 1° off, whatever their sigmas."""
    misses: str
    ratio: tuple[float, ...]
    ratio_points: tuple[float, ...]
    """RMS error over the panel points' own bound (no bracket: a true Cramér–Rao bound of
    the five they observe; NaN for the elevation)."""
    coverage: tuple[float, ...]
    sigma_over_crb: tuple[float, ...]
    pos_err_median_mm: float
    pos_err_p95_mm: float
    elev_err_median_mm: float
    elev_err_p95_mm: float
    roll_err_median_deg: float
    roll_err_p95_deg: float
    pitch_err_median_deg: float
    pitch_err_p95_deg: float
    az_err_median_deg: float
    az_err_p95_deg: float
    time_median_ms: float
    time_p95_ms: float
    ms_per_kpoint_median: float
    points_median: float
    seconds: float


def errors_3d(got: Pose3D, truth: Pose3D) -> NDArray[np.float64]:
    """``got - truth`` in :data:`~mast.pipeline.adjust3d.PARAMETERS` order, the azimuth
    wrapped to [-pi, pi]."""
    return got.minus(truth)


def _elevation_observed(covariance: NDArray[np.float64]) -> bool:
    return bool(covariance[2, 2] < UNBRACKETED / 2)


def _off(err: NDArray[np.float64], observed: bool, position_m: float, angle_deg: float) -> bool:
    """Whether errors ``err`` (:func:`errors_3d`) are more than ``position_m`` in position
    (in 3D where the fix ``observed`` the elevation, in plan where it says it did not) or
    ``angle_deg`` in azimuth, roll or pitch."""
    position = float(np.linalg.norm(err[:3] if observed else err[:2]))
    return position > position_m or bool(np.any(np.abs(np.degrees(err[3:])) > angle_deg))


def is_wrong_3d(fix: Fix3D, truth: Pose3D) -> bool:
    """Whether a fix is confidently wrong: more than :data:`WRONG_POSITION_M` or
    :data:`WRONG_ANGLE_DEG` off (:func:`_off`) and more than :data:`WRONG_SIGMAS` of its
    own sigmas off in one of the six (the elevation only where the fix observes it). A
    no-fix is not wrong; a fix without an adjustment has no sigmas to hide behind."""
    if not fix.ok or fix.pose is None:
        return False
    err = errors_3d(fix.pose, truth)
    if fix.adjustment is None:
        return _off(err, True, WRONG_POSITION_M, WRONG_ANGLE_DEG)
    observed = _elevation_observed(fix.adjustment.covariance)
    if not _off(err, observed, WRONG_POSITION_M, WRONG_ANGLE_DEG):
        return False
    sigma = np.sqrt(np.diag(fix.adjustment.covariance))
    beyond = np.abs(err) > WRONG_SIGMAS * sigma
    beyond[2] &= observed
    return bool(np.any(beyond))


def is_far_3d(fix: Fix3D, truth: Pose3D) -> bool:
    """Whether a fix is more than :data:`FAR_POSITION_M` or :data:`FAR_ANGLE_DEG` off,
    whatever its sigmas (a loosely held tilt may be, and say so). A no-fix is not."""
    if not fix.ok or fix.pose is None:
        return False
    observed = fix.adjustment is None or _elevation_observed(fix.adjustment.covariance)
    return _off(errors_3d(fix.pose, truth), observed, FAR_POSITION_M, FAR_ANGLE_DEG)


def truth_bound_3d(
    sim: SimulatedFrame3D, planes: PanelPlanes, *, range_sigma_m: float, top_edges: bool = True
) -> Bound3D:
    """The six-parameter bound of a simulated frame at its true pose: every return on a
    surveyed beacon panel (the simulator's labels), at its noise-free range; without
    ``top_edges``, the panel points' own bound of the five they observe."""
    index = {(b, p): k for k, (b, p) in enumerate(zip(planes.beacon, planes.panel, strict=True))}
    panel_of = np.array(
        [
            index.get((s.beacon, s.panel), -1) if s.kind == "beacon" else -1
            for s in sim.drift.surfaces
        ],
        dtype=np.intp,
    )
    pts = sim.frame.points
    exact = pts * (sim.true_range_m / np.linalg.norm(pts, axis=1))[:, None]
    return cramer_rao_bound3d(
        sim.pose, exact, panel_of[sim.surface_index], planes, range_sigma_m=range_sigma_m,
        top_edges=top_edges,
    )  # fmt: skip


Locator3D = Callable[[Frame3D, Survey, Locator3DConfig, PanelPlanes], Fix3D]


def _locate(frame: Frame3D, survey: Survey, config: Locator3DConfig, planes: PanelPlanes) -> Fix3D:
    return locate3d(frame, survey, config=config, planes=planes)


def frame_row(
    config: Accuracy3DConfig, scene: str, index: int, sim: SimulatedFrame3D, fix: Fix3D,
    planes: PanelPlanes,
) -> dict[str, object]:  # fmt: skip
    """One frame's row: what it was owed and got, and for a fix its errors, its sigmas and
    (for an owed frame) the bound at the truth."""
    row: dict[str, object] = {
        "config": config.name,
        "scene": scene,
        "frame": index,
        "points": len(sim.frame),
        "owed": int(sim.owed),
        "fixed": int(fix.ok),
        "wrong": int(is_wrong_3d(fix, sim.pose)),
        "far": int(is_far_3d(fix, sim.pose)),
        "reason": fix.reason or "",
        "elapsed_ms": 1e3 * fix.elapsed_s,
    }
    if sim.owed:
        # the panel points' own bound: whether the frame holds the tilt within what a fix
        # is given with (MAX_TILT_SIGMA_DEG), fixed or not
        points = truth_bound_3d(
            sim, planes, range_sigma_m=config.range_sigma_m, top_edges=False
        ).sigma
        for name, c in zip(SHORT, points, strict=True):
            if name != "Z":
                row[f"crbp_{name}"] = c
        row["tilt_held"] = int(max(points[3], points[4]) <= math.radians(MAX_TILT_SIGMA_DEG))
    if not (fix.ok and fix.pose is not None and fix.adjustment is not None):
        return row
    err = errors_3d(fix.pose, sim.pose)
    sigma = np.sqrt(np.diag(fix.adjustment.covariance))
    z_ok = _elevation_observed(fix.adjustment.covariance)
    row["elevation_observed"] = int(z_ok)
    for name, e, s in zip(SHORT, err, sigma, strict=True):
        row[f"err_{name}"] = e
        row[f"sigma_{name}"] = s
    if sim.owed:
        bound = truth_bound_3d(sim, planes, range_sigma_m=config.range_sigma_m)
        row["crb_returns"] = bound.returns
        row["crb_brackets"] = len(bound.brackets)
        for name, c in zip(SHORT, bound.sigma, strict=True):
            row[f"crb_{name}"] = c if (name != "Z" or z_ok) else math.inf
    return row


def _frames(
    config: Accuracy3DConfig, frames: int, seed: int
) -> Iterable[tuple[str, int, SimulatedFrame3D, Survey]]:
    owed = 0
    stream = simulate_frames(
        seed, frames * MAX_FRAMES_PER_OWED, lidar=config.lidar,
        range_sigma_m=config.range_sigma_m, lookalikes=config.lookalikes,
    )  # fmt: skip
    last, i = "", 0
    for scene, sim in stream:
        i = i + 1 if scene.name == last else 0
        last = scene.name
        yield scene.name, i, sim, scene.survey
        owed += sim.owed
        if owed >= frames:
            return


def run_accuracy3d(
    *,
    configs: Sequence[Accuracy3DConfig] = ACCURACY3D_CONFIGS,
    frames: int = 40,
    seed: int = 0,
    out_dir: Path | None = None,
    echo: Callable[[str], object] = print,
    locator: Locator3D = _locate,
    progress: Callable[[str], object] | None = None,
) -> list[Accuracy3DSummary]:
    """Run every configuration over ``frames`` owed frames (see the module); echo the
    tables; write ``accuracy3d_<config>.csv`` (a row a frame) and
    ``accuracy3d_summary.csv`` into ``out_dir`` when given. ``locator`` locates a frame
    (the 3D locator unless a test gives another); ``progress`` hears each
    configuration's line as it ends."""
    summaries: list[Accuracy3DSummary] = []
    for config in configs:
        t0 = time.perf_counter()
        cfg = Locator3DConfig(range_sigma_m=config.range_sigma_m, survey_sigma_m=0.0)
        rows: list[dict[str, object]] = []
        planes_of: dict[str, PanelPlanes] = {}
        for scene, index, sim, survey in _frames(config, frames, seed):
            planes = planes_of.setdefault(scene, PanelPlanes.of(survey))
            fix = locator(sim.frame, survey, cfg, planes)
            rows.append(frame_row(config, scene, index, sim, fix, planes))
        summaries.append(summarise_3d(config.name, rows, time.perf_counter() - t0))
        if out_dir is not None:
            write_rows(out_dir / f"accuracy3d_{config.name}.csv", rows)
        if progress is not None:
            progress(f"{config.name}: {summaries[-1].owed_fixed}/{summaries[-1].owed} owed fixed")
    echo(table_3d(summaries))
    if out_dir is not None:
        write_rows(out_dir / "accuracy3d_summary.csv", [_flat(s) for s in summaries])
    return summaries


def _flat(s: Accuracy3DSummary) -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in asdict(s).items():
        if isinstance(value, tuple):
            out.update({f"{key}_{name}": v for name, v in zip(SHORT, value, strict=True)})
        else:
            out[key] = value
    return out


def _quantiles(x: NDArray[np.float64]) -> tuple[float, float]:
    if x.size == 0:
        return math.nan, math.nan
    return float(np.median(x)), float(np.percentile(x, 95))


def summarise_3d(config: str, rows: list[dict[str, object]], seconds: float) -> Accuracy3DSummary:
    """A configuration's figures from its frames' rows (:func:`frame_row`)."""

    def col(sel: list[dict[str, object]], key: str) -> NDArray[np.float64]:
        return np.array([float(r[key]) for r in sel if key in r], dtype=float)  # type: ignore[arg-type]

    owed = [r for r in rows if r["owed"]]
    owed_fixed = [r for r in owed if r["fixed"]]
    held = [r for r in owed if r.get("tilt_held")]
    reasons: dict[str, int] = {}
    for r in owed:
        if not r["fixed"]:
            reasons[str(r["reason"])] = reasons.get(str(r["reason"]), 0) + 1
    ratio, coverage, efficiency, ratio_points = [], [], [], []
    for name in SHORT:
        sel = [r for r in owed_fixed if math.isfinite(float(r.get(f"crbp_{name}", math.nan)))]  # type: ignore[arg-type]
        e, c = col(sel, f"err_{name}"), col(sel, f"crbp_{name}")
        ratio_points.append(float(np.sqrt(np.mean((e / c) ** 2))) if e.size else math.nan)
        sel = [r for r in owed_fixed if math.isfinite(float(r.get(f"crb_{name}", math.nan)))]  # type: ignore[arg-type]
        if name == "Z":
            sel = [r for r in sel if r.get("elevation_observed")]
        e, s, c = col(sel, f"err_{name}"), col(sel, f"sigma_{name}"), col(sel, f"crb_{name}")
        some = e.size > 0
        ratio.append(float(np.sqrt(np.mean((e / c) ** 2))) if some else math.nan)
        coverage.append(float(np.mean(np.abs(e) <= 1.96 * s)) if some else math.nan)
        efficiency.append(float(np.median(s / c)) if some else math.nan)
    pos = np.hypot(col(owed_fixed, "err_E"), col(owed_fixed, "err_N")) * 1e3
    z_sel = [r for r in owed_fixed if r.get("elevation_observed")]
    elev = np.abs(col(z_sel, "err_Z")) * 1e3
    roll, pitch, az = (np.abs(np.degrees(col(owed_fixed, f"err_{n}"))) for n in SHORT[3:])
    elapsed = col(rows, "elapsed_ms")
    per_k = elapsed / (col(rows, "points") / 1e3)
    return Accuracy3DSummary(
        config=config,
        frames=len(rows),
        owed=len(owed),
        owed_fixed=len(owed_fixed),
        fix_rate=len(owed_fixed) / len(owed) if owed else math.nan,
        owed_tilt_held=len(held),
        tilt_held_fix_rate=sum(1 for r in held if r["fixed"]) / len(held) if held else math.nan,
        fixed_not_owed=sum(1 for r in rows if r["fixed"] and not r["owed"]),
        wrong=sum(int(r["wrong"]) for r in rows),  # type: ignore[call-overload]
        far=sum(int(r.get("far", 0)) for r in rows),  # type: ignore[call-overload]
        misses=", ".join(f"{k} {v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1])),
        ratio=tuple(ratio),
        ratio_points=tuple(ratio_points),
        coverage=tuple(coverage),
        sigma_over_crb=tuple(efficiency),
        pos_err_median_mm=_quantiles(pos)[0],
        pos_err_p95_mm=_quantiles(pos)[1],
        elev_err_median_mm=_quantiles(elev)[0],
        elev_err_p95_mm=_quantiles(elev)[1],
        roll_err_median_deg=_quantiles(roll)[0],
        roll_err_p95_deg=_quantiles(roll)[1],
        pitch_err_median_deg=_quantiles(pitch)[0],
        pitch_err_p95_deg=_quantiles(pitch)[1],
        az_err_median_deg=_quantiles(az)[0],
        az_err_p95_deg=_quantiles(az)[1],
        time_median_ms=_quantiles(elapsed)[0],
        time_p95_ms=_quantiles(elapsed)[1],
        ms_per_kpoint_median=_quantiles(per_k)[0],
        points_median=_quantiles(col(rows, "points"))[0],
        seconds=seconds,
    )


def _f(x: float, fmt: str) -> str:
    return "-" if not math.isfinite(x) else format(x, fmt)


def table_3d(summaries: Sequence[Accuracy3DSummary]) -> str:
    """The summaries as three tables, as text: fixes, errors and time; per parameter
    RMS/CRB, coverage and sigma/CRB; and the RMS error over the panel points' own bound."""
    from rich import box
    from rich.console import Console
    from rich.table import Table

    first = Table(
        title="3D accuracy: fixes, errors (median / p95) and time per frame",
        title_justify="left",
        box=box.MARKDOWN,
    )
    for col_name in (
        "config", "owed", "fixed", "fix %", "tilt held: owed, fix %", "not owed fixed",
        "WRONG", "> 0.1 m, 1°", "E,N mm", "Z mm", "roll °", "pitch °", "A °", "ms / frame",
        "ms / 1000 pts", "misses (owed)",
    ):  # fmt: skip
        left = col_name.startswith(("config", "m"))
        first.add_column(col_name, justify="left" if left else "right", no_wrap=True)
    for s in summaries:
        first.add_row(
            s.config,
            str(s.owed),
            str(s.owed_fixed),
            _f(100 * s.fix_rate, ".1f"),
            f"{s.owed_tilt_held}, {_f(100 * s.tilt_held_fix_rate, '.1f')}",
            str(s.fixed_not_owed),
            str(s.wrong),
            str(s.far),
            f"{_f(s.pos_err_median_mm, '.1f')} / {_f(s.pos_err_p95_mm, '.1f')}",
            f"{_f(s.elev_err_median_mm, '.1f')} / {_f(s.elev_err_p95_mm, '.1f')}",
            f"{_f(s.roll_err_median_deg, '.3f')} / {_f(s.roll_err_p95_deg, '.3f')}",
            f"{_f(s.pitch_err_median_deg, '.3f')} / {_f(s.pitch_err_p95_deg, '.3f')}",
            f"{_f(s.az_err_median_deg, '.3f')} / {_f(s.az_err_p95_deg, '.3f')}",
            f"{_f(s.time_median_ms, '.0f')} / {_f(s.time_p95_ms, '.0f')}",
            _f(s.ms_per_kpoint_median, ".1f"),
            s.misses or "-",
        )

    def per_parameter(title: str, names: Sequence[str]) -> Table:
        table = Table(title=title, title_justify="left", box=box.MARKDOWN)
        table.add_column("config")
        for name in names:
            table.add_column(name, justify="right")
        return table

    second = per_parameter(
        "3D accuracy of the owed frames' fixes, per parameter: RMS/CRB, 95 % coverage, "
        "median sigma/CRB (Z: against the top-edge bracket's reference)",
        SHORT,
    )
    for s in summaries:
        second.add_row(
            s.config,
            *(
                f"{_f(r, '.2f')} {_f(c, '.2f')} {_f(e, '.2f')}"
                for r, c, e in zip(s.ratio, s.coverage, s.sigma_over_crb, strict=True)
            ),
        )
    third = per_parameter(
        "RMS error over the panel points' own Cramér–Rao bound (no top-edge bracket; "
        "the locator's brackets may beat it)",
        [name for name in SHORT if name != "Z"],
    )
    for s in summaries:
        third.add_row(
            s.config,
            *(_f(r, ".2f") for name, r in zip(SHORT, s.ratio_points, strict=True) if name != "Z"),
        )
    console = Console(width=320)
    with console.capture() as cap:
        console.print(first)
        console.print(second)
        console.print(third)
    return "\n".join(line.rstrip() for line in cap.get().rstrip().splitlines())
