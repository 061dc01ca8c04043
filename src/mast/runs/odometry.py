"""Scan-to-keyframe odometry: how the scanner moved between two scans, with its covariance.

The keyframe's returns, each with the normal of the wall around it (principal
component analysis over a window of about 0.3 m of consecutive returns, as
the locator's segmentation fits its lines), are the target; the current
scan's returns are fitted to them by point-to-plane ICP (Low 2004, the
linearisation the locator's alignment uses), associating each return with
its nearest keyframe return (found by bearing: `mast.core.neighbours.BearingIndex`,
the same answers as a k-d tree). Fitting to the returns, not to long
straight segments, keeps the rock's roughness: that is what tells motion
along a drift.

The covariance is that of the linearised fit, ``s^2 (J^T J)^-1``, with
``s^2`` the residual variance (never below twice the range variance: both
scans are noisy) and inflated by the returns per independent piece of
evidence, as the locator tempers its beam likelihoods. Along a smooth,
straight drift the fit cannot see motion along the walls; the covariance
then says so (almost no information along the drift) instead of inventing a
step.

ICP only finds a motion inside its basin, a few tenths of a metre and a few
degrees from its start. When the start is further off (a turn at a door, a
log recorded a metre and 30° between scans), :func:`recover_motion` searches
the whole window the vehicle could have reached: a correlative scan match
(Olson, "Real-time correlative scan matching", ICRA 2009) of the returns
against a coarse likelihood field of the keyframe's, then ICP from the
guess, from the best distinct poses and from poses along the best result's
weakest direction (along a drift the coarse scores are flat). Where several
of them fit the keyframe about as well (a corridor seen the same a metre
on), the motion's covariance takes in their spread: the run is told the
match is ambiguous rather than given one of them as certain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from mast.core._kernels import odometry_fit
from mast.core.linalg import pose_step
from mast.core.neighbours import BearingIndex, PointGrid
from mast.core.scan import Scan

__all__ = ["Keyframe", "Motion", "OdometryConfig", "keyframe", "recover_motion", "scan_to_scan"]


@dataclass(frozen=True, slots=True)
class OdometryConfig:
    """How scans are matched to a keyframe.

    Attributes
    ----------
    gates_m : tuple of float
        Association gates of the ICP stages, decreasing, metres.
    normal_span_m : float
        Length of wall over which a return's normal is fitted.
    max_planarity : float
        A return whose window is less straight than this (smallest over
        largest principal variance) has no normal and is not a target.
    min_matches : int
        Returns that must be matched for a motion to count.
    max_rms_m : float
        A fit whose residuals are larger than this did not find the walls again.
    tempering : float
        Returns per independent piece of evidence: the covariance of the fit
        is multiplied by it.
    min_sigma_m, min_sigma_rad : float
        Floors on the motion's standard deviations (time sync, vehicle
        vibration, the walls' unmodelled roughness).
    max_iterations : int
        Per gate.
    search_res_m : float
        Cell of the coarse likelihood field a wide window is searched on
        (:func:`recover_motion`); also its Gaussian's sigma and the largest
        step a return moves between two searched rotations.
    search_reach_m : float
        Returns this close to either scanner are used in the wide search
        (far returns move most with rotation and add cells, not evidence).
    search_points : int
        Returns used in the wide search at most (evenly thinned beyond).
    search_starts : int
        Distinct best poses of the wide search that ICP is started from.
    alike_matches : float
        Another ICP result whose fit (matched returns, each weighted by its
        residual) is at least this share of the best one's, and that is a
        distinct motion, fits about as well: its offset joins the motion's
        covariance.
    wide_sigma_per_m, wide_sigma_rad_per_m, wide_sigma_per_rad : float
        What a motion searched over a wide window (scans a metre or more apart)
        is known to at best, beyond its fit: position 5 % of the step, azimuth
        0.5° a metre and 2 % of the turn. Such scans share less, and what they
        share (door frames, furniture, a drift's few features) is matched with
        errors the fit does not see: on the real CARMEN logs (1 m and up to 33°
        a step) the fit's own sigmas are 3-5 times smaller than the steps'
        errors against the corrected poses (median 2-3 cm, 0.1-0.2°; part of that
        is the corrected poses' own few centimetres). With these terms 86 % and
        99 % of the scans placed by odometry on those two logs lie inside their
        95 % ellipse (``mast bench reallog``).
    """

    gates_m: tuple[float, ...] = (0.3, 0.12, 0.06)
    normal_span_m: float = 0.3
    max_planarity: float = 0.1
    min_matches: int = 40
    max_rms_m: float = 0.05
    tempering: float = 2.0
    min_sigma_m: float = 0.002
    min_sigma_rad: float = math.radians(0.02)
    max_iterations: int = 30
    search_res_m: float = 0.2
    search_reach_m: float = 15.0
    search_points: int = 300
    search_starts: int = 5
    alike_matches: float = 0.9
    wide_sigma_per_m: float = 0.05
    wide_sigma_rad_per_m: float = math.radians(0.5)
    wide_sigma_per_rad: float = 0.02


@dataclass(frozen=True, slots=True)
class _Field:
    """``exp(-d^2 / 2 res^2)`` of the distance ``d`` to the nearest return, on a grid of
    cell ``res`` (in the layout :func:`mast.core._kernels.window_scores` reads: one tile,
    then a zero read outside it)."""

    lo: NDArray[np.float64]
    shape: NDArray[np.intp]
    values: NDArray[np.float64]
    res: float

    @classmethod
    def of(cls, points: NDArray[np.float64], res: float) -> _Field:
        from scipy import ndimage

        if points.shape[0] == 0:
            return cls(np.zeros(2), np.ones(2, dtype=np.intp), np.zeros(2), res)
        lo = points.min(axis=0) - 4.0 * res
        hi = points.max(axis=0) + 4.0 * res
        shape = np.floor((hi - lo) / res).astype(np.intp) + 1
        occ = np.ones((int(shape[0]), int(shape[1])), dtype=bool)
        ij = np.floor((points - lo) / res).astype(np.intp)
        occ[ij[:, 0], ij[:, 1]] = False
        dist = ndimage.distance_transform_edt(occ) * res
        values = np.concatenate([np.exp(-0.5 * (dist / res) ** 2).ravel(), [0.0]])
        return cls(lo, shape, values, res)

    def scores(
        self, points: NDArray[np.float64], shifts: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """The field summed over ``points`` moved by each of ``shifts`` (metres)."""
        from mast.core._kernels import window_scores

        return window_scores(
            np.ascontiguousarray(points / self.res),
            np.zeros((points.shape[0], 1), dtype=np.intp),
            (self.lo / self.res)[None, :],
            self.shape[None, :],
            np.zeros(1, dtype=np.intp),
            self.values,
            np.ascontiguousarray(shifts / self.res),
        )


@dataclass(frozen=True, slots=True)
class Keyframe:
    """A scan as a target for the next scans: its returns with their wall normals."""

    index: BearingIndex
    """The returns, by bearing from the scanner for nearest-neighbour queries."""
    normals: NDArray[np.float64]
    _fields: dict[float, _Field] = field(default_factory=dict, compare=False, repr=False)
    """Coarse likelihood fields of the returns, by cell size, built when first searched."""
    _grids: dict[float, PointGrid] = field(default_factory=dict, compare=False, repr=False)

    def grid(self, cell: float) -> PointGrid:
        """The returns binned in cells of ``cell`` (the numpy reference's search)."""
        if cell not in self._grids:
            self._grids[cell] = PointGrid.build(self.points, cell)
        return self._grids[cell]

    def coarse_field(self, res: float, reach_m: float) -> _Field:
        """The likelihood field of the returns within ``reach_m`` of the keyframe's scanner."""
        if res not in self._fields:
            pts = self.points
            self._fields[res] = _Field.of(pts[np.hypot(pts[:, 0], pts[:, 1]) <= reach_m], res)
        return self._fields[res]

    @property
    def points(self) -> NDArray[np.float64]:
        return self.index.points

    def __len__(self) -> int:
        return len(self.index)


def keyframe(scan: Scan, config: OdometryConfig | None = None) -> Keyframe:
    """The scan's returns that lie on a locally straight wall, with the wall's normal."""
    cfg = config or OdometryConfig()
    _, pts = scan.points()
    n = pts.shape[0]
    if n < 3:
        return Keyframe(BearingIndex.build(np.zeros((0, 2))), np.zeros((0, 2)))
    # Runs of consecutive returns without a jump; a window never crosses one.
    step = np.hypot(*np.diff(pts, axis=0).T)
    r = np.hypot(pts[:, 0], pts[:, 1])
    spacing = np.maximum(r[1:] * max(scan.angle_increment, 1e-4), 0.01)
    cut = step > 5 * spacing + 0.05
    run = np.concatenate([[0], np.cumsum(cut)])
    first = np.searchsorted(run, run, side="left")
    last = np.searchsorted(run, run, side="right") - 1
    half = np.clip(
        np.round(cfg.normal_span_m / 2 / (r * max(scan.angle_increment, 1e-4))), 2, 50
    ).astype(np.intp)
    idx = np.arange(n)
    lo = np.maximum(idx - half, first)
    hi = np.minimum(idx + half, last)
    # Window moments by cumulative sums (centred on the scan's mean for precision).
    c = pts - pts.mean(axis=0)
    cols = np.column_stack(
        [np.ones(n), c[:, 0], c[:, 1], c[:, 0] ** 2, c[:, 0] * c[:, 1], c[:, 1] ** 2]
    )
    cs = np.vstack([np.zeros(6), np.cumsum(cols, axis=0)])
    m = cs[hi + 1] - cs[lo]
    k = m[:, 0]
    mx, my = m[:, 1] / k, m[:, 2] / k
    sxx = m[:, 3] / k - mx**2
    sxy = m[:, 4] / k - mx * my
    syy = m[:, 5] / k - my**2
    # Principal direction angle; the normal is perpendicular to it.
    ang = 0.5 * np.arctan2(2 * sxy, sxx - syy)
    tr = sxx + syy
    det = np.sqrt(np.maximum((sxx - syy) ** 2 / 4 + sxy**2, 0.0))
    lmax, lmin = tr / 2 + det, tr / 2 - det
    good = (k >= 5) & (lmin <= cfg.max_planarity * np.maximum(lmax, 1e-12))
    nrm = np.column_stack([-np.sin(ang), np.cos(ang)])
    return Keyframe(BearingIndex.build(pts[good]), nrm[good])


@dataclass(frozen=True, slots=True)
class Motion:
    """The pose of a scan in the frame of the scan before it.

    Attributes
    ----------
    dx, dy : float
        Translation in the previous scanner frame (x forward, y left), metres.
    dtheta : float
        Rotation counter-clockwise, radians.
    covariance : ndarray, shape (3, 3)
        Of (dx, dy, dtheta), in the previous scanner frame.
    matches : int
        Returns matched to the previous scan's lines.
    rms_m : float
        RMS point-to-line residual.
    """

    dx: float
    dy: float
    dtheta: float
    covariance: NDArray[np.float64]
    matches: int
    rms_m: float


def scan_to_scan(
    key: Keyframe,
    scan: Scan,
    *,
    guess: tuple[float, float, float] = (0.0, 0.0, 0.0),
    range_sigma_m: float,
    config: OdometryConfig | None = None,
) -> Motion | None:
    """How the scanner moved from the keyframe ``key`` to ``scan``.

    Parameters
    ----------
    key : Keyframe
        The keyframe's returns and normals (:func:`keyframe`).
    scan : Scan
    guess : (dx, dy, dtheta)
        Starting motion (a constant-velocity prediction).
    range_sigma_m : float
        A-priori range precision of either scan.

    Returns
    -------
    Motion, or None when the returns do not find the keyframe's walls (too
    few matches, or residuals too large).
    """
    cfg = config or OdometryConfig()
    _, pts = scan.points()
    if len(key) < cfg.min_matches or pts.shape[0] < cfg.min_matches:
        return None
    dx, dy, dtheta, n, sse, jtj = odometry_fit(
        np.ascontiguousarray(pts, dtype=float),
        *(float(g) for g in guess),
        key.index.points,
        key.index.bearing,
        key.index.order,
        np.ascontiguousarray(key.normals, dtype=float),
        np.asarray(cfg.gates_m, dtype=float),
        cfg.max_iterations,
        cfg.min_matches,
    )
    if n < cfg.min_matches or n == 0:
        return None
    rms = math.sqrt(sse / n)
    if rms > cfg.max_rms_m:
        return None
    s2 = max(sse / max(n - 3, 1), 2 * range_sigma_m**2)
    return _motion(dx, dy, dtheta, jtj / (s2 * cfg.tempering), n, rms, cfg)


def _motion(
    dx: float,
    dy: float,
    dtheta: float,
    info: NDArray[np.float64],
    matches: int,
    rms: float,
    cfg: OdometryConfig,
) -> Motion:
    """The motion of a fit with information ``info`` and its covariance, floored."""
    floor = np.diag([cfg.min_sigma_m**2, cfg.min_sigma_m**2, cfg.min_sigma_rad**2])
    # A direction the walls do not constrain gets (almost) no information: its variance
    # is large but finite, so that a pose graph can still be solved around it.
    w, v = np.linalg.eigh(info)
    w = np.maximum(w, 1e-6)
    cov = (v / w) @ v.T + floor
    wrapped = (float(dtheta) + math.pi) % (2 * math.pi) - math.pi
    return Motion(float(dx), float(dy), wrapped, (cov + cov.T) / 2, matches, rms)


def _scan_to_scan_reference(
    key: Keyframe,
    scan: Scan,
    *,
    guess: tuple[float, float, float] = (0.0, 0.0, 0.0),
    range_sigma_m: float,
    config: OdometryConfig | None = None,
) -> Motion | None:
    """:func:`scan_to_scan` in numpy, the compiled kernel's reference."""
    cfg = config or OdometryConfig()
    _, pts = scan.points()
    if len(key) < cfg.min_matches or pts.shape[0] < cfg.min_matches:
        return None
    grid = key.grid(max(cfg.gates_m))
    x = np.array(guess, dtype=float)
    ok = np.zeros(0, dtype=bool)
    for stage, gate in enumerate(cfg.gates_m):
        coarse = stage < len(cfg.gates_m) - 1
        seen: list[bytes] = []
        for _ in range(cfg.max_iterations):
            c, s_ = math.cos(x[2]), math.sin(x[2])
            m = pts @ np.array([[c, s_], [-s_, c]]) + x[:2]
            dist, j = grid.query(m, gate)
            ok = np.isfinite(dist)
            # Matches met before end the gate: the last iteration's in a coarse gate (the
            # returns have found their walls), an earlier one's in any (a cycle, or the
            # same matches for three iterations: two steps on them, converged).
            matched = np.where(ok, j, -1).astype(np.intp).tobytes()
            if matched in seen[: len(seen) - 1] or (coarse and seen and seen[-1] == matched):
                break
            seen.append(matched)
            if np.count_nonzero(ok) < cfg.min_matches:
                return None
            nrm = key.normals[j[ok]]
            res = np.einsum("ij,ij->i", m[ok] - key.points[j[ok]], nrm)
            rel = m[ok] - x[:2]
            jac = np.column_stack([nrm, nrm[:, 1] * rel[:, 0] - nrm[:, 0] * rel[:, 1]])
            step = pose_step(jac, -res)
            x = x + step
            if math.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
                break
    c, s_ = math.cos(x[2]), math.sin(x[2])
    m = pts @ np.array([[c, s_], [-s_, c]]) + x[:2]
    dist, j = grid.query(m, cfg.gates_m[-1])
    ok = np.isfinite(dist)
    n = int(np.count_nonzero(ok))
    if n < cfg.min_matches:
        return None
    nrm = key.normals[j[ok]]
    res = np.einsum("ij,ij->i", m[ok] - key.points[j[ok]], nrm)
    rms = float(np.sqrt(np.mean(res**2)))
    if rms > cfg.max_rms_m:
        return None
    rel = m[ok] - x[:2]
    jac = np.column_stack([nrm, nrm[:, 1] * rel[:, 0] - nrm[:, 0] * rel[:, 1]])
    s2 = max(float(res @ res) / max(n - 3, 1), 2 * range_sigma_m**2)
    return _motion(x[0], x[1], x[2], jac.T @ jac / (s2 * cfg.tempering), n, rms, cfg)


def recover_motion(
    key: Keyframe,
    scan: Scan,
    *,
    guess: tuple[float, float, float],
    radius_m: float,
    yaw_rad: float,
    range_sigma_m: float,
    config: OdometryConfig | None = None,
) -> Motion | None:
    """The motion from ``key`` to ``scan`` anywhere within ``radius_m`` and ``yaw_rad`` of
    ``guess``: a correlative search of the window, then ICP from the guess, the search's
    best distinct poses and poses along the best result's weakest direction.

    The motion returned is the ICP result that fits best (matched returns, each
    weighted by a Gaussian of its residual); every other distinct result that
    fits nearly as well (``alike_matches``) adds its offset to the covariance (a
    mixture's covariance), so an ambiguous match is reported as ambiguous. None
    when no start converges onto the keyframe's walls.
    """
    cfg = config or OdometryConfig()
    _, pts = scan.points()
    if len(key) < cfg.min_matches or pts.shape[0] < cfg.min_matches:
        return None
    res = cfg.search_res_m
    r = np.hypot(pts[:, 0], pts[:, 1])
    pts, r = pts[r <= cfg.search_reach_m], r[r <= cfg.search_reach_m]
    if pts.shape[0] < cfg.min_matches:
        return None
    if pts.shape[0] > cfg.search_points:
        keep = np.linspace(0, pts.shape[0] - 1, cfg.search_points).round().astype(np.intp)
        pts, r = pts[keep], r[keep]
    grid = key.coarse_field(res, cfg.search_reach_m + radius_m)
    n_t = max(1, math.ceil(radius_m / res))
    offs = np.arange(-n_t, n_t + 1) * res
    tx, ty = np.meshgrid(offs, offs, indexing="ij")
    inside = np.hypot(tx, ty) <= radius_m + 1e-9
    shifts = np.column_stack([tx[inside], ty[inside]]) + np.array(guess[:2])
    d_rot = res / max(float(r.max()), res)
    n_r = math.ceil(yaw_rad / d_rot)
    best: list[tuple[float, float, float, float]] = []
    keep_best = 4 * cfg.search_starts
    for k in range(-n_r, n_r + 1):
        th = guess[2] + k * d_rot
        c, s_ = math.cos(th), math.sin(th)
        moved = pts @ np.array([[c, s_], [-s_, c]])
        total = grid.scores(moved, shifts)
        top = np.argpartition(total, -keep_best)[-keep_best:] if total.size > keep_best else None
        for t in np.arange(total.size) if top is None else top:
            best.append((float(total[t]), float(shifts[t, 0]), float(shifts[t, 1]), th))
    best.sort(reverse=True)
    reach = float(np.median(r))
    starts: list[tuple[float, float, float]] = []
    for _, x, y, th in best:
        if len(starts) == cfg.search_starts:
            break
        if all(
            math.hypot(x - sx, y - sy) >= 2 * res or abs(th - st) * reach >= 2 * res
            for sx, sy, st in starts
        ):
            starts.append((x, y, th))
    found: list[Motion] = []
    # The guess itself too: along a drift whose rock is finer than the search's cells,
    # the coarse scores are flat and only the guess starts ICP near the motion.
    for start in [guess, *starts]:
        m = scan_to_scan(key, scan, guess=start, range_sigma_m=range_sigma_m, config=cfg)
        if m is not None:
            found.append(m)
    if not found:
        return None
    # Along a drift the coarse scores are flat and the best distinct starts may all lie
    # in one stretch of it: ICP is also started every basin's width along the best
    # motion's weakest direction, across the window, so that another place that fits
    # as well is found (and declared) rather than missed.
    best_m = max(found, key=lambda m: (m.matches, -m.rms_m))
    _, vecs = np.linalg.eigh(best_m.covariance[:2, :2])
    along = vecs[:, -1]
    spacing = 1.5 * max(cfg.gates_m)
    for k in range(1, min(math.ceil(radius_m / spacing), cfg.search_starts * 2) + 1):
        for sign in (-1.0, 1.0):
            x, y = np.array([best_m.dx, best_m.dy]) + sign * k * spacing * along
            start = (float(x), float(y), best_m.dtheta)
            m = scan_to_scan(key, scan, guess=start, range_sigma_m=range_sigma_m, config=cfg)
            if m is not None:
                found.append(m)
    # How well each fits: its matched returns, each weighted by a Gaussian of its
    # residual whose spread is that of the result matching the most returns. Along a
    # drift, ICP from a wrong start slides to another place where as many returns lie
    # on the walls, only less closely; in clutter, a wrong start finds fewer returns
    # that lie a little closer (a wall or two, without the furniture).
    widest = max(found, key=lambda m: m.matches)
    s2 = 2.0 * max(widest.rms_m**2, 2.0 * range_sigma_m**2)

    def fit(m: Motion) -> float:
        return m.matches * math.exp(-(m.rms_m**2) / s2)

    found.sort(key=fit, reverse=True)
    top_m = found[0]
    alike = [
        m
        for m in found[1:]
        if fit(m) >= cfg.alike_matches * fit(top_m)
        and (
            math.hypot(m.dx - top_m.dx, m.dy - top_m.dy) > 2 * cfg.gates_m[-1]
            or abs(math.remainder(m.dtheta - top_m.dtheta, 2 * math.pi)) * reach
            > 2 * cfg.gates_m[-1]
        )
    ]
    x0 = np.array([top_m.dx, top_m.dy, top_m.dtheta])
    # Each alike motion could be the true one: its offset, whole, joins the covariance.
    spread = np.zeros((3, 3))
    for m in alike:
        d = np.array([m.dx, m.dy, math.remainder(m.dtheta - top_m.dtheta, 2 * math.pi)])
        d[:2] -= x0[:2]
        spread += np.outer(d, d)
    # Scans this far apart overlap less, and what they share is matched with errors
    # the fit does not see (see ``wide_sigma_per_m``).
    step = math.hypot(top_m.dx, top_m.dy)
    pos = cfg.wide_sigma_per_m * step
    rot = cfg.wide_sigma_rad_per_m * step + cfg.wide_sigma_per_rad * abs(top_m.dtheta)
    cov = top_m.covariance + spread + np.diag([pos**2, pos**2, rot**2])
    return Motion(top_m.dx, top_m.dy, top_m.dtheta, cov, top_m.matches, top_m.rms_m)
