"""Mine-wide survey benchmark: does locating against a whole mine's survey change a fix?

A survey file in use holds every beacon of the mine, hundreds of them built to
a few designs, while a scan sees two or three. This benchmark takes owed scans
of the accuracy benchmark's scenes (one noise draw each) and locates each
twice: against the scene's own beacons, and against those plus ``copies``
copies of the same designs surveyed in other drifts, out of the scanner's
reach. The copies can never be seen, so every fix, no-fix reason and pose
must come out the same; what may change is the time a fix takes, since each
identified corner now matches many surveyed beacons.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from mast.bench.accuracy import ACCURACY_CONFIGS, owed_poses
from mast.core.beacon import Beacon, Survey
from mast.core.heap import QuietCollector
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.sim import ScannerModel, simulate_scan
from mast.sim.design import random_design

__all__ = ["MinewideScan", "MinewideSummary", "minewide_survey", "run_minewide"]

#: Out-of-sight drifts: copies stand this far apart along a drift ...
COPY_SPACING_M = 10.0
#: ... the drifts this far apart ...
DRIFT_SPACING_M = 20.0
#: ... with this many copies in each.
COPIES_PER_DRIFT = 16
#: Beyond the scanner's maximum range, the least distance of a copy from any pose.
CLEARANCE_MARGIN_M = 10.0
#: A fix differs when its position moves more than this, metres ...
SAME_POSITION_M = 1e-3
#: ... or its azimuth more than this, arc-seconds.
SAME_AZIMUTH_ARCSEC = 1.0


@dataclass(frozen=True, slots=True)
class MinewideScan:
    """One scan located against the local and the mine-wide survey.

    ``*_status`` is ``"fix"`` or the no-fix reason; the differences are
    ``nan`` unless both runs fixed; times are wall-clock seconds of ``locate``.
    """

    scene: str
    pose_index: int
    local_status: str
    minewide_status: str
    position_diff_m: float
    azimuth_diff_arcsec: float
    local_s: float
    minewide_s: float
    minewide_beacons: tuple[str, ...]

    @property
    def differs(self) -> bool:
        """Whether the status or (beyond the tolerances) the pose differs."""
        return self.local_status != self.minewide_status or bool(
            self.position_diff_m > SAME_POSITION_M or self.azimuth_diff_arcsec > SAME_AZIMUTH_ARCSEC
        )


@dataclass(frozen=True, slots=True)
class MinewideSummary:
    """What the mine-wide survey changed, and what it cost.

    Attributes
    ----------
    config : str
        Scanner model.
    poses, copies : int
        Scans located, and copies added to each scene's survey.
    copies_first : bool
        Whether the copies come before the scene's beacons in the survey.
    distinct : bool
        Whether each added beacon is of a design of its own (not a copy).
    survey_beacons : tuple of int
        Fewest and most beacons in a mine-wide survey.
    min_copy_distance_m : float
        Least distance from any copy's edge to any pose of its scene.
    local_fixes, minewide_fixes : int
    status_differ : int
        Scans whose status (fix or no-fix reason) differs.
    pose_differ : int
        Scans fixed by both whose poses differ by more than 1 mm or 1 arc-second.
    copy_fixes : int
        Mine-wide fixes that used a copy (which cannot have been seen).
    max_position_diff_m, max_azimuth_diff_arcsec : float
        Largest difference between two fixes of one scan.
    local_median_s, local_max_s, minewide_median_s, minewide_max_s : float
        Per-scan time of ``locate``, survey index already built.
    median_ratio : float
        ``minewide_median_s / local_median_s``.
    index_build_s : float
        Median time to build a mine-wide survey's index (once per survey).
    seconds : float
    scans : tuple of MinewideScan
    """

    config: str
    poses: int
    copies: int
    copies_first: bool
    distinct: bool
    survey_beacons: tuple[int, int]
    min_copy_distance_m: float
    local_fixes: int
    minewide_fixes: int
    status_differ: int
    pose_differ: int
    copy_fixes: int
    max_position_diff_m: float
    max_azimuth_diff_arcsec: float
    local_median_s: float
    local_max_s: float
    minewide_median_s: float
    minewide_max_s: float
    median_ratio: float
    index_build_s: float
    seconds: float
    scans: tuple[MinewideScan, ...]


def copy_id(k: int) -> str:
    """Survey id of the ``k``-th copy (from 0): ``X0001``, ``X0002``, ..."""
    return f"X{k + 1:04d}"


def minewide_survey(
    survey: Survey,
    poses: Sequence[Pose2D],
    *,
    copies: int,
    clearance_m: float,
    rng: np.random.Generator,
    copies_first: bool = False,
    distinct: bool = False,
) -> Survey:
    """``survey`` plus ``copies`` copies of its beacons, out of sight of ``poses``.

    Copy ``k`` is of the survey's beacon ``k mod n``, rotated by a random angle
    about its centroid and moved to a grid of drifts (``COPIES_PER_DRIFT``
    copies ``COPY_SPACING_M`` apart, drifts ``DRIFT_SPACING_M`` apart) that
    starts east of the easternmost pose by ``clearance_m`` plus the copy's
    size, so that no edge of a copy comes within ``clearance_m`` of a pose.
    Copies are named by :func:`copy_id`, and listed after the survey's own
    beacons (before them with ``copies_first``: then a copy, not the beacon
    really seen, is the first of its design in the survey). With ``distinct``,
    each added beacon is instead of a random design of its own (a mine of
    many designs: identification has that many to tell apart).
    """
    originals = list(survey)
    xy = np.array([p.position for p in poses]).reshape(-1, 2)
    reach = max(float(np.max(np.hypot(*(b.edges - b.centroid).T))) for b in originals)
    east0 = float(xy[:, 0].max()) + clearance_m + reach
    north0 = float(xy[:, 1].mean())
    added: list[Beacon] = []
    for k in range(copies):
        src = originals[k % len(originals)]
        shape = random_design(rng).edges_local if distinct else src.edges - src.centroid
        turn = float(rng.uniform(0, 2 * math.pi))
        c, s = math.cos(turn), math.sin(turn)
        rot = np.array([[c, -s], [s, c]])
        drift, station = divmod(k, COPIES_PER_DRIFT)
        target = np.array([east0 + station * COPY_SPACING_M, north0 + drift * DRIFT_SPACING_M])
        added.append(Beacon(copy_id(k), (shape - shape.mean(axis=0)) @ rot.T + target))
    ordered = [*added, *originals] if copies_first else [*originals, *added]
    return Survey(ordered, source=survey.source)


def _blank_scan(model: ScannerModel) -> Scan:
    """A scan without returns: locating it only builds the survey's index."""
    return Scan.from_laserscan(
        angle_min=model.angle_min_rad,
        angle_increment=math.radians(model.resolution_deg),
        ranges=np.full(model.beam_count, np.nan),
        range_min=model.range_min_m,
        range_max=model.range_max_m,
    )


def _status(fix: Fix) -> str:
    return "fix" if fix.ok else str(fix.reason)


def run_minewide(
    *,
    poses: int = 40,
    copies: int = 184,
    seed: int = 0,
    model: ScannerModel = ACCURACY_CONFIGS[0],
    copies_first: bool = False,
    distinct: bool = False,
    echo: Callable[[str], object] = print,
) -> MinewideSummary:
    """Locate owed scans against their scene's survey and a mine-wide one; compare.

    Parameters
    ----------
    poses : int
        Owed poses (as in the accuracy benchmark), one noise draw each (the
        accuracy benchmark's first draw of that pose).
    copies : int
        Copies of the scene's beacon designs added, out of sight, to its survey.
    seed : int
        Seed of the poses, the noise and the copies' rotations.
    model : ScannerModel
        Scanner (default: 270 degrees, 0.5 degree beams, 12 mm noise).
    copies_first : bool
        List the copies before the scene's beacons in the mine-wide survey.
    distinct : bool
        Each added beacon of a random design of its own instead of a copy.
    echo : callable
        Receives the one-line summary.
    """
    from mast.cli.warmup import compile_all

    t_start = time.perf_counter()
    compile_all()  # every kernel loaded, as mast live does: the first scan is no slower
    cfg = LocatorConfig(range_sigma_m=model.range_sigma_m, survey_sigma_m=0.0)
    blank = _blank_scan(model)
    clearance = model.range_max_m + CLEARANCE_MARGIN_M
    wide: dict[str, Survey] = {}
    builds: list[float] = []
    scans: list[MinewideScan] = []
    min_dist = math.inf
    # As the commands do (mast.core.heap): what is alive after each pose, the surveys'
    # indexes above all, frozen out of the collector's full passes.
    with QuietCollector(every=1) as heap:
        for p_idx, (scene, shot) in enumerate(heap.each(owed_poses(model, poses, seed))):
            if scene.name not in wide:
                shots = [s.pose for s in scene.shots]
                big = minewide_survey(
                    scene.survey,
                    shots,
                    copies=copies,
                    clearance_m=clearance,
                    rng=np.random.default_rng([seed, len(wide), 11]),
                    copies_first=copies_first,
                    distinct=distinct,
                )
                wide[scene.name] = big
                xy = np.array([p.position for p in shots])
                for b in big:
                    if b.id not in scene.survey:
                        d = np.hypot(*(b.edges[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
                        min_dist = min(min_dist, float(d.min()))
                # Build both surveys' indexes before timing (the locator keeps them);
                # the local one again last, in case taking in the large one dropped it.
                for s in (scene.survey, big, scene.survey):
                    t0 = time.perf_counter()
                    locate(blank, s, config=cfg)
                    if s is big:
                        builds.append(time.perf_counter() - t0)
                heap.step()  # the new indexes frozen before any scan is timed against them
            big = wide[scene.name]
            rng = np.random.default_rng([seed, p_idx, 7])  # the accuracy benchmark's first draw
            sim = simulate_scan(scene.world, shot.pose, model, rng=rng)
            t0 = time.perf_counter()
            local = locate(sim.scan, scene.survey, config=cfg)
            t1 = time.perf_counter()
            mine = locate(sim.scan, big, config=cfg)
            t2 = time.perf_counter()
            dpos = daz = math.nan
            if local.ok and mine.ok and local.pose is not None and mine.pose is not None:
                dpos = float(np.hypot(*(mine.pose.position - local.pose.position)))
                turn = math.remainder(mine.pose.azimuth - local.pose.azimuth, math.tau)
                daz = abs(math.degrees(turn)) * 3600
            scans.append(
                MinewideScan(
                    scene=scene.name,
                    pose_index=p_idx,
                    local_status=_status(local),
                    minewide_status=_status(mine),
                    position_diff_m=dpos,
                    azimuth_diff_arcsec=daz,
                    local_s=t1 - t0,
                    minewide_s=t2 - t1,
                    minewide_beacons=mine.beacons,
                )
            )
    summary = _summarise(
        model.name, copies, copies_first, distinct, scans, wide, min_dist, builds, t_start
    )
    echo(_line(summary))
    return summary


def _summarise(
    config: str,
    copies: int,
    copies_first: bool,
    distinct: bool,
    scans: list[MinewideScan],
    wide: dict[str, Survey],
    min_dist: float,
    builds: list[float],
    t_start: float,
) -> MinewideSummary:
    def worst(values: list[float]) -> float:
        finite = [v for v in values if not math.isnan(v)]
        return max(finite) if finite else math.nan

    local_t = [s.local_s for s in scans]
    wide_t = [s.minewide_s for s in scans]
    sizes = [len(s) for s in wide.values()] or [0]
    local_med = statistics.median(local_t) if scans else math.nan
    wide_med = statistics.median(wide_t) if scans else math.nan
    return MinewideSummary(
        config=config,
        poses=len(scans),
        copies=copies,
        copies_first=copies_first,
        distinct=distinct,
        survey_beacons=(min(sizes), max(sizes)),
        min_copy_distance_m=min_dist,
        local_fixes=sum(s.local_status == "fix" for s in scans),
        minewide_fixes=sum(s.minewide_status == "fix" for s in scans),
        status_differ=sum(s.local_status != s.minewide_status for s in scans),
        pose_differ=sum(s.local_status == s.minewide_status and s.differs for s in scans),
        copy_fixes=sum(
            s.minewide_status == "fix" and any(b.startswith("X") for b in s.minewide_beacons)
            for s in scans
        ),
        max_position_diff_m=worst([s.position_diff_m for s in scans]),
        max_azimuth_diff_arcsec=worst([s.azimuth_diff_arcsec for s in scans]),
        local_median_s=local_med,
        local_max_s=max(local_t, default=math.nan),
        minewide_median_s=wide_med,
        minewide_max_s=max(wide_t, default=math.nan),
        median_ratio=wide_med / local_med if scans else math.nan,
        index_build_s=statistics.median(builds) if builds else math.nan,
        seconds=time.perf_counter() - t_start,
        scans=tuple(scans),
    )


def _line(s: MinewideSummary) -> str:
    lo, hi = s.survey_beacons
    order = "first" if s.copies_first else "last"
    kind = "beacons of their own designs" if s.distinct else "copies"
    return (
        f"{s.config}: {s.poses} scans, local vs mine-wide ({lo}-{hi} beacons, {kind} {order}, "
        f">= {s.min_copy_distance_m:.0f} m away): fixes {s.local_fixes} vs {s.minewide_fixes}, "
        f"status differs {s.status_differ}, pose differs {s.pose_differ} "
        f'(max {1e3 * s.max_position_diff_m:.3g} mm, {s.max_azimuth_diff_arcsec:.3g}"), '
        f"fixes on a copy {s.copy_fixes}; per scan median {1e3 * s.local_median_s:.1f} vs "
        f"{1e3 * s.minewide_median_s:.1f} ms (x{s.median_ratio:.2f}), max "
        f"{1e3 * s.local_max_s:.1f} vs {1e3 * s.minewide_max_s:.1f} ms; "
        f"index build {1e3 * s.index_build_s:.1f} ms ({s.seconds:.0f} s)"
    )
