"""A fix per scan, one core, scans in memory: the whole, each stage, the hottest functions."""

from __future__ import annotations

import cProfile
import functools
import math
import pstats
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from mast.bench.speed.model import (
    OTHER_STAGE,
    PROFILE_SCANS,
    PROFILE_TOP,
    STAGES,
    LocateSpeed,
    Stats,
)
from mast.bench.speed.scans import KeptScans, kept_scans, pose_errors
from mast.core.beacon import Survey
from mast.pipeline.locator import LocatorConfig, locate
from mast.sim import ScannerModel, SimulatedScan

__all__ = ["measure_locate"]


def _clocked(fn: Callable[..., Any], stage: str, clock: dict[str, float]) -> Callable[..., Any]:
    @functools.wraps(fn)
    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            clock[stage] = clock.get(stage, 0.0) + time.perf_counter() - t0

    return timed


@contextmanager
def _stage_clocks(clock: dict[str, float]) -> Iterator[None]:
    """Wrap the locator's stage functions with a clock adding into ``clock`` per stage.

    A function missing from the locator (renamed) is left out: its time is ``other``.
    """
    from mast.pipeline import locator as module

    saved: dict[str, Any] = {}
    for stage, names in STAGES:
        for name in names:
            fn = getattr(module, name, None)
            if callable(fn):
                saved[name] = fn
                setattr(module, name, _clocked(fn, stage, clock))
    try:
        yield
    finally:
        for name, fn in saved.items():
            setattr(module, name, fn)


def _stage_times(
    sims: Sequence[SimulatedScan], survey: Survey, cfg: LocatorConfig
) -> tuple[tuple[tuple[str, Stats], ...], Stats]:
    """Per-stage milliseconds per scan, and the wrapped total."""
    per: dict[str, list[float]] = {stage: [] for stage, _ in STAGES}
    per[OTHER_STAGE] = []
    totals: list[float] = []
    clock: dict[str, float] = {}
    with _stage_clocks(clock):
        for sim in sims:
            clock.clear()
            t0 = time.perf_counter()
            locate(sim.scan, survey, config=cfg)
            total = time.perf_counter() - t0
            totals.append(1e3 * total)
            for stage, _ in STAGES:
                per[stage].append(1e3 * clock.get(stage, 0.0))
            per[OTHER_STAGE].append(1e3 * (total - sum(clock.values())))
    return tuple((s, Stats.of(v)) for s, v in per.items()), Stats.of(totals)


def _hot_functions(
    sims: Sequence[SimulatedScan], survey: Survey, cfg: LocatorConfig
) -> tuple[tuple[str, float], ...]:
    """The functions with the most own time locating ``sims``, with their share."""
    if not sims:
        return ()
    prof = cProfile.Profile()
    prof.enable()
    for sim in sims:
        locate(sim.scan, survey, config=cfg)
    prof.disable()
    raw: dict[tuple[str, int, str], tuple[Any, ...]] = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    total = sum(v[2] for v in raw.values()) or math.nan
    top = sorted(raw.items(), key=lambda kv: -kv[1][2])[:PROFILE_TOP]
    out = []
    for (file, line, func), v in top:
        where = file
        if "site-packages/" in file:
            where = file.rsplit("site-packages/", 1)[1]
        elif "/mast/" in file:
            where = "mast/" + file.rsplit("/mast/", 1)[1]
        elif file.startswith("~"):
            where = "built-in"
        out.append((f"{where}:{line}:{func}" if line else f"{where}:{func}", v[2] / total))
    return tuple(out)


def measure_locate(
    count: int, *, seed: int = 0, model: ScannerModel | None = None, profile: bool = True
) -> tuple[LocateSpeed, KeptScans]:
    """Time ``locate`` on ``count`` kept scans of a drive, then per stage, then profile
    (``PROFILE_SCANS`` of them). Returns the figures and the scans (for the peer)."""
    kept = kept_scans(seed, count, model)
    cfg = LocatorConfig(range_sigma_m=kept.scanner.range_sigma_m)
    stages, wrapped = _stage_times(kept.sims, kept.survey, cfg)
    profiled = kept.sims[:PROFILE_SCANS] if profile else ()
    hot = _hot_functions(profiled, kept.survey, cfg)
    pos, az = [], []
    for sim, fix in zip(kept.sims, kept.fixes, strict=True):
        if fix.ok and fix.pose is not None:
            p, a = pose_errors(sim.pose, fix.pose)
            pos.append(p)
            az.append(a)
    figures = LocateSpeed(
        scanner=kept.scanner.name,
        beams=kept.scanner.beam_count,
        scans=len(kept.sims),
        fixed=sum(f.ok for f in kept.fixes),
        time_ms=Stats.of(1e3 * np.asarray(kept.seconds)),
        stages_ms=stages,
        wrapped_total_ms=wrapped,
        position_err_mm=Stats.of(pos),
        azimuth_err_arcsec=Stats.of(az),
        hot=hot,
        profiled_scans=len(profiled),
    )
    return figures, kept
