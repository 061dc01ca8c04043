"""Named simulation scenarios and writing them to disk.

A scenario is a list of :class:`Scene`: one site (world and beacon survey)
with the shots (true pose, scanner) taken in it.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mast.core.beacon import Beacon, Survey
from mast.core.pose import Pose2D
from mast.errors import InputError
from mast.io import write_laserscans, write_scan_csv, write_survey
from mast.io.atomic import atomic_open, write_atomic
from mast.io.bags import BagKind
from mast.sim.design import BeaconDesign, paper_design, random_design
from mast.sim.drive import drive_scenario
from mast.sim.mounting import direction
from mast.sim.owed import OwedRule
from mast.sim.scanner import SCANNERS, ScannerModel, SimulatedScan
from mast.sim.scene import Scene, Shot
from mast.sim.tunnel import Roughness, Tunnel, project_station, roughen
from mast.sim.world import Surface, WorldBuilder

__all__ = [
    "SCENARIOS",
    "TRUTH_COLUMNS",
    "Scene",
    "Shot",
    "build_scenario",
    "paper_scenario",
    "random_scenario",
    "write_scenario",
]


def _with_noise(model: ScannerModel, sigma_m: float) -> ScannerModel:
    from dataclasses import replace

    return replace(model, name=f"{model.name}-sigma{1000 * sigma_m:g}mm", range_sigma_m=sigma_m)


# --------------------------------------------------------------------------- paper

#: Where the paper's Table 2 positions lie, reconstructed from its coordinates:
#: Beacon 2 centred on the west wall at (6, 7); Beacon 1 9 m east of P1 = (7, 7),
#: turned about P1 by the yaw psi, on a wall of azimuth psi; the position near
#: Beacon 1 is 1 m west of it (P7 / P5 / P6) and the middle one halfway from P1
#: (P4 / P2 / P3), facing the mean of the two wall directions.
PAPER_VARIANTS: dict[str, tuple[float, str, str]] = {
    "convergent": (-10.0, "P3", "P6"),
    "parallel": (0.0, "P4", "P7"),
    "divergent": (10.0, "P2", "P5"),
}


def paper_scene(
    variant: str = "parallel",
    *,
    chord_m: float = 1.0,
    depth_m: float = 0.2,
    resolutions_deg: Sequence[float] = (0.25, 0.5),
    range_sigma_m: float = 0.0,
    seed: int = 0,
) -> Scene:
    """One wall configuration of the paper's simulation (see :data:`PAPER_VARIANTS`)."""
    if variant not in PAPER_VARIANTS:
        raise InputError(f"unknown paper variant {variant!r}; known: {', '.join(PAPER_VARIANTS)}")
    yaw_deg, mid_label, near_label = PAPER_VARIANTS[variant]
    psi = math.radians(yaw_deg)
    design = paper_design(chord_m, depth_m)
    p1 = np.array([7.0, 7.0])
    c1 = p1 + 9.0 * np.array([math.cos(psi), -math.sin(psi)])
    c2 = np.array([6.0, 7.0])
    west_t = np.array([0.0, 1.0])
    east_t = np.array([math.sin(psi), math.cos(psi)])
    b2 = design.beacon("B2", c2, west_t, tunnel_side=-1)
    b1 = design.beacon("B1", c1, east_t, tunnel_side=1)
    wb = WorldBuilder()
    wb.polyline([c2 - 40 * west_t, c2 + 40 * west_t], Surface("wall"))
    wb.polyline([c1 - 40 * east_t, c1 + 40 * east_t], Surface("wall"))
    for b in (b1, b2):
        wb.panels(b.edges, b.id)
    near = c1 - np.array([1.0, 0.0])
    mid = 0.5 * (p1 + near)
    poses = [
        ("P1", Pose2D(float(p1[0]), float(p1[1]), 0.0)),
        (mid_label, Pose2D(float(mid[0]), float(mid[1]), psi / 2)),
        (near_label, Pose2D(float(near[0]), float(near[1]), psi)),
    ]
    shots = []
    for res in resolutions_deg:
        model = ScannerModel(f"paper-270-{res:g}", 270.0, float(res), range_max_m=30.0)
        if range_sigma_m > 0:
            model = _with_noise(model, range_sigma_m)
        shots += [Shot(f"{label}@{res:g}deg", pose, model) for label, pose in poses]
    z = np.full(4, 1.5)
    survey = Survey([Beacon(b.id, b.edges, z) for b in (b1, b2)])
    return Scene(
        f"paper-{variant}",
        wb.build(),
        survey,
        tuple(shots),
        description=(
            f"Paper Table 2 layout, Beacon 1 yawed {yaw_deg:+g}° ({variant} walls), "
            f"beacons {design.name}"
        ),
        seed=seed,
        params={"variant": variant, "yaw_deg": yaw_deg, "chord_m": chord_m, "depth_m": depth_m},
    )


def paper_scenario(seed: int = 0, *, noise: bool = False, **kw: object) -> list[Scene]:
    """The paper's three wall configurations, seven positions, 0.25° and 0.5°.

    Noise-free as in the paper unless ``noise`` (then 12 mm range noise).
    """
    sigma = 0.012 if noise else 0.0
    return [
        paper_scene(v, range_sigma_m=sigma, seed=seed + i, **kw)  # type: ignore[arg-type]
        for i, v in enumerate(PAPER_VARIANTS)
    ]


# --------------------------------------------------------------------------- random


def random_scene(
    seed: int,
    index: int = 0,
    *,
    poses: int = 5,
    noise: bool = False,
    clutter: bool = True,
    rough: bool = True,
) -> Scene:
    """A seeded random drift: one bend, 2-3 beacons of random shapes, clutter, poses between."""
    rng = np.random.default_rng([seed, index])
    width = float(rng.uniform(4.0, 7.0))
    heading = float(rng.uniform(0, 2 * math.pi))
    bend = math.radians(float(rng.uniform(-25, 25)))
    origin = np.array(
        [(0.0, 0.0), (5000.0, 3000.0), (512345.678, 7012345.678)][int(rng.integers(3))]
    )
    length1, length2 = 30.0, 30.0
    c0 = origin.copy()
    c1 = c0 + length1 * direction(heading)
    c2 = c1 + length2 * direction(heading + bend)
    tunnel = Tunnel(np.array([c0, c1, c2]), width)
    left, right = tunnel.walls()

    n_beacons = int(rng.integers(2, 4))
    stations: list[float] = []
    s = float(rng.uniform(12, 20))
    for _ in range(n_beacons):
        if abs(s - length1) < 2.5:
            s += 5.0
        stations.append(s)
        s += float(rng.uniform(4, 10))
    beacons: list[Beacon] = []
    sides: list[str] = []
    designs: list[str] = []
    wb = WorldBuilder()
    smooth: dict[str, list[tuple[float, float]]] = {"left": [], "right": []}
    for j, st in enumerate(stations):
        if rng.random() < 0.6:
            design: BeaconDesign = random_design(rng)
        else:
            chord = float(rng.uniform(0.7, 1.8))
            design = paper_design(chord, chord * float(rng.uniform(0.08, 0.2)))
        # Mostly on alternate walls, as the paper mounts them opposite each other.
        if not sides:
            side = "left" if rng.random() < 0.5 else "right"
        else:
            other = "right" if sides[-1] == "left" else "left"
            side = other if rng.random() < 0.75 else sides[-1]
        centre, tangent = tunnel.centre_point(st)
        normal = np.array([-tangent[1], tangent[0]])
        on_wall = centre + (width / 2) * normal * (1 if side == "left" else -1)
        b = design.beacon(f"B{j + 1}", on_wall, tangent, tunnel_side=-1 if side == "left" else 1)
        beacons.append(b)
        sides.append(side)
        designs.append(design.name)
        wall = left if side == "left" else right
        ws = project_station(wall, on_wall)
        smooth[side].append((ws - design.chord_m / 2, ws + design.chord_m / 2))
        wb.panels(b.edges, b.id)
    roughness = (
        Roughness(amplitude_m=float(rng.uniform(0.01, 0.05)))
        if rough and rng.random() < 0.5
        else None
    )
    for side, wall in (("left", left), ("right", right)):
        pts = roughen(wall, roughness, rng, smooth_intervals=smooth[side]) if roughness else wall
        wb.polyline(pts, Surface("wall"))
    if clutter:
        for _ in range(int(rng.integers(0, 3))):
            st = float(rng.uniform(5, length1 + length2 - 5))
            centre, tangent = tunnel.centre_point(st)
            normal = np.array([-tangent[1], tangent[0]])
            off = float(rng.choice([-1, 1])) * (width / 2 - 0.6)
            p = centre + off * normal
            if rng.random() < 0.5:
                wb.box(
                    p,
                    (float(rng.uniform(0.4, 1.5)), float(rng.uniform(0.3, 0.8))),
                    float(rng.uniform(0, math.pi)),
                    Surface("clutter"),
                )
            else:
                wb.circle(p, float(rng.uniform(0.1, 0.3)), Surface("clutter"))
    world = wb.build()
    models = ["ideal-270-0.25", "ideal-270-0.5"]
    shots = []
    lo, hi = stations[0] - 1.0, stations[-1] + 1.0
    for k in range(poses):
        st = float(rng.uniform(lo, hi))
        centre, tangent = tunnel.centre_point(st)
        normal = np.array([-tangent[1], tangent[0]])
        p = centre + float(rng.uniform(-(width / 2 - 1.0), width / 2 - 1.0)) * normal
        az = math.atan2(tangent[0], tangent[1]) + (math.pi if rng.random() < 0.5 else 0.0)
        az += math.radians(float(rng.normal(0, 15)))
        model = SCANNERS[models[int(rng.integers(len(models)))]]
        if noise:
            model = _with_noise(model, 0.012)
        shots.append(Shot(f"pose{k}", Pose2D(float(p[0]), float(p[1]), az % (2 * math.pi)), model))
    return Scene(
        f"random-{seed}-{index}",
        world,
        Survey(beacons),
        tuple(shots),
        description=(
            f"random drift, width {width:.2f} m, bend {math.degrees(bend):+.1f}°, "
            f"{n_beacons} beacons ({', '.join(designs)}), "
            + (f"rough walls ±{roughness.amplitude_m:.3f} m" if roughness else "smooth walls")
        ),
        seed=seed * 1000 + index,
        params={"width_m": width, "bend_deg": math.degrees(bend), "sides": sides},
    )


def random_scenario(
    seed: int = 0, *, scenes: int = 4, poses: int = 5, noise: bool = False
) -> list[Scene]:
    """``scenes`` seeded random drifts with ``poses`` shots each."""
    return [random_scene(seed, i, poses=poses, noise=noise) for i in range(scenes)]


SCENARIOS: dict[str, Callable[..., list[Scene]]] = {
    "paper": paper_scenario,
    "random": random_scenario,
}


def build_scenario(
    name: str, seed: int = 0, *, noise: bool | None = None, **options: object
) -> list[Scene]:
    """Build a named scenario; the error lists the known names.

    ``noise=None`` is each scenario's own default: none for ``paper`` and ``random``,
    12 mm for ``drive``. ``options`` (``scans``, ``rate_hz``) are the drive's
    (:func:`mast.sim.drive.drive_scenario`).
    """
    if name == "drive":  # scans streamed one at a time; see mast.sim.drive
        unknown = sorted(set(options) - {"scans", "rate_hz"})
        if unknown:
            raise InputError(f"scenario 'drive' has no option {unknown[0]!r}")
        return drive_scenario(seed, noise=noise, **options)  # type: ignore[arg-type]
    try:
        builder = SCENARIOS[name]
    except KeyError:
        known = ", ".join([*SCENARIOS, "drive"])
        raise InputError(f"unknown scenario {name!r}; known: {known}") from None
    if options:
        raise InputError(
            f"scenario {name!r} takes no {', '.join(sorted(options))}; only drive does"
        )
    return builder(seed, noise=bool(noise))


# --------------------------------------------------------------------------- writing

SCAN_FORMATS = ("csv", "bag", "ros2", "mcap")

#: The panels ``truth.csv`` lists as seen: five returns, ten degrees off grazing (a
#: column for the reader, stricter than the rule fixes are owed by, :data:`~.owed.OWED`).
TRUTH_PANELS = OwedRule(5, 10.0)

#: Columns of ``truth.csv``, one row per scan (a file contract: tools read them by name).
TRUTH_COLUMNS = (
    "shot",
    "label",
    "file",
    "message",
    "stamp_ns",
    "easting",
    "northing",
    "azimuth_deg",
    "scanner",
    "fov_deg",
    "resolution_deg",
    "range_sigma_m",
    "panels_seen",
)


def _with_truth(scene: Scene, files: Sequence[str], truth: Any) -> Iterator[SimulatedScan]:
    """The scene's scans one at a time, each writing its row to the ``truth`` csv writer.

    ``files`` names each scan's file, or holds one name (a bag) for all of them.
    """
    for i, (shot, sim) in enumerate(zip(scene.shots, scene.iter_simulated(), strict=True)):
        truth.writerow(_truth_row(i, files[i] if len(files) > 1 else files[0], shot, sim))
        yield sim


def _truth_row(i: int, file: str, shot: Shot, sim: SimulatedScan) -> list[object]:
    seen = ";".join(
        f"{b}:{''.join(map(str, ps))}" for b, ps in sim.panels_seen(TRUTH_PANELS).items()
    )
    return [
        i,
        shot.label,
        file,
        i + 1,
        sim.scan.stamp_ns,
        repr(shot.pose.easting),
        repr(shot.pose.northing),
        repr(shot.pose.azimuth_deg),
        shot.scanner.name,
        shot.scanner.fov_deg,
        shot.scanner.resolution_deg,
        shot.scanner.range_sigma_m,
        seen,
    ]


@dataclass(frozen=True, slots=True)
class WrittenScene:
    folder: Path
    survey: Path
    scans: list[Path]
    truth: Path
    count: int


def write_scenario(
    scenes: Sequence[Scene], out: str | Path, *, fmt: str = "csv", scenario: str = "", seed: int = 0
) -> list[WrittenScene]:
    """Simulate every shot and write, per scene, a folder with ``beacons.csv``, the
    scans (one CSV per shot, or one bag) and ``truth.csv``; plus ``scenario.json``.
    """
    if fmt not in SCAN_FORMATS:
        raise InputError(f"unknown scan format {fmt!r}; known: {', '.join(SCAN_FORMATS)}")
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    written: list[WrittenScene] = []
    meta: list[dict[str, object]] = []
    for scene in scenes:
        folder = root / scene.name
        folder.mkdir(exist_ok=True)
        survey_path = folder / "beacons.csv"
        write_survey(survey_path, scene.survey)
        count = len(scene.shots)
        digits = max(3, len(str(count - 1)))
        if fmt == "csv":
            files = [f"scan_{i:0{digits}d}.csv" for i in range(count)]
            scan_paths = [folder / f for f in files]
        else:
            name = {"bag": "scans.bag", "ros2": "scans_ros2", "mcap": "scans_mcap"}[fmt]
            p = folder / name
            if p.exists():
                raise InputError("exists already; choose an empty --out folder", path=p)
            files = [name]
            scan_paths = [p]
        truth_path = folder / "truth.csv"
        with atomic_open(truth_path, "w", newline="", encoding="utf-8") as fh:
            truth = csv.writer(fh)
            truth.writerow(TRUTH_COLUMNS)
            sims = _with_truth(scene, files, truth)
            if fmt == "csv":
                for path, sim in zip(scan_paths, sims, strict=True):
                    write_scan_csv(path, sim.scan)
            else:
                kinds: dict[str, BagKind] = {"bag": "rosbag1", "ros2": "sqlite3", "mcap": "mcap"}
                # streamed: the writer takes one scan at a time, never all of them
                write_laserscans(scan_paths[0], (s.scan for s in sims), kind=kinds[fmt])
        written.append(WrittenScene(folder, survey_path, scan_paths, truth_path, count))
        meta.append(
            {
                "name": scene.name,
                "description": scene.description,
                "seed": scene.seed,
                "params": scene.params,
                "beacons": scene.survey.ids,
                "scanners": sorted({s.scanner.name for s in scene.shots}),
                "scanner_models": {s.scanner.name: asdict(s.scanner) for s in scene.shots},
            }
        )
    write_atomic(
        root / "scenario.json",
        (
            json.dumps(
                {"scenario": scenario, "seed": seed, "format": fmt, "scenes": meta}, indent=2
            )
            + "\n"
        ).encode("utf-8"),
    )
    return written
