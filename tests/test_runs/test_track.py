"""Survey runs (issue 10): a simulated drive tracked from bag to every output, with the
placed scans checked against the truth, a damaged bag, an interrupted run and Dask."""

from __future__ import annotations

import csv
import json
import math
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import ezdxf
import jsonschema
import laspy
import numpy as np
import pytest
from numpy.typing import NDArray

from mast.core.pose import Pose2D
from mast.io import read_laserscans, read_survey
from mast.pipeline import LocatorConfig
from mast.runs.odometry import Motion, keyframe, recover_motion, scan_to_scan
from mast.runs.run import RUN_FILES, track_run
from mast.runs.track import RunTracker, TrackConfig, compose
from mast.sim import drive_scene, write_scenario
from tests._cli import run_mast_text

SCHEMA = Path(__file__).resolve().parents[2] / "docs" / "fix.schema.json"
CONFIG = TrackConfig(locator=LocatorConfig(range_sigma_m=0.012))


def _track(bag: Path, drive: Path, out: Path) -> subprocess.CompletedProcess[str]:
    """``mast track`` of ``bag`` with the drive's survey and range noise."""
    return run_mast_text(
        "track",
        str(bag),
        "-b",
        str(drive / "beacons.csv"),
        "--out",
        str(out),
        "--range-sigma",
        "0.012",
    )


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 250-scan drive (10 s at 25 Hz) past beacons and into a stretch without any."""
    out = tmp_path_factory.mktemp("drive")
    (w,) = write_scenario([drive_scene(0, scans=250)], out, fmt="bag", scenario="drive")
    return w.folder


@pytest.fixture(scope="module")
def tracked(drive: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run")
    r = _track(drive / "scans.bag", drive, out)
    assert r.returncode == 0, r.stderr
    assert "250 scans" in r.stdout
    return out


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_run_writes_every_file_and_places_every_scan(tracked: Path, drive: Path) -> None:
    for name in RUN_FILES:
        assert (tracked / name).stat().st_size > 0, name
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    validator = jsonschema.Draft202012Validator(schema)
    records = [json.loads(line) for line in (tracked / "fixes.jsonl").read_text().splitlines()]
    assert [r["scan"] for r in records] == list(range(250))
    truth = _rows(drive / "truth.csv")
    assert [r["stamp_ns"] for r in records] == [int(t["stamp_ns"]) for t in truth]
    for r in records:
        assert not list(validator.iter_errors(r))
        assert r["topic"] == "/scan"
    fixed = sum(r["status"] == "fix" for r in records)
    traj = _rows(tracked / "trajectory.csv")
    assert len(traj) == 250
    assert {r["source"] for r in traj} == {"fix", "odometry"}
    assert sum(r["source"] == "fix" for r in traj) == fixed
    assert 0 < fixed < 250  # the drive leaves the beacons behind: odometry carries the rest


def test_a_second_run_into_a_run_folder_is_refused_unless_forced(
    tracked: Path, drive: Path, tmp_path: Path
) -> None:
    """``--out`` naming a folder that holds an earlier run: one line naming it and
    ``--force``, exit 2, the earlier run untouched; with ``--force`` the run is written."""
    before = {p.name: p.stat().st_mtime_ns for p in tracked.iterdir()}
    r = _track(drive / "scans.bag", drive, tracked)
    assert r.returncode == 2
    (line,) = r.stderr.strip().splitlines()
    assert str(tracked) in line
    assert "--force" in line
    assert {p.name: p.stat().st_mtime_ns for p in tracked.iterdir()} == before
    copy = tmp_path / "copy"
    copy.mkdir()
    (copy / "old.txt").write_text("an earlier run\n")
    forced = run_mast_text(
        "track", str(drive / "scans.bag"), "-b", str(drive / "beacons.csv"),
        "--out", str(copy), "--range-sigma", "0.012", "--force",
    )  # fmt: skip
    assert forced.returncode == 0, forced.stderr
    assert (copy / "trajectory.csv").exists()


def test_a_run_repeated_with_its_config_toml_gives_the_same_results(
    tracked: Path, drive: Path, tmp_path: Path
) -> None:
    # The effective settings are written beside the results, every record names them,
    # and a run given that file (no option repeated) is the same run.
    settings = (tracked / "config.toml").read_text(encoding="utf-8")
    assert "range_sigma_m = 0.012" in settings
    assert "[track]" in settings
    (sha,) = re.findall(r"SHA-256 of the settings below: ([0-9a-f]{64})", settings)
    records = [json.loads(line) for line in (tracked / "fixes.jsonl").read_text().splitlines()]
    assert {r["inputs"]["config_sha256"] for r in records} == {sha}
    again = tmp_path / "again"
    r = run_mast_text(
        "track", str(drive / "scans.bag"), "-b", str(drive / "beacons.csv"),
        "--out", str(again), "--config", str(tracked / "config.toml"),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert (again / "config.toml").read_text(encoding="utf-8") == settings
    for name in ("trajectory.csv", "trajectory.tum"):
        assert (again / name).read_bytes() == (tracked / name).read_bytes(), name


def test_placed_scans_are_within_5_cm_of_the_truth_with_honest_sigmas(
    tracked: Path, drive: Path
) -> None:
    truth = {t["stamp_ns"]: t for t in _rows(drive / "truth.csv")}
    z: list[float] = []
    for r in _rows(tracked / "trajectory.csv"):
        t = truth[r["stamp_ns"]]
        de = float(r["easting"]) - float(t["easting"])
        dn = float(r["northing"]) - float(t["northing"])
        da = (float(r["azimuth_deg"]) - float(t["azimuth_deg"]) + 180) % 360 - 180
        assert math.hypot(de, dn) < (0.01 if r["source"] == "fix" else 0.05)
        assert abs(da) < 0.1
        z += [de / float(r["sigma_easting_m"]), dn / float(r["sigma_northing_m"])]
    # 95 % intervals hold the truth at least 95 % of the time (the scans are correlated
    # along the run, so this is a sanity check; the benchmark measures coverage).
    assert np.mean(np.abs(z) <= 1.96) >= 0.95


def test_the_map_and_the_plan_reopen_in_their_own_libraries(tracked: Path) -> None:
    las = laspy.read(tracked / "map.las")
    assert len(las.points) > 100_000
    assert set(np.unique(las.scan_index)) <= set(range(250))
    traj = _rows(tracked / "trajectory.csv")
    e = np.array([float(r["easting"]) for r in traj])
    assert abs(float(np.median(las.x)) - float(np.median(e))) < 30.0  # walls around the path
    doc = ezdxf.readfile(tracked / "map.dxf")
    auditor = doc.audit()
    assert not auditor.has_errors
    layers = {layer.dxf.name for layer in doc.layers}
    assert {"MAST_WALLS", "MAST_BEACONS", "MAST_TRAJECTORY", "MAST_FIXES"} <= layers
    tum = (tracked / "trajectory.tum").read_text().splitlines()
    rows = [line.split() for line in tum if not line.startswith("#")]
    assert len(rows) == 250
    assert all(len(row) == 8 for row in rows)


def test_a_bag_cut_short_gives_the_scans_it_holds(tmp_path: Path, drive: Path) -> None:
    data = (drive / "scans.bag").read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.85)])
    out = tmp_path / "run"
    r = _track(cut, drive, out)
    assert r.returncode == 0, r.stderr
    assert "cut short" in r.stderr
    records = (out / "fixes.jsonl").read_text().splitlines()
    assert 0 < len(records) < 250
    assert len(_rows(out / "trajectory.csv")) == len(records)


@pytest.mark.parametrize("how", ["KeyboardInterrupt", "flag"])
def test_an_interrupted_run_leaves_valid_files_for_the_scans_done(
    tmp_path: Path, drive: Path, how: str
) -> None:
    """Interrupted after 40 scans, by Python's KeyboardInterrupt (a library caller) or by
    the flag ``mast track``'s signal handler sets (checked between two scans)."""
    interrupt = threading.Event()
    totals: list[int | None] = []

    def stop_after_40(scans: int, fixes: int, total: int | None) -> None:
        totals.append(total)
        if scans == 40:
            if how == "flag":
                interrupt.set()
            else:
                raise KeyboardInterrupt

    result = track_run(
        drive / "scans.bag",
        read_survey(drive / "beacons.csv"),
        tmp_path,
        config=CONFIG,
        progress=stop_after_40,
        interrupt=interrupt,
    )
    assert result.interrupted
    assert result.summary.scans == 40
    assert set(totals) == {250}  # the bag's LaserScan count, from its index: a bar's total
    lines = (tmp_path / "fixes.jsonl").read_text().splitlines()
    assert len(lines) == 40
    json.loads(lines[-1])
    assert len(_rows(tmp_path / "trajectory.csv")) == result.summary.placed > 0
    las = laspy.read(tmp_path / "map.las")
    assert int(np.max(las.scan_index)) < 40
    assert not ezdxf.readfile(tmp_path / "map.dxf").audit().has_errors
    assert "</html>" in (tmp_path / "report.html").read_text()


@pytest.mark.parametrize("after_bytes", [1, 40_000, 120_000])
def test_ctrl_c_during_mast_track_always_leaves_every_file(
    tmp_path: Path, drive: Path, after_bytes: int
) -> None:
    """Ctrl-C sets a flag checked between scans (it once landed inside a compiled kernel:
    exit 70 and an empty --out). Sent once the run has written ``after_bytes`` of records
    (a condition, not a sleep), it always ends with 130 and every file complete."""
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "mast", "track", str(drive / "scans.bag"), "-b",
         str(drive / "beacons.csv"), "--out", str(out), "--range-sigma", "0.012"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )  # fmt: skip
    try:
        while proc.poll() is None:
            parts = list(out.glob(".fixes.jsonl.*.part")) if out.exists() else []
            if parts and parts[0].exists() and parts[0].stat().st_size >= after_bytes:
                break
            time.sleep(0.01)
        if proc.poll() is not None:
            pytest.skip("the run ended before it could be interrupted")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err.decode()
    assert "interrupted; the files hold the scans read until then" in err.decode()
    assert "internal error" not in err.decode()
    for name in RUN_FILES:
        assert (out / name).exists(), name
    lines = (out / "fixes.jsonl").read_text().splitlines()
    assert 0 < len(lines) < 250
    json.loads(lines[-1])
    assert not list(out.glob(".*.part"))


def test_several_runs_on_a_dask_local_cluster(tmp_path: Path) -> None:
    from mast.runs.batch import track_runs

    folder = tmp_path / "runs"
    for seed in (1, 2):
        write_scenario([drive_scene(seed, scans=40)], folder / f"s{seed}", fmt="bag")
    bags = sorted(folder.glob("s*/*/scans.bag"))
    survey = bags[0].parent / "beacons.csv"  # each run with its own survey: run 2 gets none fixed
    out = tmp_path / "out"
    out.mkdir()
    outcomes = track_runs(
        bags, survey, out, options={"config": CONFIG}, workers=2, echo=lambda _: None
    )
    assert [o.run for o in outcomes] == [str(b) for b in bags]
    assert outcomes[0].status == "placed"
    assert outcomes[0].placed == outcomes[0].scans == 40
    assert outcomes[1].status in ("placed", "no_fix")
    index = _rows(out / "index.csv")
    assert [r["run"] for r in index] == [str(b) for b in bags]
    assert (Path(index[0]["folder"]) / "report.html").is_file()


# --- frames and odometry -------------------------------------------------------------


@pytest.mark.parametrize(
    ("azimuth_deg", "dx", "dy", "dtheta_deg", "expected"),
    [
        (0.0, 1.0, 0.0, 0.0, (0.0, 1.0, 0.0)),  # facing grid north, one metre forward
        (90.0, 1.0, 0.0, 0.0, (1.0, 0.0, 90.0)),  # facing east
        (0.0, 0.0, 1.0, 0.0, (-1.0, 0.0, 0.0)),  # facing north, one metre to the left: west
        (90.0, 0.0, 0.0, 10.0, (0.0, 0.0, 80.0)),  # a left turn lowers the azimuth
    ],
)
def test_a_motion_in_the_scanner_frame_moves_the_pose_in_the_mine_frame(
    azimuth_deg: float,
    dx: float,
    dy: float,
    dtheta_deg: float,
    expected: tuple[float, float, float],
) -> None:
    motion = Motion(dx, dy, math.radians(dtheta_deg), np.eye(3) * 1e-6, 100, 0.01)
    pose, cov = compose(Pose2D.from_degrees(1000.0, 2000.0, azimuth_deg), np.zeros((3, 3)), motion)
    assert pose.easting == pytest.approx(1000.0 + expected[0])
    assert pose.northing == pytest.approx(2000.0 + expected[1])
    assert pose.azimuth_deg == pytest.approx(expected[2])
    assert np.allclose(cov, cov.T)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_scan_to_scan_odometry_recovers_the_drives_motion(drive: Path) -> None:
    scans = list(read_laserscans(drive / "scans.bag"))
    truth = _rows(drive / "truth.csv")

    def pose(k: int) -> Pose2D:
        t = truth[k]
        return Pose2D.from_degrees(
            float(t["easting"]), float(t["northing"]), float(t["azimuth_deg"])
        )

    z: list[Any] = []
    for k in range(0, 200, 20):
        a, b = pose(k), pose(k + 5)
        m = scan_to_scan(keyframe(scans[k]), scans[k + 5], range_sigma_m=0.012)
        assert m is not None
        th = math.pi / 2 - a.azimuth
        de, dn = b.easting - a.easting, b.northing - a.northing
        true = np.array(
            [
                math.cos(th) * de + math.sin(th) * dn,
                -math.sin(th) * de + math.cos(th) * dn,
                -(b.azimuth - a.azimuth),
            ]
        )
        err = np.array([m.dx, m.dy, m.dtheta]) - true
        assert math.hypot(err[0], err[1]) < 0.02
        z.append(float(err @ np.linalg.solve(m.covariance, err)))
    assert np.mean(z) < 3 * 3  # consistent with its covariance (3 dof), within a margin


def _relative(a: Pose2D, b: Pose2D) -> NDArray[np.float64]:
    """``b`` in the scanner frame of ``a``: (dx forward, dy left, dtheta counter-clockwise)."""
    th = math.pi / 2 - a.azimuth
    de, dn = b.easting - a.easting, b.northing - a.northing
    return np.array(
        [
            math.cos(th) * de + math.sin(th) * dn,
            -math.sin(th) * de + math.cos(th) * dn,
            math.remainder(-(b.azimuth - a.azimuth), math.tau),
        ]
    )


def _truth_poses(drive: Path) -> list[Pose2D]:
    return [
        Pose2D.from_degrees(float(t["easting"]), float(t["northing"]), float(t["azimuth_deg"]))
        for t in _rows(drive / "truth.csv")
    ]


def test_a_step_beyond_icps_reach_is_found_by_searching_the_window(drive: Path) -> None:
    """A second apart (1-3 m), ICP from a standing start does not reach the motion; the
    correlative search over all the vehicle could have done does, within its sigmas."""
    scans = list(read_laserscans(drive / "scans.bag"))
    truth = _truth_poses(drive)
    for k in (0, 60, 120, 180):
        true = _relative(truth[k], truth[k + 25])
        key = keyframe(scans[k])
        m = recover_motion(
            key,
            scans[k + 25],
            guess=(0.0, 0.0, 0.0),
            radius_m=4.0,
            yaw_rad=math.radians(30.0),
            range_sigma_m=0.012,
        )
        assert m is not None
        err = np.array([m.dx, m.dy, m.dtheta]) - true
        assert math.hypot(err[0], err[1]) < 0.05, (k, err)
        assert float(err @ np.linalg.solve(m.covariance, err)) < 16.27  # chi2(3) 99.9 %
        icp = scan_to_scan(key, scans[k + 25], range_sigma_m=0.012)
        assert icp is None or math.hypot(icp.dx - true[0], icp.dy - true[1]) > 0.2


@pytest.fixture(scope="module")
def sparse(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A drive that kept one scan a second (1-3 m apart), as logs thinned for SLAM do."""
    out = tmp_path_factory.mktemp("sparse")
    (w,) = write_scenario([drive_scene(3, scans=60, rate_hz=1.0)], out, fmt="bag", scenario="drive")
    return w.folder


def test_a_log_with_a_scan_a_second_is_chained_with_max_gap_and_stays_honest(
    sparse: Path, tmp_path: Path
) -> None:
    survey = read_survey(sparse / "beacons.csv")
    truth = _truth_poses(sparse)
    runs = {}
    for gap in (0.5, 1.5):
        out = tmp_path / f"gap{gap}"
        out.mkdir()
        config = TrackConfig(locator=LocatorConfig(range_sigma_m=0.012), max_gap_s=gap)
        runs[gap] = track_run(sparse / "scans.bag", survey, out, config=config, warn=lambda _: 0)
    unchained = runs[0.5]
    assert unchained.summary.gaps == 59
    assert {p.source for p in unchained.placed} == {"fix"}
    chained = runs[1.5]
    assert chained.summary.gaps == 0
    odometry = [p for p in chained.placed if p.source == "odometry"]
    assert len(odometry) >= 10
    errors, inside = [], []
    for p in odometry:
        t = truth[p.scan]
        d = np.array([p.pose.easting - t.easting, p.pose.northing - t.northing])
        errors.append(math.hypot(*d))
        inside.append(float(d @ np.linalg.solve(p.covariance[:2, :2], d)) <= 5.991)
    # Most steps are found to a few centimetres; where the drift's rock repeats within
    # a step, the step is declared ambiguous and its scans carry metres of sigma.
    assert np.mean(np.array(errors) < 0.05) >= 0.75
    assert np.mean(inside) >= 0.95


def test_mast_track_hints_at_max_gap_when_scans_are_too_far_apart(
    sparse: Path, tmp_path: Path
) -> None:
    r = _track(sparse / "scans.bag", sparse, tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert "hint: 59 of 60 scans came more than 0.5 s after" in r.stderr
    assert "--max-gap" in r.stderr


def test_a_scan_that_can_only_coast_for_seconds_breaks_the_chain(drive: Path) -> None:
    """A blind scan 40 ms on coasts at constant velocity; one two seconds on would be
    known to metres, and starts the chain again instead."""
    scans = list(read_laserscans(drive / "scans.bag"))
    survey = read_survey(drive / "beacons.csv")
    blind = replace(scans[1], ranges_m=np.full_like(scans[1].ranges_m, np.nan))
    for later_ns, chained in ((40_000_000, True), (2_000_000_000, False)):
        tracker = RunTracker(survey, replace(CONFIG, max_gap_s=3.0))
        tracker.step(0, scans[0])
        step = tracker.step(1, replace(blind, stamp_ns=scans[0].stamp_ns + later_ns))
        assert (step.motion is not None) is chained
        if chained:
            assert step.motion is not None
            assert step.motion.matches == 0
