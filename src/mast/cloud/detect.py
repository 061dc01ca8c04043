"""Find beacon panels in a 3D cloud: vertical, flat, of a panel's height, above the floor.

Three passes over the cloud, each one chunk at a time (memory follows the
cells and the candidate points, not the cloud):

1. **Floor and roof.** The lowest and highest point of every 0.5 m plan cell and
   its eight neighbours (a cell holding nothing but a far panel, which shadows the
   rock behind it, takes the floor and roof in front of it).
2. **Columns.** Of the points in the *band* (``clearance`` above the floor and
   below the roof of their cell, or ``--band Z0,Z1`` in the cloud's frame),
   every 5 cm plan cell keeps its lowest and highest z and which 5 cm height
   bins hold points. A panel's cell holds one unbroken column that starts and
   ends inside the band, at least a panel's height tall: rock walls run from
   floor to roof, floors and roofs are left out by the band, pipes and ducts are
   short columns, machines stand on the floor. A column is level with two of its
   eight neighbours, or, where it stands alone (a far panel's scan columns are
   centimetres apart), with two within three cells.
3. **Candidates.** The points of those cells.

The candidates are then reduced to plan: clusters of touching cells are split
into straight pieces by sequential RANSAC (:func:`_lines_in`), each piece cut
into its runs of heights (:func:`_height_runs`: the wall or a pipe above a panel),
and pieces of one line that the clusters cut apart joined again (:func:`_joined`);
every piece is fitted with a vertical plane in 3D and kept only when it is
vertical, flat to the noise and at least ``min_panel_height_m`` tall (or, failing
that, where a stretch of even heights along its line is: :func:`_even_stretches`, a
panel's line running on over the rock beside it), and not mostly the points of a
larger piece (:data:`DUPLICATE_SHARE`); its top edge is
found from where the point density along the height halves (the level whose
count above equals the density times the height above a reference; unbiased
for any symmetric noise). Neighbouring pieces whose lines meet near their ends
form corners, and the corners go to the same panel identification as ``mast
locate`` (:func:`mast.pipeline.identification.identify_panels`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.cloud.grid import EIGHT, PlanGrid, cell_keys, key_ij, neighbours, pack_ij, within
from mast.cloud.io import Cloud
from mast.core.lines import fit_line, intersect_lines, plan_noise_from_neighbours
from mast.errors import InputError
from mast.pipeline.segmentation import Corner, Segment, Segmentation

__all__ = [
    "Candidates",
    "DetectConfig",
    "Panel",
    "PlanPieces",
    "find_candidates",
    "panel_from_points",
    "plan_pieces",
    "points_near",
]

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, slots=True)
class DetectConfig:
    """Thresholds of the 3D search; lengths in metres.

    Attributes
    ----------
    floor_cell_m : float
        Plan cell of the floor and roof grid.
    cell_m : float
        Plan cell of the column test.
    bin_m : float
        Height bin of the column test (64 bins: the band's lowest 3.2 m at 5 cm).
    clearance_m : float
        A panel's points are at least this far above the floor and below the roof.
    band : tuple of float, optional
        ``(z0, z1)`` in the cloud's frame instead of the floor and roof.
    min_panel_height_m, max_panel_height_m : float
        Shortest and tallest column, and plane, that may be a panel.
    max_tilt_deg : float
        Largest tilt of a panel's plane from the vertical.
    noise_m : float, optional
        The cloud's noise (one coordinate's standard deviation); estimated if ``None``.
    min_points : int
        Fewest points of a piece.
    chunk_points : int
        Points read at once.
    """

    floor_cell_m: float = 0.5
    cell_m: float = 0.05
    bin_m: float = 0.05
    clearance_m: float = 0.2
    band: tuple[float, float] | None = None
    min_panel_height_m: float = 0.25
    max_panel_height_m: float = 1.5
    max_tilt_deg: float = 3.0
    noise_m: float | None = None
    min_points: int = 12
    chunk_points: int = 2_000_000


@dataclass(frozen=True, eq=False)
class Candidates:
    """What the passes found: candidate points (``core``: in a panel cell itself, not in
    a neighbour of one), the floor grid, the cloud's extent."""

    xyz: NDArray[np.float64]
    time: NDArray[np.float64] | None
    core: NDArray[np.bool_]
    floor: PlanGrid
    cells: int
    points_read: int
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    wall_density_m2: float = math.nan
    """The walls' point density, points per square metre (:func:`wall_density`)."""


def _floor_and_roof_around(floor: PlanGrid) -> PlanGrid:
    """The floor grid with each cell's floor and roof the lowest and highest of it and
    its eight neighbours. A cell at a wall may hold nothing but a panel: from far off,
    the panel shadows the rock behind it, and the floor and roof in front of it lie in
    the next cells. Its own lowest and highest point would make the panel floor to roof
    (a wall, never a panel)."""
    zmin = floor.zmin.copy()
    zmax = floor.zmax.copy()
    for hit, pos in neighbours(floor.keys):
        zmin[hit] = np.minimum(zmin[hit], floor.zmin[pos[hit]])
        zmax[hit] = np.maximum(zmax[hit], floor.zmax[pos[hit]])
    return replace(floor, zmin=zmin, zmax=zmax)


def _band_limits(
    floor: PlanGrid, xyz: NDArray[np.float64], cfg: DetectConfig
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    if cfg.band is not None:
        n = xyz.shape[0]
        return np.full(n, cfg.band[0]), np.full(n, cfg.band[1])
    row, _ = floor.at(xyz[:, :2])
    return floor.zmin[row] + cfg.clearance_m, floor.zmax[row] - cfg.clearance_m


def find_candidates(
    cloud: Cloud, cfg: DetectConfig = DetectConfig(), progress: Progress | None = None
) -> Candidates:
    """Passes 1-3 (module docstring): the points of panel-like columns."""
    if cloud.count == 0:
        raise InputError("holds no points", path=cloud.path)
    floor: PlanGrid | None = None
    lower = np.full(3, math.inf)
    upper = np.full(3, -math.inf)
    read = 0
    for chunk in cloud.chunks(cfg.chunk_points):
        if floor is None:
            floor = PlanGrid(chunk.xyz[0, :2].copy(), cfg.floor_cell_m)
        floor.add(chunk.xyz)
        lower = np.minimum(lower, chunk.xyz.min(axis=0))
        upper = np.maximum(upper, chunk.xyz.max(axis=0))
        read += len(chunk.xyz)
        if progress:
            progress("floor and roof", read, cloud.count * 3)
    assert floor is not None
    floor = _floor_and_roof_around(floor)
    columns = PlanGrid(floor.origin, cfg.cell_m)
    done = 0
    # every step-th point of the band, for the walls' density (a known share of them)
    step = max(1, read // DENSITY_SAMPLE_POINTS)
    sample: list[NDArray[np.float64]] = []
    for chunk in cloud.chunks(cfg.chunk_points):
        lo, hi = _band_limits(floor, chunk.xyz, cfg)
        z = chunk.xyz[:, 2]
        keep = (z >= lo) & (z <= hi)
        k = np.clip(((z[keep] - lo[keep]) / cfg.bin_m).astype(np.int64), 0, 63)
        columns.add(chunk.xyz[keep], np.left_shift(np.uint64(1), k.astype(np.uint64)))
        picked = (np.arange(done, done + len(z)) % step == 0) & keep
        inner = (z >= lo + DENSITY_RADIUS_M) & (z <= hi - DENSITY_RADIUS_M)
        sample.append(np.column_stack([chunk.xyz[picked], inner[picked]]))
        done += len(z)
        if progress:
            progress("columns", read + done, cloud.count * 3)
    panel_like, zlo, zhi = _panel_runs(columns, floor, cfg)
    own = columns.keys[panel_like]
    wanted, zlo, zhi = _dilated(own, zlo[panel_like], zhi[panel_like])
    cores: list[NDArray[np.bool_]] = []
    xs: list[NDArray[np.float64]] = []
    ts: list[NDArray[np.float64]] = []
    done = 0
    for chunk in cloud.chunks(cfg.chunk_points):
        lo, hi = _band_limits(floor, chunk.xyz, cfg)
        z = chunk.xyz[:, 2]
        keys = cell_keys(chunk.xyz[:, :2], columns.origin, cfg.cell_m)
        pos = np.minimum(np.searchsorted(wanted, keys), max(wanted.size - 1, 0))
        keep = (z >= lo) & (z <= hi)
        if wanted.size:
            keep &= (wanted[pos] == keys) & (z >= zlo[pos]) & (z <= zhi[pos])
        else:
            keep[:] = False
        xs.append(chunk.xyz[keep])
        kk = keys[keep]
        cpos = np.minimum(np.searchsorted(own, kk), max(own.size - 1, 0))
        cores.append(own[cpos] == kk if own.size else np.zeros(kk.size, bool))
        if chunk.time is not None:
            ts.append(chunk.time[keep])
        done += len(z)
        if progress:
            progress("candidates", 2 * read + done, cloud.count * 3)
    xyz = np.concatenate(xs) if xs else np.zeros((0, 3))
    time = np.concatenate(ts) if ts and cloud.time_field is not None else None
    core = np.concatenate(cores) if cores else np.zeros(0, bool)
    density = wall_density(np.concatenate(sample) if sample else np.zeros((0, 4)), step)
    return Candidates(xyz, time, core, floor, int(own.size), read, lower, upper, density)


#: Points of the band kept for the density estimate (every n-th, n from the cloud's size).
DENSITY_SAMPLE_POINTS = 400_000
#: Radius of the disc a point's neighbours are counted in for the density, metres: wide
#: enough to hold a few dozen sampled points at a sparse cloud's density, narrow enough
#: that a rough wall is flat across it.
DENSITY_RADIUS_M = 0.25
#: Sampled points whose neighbours are counted.
DENSITY_QUERIES = 5000
#: The wall density below which beacons go unfound: the column test asks for the 5 cm
#: height bins of a 5 cm plan cell to be filled with gaps of two bins at the most
#: (25 cm^2 of panel each). On 150 m simulated clouds (1 cm noise, 6 beacons, 3 seeds
#: each) georef found 2 of 18 beacons at 600 points/m^2, 15 at 900, 16 at 1 200 and all
#: 18 at 1 500 and 2 000.
BEACON_DENSITY_M2 = 1200.0


#: Cell of the plan grid that marks where :func:`points_near` keeps a cloud's points.
NEAR_CELL_M = 0.25


def points_near(
    cloud: Cloud,
    centres: NDArray[np.float64],
    half_m: NDArray[np.float64],
    cfg: DetectConfig = DetectConfig(),
    progress: Progress | None = None,
) -> NDArray[np.float64]:
    """Every point of ``cloud`` within ``half_m`` (one per centre) in plan, per
    coordinate, of one of ``centres``, in one more pass: the cells of
    :data:`NEAR_CELL_M` that the squares touch are marked, and a chunk's points in a
    marked cell are kept (a few more than the squares hold: cut them with
    :class:`~mast.cloud.grid.PlanIndex`).

    The candidates of passes 1-3 keep only panel-like columns' points, and a panel a
    column test cut short keeps half of them; what is fitted where the survey says a
    beacon stands is better fitted to all of them."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    if centres.shape[0] == 0 or cloud.count == 0:
        return np.empty((0, 3))
    half = np.asarray(half_m, dtype=float).reshape(-1, 1)
    origin = centres[0].copy()
    lo = np.floor((centres - half - origin) / NEAR_CELL_M).astype(np.int64)
    hi = np.floor((centres + half - origin) / NEAR_CELL_M).astype(np.int64)
    squares = []
    for a, b in zip(lo, hi, strict=True):
        i, j = np.meshgrid(np.arange(a[0], b[0] + 1), np.arange(a[1], b[1] + 1))
        squares.append(pack_ij(np.column_stack([i.ravel(), j.ravel()])))
    marked = np.unique(np.concatenate(squares))
    xyz: list[NDArray[np.float64]] = [np.empty((0, 3))]
    read = 0
    for chunk in cloud.chunks(cfg.chunk_points):
        keys = cell_keys(chunk.xyz[:, :2], origin, NEAR_CELL_M)
        at = np.minimum(np.searchsorted(marked, keys), marked.size - 1)
        xyz.append(chunk.xyz[marked[at] == keys])
        read += chunk.xyz.shape[0]
        if progress:
            progress("beacons' neighbourhoods", read, cloud.count)
    return np.concatenate(xyz)


def wall_density(sample: NDArray[np.float64], step: int) -> float:
    """The median point density of the walls, points per square metre, from ``sample``
    (every ``step``-th band point: x, y, z and whether it is a disc's radius inside the
    band): the sampled neighbours within :data:`DENSITY_RADIUS_M` of each of up to
    :data:`DENSITY_QUERIES` inner points, over the disc's area and the sampled share.
    NaN with too few points to say."""
    from scipy.spatial import cKDTree

    pts = sample[:, :3]
    queries = np.flatnonzero(sample[:, 3] > 0)
    if queries.size < 10 or pts.shape[0] < 100:
        return math.nan
    queries = queries[:: max(1, queries.size // DENSITY_QUERIES)]
    tree = cKDTree(pts)
    counts = tree.query_ball_point(pts[queries], DENSITY_RADIUS_M, return_length=True)
    area = math.pi * DENSITY_RADIUS_M**2
    return float(np.median(np.asarray(counts, dtype=float) - 1.0) * step / area)


def _panel_runs(
    columns: PlanGrid, floor: PlanGrid, cfg: DetectConfig
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """Cells holding a panel-like column, and its lowest and highest height.

    A cell's height bins are closed over gaps of up to two bins (a sparse cloud
    leaves bins of a panel empty); of the runs of bins, the tallest one between
    ``min_panel_height_m`` and ``max_panel_height_m`` that touches neither end of
    the band is the cell's column, so a pipe or a duct above a panel in the same
    cell does not hide it, and a rock wall (floor to roof) is never one.
    """
    n = columns.keys.size
    if n == 0:
        return np.zeros(0, bool), np.zeros(0), np.zeros(0)
    if cfg.band is not None:
        lo = np.full(n, cfg.band[0])
        hi = np.full(n, cfg.band[1])
    else:
        row, _ = floor.at(columns.centres())
        lo = floor.zmin[row] + cfg.clearance_m
        hi = floor.zmax[row] - cfg.clearance_m
    top_bin = np.clip(np.floor((hi - lo) / cfg.bin_m).astype(np.int64), 0, 63)
    zlo = np.zeros(n)
    zhi = np.zeros(n)
    found = np.zeros(n, bool)
    # in blocks of cells: the bins unpacked are 64 booleans (and a few copies) a cell,
    # which over a mine's whole plan would be gigabytes at once
    for a in range(0, n, RUN_BLOCK_CELLS):
        b = min(a + RUN_BLOCK_CELLS, n)
        found[a:b], zlo[a:b], zhi[a:b] = _column_runs(columns.bins[a:b], lo[a:b], top_bin[a:b], cfg)
    return found & _level_with_neighbours(columns.keys, found, zlo, zhi, cfg), zlo, zhi


#: Cells whose height bins :func:`_panel_runs` unpacks at a time (tens of MB of arrays).
RUN_BLOCK_CELLS = 1 << 17


def _column_runs(
    bits: NDArray[np.uint64],
    lo: NDArray[np.float64],
    top_bin: NDArray[np.int64],
    cfg: DetectConfig,
) -> tuple[NDArray[np.bool_], NDArray[np.float64], NDArray[np.float64]]:
    """:func:`_panel_runs` for a block of cells, before the level test: whether each has
    a panel-like column, and its lowest and highest height."""
    n = bits.size
    # bit k of each cell's word as column k (a byte a bin, not eight)
    occupied = np.unpackbits(
        np.ascontiguousarray(bits, dtype="<u8").view(np.uint8).reshape(-1, 8),
        axis=1,
        bitorder="little",
    ).view(bool)
    grown = occupied.copy()
    grown[:, 1:] |= occupied[:, :-1]
    grown[:, :-1] |= occupied[:, 1:]
    closed = grown.copy()
    closed[:, 1:] &= grown[:, :-1]
    closed[:, :-1] &= grown[:, 1:]
    closed |= occupied
    pad = np.zeros((n, 1), bool)
    edges = np.diff(np.hstack([pad, closed, pad]).astype(np.int8), axis=1)
    cell_s, start = np.nonzero(edges == 1)
    cell_e, end = np.nonzero(edges == -1)  # exclusive, in the same order as the starts
    del cell_e
    height = (end - start) * cfg.bin_m
    # occupied bins of each run, from the cells' running counts
    counts = np.zeros((n, 65), np.int32)
    np.cumsum(occupied, axis=1, out=counts[:, 1:])
    filled = counts[cell_s, end] - counts[cell_s, start]
    ok = (
        (height >= cfg.min_panel_height_m)
        & (height <= cfg.max_panel_height_m + 2 * cfg.bin_m)
        & (start > 0)
        & (end - 1 < top_bin[cell_s])
        & (filled >= 0.5 * (end - start))
    )
    # each cell's tallest run (the lowest of equals)
    run = np.flatnonzero(ok)
    run = run[np.lexsort((start[run], -height[run], cell_s[run]))]
    run = run[np.r_[True, cell_s[run][1:] != cell_s[run][:-1]]] if run.size else run
    cell = cell_s[run]
    found = np.zeros(n, bool)
    zlo = np.zeros(n)
    zhi = np.zeros(n)
    found[cell] = True
    zlo[cell] = lo[cell] + (start[run] - 1) * cfg.bin_m
    zhi[cell] = lo[cell] + (end[run] + 1) * cfg.bin_m
    return found, zlo, zhi


def _dilated(
    keys: NDArray[np.int64], zlo: NDArray[np.float64], zhi: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """The panel cells and their eight neighbours, each with the heights of the panel
    columns beside it (the widest span).

    A panel's noisy points spread a few centimetres either side of it; a cell beside
    the panel holding only that tail is too sparse to pass as a column. Left out, it
    would cut the tail on one side only, wherever the grid happens to fall, and pull
    the fitted line off by a fraction of the noise (the line fits' errors were half as
    large again as their standard deviations); taken in, the line fit's own band
    decides.
    """
    if keys.size == 0:
        return keys, zlo, zhi
    ij = key_ij(keys)
    offs = [(0, 0), *EIGHT]
    allk = np.concatenate([pack_ij(ij + np.array(o)) for o in offs])
    lo = np.tile(zlo, len(offs))
    hi = np.tile(zhi, len(offs))
    order = np.argsort(allk, kind="stable")
    allk = allk[order]
    starts = np.flatnonzero(np.concatenate([[True], allk[1:] != allk[:-1]]))
    return (
        allk[starts],
        np.minimum.reduceat(lo[order], starts),
        np.maximum.reduceat(hi[order], starts),
    )


#: How far (in cells) :func:`_level_with_neighbours` looks for a lone column's neighbours.
LEVEL_REACH_CELLS = 3


def _level_with_neighbours(
    keys: NDArray[np.int64],
    found: NDArray[np.bool_],
    zlo: NDArray[np.float64],
    zhi: NDArray[np.float64],
    cfg: DetectConfig,
) -> NDArray[np.bool_]:
    """Columns with two or more neighbours (of the 8) whose columns start and end at the
    same heights (within 3 bins): a panel's top and bottom are level along it, the
    bits of rough rock that pass for a column in one cell are not.

    A lone column, with at most one of its 8 neighbours holding other points, may find
    its two within :data:`LEVEL_REACH_CELLS` cells instead: an oblique panel far from
    the scanner is seen in scan columns centimetres apart, a cell or two empty between
    them. Rock is seen in every cell around it, and keeps the nearer test.
    """
    rows = np.flatnonzero(found)
    k = keys[rows]
    tol = 3.0 * cfg.bin_m

    def agreeing(offsets: tuple[tuple[int, int], ...]) -> NDArray[np.int64]:
        agree = np.zeros(rows.size, np.int64)
        for hit, pos in neighbours(k, offsets):
            same = (np.abs(zhi[rows[pos]] - zhi[rows]) <= tol) & (
                np.abs(zlo[rows[pos]] - zlo[rows]) <= tol
            )
            agree += hit & same
        return agree

    near = agreeing(EIGHT)
    occupied = np.zeros(rows.size, np.int64)
    for hit, _ in neighbours(k, among=keys):
        occupied += hit
    lone = occupied - near <= 1
    ok = near >= 2
    if np.any(lone & ~ok):
        ok |= lone & (agreeing(within(LEVEL_REACH_CELLS)) >= 2)
    out = np.zeros(found.size, bool)
    out[rows] = ok
    return out


# --------------------------------------------------------------------------- plan pieces


@dataclass(frozen=True, eq=False)
class Panel:
    """A vertical plane found in the cloud: its plan line (a :class:`Segment`), its
    3D fit and its top edge.

    Attributes
    ----------
    segment : Segment
        The plan line; ``beams`` index the candidate points.
    tilt_deg : float
        Angle of the plane from the vertical.
    plane_rms_m : float
    height_m : float
        Extent of its points in z (2nd to 98th percentile).
    top_m, sigma_top_m : float
        Height of the top edge and its standard deviation.
    bottom_m : float
    time_s : float or None
        Median time of its points.
    """

    segment: Segment
    tilt_deg: float
    plane_rms_m: float
    height_m: float
    top_m: float
    sigma_top_m: float
    bottom_m: float
    time_s: float | None


@dataclass(frozen=True, eq=False)
class PlanPieces:
    """The candidates in plan: panels, the corners between them, rejected pieces."""

    segmentation: Segmentation
    panels: tuple[Panel, ...]
    rejected: dict[str, int] = field(default_factory=dict)


def beacon_top(panels: Sequence[Panel]) -> tuple[float, float]:
    """A beacon's top and its sigma from its panels' (they share one level): the weighted
    mean of the largest group of panel tops that agree within three combined sigmas (the
    best-placed group on a tie). A panel whose points ran on into a pipe, rock or an end
    wall above it (on simulated clouds, tops 0.2 to 1 m high, and at times the
    best-placed of the three) is outvoted by the two that agree; taking the best-placed
    panel as the one reference, as georef did, let such a panel decide alone."""
    tops = np.array([p.top_m for p in panels])
    sig = np.array([max(p.sigma_top_m, 1e-6) for p in panels])
    best: tuple[int, float, NDArray[np.bool_]] | None = None
    for ref in range(len(panels)):
        agree = np.abs(tops - tops[ref]) <= 3.0 * np.hypot(sig, sig[ref])
        key = (int(agree.sum()), -float(np.sum(1.0 / sig[agree] ** 2)))
        if best is None or key > (best[0], best[1]):
            best = (key[0], key[1], agree)
    assert best is not None
    w = 1.0 / sig[best[2]] ** 2
    return float(np.sum(w * tops[best[2]]) / np.sum(w)), float(1.0 / math.sqrt(float(np.sum(w))))


def _clusters(xy: NDArray[np.float64], cell_m: float) -> tuple[NDArray[np.intp], int]:
    """Cluster label of every point: cells touching (8-neighbours) are one cluster."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    keys = cell_keys(xy, np.zeros(2), cell_m)
    uniq, inv = np.unique(keys, return_inverse=True)
    rows, cols = [], []
    for hit, pos in neighbours(uniq):
        rows.append(np.flatnonzero(hit))
        cols.append(pos[hit])
    r = np.concatenate(rows) if rows else np.zeros(0, np.intp)
    c = np.concatenate(cols) if cols else np.zeros(0, np.intp)
    graph = coo_matrix((np.ones(r.size), (r, c)), shape=(uniq.size, uniq.size))
    n, label = connected_components(graph, directed=False)
    return np.asarray(label[inv], dtype=np.intp), int(n)


#: Points whose distances to every RANSAC try :func:`_lines_in` takes at a time.
RANSAC_BLOCK_POINTS = 1 << 14


def _lines_in(
    xy: NDArray[np.float64], noise: float, min_points: int, gap_m: float, seed: int = 0
) -> list[NDArray[np.intp]]:
    """Straight pieces of one cluster by sequential RANSAC: the line through two points
    with the most points within ``3 noise`` (a few hundred tries), refitted by total
    least squares, cut at gaps wider than ``gap_m`` along it; its longest run is a
    piece, taken out, and the search goes on while a piece of ``min_points`` is left.
    Junk beside a panel (rock, a pipe) does not bend its line, as it would bend a
    partition of the points in one order."""
    rng = np.random.default_rng(seed)
    left = np.arange(xy.shape[0])
    out: list[NDArray[np.intp]] = []
    band = 3.0 * noise
    while left.size >= min_points:
        p = xy[left]
        tries = min(300, left.size * (left.size - 1) // 2)
        i = rng.integers(0, left.size, tries)
        j = rng.integers(0, left.size, tries)
        d = p[j] - p[i]
        length = np.hypot(d[:, 0], d[:, 1])
        ok = length > 2.0 * band
        if not np.any(ok):
            break
        i, d, length = i[ok], d[ok], length[ok]
        nrm = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
        off = np.einsum("tk,tk->t", nrm, p[i])
        # inliers of every try, counted in blocks of points (a dense cluster holds
        # hundreds of thousands: all at once would be a tries x points matrix)
        counts = np.zeros(i.size, np.int64)
        for a in range(0, p.shape[0], RANSAC_BLOCK_POINTS):
            blk = p[a : a + RANSAC_BLOCK_POINTS]
            counts += (np.abs(blk @ nrm.T - off) <= band).sum(axis=0)
        best = int(np.argmax(counts))
        inl = np.flatnonzero(np.abs(p @ nrm[best] - off[best]) <= band)
        run = None
        for _ in range(2):  # refit, gather again
            if inl.size < 2:
                break
            line = fit_line(p[inl])
            c, u, n = line.centroid, line.direction, line.normal
            near = np.flatnonzero(np.abs((p - c) @ n) <= band)
            t = (p[near] - c) @ u
            order = np.argsort(t)
            cuts = np.flatnonzero(np.diff(t[order]) > gap_m) + 1
            runs = np.split(order, cuts)
            run = max(runs, key=len)
            inl = near[run]
        if inl.size < min_points:
            break
        out.append(left[inl])
        left = np.delete(left, inl)
    return out


#: Pieces of different clusters are joined across gaps of up to this many column cells.
JOIN_GAP_CELLS = 4
#: A joined piece's points are this many times the noise about its line, at most (RMS).
JOIN_RMS_NOISE = 1.5


def _joined(
    pieces: list[tuple[int, NDArray[np.intp]]],
    xyz: NDArray[np.float64],
    noise: float,
    gap_m: float,
    bin_m: float,
) -> list[tuple[int, NDArray[np.intp]]]:
    """Pieces of one panel that the clusters cut apart, joined.

    An oblique panel far from the scanner is seen in scan columns centimetres apart;
    where the column cells leave a cell empty between two columns, the panel falls
    into clusters of its own. Two pieces of different clusters are one when their ends
    are within ``gap_m``, their heights agree (lowest and highest within three
    ``bin_m``), and their points together lie on one line: no gap wider than ``gap_m``
    along it and an RMS of at most :data:`JOIN_RMS_NOISE` noises about it. Closest
    ends first; a piece joins a chain of pieces as a whole.

    The clusters of any two pieces whose ends meet so, on one line or not, become one:
    a corner is looked for between pieces of one cluster, and where the corner's own
    columns fell out of the column cells, its two panels lie in clusters apart.
    """
    if len(pieces) < 2:
        return pieces
    from scipy.spatial import cKDTree

    xy = xyz[:, :2]
    ends = np.zeros((2 * len(pieces), 2))
    zlim = np.zeros((len(pieces), 2))
    for k, (_, rows) in enumerate(pieces):
        line = fit_line(xy[rows])
        t = (xy[rows] - line.centroid) @ line.direction
        ends[2 * k] = line.centroid + t.min() * line.direction
        ends[2 * k + 1] = line.centroid + t.max() * line.direction
        zlim[k] = xyz[rows, 2].min(), xyz[rows, 2].max()
    pairs = cKDTree(ends).query_pairs(gap_m, output_type="ndarray")
    if pairs.size == 0:
        return pieces
    a, b = pairs[:, 0] // 2, pairs[:, 1] // 2
    cluster = np.array([c for c, _ in pieces])
    ok = (cluster[a] != cluster[b]) & np.all(np.abs(zlim[a] - zlim[b]) <= 3.0 * bin_m, axis=1)
    gap = np.hypot(*(ends[pairs[:, 0]] - ends[pairs[:, 1]]).T)
    order = np.flatnonzero(ok)[np.argsort(gap[ok], kind="stable")]
    chain = list(range(len(pieces)))  # the chain each piece is in (its first piece)
    members: dict[int, list[int]] = {k: [k] for k in range(len(pieces))}
    for i, j in zip(a[order].tolist(), b[order].tolist(), strict=True):
        ci, cj = chain[i], chain[j]
        if ci == cj:
            continue
        rows = np.concatenate([pieces[k][1] for k in members[ci] + members[cj]])
        line = fit_line(xy[rows])
        q = xy[rows] - line.centroid
        t = np.sort(q @ line.direction)
        if line.rms > JOIN_RMS_NOISE * noise or np.max(np.diff(t)) > gap_m:
            continue
        for k in members[cj]:
            chain[k] = ci
        members[ci] += members.pop(cj)
    # the clusters of two pieces whose ends meet become one (the lowest label)
    parent = {int(c): int(c) for c in cluster}

    def root(c: int) -> int:
        while parent[c] != c:
            c = parent[c]
        return c

    for i, j in zip(a[ok].tolist(), b[ok].tolist(), strict=True):
        ri, rj = root(int(cluster[i])), root(int(cluster[j]))
        parent[max(ri, rj)] = min(ri, rj)
    out = []
    for chain_members in members.values():
        rows = np.concatenate([pieces[k][1] for k in chain_members])
        out.append((root(int(cluster[chain_members[0]])), rows))
    return out


def _height_runs(z: NDArray[np.float64], bin_m: float) -> list[NDArray[np.intp]]:
    """The points of a plan piece in runs of heights (gaps of more than three empty bins
    cut them): a pipe above a panel, or the rock of the wall above it, shares its plan
    line, not its heights."""
    order = np.argsort(z)
    cuts = np.flatnonzero(np.diff(z[order]) > 3.0 * bin_m) + 1
    return [np.asarray(r, dtype=np.intp) for r in np.split(order, cuts)]


def _even_stretches(xyz: NDArray[np.float64], bin_m: float) -> list[NDArray[np.intp]]:
    """A plan piece's points cut into stretches of even heights along its line: its
    points in bins along the line (``bin_m``, or longer where fewer than
    :data:`EVEN_BIN_POINTS` points would fall in one), neighbouring bins whose 10th and
    90th height percentiles stay within three ``bin_m`` of each other in one stretch. A
    panel's line may run on over the rock beside or behind it (within the noise band
    the rock crosses it for centimetres or metres), whose points reach from floor to
    roof: with them, the piece would be no panel."""
    line = fit_line(xyz[:, :2])
    t = (xyz[:, :2] - line.centroid) @ line.direction
    span = float(np.ptp(t))
    width = max(bin_m, EVEN_BIN_POINTS * span / max(t.size, 1))
    bins = max(1, round(span / width))  # the last bin is no sliver of a few points
    k = np.minimum((t - float(t.min())) * (bins / max(span, 1e-12)), bins - 1).astype(np.intp)
    order = np.lexsort((xyz[:, 2], k))
    ks, z = k[order], xyz[order, 2]
    first = np.flatnonzero(np.r_[True, np.diff(ks) > 0])
    count = np.diff(np.r_[first, ks.size])
    # a bin's heights by its 10th and 90th percentiles: a few rock points in the band
    # above or below a panel do not move them
    lo = z[first + (0.1 * (count - 1)).astype(np.intp)]
    hi = z[first + (0.9 * (count - 1)).astype(np.intp)]
    tol = 3.0 * bin_m
    same = (np.diff(ks[first]) <= 2) & (np.abs(np.diff(lo)) <= tol) & (np.abs(np.diff(hi)) <= tol)
    ends = np.r_[first, ks.size]
    return [
        np.asarray(order[ends[r[0]] : ends[r[-1] + 1]], dtype=np.intp)
        for r in np.split(np.arange(first.size), np.flatnonzero(~same) + 1)
    ]


#: Fewest points a bin of :func:`_even_stretches` is made to hold.
EVEN_BIN_POINTS = 20


def _top_edge(z: NDArray[np.float64], noise: float) -> tuple[float, float, float]:
    """Top edge of a panel from its points' heights, and its standard deviation; and
    the bottom edge.

    With points spread up the panel at ``lam`` per metre and symmetric noise, the count
    above any level ``r`` well below the top is ``lam (top - r)`` (noise moves as many
    points up across the edge as it loses), so ``top = r + count / lam``; ``r`` is
    ``3 sigma`` below a first estimate. The density is the one at ``r``: a scanner's
    points thin out (or crowd) up a panel as its range and incidence change along it,
    so ``lam`` is extrapolated to ``r`` from the count and mean height of the points
    in the band below it (a density linear in height: ``lam(r) = N / B (1 + 6 m / B)``
    for ``N`` points in a band of height ``B`` whose mean lies ``m`` above its middle).
    An even density assumed over the panel's middle, as before, put the tops of
    simulated SLAM clouds 3-4 mm low on average.
    """
    lo, hi = np.quantile(z, [0.02, 0.98])
    height = float(hi - lo)
    mid = (z > lo + 0.25 * height) & (z < hi - 0.25 * height)
    n_mid = int(mid.sum())
    even = n_mid / max(0.5 * height, 1e-9)
    top = float(hi)
    window = max(3.0 * noise, 0.01)
    above = 0
    lam, n_band = even, n_mid
    factor = 1.0
    for _ in range(3):
        ref = top - window
        above = int(np.count_nonzero(z > ref))
        band = max(ref - (float(lo) + window), 1e-9)
        inside = z[(z > ref - band) & (z <= ref)]
        n_band = int(inside.size)
        if n_band >= 10:
            m = float(np.mean(inside)) - (ref - 0.5 * band)
            # never more than five times or less than a fifth of the band's mean density:
            # beyond that the band's own scatter decides, not the panel
            factor = min(max(1.0 + 6.0 * m / band, 0.2), 5.0)
            lam = n_band / band * factor
        else:
            factor, lam, n_band = 1.0, even, n_mid
        top = ref + above / max(lam, 1e-9)
    # the count above, and the density at the reference extrapolated from the band: a
    # linear fit's end, twice the standard error of the band's mean density, over the
    # factor that carried the mean to the end
    rel = 2.0 / math.sqrt(max(n_band, 1)) / factor
    reach = max(above / max(lam, 1e-9), window)  # how far the density carries the top
    sigma = math.sqrt(above / max(lam, 1e-9) ** 2 + (reach * rel) ** 2)
    below = int(np.count_nonzero(z < float(lo) + window))
    bottom = float(lo) + window - below / max(even, 1e-9)
    return top, sigma, bottom


def _plane(points: NDArray[np.float64]) -> tuple[float, float]:
    """Tilt from the vertical (degrees) and RMS of a plane fitted to 3D points."""
    c = points - points.mean(axis=0)
    _, s, vt = np.linalg.svd(c, full_matrices=False)
    normal = vt[-1]
    tilt = math.degrees(math.asin(min(1.0, abs(float(normal[2])))))
    return tilt, float(s[-1] / math.sqrt(points.shape[0]))


def _segment(
    index: int,
    cluster: int,
    rows: NDArray[np.intp],
    xy: NDArray[np.float64],
    noise: float,
    trim_m: float,
) -> Segment:
    """A plan :class:`Segment` of a piece (``rows``: its candidate points)."""
    line = fit_line(xy)  # directed from the first point towards the last
    c, d, n = line.centroid, line.direction, line.normal
    q = xy - c
    t = q @ d
    order = np.argsort(t)
    t_sorted = t[order]
    spread = float(np.sum(t**2))
    return Segment(
        index=index,
        run=cluster,
        beams=rows[order],
        points=xy[order],
        centroid=c,
        direction=d,
        normal=n,
        length=float(t_sorted[-1] - t_sorted[0]),
        start=c + t_sorted[0] * d,
        end=c + t_sorted[-1] * d,
        rms=float(np.sqrt(np.mean((q @ n) ** 2))),
        sigma_direction=noise / math.sqrt(spread) if spread > 0 else math.inf,
        spacing_start=trim_m,
        spacing_end=trim_m,
    )


def _reversed(seg: Segment, index: int) -> Segment:
    return Segment(
        index=index,
        run=seg.run,
        beams=seg.beams[::-1],
        points=seg.points[::-1],
        centroid=seg.centroid,
        direction=-seg.direction,
        normal=-seg.normal,
        length=seg.length,
        start=seg.end,
        end=seg.start,
        rms=seg.rms,
        sigma_direction=seg.sigma_direction,
        spacing_start=seg.spacing_end,
        spacing_end=seg.spacing_start,
    )


#: Lines closer to parallel than this sine (3 degrees) meet nowhere in particular.
NEARLY_PARALLEL_SINE = 0.05
#: A piece whose points are more than this share another, larger piece's, along nearly
#: the same line (:data:`NEARLY_PARALLEL_SINE`), is that piece.
DUPLICATE_SHARE = 0.5
#: A panel's points, top, its standard deviation and bottom.
_Tall = tuple[NDArray[np.intp], float, float, float]


def panel_from_points(
    xyz: NDArray[np.float64], noise: float, cfg: DetectConfig = DetectConfig()
) -> Panel | str:
    """A :class:`Panel` of points gathered on one face by other means than the piece
    search (where a design says a panel must stand), tested as the pieces' are: its
    plane vertical and flat (:func:`_plane`), its top and bottom (:func:`_top_edge`)
    within the heights a panel may have. Otherwise the reason, as in
    :attr:`PlanPieces.rejected`. Its segment's ``beams`` index ``xyz`` (not the
    candidates), and its ``index`` and ``run`` are -1: it is in no segmentation."""
    if xyz.shape[0] < cfg.min_points:
        return "too_few_points"
    tilt, rms = _plane(xyz)
    why = _not_a_plane(tilt, rms, noise, cfg)
    if why is not None:
        return why
    top, sigma_top, bottom = _top_edge(xyz[:, 2], noise)
    if top - bottom < cfg.min_panel_height_m:
        return "too_short"
    if top - bottom > cfg.max_panel_height_m:
        return "too_tall"
    rows = np.arange(xyz.shape[0])
    seg = _segment(-1, -1, rows, xyz[:, :2], noise, 2.0 * cfg.cell_m)
    return Panel(seg, tilt, rms, top - bottom, top, sigma_top, bottom, None)


def _not_a_plane(tilt: float, rms: float, noise: float, cfg: DetectConfig) -> str | None:
    if tilt > cfg.max_tilt_deg:
        return "not_vertical"
    if rms > 3.0 * noise:
        return "not_flat"
    return None


def _duplicates(
    pieces: list[NDArray[np.intp]], xy: NDArray[np.float64], n: int
) -> NDArray[np.bool_]:
    """Which pieces are mostly the points of a larger one along nearly its line (a short
    streak of mixed returns crossing a panel at a shallow angle finds the panel's points
    again): left out, or their 'corners' with the panel would cut it short. A short
    panel at a shallow corner shares many points with its neighbour too, but not its
    line."""
    owner = np.full(n, -1, dtype=np.intp)
    directions = [fit_line(xy[rows]).direction for rows in pieces]
    out = np.zeros(len(pieces), dtype=bool)
    for k in sorted(range(len(pieces)), key=lambda k: -pieces[k].size):
        rows = pieces[k]
        held = owner[rows]
        held = held[held >= 0]
        if held.size > DUPLICATE_SHARE * rows.size:
            j = int(np.bincount(held).argmax())
            (a0, a1), (b0, b1) = directions[k], directions[j]
            sine = abs(float(a0 * b1 - a1 * b0))
            if sine < NEARLY_PARALLEL_SINE:
                out[k] = True
                continue
        owner[rows[owner[rows] < 0]] = k
    return out


def plan_pieces(cand: Candidates, cfg: DetectConfig = DetectConfig()) -> PlanPieces:
    """Clusters, straight pieces, vertical panels and their corners (module docstring).

    The segmentation's segments come in pairs: ``k`` and ``k + n`` are one piece in
    both directions, so that every corner can be met with its first piece ending
    at the node and its second starting there, as a scan meets them.
    """
    xyz = cand.xyz
    rejected = {
        "too_few_points": 0,
        "not_vertical": 0,
        "not_flat": 0,
        "too_short": 0,
        "too_tall": 0,
        "duplicate": 0,
    }
    if xyz.shape[0] == 0:
        return PlanPieces(Segmentation((), (), cfg.noise_m or 0.0), (), rejected)
    from scipy.spatial import cKDTree

    xy = xyz[:, :2]
    core = np.flatnonzero(cand.core)
    noise = cfg.noise_m if cfg.noise_m is not None else plan_noise_from_neighbours(xy[core])
    noise = max(noise, 1e-4)
    tree = cKDTree(xy)
    core_label, _ = _clusters(xy[core], cfg.cell_m)
    label = np.full(xy.shape[0], -1, dtype=np.intp)
    label[core] = core_label
    by_cluster = core[np.argsort(core_label, kind="stable")]
    bounds = np.flatnonzero(np.diff(label[by_cluster])) + 1
    pieces: list[tuple[int, NDArray[np.intp]]] = []
    for group in np.split(by_cluster, bounds):
        if group.size < cfg.min_points:
            rejected["too_few_points"] += 1
            continue
        for rows in _lines_in(xy[group], noise, cfg.min_points, 2.0 * cfg.cell_m):
            rows = group[rows]
            for run in _height_runs(xyz[rows, 2], cfg.bin_m):
                if run.size >= cfg.min_points:
                    pieces.append((int(label[group[0]]), rows[run]))
    pieces = _joined(pieces, xyz, noise, JOIN_GAP_CELLS * cfg.cell_m, cfg.bin_m)
    kept: list[tuple[int, NDArray[np.intp], float, float]] = []
    failed: list[tuple[int, NDArray[np.intp], str]] = []
    for cluster, rows in pieces:
        if rows.size < cfg.min_points:
            rejected["too_few_points"] += 1
            continue
        tilt, rms = _plane(xyz[rows])
        why = _not_a_plane(tilt, rms, noise, cfg)
        if why is not None:
            failed.append((cluster, rows, why))
            continue
        kept.append((cluster, rows, tilt, rms))
    if cfg.noise_m is None and kept:
        noise = _panel_noise(kept, xyz, tree, noise)

    def as_panel(rows: NDArray[np.intp]) -> _Tall | str:
        # the piece's points found again among all candidates, its noise's tails with them
        rows = _near_line(rows, xyz, tree, 3.0 * noise, 1.0)
        top, sigma_top, bottom = _top_edge(xyz[rows, 2], noise)
        if top - bottom < cfg.min_panel_height_m:
            return "too_short"
        if top - bottom > cfg.max_panel_height_m:
            return "too_tall"
        return rows, top, sigma_top, bottom

    tall: list[tuple[int, float, float, _Tall]] = []
    for cluster, rows, tilt, rms in kept:
        done = as_panel(rows)
        if isinstance(done, str):
            failed.append((cluster, rows, done))
        else:
            tall.append((cluster, tilt, rms, done))
    # a piece that is no panel as a whole may be one along a stretch of even heights: a
    # panel's line runs on over the rock beside it (in a dense scan's narrow band the
    # rough rock crosses it for centimetres), and the rock reaches from floor to roof
    for cluster, rows, why in failed:
        for part in _even_stretches(xyz[rows], cfg.bin_m):
            sub = rows[part]
            if not cfg.min_points <= sub.size < rows.size:
                continue
            tilt, rms = _plane(xyz[sub])
            if _not_a_plane(tilt, rms, noise, cfg) is None:
                done = as_panel(sub)
                if not isinstance(done, str):
                    tall.append((cluster, tilt, rms, done))
                    why = ""
        if why:
            rejected[why] += 1
    # a piece that finds mostly points a larger one holds is that piece (a short streak
    # of mixed returns crossing a panel finds the panel again): it is left out, or its
    # corners with the panel would cut the panel short
    duplicate = _duplicates([t[3][0] for t in tall], xy, xyz.shape[0])
    rejected["duplicate"] = int(np.count_nonzero(duplicate))
    panels: list[Panel] = []
    for (cluster, tilt, rms, (rows, top, sigma_top, bottom)), dup in zip(
        tall, duplicate, strict=True
    ):
        if dup:
            continue
        # a free end may lose a cell or two where it meets the wall (the column test)
        seg = _segment(len(panels), cluster, rows, xy[rows], noise, 2.0 * cfg.cell_m)
        t = None if cand.time is None else float(np.median(cand.time[rows]))
        panels.append(Panel(seg, tilt, rms, top - bottom, top, sigma_top, bottom, t))
    segs = [p.segment for p in panels]
    corners = _corners(segs, noise)
    segs = _trimmed(segs, corners, xy, noise, 2.0 * cfg.cell_m)
    panels = [replace(p, segment=sg) for p, sg in zip(panels, segs, strict=True)]
    corners = _corners(segs, noise)
    n = len(segs)
    both = segs + [_reversed(s, n + k) for k, s in enumerate(segs)]
    return PlanPieces(Segmentation(tuple(both), tuple(corners), noise), tuple(panels), rejected)


def _near_line(
    rows: NDArray[np.intp],
    xyz: NDArray[np.float64],
    tree: object,
    band: float,
    middle: float,
) -> NDArray[np.intp]:
    """The candidates within ``band`` of a piece's plan line, along the middle
    ``middle`` share of its extent and within its heights (and 3 bands beyond)."""
    p = xyz[rows, :2]
    line = fit_line(p)
    c = line.centroid
    t = (p - c) @ line.direction
    a0, a1 = float(t.min()), float(t.max())
    cut = 0.5 * (1.0 - middle) * (a1 - a0)
    a0, a1 = a0 + cut, a1 - cut
    reach = max(abs(a0), abs(a1)) + band
    found = np.asarray(tree.query_ball_point(c, reach), dtype=np.intp)  # type: ignore[attr-defined]
    q = xyz[found, :2] - c
    along, across = q @ line.direction, q @ line.normal
    z = xyz[found, 2]
    z0, z1 = float(xyz[rows, 2].min()), float(xyz[rows, 2].max())
    near = (
        (along >= a0)
        & (along <= a1)
        & (np.abs(across) <= band)
        & (z >= z0 - 3.0 * band)
        & (z <= z1 + 3.0 * band)
    )
    return np.sort(found[near])


def _panel_noise(
    kept: list[tuple[int, NDArray[np.intp], float, float]],
    xyz: NDArray[np.float64],
    tree: object,
    noise: float,
) -> float:
    """The noise across the panels: the median, over the flattest pieces, of each
    piece's own RMS about its line.

    A piece holds only points within 3 noise of the first estimate, which cuts its
    tails; so each piece's RMS is found again from the candidates within 4 of its own
    RMS of its line, along the middle half of its extent (clear of the corners), six
    times over (a band of 4 sigma keeps all but 0.006 % of the points, and the RMS
    within it is 0.999 sigma). Panels are the flattest surfaces that pass: rock and
    clutter that pass too only have larger RMS, and may be most of the pieces, so
    the estimate is the median of the flattest group (the pieces within 1.25 times the
    lowest decile).
    """
    rms = []
    for _cluster, rows, _tilt, plane_rms in kept:
        # a short piece's line takes up part of its noise: long ones only
        p = xyz[rows, :2]
        if rows.size < 100 or float(np.max(np.ptp(p, axis=0))) < 0.15:
            continue
        own: float | None = max(plane_rms, noise, 1e-4)
        for _ in range(6):
            assert own is not None
            near = _near_line(rows, xyz, tree, 4.0 * own, 0.5)
            if near.size < 15:
                own = None  # too short to say: left out
                break
            own = max(fit_line(xyz[near, :2]).rms, 1e-4)
        if own is not None:
            rms.append(own)
    if not rms:
        return noise
    r = np.array(rms)
    flat = r[r <= 1.25 * np.quantile(r, 0.1)]
    return float(np.median(flat))


def _trimmed(
    segs: list[Segment], corners: list[Corner], xy: NDArray[np.float64], noise: float, trim: float
) -> list[Segment]:
    """Pieces refitted without their points near a corner.

    Within ``3 noise / sin(deflection) + 3 noise`` of where two lines meet, a point
    may belong to either: which line took it depends on its noise across them,
    and that choice bends both lines towards each other (a shallow corner's node
    then slides along them by centimetres). Leaving out, from both, every point
    within that distance of the node along its own line (which the noise across
    it hardly moves) keeps the fits unbiased. Points past the node are left out too.
    A node that is nowhere in particular (:data:`NEARLY_PARALLEL_SINE`) trims nothing,
    and each end of a piece is trimmed by one corner alone, its strongest.
    """
    n = len(segs)
    # each end of a piece is trimmed by one corner alone, the one with the piece of the
    # most points: a streak of mixed returns meeting a panel's face along the beam
    # makes a 'corner' inside the panel, weaker than its neighbour's
    ends: dict[tuple[int, float], tuple[int, NDArray[np.bool_]]] = {}
    for c in corners:
        if (
            abs(math.sin(c.deflection)) < NEARLY_PARALLEL_SINE
            or max(segs[c.first % n].sigma_direction, segs[c.second % n].sigma_direction)
            > NEARLY_PARALLEL_SINE
        ):
            # two lines that nearly coincide, or one whose direction is not known to a
            # few degrees (a few mixed returns, millimetres long): their node may be
            # anywhere along the other
            continue
        reach = 3.0 * noise / abs(math.sin(c.deflection)) + 3.0 * noise
        a, b = c.first % n, c.second % n
        for k, j in ((a, b), (b, a)):
            sg = segs[k]
            t = (sg.points - c.node) @ sg.direction
            # and every point past the node: a panel ends at its corner (what lies
            # beyond, within the line's band, is the neighbour or the wall)
            side = 1.0 if float(np.median(t)) >= 0 else -1.0
            if (k, side) not in ends or len(segs[j]) > ends[(k, side)][0]:
                ends[(k, side)] = (len(segs[j]), (np.abs(t) < reach) | (side * t < 0))
    drop: dict[int, NDArray[np.bool_]] = {}
    for (k, _), (_, near) in ends.items():
        drop[k] = drop.get(k, np.zeros(len(segs[k]), bool)) | near
    out = []
    for k, sg in enumerate(segs):
        gone = drop.get(k)
        if gone is None or (~gone).sum() < 3:
            out.append(sg)
            continue
        rows = sg.beams[~gone]
        out.append(_segment(k, sg.run, rows, xy[rows], noise, trim))
    return out


def _corners(segs: list[Segment], noise: float) -> list[Corner]:
    """Corners between pieces of one cluster whose lines meet near an end of each.

    The first piece is taken in the direction that ends at the node and the
    second in the one that starts there (index ``k + n`` is piece ``k`` reversed).
    """
    n = len(segs)
    reach = 0.20 + 4.0 * noise
    out: list[Corner] = []
    by_run: dict[int, list[Segment]] = {}
    for s in segs:
        by_run.setdefault(s.run, []).append(s)
    for group in by_run.values():
        for ai in range(len(group)):
            for bi in range(ai + 1, len(group)):
                a, b = group[ai], group[bi]
                node = intersect_lines(
                    a.centroid, a.direction, b.centroid, b.direction, min_sine=1e-6
                )
                if node is None:
                    continue
                da_end = float(np.hypot(*(a.end - node)))
                da_start = float(np.hypot(*(a.start - node)))
                db_end = float(np.hypot(*(b.end - node)))
                db_start = float(np.hypot(*(b.start - node)))
                if min(da_end, da_start) > reach or min(db_end, db_start) > reach:
                    continue
                first = a.index if da_end <= da_start else a.index + n
                second = b.index if db_start <= db_end else b.index + n
                d1 = a.direction if first == a.index else -a.direction
                d2 = b.direction if second == b.index else -b.direction
                defl = math.atan2(d1[0] * d2[1] - d1[1] * d2[0], float(d1 @ d2))
                out.append(Corner(first, second, defl, node))
    return out
