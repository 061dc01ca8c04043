"""Georeference a 3D cloud from the beacons it shows: the one pipeline ``mast georef`` runs.

1. :func:`mast.cloud.detect.find_candidates` and :func:`~mast.cloud.detect.plan_pieces`:
   vertical panels in 3D, reduced to plan lines and corners;
2. :func:`mast.pipeline.identification.identify_panels`: the Table 1 tests of
   ``mast locate``;
3. :func:`mast.cloud.match.detect_beacons` and :func:`~mast.cloud.match.match_beacons`:
   which surveyed beacon each one is;
4. :func:`mast.cloud.adjust.adjust_transformation`: the transformation with its
   tests, check beacons after it;
5. with a trajectory, :func:`mast.cloud.drift.correct_drift`: a pose graph that
   bends the cloud onto the beacons along the run;
6. :mod:`mast.cloud.sought`: the surveyed beacons detection missed, looked for where
   the transformation (or the drift correction) puts them, and stages 4-5 again with
   those found.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from numpy.typing import NDArray

from mast.cloud.adjust import (
    AdjustmentError,
    BeaconObs,
    CheckResult,
    Solution,
    adjust_transformation,
    check_beacons,
    rigid_solution,
)
from mast.cloud.beacon_fit import BeaconFit, fit_beacon
from mast.cloud.detect import (
    BEACON_DENSITY_M2,
    Candidates,
    DetectConfig,
    PlanPieces,
    Progress,
    beacon_top,
    find_candidates,
    plan_pieces,
    points_near,
)
from mast.cloud.drift import DriftCorrection, correct_drift
from mast.cloud.grid import PlanIndex
from mast.cloud.io import Cloud
from mast.cloud.match import Detection, Match, MatchConfig, detect_beacons, match_beacons
from mast.cloud.sought import MAX_SNAP_M, measure_top, reach_m, seek_beacon
from mast.core.beacon import Beacon, Survey
from mast.core.index import SurveyIndex
from mast.core.noise import DEFAULT_SURVEY_SIGMA_M
from mast.core.trajectory import ScannerPath
from mast.errors import InputError
from mast.pipeline.identification import identify_panels

__all__ = ["FoundBeacon", "Georef", "GeorefConfig", "georeference"]

Points = NDArray[np.float64]

MODELS = ("4", "helmert7")
#: Why a beacon matched to no detection is not used (until :func:`explain_missing` says
#: whether it lies outside the cloud or in it unseen).
NOT_FOUND = "not found in the cloud"
#: With a trajectory, the beacons detection missed are looked for where the drift
#: correction puts them this many times, the correction solved again with those found.
SOUGHT_ROUNDS = 2
#: How far (per coordinate, standard deviation) the drift correction's prediction of a
#: beacon may be off: the simulated 1 % drifts' inner checks were up to 8 cm off.
DRIFT_PREDICTION_M = 0.04
#: The beacons sought are fitted to every point of the cloud about them (one more pass,
#: :func:`~mast.cloud.detect.points_near`), read this far beyond the square about their
#: first predicted place: the snap (:data:`~mast.cloud.sought.MAX_SNAP_M`) and the later
#: drift rounds' predictions moving (a beacon whose square is not inside what was read
#: is fitted to the candidates alone).
NEIGHBOURHOOD_SLACK_M = 0.3
#: How a beacon detection missed was found (:mod:`mast.cloud.sought`).
SOUGHT = "not detected on its own: found where the control beacons put it"


@dataclass(frozen=True, slots=True)
class GeorefConfig:
    """What ``mast georef`` is asked to do.

    Attributes
    ----------
    model : str
        ``"4"`` or ``"helmert7"``.
    checks : tuple of str
        Beacons kept out of the solution, reported as the independent check.
    survey_sigma_m : float
        A surveyed coordinate's standard deviation.
    detect, match : the stages' settings.
    drift : float
        The drift model of the pose graph with a trajectory: standard deviation of
        the SLAM's relative motion as a fraction of the distance.
    """

    model: str = "4"
    checks: tuple[str, ...] = ()
    survey_sigma_m: float = DEFAULT_SURVEY_SIGMA_M
    detect: DetectConfig = field(default_factory=DetectConfig)
    match: MatchConfig = field(default_factory=MatchConfig)
    drift: float = 0.01


@dataclass(frozen=True, eq=False)
class FoundBeacon:
    """A surveyed beacon and what became of it.

    ``role``: ``control``, ``check``, ``excluded`` (an outlier left out) or
    ``not_found``; ``why`` says why a beacon is not used.
    """

    beacon: str
    role: str
    obs: BeaconObs | None = None
    why: str = ""


@dataclass(frozen=True, eq=False)
class Georef:
    """Everything one run found, for the outputs and the report."""

    cloud: Cloud
    survey: Survey
    config: GeorefConfig
    candidates: Candidates
    pieces: PlanPieces
    detections: list[Detection]
    match: Match
    beacons: list[FoundBeacon]
    solution: Solution | None
    checks: list[CheckResult]
    heights: bool
    refusal: AdjustmentError | None = None
    drift: DriftCorrection | None = None

    @property
    def controls(self) -> list[BeaconObs]:
        return [b.obs for b in self.beacons if b.role == "control" and b.obs is not None]


#: An inner edge is used only when the outer panel it rests on (P1 for e2, P3 for e3)
#: keeps this share of its surveyed length after the trims near its corners and the
#: wall: a few centimetres of panel give a line whose direction the noise decides, and
#: the node slides along P2 by centimetres (on simulated clouds 3-5 cm of P3 put e3
#: 3-15 cm off, far beyond its covariance).
MIN_OUTER_SHARE = 0.4
#: The edges a beacon's fitted design gives the adjustment (the survey's inner edges).
INNER_EDGES = (2, 3)


def _usable_edges(det: Detection, beacon: str, pieces: PlanPieces, survey: Survey) -> list[int]:
    """The detected inner edges whose outer panel is long enough to place them."""
    lengths = survey[beacon].template.panel_lengths
    out = []
    for e in sorted(det.nodes):
        outer = 1 if e == 2 else 3
        k = det.panels.get(outer)
        if k is None:
            continue
        if pieces.panels[k].segment.length >= MIN_OUTER_SHARE * float(lengths[outer - 1]):
            out.append(e)
    return out


def _start(det: Detection, shape: NDArray[np.float64]) -> NDArray[np.float64]:
    """The design ``shape`` (four edges) placed where a detection puts it: on its two
    inner edges, or on its one edge and the direction of its identified panel."""
    local = shape - shape.mean(axis=0)
    if 2 in det.nodes and 3 in det.nodes:
        seen, design = det.nodes[3] - det.nodes[2], local[2] - local[1]
        at, here = 0.5 * (det.nodes[2] + det.nodes[3]), 0.5 * (local[1] + local[2])
    else:
        (e, at), p = next(iter(det.nodes.items())), det.angle_panel
        seen = np.array([math.cos(det.angle), math.sin(det.angle)])
        design, here = local[p] - local[p - 1], local[e - 1]
    theta = math.atan2(seen[1], seen[0]) - math.atan2(design[1], design[0])
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    return np.asarray(local @ rot.T + (at - rot @ here))


def _design_fit(
    det: Detection,
    shape: NDArray[np.float64],
    pieces: PlanPieces,
    xyz: NDArray[np.float64],
    index: PlanIndex,
    heights: tuple[float, float],
) -> BeaconFit | None:
    """The beacon fitted whole to its candidate points (:mod:`mast.cloud.beacon_fit`)
    between ``heights``."""
    start = _start(det, shape)
    reach = float(np.max(np.hypot(*(shape - shape.mean(axis=0)).T))) + 0.1
    near = xyz[index.square(start.mean(axis=0), reach)]
    return fit_beacon(near, shape, start, heights, pieces.segmentation.noise_m)


def _heights(det: Detection, pieces: PlanPieces) -> tuple[float, float]:
    """A detected beacon's bottom and top as its pieces give them (medians)."""
    panels = [pieces.panels[k] for k in det.panels.values()]
    return (
        float(np.median([p.bottom_m for p in panels])),
        float(np.median([p.top_m for p in panels])),
    )


def _observation(
    det: Detection,
    beacon: str,
    pieces: PlanPieces,
    survey: Survey,
    heights: bool,
    survey_sigma_m: float,
    xyz: NDArray[np.float64],
    index: PlanIndex,
    cfg: DetectConfig,
) -> BeaconObs | None:
    b = survey[beacon]
    span = _heights(det, pieces)
    fit = _design_fit(det, b.edges, pieces, xyz, index, span)
    if fit is not None:
        edges: tuple[int, ...] = INNER_EDGES
        cloud_xy, cloud_cov = fit.edges[[e - 1 for e in edges]], fit.edge_covariance(edges)
    else:
        edges = tuple(_usable_edges(det, beacon, pieces, survey))
        cloud_xy = np.array([det.nodes[e] for e in edges])
        cloud_cov = _block_diagonal([det.covariances[e] for e in edges])
    if not edges:
        return None
    panels = [pieces.panels[k] for k in det.panels.values()]
    times = [p.time_s for p in panels if p.time_s is not None]
    # the top from the fitted panels' points where it can be (its run of heights, not
    # wherever the pieces' points stop), else from the pieces' tops
    top = None
    if fit is not None:
        near = xyz[index.square(fit.edges.mean(axis=0), reach_m(fit.edges))]
        top = measure_top(near, fit.edges, pieces.segmentation.noise_m, cfg, span)
    return _beacon_obs(
        b,
        edges,
        cloud_xy,
        cloud_cov,
        beacon_top(panels) if top is None else top,
        float(np.median(times)) if times else None,
        int(sum(len(p.segment) for p in panels)),
        heights,
        survey_sigma_m,
    )


def _beacon_obs(
    b: Beacon,
    edges: tuple[int, ...],
    cloud_xy: NDArray[np.float64],
    cloud_cov: NDArray[np.float64],
    top: tuple[float, float],
    time: float | None,
    points: int,
    heights: bool,
    survey_sigma_m: float,
) -> BeaconObs:
    """A found beacon's observation of its surveyed ``edges``, with the survey's side."""
    grid_top = math.nan
    if heights and b.elevations is not None:
        z = np.array([b.elevations[e - 1] for e in edges])
        # the observed edges' tops, or the beacon's others where those are blank
        z = z[np.isfinite(z)] if np.any(np.isfinite(z)) else b.elevations[np.isfinite(b.elevations)]
        grid_top = float(np.mean(z))
    return BeaconObs(
        b.id,
        edges,
        cloud_xy,
        cloud_cov,
        top[0],
        top[1],
        np.array([b.edges[e - 1] for e in edges]),
        grid_top,
        time,
        points,
        None
        if b.edge_sigmas_m is None
        else np.array([b.sigmas_or(survey_sigma_m)[e - 1] ** 2 for e in edges]),
    )


def _rigid_to_cloud(solution: Solution) -> Callable[[Points], Points]:
    """Grid edges (E, N and Z, Z nan where unknown) to the cloud's plan by ``solution``."""
    tr = solution.transformation

    def to_cloud(grid: Points) -> Points:
        z = np.where(np.isfinite(grid[:, 2]), grid[:, 2], tr.translation[2])
        return np.asarray(tr.to_cloud(np.column_stack([grid[:, :2], z]))[:, :2])

    return to_cloud


def _drift_to_cloud(drift: DriftCorrection, path: ScannerPath, grid: Points) -> Points:
    """Grid edges (E, N, Z rows) to the cloud's plan by the drift correction."""
    return drift.to_cloud(grid[:, :2], path)


def _predicted(b: Beacon, to_cloud: Callable[[Points], Points]) -> Points:
    """A surveyed beacon's edges in the cloud's plan where ``to_cloud`` puts them."""
    z = b.elevations if b.elevations is not None else np.full(4, math.nan)
    return to_cloud(np.column_stack([b.edges, z]))


@dataclass(frozen=True, eq=False)
class _Near:
    """Every point of the cloud in squares about the beacons sought, indexed: the
    squares' centres and half sides, to say whether a later prediction's is inside."""

    xyz: Points
    index: PlanIndex
    centres: Points
    half_m: NDArray[np.float64]

    @classmethod
    def read(
        cls,
        cloud: Cloud,
        places: Sequence[Points],
        config: GeorefConfig,
        progress: Progress | None,
    ) -> _Near:
        """One more pass, about ``places`` (each beacon's four predicted edges, plan)."""
        centres = np.array([p.mean(axis=0) for p in places]).reshape(-1, 2)
        half = np.array([reach_m(p) for p in places]) + NEIGHBOURHOOD_SLACK_M
        xyz = points_near(cloud, centres, half, config.detect, progress)
        return cls(xyz, PlanIndex(xyz[:, :2]), centres, half)

    def square(self, centre: Points, half_m: float) -> Points | None:
        """Every point in the square about ``centre``, or None when no square read holds
        it (the prediction moved since: the candidates alone serve)."""
        inside = np.all(np.abs(self.centres - centre) + half_m <= self.half_m[:, None], axis=1)
        if not np.any(inside):
            return None
        out: Points = self.xyz[self.index.square(centre, half_m)]
        return out


def _looked_for(
    missing: Sequence[Beacon],
    to_cloud: Callable[[Points], Points],
    index: PlanIndex,
    min_points: int,
) -> list[tuple[Beacon, Points, NDArray[np.intp]]]:
    """The beacons detection missed, each with its edges where ``to_cloud`` (grid E, N,
    Z rows to the cloud's plan) puts them and the candidates about them, where those
    are ``min_points`` or more: elsewhere nothing panel-like is there (beyond the cloud's
    ends, or not seen), and nothing is looked for or read."""
    out = []
    for b in missing:
        predicted = _predicted(b, to_cloud)
        rows = index.square(predicted.mean(axis=0), reach_m(predicted))
        if len(rows) >= min_points:
            out.append((b, predicted, rows))
    return out


def _sought(
    looked: Sequence[tuple[Beacon, Points, NDArray[np.intp]]],
    prediction_sigma_m: float,
    cand: Candidates,
    near: _Near,
    noise_m: float,
    config: GeorefConfig,
    heights: bool,
) -> dict[str, BeaconObs]:
    """The surveyed beacons detection missed (:func:`_looked_for`), looked for where they
    were predicted, that prediction ``prediction_sigma_m`` off beyond the survey's own
    sigma, among the candidates, their edges fitted to all the cloud's points about them
    (:mod:`mast.cloud.sought`)."""
    out = {}
    for b, predicted, rows in looked:
        found = seek_beacon(
            cand.xyz[rows],
            None if cand.time is None else cand.time[rows],
            b.edges,
            predicted,
            noise_m,
            math.hypot(float(np.max(b.sigmas_or(config.survey_sigma_m))), prediction_sigma_m),
            config.detect,
            near.square(predicted.mean(axis=0), reach_m(predicted) + MAX_SNAP_M),
        )
        if found is None:
            continue
        fit = found.fit
        out[b.id] = _beacon_obs(
            b,
            INNER_EDGES,
            fit.edges[[e - 1 for e in INNER_EDGES]],
            fit.edge_covariance(INNER_EDGES),
            (found.top, found.sigma_top),
            found.time,
            found.points,
            heights,
            config.survey_sigma_m,
        )
    return out


def georeference(
    cloud: Cloud,
    survey: Survey,
    config: GeorefConfig = GeorefConfig(),
    *,
    trajectory: ScannerPath | None = None,
    progress: Progress | None = None,
) -> Georef:
    """Find the beacons in ``cloud`` and adjust the transformation to the grid.

    A refusal (too few beacons, an ambiguous match, inconsistent beacons) is
    not an exception: :attr:`Georef.refusal` says why and the rest of the
    result says what was found, for the report.
    """
    if config.model not in MODELS:
        raise InputError(f"unknown model {config.model!r}; known: {', '.join(MODELS)}")
    unknown = [c for c in config.checks if c not in survey]
    if unknown:
        raise InputError(f"--check names beacon(s) not in the survey: {', '.join(unknown)}")
    # a beacon's panels are level: one surveyed edge top is enough for its height
    heights = all(
        b.elevations is not None and bool(np.any(np.isfinite(b.elevations))) for b in survey
    )
    cand = find_candidates(cloud, config.detect, progress)
    pieces = plan_pieces(cand, config.detect)
    index = SurveyIndex.from_survey(survey, reach_m=5.0)
    ident = identify_panels(
        pieces.segmentation, index.representatives, survey_sigma_m=config.survey_sigma_m
    )
    dets = detect_beacons(pieces, ident, index)
    match = match_beacons(dets, survey, index, config.match)
    plan = PlanIndex(cand.xyz[:, :2])
    observed = {
        b: _observation(
            dets[d],
            b,
            pieces,
            survey,
            heights,
            config.survey_sigma_m,
            cand.xyz,
            plan,
            config.detect,
        )
        for d, b in match.assigned.items()
    }
    found = {b: o for b, o in observed.items() if o is not None}
    short = {b for b, o in observed.items() if o is None}
    controls = [o for b, o in found.items() if b not in config.checks]
    checks_obs = [o for b, o in found.items() if b in config.checks]
    refusal: AdjustmentError | None = None
    solution: Solution | None = None
    checks: list[CheckResult] = []
    if match.reason == "ambiguous":
        refusal = AdjustmentError(
            "ambiguous",
            f"the detections fit the survey in more than one way ({match.score} beacons "
            f"either way); the survey repeats itself within the matching tolerance",
        )
    else:
        try:
            solution = adjust_transformation(
                controls,
                model=config.model,
                survey_sigma_m=config.survey_sigma_m,
                heights=heights,
            )
        except AdjustmentError as err:
            refusal = err
            if trajectory is not None and err.reason == "inconsistent":
                # a drifting cloud fits no one transformation: the rigid least-squares
                # solution is only where the pose graph starts ("before" in the report)
                solution = rigid_solution(controls, config.model, config.survey_sigma_m, heights)
                refusal = None
    sought: set[str] = set()
    noise = pieces.segmentation.noise_m
    near: _Near | None = None

    def seek(to_cloud: Callable[[Points], Points], off_m: float) -> dict[str, BeaconObs]:
        nonlocal near
        missing = [b for b in survey if b.id not in found]
        looked = _looked_for(missing, to_cloud, plan, config.detect.min_points)
        if not looked:
            return {}
        if near is None:  # one more pass, about the beacons looked for at the first search
            near = _Near.read(cloud, [p for _, p, _ in looked], config, progress)
        return _sought(looked, off_m, cand, near, noise, config, heights)

    def take(extra: dict[str, BeaconObs]) -> None:
        controls.extend(o for b, o in extra.items() if b not in config.checks)
        checks_obs.extend(o for b, o in extra.items() if b in config.checks)
        found.update(extra)
        short.difference_update(extra)
        sought.update(extra)

    if solution is not None and refusal is None and trajectory is None:
        extra = seek(_rigid_to_cloud(solution), 0.0)
        more = [o for b, o in extra.items() if b not in config.checks]
        try:
            if more:
                solution = adjust_transformation(
                    controls + more,
                    model=config.model,
                    survey_sigma_m=config.survey_sigma_m,
                    heights=heights,
                )
        except AdjustmentError:
            pass  # they do not fit with the rest: the transformation stays the first
        else:
            take(extra)
    drift = None
    if solution is not None:
        if trajectory is not None:
            if cand.time is None:
                raise InputError(
                    "the points have no time (gps_time, or name one with --time-field): "
                    "the drift correction needs it",
                    path=cloud.path,
                )
            try:
                # every control: in a drifting cloud the rigid fit's outlier test means
                # little; the pose graph's own tests decide
                drift = correct_drift(
                    trajectory,
                    controls,
                    solution.transformation,
                    drift=config.drift,
                    survey_sigma_m=config.survey_sigma_m,
                    heights=heights,
                    checks=checks_obs,
                )
            except AdjustmentError as err:
                refusal = err
            for _ in range(SOUGHT_ROUNDS):
                if drift is None:
                    break
                extra = {
                    b: o
                    for b, o in seek(
                        partial(_drift_to_cloud, drift, trajectory), DRIFT_PREDICTION_M
                    ).items()
                    # seen while the trajectory ran (a partial one: not beyond its ends)
                    if o.time is not None
                    and trajectory.time[0] - 1.0 <= o.time <= trajectory.time[-1] + 1.0
                }
                if not extra:
                    break
                try:
                    drift = correct_drift(
                        trajectory,
                        controls + [o for b, o in extra.items() if b not in config.checks],
                        solution.transformation,
                        drift=config.drift,
                        survey_sigma_m=config.survey_sigma_m,
                        heights=heights,
                        checks=checks_obs + [o for b, o in extra.items() if b in config.checks],
                    )
                except AdjustmentError:
                    break  # they do not fit with the rest: the correction stays the last
                take(extra)
        checks = check_beacons(solution, checks_obs, survey_sigma_m=config.survey_sigma_m)
    excluded = (
        dict.fromkeys(drift.excluded, "outlier: fails its test against the drift-corrected rest")
        if drift is not None
        else dict.fromkeys(
            solution.excluded if solution is not None else [],
            "outlier: its removal alone makes the rest fit",
        )
    )
    beacons = _fates(survey, found, config, excluded, short, sought)
    if refusal is not None and refusal.reason == "too_few":
        refusal = _too_sparse(refusal, cand.wall_density_m2)
    return Georef(
        cloud,
        survey,
        config,
        cand,
        pieces,
        dets,
        match,
        beacons,
        solution,
        checks,
        heights,
        refusal,
        drift,
    )


def _too_sparse(refusal: AdjustmentError, density_m2: float) -> AdjustmentError:
    """Too few beacons in a cloud too sparse for them: say so, with the density measured
    and the density beacons need (:data:`~mast.cloud.detect.BEACON_DENSITY_M2`)."""
    if not density_m2 < BEACON_DENSITY_M2:  # dense enough (or NaN: cannot say)
        return refusal
    return AdjustmentError(
        refusal.reason,
        f"too sparse for beacons: {density_m2:.0f} points per m² on the walls, beacons "
        f"need about {BEACON_DENSITY_M2:.0f} ({refusal.detail})",
        refusal.suspects,
    )


def _fates(
    survey: Survey,
    found: dict[str, BeaconObs],
    config: GeorefConfig,
    excluded: dict[str, str],
    short: set[str],
    sought: set[str],
) -> list[FoundBeacon]:
    out = []
    for b in survey:
        obs = found.get(b.id)
        if b.id in short:
            out.append(
                FoundBeacon(
                    b.id,
                    "not_found",
                    None,
                    "found, but its outer panels too short in the cloud to place an edge",
                )
            )
        elif obs is None:
            out.append(FoundBeacon(b.id, "not_found", None, NOT_FOUND))
        elif b.id in config.checks:
            out.append(FoundBeacon(b.id, "check", obs, SOUGHT if b.id in sought else ""))
        elif b.id in excluded:
            out.append(FoundBeacon(b.id, "excluded", obs, excluded[b.id]))
        else:
            out.append(FoundBeacon(b.id, "control", obs, SOUGHT if b.id in sought else ""))
    return out


def explain_missing(result: Georef) -> list[FoundBeacon]:
    """Why each beacon not found was not: outside the cloud, or in it but not seen."""
    sol = result.solution
    if sol is None:
        return result.beacons
    inv = np.linalg.inv(sol.transformation.matrix())
    floor = result.candidates.floor
    out = []
    for fb in result.beacons:
        if fb.role != "not_found" or fb.why != NOT_FOUND:
            out.append(fb)
            continue
        b = result.survey[fb.beacon]
        xy = np.column_stack([b.edges, np.zeros(4), np.ones(4)]) @ inv.T
        _, inside = floor.at(np.asarray(xy[:, :2], dtype=float))
        why = (
            "in the cloud, but no beacon found there (occluded, too few points, or not identified)"
            if bool(np.any(inside))
            else "outside the cloud"
        )
        out.append(FoundBeacon(fb.beacon, fb.role, None, why))
    return out


def grid_origin(result: Georef) -> NDArray[np.float64]:
    """A grid point near the cloud (for the LAS offsets)."""
    if result.solution is None:
        return np.zeros(3)
    return np.asarray(result.solution.transformation.translation, dtype=float)


def _block_diagonal(blocks: Sequence[NDArray[np.float64]]) -> NDArray[np.float64]:
    """Independent 2x2 covariances as one (2k, 2k) matrix."""
    out = np.zeros((2 * len(blocks), 2 * len(blocks)))
    for i, c in enumerate(blocks):
        out[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = c
    return out
