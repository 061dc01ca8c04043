"""Six degrees of freedom from one 3D lidar frame: the 2D pipeline on the frame's plan
view, then the six-parameter adjustment on the panels it names (docs/3d.md).

1. **The vertical** (:func:`mast.pipeline.plan_view.estimate_up`): from the normals of
   the walls, the floor and the roof.
2. **The plan view** (:func:`~mast.pipeline.plan_view.plan_scan`): the frame levelled
   by it, the band about the sensor's height projected, as one 2D scan.
3. **The 2D fix** (:func:`mast.pipeline.locator.locate`): easting, northing and azimuth,
   the beacons told from clutter, with every test of 2D; where the plan view finds
   none, the vertical pitched by a grade's worth (:data:`PITCH_TRIES_DEG`). No 2D fix,
   no 3D fix: its reason is the frame's.
4. **The start**: the 2D pose with the levelling's pitch and roll; the elevation from
   the highest return on each panel, which is below that panel's top.
5. **The adjustment** (:func:`mast.pipeline.adjust3d.adjust_pose`), twice: once on the
   returns within a wide gate of the panels, once on those within four range sigmas of
   the adjusted panels and below their tops.
6. **The tests**: two beacons each showing two panels with enough returns, the global
   test of the adjustment, and the 3D position within the 2D fix's 99.9 % ellipse
   widened by the tilt's share. A frame whose panels no ring crosses at the top keeps
   its fix with the elevation unobserved (its variance says so).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.frames import yaw_of_azimuth
from mast.core.pose3d import Frame3D, Pose3D, rotation_rpy
from mast.errors import InputError
from mast.pipeline.adjust3d import Adjustment3D, PanelPlanes, adjust_pose
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.pipeline.plan_view import estimate_up, level_rotation, plan_scan

__all__ = ["Fix3D", "Locator3DConfig", "locate3d"]

#: The pitches about the estimated vertical the plan view is tried at, in turn, degrees.
PITCH_TRIES_DEG = (0.0, 4.0, -4.0, 8.0, -8.0)


@dataclass(frozen=True, slots=True)
class Locator3DConfig:
    """The 3D locator's settings.

    Attributes
    ----------
    range_sigma_m : float
        The lidar's range noise (one sigma), metres.
    survey_sigma_m : float
        Each surveyed edge's horizontal and elevation sigma, metres.
    band_m : (float, float)
        Heights about the sensor, levelled, that make the plan view.
    plan_resolution_deg : float
        Bearing bins of the plan view.
    min_panel_returns : int
        Returns a panel needs to count as shown.
    first_gate_m : float
        The first adjustment's gate about the panels (the start is the 2D fix's).
    reject_alpha : float
        The global test's level.
    """

    range_sigma_m: float = 0.02
    survey_sigma_m: float = 0.003
    band_m: tuple[float, float] = (-0.5, 1.0)
    plan_resolution_deg: float = 0.25
    min_panel_returns: int = 6
    first_gate_m: float = 0.1
    reject_alpha: float = 1e-3


@dataclass(frozen=True, slots=True)
class Fix3D:
    """What the 3D locator concluded about one frame: ``status`` "fix" with ``pose`` and
    ``adjustment``, or "no_fix" with ``reason`` (2D's reasons, or ``rejected``,
    ``inconsistent``, ``one_beacon``) and ``detail``."""

    status: str
    pose: Pose3D | None
    adjustment: Adjustment3D | None
    reason: str | None
    detail: str
    plan: Fix
    """The 2D fix of the plan view."""
    up: NDArray[np.float64]
    beacons: tuple[str, ...] = ()
    elapsed_s: float = 0.0
    stages_s: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "fix"


def _start_elevation(
    grid: NDArray[np.float64], which: NDArray[np.intp], planes: PanelPlanes
) -> float | None:
    """The sensor's elevation from the highest return on each panel (heights relative to
    a sensor at elevation 0): the median of top - highest, None without tops."""
    guesses = [
        float(planes.top[k] - grid[which == k, 2].max())
        for k in np.unique(which[which >= 0])
        if math.isfinite(planes.top[k])
    ]
    return float(np.median(guesses)) if guesses else None


def _shown(which: NDArray[np.intp], planes: PanelPlanes, least: int) -> tuple[str, ...]:
    """The beacons showing at least two panels with ``least`` returns each."""
    counts = np.bincount(which[which >= 0], minlength=len(planes))
    shown: dict[str, int] = {}
    for k, c in enumerate(counts):
        if c >= least:
            shown[planes.beacon[k]] = shown.get(planes.beacon[k], 0) + 1
    return tuple(sorted(b for b, n in shown.items() if n >= 2))


def _too_few(beacons: tuple[str, ...], cfg: Locator3DConfig) -> str:
    return (
        f"in 3D, {len(beacons)} beacon(s) show two panels with {cfg.min_panel_returns} returns each"
    )


def locate3d(
    frame: Frame3D,
    survey: Survey,
    *,
    config: Locator3DConfig | None = None,
    planes: PanelPlanes | None = None,
) -> Fix3D:
    """Locate one 3D frame against the survey (see the module). The survey's beacons
    must carry elevations (their top edges); ``planes`` may be given to spare building
    them again for each frame."""
    cfg = config or Locator3DConfig()
    if any(b.elevations is None for b in survey):
        raise InputError("a 3D frame needs the survey's elevations (the panels' top edges)")
    t0 = time.perf_counter()
    spent: dict[str, float] = {}

    def lap(name: str, since: float) -> float:
        now = time.perf_counter()
        spent[name] = now - since
        return now

    up = estimate_up(frame)
    t = lap("vertical", t0)
    plan_cfg = LocatorConfig(range_sigma_m=cfg.range_sigma_m, survey_sigma_m=cfg.survey_sigma_m)
    level = level_rotation(up)
    for tilt in PITCH_TRIES_DEG:
        # the walls leave the pitch along the drift to the floor, which a grade tilts:
        # where the plan view finds no fix, the same vertical pitched by a grade's worth
        a = math.radians(tilt)
        up = level.T @ np.array([math.sin(a), 0.0, math.cos(a)])
        scan = plan_scan(frame, up=up, band=cfg.band_m, resolution_deg=cfg.plan_resolution_deg)
        plan = locate(scan, survey, config=plan_cfg)
        if plan.ok:
            break
    t = lap("plan", t)

    def refused(reason: str | None, detail: str, adj: Adjustment3D | None = None) -> Fix3D:
        return Fix3D(
            "no_fix", None, adj, reason, detail, plan, up, (), time.perf_counter() - t0, spent
        )

    if not plan.ok or plan.pose is None:
        return refused(plan.reason, f"plan view: {plan.detail}")
    planes = planes or PanelPlanes.of(survey)
    # the 2D pose, with the levelling's tilt: R = Rz(yaw) @ L, L = Ry(pitch) Rx(roll)
    R0 = rotation_rpy(0.0, 0.0, yaw_of_azimuth(plan.pose.azimuth)) @ level_rotation(up)
    flat = Pose3D.from_rotation(R0, (plan.pose.easting, plan.pose.northing, 0.0))
    pts = frame.points
    grid = flat.sensor_to_grid(pts)
    clear = 3.0 * cfg.range_sigma_m  # the wall at a free end: within 3 sigmas, ambiguous
    which = planes.assign(grid, flat.position, cfg.first_gate_m, clear_m=clear)
    z0 = _start_elevation(grid, which, planes)
    if z0 is None:
        return refused("one_beacon", "no return on a surveyed panel in 3D")
    start = Pose3D(flat.easting, flat.northing, z0, flat.azimuth, flat.pitch, flat.roll)
    beacons = _shown(which, planes, cfg.min_panel_returns)
    if len(beacons) < 2:
        return refused("one_beacon", _too_few(beacons, cfg))
    sig_r, sig_s = cfg.range_sigma_m, cfg.survey_sigma_m
    try:
        adj = adjust_pose(
            pts, which, planes, start, range_sigma_m=sig_r, survey_sigma_m=sig_s,
            gate_m=cfg.first_gate_m,
        )  # fmt: skip
        gate = 4.0 * sig_r
        for _ in range(3):  # the tight gate about the adjusted panels, until it holds
            grid = adj.pose.sensor_to_grid(pts)
            margin = max(2.0 * math.sqrt(adj.covariance[2, 2]), 2.0 * sig_r)
            if adj.top_edges == 0:
                margin = math.inf  # the elevation unknown: no top to cut at
            floor = planes.bottoms(grid, adj.pose.position, which, 2.0 * sig_r)
            again = planes.assign(
                grid, adj.pose.position, gate, clear_m=clear, top_margin_m=margin,
                bottoms=floor,
            )  # fmt: skip
            if np.array_equal(again, which):
                break
            which = again
            beacons = _shown(which, planes, cfg.min_panel_returns)
            if len(beacons) < 2:
                return refused("one_beacon", _too_few(beacons, cfg), adj)
            adj = adjust_pose(
                pts, which, planes, adj.pose, range_sigma_m=sig_r, survey_sigma_m=sig_s,
                gate_m=gate,
            )  # fmt: skip
    except np.linalg.LinAlgError:  # the panels seen leave a direction unobserved
        return refused("one_beacon", "the panels seen do not hold the pose in 3D")
    lap("adjustment", t)
    beacons = _shown(which, planes, cfg.min_panel_returns)
    if len(beacons) < 2:
        return refused("one_beacon", _too_few(beacons, cfg), adj)
    if adj.test_p < cfg.reject_alpha:
        return refused(
            "rejected",
            f"reference variance {adj.reference_variance:.2f} on {adj.dof} degrees of "
            "freedom: the returns do not fit the surveyed panels",
            adj,
        )
    # the 3D position must be where the plan view put it (within both sigmas)
    assert plan.adjustment is not None
    d = np.array([adj.pose.easting - plan.pose.easting, adj.pose.northing - plan.pose.northing])
    c = plan.adjustment.covariance[:2, :2] + adj.covariance[:2, :2]
    if float(d @ np.linalg.solve(c, d)) > 13.8:  # chi-square, 2 dof, 0.1 %
        return refused(
            "inconsistent",
            f"the 3D position is {1e3 * float(np.hypot(*d)):.1f} mm from the plan view's fix",
            adj,
        )
    return Fix3D(
        "fix",
        adj.pose,
        adj,
        None,
        "",
        plan,
        up,
        beacons,
        time.perf_counter() - t0,
        spent,
    )
