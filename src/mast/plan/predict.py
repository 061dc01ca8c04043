"""What a scanner will get at each cell of a drift: beacons in view, the fix the
locator achieves, and the Cramér–Rao bound of its precision.

Each cell and heading is predicted twice over:

- **by geometry**, from one noise-free scan ray-cast against the walls and the
  beacons: which beacons and panels it sees (at least
  :data:`MIN_PANEL_RETURNS` returns, not within :data:`MIN_INCIDENCE_DEG` of
  grazing), whether a fix is owed (two beacons with two such panels each, as
  the availability benchmark counts it), and the Fisher information of the
  pose from the beams on panels, whose inverse is the Cramér–Rao bound
  (DESIGN.md; :mod:`mast.pipeline.bounds`);
- **by the locator itself**, on a few scans simulated there with the scanner's
  noise and located from nothing (no prior), exactly as ``mast locate`` would:
  the share that comes back with a fix within :attr:`PlanSettings.wrong_position_m`
  and :attr:`PlanSettings.wrong_azimuth_deg` of the truth is the fix rate; a fix
  further off is counted as wrong (the simulated scenes have never produced one).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from mast.pipeline.locator import LocatorConfig

from mast.core.beacon import Survey
from mast.core.geometry import PanelSet
from mast.core.noise import DEFAULT_SURVEY_SIGMA_M
from mast.core.pose import Pose2D, wrap_angle
from mast.core.walls import Drift
from mast.errors import InputError
from mast.pipeline.bounds import bound_of, truth_information
from mast.pipeline.hypotheses import major_sigma
from mast.plan.drift import Grid, build_grid
from mast.sim.drive import Reach
from mast.sim.owed import OWED, owes_fix
from mast.sim.scanner import ScannerModel, SimulatedScan, simulate_scan
from mast.sim.tunnel import Roughness, polyline_station, project_station, roughen
from mast.sim.world import Surface, World, WorldBuilder

__all__ = [
    "MIN_INCIDENCE_DEG",
    "MIN_PANEL_RETURNS",
    "CellView",
    "Plan",
    "PlanSettings",
    "cell_pose",
    "plan_world",
    "predict",
    "view_cell",
]

#: Returns a panel needs to count as seen, and how far off grazing (as "owed" counts).
MIN_PANEL_RETURNS = OWED.min_points
MIN_INCIDENCE_DEG = OWED.min_incidence_deg

Progress = Callable[[int, int], None]


@dataclass(frozen=True, slots=True)
class PlanSettings:
    """How a plan is predicted.

    Attributes
    ----------
    step_m : float
        Spacing of the cells along the centreline.
    across_m : float, optional
        Spacing across the drift (``step_m`` when not given).
    margin_m : float
        Cells closer than this to a wall are not planned (the vehicle's half width).
    scans_per_cell : int
        Noisy scans located per cell and heading for the fix rate.
    min_fix_rate : float
        A cell and heading "has a fix" when at least this share of its scans fix.
    target_sigma_m : float, optional
        With a target, a cell is covered only when the bound's position
        standard deviation (semi-major axis of the 1-sigma ellipse) meets it too.
    roughness_m : float
        Peak amplitude of the rock's texture added to the walls (not at beacons).
    survey_sigma_m : float
        The locator's survey precision (its gates; the simulated survey is exact).
    wrong_position_m, wrong_azimuth_deg : float
        A fix further than this from the truth is counted as wrong, not as a fix.
    seed : int
        Seed of the noise and the rock's texture; each cell has its own stream.
    """

    step_m: float = 2.0
    across_m: float | None = None
    margin_m: float = 0.5
    scans_per_cell: int = 3
    min_fix_rate: float = 0.5
    target_sigma_m: float | None = None
    roughness_m: float = 0.03
    survey_sigma_m: float = DEFAULT_SURVEY_SIGMA_M
    wrong_position_m: float = 0.10
    wrong_azimuth_deg: float = 0.5
    seed: int = 0

    def __post_init__(self) -> None:
        if not 1 <= self.scans_per_cell <= 1000:
            raise InputError(f"scans per cell: {self.scans_per_cell}; give 1 to 1000")
        if not 0.0 < self.min_fix_rate <= 1.0:
            raise InputError(f"minimum fix rate {self.min_fix_rate:g} is not in (0, 1]")
        if self.target_sigma_m is not None and not (
            math.isfinite(self.target_sigma_m) and self.target_sigma_m > 0
        ):
            raise InputError(f"target sigma {self.target_sigma_m:g} m must be positive")
        if not (math.isfinite(self.roughness_m) and 0.0 <= self.roughness_m <= 1.0):
            raise InputError(f"wall roughness {self.roughness_m:g} m is not in [0, 1] m")

    @property
    def across(self) -> float:
        return self.step_m if self.across_m is None else self.across_m


@dataclass(frozen=True, slots=True)
class CellView:
    """What one noise-free scan from a cell and heading shows.

    Attributes
    ----------
    panels : dict of str to tuple of int
        The panels seen (enough returns, not grazing), per beacon id.
    information : ndarray, shape (3, 3)
        Fisher information of (E [m], N [m], A [rad]) from the beams on panels.
    """

    panels: dict[str, tuple[int, ...]]
    information: NDArray[np.float64]

    @property
    def beacons(self) -> tuple[str, ...]:
        return tuple(sorted(self.panels))

    @property
    def two_panel_beacons(self) -> int:
        return sum(len(p) >= 2 for p in self.panels.values())

    @property
    def owed(self) -> bool:
        return owes_fix(self.panels)


def covariance(information: NDArray[np.float64]) -> NDArray[np.float64]:
    """The bound ``information^-1``; ``inf`` on the diagonal when the pose is not determined."""
    return bound_of(information)


def position_major_sigma(cov: NDArray[np.float64]) -> float:
    """Semi-major axis of the 1-sigma position ellipse of a (3, 3) covariance."""
    c = cov[:2, :2]
    return major_sigma(c) if np.all(np.isfinite(c)) else math.inf


def plan_world(drift: Drift, survey: Survey, *, roughness_m: float = 0.0, seed: int = 0) -> World:
    """The drift's walls and the survey's beacons as a world to ray-cast.

    With ``roughness_m``, each wall gets a rock texture of that peak amplitude
    (wavelengths 0.2-1.5 m, drawn from ``seed`` and the wall's order), left
    smooth where a beacon is mounted on it. The texture of a wall does not
    depend on which beacons are mounted, only where it is dressed smooth.
    """
    wb = WorldBuilder()
    rough = Roughness(amplitude_m=roughness_m, wavelength_min_m=0.2, wavelength_max_m=1.5)
    for k, wall in enumerate(drift.walls):
        pts = wall.points
        if roughness_m > 0:
            smooth = []
            for b in survey:
                ends = [project_station(pts, b.edges[i]) for i in (0, 3)]
                on_wall = all(
                    math.dist(polyline_station(pts, s)[0], b.edges[i]) < 0.05
                    for s, i in zip(ends, (0, 3), strict=True)
                )
                if on_wall:
                    smooth.append((min(ends), max(ends)))
            pts = roughen(pts, rough, np.random.default_rng([seed, 23, k]), smooth_intervals=smooth)
        wb.polyline(pts, Surface("wall"))
    for b in survey:
        wb.panels(b.edges, b.id)
    return wb.build()


def _panels_seen(sim: SimulatedScan) -> dict[str, tuple[int, ...]]:
    seen = sim.panels_seen(OWED)
    return {b: tuple(p) for b, p in seen.items()}


def view_cell(
    world: World,
    panels: PanelSet,
    pose: Pose2D,
    scanner: ScannerModel,
) -> CellView:
    """The noise-free view from ``pose``: panels seen and the pose's Fisher information."""
    sim = simulate_scan(world, pose, scanner.noise_free())
    noise = scanner.noise()
    info = truth_information(
        pose,
        sim.scan.angles_rad,
        sim.scan.valid,
        panels,
        noise=noise,
        beacon_beams=sim.beacon_mask(),
    )
    return CellView(_panels_seen(sim), info)


@dataclass(frozen=True, eq=False)
class Plan:
    """The prediction over a drift's grid; arrays are indexed ``[station, offset, heading]``,
    heading 0 along the centreline's direction and 1 against it.

    Attributes
    ----------
    drift, survey, scanner, settings
        What was planned.
    grid : Grid
    views : ndarray of object (CellView or None outside the drift)
    fixes, wrong, scans : ndarray of int
        Locator outcomes on the noisy scans of each cell.
    """

    drift: Drift
    survey: Survey
    scanner: ScannerModel
    settings: PlanSettings
    grid: Grid
    views: NDArray[np.object_]
    fixes: NDArray[np.int64]
    wrong: NDArray[np.int64]
    scans: NDArray[np.int64]
    proposed: tuple[str, ...] = ()
    _cache: dict[str, NDArray[np.float64]] = field(default_factory=dict, repr=False)

    @property
    def inside(self) -> NDArray[np.bool_]:
        """(s, o, 2): cells planned."""
        return np.repeat(self.grid.inside[:, :, None], 2, axis=2)

    def headings_rad(self) -> NDArray[np.float64]:
        """(s, 2) azimuths of the scanner's forward axis at each station."""
        a = self.grid.azimuth_rad
        return np.stack([a, (a + math.pi) % (2 * math.pi)], axis=1)

    @property
    def fix_rate(self) -> NDArray[np.float64]:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.scans > 0, self.fixes / np.maximum(self.scans, 1), np.nan)

    @property
    def covariance(self) -> NDArray[np.float64]:
        """(s, o, 2, 3, 3) Cramér–Rao bound; NaN outside the drift."""
        if "cov" not in self._cache:
            out = np.full((*self.views.shape, 3, 3), np.nan)
            for idx, v in np.ndenumerate(self.views):
                if v is not None:
                    out[idx] = covariance(v.information)
            self._cache["cov"] = out
        return self._cache["cov"]

    @property
    def sigma_position(self) -> NDArray[np.float64]:
        """(s, o, 2) semi-major axis of the 1-sigma position ellipse (inf: not determined)."""
        if "major" not in self._cache:
            cov = self.covariance
            out = np.full(self.views.shape, np.nan)
            for idx, v in np.ndenumerate(self.views):
                if v is not None:
                    out[idx] = position_major_sigma(cov[idx])
            self._cache["major"] = out
        return self._cache["major"]

    @property
    def owed(self) -> NDArray[np.bool_]:
        out: NDArray[np.bool_] = np.vectorize(lambda v: v is not None and v.owed, otypes=[bool])(
            self.views
        )
        return out

    @property
    def beacons_in_view(self) -> NDArray[np.int64]:
        out: NDArray[np.int64] = np.vectorize(
            lambda v: 0 if v is None else len(v.panels), otypes=[np.int64]
        )(self.views)
        return out

    @property
    def has_fix(self) -> NDArray[np.bool_]:
        """(s, o, 2): the locator fixed at least the minimum share of the cell's scans."""
        with np.errstate(invalid="ignore"):
            return self.inside & (self.fix_rate >= self.settings.min_fix_rate - 1e-12)

    @property
    def covered(self) -> NDArray[np.bool_]:
        """(s, o, 2): a fix, and the target precision when one is set."""
        ok = self.has_fix
        target = self.settings.target_sigma_m
        if target is not None:
            with np.errstate(invalid="ignore"):
                ok = ok & (self.sigma_position <= target)
        return ok


def cell_pose(grid: Grid, row: int, col: int, heading: int) -> Pose2D:
    """The scanner's pose at a cell, heading 0 along the centreline's direction, 1 against."""
    az = float(grid.azimuth_rad[row]) + (math.pi if heading else 0.0)
    e, n = grid.xy[row, col]
    return Pose2D(float(e), float(n), az % (2 * math.pi))


def locator_config(scanner: ScannerModel, settings: PlanSettings) -> LocatorConfig:
    """The locator as ``mast locate --scanner`` would run it."""
    from mast.pipeline.locator import LocatorConfig

    noise = scanner.noise()
    return LocatorConfig(
        range_sigma_m=noise.range_sigma_m,
        angle_sigma_rad=noise.angle_sigma_rad,
        survey_sigma_m=settings.survey_sigma_m,
    )


def _locate_cell(
    world: World,
    survey: Survey,
    pose: Pose2D,
    scanner: ScannerModel,
    settings: PlanSettings,
    rng: np.random.Generator,
) -> tuple[int, int]:
    """Fixes and wrong fixes over the cell's noisy scans."""
    from mast.pipeline.locator import locate

    cfg = locator_config(scanner, settings)
    fixes = wrong = 0
    for _ in range(settings.scans_per_cell):
        sim = simulate_scan(world, pose, scanner, rng=rng)
        fix = locate(sim.scan, survey, config=cfg)
        if not fix.ok or fix.pose is None:
            continue
        off = math.hypot(fix.pose.easting - pose.easting, fix.pose.northing - pose.northing)
        turn = abs(math.degrees(wrap_angle(fix.pose.azimuth - pose.azimuth)))
        if off <= settings.wrong_position_m and turn <= settings.wrong_azimuth_deg:
            fixes += 1
        else:
            wrong += 1
    return fixes, wrong


def predict(
    drift: Drift,
    survey: Survey,
    scanner: ScannerModel,
    settings: PlanSettings = PlanSettings(),
    *,
    grid: Grid | None = None,
    base: Plan | None = None,
    only: NDArray[np.bool_] | None = None,
    progress: Progress | None = None,
) -> Plan:
    """Predict every cell of the drift's grid, or only the cells ``only`` marks.

    Parameters
    ----------
    grid : Grid, optional
        The cells (built from the drift and the settings when not given).
    base, only : Plan and ndarray of bool (s, o), optional
        Re-predict only the marked cells; the others are copied from ``base``
        (a layout changed within reach of those cells).
    progress : callable, optional
        Called with (cells done, cells to do).
    """
    if grid is None:
        grid = (
            base.grid
            if base is not None
            else build_grid(drift, settings.step_m, settings.across, settings.margin_m)
        )
    shape = (*grid.inside.shape, 2)
    if base is not None:
        views = base.views.copy()
        fixes, wrong, scans = base.fixes.copy(), base.wrong.copy(), base.scans.copy()
    else:
        views = np.full(shape, None, dtype=object)
        fixes = np.zeros(shape, dtype=np.int64)
        wrong = np.zeros(shape, dtype=np.int64)
        scans = np.zeros(shape, dtype=np.int64)
    todo_cells = grid.inside if only is None else grid.inside & only
    world = plan_world(drift, survey, roughness_m=settings.roughness_m, seed=settings.seed)
    reach = Reach.of(world)
    panels = PanelSet.from_survey(survey)
    todo = [(r, c) for r, c in zip(*np.nonzero(todo_cells), strict=True)]
    total = 2 * len(todo)
    done = 0
    for r, c in todo:
        near = reach.near(grid.xy[r, c], scanner.range_max_m + 1.0)
        for h in (0, 1):
            pose = cell_pose(grid, int(r), int(c), h)
            views[r, c, h] = view_cell(near, panels, pose, scanner)
            rng = np.random.default_rng([settings.seed, 101, int(r), int(c), h])
            fixes[r, c, h], wrong[r, c, h] = _locate_cell(
                near, survey, pose, scanner, settings, rng
            )
            scans[r, c, h] = settings.scans_per_cell
            done += 1
            if progress is not None:
                progress(done, total)
    return Plan(
        drift,
        survey,
        scanner,
        settings,
        grid,
        views,
        fixes,
        wrong,
        scans,
        proposed=() if base is None else base.proposed,
    )
