"""Stage 1: segment a scan into straight lines (the paper's "Data Segmentation").

Runs of consecutive returns are cut where the gap between neighbours is more
than the beam spacing can explain (the adaptive breakpoint detector of Borges
and Aldon, 2004); each run is then partitioned optimally into straight pieces
(dynamic programming over all break points, each break paid for by a
penalty that follows the scan's noise). Every line is a total-least-squares
(principal component) fit.

References
----------
G. A. Borges and M.-J. Aldon, "Line extraction in 2D range images for mobile
robotics", J. Intelligent and Robotic Systems 40, 2004.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.lines import (
    fit_line,
    intersect_lines,
    range_noise_from_triples,
    range_noise_from_triples_reference,
)
from mast.core.scan import Scan

__all__ = ["Corner", "Segment", "Segmentation", "SegmentationConfig", "fit_line", "segment_scan"]


@dataclass(frozen=True, slots=True)
class SegmentationConfig:
    """Thresholds of the segmentation; all follow the scanner's spacing and noise.

    Attributes
    ----------
    min_points : int
        Fewest returns a line needs.
    incidence_limit_deg : float
        Breakpoint detector: the shallowest incidence (degrees between beam
        and surface) at which neighbouring returns still count as one surface.
    max_gap_beams : int
        Most consecutive missing returns bridged inside one run.
    noise_floor_m : float
        Lower bound on the noise used for thresholds: keeps rounding in the
        cumulative moments of a noise-free scan from passing for structure.
    noise_m : float or None
        Range noise to use for thresholds; ``None`` estimates it from the scan.
    """

    min_points: int = 3
    incidence_limit_deg: float = 8.0
    max_gap_beams: int = 3
    noise_floor_m: float = 2e-5
    noise_m: float | None = None


@dataclass(frozen=True, eq=False)
class Segment:
    """A straight piece of the scan, in the scanner frame.

    Attributes
    ----------
    index : int
        Position in the segmentation's list.
    run : int
        Run (stretch without a breakpoint) it belongs to.
    beams : ndarray of int
        Beam indices of its returns, increasing.
    points : ndarray, shape (n, 2)
    centroid, direction, normal : ndarray, shape (2,)
        TLS fit; ``direction`` follows increasing beam angle, ``normal`` is it
        turned +90 degrees.
    length : float
        Extent of the projected returns along the line, metres.
    start, end : ndarray, shape (2,)
        First and last return projected on the line.
    rms : float
        RMS perpendicular residual of the fit, metres.
    sigma_direction : float
        Standard deviation of the direction, radians, for the noise in use.
    spacing_start, spacing_end : float
        Distance along the line between the two first and the two last returns:
        how far the true end of the surface may lie beyond ``start``/``end``.
    """

    index: int
    run: int
    beams: NDArray[np.intp]
    points: NDArray[np.float64]
    centroid: NDArray[np.float64]
    direction: NDArray[np.float64]
    normal: NDArray[np.float64]
    length: float
    start: NDArray[np.float64]
    end: NDArray[np.float64]
    rms: float
    sigma_direction: float
    spacing_start: float
    spacing_end: float

    @property
    def midpoint(self) -> NDArray[np.float64]:
        """Middle of the seen extent along the line."""
        return np.asarray(0.5 * (self.start + self.end))

    @property
    def first_beam(self) -> int:
        return int(self.beams[0])

    @property
    def last_beam(self) -> int:
        return int(self.beams[-1])

    def __len__(self) -> int:
        return int(self.beams.size)


@dataclass(frozen=True, slots=True)
class Corner:
    """Two consecutive segments of one run and where their lines meet.

    ``deflection`` is the signed turn (counter-clockwise positive, radians)
    from the first segment's direction to the second's; ``node`` is the
    intersection of the two lines (a beacon edge when both are panels).
    """

    first: int
    second: int
    deflection: float
    node: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Segmentation:
    segments: tuple[Segment, ...]
    corners: tuple[Corner, ...]
    noise_m: float
    """Noise standard deviation used for the thresholds (estimated or given)."""


#: Longest piece the optimal partition considers at once (returns): bounds its work
#: to ``n * MAX_PIECE`` for a run of ``n``; longer straight pieces are put back
#: together from these afterwards (only where the cap alone made the cut).
MAX_PIECE = 128

#: Piece ends whose candidate costs (``COST_BLOCK x MAX_PIECE``) the partition holds
#: at once: its memory stays a few megabytes however long the run.
COST_BLOCK = 512


def _partition(
    points: NDArray[np.float64], var: float, max_piece: int = MAX_PIECE
) -> list[tuple[int, int]]:
    """Optimal partition of one run into straight pieces (dynamic programming).

    Minimises, over all partitions, the sum over pieces of

        SSE_TLS(piece) / (var * mean((n . u_i)^2)) + penalty(n) + 4 * (returns in a piece of 1 or 2)

    where ``var`` is the range noise variance and ``(n . u_i)^2`` turns it
    into the noise across the piece's line for each beam ``u_i``: costs are in
    chi-square units, so a face-on panel and an oblique wall are judged
    alike. Every break must buy more than :func:`mast.core._kernels.penalty` (the optimal
    partitioning changepoint method, Jackson et al. 2005). Returns left in a
    piece of one or two cost like outliers, so exact ties break towards real
    lines. Pieces hold at most ``max_piece`` returns, which bounds the work
    to ``n * max_piece``; cuts that only the cap made are undone after.
    Every candidate piece's SSE and normal come at once from cumulative
    moments, :data:`COST_BLOCK` piece ends at a time, so memory is linear in
    the run's returns.

    References
    ----------
    B. Jackson et al., "An algorithm for optimal partitioning of data on an
    interval", IEEE Signal Processing Letters 12, 2005.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        return _partition_impl(points, var, max_piece)


def _cumulative_moments(
    points: NDArray[np.float64],
) -> tuple[NDArray[np.float64], tuple[NDArray[np.float64], ...]]:
    """Unit beam vectors, and cumulative sums (from 0) of the centred points' first and
    second moments and of the beam vectors' second moments."""
    c = points - points.mean(axis=0)
    r = np.hypot(points[:, 0], points[:, 1])
    u = points / np.where(r > 0, r, 1.0)[:, None]
    z = np.zeros(1)

    def cum(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([z, np.cumsum(v)])

    return u, (
        cum(c[:, 0]),
        cum(c[:, 1]),
        cum(c[:, 0] ** 2),
        cum(c[:, 1] ** 2),
        cum(c[:, 0] * c[:, 1]),
        cum(u[:, 0] ** 2),
        cum(u[:, 1] ** 2),
        cum(u[:, 0] * u[:, 1]),
    )


def _partition_reference(
    points: NDArray[np.float64], var: float, max_piece: int = MAX_PIECE
) -> NDArray[np.intp]:
    """Back-pointers of the optimal partition, in numpy: the readable reference of
    :func:`mast.core._kernels.partition_dp` (the tests compare them)."""
    from mast.core._kernels import penalty

    n = points.shape[0]
    _, (sx, sy, sxx, syy, sxy, uxx, uyy, uxy) = _cumulative_moments(points)
    w = min(n, max_piece)
    d = np.arange(1, w + 1)  # piece lengths
    m = d[None, :].astype(float)
    pen = penalty(n)
    small = 4.0 * np.where(m < 3, m, 0.0)

    def costs(j0: int, j1: int) -> NDArray[np.float64]:
        """Cost of every piece ending at ``j0 .. j1 - 1`` (exclusive ends), by length."""
        j = np.arange(j0, j1)[:, None]  # piece ends (exclusive)
        i = j - d[None, :]  # piece starts
        ok = i >= 0
        ii = np.where(ok, i, 0)
        ax, ay = sx[j] - sx[ii], sy[j] - sy[ii]
        vxx = sxx[j] - sxx[ii] - ax * ax / m
        vyy = syy[j] - syy[ii] - ay * ay / m
        vxy = sxy[j] - sxy[ii] - ax * ay / m
        half = 0.5 * (vxx + vyy)
        sse = np.maximum(half - np.sqrt(np.maximum(0.25 * (vxx - vyy) ** 2 + vxy**2, 0.0)), 0.0)
        theta = 0.5 * np.arctan2(2.0 * vxy, vxx - vyy)  # direction of the piece's line
        nx, ny = -np.sin(theta), np.cos(theta)
        nu2 = (
            nx * nx * (uxx[j] - uxx[ii])
            + 2 * nx * ny * (uxy[j] - uxy[ii])
            + ny * ny * (uyy[j] - uyy[ii])
        ) / m
        scale = var * np.maximum(nu2, 0.05)
        out: NDArray[np.float64] = np.where(ok, sse / scale + pen + small, np.inf)
        return out

    best = np.empty(n + 1)
    best[0] = -pen
    last = np.zeros(n + 1, dtype=np.intp)
    for j0 in range(1, n + 1, COST_BLOCK):
        j1 = min(j0 + COST_BLOCK, n + 1)
        cost = costs(j0, j1)
        for jj in range(j0, j1):
            k = min(jj, w)
            total = best[jj - 1 :: -1][:k] + cost[jj - j0, :k]
            arg = int(np.argmin(total))
            best[jj] = total[arg]
            last[jj] = jj - 1 - arg
    return last


def _partition_impl(
    points: NDArray[np.float64],
    var: float,
    max_piece: int,
    run: tuple[NDArray[np.float64], tuple[NDArray[np.float64], ...]] | None = None,
) -> list[tuple[int, int]]:
    """:func:`_partition`, its pieces' costs from ``run`` when given: the unit beam
    vectors and cumulative moments (:func:`_cumulative_moments`) of ``points`` taken
    from those of the run they are part of (a piece's cost needs only the moments at
    its two ends, so the run's serve every stretch of it)."""
    from mast.core._kernels import partition_dp, penalty

    n = points.shape[0]
    u, moments = _cumulative_moments(points) if run is None else run
    w = min(n, max_piece)
    pen = penalty(n)
    last = partition_dp(*moments, float(var), pen, w)
    pieces: list[tuple[int, int]] = []
    e = n
    while e > 0:
        pieces.append((int(last[e]), e))
        e = int(last[e])
    pieces.reverse()
    # Undo the cuts that only the cap on piece length made.
    merged: list[tuple[int, int]] = []
    joined: _Moments | None = None  # moments of merged[-1]
    for a0, b0 in pieces:
        if merged and b0 - merged[-1][0] > w:
            s0 = merged[-1][0]
            if joined is None:
                joined = _Moments.of(points[s0:a0], u[s0:a0])
            piece = _Moments.of(points[a0:b0], u[a0:b0])
            both = joined.union(piece)
            gain = both.sse() - joined.sse() - piece.sse()
            if gain / (var * max(both.mean_nu2(), 0.05)) <= pen:
                merged[-1] = (s0, b0)
                joined = both
                continue
        merged.append((a0, b0))
        joined = None
    return merged


@dataclass(frozen=True, slots=True)
class _Moments:
    """What a piece's total-least-squares fit needs, kept small and exact.

    ``r`` is the triangular factor of the piece's centred points (their
    scatter is ``r.T @ r``): the SSE is the smallest singular value of ``r``
    squared and the line's normal its right singular vector, to the accuracy
    of a singular value decomposition of the points themselves. Two pieces'
    factors, centroids and counts give their union's (Chan, Golub and LeVeque
    1979), so a piece grown one piece at a time costs no pass over its points.
    """

    count: int
    mean: NDArray[np.float64]
    r: NDArray[np.float64]
    uu: NDArray[np.float64]  # sum of u u^T over the beams (unit vectors)

    @classmethod
    def of(cls, points: NDArray[np.float64], u: NDArray[np.float64]) -> _Moments:
        mean = points.mean(axis=0)
        r = np.linalg.qr(points - mean, mode="r") if points.shape[0] > 1 else np.zeros((1, 2))
        return cls(int(points.shape[0]), mean, np.asarray(r), u.T @ u)

    def union(self, other: _Moments) -> _Moments:
        n = self.count + other.count
        dm = other.mean - self.mean
        shift = math.sqrt(self.count * other.count / n) * dm
        r = np.linalg.qr(np.vstack([self.r, other.r, shift[None, :]]), mode="r")
        return _Moments(n, self.mean + dm * (other.count / n), np.asarray(r), self.uu + other.uu)

    def _svd(self) -> tuple[float, NDArray[np.float64]]:
        _, s, vt = np.linalg.svd(self.r)
        return (float(s[-1]) if s.size > 1 else 0.0), vt[-1]

    def sse(self) -> float:
        """Total-least-squares residual sum of squares (0 for fewer than three points)."""
        return self._svd()[0] ** 2 if self.count >= 3 else 0.0

    def mean_nu2(self) -> float:
        """Mean of (normal . u)^2 over the beams, for the fitted line's normal."""
        nrm = self._svd()[1]
        return float(nrm @ self.uu @ nrm) / self.count


def _refine(
    points: NDArray[np.float64], pieces: list[tuple[int, int]], var: float, min_points: int
) -> list[tuple[int, int]]:
    """Partition every piece of a run again, its break paid for by its own length.

    The penalty grows with ln n because a break is chosen among n places;
    across a whole run of hundreds of returns that buries the bend between
    two short panels far away (a few returns each) under a break the long
    run's walls cannot afford. Within one piece the choice is among its own
    returns, so a piece is split when the split pays the penalty of its length.
    A piece's costs are read from the run's cumulative moments, as the compiled
    :func:`mast.core._kernels.segment_run` reads them from its one table of the run's.
    """
    out: list[tuple[int, int]] = []
    u, moments = _cumulative_moments(points)
    for i, j in pieces:
        if j - i >= 2 * min_points and j - i < points.shape[0]:
            # The piece's stretch of the run's moments: its costs are the run's own.
            stretch = (u[i:j], tuple(m[i : j + 1] for m in moments))
            with np.errstate(over="ignore", invalid="ignore"):
                sub = _partition_impl(points[i:j], var, MAX_PIECE, stretch)
            out.extend((i + a, i + b) for a, b in sub)
        else:
            out.append((i, j))
    return out


def _make_segment(
    index: int, run: int, beams: NDArray[np.intp], pts: NDArray[np.float64], noise: float
) -> Segment:
    fit = fit_line(pts)
    t = (pts - fit.centroid) @ fit.direction
    start = fit.centroid + t[0] * fit.direction
    end = fit.centroid + t[-1] * fit.direction
    # range noise seen across this line: sigma_r * rms(n . u) over its beams
    u = pts / np.hypot(pts[:, 0], pts[:, 1])[:, None]
    perp = noise * math.sqrt(max(float(np.mean((u @ fit.normal) ** 2)), 1e-6))
    sigma_dir = perp / math.sqrt(fit.t_spread) if fit.t_spread > 0 else math.inf
    return Segment(
        index=index,
        run=run,
        beams=beams,
        points=pts,
        centroid=fit.centroid,
        direction=fit.direction,
        normal=fit.normal,
        length=float(t[-1] - t[0]),
        start=start,
        end=end,
        rms=fit.rms,
        sigma_direction=sigma_dir,
        spacing_start=float(abs(t[1] - t[0])) if t.size > 1 else 0.0,
        spacing_end=float(abs(t[-1] - t[-2])) if t.size > 1 else 0.0,
    )


def _segment_of(
    index: int,
    run: int,
    beams: NDArray[np.intp],
    pts: NDArray[np.float64],
    fit: NDArray[np.float64],
) -> Segment:
    """A segment from its row of :func:`mast.core._kernels.line_fits` (its vectors are
    views of the row)."""
    return Segment(
        index=index,
        run=run,
        beams=beams,
        points=pts,
        centroid=fit[0:2],
        direction=fit[2:4],
        normal=fit[10:12],
        length=float(fit[6]) - float(fit[5]),
        start=fit[12:14],
        end=fit[14:16],
        rms=float(fit[4]),
        sigma_direction=float(fit[9]),
        spacing_start=float(fit[7]),
        spacing_end=float(fit[8]),
    )


def _runs(
    scan: Scan, beams: NDArray[np.intp], pts: NDArray[np.float64], config: SegmentationConfig
) -> tuple[NDArray[np.intp], float]:
    """Run (stretch without a breakpoint) of every return, and the noise for the thresholds.

    A breakpoint is a jump larger than a surface at the limiting incidence explains,
    beams more than ``max_gap_beams`` apart, or beams the incidence limit apart; with
    the noise estimated (no ``noise_m``), the runs are cut again with three times the
    estimate more jump explained, so that noisy returns do not cut them. Compiled
    (:func:`mast.core._kernels.run_breaks`, :func:`mast.core._kernels.rebreak`);
    :func:`_runs_reference` is the same in numpy.
    """
    from mast.core._kernels import rebreak, run_breaks

    beams = np.ascontiguousarray(beams, dtype=np.intp)
    angles = np.ascontiguousarray(scan.angles_rad[beams], dtype=float)
    lam = math.radians(config.incidence_limit_deg)
    noise_guess = config.noise_m
    slack = 3.0 * (noise_guess if noise_guess is not None else 0.0)
    run_ids, explained, step = run_breaks(
        beams,
        np.ascontiguousarray(scan.ranges_m[beams], dtype=float),
        angles,
        np.ascontiguousarray(pts, dtype=float).reshape(-1, 2),
        config.max_gap_beams,
        lam,
        slack,
    )
    noise = noise_guess if noise_guess is not None else range_noise_from_triples(pts, run_ids)
    noise = max(noise, config.noise_floor_m)
    if noise_guess is None and beams.size > 1:
        run_ids = rebreak(beams, angles, explained, step, config.max_gap_beams, lam, 3.0 * noise)
    return run_ids, noise


def _runs_reference(
    scan: Scan, beams: NDArray[np.intp], pts: NDArray[np.float64], config: SegmentationConfig
) -> tuple[NDArray[np.intp], float]:
    """:func:`_runs` in numpy (the tests compare the two)."""
    r = scan.ranges_m[beams]
    ang = scan.angles_rad[beams]
    # Breakpoints: a jump larger than a surface at the limiting incidence explains.
    gap_beams = np.diff(beams)
    dphi = np.diff(ang)
    lam = math.radians(config.incidence_limit_deg)
    step = np.hypot(*np.diff(pts, axis=0).T)
    noise_guess = config.noise_m
    run_ids = np.zeros(beams.size, dtype=np.intp)
    if beams.size > 1:
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            dmax = r[:-1] * np.sin(dphi) / np.sin(np.maximum(lam - dphi, 1e-6))
        dmax = dmax + 3.0 * (noise_guess if noise_guess is not None else 0.0)
        brk = (gap_beams > config.max_gap_beams + 1) | (step > dmax) | (dphi >= lam)
        run_ids[1:] = np.cumsum(brk)
    noise = (
        noise_guess if noise_guess is not None else range_noise_from_triples_reference(pts, run_ids)
    )
    noise = max(noise, config.noise_floor_m)
    if noise_guess is None and beams.size > 1:
        # Second pass with the estimated noise, so noisy returns do not cut runs.
        brk = (gap_beams > config.max_gap_beams + 1) | (step > dmax + 3.0 * noise) | (dphi >= lam)
        run_ids[1:] = np.cumsum(brk)
    return run_ids, noise


def segment_scan(scan: Scan, config: SegmentationConfig = SegmentationConfig()) -> Segmentation:
    """Split a scan into straight segments and the corners between them.

    Parameters
    ----------
    scan : Scan
    config : SegmentationConfig

    Returns
    -------
    Segmentation
        Segments in increasing beam order, the corners between consecutive
        segments of a run, and the noise level the thresholds used.
    """
    beams, pts = scan.points()
    if beams.size == 0:
        return Segmentation((), (), config.noise_floor_m)
    run_ids, noise = _runs(scan, beams, pts, config)
    from mast.core._kernels import line_fits, segment_run

    segments: list[Segment] = []
    corners: list[Corner] = []
    # run_ids never decrease: each run is one slice of the returns
    bounds = np.flatnonzero(np.diff(run_ids)) + 1
    pts = np.ascontiguousarray(pts, dtype=float)
    for lo, hi in zip([0, *bounds.tolist()], [*bounds.tolist(), beams.size], strict=True):
        if hi - lo < config.min_points:
            continue
        run = int(run_ids[lo])
        p = pts[lo:hi]
        # the compiled _refine(p, _partition(p, var), var, min_points)
        pieces = segment_run(p, noise**2, config.min_points, MAX_PIECE)
        pieces = pieces[pieces[:, 1] - pieces[:, 0] >= config.min_points]
        fits = line_fits(p, pieces, noise)  # the compiled _make_segment's fits
        fits.flags.writeable = False  # the segments' vectors are views of its rows
        prev: Segment | None = None
        for (i, j), fit in zip(pieces.tolist(), fits, strict=True):
            seg = _segment_of(len(segments), run, beams[lo + i : lo + j], p[i:j], fit)
            if prev is not None and prev.last_beam + 1 + config.max_gap_beams >= seg.first_beam:
                corner = _corner(prev, seg)
                if corner is not None:
                    corners.append(corner)
            segments.append(seg)
            prev = seg
    return Segmentation(tuple(segments), tuple(corners), noise)


def _corner(a: Segment, b: Segment) -> Corner | None:
    cross = a.direction[0] * b.direction[1] - a.direction[1] * b.direction[0]
    dot = float(a.direction @ b.direction)
    defl = math.atan2(cross, dot)
    node = intersect_lines(a.centroid, a.direction, b.centroid, b.direction, min_sine=1e-12)
    if node is None:
        return None
    return Corner(a.index, b.index, defl, node)
