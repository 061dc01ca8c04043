"""The simulated drive: a vehicle along a drift at the scanner's rate, streamed to a bag."""

from __future__ import annotations

import csv
import math
import tracemalloc
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import mast.sim.drive as drive_module
import mast.sim.scenarios as scenarios_module
from mast.io import read_laserscans, read_survey, write_survey
from mast.pipeline import LocatorConfig, locate
from mast.sim import (
    TRUTH_COLUMNS,
    build_scenario,
    drive_scene,
    simulate_scan,
    write_scenario,
)
from mast.sim.drive import DEFAULT_DRIVE_SCANS, DRIVE_START_NS
from tests._cli import run_mast_text


def _truth(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def _seen(row: dict[str, str]) -> dict[str, str]:
    """``panels_seen`` of a truth row: beacon id -> panels (e.g. ``"123"``)."""
    return dict(item.split(":") for item in row["panels_seen"].split(";") if item)


@pytest.fixture(scope="module")
def default_drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``mast simulate --scenario drive --format bag`` with the defaults (seed 0)."""
    out = tmp_path_factory.mktemp("drive")
    (w,) = write_scenario(build_scenario("drive"), out, fmt="bag", scenario="drive")
    return w.folder


def test_bag_reads_back_at_the_scanners_rate(default_drive: Path) -> None:
    scans = list(read_laserscans(default_drive / "scans.bag"))
    assert len(scans) == DEFAULT_DRIVE_SCANS
    stamps = np.array([s.stamp_ns for s in scans])
    assert stamps[0] == DRIVE_START_NS  # 2026-01-01 06:00 UTC
    assert np.all(np.diff(stamps) == 40_000_000)  # 25 Hz, well within the 0.5 s of a prior
    assert {len(s) for s in scans} == {1081}  # 270° at 0.25°
    assert scans[0].range_max_m == pytest.approx(30.0)
    rows = _truth(default_drive / "truth.csv")
    assert len(rows) == len(scans)
    assert [int(r["stamp_ns"]) for r in rows] == stamps.tolist()
    assert [int(r["message"]) for r in rows] == list(range(1, len(scans) + 1))


def test_truth_keeps_the_scenario_columns(default_drive: Path, tmp_path: Path) -> None:
    (w,) = write_scenario(build_scenario("paper")[:1], tmp_path, fmt="csv")
    with w.truth.open(encoding="utf-8") as fh:
        paper_header = next(csv.reader(fh))
    with (default_drive / "truth.csv").open(encoding="utf-8") as fh:
        drive_header = next(csv.reader(fh))
    assert drive_header == paper_header == list(TRUTH_COLUMNS)
    row = _truth(default_drive / "truth.csv")[0]
    assert row["scanner"] == "drive-lms1xx-0.25"
    assert float(row["range_sigma_m"]) == 0.012
    assert float(row["fov_deg"]) == 270.0


def test_some_scans_see_two_beacons_and_many_fewer(default_drive: Path) -> None:
    counts = np.array([len(_seen(r)) for r in _truth(default_drive / "truth.csv")])
    assert np.sum(counts >= 2) > 50
    assert np.sum(counts < 2) > 50


def test_beacons_in_stretches_with_long_gaps(tmp_path: Path) -> None:
    scene = drive_scene(4, scans=6000)  # 240 s, some 480 m
    stations = np.array(scene.beacon_stations_m)
    spacing = np.diff(stations)
    in_stretch = spacing < 30
    assert np.all((spacing[in_stretch] >= 6) & (spacing[in_stretch] <= 14))
    assert np.all((spacing[~in_stretch] >= 30) & (spacing[~in_stretch] <= 60))
    assert np.sum(~in_stretch) >= 4
    # every gap but one cut short by the drift's end lasts 30-60 m, and the drive crosses them
    full = [b - a for a, b in scene.gaps_m if b < scene.length_m]
    assert len(full) >= 4
    assert all(30 <= g <= 60 for g in full)
    assert sum(a > scene.stations_m[0] and b < scene.stations_m[-1] for a, b in scene.gaps_m) >= 4
    # the same seen in the survey file: consecutive beacons 6-15 m apart, or 29 m and more
    write_survey(tmp_path / "beacons.csv", scene.survey)
    survey = read_survey(tmp_path / "beacons.csv")
    centres = np.array([survey[b].edges.mean(axis=0) for b in sorted(survey.ids)])
    apart = np.hypot(*np.diff(centres, axis=0).T)
    assert np.all(((apart > 6) & (apart < 16)) | (apart > 29))
    assert np.sum(apart > 29) == np.sum(~in_stretch)
    # alternating walls: beacons in a stretch stand a drift's width apart across it
    assert len(survey.ids) == len(stations) >= 20


def test_vehicle_path_is_smooth_and_follows_the_drift() -> None:
    scene = drive_scene(2, scans=3000)
    assert scene.speeds_mps.min() >= 1.0
    assert scene.speeds_mps.max() <= 3.0
    assert np.ptp(scene.speeds_mps) > 0.5  # the speed varies ...
    assert np.abs(np.diff(scene.speeds_mps)).max() < 0.01  # ... smoothly (m/s per scan)
    pose = np.array([[s.pose.easting, s.pose.northing, s.pose.azimuth] for s in scene.shots])
    step = np.hypot(*np.diff(pose[:, :2], axis=0).T)
    expected = 0.5 * (scene.speeds_mps[1:] + scene.speeds_mps[:-1]) / scene.rate_hz
    assert np.abs(step - expected).max() < 0.01 * expected.max()
    # heading follows the direction of travel, within the yaw noise
    travel = np.arctan2(*np.diff(pose[:, :2], axis=0).T)  # azimuth of each step
    off = (pose[1:, 2] - travel + math.pi) % (2 * math.pi) - math.pi
    assert np.degrees(np.abs(off)).max() < 3.0
    assert 0.05 < np.degrees(np.std(off)) < 1.0
    turn = (np.diff(pose[:, 2]) + math.pi) % (2 * math.pi) - math.pi
    assert np.degrees(np.abs(turn)).max() < 1.0  # per 40 ms
    # and the drift bends
    heading_change = np.degrees(np.abs(np.unwrap(travel)[-1] - np.unwrap(travel)[0]))
    assert np.degrees(np.ptp(np.unwrap(travel))) > 10 or heading_change > 10


def test_owed_scans_are_located_within_millimetres(default_drive: Path) -> None:
    rows = _truth(default_drive / "truth.csv")
    owed = [i for i, r in enumerate(rows) if sum(len(p) >= 2 for p in _seen(r).values()) >= 2]
    assert len(owed) > 30
    pick = set(owed[:: len(owed) // 6][:6])
    survey = read_survey(default_drive / "beacons.csv")
    config = LocatorConfig(range_sigma_m=0.012)
    fixed = 0
    for i, scan in enumerate(read_laserscans(default_drive / "scans.bag")):
        if i not in pick:
            continue
        fix = locate(scan, survey, config=config)
        if not fix.ok:
            continue
        fixed += 1
        r = rows[i]
        assert fix.pose is not None
        error = math.hypot(
            fix.pose.easting - float(r["easting"]), fix.pose.northing - float(r["northing"])
        )
        assert error < 0.03
        assert abs((fix.pose.azimuth_deg - float(r["azimuth_deg"]) + 180) % 360 - 180) < 0.1
    assert fixed >= 4


def test_deterministic_per_seed(tmp_path: Path) -> None:
    def files(seed: int, name: str) -> list[bytes]:
        (w,) = write_scenario(build_scenario("drive", seed, scans=30), tmp_path / name, fmt="bag")
        return [(w.folder / f).read_bytes() for f in ("beacons.csv", "truth.csv", "scans.bag")]

    first = files(3, "a")
    assert files(3, "b") == first
    other = files(4, "c")
    assert all(x != y for x, y in zip(first, other, strict=True))


def test_a_longer_drive_continues_a_shorter_one() -> None:
    short, long = drive_scene(1, scans=300), drive_scene(1, scans=900)
    assert [s.pose for s in short.shots] == [s.pose for s in long.shots[:300]]
    assert_array_equal(short.stamps_ns, long.stamps_ns[:300])
    assert short.survey.ids == long.survey.ids[: len(short.survey.ids)]
    for b in short.survey.ids:
        assert_array_equal(short.survey[b].edges, long.survey[b].edges)


def test_culled_ray_casting_gives_the_whole_worlds_scans() -> None:
    """Each scan is cast only against the walls within reach, by beam sectors: the same
    ranges and surfaces as casting against the whole drift, all along it."""
    scene = drive_scene(5, scans=2500)
    reach = drive_module.Reach.of(scene.world)
    for i in range(0, 2500, 250):
        shot = scene.shots[i]
        near = reach.near(shot.pose.position, 31.0)
        assert near.seg_a.shape[0] < scene.world.seg_a.shape[0] / 2
        culled = simulate_scan(near, shot.pose, shot.scanner, rng=np.random.default_rng(i))
        whole = simulate_scan(scene.world, shot.pose, shot.scanner, rng=np.random.default_rng(i))
        assert_array_equal(culled.scan.ranges_m, whole.scan.ranges_m)
        assert_array_equal(culled.surface_index, whole.surface_index)
    first = next(scene.iter_simulated())
    whole = simulate_scan(
        scene.world,
        scene.shots[0].pose,
        scene.shots[0].scanner,
        rng=np.random.default_rng(scene.seed),
        stamp_ns=int(scene.stamps_ns[0]),
    )
    assert_array_equal(first.scan.ranges_m, whole.scan.ranges_m)
    assert first.scan.stamp_ns == whole.scan.stamp_ns


def test_fifty_hertz_is_half_a_degree() -> None:
    scene = drive_scene(0, scans=20, rate_hz=50.0)
    assert {s.scanner.resolution_deg for s in scene.shots} == {0.5}
    assert np.all(np.diff(scene.stamps_ns) == 20_000_000)
    sim = next(iter(scene.iter_simulated()))
    assert len(sim.scan) == 541


def test_scans_are_streamed_to_the_writer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The writer gets an iterator, and each scan is simulated only when it asks for it."""
    simulated = 0
    real_simulate = drive_module.simulate_scan
    real_write = scenarios_module.write_laserscans

    def counting_simulate(*args: Any, **kwargs: Any) -> Any:
        nonlocal simulated
        simulated += 1
        return real_simulate(*args, **kwargs)

    def checking_write(path: Path, scans: Iterable[Any], **kwargs: Any) -> int:
        assert isinstance(scans, Iterator)
        assert simulated == 0

        def watch() -> Iterator[Any]:
            for i, scan in enumerate(scans):
                assert simulated == i + 1  # one scan made per scan taken
                yield scan

        return real_write(path, watch(), **kwargs)

    monkeypatch.setattr(drive_module, "simulate_scan", counting_simulate)
    monkeypatch.setattr(scenarios_module, "write_laserscans", checking_write)
    (w,) = write_scenario(build_scenario("drive", 0, scans=60), tmp_path, fmt="mcap")
    assert simulated == w.count == 60


def test_memory_does_not_grow_with_the_number_of_scans(tmp_path: Path) -> None:
    def peak(scans: int) -> int:
        scenes = build_scenario("drive", 0, scans=scans)
        tracemalloc.start()
        try:
            write_scenario(scenes, tmp_path / str(scans), fmt="bag")
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    small, large = peak(250), peak(1250)
    # 1 250 scans of 1 081 ranges, simulated with their truth, would be over 40 MB
    assert large < 1.5 * small
    assert large < 8_000_000


def test_cli_writes_a_drive(tmp_path: Path) -> None:
    r = run_mast_text(
        "simulate", "--scenario", "drive", "--scans", "40", "--rate", "50", "--seed", "2",
        "--scan-format", "ros2", "--out", str(tmp_path),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    scans = list(read_laserscans(tmp_path / "drive-2" / "scans_ros2"))
    assert len(scans) == 40
    assert np.all(np.diff([s.stamp_ns for s in scans]) == 20_000_000)
    assert len(_truth(tmp_path / "drive-2" / "truth.csv")) == 40
    assert (tmp_path / "scenario.json").is_file()
    r = run_mast_text("simulate", "--scans", "40", "--out", str(tmp_path / "paper"))
    assert r.returncode == 2
    assert r.stderr.strip() == "mast: error: --scans and --rate apply to --scenario drive only"
