"""A 3D lidar's PointCloud2 frames through the ``mast`` process: ``locate``, ``track`` and
``live replay://`` give the 3D record (docs/fix.schema.json, ``dimensions`` 3) with a
pose within a few sigmas of the simulator's truth; a survey without elevations is a
one-line error with status 2; a 2D scan's record is unchanged.

The frames come from one seeded simulated drift (a VLP-16 at 2 cm), three frames owed a
fix, written as a ROS 1 bag and an MCAP file. Nothing here depends on timing."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from mast.core.beacon import Beacon, Survey
from mast.core.pose3d import Frame3D, Pose3D
from mast.io.beacons_csv import write_survey
from mast.io.pointclouds import write_pointclouds
from mast.io.trajectory import rotation_quaternion
from mast.pipeline.adjust3d import UNBRACKETED
from mast.pipeline.locator3d import Locator3DConfig, locate3d
from mast.report.record import fix3d_record
from mast.sim.lidar3d import random_drift_scene
from tests._cli import run_mast_text

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "docs" / "fix.schema.json"
#: The drift (six poses drawn) and three of its frames owed a fix, which the locator fixes.
SEED = 4
POSES = 6
FRAMES = (1, 3, 5)
T0_NS = 1_700_000_000 * 10**9
#: How far from the truth a fix may be, in its own sigmas.
K_SIGMA = 5.0


@pytest.fixture(scope="module")
def lidar_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    folder = tmp_path_factory.mktemp("lidar3d")
    scene = random_drift_scene(SEED, frames=POSES, lidar="vlp16", range_sigma_m=0.02)
    sims = [scene.simulate(i) for i in FRAMES]
    frames = [replace(s.frame, stamp_ns=T0_NS + k * 100_000_000) for k, s in enumerate(sims)]
    write_pointclouds(folder / "run.bag", frames, topic="/points")
    write_pointclouds(folder / "run_mcap", frames, kind="mcap", topic="/lidar/points")
    write_survey(folder / "beacons.csv", scene.survey)
    flat = Survey([Beacon(b.id, b.edges) for b in scene.survey])
    write_survey(folder / "flat.csv", flat)
    return {
        "folder": folder,
        "truth": [s.pose for s in sims],
        "stamps": [f.stamp_ns for f in frames],
        "survey": scene.survey,
        "frames": frames,
    }


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft202012Validator:
    schema = json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(
        schema, format_checker=jsonschema.Draft202012Validator.FORMAT_CHECKER
    )


def _valid(validator: jsonschema.Draft202012Validator, rec: dict[str, Any]) -> None:
    errors = sorted(validator.iter_errors(rec), key=str)
    assert not errors, [e.message for e in errors]


def _records(stdout: str) -> list[dict[str, Any]]:
    return [json.loads(line) for line in stdout.splitlines() if line.strip()]


def _near_truth(rec: dict[str, Any], truth: Pose3D) -> None:
    """Each of the six parameters within K_SIGMA of its sigma from the truth (the
    elevation only where it was observed)."""
    assert rec["status"] == "fix"
    assert abs(rec["easting"] - truth.easting) <= K_SIGMA * rec["sigma_easting_m"]
    assert abs(rec["northing"] - truth.northing) <= K_SIGMA * rec["sigma_northing_m"]
    if rec["elevation_observed"]:
        assert abs(rec["elevation_m"] - truth.elevation) <= K_SIGMA * rec["sigma_elevation_m"]
    daz = (rec["azimuth_deg"] - math.degrees(truth.azimuth) + 180.0) % 360.0 - 180.0
    assert abs(daz) <= K_SIGMA * rec["sigma_azimuth_deg"]
    assert abs(rec["roll_deg"] - math.degrees(truth.roll)) <= K_SIGMA * rec["sigma_roll_deg"]
    assert abs(rec["pitch_deg"] - math.degrees(truth.pitch)) <= K_SIGMA * rec["sigma_pitch_deg"]


def test_locate_gives_a_3d_record_per_frame_near_the_truth(
    lidar_run: dict[str, Any], validator: jsonschema.Draft202012Validator
) -> None:
    folder = lidar_run["folder"]
    done = run_mast_text(
        "locate", str(folder / "run.bag"), "-b", str(folder / "beacons.csv"),
        "--scanner", "vlp16", "--format", "json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    recs = _records(done.stdout)
    assert [r["scan"] for r in recs] == list(range(len(FRAMES)))
    assert [r["stamp_ns"] for r in recs] == lidar_run["stamps"]
    for rec, truth in zip(recs, lidar_run["truth"], strict=True):
        _valid(validator, rec)
        assert rec["dimensions"] == 3
        assert rec["topic"] == "/points"
        assert rec["range_sigma_m"] == 0.02  # the VLP-16's
        assert rec["inputs"]["scanner"] == "vlp16"
        assert rec["covariance_order"] == [
            "easting_m", "northing_m", "elevation_m", "roll_rad", "pitch_rad", "azimuth_rad"
        ]  # fmt: skip
        cov = np.array(rec["covariance"])
        assert cov.shape == (6, 6)
        assert np.allclose(cov, cov.T)
        assert math.sqrt(cov[5, 5]) == pytest.approx(
            math.radians(rec["sigma_azimuth_deg"]), rel=1e-5
        )
        assert len(rec["beacons"]) >= 2
        _near_truth(rec, truth)


def test_locate_text_report_and_the_range_sigma_option(lidar_run: dict[str, Any]) -> None:
    folder = lidar_run["folder"]
    done = run_mast_text(
        "locate", str(folder / "run_mcap"), "-b", str(folder / "beacons.csv"),
        "--range-sigma", "0.025",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("MAST 3D fix report") == len(FRAMES)
    assert "FIX (six degrees of freedom)" in done.stdout
    assert "Range σ       25.0 mm" in done.stdout
    for word in ("Elevation", "Roll", "Pitch", "Azimuth"):
        assert word in done.stdout


@pytest.mark.parametrize("command", ["locate", "track", "live"])
def test_a_survey_without_elevations_is_a_one_line_error(
    lidar_run: dict[str, Any], command: str, tmp_path: Path
) -> None:
    folder = lidar_run["folder"]
    run = str(folder / "run.bag")
    flat = str(folder / "flat.csv")
    args = {
        "locate": ["locate", run, "-b", flat],
        "track": ["track", run, "-b", flat, "--out", str(tmp_path / "out")],
        "live": ["live", f"replay://{run}?topic=/points", "-b", flat],
    }[command]
    done = run_mast_text(*args)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert flat in lines[0]
    assert "elevation" in lines[0]
    assert "Traceback" not in done.stderr
    assert done.stdout == ""
    if command == "track":
        assert not any((tmp_path / "out").glob("*"))  # a refused run leaves nothing


def test_track_writes_a_6dof_trajectory(
    lidar_run: dict[str, Any], validator: jsonschema.Draft202012Validator, tmp_path: Path
) -> None:
    import laspy

    folder = lidar_run["folder"]
    out = tmp_path / "run"
    done = run_mast_text(
        "track", str(folder / "run.bag"), "-b", str(folder / "beacons.csv"),
        "--scanner", "vlp16", "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "fixed one by one" in done.stdout  # the summary says what a 3D run is
    # the settings the frames were located with: --config gives the same results again
    assert "range_sigma_m = 0.02" in (out / "config.toml").read_text(encoding="utf-8")
    recs = _records((out / "fixes.jsonl").read_text(encoding="utf-8"))
    assert len(recs) == len(FRAMES)
    for rec in recs:
        _valid(validator, rec)
    fixed = [r for r in recs if r["status"] == "fix"]
    assert fixed
    # TUM: t x y z qx qy qz qw, z the elevation, q the full sensor-to-grid rotation
    tum = [
        line.split()
        for line in (out / "trajectory.tum").read_text(encoding="utf-8").splitlines()
        if not line.startswith("#")
    ]
    assert len(tum) == len(fixed)
    for row, rec in zip(tum, fixed, strict=True):
        seconds, nanoseconds = divmod(rec["stamp_ns"], 10**9)
        assert row[0] == f"{seconds}.{nanoseconds:09d}"
        x, y, z, qx, qy, qz, qw = (float(v) for v in row[1:])
        assert (x, y, z) == pytest.approx(
            (rec["easting"], rec["northing"], rec["elevation_m"]), abs=1e-6
        )
        pose = Pose3D.from_degrees(
            rec["easting"], rec["northing"], rec["elevation_m"],
            rec["azimuth_deg"], rec["pitch_deg"], rec["roll_deg"],
        )  # fmt: skip
        assert qw >= 0
        assert (qx, qy, qz, qw) == pytest.approx(rotation_quaternion(pose.rotation), abs=1e-7)
        assert _quaternion_matrix(qx, qy, qz, qw) == pytest.approx(pose.rotation, abs=1e-7)
    header = (out / "trajectory.csv").read_text(encoding="utf-8").splitlines()[0]
    assert header.endswith("elevation_m,roll_deg,pitch_deg,sigma_elevation_m,sigma_roll_deg,"
                           "sigma_pitch_deg")  # fmt: skip
    cloud = laspy.read(out / "map.las")
    assert len(cloud.points) > 10_000
    # real z: the drift's floor and roof, metres apart
    assert float(np.ptp(np.asarray(cloud.z))) > 2.0
    assert (out / "fixes.geojson").exists()
    with (out / "fixes_points.csv").open(encoding="utf-8") as fh:
        points = list(csv.DictReader(fh))
    # an elevation not observed (to 5 cm) is left empty in the point list
    assert [float(p["elevation"]) if p["elevation"] else None for p in points] == [
        pytest.approx(r["elevation_m"], abs=1e-3) if r["elevation_observed"] else None
        for r in fixed
    ]


def test_range_limits_on_3d_frames_are_named_as_not_applied(lidar_run: dict[str, Any]) -> None:
    folder = lidar_run["folder"]
    done = run_mast_text(
        "locate", str(folder / "run.bag"), "-b", str(folder / "beacons.csv"),
        "--scanner", "vlp16", "--range-max", "30", "--format", "json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "--range-max applies to 2D scans" in done.stderr


def test_several_3d_runs_are_refused_before_anything_is_written(
    lidar_run: dict[str, Any], tmp_path: Path
) -> None:
    import shutil

    folder = lidar_run["folder"]
    second = tmp_path / "second.bag"
    shutil.copy(folder / "run.bag", second)
    out = tmp_path / "run"
    done = run_mast_text(
        "track", str(folder / "run.bag"), str(second), "-b", str(folder / "beacons.csv"),
        "--scanner", "vlp16", "--out", str(out),
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "tracked one at a time" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (out / "config.toml").exists()  # a refused run leaves nothing


def test_live_replays_a_pointcloud2_topic(
    lidar_run: dict[str, Any], validator: jsonschema.Draft202012Validator
) -> None:
    folder = lidar_run["folder"]
    done = run_mast_text(
        "live", f"replay://{folder / 'run_mcap'}?topic=/lidar/points&rate=100",
        "-b", str(folder / "beacons.csv"), "--scanner", "vlp16",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    recs = _records(done.stdout)
    assert recs
    for rec in recs:
        _valid(validator, rec)
        assert rec["dimensions"] == 3
        assert rec["topic"] == "/lidar/points"
        assert rec["tracking"] is False
        assert {"received_ns", "latency_ms", "dropped"} <= set(rec)
    # the newest frame wins when locating falls behind: every frame is either located or
    # counted as dropped
    assert len(recs) + sum(r["dropped"] for r in recs) == len(FRAMES)
    for rec in recs:
        if rec["status"] == "fix":
            _near_truth(rec, lidar_run["truth"][rec["scan"]])
    assert "located in 3D" in done.stderr


def test_the_3d_warm_up_fixes_the_demos_frame() -> None:
    """The frame :func:`compile_3d` locates is fixed: every 3D stage and its kernels ran."""
    from mast.cli.warmup import compile_3d

    assert compile_3d() is True


def test_live_compiles_the_3d_kernels_before_the_first_frame(
    lidar_run: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A 3D lidar's first frame does not wait for the compiler: ``mast live`` warms the 3D
    kernels up before it takes frames (in this process, to see the order of calls)."""
    from typer.testing import CliRunner

    import mast.cli.warmup
    from mast.cli.root import app
    from mast.runs.frames3d import FrameLocator

    calls: list[str] = []
    monkeypatch.setattr(mast.cli.warmup, "compile_3d", lambda: calls.append("warm-up") or True)
    locate = FrameLocator.locate

    def located(self: FrameLocator, *args: Any, **kwargs: Any) -> Any:
        calls.append("frame")
        return locate(self, *args, **kwargs)

    monkeypatch.setattr(FrameLocator, "locate", located)
    folder = lidar_run["folder"]
    done = CliRunner().invoke(
        app,
        ["live", f"replay://{folder / 'run.bag'}?topic=/points&rate=100",
         "-b", str(folder / "beacons.csv"), "--scanner", "vlp16", "--max-scans", "1"],
    )  # fmt: skip
    assert done.exit_code == 0, done.output
    assert calls[:2] == ["warm-up", "frame"]
    assert calls.count("warm-up") == 1


def test_a_2d_bag_is_located_as_before(validator: jsonschema.Draft202012Validator) -> None:
    examples = Path(__file__).resolve().parents[2] / "examples"
    done = run_mast_text(
        "locate", str(examples / "run.bag"), "-b", str(examples / "beacons.csv"),
        "--scanner", "lms1xx-0.25", "--format", "json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    recs = _records(done.stdout)
    assert any(r["status"] == "fix" for r in recs)
    for rec in recs:
        _valid(validator, rec)
        assert "dimensions" not in rec
        assert "elevation_m" not in rec
        if rec["status"] == "fix":
            assert rec["covariance_order"] == ["easting_m", "northing_m", "azimuth_rad"]
            assert "residuals" in rec


def test_an_unobserved_elevation_is_null_with_its_flag(
    lidar_run: dict[str, Any], validator: jsonschema.Draft202012Validator
) -> None:
    cfg = Locator3DConfig(range_sigma_m=0.02)
    fix = locate3d(lidar_run["frames"][0], lidar_run["survey"], config=cfg)
    assert fix.ok
    assert fix.adjustment is not None
    cov = fix.adjustment.covariance.copy()
    cov[2, :] = cov[:, 2] = 0.0
    cov[2, 2] = UNBRACKETED
    unbracketed = replace(fix, adjustment=replace(fix.adjustment, covariance=cov, top_edges=0))
    rec = fix3d_record(unbracketed, range_sigma_m=0.02, survey_sigma_m=0.003)
    _valid(validator, rec)
    assert rec["elevation_observed"] is False
    assert rec["sigma_elevation_m"] is None
    assert rec["ci95_elevation_m"] is None
    assert rec["elevation_m"] is not None
    assert rec["sigma_easting_m"] > 0


def test_no_fix_records_carry_the_3d_keys_as_null(
    lidar_run: dict[str, Any], validator: jsonschema.Draft202012Validator
) -> None:
    survey: Survey = lidar_run["survey"]
    frame = lidar_run["frames"][0]
    far = Frame3D(frame.points[:0], stamp_ns=frame.stamp_ns)  # no return at all
    fix = locate3d(far, survey, config=Locator3DConfig(range_sigma_m=0.02))
    assert not fix.ok
    rec = fix3d_record(fix, range_sigma_m=0.02, survey_sigma_m=0.003)
    _valid(validator, rec)
    for key in ("elevation_m", "roll_deg", "pitch_deg", "sigma_elevation_m", "sigma_roll_deg",
                "sigma_pitch_deg", "easting"):  # fmt: skip
        assert rec[key] is None
    assert rec["reason"]


def test_rotation_quaternion_round_trips() -> None:
    rng = np.random.default_rng(36)
    for _ in range(200):
        roll, pitch = rng.uniform(-1.5, 1.5, 2)
        pose = Pose3D(0.0, 0.0, 0.0, float(rng.uniform(0, 2 * math.pi)), float(pitch), float(roll))
        q = rotation_quaternion(pose.rotation)
        assert q[3] >= 0
        assert math.fsum(v * v for v in q) == pytest.approx(1.0)
        assert _quaternion_matrix(*q) == pytest.approx(pose.rotation, abs=1e-12)


def _quaternion_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    return np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )
