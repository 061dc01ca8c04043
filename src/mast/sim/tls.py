"""Simulated terrestrial laser scans (TLS) of a drift with beacons, already in the mine grid.

What ``mast survey-in`` starts from: a phase-based scanner set up on a tripod over
control at one or more stations along a drift, levelled and oriented, so that every
scan's pose in the grid is known (the E57 file carries it, as every TLS package writes
it). The scanner is simulated by casting its rays:

* **Geometry** (a drift frame: x along the drift from 0 to ``length_m``, y across it,
  z up from the floor): two walls at ``y = ±width_m / 2``, a floor and a roof, end
  walls. The rock is rough: every wall, the floor and the roof are displaced along
  their normal by a sum of random waves (wavelengths 0.15-3 m) of standard deviation
  ``roughness_m``. The drift is then placed in the grid (easting, northing and
  elevation of its start, and its bearing).
* **Beacons**: ``beacons`` of them, of ``designs`` distinct designs (the paper's hat
  and random identifiable hats), bolted to alternate walls along the drift, each a
  rigid body (a beacon on the far wall is the same shape turned half a turn, never a
  mirror image), its panels vertical rectangles ``panel_height_m`` tall with their
  tops ``beacon_top_m`` above the floor; the free ends stand off the rock by its
  roughness so that no bump pokes through a panel.
* **Rays**: the scanner's angular step is ``step_rad`` (4 mm at 10 m by default), on a
  levelled head ``scanner_height_m`` above the floor. Every beacon within
  ``max_range_m`` is scanned at full resolution over an angular window around it (its
  box grown by ``margin_m``), the step widened where it would give points closer than
  ``min_spacing_m`` (a surveyor does not scan a near wall at 0.4 mm); the rest of the
  dome (floor, roof and walls, for context and for the floor and roof a detector
  looks for) at ``overview_step_rad``. Each ray takes the nearest surface it meets
  (panels hide the rock behind them), its range gets Gaussian noise
  ``range_noise_m`` and beyond ``max_range_m`` it has no return.
* **What a real scan adds** (each off by default, the benchmark turns them on): a
  beam ``beam_exit_m`` wide at the exit, diverging, whose footprint on a panel's
  boundary mixes the panel's range with what lies behind (a phase-based scanner's
  mixed pixel); panels bulging ``panel_bow_m`` at their middle; each station's setup
  ``station_sigma_m`` off per horizontal coordinate (the E57 pose is the written one,
  ``truth.json`` the true one).

Files written into the output folder:

* ``scans.e57``: one scan per station, points in the scanner's own frame (x along its
  zero direction, z up) with the station's pose in the grid (translation and a
  rotation about the vertical), intensity (panels bright, rock dull).
* ``designs.csv``: the designs, one beacon per design in its own frame (wall along +x,
  the drift at +y), 5 m apart (the survey contract; each beacon's id is its design's
  name).
* ``beacons.csv``: the true survey: each beacon's edges in the grid, the elevation of
  each edge's top, its ``design``.
* ``truth.json``: the options, the stations' poses, and per beacon its design, wall,
  stations within range and points on each panel.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Beacon, Survey
from mast.errors import InputError
from mast.io.atomic import atomic_path, write_atomic
from mast.io.beacons_csv import write_survey
from mast.sim.design import BeaconDesign, paper_design, random_design

__all__ = ["TlsOptions", "TlsScenario", "simulate_tls"]

Array = NDArray[np.float64]

#: Intensity (0..1) of a panel's retro-reflective face and of rock.
PANEL_INTENSITY, ROCK_INTENSITY = 0.9, 0.25
#: Rays cast at once (memory: about 40 bytes a ray and surface).
RAY_CHUNK = 1 << 20


@dataclass(frozen=True, slots=True)
class TlsOptions:
    """What to simulate (lengths in metres, angles in radians unless named).

    Attributes
    ----------
    length_m, width_m, height_m : float
        The drift's length, width and height.
    beacons, designs : int
        Beacons mounted, and distinct designs among them (the paper's hat first).
    stations : int
        Tripod stations, spread evenly along the drift's centre line.
    range_noise_m : float
        Standard deviation of a range (a phase-based scanner: 1-2 mm).
    step_rad : float
        The scanner's angular step (0.0004: 4 mm at 10 m).
    min_spacing_m : float
        Points on a near surface are no closer than this (the step is widened there).
    overview_step_rad : float
        The step of the rest of the dome.
    max_range_m : float
        Longest range with a return.
    roughness_m : float
        Standard deviation of the rock's surface about its mean plane.
    panel_height_m, beacon_top_m : float
        Panel height, and height of the panels' tops above the floor.
    scanner_height_m : float
        The scanner's centre above the floor.
    margin_m : float
        A beacon's window reaches this far beyond it.
    station_sigma_m : float
        Standard deviation of each station's setup per horizontal coordinate: the pose
        written in the E57 is off the true one by this much (0: exact).
    panel_bow_m : float
        A panel's bulge at its middle (a dome across its length and height): real
        panels are flat to a millimetre, not to the micron.
    beam_exit_m, beam_divergence_rad : float
        The beam's diameter at the exit and its divergence. Where the footprint straddles
        a panel's boundary, the return is a mixed pixel: a phase-based scanner averages
        the ranges under it, weighted by the share on each (0: a beam without width).
    origin : tuple of float
        Easting, northing and elevation of the drift's start (floor, centre line).
    bearing_deg : float
        The drift's direction, clockwise from grid north.
    """

    length_m: float = 40.0
    width_m: float = 5.0
    height_m: float = 4.5
    beacons: int = 4
    designs: int = 2
    stations: int = 2
    range_noise_m: float = 0.0015
    step_rad: float = 0.0004
    min_spacing_m: float = 0.002
    overview_step_rad: float = 0.01
    max_range_m: float = 40.0
    roughness_m: float = 0.03
    panel_height_m: float = 0.5
    beacon_top_m: float = 2.0
    scanner_height_m: float = 1.5
    margin_m: float = 0.4
    station_sigma_m: float = 0.0
    panel_bow_m: float = 0.0
    beam_exit_m: float = 0.0
    beam_divergence_rad: float = 0.0003
    origin: tuple[float, float, float] = (25_000.0, 71_000.0, -840.0)
    bearing_deg: float = 57.0


@dataclass(frozen=True, slots=True)
class TlsScenario:
    """The files written and what is in them."""

    folder: Path
    e57: Path
    designs: Path
    survey: Path
    truth: Path
    points: int
    stations: tuple[tuple[float, float, float, float], ...]  # E, N, elevation, azimuth deg
    beacons: tuple[str, ...] = field(default=())


# --------------------------------------------------------------------------- the scene


@dataclass(frozen=True, slots=True)
class _Rough:
    """A rough surface's displacement along its normal: a sum of plane waves."""

    k: Array  # (m, 2) wave vectors, rad/m
    phase: Array  # (m,)
    amp: Array  # (m,)

    @classmethod
    def draw(cls, rng: np.random.Generator, sigma: float, waves: int = 24) -> _Rough:
        wavelength = np.exp(rng.uniform(math.log(0.15), math.log(3.0), waves))
        angle = rng.uniform(0.0, math.pi, waves)
        k = (2 * math.pi / wavelength)[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
        amp = wavelength**0.8  # longer waves are larger, as in rock
        amp *= sigma * math.sqrt(2.0) / math.sqrt(float(np.sum(amp**2)))
        return cls(k, rng.uniform(0.0, 2 * math.pi, waves), amp)

    def __call__(self, u: Array, v: Array) -> Array:
        arg = np.multiply.outer(u, self.k[:, 0]) + np.multiply.outer(v, self.k[:, 1]) + self.phase
        out: Array = np.sin(arg) @ self.amp
        return out


@dataclass(frozen=True, slots=True)
class _Panel:
    a: Array  # (2,) drift frame, plan
    b: Array
    z0: float
    z1: float
    beacon: int
    index: int  # 0, 1, 2


@dataclass(frozen=True, slots=True)
class _Mounted:
    name: str
    design: BeaconDesign
    edges: Array  # (4, 2) drift frame
    wall: int  # -1: y = -w/2, +1: y = +w/2
    top_z: float


def _designs(count: int, rng: np.random.Generator) -> list[BeaconDesign]:
    """The paper's hat, then random identifiable hats, each named and distinct."""
    out = [BeaconDesign("hat-1.0", paper_design(1.0, 0.2).edges_local)]
    while len(out) < count:
        d = random_design(rng, chord_range_m=(0.7, 1.6))
        lengths = np.hypot(*np.diff(d.edges_local, axis=0).T)
        if all(
            np.max(np.abs(lengths - np.hypot(*np.diff(o.edges_local, axis=0).T))) > 0.08
            for o in out
        ):
            out.append(BeaconDesign(f"hat-{len(out) + 1}", d.edges_local))
    return out[:count]


def _mount(o: TlsOptions, designs: list[BeaconDesign], rng: np.random.Generator) -> list[_Mounted]:
    """Beacons along the drift, on alternate walls, evenly spaced, clear of the ends."""
    out = []
    span = o.length_m - 4.0
    standoff = 3.0 * o.roughness_m + 0.01
    for k in range(o.beacons):
        design = designs[k % len(designs)]
        x = 2.0 + span * (k + 0.5) / o.beacons + rng.uniform(-0.5, 0.5)
        wall = -1 if k % 2 == 0 else 1
        local = design.edges_local - np.array([design.chord_m / 2, 0.0])
        local = local + np.array([0.0, standoff])
        if wall < 0:  # wall at -w/2, the drift towards +y: design axes as they are
            edges = np.column_stack([x + local[:, 0], -o.width_m / 2 + local[:, 1]])
        else:  # the same body turned half a turn onto the far wall
            edges = np.column_stack([x - local[:, 0], o.width_m / 2 - local[:, 1]])
        out.append(_Mounted(f"T{k + 1:02d}", design, edges, wall, o.beacon_top_m))
    return out


def _panels(beacons: list[_Mounted], o: TlsOptions) -> list[_Panel]:
    return [
        _Panel(b.edges[i], b.edges[i + 1], b.top_z - o.panel_height_m, b.top_z, k, i)
        for k, b in enumerate(beacons)
        for i in range(3)
    ]


# --------------------------------------------------------------------------- rays


def _cast(
    origin: Array,
    dirs: Array,
    o: TlsOptions,
    walls: tuple[_Rough, _Rough, _Rough, _Rough],
    panels: list[_Panel],
) -> tuple[Array, NDArray[np.intp]]:
    """Range of each ray to the nearest surface (inf: none), and what it hit (-1 rock,
    else ``3 * beacon + panel``)."""
    n = dirs.shape[0]
    best = np.full(n, np.inf)
    hit = np.full(n, -1, dtype=np.intp)
    dx, dy, dz = dirs.T
    half = o.width_m / 2
    left, right, floor, roof = walls
    with np.errstate(divide="ignore", invalid="ignore"):
        # rough planes: intersect the mean plane, then move by the roughness there
        for plane, axis, sign, rough, u_axis, v_axis in (
            (-half, 1, -1, left, 0, 2),
            (half, 1, 1, right, 0, 2),
            (0.0, 2, -1, floor, 0, 1),
            (o.height_m, 2, 1, roof, 0, 1),
        ):
            d = dirs[:, axis]
            t = (plane - origin[axis]) / d
            p = origin + t[:, None] * dirs
            offset = rough(p[:, u_axis], p[:, v_axis])
            t = (plane - sign * offset - origin[axis]) / d
            ok = (t > 0) & (t < best)
            best = np.where(ok, t, best)
            hit = np.where(ok, -1, hit)
        for end in (0.0, o.length_m):  # the end walls, flat
            t = (end - origin[0]) / dx
            ok = (t > 0) & (t < best)
            best = np.where(ok, t, best)
            hit = np.where(ok, -1, hit)
        for pan in panels:
            ab = pan.b - pan.a
            nrm = np.array([-ab[1], ab[0]])
            denom = dx * nrm[0] + dy * nrm[1]
            t = float((pan.a - origin[:2]) @ nrm) / denom
            px = origin[0] + t * dx - pan.a[0]
            py = origin[1] + t * dy - pan.a[1]
            s = (px * ab[0] + py * ab[1]) / float(ab @ ab)
            z = origin[2] + t * dz
            ok = (t > 0) & (t < best) & (s >= 0) & (s <= 1) & (z >= pan.z0) & (z <= pan.z1)
            if o.panel_bow_m > 0:  # the bulge towards the drift, to first order along the ray
                h = pan.z1 - pan.z0
                bow = (
                    o.panel_bow_m
                    * np.sin(np.pi * np.clip(s, 0, 1))
                    * np.sin(np.pi * np.clip((z - pan.z0) / h, 0, 1))
                )
                unit = nrm / math.hypot(*nrm)
                toward = 1.0 if float((origin[:2] - pan.a) @ unit) > 0 else -1.0
                t = t - toward * bow * math.hypot(*nrm) / np.abs(denom)
            best = np.where(ok, t, best)
            hit = np.where(ok, 3 * pan.beacon + pan.index, hit)
    return best, hit


def _mixed(
    origin: Array,
    dirs: Array,
    r: Array,
    hit: NDArray[np.intp],
    o: TlsOptions,
    walls: tuple[_Rough, _Rough, _Rough, _Rough],
    panels: list[_Panel],
) -> Array:
    """Ranges with mixed pixels: a ray whose footprint straddles its panel's boundary
    returns the mean of the panel's range and the range behind (the next surface the
    ray meets without that panel), weighted by the footprint's share on each."""
    if o.beam_exit_m <= 0:
        return r
    out = r.copy()
    for k, pan in enumerate(panels):
        rows = np.flatnonzero(hit == 3 * pan.beacon + pan.index)
        if rows.size == 0:
            continue
        p = origin + r[rows, None] * dirs[rows]
        ab = pan.b - pan.a
        length = math.hypot(*ab)
        s = ((p[:, :2] - pan.a) @ ab) / length
        inside = np.minimum.reduce(
            [s, length - s, p[:, 2] - pan.z0, pan.z1 - p[:, 2]]
        )  # distance to the nearest boundary, in the panel's plane
        half = 0.5 * (o.beam_exit_m + o.beam_divergence_rad * r[rows])
        edge = inside < half
        if not np.any(edge):
            continue
        rows = rows[edge]
        share = 0.5 + 0.5 * inside[edge] / half[edge]  # the footprint's share on the panel
        behind, _ = _cast(origin, dirs[rows], o, walls, panels[:k] + panels[k + 1 :])
        behind = np.where(np.isfinite(behind), behind, r[rows])
        out[rows] = share * r[rows] + (1.0 - share) * behind
    return out


def _window(
    station: Array, b: _Mounted, o: TlsOptions
) -> tuple[float, float, float, float, float] | None:
    """Azimuth and elevation limits of a beacon's window from ``station`` and the step
    there; None beyond the scanner's reach."""
    grow = b.edges.mean(axis=0)
    corners = []
    for e in b.edges:
        out = e + o.margin_m * (e - grow) / max(float(np.hypot(*(e - grow))), 1e-9)
        for z in (b.top_z - o.panel_height_m - o.margin_m, b.top_z + o.margin_m):
            corners.append([out[0], out[1], z])
    c = np.array(corners) - station
    rng_h = np.hypot(c[:, 0], c[:, 1])
    near = float(np.min(np.hypot(rng_h, c[:, 2])))
    if near > o.max_range_m:
        return None
    az = np.arctan2(c[:, 1], c[:, 0])
    ref = float(np.arctan2(*(grow - station[:2])[::-1]))
    az = ref + np.remainder(az - ref + math.pi, 2 * math.pi) - math.pi
    el = np.arctan2(c[:, 2], rng_h)
    step = max(o.step_rad, o.min_spacing_m / max(near, 1e-3))
    return float(az.min()), float(az.max()), float(el.min()), float(el.max()), step


def _grid(az0: float, az1: float, el0: float, el1: float, step: float) -> Iterator[Array]:
    """Unit ray directions on a grid of ``step`` over the window, in chunks."""
    az = np.arange(az0, az1 + step / 2, step)
    el = np.arange(el0, el1 + step / 2, step)
    rows = max(1, RAY_CHUNK // max(az.size, 1))
    for i in range(0, el.size, rows):
        e, a = np.meshgrid(el[i : i + rows], az, indexing="ij")
        e, a = e.ravel(), a.ravel()
        yield np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


# --------------------------------------------------------------------------- writing


def simulate_tls(out: str | Path, seed: int = 0, options: TlsOptions = TlsOptions()) -> TlsScenario:
    """Simulate TLS scans of a drift with beacons and write them into ``out``.

    Parameters
    ----------
    out : str or Path
        Folder to write (created): ``scans.e57``, ``designs.csv``, ``beacons.csv``,
        ``truth.json`` (see the module).
    seed : int
        Seed of everything random.
    options : TlsOptions

    Raises
    ------
    InputError
        Options out of range.
    OutputError
        A file cannot be written.
    """
    import pye57

    o = options
    _check(o)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    walls = (
        _Rough.draw(rng, o.roughness_m),
        _Rough.draw(rng, o.roughness_m),
        _Rough.draw(rng, o.roughness_m / 2),
        _Rough.draw(rng, o.roughness_m),
    )
    designs = _designs(o.designs, rng)
    mounted = _mount(o, designs, rng)
    panels = _panels(mounted, o)
    noise_rng = np.random.default_rng([seed, 1])
    setup_rng = np.random.default_rng([seed, 2])
    theta = math.radians(90.0 - o.bearing_deg)  # the drift's x axis, counter-clockwise from E
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    e0, n0, z0 = o.origin

    def to_grid(p: Array) -> Array:
        return np.column_stack(
            [
                e0 + cos_t * p[:, 0] - sin_t * p[:, 1],
                n0 + sin_t * p[:, 0] + cos_t * p[:, 1],
                z0 + p[:, 2],
            ]
        )

    stations: list[tuple[float, float, float, float]] = []
    per_panel = np.zeros((len(mounted), 3), dtype=np.int64)
    in_reach: dict[str, list[int]] = {b.name: [] for b in mounted}
    total = 0
    e57_path = folder / "scans.e57"
    with atomic_path(e57_path) as tmp:
        e57 = pye57.E57(str(tmp), mode="w")
        try:
            for s in range(o.stations):
                x = o.length_m * (s + 0.5) / o.stations
                station = np.array([x, rng.uniform(-0.3, 0.3), o.scanner_height_m])
                heading = rng.uniform(-math.pi, math.pi)  # the scanner's zero direction
                pts, kinds = _scan_station(station, o, walls, panels, mounted, in_reach, s)
                r = np.hypot.reduce(pts - station, axis=1)
                keep = np.isfinite(r) & (r <= o.max_range_m)
                pts, kinds, r = pts[keep], kinds[keep], r[keep]
                # range noise along each ray
                pts = (
                    pts
                    + ((pts - station) / r[:, None])
                    * noise_rng.normal(0.0, o.range_noise_m, r.size)[:, None]
                )
                for k in kinds[kinds >= 0]:
                    per_panel[k // 3, k % 3] += 1
                local = pts - station
                ch, sh = math.cos(heading), math.sin(heading)
                scanner = np.column_stack(
                    [
                        ch * local[:, 0] + sh * local[:, 1],
                        -sh * local[:, 0] + ch * local[:, 1],
                        local[:, 2],
                    ]
                )
                # the scanner's axes in the grid: its heading plus the drift's bearing
                yaw = theta + heading
                grid_station = to_grid(station[None, :])[0]
                # the setup's error: the pose written, not the station's true place
                written = grid_station + np.array(
                    [*setup_rng.normal(0.0, o.station_sigma_m, 2), 0.0]
                )
                inten = np.where(kinds >= 0, PANEL_INTENSITY, ROCK_INTENSITY)
                inten = np.clip(inten + noise_rng.normal(0.0, 0.03, r.size), 0.0, 1.0)
                e57.write_scan_raw(
                    {
                        "cartesianX": scanner[:, 0],
                        "cartesianY": scanner[:, 1],
                        "cartesianZ": scanner[:, 2],
                        "intensity": inten,
                    },
                    name=f"station {s + 1}",
                    rotation=np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]),
                    translation=written,
                )
                azimuth = math.degrees(math.pi / 2 - yaw) % 360.0
                stations.append(
                    (
                        float(grid_station[0]),
                        float(grid_station[1]),
                        float(grid_station[2]),
                        azimuth,
                    )
                )
                total += r.size
        finally:
            e57.close()
    designs_path = folder / "designs.csv"
    # each design in its own frame, 5 m apart so that the file is also a valid survey
    own = [
        Beacon(d.name, d.edges_local + [5.0 * k, 0.0], design=d.name) for k, d in enumerate(designs)
    ]
    write_survey(designs_path, Survey(own))
    truth_beacons = []
    for b in mounted:
        grid = to_grid(np.column_stack([b.edges, np.full(4, b.top_z)]))
        truth_beacons.append(Beacon(b.name, grid[:, :2], grid[:, 2], design=b.design.name))
    survey_path = folder / "beacons.csv"
    write_survey(survey_path, Survey(truth_beacons))
    truth: dict[str, Any] = {
        "seed": seed,
        "options": asdict(o),
        "points": total,
        "stations": [
            {"easting": e, "northing": n, "elevation": z, "azimuth_deg": a}
            for e, n, z, a in stations
        ],
        "beacons": [
            {
                "id": b.name,
                "design": b.design.name,
                "wall": "left" if b.wall < 0 else "right",
                "stations_in_reach": in_reach[b.name],
                "points_per_panel": per_panel[k].tolist(),
            }
            for k, b in enumerate(mounted)
        ],
    }
    truth_path = folder / "truth.json"
    write_atomic(truth_path, (json.dumps(truth, indent=2) + "\n").encode("utf-8"))
    return TlsScenario(
        folder,
        e57_path,
        designs_path,
        survey_path,
        truth_path,
        total,
        tuple(stations),
        tuple(b.name for b in mounted),
    )


def _scan_station(
    station: Array,
    o: TlsOptions,
    walls: tuple[_Rough, _Rough, _Rough, _Rough],
    panels: list[_Panel],
    mounted: list[_Mounted],
    in_reach: dict[str, list[int]],
    index: int,
) -> tuple[Array, NDArray[np.intp]]:
    """Every return of one station (drift frame) and what each hit: the overview dome,
    then each beacon's window in reach (rays inside a window already cast by the
    overview are cast again finer; the overview's are dropped there)."""
    pts: list[Array] = []
    kinds: list[NDArray[np.intp]] = []
    windows = []
    for b in mounted:
        w = _window(station, b, o)
        if w is not None:
            windows.append(w)
            in_reach[b.name].append(index)
    el_lo, el_hi = math.radians(-70.0), math.radians(85.0)
    for dirs in _grid(-math.pi, math.pi - o.overview_step_rad, el_lo, el_hi, o.overview_step_rad):
        az = np.arctan2(dirs[:, 1], dirs[:, 0])
        el = np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0))
        inside = np.zeros(az.size, dtype=bool)
        for a0, a1, e0, e1, _ in windows:
            rel = np.remainder(az - a0, 2 * math.pi)
            inside |= (rel <= a1 - a0) & (el >= e0) & (el <= e1)
        r, hit = _cast(station, dirs[~inside], o, walls, panels)
        r = _mixed(station, dirs[~inside], r, hit, o, walls, panels)
        pts.append(station + r[:, None] * dirs[~inside])
        kinds.append(hit)
    for a0, a1, e0, e1, step in windows:
        for dirs in _grid(a0, a1, e0, e1, step):
            r, hit = _cast(station, dirs, o, walls, panels)
            r = _mixed(station, dirs, r, hit, o, walls, panels)
            pts.append(station + r[:, None] * dirs)
            kinds.append(hit)
    return np.concatenate(pts), np.concatenate(kinds)


def _check(o: TlsOptions) -> None:
    problems = [
        (5.0 <= o.length_m <= 2000.0, f"length_m {o.length_m} must be within 5-2000 m"),
        (2.0 <= o.width_m <= 20.0 and 2.0 <= o.height_m <= 20.0, "width and height 2-20 m"),
        (o.beacons >= 0 and o.designs >= 1 and o.stations >= 1, "counts must be positive"),
        (o.range_noise_m >= 0 and o.roughness_m >= 0, "noise and roughness must be >= 0"),
        (0 < o.step_rad <= o.overview_step_rad, "0 < step_rad <= overview_step_rad"),
        (
            0 < o.panel_height_m <= o.beacon_top_m < o.height_m,
            "need 0 < panel_height_m <= beacon_top_m < height_m",
        ),
        (0 < o.scanner_height_m < o.height_m, "the scanner must stand inside the drift"),
    ]
    bad = [why for ok, why in problems if not ok]
    if bad:
        raise InputError("TLS simulation: " + "; ".join(bad))
