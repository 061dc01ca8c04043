"""Six degrees of freedom from one 3D lidar frame: the 2D pipeline on the frame's plan
view, then the six-parameter adjustment on the panels it names (docs/3d.md).

1. **The vertical** (:func:`mast.pipeline.plan_view.estimate_up`): from the normals of
   the walls, the floor and the roof.
2. **The plan view** (:func:`~mast.pipeline.plan_view.plan_scan`): the frame levelled
   by it, a band of heights about the sensor's projected, as one 2D scan.
3. **The 2D fix** (:func:`mast.pipeline.locator.locate`): easting, northing and azimuth,
   the beacons told from clutter, with every test of 2D. The walls leave the pitch
   along the drift to the floor, which a grade tilts, and a beacon may stand wholly
   below or above the sensor: where the plan view finds no fix, or its fix no 3D fix,
   the next of the bands (:attr:`Locator3DConfig.bands_m`) and pitches
   (:data:`PITCH_TRIES_DEG`) is tried (:func:`_tries`). After the first try that
   fails, the beacons its plan view found, even one, give the vertical
   (:func:`_on_its_panels`), tried next. A plan view that confirms one beacon only
   starts the 3D stages from that beacon's pose (where they refuse, again from the
   pose on its own panels, :data:`OWN_TILT_SIGMA_DEG`); a second beacon they find is
   confirmed by the plan view located again with the pose as a 2D prior, each beacon
   in the band of its own tops (:func:`_plan_again`), where that plan view finds a fix
   (:func:`_from_one_beacon`; where it confirms the first beacon alone, the 3D tests
   stand, the tilt held to :data:`ALONE_TILT_SIGMA_DEG`). No fix in any, no 3D fix: the
   reason is the first refusal of a 3D adjustment's, or else the first refusal's.
4. **The start**: the 2D pose with the levelling's pitch and roll, and the elevation
   where the most panels' top brackets agree (:func:`_start_elevation`: hits in a
   tight gate, on panels with :data:`START_HITS` of them, each panel's run of them up
   from its middle, and the rays crossing over it). Only returns within :data:`NEAR_M`
   of a panel in plan are looked at after.
5. **The tilt, grown out** (:func:`mast.pipeline.adjust3d.adjust_pose`, elevation
   held): on the returns within four range sigmas of the panels, first those within
   half a metre of the sensor's height, where the plan view's tilt error moves a return
   least, then a metre, two, all (:data:`REACH_M`); a stage that shows one beacon only,
   before any shows two, moves the pose onto its panels (:func:`_on_one_beacon`). Each
   panel is cut at its top (the start's elevation), above its floor
   (:data:`FLOOR_CLEAR_M`) and, once adjusted, at the bottom its returns show; a
   return within the gate of two panels is neither's, one nearer its beacon's wall
   than its panel the wall's. The walls' vertical enters as an observation of the tilt
   (:data:`TILT_PRIOR_DEG`), which only a frame whose panels hold the tilt loosely
   feels.
6. **The elevation**: the adjustment with the top edges' brackets of the beacons shown,
   and the panels cut again at their adjusted tops, until the assignment holds.
7. **The tests**: two beacons each showing two panels crossed by two rings of three
   returns (the rule a frame is owed a fix by); the global test of the adjustment; the
   tilt held to :data:`MAX_TILT_SIGMA_DEG` (an elevation held no better than
   :data:`MAX_ELEVATION_SIGMA_M` is reported not observed); the top edges' rays settled
   (:attr:`~mast.pipeline.adjust3d.Adjustment3D.settled`); every beam crossing a panel
   with returns, between its lowest and highest, hitting it where the pose puts it
   (:meth:`~mast.pipeline.adjust3d.PanelPlanes.misfits`: the beam verification of 2D,
   in 3D; a panel with no return is not looked at); and the 3D position within the 2D
   fix's 99.9 % ellipse widened by the plan view's smear (:data:`PLAN_SLACK_M`). A
   frame whose panels no ring crosses at the top keeps its fix with the elevation
   unobserved (its variance says so).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core._kernels import contiguous3d, floors3d
from mast.core.beacon import Survey
from mast.core.frames import yaw_of_azimuth
from mast.core.pose import Pose2D
from mast.core.pose3d import Frame3D, Pose3D, rotation_rpy
from mast.core.scan import Scan
from mast.errors import InputError
from mast.pipeline.adjust3d import (
    FLOOR_PAST_M,
    ROCK_M,
    UNBRACKETED,
    Adjustment3D,
    PanelPlanes,
    _beacon_groups,
    _panel_lists,
    _per_panel,
    _Rays,
    _runs,
    _sorted_medians,
    _top_edges,
    adjust_pose,
)
from mast.pipeline.bounds3d import _rotation_derivatives
from mast.pipeline.locator import Fix, LocatorConfig, locate, locate_again
from mast.pipeline.plan_view import estimate_up, level_rotation, plan_scan, rings_bottom_up
from mast.pipeline.tracking import Prior

__all__ = ["Fix3D", "Locator3DConfig", "locate3d"]

#: The pitches about the estimated vertical the plan view is tried at, in turn, degrees.
PITCH_TRIES_DEG = (0.0, 4.0, -4.0, 8.0, -8.0, 12.0, -12.0)
#: How many of the bands (``Locator3DConfig.bands_m``, in order) a vertical refined
#: from a beacon's panels is tried in: None, every band. At the refined vertical a second
#: beacon may be in the widest band only (the first two bands alone left 3 of seed 0's
#: 480 owed frames and 5 of seeds 1 and 2's 960 unfixed).
REFINED_BANDS: int | None = None
#: The heights about the sensor the adjustment is grown through, metres.
REACH_M = (0.5, 1.0, 2.0, math.inf)
#: Before the first adjustment, the gate is widened by this times a return's height
#: (the plan view's vertical may be off by a couple of degrees).
TILT_SLACK = 0.04
#: The sigma of the walls' vertical as an observation of the pitch and roll, degrees
#: (the estimate is within 2 deg across the drift and is pitched by the plan view's
#: tries along it).
TILT_PRIOR_DEG = 5.0
#: The largest sigma of roll or pitch a fix is given with, degrees (the panels seen
#: hold the tilt by their heights' spread and their directions: one short panel's few
#: rings may not), and of an elevation, metres (above it, the elevation is reported
#: not observed: its brackets were a ring spacing wide). A fix is given with the tilt's
#: own sigma up to the limit: at 0.6 deg rather than 0.3, the benchmark fixed 424
#: owed frames of 480 against 393 (24 more at the VLP-16 at 3 cm) and fresh draws 776
#: of 1060 against 667, none wrong, the plan position still to millimetres
#: (docs/3d.md). At 1 deg rather than 0.6 (2026-12-07, the seventh session), 12 more of
#: seeds 0-3's 1 920 owed frames, none lost, none wrong, every one within 2.1 sigma, the
#: coverage the same: 1 374 of the fresh seeds' 1 440 against 1 362 (no owed frame of
#: them is left refused for its tilt). Such a fix's roll and pitch are no survey's; its
#: position and azimuth are (within 12 mm and 0.002 deg on those frames), and the
#: record's sigmas say which.
MAX_TILT_SIGMA_DEG = 1.0
MAX_ELEVATION_SIGMA_M = 0.05
#: A panel with fewer returns than this is left out of the fix's adjustment: a lone
#: return cannot be checked against its panel's others (its residual is all its own),
#: and on a far panel, the floor's or the neighbouring panel's across a joint, it
#: levers the azimuth and the tilt by many sigmas that no test sees (a fix 7 sigma off
#: in azimuth; at three returns, rather than two, fewer fixes and more tails).
MIN_PANEL_RETURNS = 2
#: The plan view's own error, beyond its covariance, in the test that the 3D position
#: is where it put it: a vertical off by a degree smears each panel's plan view by its
#: height times that (1.7 cm a metre up), metres.
PLAN_SLACK_M = 0.02
#: How far above the floor by a panel its returns must cross (no beacon stands on the
#: floor, and near its foot the floor is within the gate of its plane), metres.
FLOOR_CLEAR_M = 0.15
#: Beams crossing a panel where the pose puts it that may miss it: this many, or this
#: share of those that hit it, whichever is more (a return's noise beyond the gate, a
#: ray grazing an edge).
MISFIT_LEAST = 3
MISFIT_SHARE = 0.01
#: The heights about the sensor the vertical is grown through from the plan view's
#: beacons (:func:`_on_its_panels`), metres, and the loosest tilt it is tried with,
#: degrees (a plan view is smeared by a degree's error a metre up by 1.7 cm).
REFINE_REACH_M = (0.5, 1.0, 1.5)
REFINE_TILT_SIGMA_DEG = 1.0
#: The adjustments with the top edges, each on the panels cut again at the tops the last
#: one put, until the cut holds; a fix whose cut still changes after these, and whose
#: last adjustment moved a parameter by more than SETTLE_SIGMAS of its sigma, is refused
#: (a few returns at a cut's edge may go in and out for ever; a pose that jumps does
#: not know where it is).
ELEVATION_ROUNDS = 5
SETTLE_SIGMAS = 2.0
#: A return the fix adjusted on lies below its panel's surveyed top: above it by more
#: than the gate and this many sigmas of its height there (the elevation's and the
#: tilt's, from the adjustment that bracketed the elevation, and the survey's), the
#: fix is refused. A tilt many degrees off within a drift's walls moves every panel
#: within its own plane, which no plane residual and no beam test sees; the tops see it
#: (two fixes 9.4 deg off in pitch at 26 sigma and 1.5 deg in roll at 8 sigma had
#: returns 1 and 2.2 m above their panels' tops, 13 and 70 of these sigmas).
TOP_SIGMAS = 5.0
#: Plan views confirming one beacon only that a frame tries to start from
#: (:func:`_from_one_beacon`). Where beacons share a design, one beacon alone is any of
#: them to the plan view, and the first tries' single beacon is often another's
#: identity, metres off, while a later try's is the true one (15 of seed 1's 24 VLP-16
#: misses at two starts had the true pose first in some try's plan view). Six starts
#: rather than two fixed 16 more of fresh draws' 960 owed frames (seeds 1 and 2), none
#: lost, none wrong; eight fixed no more of seed 1's misses (those fixed, at the third
#: to sixth start).
ONE_BEACON_STARTS = 6
#: Where no try fixes, the plan views refused as ``inconsistent`` (no pose the beams
#: confirm, or beacons that disagree) are located again leniently
#: (:data:`LENIENT_WALL_M`), in the tries' order, and at most this many of their 2D
#: fixes start the 3D stages (:func:`_from_one_beacon`). On fresh draws (seeds 1 and
#: 2) 8 more of 960 owed frames fixed, none lost, none wrong.
LENIENT_STARTS = 3
#: Where the 3D stages from a one-beacon start refuse, they start again from the pose
#: on that beacon's own panels (:func:`_on_its_panels`: its position, azimuth and
#: vertical), where those hold the tilt to OWN_TILT_SIGMA_DEG and put the vertical more
#: than OWN_APART_DEG from the try's, degrees: a try's vertical degrees off on a grade
#: smears the plan view, and its pose with it.
OWN_TILT_SIGMA_DEG = 3.0
OWN_APART_DEG = 2.0
#: The 3D stages from a one-beacon start on the same beacon within this distance, and
#: this angle in azimuth and vertical, of one made already are not run again: its
#: result is taken (the plan view located again to confirm a fix is still its own
#: band's). The 3D stages converge from decimetres off; on seed 0's 780 frames none of
#: 301 such starts (another band's plan view's, with the same vertical) ended otherwise
#: than the first, nor on the 120-frame set 59 of 361 3D runs from one beacon (starts
#: from a beacon's own panels among them, their verticals within 0.2 deg).
SAME_START_M = 0.02
SAME_START_DEG = 0.2
#: In the lenient plan view, a return beyond a panel within this of its beacon's wall
#: (the line of its free ends) is no verdict rather than a beam through the panel
#: (``VerificationConfig.wall_behind_m``), metres: a plan view cannot tell a beam
#: through a panel from one passing over or under it onto the wall the beacon stands on
#: (a beacon 4.9 m off and 0.86 m below the sensor, under the band at most bearings,
#: refused the true pose by 24 such beams, 19 of them within this of its wall). The
#: rock's roughness and the noise of a bin's centroid.
LENIENT_WALL_M = 0.15
#: The window of the prior a one-beacon start's 3D pose sets the plan view located
#: again (metres, degrees).
ONE_BEACON_PRIOR = (0.25, 2.0)
#: The plan view located again near a 3D pose (:func:`_plan_again`) is verified as the
#: lenient one is (AGAIN_WALL_M: :data:`LENIENT_WALL_M`), and ICP refines its
#: hypotheses with these coarse gates only (metres; one less certain than the first
#: starts wider, by its own spread, as in 2D). A 3D pose is millimetres off in plan, and
#: a beacon whose panels the band passes over or under shows the plan view only its
#: wall, a decimetre or two behind them: the 2D gates (15 cm first) took that wall for
#: its panels, and dragged a hypothesis that started 3 mm off to 0.44 m (a VLP-16 frame
#: of fresh draws, seed 2, drift 3, frame 4: B3 3.3 m off, its top 0.79 m below the
#: sensor and grazed by the lowest ring), and the strict beams took that wall's returns
#: for 68 beams through its panels. Near a pose that passed every 3D test (the 3D beams'
#: own, :meth:`~mast.pipeline.adjust3d.PanelPlanes.misfits`, among them) the plan view
#: must still show two beacons' panels where the pose puts them.
AGAIN_GATES_M = (0.05,)
AGAIN_WALL_M = LENIENT_WALL_M
#: The band of tops in the plan view located again (each beacon's bearings in its own,
#: then every bearing in that of the beacons the 3D pose shows): from this far below
#: the lowest of the tops to this far below the highest, metres.
ONE_BEACON_BAND_M = (0.4, 0.05)
#: The largest sigma of roll or pitch a one-beacon 3D fix is given with where the plan
#: view located again confirms its first beacon alone, degrees: without the plan view's
#: agreement, a fix held to 0.29 deg came out 1.05 deg off in pitch (3.6 sigma).
ALONE_TILT_SIGMA_DEG = 0.2
#: Nearer a free end than the clearance (the gate over the sine of the panel's angle to
#: the wall), down to this share of it, a panel keeps the returns of the rings that
#: cross its beacon clear of both free ends (:func:`_witnessed`). On five draws of 367
#: owed frames, 0.5 fixed 23 more than none, 0.25 five more again with a worse coverage
#: (rms error/sigma up to 1.38), 0 gave a 5.5-sigma pitch.
WITNESSED_CLEAR = 0.5
#: The same for the returns that show a panel (count its rings, :func:`_shown`, as the
#: rule a frame is owed a fix by counts them, up to its free end) but are not adjusted
#: on (there a return may be the wall's). A far beacon's end panel, cut clear of its free
#: end, kept one or two returns a ring, and the frame was refused as one beacon: 0
#: rather than WITNESSED_CLEAR fixed 10 more of fresh draws' 960 owed frames (seeds 1
#: and 2), none lost, none wrong; seed 0 the same.
SHOWN_CLEAR = 0.0
#: A ring's returns on a beacon witness it (:func:`_standing_off`) where their mean
#: stands off the wall by more than the rock's bulge plus some gates over the root of
#: their count. From the chord e1-e4, where the ring shows no wall past the beacon's
#: free ends, WITNESS_MEAN_GATES of the gate (a pose's error moves the returns off the
#: chord and does not average out). On my eleven draws (803 owed frames) 1.5 fixed 24
#: more than the per-return rule alone, none wrong (then the bar from the wall shown
#: too); 0.75 fixed 30 more, one of them wrong (1.5 deg in pitch), and 0.75 from the
#: chord alone a fix 16 sigma off in azimuth (a far beacon's middle panel put on its
#: wall, which the pose's error made stand off it).
WITNESS_MEAN_GATES = 1.5
#: From the wall the ring shows within WALL_PAST_M past the beacon's free ends (metres;
#: a pose's error moves it as it moves the returns), WITNESS_WALL_GATES of the range
#: noise's gate: 2.5 sigmas of the difference of three returns' mean and three others'
#: median (the gate is four range sigmas, the median's own noise about 0.7 sigma),
#: where 1.5 gates were 3.8. A beacon standing 12.8 cm off its wall, its middle panel
#: crossed by three or four returns a ring at 3 cm, met a bar of 14.0 to 15.4 cm on
#: every ring: none was witnessed, its 0.2 m end panel (all of it within the clearance
#: of its free end) was shown by none, and the frame was refused as one beacon even from
#: the true pose. On seeds 0-3 (1 920 owed frames) 1.0 rather than 1.5 fixed 4 more,
#: none lost, none wrong (83 fixes moved, within 2.9 sigma after); on seeds 4 and 5,
#: run first after it was chosen, 9 more and one fewer of 960, none wrong.
WITNESS_WALL_GATES = 1.0
WALL_PAST_M = 0.3
#: How far about a panel, in plan, the lowest returns are its floor, metres (a floor
#: may rise to the wall's foot: at 2 m the lowest returns of a drift's middle, 22 cm
#: below the floor under a beacon, let one ring's floor returns pass for an end panel and
#: lever a roll 1.06 deg off; at 1 m too few returns spread out from the wall to tell a
#: floor, and a fix went 1.13 deg off in roll).
FLOOR_RADIUS_M = 1.5
#: The plan view's tilt error in a return's place, for the first look, metres.
START_SLACK_M = 0.03
#: The tight hits a panel needs for its top bracket to count towards the start's
#: elevation (:func:`_start_elevation`): as many as a ring needs on a panel to count
#: (``Locator3DConfig.min_line_returns``' default). On seeds 0-3 (1 920 owed frames) one
#: more fixed and one fewer (whose start, 4.1 m low, had let a third beacon show), none
#: wrong, 60 fixes moved (within 2.7 sigma after, as before); on seed 3's misses the
#: starts from a right 2D pose that were 0.7 to 3.6 m low are within 0.26 m.
START_HITS = 3
#: A beacon is one plate: its panels' bottoms are as far below their tops. A return on a
#: panel deeper below its top than the beacon's other panels are seen, by more than
#: PLATE_RINGS ring spacings at its range and PLATE_SLACK_M, is below the plate
#: (:func:`_plate_floors`). The slack is for the other panels' lower parts hidden (on my
#: draws a panel 5 m off was seen 0.2 m deeper than both its neighbours, beyond a ring
#: and a half; 5 cm lost 11 fixes there against 6 won); the floor returns it is for lay
#: 0.8 to 1.9 m below the others' lowest.
PLATE_RINGS = 1.5
PLATE_SLACK_M = 0.5
#: How far from a panel, in plan, a return may lie and be looked at by the adjustment:
#: the wall behind the panel and a 10 deg tilt's worth at 2 m above or below the sensor.
NEAR_M = 0.5


@dataclass(frozen=True, slots=True)
class Locator3DConfig:
    """The 3D locator's settings.

    Attributes
    ----------
    range_sigma_m : float
        The lidar's range noise (one sigma), metres.
    survey_sigma_m : float
        Each surveyed edge's horizontal and elevation sigma, metres.
    bands_m : tuple of (float, float)
        Heights about the sensor, levelled, that make the plan view, tried in turn (a
        beacon may be wholly below or above the sensor).
    plan_resolution_deg : float
        Bearing bins of the plan view.
    min_line_returns : int
        Returns a ring (a line) needs on a panel to count; a panel is shown by two such
        lines.
    reject_alpha : float
        The global test's level.
    """

    range_sigma_m: float = 0.02
    survey_sigma_m: float = 0.003
    bands_m: tuple[tuple[float, float], ...] = ((-1.0, 0.5), (-0.5, 1.0), (-1.5, 1.5))
    plan_resolution_deg: float = 0.25
    min_line_returns: int = 3
    reject_alpha: float = 1e-3


@dataclass(frozen=True, slots=True)
class Fix3D:
    """What the 3D locator concluded about one frame: ``status`` "fix" with ``pose`` and
    ``adjustment``, or "no_fix" with ``reason`` (2D's reasons: the plan view's, or the 3D
    tests' ``one_beacon``, ``rejected``, ``inconsistent``, ``degenerate_geometry``) and
    ``detail``."""

    status: str
    pose: Pose3D | None
    adjustment: Adjustment3D | None
    reason: str | None
    detail: str
    plan: Fix
    """The plan view's 2D locate the 3D stages started from: its fix, or, for a fix
    started from one beacon whose plan view located again confirmed that beacon alone
    (:func:`_from_one_beacon`), that first plan view's refusal (``one_beacon``)."""
    up: NDArray[np.float64]
    beacons: tuple[str, ...] = ()
    panels: dict[str, tuple[int, ...]] = field(default_factory=dict)
    """For a fix, beacon id → the panels (1..3) whose returns the adjustment used."""
    elapsed_s: float = 0.0
    stages_s: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == "fix"


def _start_elevation(
    grid: NDArray[np.float64],
    origin: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    gate_m: float,
    spacing_rad: float,
    local: list[NDArray[np.intp]],
    rays: _Rays | None = None,
    *,
    least: int = 1,
) -> tuple[float, float] | None:
    """The sensor's elevation where the most panels' top brackets agree (``grid`` seen
    from ``origin`` at elevation 0, ``which`` tight hits): each panel with at least
    ``least`` hits says ``top - crossing over < Z <= top - hit``, its top edge's bracket
    where it has one (:func:`~mast.pipeline.adjust3d._top_edges`), else
    ``Z <= top - highest hit``; a return on the roof or the wall within the gate of a
    panel's plane far above it makes one panel's bracket wrong, not the most. A bracket
    open below is met by every elevation under it, and so are all of them together:
    one or two stray returns (fewer than ``least``: :data:`START_HITS`) on panels that
    show nothing else would each open one, and outnumber the top edges where the tops
    agree (on seed 0 a lone return 2.9 m above a panel's top put the start 3.2 m low,
    where the stages grew a pitch 7 deg off). The middle and half the width of the
    interval the most brackets share; None without ``least`` hits on a panel with a top.
    ``spacing_rad``: the lidar's rings' spacing; ``local``: each panel's returns
    (PanelPlanes.local); ``rays``: their crossings seen from ``origin``, where the
    caller has them."""
    o = np.asarray(origin, dtype=float)
    rel = grid - o
    if least > 1:
        which = _checked(which, planes, least)
    if rays is None:
        rays = planes._rays(rel, o, local)
    ends: list[tuple[float, int]] = []
    which = _contiguous(which, grid, o, planes, spacing_rad, rays)
    own, j = planes._own(rays, which)
    k_of = own.k[j]
    highest = _per_panel(k_of, own.s[j] * own.rel[own.i[j], 2], len(planes), np.maximum, 0.0)
    # a panel's bracket: its top edge's where it has one (split where the fewest of its
    # hits and crossings over contradict it), else its highest hit's, open below
    bracket: dict[int, tuple[float, float]] = {}
    for k, a, b in _top_edges(grid, rel, which, o, planes, gate_m, local, rays=rays):
        (sa, sb), _, _ = planes.crossing(k, o, rel[[a, b]])
        bracket[k] = (float(planes.top[k] - sb * rel[b, 2]), float(planes.top[k] - sa * rel[a, 2]))
    for hit in np.flatnonzero(np.bincount(k_of, minlength=len(planes))):
        if not math.isfinite(planes.top[hit]):
            continue
        low, high = bracket.get(int(hit), (-math.inf, float(planes.top[hit] - highest[hit])))
        ends.append((high, -1))
        ends.append((low, +1))
    if not ends:
        return None
    ends.sort(key=lambda e: (e[0], -e[1]))  # at a tie, a bracket opens before one closes
    best, count, start, middle, half = 0, 0, -math.inf, 0.0, 0.0
    for i, (z, step) in enumerate(ends):
        count += step
        if step > 0:
            start = z
        elif count + 1 > best:  # the deepest overlap ends here
            best = count + 1
            low = start if math.isfinite(start) else z - 0.5
            middle, half = 0.5 * (low + z), 0.5 * (z - low)
        del i
    return middle, half


def _contiguous(
    which: NDArray[np.intp],
    grid: NDArray[np.float64],
    origin: NDArray[np.float64],
    planes: PanelPlanes,
    spacing_rad: float,
    rays: _Rays | None = None,
) -> NDArray[np.intp]:
    """``which`` with each panel's returns kept to the run of heights (where their rays
    cross its plane) about their median that no gap wider than 1.5 ring spacings at
    their range (their median), plus 5 cm, breaks: a panel is one piece, and the roof,
    the floor or the wall far above or below within the gate of its plane is not of it.
    ``rays``: the crossings seen from ``origin``, where the caller has them. In one
    compiled pass (:func:`_contiguous_reference` in numpy)."""
    out = which.copy()
    if rays is None:
        o = np.asarray(origin, dtype=float).reshape(3)
        rays = planes._rays(grid - o, o, _panel_lists(which, len(planes)))
    rays, j = planes._own(rays, which)
    if j.size == 0:
        return out
    k, i = rays.k[j], rays.i[j]
    h = rays.s[j] * rays.rel[i, 2]
    out[i[contiguous3d(k, i, h, rays.reach, len(planes), spacing_rad)]] = -1
    return out


def _contiguous_reference(
    k: NDArray[np.intp],
    i: NDArray[np.intp],
    h: NDArray[np.float64],
    reach: NDArray[np.float64],
    panels: int,
    spacing_rad: float,
) -> NDArray[np.bool_]:
    """The numpy reference of :func:`mast.core._kernels.contiguous3d` (the returns
    :func:`_contiguous` drops), on the same arrays (``panels`` is the kernel's; here
    the runs of ``k`` say which panels there are)."""
    drop = np.zeros(len(k), dtype=np.bool_)
    if not len(k) or not panels:
        return drop
    # every panel's returns at once: by panel, and by height within it
    by_height = np.lexsort((h, k))
    k, i, h = k[by_height], i[by_height], h[by_height]
    first, count = _runs(k)
    panel = np.repeat(np.arange(len(first)), count)  # each return's panel, 0.. here
    at = np.arange(len(k)) - first[panel]  # its place by height on its panel
    ranges = reach[i]
    ranges = ranges[np.lexsort((ranges, k))]
    gap = 1.5 * spacing_rad * _sorted_medians(ranges, first, count) + 0.05
    middle = np.bincount(panel[h < _sorted_medians(h, first, count)[panel]], minlength=len(first))
    # the gaps (between a return and the next up) wider than that, below the median
    # height and from it up: the run is from the highest below to the lowest above
    wide = np.flatnonzero((np.diff(h) > gap[panel[:-1]]) & (panel[1:] == panel[:-1]))
    below = at[wide] < middle[panel[wide]]
    lo = np.zeros(len(first), dtype=np.intp)
    np.maximum.at(lo, panel[wide[below]], at[wide[below]] + 1)
    hi = count.copy()
    np.minimum.at(hi, panel[wide[~below]], at[wide[~below]] + 1)
    drop[by_height[(at < lo[panel]) | (at >= hi[panel])]] = True
    return drop


def _plate_floors(
    planes: PanelPlanes,
    lows: NDArray[np.float64],
    origin: NDArray[np.float64],
    spacing_rad: float,
) -> NDArray[np.float64]:
    """Each panel's floor from its beacon's other panels, ``lows`` (per panel, the lowest
    crossing of its middle half, NaN where none: :meth:`PanelPlanes.bottoms`): a beacon
    is one plate, its panels' bottoms as far below their tops, so a ring crossing one
    panel below the others' lowest hits by more than :data:`PLATE_RINGS` ring spacings
    (``spacing_rad``) at its range from ``origin``, plus :data:`PLATE_SLACK_M`, would
    have crossed them below theirs too: it is the floor or the wall under the plate (a
    panel seen nearly edge-on, whose returns are the floor at its foot, or a far
    panel's lone floor return that levers the tilt). NaN where no other panel of the
    beacon is seen."""
    depth = planes.top - lows
    _, number = _beacon_groups(planes.beacon)
    middle = planes.start + planes.along * (0.5 * planes.length)[:, None]
    reach = np.hypot(middle[:, 0] - origin[0], middle[:, 1] - origin[1])
    gap = PLATE_RINGS * spacing_rad * reach + PLATE_SLACK_M
    out = np.full(len(planes), np.nan)
    every = np.arange(len(planes))
    for k in every:
        others = depth[(number == number[k]) & np.isfinite(depth) & (every != k)]
        if others.size:
            out[k] = planes.top[k] - float(others.max()) - gap[k]
    return out


def _witnessed(
    which: NDArray[np.intp],
    nearers: Sequence[NDArray[np.intp]],
    grid: NDArray[np.float64],
    lines: NDArray[np.intp],
    planes: PanelPlanes,
    least: int,
    gate_m: float,
    noise_gate_m: float | None = None,
) -> list[NDArray[np.intp]]:
    """For each of ``nearers``, ``which`` (each panel cut clear of its free ends) and
    those returns ``nearer`` (cut nearer them) gives a panel where ``which`` gives none,
    on the lines (rings) whose returns of ``which`` on the same beacon stand off its wall
    (``grid``: the returns' places): a ring that crosses a beacon clear of its free ends
    crosses it there too (its panels share their top and bottom), where the same
    height's wall above or below the beacon would not. A ring stands off the wall by at
    least ``least`` returns each more than ``gate_m`` and
    :data:`~mast.pipeline.adjust3d.ROCK_M` off the chord e1-e4 (the wall a beacon stands
    on, within the gate of its panels' planes where the pose is a little off, is no
    witness), or by :func:`_standing_off` (a shallow beacon's middle panel, within the
    gate of its wall, by the mean of its returns; ``noise_gate_m`` the gate of the range
    noise alone, where ``gate_m`` is widened for the tilt's error)."""
    extras = [np.flatnonzero((nearer >= 0) & (which < 0)) for nearer in nearers]
    on = np.flatnonzero(which >= 0)
    if on.size == 0 or not any(extra.size for extra in extras):
        return [which for _ in nearers]
    ids = {b: i for i, b in enumerate(dict.fromkeys(planes.beacon))}
    beacon = np.array([ids[b] for b in planes.beacon], dtype=np.intp)
    every = np.concatenate([on, *extras])
    low = int(lines[every].min())
    span = int(lines[every].max()) - low + 1
    wall = np.take(planes.wall, which[on], axis=0)
    off = np.abs(np.einsum("ij,ij->i", np.take(grid, on, axis=0)[:, :2], wall[:, :2]) - wall[:, 2])
    far = on[off > gate_m + ROCK_M]
    counts = np.bincount(beacon[which[far]] * span + lines[far] - low, minlength=len(ids) * span)
    # a line with fewer than ``least`` returns on the beacon stands off by no mean
    crossed = np.bincount(beacon[which[on]] * span + lines[on] - low, minlength=len(ids) * span)
    wanted = [beacon[nearer[extra]] for nearer, extra in zip(nearers, extras, strict=True)]
    keys = [w * span + lines[extra] - low for w, extra in zip(wanted, extras, strict=True)]
    short = np.concatenate(
        [
            w[(counts[key] < least) & (crossed[key] >= least)]
            for w, key in zip(wanted, keys, strict=True)
        ]
    )
    for b in np.unique(short):  # those the returns alone do not
        counts[b * span : (b + 1) * span] += least * _standing_off(
            which, grid, lines - low, span, planes, np.flatnonzero(beacon == b), least, gate_m,
            gate_m if noise_gate_m is None else noise_gate_m,
        )  # fmt: skip
    out = []
    for nearer, extra, key in zip(nearers, extras, keys, strict=True):
        ok = extra[counts[key] >= least]
        given = which.copy()
        given[ok] = nearer[ok]
        out.append(given)
    return out


def _standing_off(
    which: NDArray[np.intp],
    grid: NDArray[np.float64],
    line: NDArray[np.intp],
    span: int,
    planes: PanelPlanes,
    panels: NDArray[np.intp],
    least: int,
    gate_m: float,
    noise_gate_m: float,
) -> NDArray[np.bool_]:
    """Per line (``line``, 0 to ``span``), whether its ``n >= least`` returns of ``which``
    on the beacon of ``panels`` (its three, in order) stand, on average, off the wall by
    more than :data:`~mast.pipeline.adjust3d.ROCK_M` plus some gates over the root of n:
    the wall where the same line shows it just past the beacon's free ends
    (:data:`WALL_PAST_M`, the median of at least ``least`` of its returns there), by
    :data:`WITNESS_WALL_GATES` of the range noise's gate (``noise_gate_m``); else the
    chord e1-e4, by :data:`WITNESS_MEAN_GATES` of the gate ``gate_m`` (widened for the
    tilt's error before the first adjustment). A
    pose off across the wall, or tilted, moves the wall the line shows as it moves the
    returns, and does not make the wall stand off itself; the chord it does, and a
    pose's error does not average out over a ring's returns, which a dense lidar's many
    returns would let through were the pose far enough off (on my draws, 0.75 gates
    from the chord gave a fix 16 sigma off in azimuth; 1.5 none). With the median's
    own noise (about 0.7 sigma from three returns) the bar from the wall shown is 2.5
    sigmas of the difference beyond the rock's bulge, for three returns each side. A
    beacon whose middle edges stand out to neither side witnesses nothing."""
    first, last = int(panels[0]), int(panels[-1])
    if planes.front[first] == 0:
        return np.zeros(span, dtype=np.bool_)
    e1 = planes.start[first]
    chord = planes.start[last] + planes.along[last] * planes.length[last] - e1
    length = float(np.hypot(*chord))
    chord = chord / length
    rel = grid[:, :2] - e1
    t = rel @ chord
    d = planes.front[first] * (rel @ planes.wall[first, :2])  # off the chord, to the drift
    valid = (line >= 0) & (line < span)
    mine = valid & (which >= first) & (which <= last)  # a beacon's panels are in order
    past = (t < 0.0) & (t > -WALL_PAST_M) | (t > length) & (t < length + WALL_PAST_M)
    past &= valid & (which < 0) & (np.abs(d) < NEAR_M)
    n = np.bincount(line[mine], minlength=span)
    mean = np.bincount(line[mine], weights=d[mine], minlength=span) / np.maximum(n, 1)
    wall = np.zeros(span)
    gates = np.full(span, WITNESS_MEAN_GATES * gate_m)
    if past.any():
        lp, dp = line[past], d[past]
        order = np.lexsort((dp, lp))
        lp, dp = lp[order], dp[order]
        starts, count = _runs(lp)
        shown = count >= least
        wall[lp[starts[shown]]] = _sorted_medians(dp, starts, count)[shown]
        gates[lp[starts[shown]]] = WITNESS_WALL_GATES * noise_gate_m
    bar = ROCK_M + gates / np.sqrt(np.maximum(n, 1))
    return np.asarray((n >= least) & (mean - wall > bar), dtype=np.bool_)


def _moved(before: Pose3D, after: Pose3D, covariance: NDArray[np.float64]) -> NDArray[np.float64]:
    """How far ``after`` is from ``before`` in each parameter (record order), in sigmas of
    ``covariance``; infinite where its variance is not positive (a direction the panels
    leave unobserved, which the fix is refused for)."""
    variance = np.diag(covariance)
    out = np.full(variance.shape, np.inf)
    known = variance > 0.0
    out[known] = np.abs(after.minus(before))[known] / np.sqrt(variance[known])
    return out


def _gathered(
    local: list[NDArray[np.intp]],
) -> tuple[NDArray[np.intp], list[NDArray[np.intp]]]:
    """The returns any panel looks at, and each panel's as indices into those."""
    if not local:
        return np.zeros(0, dtype=np.intp), []
    stacked = np.concatenate(local)
    looked = np.zeros(int(stacked.max(initial=-1)) + 1, dtype=bool)
    looked[stacked] = True
    place = np.cumsum(looked) - 1
    return np.flatnonzero(looked), [place[idx] for idx in local]


def ring_spacing(
    frame: Frame3D, rings: list[tuple[float, NDArray[np.intp]]] | None = None
) -> float:
    """The angle between a frame's neighbouring rings (radians): the median step between
    the rings' median elevation angles; 2 deg (a VLP-16's) without rings. ``rings``: the
    frame's :func:`~mast.pipeline.plan_view.rings_bottom_up`, where known."""
    angles = [e for e, _ in (rings_bottom_up(frame) if rings is None else rings)]
    if len(angles) < 2:
        return math.radians(2.0)
    return float(np.median(np.diff(angles)))


def _shown_panels(
    which: NDArray[np.intp], lines: NDArray[np.intp], planes: PanelPlanes, cfg: Locator3DConfig
) -> frozenset[int]:
    """The panels with at least ``cfg.min_line_returns`` returns on each of at least two
    lines (rings): two lines at different heights span a panel's plane, as the rule a
    frame is owed a fix by (:class:`mast.sim.lidar3d.OwedRule3D`) counts them."""
    on = which >= 0
    if not on.any():
        return frozenset()
    line = lines[on] - lines[on].min()
    span = int(line.max()) + 1
    counts = np.bincount(which[on] * span + line)  # returns per (panel, line)
    rings = np.bincount(
        np.flatnonzero(counts >= cfg.min_line_returns) // span, minlength=len(planes)
    )
    return frozenset(int(k) for k in np.flatnonzero(rings >= 2))


def _shown(
    which: NDArray[np.intp], lines: NDArray[np.intp], planes: PanelPlanes, cfg: Locator3DConfig
) -> tuple[str, ...]:
    """The beacons showing at least two panels (:func:`_shown_panels`)."""
    shown: dict[str, int] = {}
    for k in _shown_panels(which, lines, planes, cfg):
        shown[planes.beacon[k]] = shown.get(planes.beacon[k], 0) + 1
    return tuple(sorted(b for b, n in shown.items() if n >= 2))


def _checked(
    which: NDArray[np.intp], planes: PanelPlanes, least: int = MIN_PANEL_RETURNS
) -> NDArray[np.intp]:
    """``which`` less the returns of panels with fewer than ``least`` of them
    (:data:`MIN_PANEL_RETURNS` unless given; -1: no panel's)."""
    counts = np.bincount(which[which >= 0], minlength=len(planes))
    kept = np.append(counts >= least, False)  # which == -1 reads the last
    return np.where(kept[which], which, -1)


def _too_few(beacons: tuple[str, ...], cfg: Locator3DConfig) -> str:
    return (
        f"in 3D, {len(beacons)} beacon(s) show two panels each crossed by two rings of "
        f"{cfg.min_line_returns} returns"
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
    planes = planes or PanelPlanes.of(survey)
    spent = {"vertical": 0.0, "plan": 0.0, "adjustment": 0.0}
    rings = rings_bottom_up(frame)  # for the vertical and the rings' spacing
    up = estimate_up(frame, rings=rings)
    spent["vertical"] = time.perf_counter() - t0
    level = level_rotation(up)
    plan_cfg = LocatorConfig(range_sigma_m=cfg.range_sigma_m, survey_sigma_m=cfg.survey_sigma_m)
    lenient_cfg = replace(
        plan_cfg, verification=replace(plan_cfg.verification, wall_behind_m=LENIENT_WALL_M)
    )
    first: Fix3D | None = None  # the first refusal: the frame's reason, where none fixes
    tries = [(level.T @ _pitched(tilt), band) for tilt, band in _tries(cfg)]
    refined = False
    singles = starts = 0
    refused: list[tuple[Scan, Fix, NDArray[np.float64], tuple[float, float]]] = []
    started: list[tuple[Pose2D, tuple[str, ...], NDArray[np.float64], Fix3D]] = []
    spacing = ring_spacing(frame, rings)

    def one_start(
        plan: Fix,
        start: Pose2D,
        seen: tuple[str, ...],
        up: NDArray[np.float64],
        band: tuple[float, float],
    ) -> Fix3D:
        # _from_one_beacon; the 3D stages from a start made already not run again
        made = next((f for s, a, u, f in started if _same_start(start, seen, up, s, a, u)), None)
        if made is None:
            t = time.perf_counter()
            made = _fix3d(frame, planes, plan, up, cfg, one_beacon=start, spacing=spacing)
            spent["adjustment"] += time.perf_counter() - t
            started.append((start, seen, up, made))
        return _from_one_beacon(
            frame, survey, planes, plan, start, seen, up, band, cfg, spent, spacing=spacing,
            first=replace(made, plan=plan, up=up),
        )  # fmt: skip

    while tries:
        # the walls leave the pitch along the drift to the floor, which a grade tilts:
        # the same vertical pitched by a grade's worth, and the beacons at other heights
        tried, band = tries.pop(0)
        t = time.perf_counter()
        view = _plan_view(frame, tried, band, cfg)
        plan = locate(view, survey, config=plan_cfg)
        spent["plan"] += time.perf_counter() - t
        fix: Fix3D | None = None
        own: tuple[Pose3D, float] | None = None  # the pose on the plan's beacons' panels
        looked = False  # whether it was made
        if plan.ok and plan.pose is not None:
            t = time.perf_counter()
            fix = _fix3d(frame, planes, plan, tried, cfg, spacing=spacing)
            spent["adjustment"] += time.perf_counter() - t
            if fix.ok:
                fix = _confirmed(frame, survey, planes, fix, band, cfg, spent, spacing)
            if fix.ok:
                return replace(fix, elapsed_s=time.perf_counter() - t0, stages_s=spent)
        else:
            if first is None:
                first = Fix3D(
                    "no_fix", None, None, plan.reason, f"plan view: {plan.detail}", plan, tried
                )
            alone = plan.verified[0].supported if plan.verified else ()
            if plan.reason == "one_beacon" and len(alone) == 1 and singles < ONE_BEACON_STARTS:
                singles += 1
                fix = one_start(plan, plan.verified[0].pose, alone, tried, band)
                if not fix.ok:
                    # the beacon's own panels, where they put it and its vertical
                    # apart from the smeared plan view and the try's vertical
                    t = time.perf_counter()
                    own, looked = _on_its_panels(frame, planes, plan, tried, cfg, spacing), True
                    spent["vertical"] += time.perf_counter() - t
                    if _apart(own, tried):
                        assert own is not None
                        vertical = np.asarray(own[0].rotation[2], dtype=np.float64)
                        again = one_start(plan, own[0].horizontal, alone, vertical, band)
                        fix = again if again.ok else fix  # the first start's refusal stands
                if fix.ok:
                    return replace(fix, elapsed_s=time.perf_counter() - t0, stages_s=spent)
            if plan.reason == "inconsistent":
                refused.append((view, plan, tried, band))
        if fix is not None and (first is None or first.adjustment is None):
            first = fix  # a 3D refusal says more
        if not refined:
            # a beacon the plan view found, though smeared, holds the vertical itself
            if not looked:
                t = time.perf_counter()
                own = _on_its_panels(frame, planes, plan, tried, cfg, spacing)
                spent["vertical"] += time.perf_counter() - t
            if own is not None and not own[1] > math.radians(REFINE_TILT_SIGMA_DEG):
                refined = True
                better = np.asarray(own[0].rotation[2], dtype=np.float64)
                tries[:0] = [(better, band) for band in cfg.bands_m[:REFINED_BANDS]]
    # where no try fixes: the plan views no pose of which the beams confirmed, located
    # again leniently (LENIENT_WALL_M), start the 3D stages from their 2D fixes
    for view, plan, tried, band in refused:
        if starts >= LENIENT_STARTS:
            break
        t = time.perf_counter()
        lenient = locate_again(plan, view, survey, lenient_cfg)  # its segments kept
        spent["plan"] += time.perf_counter() - t
        if not lenient.ok or lenient.pose is None:
            continue
        starts += 1
        fix = _from_one_beacon(
            frame, survey, planes, plan, lenient.pose, lenient.beacons, tried, band, cfg, spent,
            spacing=spacing,
        )  # fmt: skip
        if fix.ok:
            return replace(fix, elapsed_s=time.perf_counter() - t0, stages_s=spent)
        if first is None or first.adjustment is None:
            first = fix
    assert first is not None
    return replace(first, elapsed_s=time.perf_counter() - t0, stages_s=spent)


def _same_start(
    start: Pose2D,
    seen: tuple[str, ...],
    up: NDArray[np.float64],
    before: Pose2D,
    seen_before: tuple[str, ...],
    up_before: NDArray[np.float64],
) -> bool:
    """Whether a one-beacon start (``start`` on the beacons ``seen``, with the vertical
    ``up``) is one made already: the same beacons, within :data:`SAME_START_M` of its
    position and :data:`SAME_START_DEG` of its azimuth and vertical."""
    turn = abs(math.remainder(start.azimuth - before.azimuth, 2.0 * math.pi))
    limit = math.radians(SAME_START_DEG)
    return (
        seen == seen_before
        and float(np.dot(up, up_before)) >= math.cos(limit)
        and math.hypot(start.easting - before.easting, start.northing - before.northing)
        <= SAME_START_M
        and turn <= limit
    )


def _from_one_beacon(
    frame: Frame3D,
    survey: Survey,
    planes: PanelPlanes,
    plan: Fix,
    start: Pose2D,
    seen: tuple[str, ...],
    up: NDArray[np.float64],
    band: tuple[float, float],
    cfg: Locator3DConfig,
    spent: dict[str, float],
    *,
    spacing: float | None = None,
    first: Fix3D | None = None,
) -> Fix3D:
    """A 3D fix, or the 3D refusal, from a 2D pose ``start`` that the beacons ``seen``
    support and no plan view's 2D fix confirms: the best verified pose of a plan view
    that confirmed one beacon only (``plan``, seen with the vertical ``up`` in
    ``band``), or a 2D fix of the plan view located leniently (``LENIENT_WALL_M``). The
    3D fix must show ``seen`` (two of them where there are more). That pose starts the
    3D stages, which find the other
    beacons' panels where it puts them (a beacon the plan view missed may be below or
    above the band, or smeared by the vertical's error); where they show that beacon
    and a second and pass every 3D test, that pose's vertical and position give the
    plan view again, in the band of those beacons' tops (:data:`ONE_BEACON_BAND_M`) and
    then in ``band``, located by 2D with the pose as its prior (a prior only adds, and
    the 2D beam verification confirms both beacons), and that 2D fix the 3D fix with
    every test, the plan view's agreement included. Where that plan view confirms the
    first beacon alone, near the 3D pose (a thin second beacon, two rings of a few
    returns, smeared out of its band), the one-beacon 3D fix stands on its own tests,
    with its tilt held to :data:`ALONE_TILT_SIGMA_DEG`; where it confirms no beacon
    near the 3D pose, or another, the frame is refused (a 3D fix there was 1.7 deg off
    in pitch and 0.7 deg in azimuth); where it finds a fix, the 3D fix from it must pass
    (taking the one-beacon 3D fix there too gave one 2.1 deg off in pitch that the plan
    view's agreement refuses). ``spent`` is added to; ``spacing`` is the frame's
    :func:`ring_spacing`, where known; ``first``, the 3D stages' result from ``start``
    where the caller has it (:func:`_fix3d` with ``one_beacon``)."""
    if first is None:
        t = time.perf_counter()
        first = _fix3d(frame, planes, plan, up, cfg, one_beacon=start, spacing=spacing)
        spent["adjustment"] += time.perf_counter() - t
    if not first.ok or first.pose is None:
        return first
    missing = [b for b in seen if b not in first.beacons]
    if len(seen) - len(missing) < min(2, len(seen)):
        return replace(
            first,
            status="no_fix",
            pose=None,
            reason="inconsistent",
            detail=f"in 3D, the plan view's beacon {missing[0]} is not among those shown "
            f"({', '.join(first.beacons)})",
        )
    again = _plan_again(frame, survey, first.pose, first.beacons, band, cfg, spent)
    if not again.ok or again.pose is None:
        # the plan view (in the last band tried) confirms the first beacon where the 3D
        # pose puts it, and says nothing of the second (smeared out of its band): the 3D
        # tests stand, the tilt held to ALONE_TILT_SIGMA_DEG
        if _confirms_alone(again, seen, first.adjustment):
            return first
        return replace(
            first,
            status="no_fix",
            pose=None,
            reason=again.reason,
            detail=f"plan view located again near the one-beacon 3D pose: {again.detail}",
        )
    t = time.perf_counter()
    vertical = np.asarray(first.pose.rotation[2], dtype=np.float64)  # grid z, sensor frame
    fix = _fix3d(frame, planes, again, vertical, cfg, spacing=spacing)
    spent["adjustment"] += time.perf_counter() - t
    return _refused_off_plan(fix)


def _plan_again(
    frame: Frame3D,
    survey: Survey,
    pose: Pose3D,
    beacons: tuple[str, ...],
    band: tuple[float, float],
    cfg: Locator3DConfig,
    spent: dict[str, float],
) -> Fix:
    """The plan view levelled by a 3D ``pose`` (its vertical, which a fix knows to a
    fraction of a degree where a try's was degrees off), located by 2D with the pose as
    its prior (:data:`ONE_BEACON_PRIOR`: a prior only adds, and the 2D beam verification
    confirms every beacon it takes), a return on a beacon's own wall no verdict and
    ICP's coarse gates narrow (:data:`AGAIN_GATES_M`). First with each surveyed beacon's
    bearings in the band of its own tops (:func:`_beacon_bands`: on a grade the beacons
    stand at other heights than a band about the sensor, and its beams pass over or
    under them), the try's ``band`` elsewhere; then every bearing in the band of the
    tops of the ``beacons`` the pose shows (:data:`ONE_BEACON_BAND_M`); then in the
    try's band. The first 2D fix, or the last refusal. ``spent`` is added to."""
    t = time.perf_counter()
    vertical = np.asarray(pose.rotation[2], dtype=np.float64)  # grid z, sensor frame
    radius, degrees = ONE_BEACON_PRIOR
    prior = Prior(pose.horizontal, radius, math.radians(degrees))
    plan_cfg = LocatorConfig(
        range_sigma_m=cfg.range_sigma_m, survey_sigma_m=cfg.survey_sigma_m, prior=prior
    )
    plan_cfg = replace(
        plan_cfg,
        verification=replace(
            plan_cfg.verification, coarse_gates_m=AGAIN_GATES_M, wall_behind_m=AGAIN_WALL_M
        ),
    )
    tops = [
        float(np.mean(b.elevations)) - pose.elevation
        for b in survey
        if b.id in beacons and b.elevations is not None and np.isfinite(b.elevations).all()
    ]
    views: list[tuple[tuple[float, float], list[tuple[float, float, float, float]]]] = []
    own = _beacon_bands(survey, pose)
    if own:
        views.append((band, own))
    if tops:
        views.append(((min(tops) - ONE_BEACON_BAND_M[0], max(tops) - ONE_BEACON_BAND_M[1]), []))
    views.append((band, []))
    for in_band, bands in views:
        again = locate(_plan_view(frame, vertical, in_band, cfg, bands), survey, config=plan_cfg)
        if again.ok:
            break
    spent["plan"] += time.perf_counter() - t
    return again


def _plan_view(
    frame: Frame3D,
    up: NDArray[np.float64],
    band: tuple[float, float],
    cfg: Locator3DConfig,
    bands: Sequence[tuple[float, float, float, float]] = (),
) -> Scan:
    """The plan view of ``frame`` levelled by ``up``, in ``band`` (and ``bands``: see
    :func:`~mast.pipeline.plan_view.plan_scan`), at the locator's resolution and range
    noise."""
    return plan_scan(
        frame,
        up=up,
        band=band,
        resolution_deg=cfg.plan_resolution_deg,
        range_sigma_m=cfg.range_sigma_m,
        bands=bands,
    )


def _beacon_bands(survey: Survey, pose: Pose3D) -> list[tuple[float, float, float, float]]:
    """Each surveyed beacon's bearings from the ``pose`` (levelled, counter-clockwise
    from its heading, as :func:`~mast.pipeline.plan_view.plan_scan` takes them), with
    the band of its tops relative to the pose's elevation (:data:`ONE_BEACON_BAND_M`
    below them), the farthest first (a nearer beacon's band is the one its bearings
    keep)."""
    out = []
    for b in sorted(survey, key=lambda b: -float(np.hypot(*(b.centroid - pose.position[:2])))):
        if b.elevations is None or not np.isfinite(b.elevations).all():
            continue
        d = b.edges - pose.position[:2]
        bearing = np.unwrap(pose.azimuth - np.arctan2(d[:, 0], d[:, 1]))
        start = (float(bearing.min()) + math.pi) % (2.0 * math.pi) - math.pi
        tops = b.elevations - pose.elevation
        low, high = (
            float(tops.min()) - ONE_BEACON_BAND_M[0],
            float(tops.max()) - ONE_BEACON_BAND_M[1],
        )
        out.append((start, start + float(np.ptp(bearing)), low, high))
    return out


def _confirmed(
    frame: Frame3D,
    survey: Survey,
    planes: PanelPlanes,
    fix: Fix3D,
    band: tuple[float, float],
    cfg: Locator3DConfig,
    spent: dict[str, float],
    spacing: float,
) -> Fix3D:
    """A 3D ``fix`` that passed every 3D test, as it is where it lies inside its plan
    view's ellipse (:func:`_off_plan`); elsewhere confirmed or refused: a plan view seen
    with a try's vertical, degrees off, is smeared, and its 2D fix may be decimetres off
    where the 3D fix is right to millimetres. The plan view levelled by the fix's own
    pose and located near it (:func:`_plan_again`) starts the 3D stages again, and that
    3D fix must pass every test, its agreement with that plan view included; where that
    plan view confirms one of the fix's beacons alone, the fix stands on its own tests
    with its tilt held to :data:`ALONE_TILT_SIGMA_DEG`, as a one-beacon start's;
    elsewhere the first fix is refused for its plan view's disagreement."""
    why = _off_plan(fix)
    if why is None:
        return fix
    assert fix.pose is not None
    refused = _disagreeing(fix, why)
    again = _plan_again(frame, survey, fix.pose, fix.beacons, band, cfg, spent)
    if not again.ok or again.pose is None:
        # levelled, the plan view confirms one of the fix's beacons alone near it (the
        # other smeared out of its band): the 3D fix stands on its own tests, its tilt
        # held as a one-beacon start's must be (_from_one_beacon)
        return fix if _confirms_alone(again, fix.beacons, fix.adjustment) else refused
    t = time.perf_counter()
    vertical = np.asarray(fix.pose.rotation[2], dtype=np.float64)
    second = _refused_off_plan(_fix3d(frame, planes, again, vertical, cfg, spacing=spacing))
    spent["adjustment"] += time.perf_counter() - t
    return second if second.ok else refused


def _confirms_alone(again: Fix, beacons: tuple[str, ...], adj: Adjustment3D | None) -> bool:
    """Whether a plan view located again near a 3D pose (``again``, no fix) confirms
    one beacon alone, one of ``beacons``, and the adjustment ``adj`` holds the tilt to
    :data:`ALONE_TILT_SIGMA_DEG`: then the 3D fix stands on its own tests."""
    alone = again.verified[0].supported if again.verified else ()
    return (
        again.reason == "one_beacon"
        and len(alone) == 1
        and alone[0] in beacons
        and adj is not None
        and _tilt_sigma(adj) <= math.radians(ALONE_TILT_SIGMA_DEG)
    )


def _off_plan(fix: Fix3D) -> str | None:
    """Where a 3D ``fix``'s position lies outside its plan view's 2D fix's 99.9 %
    ellipse (both covariances, and :data:`PLAN_SLACK_M` for the plan view's smear), why;
    None where it lies inside, or for a fix that has no plan view's 2D fix (a one-beacon
    start's)."""
    plan = fix.plan
    if fix.pose is None or fix.adjustment is None or plan.pose is None:
        return None
    if plan.adjustment is None:
        return None
    pose = fix.pose
    d = np.array([pose.easting - plan.pose.easting, pose.northing - plan.pose.northing])
    c = (
        plan.adjustment.covariance[:2, :2]
        + fix.adjustment.covariance[:2, :2]
        + PLAN_SLACK_M**2 * np.eye(2)
    )
    if float(d @ np.linalg.solve(c, d)) <= 13.8:  # chi-square, 2 dof, 0.1 %
        return None
    return f"the 3D position is {1e3 * float(np.hypot(*d)):.1f} mm from the plan view's fix"


def _refused_off_plan(fix: Fix3D) -> Fix3D:
    """``fix`` refused (``inconsistent``) where it lies outside its plan view's ellipse
    (:func:`_off_plan`); as it is elsewhere."""
    why = _off_plan(fix) if fix.ok else None
    return fix if why is None else _disagreeing(fix, why)


def _disagreeing(fix: Fix3D, why: str) -> Fix3D:
    """``fix`` refused (``inconsistent``) for its plan view's disagreement ``why``."""
    return replace(
        fix, status="no_fix", pose=None, reason="inconsistent", detail=why, beacons=(), panels={}
    )


def _levelled(pose2d: Pose2D, up: NDArray[np.float64]) -> Pose3D:
    """The 2D pose with the levelling's tilt (``R = Rz(yaw) L``, ``L = Ry(pitch) Rx(roll)``
    levelling by the vertical ``up``), at elevation 0."""
    R0 = rotation_rpy(0.0, 0.0, yaw_of_azimuth(pose2d.azimuth)) @ level_rotation(up)
    return Pose3D.from_rotation(R0, (pose2d.easting, pose2d.northing, 0.0))


def _lines(frame: Frame3D, near: NDArray[np.intp]) -> NDArray[np.intp]:
    """The line each of the returns ``near`` draws across a panel: its ring, or without
    rings, its 10 cm height."""
    if frame.ring is not None:
        return np.asarray(frame.ring[near], dtype=np.intp)
    return np.asarray(np.floor(frame.points[near, 2] / 0.1), dtype=np.intp)


def _pitched(tilt_deg: float) -> NDArray[np.float64]:
    """The levelled vertical pitched by ``tilt_deg`` about the sensor's y axis."""
    a = math.radians(tilt_deg)
    return np.array([math.sin(a), 0.0, math.cos(a)])


def _tries(cfg: Locator3DConfig) -> list[tuple[float, tuple[float, float]]]:
    """The (pitch about the walls' vertical, band) the plan view is tried at, in turn:
    every band level, then the first two pitched by a grade's worth either way."""
    out = [(0.0, band) for band in cfg.bands_m]
    for tilt in PITCH_TRIES_DEG[1:]:
        out += [(tilt, band) for band in cfg.bands_m[:2]]
    return out


def _on_its_panels(
    frame: Frame3D,
    planes: PanelPlanes,
    plan: Fix,
    up: NDArray[np.float64],
    cfg: Locator3DConfig,
    spacing: float | None = None,
) -> tuple[Pose3D, float] | None:
    """The pose on the panels of the beacons the plan view (seen with the vertical
    ``up``) found, and the sigma its tilt is held to, radians: its fix's beacons, or
    where it has none, those its best verified pose confirms (one beacon is enough: its
    panels are vertical planes in different directions, which hold the vertical that
    the walls of a drift leave free along it; and a look-alike's panels, taken for
    another beacon, are as vertical). The tilt is grown out from the sensor's height as
    in the 3D fix, with the elevation held (the pose's elevation is not a fix's). None
    without such a beacon, or where fewer than two of its panels are shown."""
    if plan.ok and plan.pose is not None:
        pose2d, beacons = plan.pose, plan.beacons
    elif plan.verified and plan.verified[0].supported:
        pose2d, beacons = plan.verified[0].pose, plan.verified[0].supported
    else:
        return None
    pose = _levelled(pose2d, up)
    grid = pose.sensor_to_grid(frame.points)
    empty = np.zeros(0, dtype=np.intp)
    local = [
        idx if planes.beacon[k] in beacons else empty
        for k, idx in enumerate(planes.local(grid, NEAR_M))
    ]
    near, local = _gathered(local)
    if near.size == 0:
        return None
    pts = frame.points[near]
    lines = _lines(frame, near)
    sig_r = cfg.range_sigma_m
    gate = 4.0 * sig_r
    spacing = ring_spacing(frame) if spacing is None else spacing
    prior = (pose.pitch, pose.roll, math.radians(TILT_PRIOR_DEG))
    adj: Adjustment3D | None = None
    try:
        for reach in REFINE_REACH_M:
            grid = pose.sensor_to_grid(pts)
            slack = 0.0 if adj is not None else reach * TILT_SLACK
            which = planes.assign(
                grid, pose.position, gate + slack, clear_m=gate, reach_m=reach, local=local
            )
            which = _contiguous(which, grid, pose.position, planes, spacing)
            if len(_shown_panels(which, lines, planes, cfg)) < 2:
                continue
            adj = _adjust_tilt(pts, which, planes, pose, prior, sig_r, cfg.survey_sigma_m, gate)
            pose = adj.pose
    except np.linalg.LinAlgError:
        return None
    if adj is None:
        return None
    return pose, _tilt_sigma(adj)


def _apart(own: tuple[Pose3D, float] | None, up: NDArray[np.float64]) -> bool:
    """Whether the pose on a beacon's own panels (:func:`_on_its_panels`) holds its tilt
    to :data:`OWN_TILT_SIGMA_DEG` and puts the vertical more than :data:`OWN_APART_DEG`
    from the try's ``up``: then it starts the 3D stages again."""
    if own is None or own[1] > math.radians(OWN_TILT_SIGMA_DEG):
        return False
    cosine = float(np.asarray(own[0].rotation[2]) @ up)
    return cosine < math.cos(math.radians(OWN_APART_DEG))


def _on_one_beacon(
    pts: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    pose: Pose3D,
    prior: tuple[float, float, float],
    range_sigma_m: float,
    survey_sigma_m: float,
    gate_m: float,
) -> Pose3D:
    """``pose`` moved (its elevation held) onto the returns ``which`` of a growth stage's
    cut that shows one beacon only, before any shows two (that beacon's panels and any
    other's single one), where they hold the tilt to :data:`REFINE_TILT_SIGMA_DEG`: a
    beacon's panels are vertical planes in different directions, which hold the tilt
    the plan view's vertical may be degrees off in, so the next stage reaches further
    from it (a second beacon's end panel a tilt's error had moved out of the gate, say).
    The fix still needs two beacons; as it stands, ``pose``. On my eleven draws the
    other beacons' single panels in the adjustment gave 640 owed fixes and 5 frames
    beyond 3.5 sigma, the one beacon's panels alone 628 and 9 (the cut's other returns
    hold the position and azimuth the one beacon leaves loose)."""
    try:
        one = _adjust_tilt(pts, which, planes, pose, prior, range_sigma_m, survey_sigma_m, gate_m)
    except np.linalg.LinAlgError:
        return pose
    if _tilt_sigma(one) > math.radians(REFINE_TILT_SIGMA_DEG):
        return pose
    return one.pose  # the elevation, unobserved, is the start's


def _adjust_tilt(
    pts: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    pose: Pose3D,
    prior: tuple[float, float, float],
    range_sigma_m: float,
    survey_sigma_m: float,
    gate_m: float,
) -> Adjustment3D:
    """The adjustment of a growth stage: the elevation held, the walls' vertical
    ``prior`` an observation of the tilt, no snooping (the next stage's cut sorts the
    returns again)."""
    return adjust_pose(
        pts, which, planes, pose, range_sigma_m=range_sigma_m, survey_sigma_m=survey_sigma_m,
        gate_m=gate_m, elevation=False, tilt_prior=prior, snooping_rounds=0,
    )  # fmt: skip


def _tilt_sigma(adj: Adjustment3D) -> float:
    """The larger of an adjustment's roll and pitch sigmas, radians."""
    return math.sqrt(max(adj.covariance[3, 3], adj.covariance[4, 4]))


def _fix3d(
    frame: Frame3D,
    planes: PanelPlanes,
    plan: Fix,
    up: NDArray[np.float64],
    cfg: Locator3DConfig,
    *,
    one_beacon: Pose2D | None = None,
    spacing: float | None = None,
) -> Fix3D:
    """The six parameters from the plan view's 2D fix ``plan``, seen with the vertical
    ``up`` (steps 4 to 7 of the module); or, where the plan view confirmed one beacon
    only, from its best verified pose ``one_beacon`` (no 2D fix for the 3D position to agree
    with: the 3D fix must show a second beacon where that pose puts it)."""

    def refused(reason: str | None, detail: str, adj: Adjustment3D | None = None) -> Fix3D:
        return Fix3D("no_fix", None, adj, reason, detail, plan, up)

    pose2d = one_beacon or plan.pose
    assert pose2d is not None
    flat = _levelled(pose2d, up)

    # only the returns near a panel in plan can be a panel's or pass over its top; each
    # panel looks at its own (local), and its floor at those a little further about
    grid = flat.sensor_to_grid(frame.points)
    wide, square = planes._local(grid, FLOOR_RADIUS_M)  # the nearer, a part of them
    near, local = _gathered([idx[d <= NEAR_M**2] for idx, d in zip(wide, square, strict=True)])
    about, around = _gathered(wide)
    pts, grid = np.take(frame.points, near, axis=0), np.take(grid, near, axis=0)

    looked = np.take(frame.points, about, axis=0)
    around_flat = np.concatenate(around) if around else np.zeros(0, dtype=np.intp)
    around_first = np.cumsum([0] + [len(idx) for idx in around], dtype=np.intp)

    past = planes.depth + FLOOR_PAST_M  # how far out a floor about each panel reaches

    def floors(pose: Pose3D) -> NDArray[np.float64]:
        # planes.floors on the pose's grid, of which they need the heights and the
        # lowest returns' places in plan: compiled (PanelPlanes._floors in numpy)
        lows = floors3d(
            looked, pose.rotation, pose.position, around_flat, around_first, planes.wall,
            planes.front, past,
        )  # fmt: skip
        return lows + FLOOR_CLEAR_M

    lines = _lines(frame, near)
    sig_r, sig_s = cfg.range_sigma_m, cfg.survey_sigma_m
    gate = 4.0 * sig_r
    # The wall at a free end is within a gate of the panel's plane for gate / sine:
    # there a return is ambiguous (PanelPlanes.assign), whichever plane it is nearer
    # (the rock is rough, and a beacon is mounted on it, not on the chord e1-e4).
    clear = gate
    step = ring_spacing(frame) if spacing is None else spacing

    def cut(
        rays: _Rays,
        grid: NDArray[np.float64],
        gate_m: float,
        *,
        top_margin_m: float,
        bottoms: NDArray[np.float64],
        reach_m: float = math.inf,
        ceilings: NDArray[np.float64] | None = None,
        boxes: NDArray[np.float64] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        # each panel cut clear of a free end, and nearer it on the lines its beacon
        # shows clear of it (_witnessed), each panel's a contiguous piece; and with them
        # the returns that show a panel, cut nearer again on those lines (SHOWN_CLEAR)
        which, nearer, shows = planes._assigns(
            rays, grid, gate_m, (clear, WITNESSED_CLEAR * clear, SHOWN_CLEAR * clear),
            top_margin_m=top_margin_m, bottoms=bottoms, reach_m=reach_m, ceilings=ceilings,
            boxes=boxes,
        )  # fmt: skip
        kept, shown = _witnessed(
            which, (nearer, shows), grid, lines, planes, cfg.min_line_returns, gate_m, gate
        )
        contiguous = _contiguous(kept, grid, rays.origin, planes, step, rays)
        return contiguous, np.where(kept >= 0, contiguous, shown)

    # The elevation first, from hits in a gate tight but for the plan view's tilt error.
    loose = 2.5 * sig_r + START_SLACK_M
    local = planes._paired(local)  # each pose's crossings computed once (_rays)
    pairs = local.pairs
    rays = planes._rays(grid - flat.position, flat.position, pairs)
    tight = planes._assign(rays, grid, loose, clear_m=clear)

    def below(
        rays: _Rays, grid: NDArray[np.float64], which: NDArray[np.intp], pose: Pose3D
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        # once adjusted, each panel's floor: the floor about it, the bottom its returns
        # ``which`` show less the gate, and its plate's (_plate_floors); and the heights
        # it is seen at (the boxes of PanelPlanes._assigns)
        lows, seen = planes._lows(rays, grid, which, 0.0)
        plate = _plate_floors(planes, lows, pose.position, step)
        return np.fmax(np.fmax(floors(pose), lows - gate), plate), seen

    start = _start_elevation(
        grid, flat.position, tight, planes, 2.0 * loose, step, local, rays, least=START_HITS
    )
    if start is None:
        return refused(
            "one_beacon", f"no surveyed panel with {START_HITS} returns in the start's gate in 3D"
        )
    z0, spread = start
    pose = Pose3D(flat.easting, flat.northing, z0, flat.azimuth, flat.pitch, flat.roll)
    adj: Adjustment3D | None = None
    which = shown = tight
    prior = (flat.pitch, flat.roll, math.radians(TILT_PRIOR_DEG))
    most: tuple[str, ...] = ()  # the most beacons a growth stage's cut showed
    try:
        # Grown from the sensor's height out: near it a tilt's error moves a return
        # little, so the tight gate holds from the start; each stage's tilt lets the
        # next reach further, and its elevation cuts each panel at its top.
        for reach in REACH_M:
            grid = pose.sensor_to_grid(pts)
            rays = planes._rays(grid - pose.position, pose.position, pairs)
            margin = spread + 2.0 * sig_r + START_SLACK_M  # the start's elevation
            slack = 0.0 if adj is not None else min(reach, 2.0) * TILT_SLACK
            roof = boxes = None
            if adj is None:  # each panel cut at its highest tight hit, too
                floor = floors(pose)
                roof = planes._ceilings(rays, tight, 2.0 * sig_r)
            else:
                floor, boxes = below(rays, grid, which, pose)
            trial, shows = cut(
                rays, grid, gate + slack, top_margin_m=margin, bottoms=floor, reach_m=reach,
                ceilings=roof, boxes=boxes,
            )  # fmt: skip
            showing = _shown(shows, lines, planes, cfg)
            most = max(most, showing, key=len)
            if len(showing) < 2:
                if adj is None and showing:
                    pose = _on_one_beacon(pts, trial, planes, pose, prior, sig_r, sig_s, gate)
                continue  # the last assignment that showed two beacons stands
            which, shown = trial, shows
            adj = _adjust_tilt(pts, which, planes, pose, prior, sig_r, sig_s, gate)
            pose = adj.pose
        if adj is None:  # no stage's cut showed two beacons
            return refused("one_beacon", _too_few(most, cfg))
        # the elevation last, from the top edges of panels the tilt now holds; the
        # panels cut again at the adjusted tops, until the assignment holds
        held = False  # the assignment the last adjustment ran on holds at its pose
        thinned = False
        moved = np.zeros(6)  # the last adjustment's move from the one before, in sigmas
        for _ in range(ELEVATION_ROUNDS):
            before, bracketed = pose, adj is not None and adj.top_edges > 0
            adj = adjust_pose(
                pts, _checked(which, planes), planes, pose, range_sigma_m=sig_r,
                survey_sigma_m=sig_s, gate_m=gate, lines=lines, tilt_prior=prior, local=local,
                top_panels=_shown_panels(which, lines, planes, cfg),
            )  # fmt: skip
            pose = adj.pose
            moved = _moved(before, pose, adj.covariance)
            if not (bracketed and adj.top_edges):
                moved[2] = 0.0  # an elevation not observed in both is not compared
            if not adj.top_edges:
                held = True
                break
            grid = pose.sensor_to_grid(pts)
            rays = planes._rays(grid - pose.position, pose.position, pairs)
            margin = max(2.0 * math.sqrt(adj.covariance[2, 2]), 2.0 * sig_r)
            floor, boxes = below(rays, grid, which, pose)
            again, shows = cut(rays, grid, gate, top_margin_m=margin, bottoms=floor, boxes=boxes)
            if np.array_equal(again, which):
                held, shown = True, shows
                break
            if len(_shown(shows, lines, planes, cfg)) < 2:
                thinned = True  # the adjusted pose's own cut shows fewer than two beacons:
                break  # the last adjustment's own assignment is tested below
            which, shown = again, shows
    except np.linalg.LinAlgError:  # the panels seen leave a direction unobserved
        return refused("degenerate_geometry", "the panels seen do not hold the pose in 3D")
    variances = np.diag(adj.covariance)
    if not np.all(np.isfinite(variances) & (variances > 0.0)):
        # normal equations so near singular that their inverse is not a covariance: a
        # direction the panels leave all but unobserved (no fix with a NaN sigma)
        return refused(
            "degenerate_geometry",
            "the panels seen do not hold the pose in 3D (the adjustment's variances are "
            "not all positive)",
            adj,
        )
    # the returns adjusted on: the panels hit thickly enough, less those snooping left out
    checked = _checked(which, planes)
    used = checked if adj.used is None else adj.used
    # the panels too thinly hit to be adjusted on are still beams' ends for the misfits
    kept = which  # the cut adjusted on
    which = np.where((checked < 0) & (which >= 0), which, used)
    # those only showing a panel (nearer a free end) still show it, where the snooping
    # left the panel a return adjusted on
    left = np.append(np.bincount(used[used >= 0], minlength=len(planes)) > 0, False)
    only = np.where((kept < 0) & left[shown], shown, -1)
    beacons = _shown(np.where(which >= 0, which, only), lines, planes, cfg)
    if len(beacons) < 2:
        return refused("one_beacon", _too_few(beacons, cfg), adj)
    if not held and float(np.max(moved)) > SETTLE_SIGMAS:
        why = (
            "cut again at the adjusted tops, the panels show fewer than two beacons"
            if thinned
            else f"the panels' returns, cut again at the adjusted tops, still change after "
            f"{ELEVATION_ROUNDS} adjustments"
        )
        return refused(
            "inconsistent",
            f"{why}, and the last adjustment moved the pose by "
            f"{float(np.max(moved)):.1f} sigma: the elevation and the tilt do not settle",
            adj,
        )
    if not adj.settled:
        return refused(
            "inconsistent",
            "the top edges' rays settle on no choice, nor alternate between two that each "
            "bracket the elevation and pass their w-test: the elevation and the tilt they "
            "lever are not known",
            adj,
        )
    if adj.test_p < cfg.reject_alpha:
        return refused(
            "rejected",
            f"reference variance {adj.reference_variance:.2f} on {adj.dof} degrees of "
            "freedom: the returns do not fit the surveyed panels",
            adj,
        )
    # a tilt the panels hold too loosely is no survey's; an elevation only wide brackets
    # hold is reported not observed (the record says so) rather than to decimetres
    tilt = _tilt_sigma(adj)
    if tilt > math.radians(MAX_TILT_SIGMA_DEG):
        return refused(
            "degenerate_geometry",
            f"the panels seen hold the tilt to {math.degrees(tilt):.2f} deg only",
            adj,
        )
    above = _above_tops(pts, used, planes, adj, gate, sig_s)
    if above is not None:
        k, height, sigma = above
        return refused(
            "inconsistent",
            f"returns taken for panel {planes.beacon[k]}/P{planes.panel[k]} lie "
            f"{100.0 * height:.0f} cm above its surveyed top ({height / sigma:.0f} sigma)",
            adj,
        )
    if adj.top_edges and math.sqrt(adj.covariance[2, 2]) > MAX_ELEVATION_SIGMA_M:
        cov = adj.covariance.copy()
        cov[2, :], cov[:, 2] = 0.0, 0.0
        cov[2, 2] = UNBRACKETED
        adj = replace(adj, covariance=cov, top_edges=0)
    # every beam crossing a panel where the pose puts it hits it
    grid = adj.pose.sensor_to_grid(pts)
    hits = np.bincount(which[which >= 0], minlength=len(planes))
    misfit = planes.misfits(
        grid, adj.pose.position, which, gate, local, _under_tops(planes, adj), lines
    )
    seen = np.flatnonzero(misfit > np.maximum(MISFIT_LEAST, MISFIT_SHARE * hits))
    if seen.size:
        k = int(seen[np.argmax(misfit[seen])])
        return refused(
            "inconsistent",
            f"{misfit[k]} beams crossing panel {planes.beacon[k]}/P{planes.panel[k]} where the "
            f"pose puts it do not fit it ({hits[k]} do)",
            adj,
        )
    # the 3D position must be where the plan view put it: the caller's test
    # (_off_plan), where the fix started from a plan view's 2D fix
    panels = _panels_of(used, planes)
    return Fix3D("fix", adj.pose, adj, None, "", plan, up, beacons, panels)


def _under_tops(planes: PanelPlanes, adj: Adjustment3D) -> NDArray[np.float64] | None:
    """Per panel, the height below which the beam test looks at the rays crossing it:
    its surveyed top, where a top edge bracketed the elevation (None elsewhere: the
    tops' heights are then not known). The test's window otherwise ends at the panel's
    highest hit, and a hit above the top is no panel's (a shallow beacon's wall within
    the gate of its plane, or a ring the pose puts a few millimetres over the top): the
    rays of the same ring that passed over the panel were counted against right fixes
    (13 to 27 of them, refusing fixes right to millimetres and 0.1 deg). Below the top
    the window stays: a margin of three sigmas of the top's height there let an
    elevation 12 cm off at 9 sigma through, whose only witness was six rays within 4 cm
    under a panel's top."""
    return planes.top if adj.top_edges else None


def _above_tops(
    pts: NDArray[np.float64],
    used: NDArray[np.intp],
    planes: PanelPlanes,
    adj: Adjustment3D,
    gate_m: float,
    survey_sigma_m: float,
) -> tuple[int, float, float] | None:
    """The panel whose returns (``pts``, sensor frame, taken for panels by ``used``) lie
    highest above its surveyed top at the adjusted pose, in sigmas of their heights (the
    covariance's elevation, roll and pitch, and the survey's ``survey_sigma_m``), where
    one lies above it by more than ``gate_m`` and :data:`TOP_SIGMAS` of them: (panel,
    its height above the top, its sigma); None where none does, or where no top edge
    bracketed the elevation (then the heights are not known)."""
    on = np.flatnonzero(used >= 0)
    if adj.top_edges == 0 or on.size == 0:
        return None
    pose = adj.pose
    p = np.take(pts, on, axis=0)
    k = used[on]
    above = p @ pose.rotation[2] + pose.elevation - planes.top[k]
    _, d_roll, d_pitch, _ = _rotation_derivatives(pose)
    J = np.zeros((on.size, 3))  # the height by elevation, roll and pitch
    J[:, 0], J[:, 1], J[:, 2] = 1.0, p @ d_roll[2], p @ d_pitch[2]
    C = adj.covariance[2:5, 2:5]
    sigma = np.sqrt(np.einsum("ij,jk,ik->i", J, C, J) + survey_sigma_m**2)
    excess = (above - gate_m) / sigma
    worst = int(np.argmax(excess))
    if excess[worst] <= TOP_SIGMAS:
        return None
    return int(k[worst]), float(above[worst]), float(sigma[worst])


def _panels_of(which: NDArray[np.intp], planes: PanelPlanes) -> dict[str, tuple[int, ...]]:
    """Beacon id → the panels (1..3) ``which`` gives a return."""
    out: dict[str, list[int]] = {}
    for k in np.unique(which[which >= 0]).tolist():
        out.setdefault(planes.beacon[k], []).append(planes.panel[k])
    return {b: tuple(sorted(p)) for b, p in out.items()}
