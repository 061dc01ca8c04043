"""Survey-in benchmark: simulated terrestrial scans through ``mast survey-in``.

Each scene is a drift with beacons of several designs on rough rock
(:func:`mast.sim.tls.simulate_tls`), scanned from two or three tripod stations by a
phase-based scanner (1-2 mm range noise, 4 or 6 mm at 10 m); ``far_scenes`` more, each
scanned from two stations 45-50 m apart in a 90-100 m drift (beacons up to 25 m from the
nearer, drawn apart from the first scenes so that those keep theirs). Per scene:

* **Eligible** beacons: within 25 m of a station, every panel showing at least
  :data:`MIN_PANEL_POINTS` points in the scans (a panel no station sees cannot be
  surveyed, whatever the method). Found: surveyed in with the right design; wrong
  design; invented (a beacon surveyed where none stands, or not within
  :data:`SAME_M` of one).
* **Errors**: each edge's horizontal error against the truth, and its elevation's,
  for beacons within 15 m of a station and beyond; their RMS; the share of edge
  coordinates inside +-1.96 ``sigma_m`` (each station's setup is 1 mm off, and
  ``--station-sigma`` says so).
* **Re-survey**: the truth as the previous survey (its ``sigma_m`` 0.5 mm) with one
  beacon 8 mm away from where it stands: that beacon named as moved, no other one.

Run: ``mast bench survey-in``.
"""

from __future__ import annotations

import json
import math
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mast.bench.rows import write_rows

__all__ = ["SurveyInFigures", "run_survey_in_bench"]

#: A panel shows in the scans with at least this many points.
MIN_PANEL_POINTS = 50
#: A surveyed beacon is a true one when their centres are this close.
SAME_M = 0.25
#: The reach the targets speak of: found within 25 m of a station, errors within 15 m.
FOUND_REACH_M, ERROR_REACH_M = 25.0, 15.0
#: The far scenes' seed offset: two stations 45-50 m apart in a 90-100 m drift, so that
#: beacons stand up to 25 m from the nearer.
FAR_SEED = 1000
#: How far the moved beacon is moved on the re-survey.
MOVE_M = 0.008
#: What a real scan adds to the simulator's ideal one: each station's setup 1 mm off per
#: horizontal coordinate (given to survey-in as --station-sigma, as a surveyor states
#: it), panels bulging 1 mm at their middle, a 3.5 mm beam at the exit (0.3 mrad
#: divergence) whose footprint mixes a panel's boundary with what lies behind it.
STATION_SIGMA_M = 0.001
PANEL_BOW_M = 0.001
BEAM_EXIT_M = 0.0035


@dataclass(slots=True)
class SurveyInFigures:
    scenes: int = 0
    eligible: int = 0
    found: int = 0
    wrong_design: int = 0
    invented: int = 0
    moved_named: int = 0
    still_named: int = 0
    resurveys: int = 0
    eligible_far: int = 0
    found_far: int = 0
    edges_near: list[float] = field(default_factory=list)
    edges_far: list[float] = field(default_factory=list)
    elevations_near: list[float] = field(default_factory=list)
    inside: int = 0
    coordinates: int = 0
    edge_on: int = 0  # middle panels seen edge-on, their beacon refused (reported)
    edge_on_astray: int = 0  # of those, none at a beacon
    seconds: list[float] = field(default_factory=list)


def run_survey_in_bench(
    *,
    scenes: int = 12,
    far_scenes: int = 0,
    seed: int = 0,
    out: Path | None = None,
    echo: Callable[[str], object] = print,
) -> SurveyInFigures:
    """Run the benchmark (see the module) and print its figures."""
    from mast.cloud.survey_in import SurveyInConfig, survey_in
    from mast.core.beacon import Beacon, Survey
    from mast.io import read_survey
    from mast.sim.tls import TlsOptions, simulate_tls

    f = SurveyInFigures()
    rows: list[dict[str, object]] = []
    rng = np.random.default_rng(seed)
    far = np.random.default_rng(seed + FAR_SEED)  # the scenes above keep their draws
    with tempfile.TemporaryDirectory(prefix="mast-bench-survey-in-") as tmp:
        for k in range(scenes + far_scenes):
            r = rng if k < scenes else far
            o = TlsOptions(
                length_m=float(r.uniform(35.0, 55.0) if k < scenes else r.uniform(90.0, 100.0)),
                beacons=int(r.integers(4, 7) if k < scenes else r.integers(6, 9)),
                designs=3,
                stations=int(r.integers(2, 4)) if k < scenes else 2,
                range_noise_m=float(r.uniform(0.001, 0.002)),
                step_rad=float(r.choice([0.0004, 0.0006])),
                roughness_m=float(r.uniform(0.02, 0.05)),
                station_sigma_m=STATION_SIGMA_M,
                panel_bow_m=PANEL_BOW_M,
                beam_exit_m=BEAM_EXIT_M,
            )
            scene = simulate_tls(Path(tmp) / f"s{k}", seed + k, o)
            truth = read_survey(scene.survey)
            designs = read_survey(scene.designs, apart=False)
            facts = {b["id"]: b for b in json.loads(scene.truth.read_text())["beacons"]}
            stations = np.array([s[:2] for s in scene.stations])
            config = SurveyInConfig(noise_m=o.range_noise_m, station_sigma_m=STATION_SIGMA_M)
            t0 = time.perf_counter()
            result = survey_in([scene.e57], designs, config)
            f.seconds.append(time.perf_counter() - t0)
            f.scenes += 1
            near_station = {
                b.id: float(np.min(np.hypot(*(stations - b.edges.mean(axis=0)).T))) for b in truth
            }
            eligible = {
                b.id
                for b in truth
                if near_station[b.id] <= FOUND_REACH_M
                and min(facts[b.id]["points_per_panel"]) >= MIN_PANEL_POINTS
            }
            f.eligible += len(eligible)
            matched: set[str] = set()
            for fb in result.beacons:
                b = fb.beacon
                centre = b.edges.mean(axis=0)
                t = min(truth, key=lambda t: math.dist(t.edges.mean(axis=0), centre))
                if math.dist(t.edges.mean(axis=0), centre) > SAME_M:
                    f.invented += 1
                    continue
                if b.design != t.design:
                    f.wrong_design += 1
                    continue
                matched.add(t.id)
                err = np.hypot(*(b.edges - t.edges).T)
                sig = b.edge_sigmas_m if b.edge_sigmas_m is not None else np.full(4, np.nan)
                inside = np.abs(b.edges - t.edges) <= 1.96 * sig[:, None]
                f.inside += int(np.sum(inside))
                f.coordinates += 8
                dz = math.nan
                if b.elevations is not None and t.elevations is not None:
                    dz = float(b.elevations[0] - t.elevations[0])
                near = near_station[t.id] <= ERROR_REACH_M
                (f.edges_near if near else f.edges_far).extend(err.tolist())
                if near:
                    f.elevations_near.append(dz)
                rows.append(
                    {
                        "scene": k,
                        "beacon": t.id,
                        "design": t.design,
                        "station_m": round(near_station[t.id], 2),
                        "max_edge_error_mm": round(1000 * float(err.max()), 3),
                        "max_sigma_mm": round(1000 * float(np.nanmax(sig)), 3),
                        "elevation_error_mm": round(1000 * dz, 3),
                        "inside_196": int(np.sum(inside)),
                        "panel_points": "/".join(str(n) for n in fb.points_per_panel),
                    }
                )
            f.found += len(matched & eligible)
            for c in result.edge_on:
                f.edge_on += 1
                f.edge_on_astray += all(math.dist(c, t.edges.mean(axis=0)) > SAME_M for t in truth)
            far_ones = {b for b in eligible if near_station[b] > ERROR_REACH_M}
            f.eligible_far += len(far_ones)
            f.found_far += len(matched & far_ones)
            # the re-survey: one found beacon moved by 8 mm in the previous survey
            if matched:
                moved = sorted(matched)[0]
                before = Survey(
                    [
                        Beacon(
                            b.id,
                            b.edges + ([MOVE_M, 0.0] if b.id == moved else 0.0),
                            b.elevations,
                            np.full(4, 0.0005),
                            b.design,
                        )
                        for b in truth
                    ]
                )
                again = survey_in([scene.e57], designs, config, previous=before)
                f.resurveys += 1
                for fb in again.beacons:
                    named = any(fb.moved)
                    if fb.previous == moved and named:
                        f.moved_named += 1
                    elif named:
                        f.still_named += 1
            echo(
                f"scene {k}: {len(matched & eligible)} of {len(eligible)} eligible found, "
                f"{len(result.beacons)} surveyed, {result.partial} in part, "
                f"{len(result.edge_on)} edge-on refused, "
                f"{scene.points} points, {f.seconds[-1]:.1f} s"
            )
    if out is not None:
        write_rows(out, rows)
    _report(f, echo)
    return f


def _rms(v: list[float]) -> float:
    return math.sqrt(statistics.fmean(x * x for x in v)) if v else math.nan


def _report(f: SurveyInFigures, echo: Callable[[str], object]) -> None:
    echo("")
    echo(
        f"{f.scenes} scenes: {f.found} of {f.eligible} eligible beacons found with their "
        f"design ({100 * f.found / max(f.eligible, 1):.1f} %), wrong design {f.wrong_design}, "
        f"invented {f.invented}; beyond {ERROR_REACH_M:g} m {f.found_far} of {f.eligible_far}"
    )
    echo(
        f"edge horizontal error RMS within {ERROR_REACH_M:g} m {1000 * _rms(f.edges_near):.2f} mm "
        f"({len(f.edges_near)} edges; worst {1000 * max(f.edges_near, default=math.nan):.2f} mm), "
        f"beyond {1000 * _rms(f.edges_far):.2f} mm ({len(f.edges_far)} edges); elevation RMS "
        f"within {ERROR_REACH_M:g} m {1000 * _rms(f.elevations_near):.2f} mm"
    )
    echo(
        f"middle panels seen edge-on, their beacon refused and reported: {f.edge_on} "
        f"({f.edge_on_astray} not at a beacon)"
    )
    echo(
        f"edge coordinates inside +-1.96 sigma_m: {f.inside} of {f.coordinates} "
        f"({f.inside / max(f.coordinates, 1):.3f})"
    )
    echo(
        f"re-survey with one beacon {1000 * MOVE_M:g} mm away: named as moved in {f.moved_named} "
        f"of {f.resurveys}; beacons that did not move named {f.still_named}"
    )
    if f.seconds:
        echo(f"survey-in time per scene: median {statistics.median(f.seconds):.1f} s")
