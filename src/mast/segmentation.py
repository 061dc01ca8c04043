"""Stage 1: segment a scan into straight lines (the paper's "Data Segmentation").

Runs of consecutive returns are cut where the gap between neighbours is more
than the beam spacing can explain (the adaptive breakpoint detector of Borges
and Aldon, 2004); each run is split recursively at its farthest point from
the chord (iterative end-point fit), collinear neighbours are merged, and the
points at each split are handed to the line that fits them. Every line is a
total-least-squares (principal component) fit.

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

from .scan import Scan

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
    split_sigmas : float
        A run is split when a point lies more than this many noise standard
        deviations from the chord.
    noise_floor_m : float
        Lower bound on the noise used for thresholds (numerical precision of
        noise-free scans).
    noise_m : float or None
        Range noise to use for thresholds; ``None`` estimates it from the scan.
    """

    min_points: int = 3
    incidence_limit_deg: float = 8.0
    max_gap_beams: int = 3
    split_sigmas: float = 4.0
    noise_floor_m: float = 1e-7
    noise_m: float | None = None


@dataclass(frozen=True, slots=True)
class LineFit:
    centroid: NDArray[np.float64]
    direction: NDArray[np.float64]
    normal: NDArray[np.float64]
    rms: float
    t_spread: float  # sum of squared projections about the centroid


def fit_line(points: NDArray[np.float64]) -> LineFit:
    """Total least squares line through ``(n, 2)`` points (principal component).

    The direction points from the first point towards the last.
    """
    c = points.mean(axis=0)
    q = points - c
    cov = q.T @ q
    w, v = np.linalg.eigh(cov)
    d = v[:, 1]
    if np.dot(points[-1] - points[0], d) < 0:
        d = -d
    n = np.array([-d[1], d[0]])
    resid = q @ n
    t = q @ d
    return LineFit(c, d, n, float(np.sqrt(np.mean(resid**2))), float(np.sum(t**2)))


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


def estimate_noise(points: NDArray[np.float64], run_ids: NDArray[np.intp]) -> float:
    """Robust estimate of the perpendicular noise from triples of consecutive returns.

    For three neighbours on a straight surface, the middle one's distance
    from the line through the outer two has variance about 1.5 sigma^2; the
    median absolute value is robust to the few triples that straddle corners.
    """
    if points.shape[0] < 3:
        return 0.0
    a, b, c = points[:-2], points[1:-1], points[2:]
    same = (run_ids[:-2] == run_ids[1:-1]) & (run_ids[1:-1] == run_ids[2:])
    if not np.any(same):
        return 0.0
    ac = c - a
    length = np.hypot(ac[:, 0], ac[:, 1])
    ok = same & (length > 0)
    dist = np.abs(ac[ok, 0] * (b[ok, 1] - a[ok, 1]) - ac[ok, 1] * (b[ok, 0] - a[ok, 0])) / length[ok]
    # median |N(0, s)| = 0.6745 s, s^2 = 1.5 sigma^2
    return float(np.median(dist) / 0.6745 / math.sqrt(1.5))


def _split(points: NDArray[np.float64], tol: float, min_points: int) -> list[tuple[int, int]]:
    """Iterative end-point fit: index ranges [i, j) of straight pieces."""
    out: list[tuple[int, int]] = []
    stack = [(0, points.shape[0])]
    while stack:
        i, j = stack.pop()
        p = points[i:j]
        if j - i < 2 * min_points:
            out.append((i, j))
            continue
        chord = p[-1] - p[0]
        length = math.hypot(chord[0], chord[1])
        if length == 0:
            out.append((i, j))
            continue
        dist = np.abs(chord[0] * (p[:, 1] - p[0, 1]) - chord[1] * (p[:, 0] - p[0, 0])) / length
        k = int(np.argmax(dist))
        if dist[k] <= tol:
            fit = fit_line(p)
            resid = np.abs((p - fit.centroid) @ fit.normal)
            if resid.max() <= tol:
                out.append((i, j))
                continue
            k = int(np.argmax(resid))
        k = min(max(k, min_points - 1), j - i - min_points)
        # The farthest point is the corner: it belongs to both sides until refined.
        stack.append((i + k, j))
        stack.append((i, i + k + 1))
    out.sort()
    # Pieces share their corner point; give it to the left piece for now.
    fixed: list[tuple[int, int]] = []
    for a, b in out:
        if fixed and a < fixed[-1][1]:
            a = fixed[-1][1]
        if b > a:
            fixed.append((a, b))
    return fixed


def _merge(points: NDArray[np.float64], pieces: list[tuple[int, int]], tol: float) -> list[tuple[int, int]]:
    merged = True
    while merged and len(pieces) > 1:
        merged = False
        best, best_rms = -1, math.inf
        for k in range(len(pieces) - 1):
            i, j = pieces[k][0], pieces[k + 1][1]
            fit = fit_line(points[i:j])
            resid = np.abs((points[i:j] - fit.centroid) @ fit.normal)
            if resid.max() <= tol and fit.rms < best_rms:
                best, best_rms = k, fit.rms
        if best >= 0:
            pieces[best : best + 2] = [(pieces[best][0], pieces[best + 1][1])]
            merged = True
    return pieces


def _absorb_small(
    points: NDArray[np.float64], pieces: list[tuple[int, int]], tol: float, min_points: int
) -> list[tuple[int, int]]:
    """Hand the returns of pieces too small for a line to a neighbour they fit.

    Splitting near a corner can leave one or two returns on their own; they
    belong to one of the lines beside them (or to neither, e.g. a mixed pixel).
    """
    out = list(pieces)
    k = 0
    while k < len(out):
        i, j = out[k]
        if j - i >= min_points or len(out) == 1:
            k += 1
            continue
        left = out[k - 1] if k > 0 and out[k - 1][1] - out[k - 1][0] >= min_points else None
        right = out[k + 1] if k + 1 < len(out) and out[k + 1][1] - out[k + 1][0] >= min_points else None
        fl = fit_line(points[left[0] : left[1]]) if left else None
        fr = fit_line(points[right[0] : right[1]]) if right else None
        # each point goes left while it fits the left line, the rest right while they fit it
        cut = i
        while fl is not None and cut < j and abs((points[cut] - fl.centroid) @ fl.normal) <= tol:
            cut += 1
        cut_r = j
        while fr is not None and cut_r > cut and abs((points[cut_r - 1] - fr.centroid) @ fr.normal) <= tol:
            cut_r -= 1
        if left is not None and cut > i:
            out[k - 1] = (left[0], cut)
        if right is not None and cut_r < j:
            out[k + 1] = (cut_r, right[1])
        if cut_r > cut:  # returns that fit neither line stay out of every segment
            out[k] = (cut, cut_r)
            k += 1
        else:
            del out[k]
    return out


def _refine_boundaries(points: NDArray[np.float64], pieces: list[tuple[int, int]], min_points: int) -> list[tuple[int, int]]:
    """Move returns across each boundary to the line they lie closer to."""
    pieces = list(pieces)
    for _ in range(5):
        changed = False
        for k in range(len(pieces) - 1):
            (a0, a1), (b0, b1) = pieces[k], pieces[k + 1]
            fa, fb = fit_line(points[a0 : a1 - 1]) if a1 - a0 > min_points else fit_line(points[a0:a1]), (
                fit_line(points[b0 + 1 : b1]) if b1 - b0 > min_points else fit_line(points[b0:b1])
            )
            # last of A to B?
            p = points[a1 - 1]
            if a1 - a0 > min_points and abs((p - fb.centroid) @ fb.normal) < abs((p - fa.centroid) @ fa.normal):
                pieces[k], pieces[k + 1] = (a0, a1 - 1), (a1 - 1, b1)
                changed = True
                continue
            p = points[b0]
            if b1 - b0 > min_points and abs((p - fa.centroid) @ fa.normal) < abs((p - fb.centroid) @ fb.normal):
                pieces[k], pieces[k + 1] = (a0, a1 + 1), (b0 + 1, b1)
                changed = True
        if not changed:
            break
    return pieces


def _make_segment(index: int, run: int, beams: NDArray[np.intp], pts: NDArray[np.float64], noise: float) -> Segment:
    fit = fit_line(pts)
    t = (pts - fit.centroid) @ fit.direction
    start = fit.centroid + t[0] * fit.direction
    end = fit.centroid + t[-1] * fit.direction
    sigma_dir = noise / math.sqrt(fit.t_spread) if fit.t_spread > 0 else math.inf
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
        with np.errstate(invalid="ignore", divide="ignore"):
            dmax = r[:-1] * np.sin(dphi) / np.sin(np.maximum(lam - dphi, 1e-6))
        dmax = dmax + 3.0 * (noise_guess if noise_guess is not None else 0.0)
        brk = (gap_beams > config.max_gap_beams + 1) | (step > dmax) | (dphi >= lam)
        run_ids[1:] = np.cumsum(brk)
    noise = noise_guess if noise_guess is not None else estimate_noise(pts, run_ids)
    noise = max(noise, config.noise_floor_m)
    if noise_guess is None and beams.size > 1:
        # Second pass with the estimated noise, so noisy returns do not cut runs.
        brk = (gap_beams > config.max_gap_beams + 1) | (step > dmax + 3.0 * noise) | (dphi >= lam)
        run_ids[1:] = np.cumsum(brk)
    tol = config.split_sigmas * noise
    segments: list[Segment] = []
    corners: list[Corner] = []
    for run in np.unique(run_ids):
        sel = np.flatnonzero(run_ids == run)
        if sel.size < config.min_points:
            continue
        p = pts[sel]
        pieces = _split(p, tol, config.min_points)
        pieces = _merge(p, pieces, tol)
        pieces = _absorb_small(p, pieces, tol, config.min_points)
        pieces = _refine_boundaries(p, pieces, config.min_points)
        prev: Segment | None = None
        for i, j in pieces:
            if j - i < config.min_points:
                continue
            seg = _make_segment(len(segments), int(run), beams[sel[i:j]], p[i:j], noise)
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
    if abs(cross) < 1e-12:
        return None
    # a.centroid + s a.dir = b.centroid + u b.dir
    w = b.centroid - a.centroid
    s = (w[0] * b.direction[1] - w[1] * b.direction[0]) / cross
    node = a.centroid + s * a.direction
    return Corner(a.index, b.index, defl, node)
