"""Tracking with a prior: find the pose near a prior without identifying panels.

With a prior pose (the previous scan's fix, or ``--near``), identification is
not needed: every surveyed panel is where the prior says, to within the
prior's radius and azimuth tolerance. A narrow window (a constant-velocity
prediction's) is first searched by ICP from its centre alone. The window's grid is
searched (a correlative scan match against a likelihood field of the surveyed panels) by
branch and bound: each rotation's translations form a quadtree whose blocks are
bounded from a max pyramid of the field, so the poses come out best first, as
scoring them all would rank them, without scoring most of them. The best poses
are handed on as hypotheses to be refined by ICP and verified like any other. A
wrong prior finds no pose that the beams confirm and gives no fix, never one that
follows the prior.

References
----------
E. Olson, "Real-time correlative scan matching", ICRA 2009.
W. Hess, D. Kohler, H. Rapp and D. Andor, "Real-time loop closure in 2D LIDAR
SLAM", ICRA 2016 (the branch and bound).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from mast.core._kernels import field_pyramid, field_sliding, window_picks
from mast.core.frames import yaw_of_azimuth
from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D
from mast.pipeline.alignment import Similarity
from mast.pipeline.hypotheses import Hypothesis

__all__ = [
    "Prior",
    "TrackingConfig",
    "VehicleLimits",
    "centre_hypotheses",
    "prior_hypotheses",
    "window_may_fix",
]


@dataclass(frozen=True, slots=True)
class VehicleLimits:
    """What a vehicle underground can do between two scans, and what the scanner adds:
    the one definition that every tracking window (a scan sequence's, a run's) and the
    run odometry's plausibility checks are built from.

    Attributes
    ----------
    max_speed_mps, max_turn_rad_s : float
        The fastest a vehicle drives and turns.
    max_accel_mps2, max_yaw_accel_rad_s2 : float
        The most it speeds up, brakes or changes its turn rate: how far it can stray
        from a constant-velocity prediction.
    jolt_m, jolt_rad : float
        The scanner's own jolts on its mount and the stamps' jitter, beyond the
        vehicle's motion: the least a window around a prediction is widened by.
    """

    max_speed_mps: float = 6.0
    max_turn_rad_s: float = math.radians(90.0)
    max_accel_mps2: float = 3.0
    max_yaw_accel_rad_s2: float = 2.0
    jolt_m: float = 0.05
    jolt_rad: float = math.radians(1.0)


@dataclass(frozen=True, slots=True)
class Prior:
    """Where the scanner is believed to be.

    Attributes
    ----------
    pose : Pose2D
    radius_m : float
        The true position lies within this distance of ``pose``.
    azimuth_tolerance_rad : float or None
        The true azimuth lies within this of ``pose.azimuth``; None: unknown.
    """

    pose: Pose2D
    radius_m: float
    azimuth_tolerance_rad: float | None = None

    def admits(self, pose: Pose2D, margin_m: float = 0.0, margin_rad: float = 0.0) -> bool:
        """Whether ``pose`` lies inside the prior's window, widened by the margins.

        The margins are the estimate's own uncertainty: a true pose on the
        window's rim is estimated a few millimetres either side of it.
        """
        d = math.hypot(pose.easting - self.pose.easting, pose.northing - self.pose.northing)
        if d > self.radius_m + margin_m:
            return False
        if self.azimuth_tolerance_rad is None:
            return True
        da = abs(math.remainder(pose.azimuth - self.pose.azimuth, 2 * math.pi))
        return da <= self.azimuth_tolerance_rad + margin_rad


@dataclass(frozen=True, slots=True)
class TrackingConfig:
    """The grid search of a prior's window.

    Attributes
    ----------
    max_radius_m : float
        Widest position window searched on a grid; wider priors go through
        identification instead.
    max_azimuth_tolerance_rad : float
        Widest azimuth window searched on a grid.
    step_m : float
        Grid step in position, and the largest step a return may move per
        azimuth step: a whole number of ``field_resolution_m`` (the search moves
        returns by whole cells).
    field_resolution_m : float
        Cell size of the panels' likelihood field.
    max_points : int
        Returns used in the search at most (evenly thinned beyond).
    candidates : int
        Distinct best poses handed on as hypotheses.
    distinct_m : float
        Two grid poses are distinct hypotheses when one moves the returns by
        at least this much from the other (translation, or rotation times the
        returns' median range): closer ones fall in the same ICP basin.
    other_basins_m : float
        The second batch of hypotheses, searched when the first gives no fix
        (and judged together with the poses the first verified): up to
        ``candidates`` more grid poses, each moving the returns by at least
        this much from every pose before it. In a wide window the best
        grid poses can all lie in one wrong basin (rock parallel to a middle
        panel scores like the panel: shared independent scenes noisy 0096 and
        0146, hostile 0046, the true pose ranked 8th to 14th, every pose above
        it within 0.4 m and 3.5 degrees of one wrong one).
    direct_radius_m, direct_tolerance_rad : float
        A window no wider than these (a constant-velocity prediction's, a few
        centimetres and about a degree) is first searched by ICP from its centre
        alone (:func:`centre_hypotheses`), the grid only when that gives no fix:
        the window bounds where the vehicle can be, but the prediction itself is
        usually a few millimetres off, well inside ICP's reach.
    """

    max_radius_m: float = 2.0
    max_azimuth_tolerance_rad: float = math.radians(15.0)
    step_m: float = 0.04
    field_resolution_m: float = 0.02
    max_points: int = 600
    candidates: int = 6
    distinct_m: float = 0.1
    other_basins_m: float = 0.4
    direct_radius_m: float = 0.1
    direct_tolerance_rad: float = math.radians(1.5)

    def __post_init__(self) -> None:
        cells = self.step_m / self.field_resolution_m if self.field_resolution_m > 0 else 0.0
        if not (self.step_m > 0 and cells >= 1 and abs(cells - round(cells)) <= 1e-9 * cells):
            raise ValueError(
                f"step_m ({self.step_m}) must be a whole number of field_resolution_m "
                f"({self.field_resolution_m}), at least one"
            )


def _likelihood_field(
    panels: PanelSet,
    subset: NDArray[np.intp],
    lo: NDArray[np.float64],
    shape: tuple[int, int],
    res: float,
    sigma: float,
) -> NDArray[np.float64]:
    """``exp(-d^2 / 2 sigma^2)`` of the distance to the nearest surveyed panel, on a grid."""
    occ = np.ones(shape, dtype=bool)
    for k in subset:
        n = max(2, math.ceil(panels.length[k] / (0.5 * res)) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        p = panels.a[k] + s * (panels.b[k] - panels.a[k])
        ij = np.floor((p - lo) / res).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[1])
        occ[ij[ok, 0], ij[ok, 1]] = False
    dist = ndimage.distance_transform_edt(occ) * res
    return np.asarray(np.exp(-0.5 * (dist / sigma) ** 2))


# Beyond this many sigmas from every panel the field is taken as zero (e^-18).
_FIELD_CUTOFF_SIGMAS = 6.0

#: Blocks of the window's grid up to 2^SLIDING_LEVELS translations a side are bounded from
#: the field's sliding maxima (one read a return), wider ones from its pyramid: nearly
#: all of a wide search's blocks are the small ones.
SLIDING_LEVELS = 4
#: ... and no wider than this many cells: each map holds its tiles widened by its width
#: (about 1 MB a field at the default 2 cells a step).
SLIDING_MAX_CELLS = 64


@dataclass(frozen=True, slots=True)
class _TiledField:
    """The likelihood field kept only where it is not zero: a tile about each beacon.

    A field over the whole box of the panels in reach is mostly zeros and,
    with beacons tens of metres apart, millions of cells (about 100 MB and
    100 ms a scan). Each beacon's tile covers its panels' box widened by the
    cutoff, and holds the field of every panel that reaches into it, so the
    largest value over the tiles that contain a point is the field there.

    Attributes
    ----------
    lo : ndarray, shape (k, 2)
        Lower corner of each tile, metres.
    shape : ndarray of int, shape (k, 2)
        Cells of each tile along E and N.
    offset : ndarray of int, shape (k,)
        Where each tile starts in ``values``.
    values : ndarray, shape (cells + 1,)
        The tiles' cells, row by row, one after the other; the last cell is a
        zero that every lookup outside a tile reads.
    res : float
        Cell size, metres.
    """

    lo: NDArray[np.float64]
    shape: NDArray[np.intp]
    offset: NDArray[np.intp]
    values: NDArray[np.float64]
    res: float
    pyramid: NDArray[np.float64]
    """Row ``h``: each cell's largest value over the ``2^h`` cells from it along both
    axes, within its tile (row 0 is ``values``): the window search's bounds."""
    _sliding: dict[int, tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]] = field(
        default_factory=dict
    )

    def sliding(
        self, step_cells: int
    ) -> tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp]]:
        """The sliding maxima (:func:`mast.core._kernels.field_sliding`) over the cells
        that blocks of 2, 4, ... ``2^SLIDING_LEVELS`` translations ``step_cells`` apart
        span, those no wider than ``SLIDING_MAX_CELLS``: ``(values, starts, widths)``,
        made once per field and step, on the first window searched with them."""
        made = self._sliding.get(step_cells)
        if made is None:
            spans = [(2**lw - 1) * step_cells + 1 for lw in range(1, SLIDING_LEVELS + 1)]
            widths = np.array([w for w in spans if w <= SLIDING_MAX_CELLS], dtype=np.intp)
            made = (*field_sliding(self.shape, self.offset, self.pyramid, widths), widths)
            self._sliding[step_cells] = made
        return made

    @classmethod
    def build(
        cls, panels: PanelSet, subset: NDArray[np.intp], res: float, sigma: float
    ) -> _TiledField:
        margin = _FIELD_CUTOFF_SIGMAS * sigma + 2.0 * res
        ends = np.concatenate([panels.a[subset], panels.b[subset]])
        owner = np.concatenate([panels.beacon[subset], panels.beacon[subset]])
        a, b = panels.a[subset], panels.b[subset]
        low, high = np.minimum(a, b), np.maximum(a, b)
        lows, shapes, offsets, chunks = [], [], [], []
        total = 0
        for beacon in np.unique(owner):
            box = ends[owner == beacon]
            lo = box.min(axis=0) - margin
            hi = box.max(axis=0) + margin
            shape = (int((hi[0] - lo[0]) / res) + 1, int((hi[1] - lo[1]) / res) + 1)
            # Every panel reaching into the tile is drawn in it, not only this beacon's.
            touch = np.all((low <= hi) & (high >= lo), axis=1)
            field = _likelihood_field(panels, subset[touch], lo, shape, res, sigma)
            lows.append(lo)
            shapes.append(shape)
            offsets.append(total)
            chunks.append(field.ravel())
            total += field.size
        chunks.append(np.zeros(1))
        shape_arr = np.array(shapes, dtype=np.intp).reshape(-1, 2)
        offset_arr = np.array(offsets, dtype=np.intp)
        values = np.concatenate(chunks)
        # Enough levels that the top one holds each tile's largest value from any cell.
        levels = max(0, math.ceil(math.log2(max(1, int(shape_arr.max(initial=1))))))
        return cls(
            np.array(lows, dtype=float).reshape(-1, 2),
            shape_arr,
            offset_arr,
            values,
            res,
            field_pyramid(shape_arr, offset_arr, values, levels),
        )

    @property
    def outside(self) -> int:
        """Index of the zero cell read outside every tile."""
        return self.values.size - 1

    def reaching(
        self, centres: NDArray[np.float64], reach: NDArray[np.float64]
    ) -> NDArray[np.intp]:
        """Per point, the tiles its box ``centre +- reach`` meets; -1 pads, shape (n, slots)."""
        lo, hi = self.lo, self.lo + self.shape * self.res
        meets = np.all(
            (centres[:, None, :] + reach[:, None, None] >= lo[None, :, :])
            & (centres[:, None, :] - reach[:, None, None] <= hi[None, :, :]),
            axis=2,
        )
        count = meets.sum(axis=1)
        slots = max(1, int(count.max(initial=0)))
        # Each point's tiles in increasing order (a stable sort puts the met ones first).
        order = np.argsort(~meets, axis=1, kind="stable")[:, :slots]
        out: NDArray[np.intp] = np.where(
            np.arange(slots)[None, :] < count[:, None], order, -1
        ).astype(np.intp)
        return out

    def scores(
        self,
        cells: NDArray[np.float64],
        tiles: NDArray[np.intp],
        shift: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """The field summed over the points, for each translation: shape (m,).

        ``cells`` and ``shift`` as in :meth:`lookup`; ``tiles`` as from
        :meth:`reaching` (each point takes the largest value over its tiles).
        Compiled (:func:`mast.core._kernels.window_scores`): no
        (translations x points) arrays. :meth:`lookup` is the reference.
        """
        from mast.core._kernels import window_scores

        return window_scores(
            np.ascontiguousarray(cells, dtype=float),
            np.ascontiguousarray(tiles, dtype=np.intp),
            self.lo / self.res,
            self.shape,
            self.offset,
            self.values,
            np.ascontiguousarray(shift, dtype=float),
        )

    def lookup(
        self,
        cells: NDArray[np.float64],
        tile: NDArray[np.intp],
        shift: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        """Field values at points moved by translations, one tile per point.

        ``cells`` are the points in cells of the grid anchored at the origin
        (``position / res``), shape (n, 2); ``tile`` the tile each point is
        looked up in (-1: none), shape (n,); ``shift`` the translations in
        cells, shape (m, 2). Returns shape (m, n). The reference of
        :meth:`scores` (the tests compare the two).
        """
        has = tile >= 0
        t = np.where(has, tile, 0)
        local = cells - self.lo[t] / self.res
        gi = np.floor(local[None, :, 0] + shift[:, 0, None]).astype(np.intp)
        gj = np.floor(local[None, :, 1] + shift[:, 1, None]).astype(np.intp)
        w, h = self.shape[t, 0], self.shape[t, 1]
        inside = has & (gi >= 0) & (gi < w) & (gj >= 0) & (gj < h)
        flat = np.where(inside, self.offset[t] + gi * h + gj, self.outside)
        return np.asarray(self.values[flat])


def window_may_fix(
    points_scanner: NDArray[np.float64],
    panels: PanelSet,
    prior: Prior,
    range_max_m: float,
    *,
    gate_m: float,
    margin_m: float,
    margin_rad: float,
    min_beacons: int,
    min_panel_points: int,
) -> bool:
    """Whether any pose in the prior's window (widened by the margins) could put
    returns on the panels of ``min_beacons`` beacons, two panels and ``2 *
    min_panel_points`` returns each, within ``gate_m``: what a verified pose needs
    before the beams are even checked (``verification._may_support``). False proves
    the window's search can give no fix, so it need not run (on a drive, most scans
    near the last fix see one beacon or none).

    A return at range ``r`` moves at most ``radius + margin_m + r * (tolerance +
    margin_rad)`` over the window (the chord of the turn is shorter than its arc);
    a return is counted for every panel it could reach, so the count never falls
    short of what a pose in the window associates.
    """
    tol = prior.azimuth_tolerance_rad
    if tol is None:
        return True  # an azimuth window without bounds: nothing to bound with
    if points_scanner.shape[0] == 0:
        return False
    move = prior.radius_m + margin_m
    near = panels.near(prior.pose.position, range_max_m + 1.0 + move)
    if near.size == 0:
        return False
    r = np.hypot(points_scanner[:, 0], points_scanner[:, 1])
    # Returns (at the prior) within reach of each panel segment.
    per_panel, _, _ = panels.reach_tallies(
        prior.pose.scanner_to_mine(points_scanner), r, move, tol + margin_rad, gate_m, subset=near
    )
    owner = panels.beacon[near]
    enough = 0
    for b in np.unique(owner[per_panel > 0]):
        mine = per_panel[owner == b]
        if np.count_nonzero(mine) >= 2 and int(mine.sum()) >= 2 * min_panel_points:
            enough += 1
            if enough >= min_beacons:
                return True
    return False


#: Tiled fields kept (least recently used dropped first): consecutive scans of a run
#: mostly see the same panels, and a field costs milliseconds to build.
_FIELD_CACHE_SIZE = 16
_FIELD_CACHE: OrderedDict[tuple[int, bytes, float, float], tuple[PanelSet, _TiledField]] = (
    OrderedDict()
)


def _tiled_field(
    panels: PanelSet, subset: NDArray[np.intp], res: float, sigma: float
) -> _TiledField:
    """:meth:`_TiledField.build`, once per panel set, subset of it, cell size and sigma."""
    key = (id(panels), np.ascontiguousarray(subset, dtype=np.intp).tobytes(), res, sigma)
    hit = _FIELD_CACHE.get(key)
    if hit is not None and hit[0] is panels:
        _FIELD_CACHE.move_to_end(key)
        return hit[1]
    field = _TiledField.build(panels, subset, res, sigma)
    while len(_FIELD_CACHE) >= _FIELD_CACHE_SIZE:
        _FIELD_CACHE.popitem(last=False)
    _FIELD_CACHE[key] = (panels, field)
    return field


def _window_returns(
    points_scanner: NDArray[np.float64],
    panels: PanelSet,
    prior: Prior,
    near: NDArray[np.intp],
    tol: float,
    config: TrackingConfig,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The returns that, anywhere in the window, could lie on a panel in reach (evenly
    thinned to ``max_points``), and their ranges."""
    pts = points_scanner
    r = np.hypot(pts[:, 0], pts[:, 1])
    at_prior = prior.pose.scanner_to_mine(pts)
    slack = prior.radius_m + r * math.sin(tol) + 0.1
    _, dist = panels.associate(at_prior, np.inf, subset=near)
    mid = 0.5 * (panels.a[near] + panels.b[near])
    d_mid = np.min(
        np.hypot(at_prior[:, None, 0] - mid[None, :, 0], at_prior[:, None, 1] - mid[None, :, 1])
        - 0.5 * panels.length[near][None, :],
        axis=1,
    )
    cand = np.minimum(np.abs(dist), d_mid) <= slack
    pts, r = pts[cand], r[cand]
    if pts.shape[0] > config.max_points:
        keep = np.linspace(0, pts.shape[0] - 1, config.max_points).round().astype(int)
        pts, r = pts[keep], r[keep]
    return pts, r


def _window_grid(
    radius_m: float, tol: float, step: float, r: NDArray[np.float64]
) -> tuple[NDArray[np.float64], float, int]:
    """The window's translations (a disc of ``step`` grid points), the rotation step
    that moves no return more than ``step``, and the rotation steps either way."""
    offs, inside = _window_places(radius_m, step)
    tx, ty = np.meshgrid(offs, offs, indexing="ij")
    shifts = np.column_stack([tx[inside], ty[inside]])
    return (shifts, *_rotation_steps(tol, step, r))


def _rotation_steps(tol: float, step: float, r: NDArray[np.float64]) -> tuple[float, int]:
    """The rotation step that moves no return (ranges ``r``) more than ``step``, and the
    steps either way that cover ``tol``."""
    d_rot = step / max(float(r.max()), step)
    return d_rot, math.ceil(tol / d_rot)


def _window_places(radius_m: float, step: float) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The grid's offsets along each axis and which places (a, b), at ``(offs[a],
    offs[b])``, lie in the disc; :func:`_window_grid` numbers them in row order."""
    n_t = math.ceil(radius_m / step)
    offs = np.arange(-n_t, n_t + 1, dtype=np.float64) * step
    tx, ty = np.meshgrid(offs, offs, indexing="ij")
    inside: NDArray[np.bool_] = np.hypot(tx, ty) <= radius_m + 1e-9
    return offs, inside


def _whole_cells(offs: NDArray[np.float64], res: float) -> NDArray[np.int64]:
    """The grid's offsets in whole cells of the field (``step_m`` is a whole number of
    ``field_resolution_m``, :class:`TrackingConfig`)."""
    return np.rint(offs / res).astype(np.int64)


def centre_hypotheses(prior: Prior, config: TrackingConfig = TrackingConfig()) -> list[Hypothesis]:
    """The prior's own pose as the one hypothesis, when its window is narrow enough to
    be searched by ICP from there first (``direct_radius_m`` and
    ``direct_tolerance_rad``); none otherwise."""
    tol = prior.azimuth_tolerance_rad
    if tol is None or prior.radius_m > config.direct_radius_m or tol > config.direct_tolerance_rad:
        return []
    pose = prior.pose
    rot = math.remainder(yaw_of_azimuth(pose.azimuth), math.tau)
    return [Hypothesis((), Similarity(1.0, rot, pose.position, 0.0), 0.0, "prior")]


def prior_hypotheses(
    points_scanner: NDArray[np.float64],
    panels: PanelSet,
    prior: Prior,
    range_max_m: float,
    config: TrackingConfig = TrackingConfig(),
) -> list[list[Hypothesis]]:
    """The best poses in the prior's window by a grid search, as batches of hypotheses.

    Every candidate pose is scored by the likelihood field of the surveyed
    panels at the returns; rotations step so that no return moves more than
    ``step_m``, translations step by ``step_m``. The first batch holds the
    best ``candidates`` poses at least ``distinct_m`` apart; the second, to be
    searched only when the first gives no fix, the best ones at least
    ``other_basins_m`` from every pose before them (empty when there are none).
    A pose that puts no return near a panel (scores zero) is never taken. The poses
    come from a branch and bound over each rotation's grid
    (:func:`mast.core._kernels.window_picks`), in exactly the order of scoring them
    all, without scoring most of them. Returns no batch when the window is too wide
    to search this way, no panel is in reach or no pose scores.
    """
    tol = prior.azimuth_tolerance_rad
    if (
        prior.radius_m > config.max_radius_m
        or tol is None
        or tol > config.max_azimuth_tolerance_rad
    ):
        return []
    near = panels.near(prior.pose.position, range_max_m + prior.radius_m)
    if near.size == 0 or points_scanner.shape[0] == 0:
        return []
    pts, r = _window_returns(points_scanner, panels, prior, near, tol, config)
    if pts.shape[0] < 6:
        return []
    step = config.step_m
    res = config.field_resolution_m
    field = _tiled_field(panels, near, res, step)
    sliding, sliding_starts, sliding_widths = field.sliding(round(step / res))
    d_rot, n_r = _rotation_steps(tol, step, r)
    offs, inside = _window_places(prior.radius_m, step)
    rot0 = yaw_of_azimuth(prior.pose.azimuth)
    # The tiles each return can reach anywhere in the window.
    at_prior = prior.pose.scanner_to_mine(pts)
    tiles = field.reaching(at_prior, prior.radius_m + r * math.sin(tol) + step + res)
    rots = np.array([rot0 + k * d_rot for k in range(-n_r, n_r + 1)])
    taken, first, _ = window_picks(
        np.ascontiguousarray(pts, dtype=float),
        rots,
        prior.pose.position,
        res,
        np.ascontiguousarray(tiles, dtype=np.intp),
        field.lo / res,
        field.shape,
        field.offset,
        field.pyramid,
        _whole_cells(offs, res),
        offs,
        inside,
        float(np.median(r)),
        config.candidates,
        config.distinct_m,
        config.other_basins_m,
        sliding,
        sliding_starts,
        sliding_widths,
    )
    out: list[Hypothesis] = []
    for k, a, b, score in taken.tolist():
        t = prior.pose.position + np.array([offs[int(a)], offs[int(b)]])
        sim = Similarity(1.0, math.remainder(float(rots[int(k)]), 2 * math.pi), t, 0.0)
        out.append(Hypothesis((), sim, -score, "prior"))
    if not out:
        return []
    return [out[:first], out[first:]] if len(out) > first else [out]
