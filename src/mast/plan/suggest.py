"""Where one more beacon helps most: a greedy layout on the drift's walls.

Each round screens every candidate position on the walls (every
``candidate_step_m``, each shape the survey already uses) by geometry alone:
from each centreline cell within the scanner's reach that is not yet covered,
would the candidate make a fix owed (a second beacon with two panels in view)
and, with a target, bring the Cramér–Rao bound within it? The Fisher
information of the candidate's beams is added to the cell's. Candidates are
tried best first; one is accepted only when the full prediction — the locator
on noisy scans, with the candidate ray-cast among the walls and the other
beacons — covers more of the centreline with it than without. A round that
accepts none ends the search.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon, Survey
from mast.core.noise import NoiseModel
from mast.core.pose import Pose2D, wrap_angle
from mast.core.walls import Drift
from mast.pipeline.adjustment import MIN_INCIDENCE_COS
from mast.pipeline.bounds import information
from mast.plan.drift import wall_distance
from mast.plan.predict import (
    MIN_INCIDENCE_DEG,
    MIN_PANEL_RETURNS,
    Plan,
    cell_pose,
    covariance,
    plan_world,
    position_major_sigma,
    predict,
)
from mast.sim.design import BeaconDesign
from mast.sim.tunnel import polyline_station
from mast.sim.world import Surface, World

__all__ = ["Candidate", "Suggestion", "designs_of", "suggest"]

#: Tries of the best-screened candidates per round before the search gives up.
TRIES_PER_ROUND = 3
#: Candidates paired with every other one per round (those that would be the first
#: beacon with two panels in view for the most uncovered cells).
PAIR_SEEDS = 6
#: Clear wall between a new beacon and any other, beyond their half chords, metres.
MIN_BEACON_GAP_M = 1.0
#: Shapes whose edges agree within this are one design (survey rounding, mirroring).
DESIGN_TOLERANCE_M = 0.01
#: How far a mounted beacon's free ends may lie off the drawn wall, metres.
MOUNT_TOLERANCE_M = 0.02


@dataclass(frozen=True, slots=True)
class Candidate:
    """A beacon that could be mounted: its edges and where on which wall."""

    design: BeaconDesign
    wall: int
    station_m: float
    edges: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Suggestion:
    """The greedy search's result.

    Attributes
    ----------
    before, after : Plan
        The prediction for the surveyed layout and for it with the new beacons.
    added : tuple of Beacon
        The new beacons, in the order they were chosen.
    shares : tuple of float
        The covered share of the centreline after each one.
    """

    before: Plan
    after: Plan
    added: tuple[Beacon, ...]
    shares: tuple[float, ...]


def designs_of(survey: Survey) -> list[BeaconDesign]:
    """The distinct shapes of a survey's beacons, in the design frame (wall along +x)."""
    out: list[BeaconDesign] = []
    for b in survey:
        e = np.asarray(b.edges, dtype=float)
        t = e[3] - e[0]
        t /= math.hypot(*t)
        n = np.array([-t[1], t[0]])
        local = np.stack([(e - e[0]) @ t, (e - e[0]) @ n], axis=1)
        if local[1:3, 1].mean() < 0:  # stand out towards +y, as designs do
            local[:, 1] = -local[:, 1]
        if all(np.abs(d.edges_local - local).max() > DESIGN_TOLERANCE_M for d in out):
            out.append(BeaconDesign(f"as {b.id}", local))
    return out


def _candidates(plan: Plan, designs: list[BeaconDesign], step_m: float) -> list[Candidate]:
    drift, grid = plan.drift, plan.grid
    existing = [(b.centroid, math.dist(b.edges[0], b.edges[3])) for b in plan.survey]
    out = []
    for k, wall in enumerate(drift.walls):
        pts = wall.points
        length = float(np.sum(np.hypot(*np.diff(pts, axis=0).T)))
        for design in designs:
            half = design.chord_m / 2
            for s in np.arange(half + 0.1, length - half - 0.1, step_m):
                point, tangent = polyline_station(pts, float(s))
                near = grid.centreline[np.argmin(np.hypot(*(grid.centreline - point).T))]
                side = (
                    1 if tangent[0] * (near - point)[1] - tangent[1] * (near - point)[0] > 0 else -1
                )
                edges = design.mounted(point, tangent, tunnel_side=side)
                if _fits(drift, edges) and all(
                    math.dist(np.mean(edges[[0, 3]], axis=0), c) >= half + h / 2 + MIN_BEACON_GAP_M
                    for c, h in existing
                ):
                    out.append(Candidate(design, k, float(s), edges))
    return out


def _fits(drift: Drift, edges: NDArray[np.float64]) -> bool:
    """The free ends on the wall, the panels clear of every wall in between."""
    ends = wall_distance(drift, edges[[0, 3]])
    if float(ends.max()) > MOUNT_TOLERANCE_M:
        return False
    u = np.linspace(0.05, 0.95, 7)[:, None]
    inner = np.vstack([edges[i] + u * (edges[i + 1] - edges[i]) for i in range(3)])
    return bool(wall_distance(drift, inner).min() > 0.005)


def _with_beacon(world: World, edges: NDArray[np.float64], beacon_id: str) -> World:
    surfaces = (*world.surfaces, *(Surface("beacon", beacon_id, p) for p in (1, 2, 3)))
    first = len(world.surfaces)
    return World(
        np.vstack([world.seg_a, edges[:3]]),
        np.vstack([world.seg_b, edges[1:]]),
        np.concatenate([world.seg_surface, np.arange(first, first + 3)]),
        world.circ_c,
        world.circ_r,
        world.circ_surface,
        surfaces,
    )


def _surface_of(world: World, edges: NDArray[np.float64]) -> int:
    """Index of the first of the three surfaces :func:`_with_beacon` gave these edges."""
    k = int(np.flatnonzero(np.all(world.seg_a == edges[0], axis=1))[-1])
    return int(world.seg_surface[k])


def _candidate_view(
    world: World, edges: NDArray[np.float64], pose: Pose2D, plan: Plan, noise: NoiseModel
) -> tuple[bool, NDArray[np.float64]]:
    """Whether the candidate shows two panels from ``pose``, and its beams' information.

    Only the beams towards the candidate are cast (in ``world``, which holds it).
    """
    scanner = plan.scanner
    rel = edges - pose.position
    if float(np.min(np.hypot(*rel.T))) > scanner.range_max_m:
        return False, np.zeros((3, 3))
    bearing = np.arctan2(rel[:, 0], rel[:, 1])
    phi_edges = np.array([wrap_angle(pose.azimuth - b) for b in bearing])
    lo, hi = float(phi_edges.min()), float(phi_edges.max())
    if hi - lo > math.pi:  # the beacon straddles the scanner's back: no 270-degree view of it
        return False, np.zeros((3, 3))
    phi = scanner.beam_angles()
    sel = phi[(phi >= lo - 1e-9) & (phi <= hi + 1e-9)]
    if sel.size < MIN_PANEL_RETURNS:
        return False, np.zeros((3, 3))
    dirs = pose.beam_directions(sel)
    t, which = world.raycast(pose.position, dirs)
    # the candidate's panels: the surfaces whose segments are its edges
    first = _surface_of(world, edges)
    ok = (which >= first) & (which < first + 3)
    ok &= (t >= scanner.range_min_m) & (t <= scanner.range_max_m)
    panel = which - first
    seen = 0
    cos_min = math.cos(math.radians(90.0 - MIN_INCIDENCE_DEG))
    normals = np.empty((3, 2))
    for p in range(3):
        d = edges[p + 1] - edges[p]
        d /= math.hypot(*d)
        normals[p] = (-d[1], d[0])
        hits = ok & (panel == p)
        if np.count_nonzero(hits) >= MIN_PANEL_RETURNS:
            mean_dir = dirs[hits].mean(axis=0)
            mean_dir /= math.hypot(*mean_dir)
            if abs(float(normals[p] @ mean_dir)) >= cos_min:
                seen += 1
    panel = np.where(ok, panel, 0)
    facing = np.abs(np.einsum("ij,ij->i", normals[panel], dirs)) > MIN_INCIDENCE_COS
    use = ok & facing
    if not np.any(use):
        return seen >= 2, np.zeros((3, 3))
    nrm = normals[panel[use]]
    off = np.einsum("ij,ij->i", nrm, edges[panel[use]])
    return seen >= 2, information(pose, sel[use], nrm, off, noise=noise)


_Effect = dict[tuple[int, int], tuple[int, NDArray[np.float64]]]


def _effect(plan: Plan, world: World, cand: Candidate, covered: NDArray[np.bool_]) -> _Effect:
    """What the candidate adds at each centreline cell and heading within reach that
    ``covered`` (the plan's) leaves out: two panels in view (1 or 0) and the information
    of its beams."""
    grid = plan.grid
    c = grid.centre
    reach = plan.scanner.range_max_m + 1.0
    rows = np.flatnonzero(np.hypot(*(grid.xy[:, c] - cand.edges.mean(axis=0)).T) <= reach)
    noise = plan.scanner.noise()
    w = _with_beacon(world, cand.edges, "?")
    out: _Effect = {}
    for r in rows:
        for h in (0, 1):
            if not covered[r, c, h]:
                two, info = _candidate_view(
                    w, cand.edges, cell_pose(grid, int(r), c, h), plan, noise
                )
                if two or np.any(info):
                    out[int(r), h] = (int(two), info)
    return out


def _score(plan: Plan, effects: list[_Effect], target: float | None) -> tuple[int, int]:
    """Centreline cells and headings newly covered with the candidates (by geometry), and
    those where they would give the first beacon with two panels in view (half a fix).

    Each candidate's effect was found without the others: one hiding another is
    left to the full prediction that checks every placement.
    """
    gain = half = 0
    for r, h in set().union(*effects):
        view = plan.views[r, plan.grid.centre, h]
        two, info = view.two_panel_beacons, view.information
        for e in effects:
            if (r, h) in e:
                two, info = two + e[r, h][0], info + e[r, h][1]
        if two == 1:
            half += 1
        if two < 2:
            continue
        if target is not None and position_major_sigma(covariance(info)) > target:
            continue
        gain += 1
    return gain, half


def centreline_share(plan: Plan) -> float:
    """Share of the centreline (both headings) covered."""
    return float(np.mean(plan.covered[:, plan.grid.centre, :]))


def _new_id(survey: Survey, k: int) -> str:
    while f"N{k}" in survey:
        k += 1
    return f"N{k}"


def _try(current: Plan, cands: list[Candidate], added: list[Beacon]) -> Plan | None:
    """The full prediction with the candidates mounted, if it covers more of the centreline."""
    survey = current.survey
    new: list[Beacon] = []
    for cand in cands:
        beacon = Beacon(_new_id(survey, len(added) + len(new) + 1), cand.edges)
        survey = Survey([*survey, beacon], source=current.survey.source)
        new.append(beacon)
    reach = current.scanner.range_max_m + 1.0
    xy = current.grid.xy
    near = np.zeros(xy.shape[:2], dtype=bool)
    for cand in cands:
        centroid = cand.edges.mean(axis=0)
        near |= np.hypot(xy[..., 0] - centroid[0], xy[..., 1] - centroid[1]) <= reach
    trial = predict(
        current.drift, survey, current.scanner, current.settings, base=current, only=near
    )
    trial = replace(trial, proposed=(*current.proposed, *(b.id for b in new)), _cache={})
    if centreline_share(trial) <= centreline_share(current):
        return None
    added.extend(new)
    return trial


def suggest(
    plan: Plan,
    count: int,
    *,
    candidate_step_m: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> Suggestion:
    """Add up to ``count`` beacons to the plan's layout, greedily (see the module).

    A stretch without any beacon gains nothing from one new beacon (a fix needs
    two), so each round also screens pairs: the candidates that would be the
    first two-panel beacon for the most uncovered cells, each with every other
    candidate. A pair is tried first when it gains more per beacon than the
    best single one.
    """
    designs = designs_of(plan.survey)
    step = candidate_step_m or plan.settings.step_m
    target = plan.settings.target_sigma_m
    current = plan
    added: list[Beacon] = []
    shares: list[float] = []
    while len(added) < count:
        world = plan_world(
            current.drift,
            current.survey,
            roughness_m=current.settings.roughness_m,
            seed=current.settings.seed,
        )
        cands = _candidates(current, designs, step)
        covered = current.covered
        effects = [_effect(current, world, cand, covered) for cand in cands]
        singles = [(*_score(current, [e], target), i) for i, e in enumerate(effects)]
        options: list[tuple[float, list[Candidate]]] = [
            (g, [cands[i]]) for g, _, i in singles if g > 0
        ]
        if count - len(added) >= 2:
            seeds = sorted((s for s in singles if s[1] > 0), key=lambda s: (-s[1], s[2]))
            for _, _, i in seeds[:PAIR_SEEDS]:
                a = cands[i]
                for j, b in enumerate(cands):
                    if j == i or _overlap(a, b):
                        continue
                    g, _ = _score(current, [effects[i], effects[j]], target)
                    if g > 0:
                        options.append((g / 2, [a, b]))
        options.sort(key=lambda o: -o[0])
        if progress is not None:
            progress(f"{len(options)} placement(s) of one or two beacons would add coverage")
        for _, chosen in options[:TRIES_PER_ROUND]:
            trial = _try(current, chosen, added)
            if trial is not None:
                current = trial
                shares.extend([centreline_share(trial)] * len(chosen))
                break
        else:
            break
    return Suggestion(plan, current, tuple(added), tuple(shares))


def _overlap(a: Candidate, b: Candidate) -> bool:
    gap = math.dist(a.edges.mean(axis=0), b.edges.mean(axis=0))
    return gap < (a.design.chord_m + b.design.chord_m) / 2 + MIN_BEACON_GAP_M
