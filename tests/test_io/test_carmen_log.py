import gzip
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from mast import InputError
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.io.carmen_log import read_carmen_log
from mast.pipeline.segmentation import segment_scan
from tests._paths import SHARED_DATA

LOGS = SHARED_DATA / "carmen_corrected"
FHW = LOGS / "fhw-corrected.log.gz"
FREIBURG = LOGS / "freiburg-101-corrected.log.gz"


def _flaser(ranges: list[float], x: float, y: float, theta: float, stamp: float = 12.5) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    return f"FLASER {len(ranges)} {r} {x} {y} {theta} {x} {y} {theta} {stamp} host {stamp}"


LOG = "\n".join(
    [
        "# message formats defined: PARAM SYNC ODOM FLASER RLASER",
        "PARAM robot_frontlaser_offset 0.0 nohost 0",
        "ODOM 0 0 0 0 0 0 0.009984 pippo 0.009984",
        _flaser([1.0, 2.0, 51.05, 3.0, 4.0], 1.0, 2.0, 0.25),
        "NEFF 12.0 13.0 host 13.0",
        "",
        _flaser([5.0, 5.0, 5.0], -3.0, 0.5, -2.0, stamp=20.0),
    ]
)


def test_reads_flaser_lines_and_skips_the_rest(write_text: Callable[..., Path]) -> None:
    out = list(read_carmen_log(write_text("run.log", LOG + "\n")))
    assert len(out) == 2
    scan, pose = out[0]
    assert len(scan) == 5
    np.testing.assert_allclose(scan.angles_rad, np.linspace(-math.pi / 2, math.pi / 2, 5))
    np.testing.assert_array_equal(scan.valid, [True, True, False, True, True])
    assert scan.range_max_m == pytest.approx(49.9)
    assert scan.stamp_ns == 12_500_000_000
    assert (pose.easting, pose.northing) == (1.0, 2.0)
    assert pose.azimuth == pytest.approx(math.pi / 2 - 0.25)
    # azimuth kept in [0, 2 pi): theta = -2 rad is azimuth 90 deg + 114.6 deg
    assert out[1][1].azimuth_deg == pytest.approx(90.0 + math.degrees(2.0))


def test_reads_gzip_and_a_smaller_max_range_param(tmp_path: Path) -> None:
    p = tmp_path / "run.log.gz"
    text = "PARAM robot_front_laser_max 8.0 nohost 0\n" + _flaser([1.0, 9.0, 2.0], 0, 0, 0)
    with gzip.open(p, "wt") as fh:
        fh.write(text + "\n")
    ((scan, _),) = read_carmen_log(p)
    assert scan.range_max_m == 8.0
    np.testing.assert_array_equal(scan.valid, [True, False, True])


def test_pose_follows_the_log_heading() -> None:
    """Heading theta CCW from world x: a point ahead of the laser lies along theta."""
    theta = math.radians(30.0)
    pose = Pose2D(1.0, 2.0, math.pi / 2 - theta)
    ahead = pose.scanner_to_mine([[2.0, 0.0]])[0]
    left = pose.scanner_to_mine([[0.0, 1.0]])[0]
    np.testing.assert_allclose(ahead, [1 + 2 * math.cos(theta), 2 + 2 * math.sin(theta)])
    np.testing.assert_allclose(left, [1 - math.sin(theta), 2 + math.cos(theta)])


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("FLASER", r"beam count of at least 2"),
        ("FLASER x 1 2", r"beam count is not an integer"),
        ("FLASER 3 1 2 3 0 0 0", r"FLASER with 3 beams needs 14 fields, got 8"),
        (_flaser([1.0, 2.0, 3.0], 0, 0, 0).replace(" 2 ", " two ", 1), r"field is not a number"),
        (_flaser([1.0, 2.0, 3.0], 0, 0, math.nan), r"pose or time stamp is not finite"),
        ("PARAM robot_front_laser_max lots nohost 0", r"robot_front_laser_max is not a number"),
    ],
)
def test_malformed_lines_are_named(
    write_text: Callable[..., Path], line: str, message: str
) -> None:
    p = write_text("bad.log", _flaser([1.0, 2.0], 0, 0, 0) + "\n" + line + "\n")
    with pytest.raises(InputError, match=r"bad\.log, line 2: .*" + message):
        list(read_carmen_log(p))


def test_unreadable_files_are_named(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"missing\.log: cannot read"):
        list(read_carmen_log(tmp_path / "missing.log"))
    p = tmp_path / "broken.log.gz"
    p.write_bytes(b"\x1f\x8b" + b"\x00" * 20)
    with pytest.raises(InputError, match=r"broken\.log\.gz, line 1: cannot read"):
        list(read_carmen_log(p))


def _wall_residuals(a: tuple[Scan, Pose2D], b: tuple[Scan, Pose2D]) -> np.ndarray:
    """Distances of scan a's returns (mine frame) from scan b's long walls (mine frame)."""
    points = a[1].scanner_to_mine(a[0].points()[1])
    out = []
    for seg in segment_scan(b[0]).segments:
        if seg.length < 1.0:
            continue
        start, end = b[1].scanner_to_mine(np.array([seg.start, seg.end]))
        d = (end - start) / np.hypot(*(end - start))
        t = (points - start) @ d
        h = (points - start) @ np.array([-d[1], d[0]])
        near = (t > 0.1) & (t < np.hypot(*(end - start)) - 0.1) & (np.abs(h) < 0.3)
        out.append(np.abs(h[near]))
    return np.concatenate(out)


def _mirrored(item: tuple[Scan, Pose2D]) -> tuple[Scan, Pose2D]:
    """The same scan under the wrong sign of theta: azimuth = pi/2 + theta."""
    scan, pose = item
    return scan, Pose2D(pose.easting, pose.northing, math.pi - pose.azimuth)


@pytest.mark.skipif(not LOGS.is_dir(), reason="shared data not present")
@pytest.mark.parametrize(("path", "count", "beams"), [(FHW, 488, 180), (FREIBURG, 292, 360)])
def test_reads_the_real_logs(path: Path, count: int, beams: int) -> None:
    data = list(read_carmen_log(path))
    assert len(data) == count
    assert all(len(s) == beams for s, _ in data)
    # no-return ranges (50 m and more) are invalid, the others valid
    r = np.concatenate([s.ranges_m for s, _ in data])
    v = np.concatenate([s.valid for s, _ in data])
    np.testing.assert_array_equal(v, r < 50.0)


@pytest.mark.skipif(not LOGS.is_dir(), reason="shared data not present")
@pytest.mark.parametrize(("path", "first", "second"), [(FHW, 7, 17), (FREIBURG, 9, 12)])
def test_the_same_wall_lands_in_the_same_place_from_two_poses(
    path: Path, first: int, second: int
) -> None:
    """Two scans metres and tens of degrees apart: their walls coincide in the mine frame."""
    data = list(read_carmen_log(path))[: second + 1]
    a, b = data[first], data[second]
    assert np.hypot(*(a[1].position - b[1].position)) > 1.5
    assert abs(math.remainder(a[1].azimuth - b[1].azimuth, 2 * math.pi)) > math.radians(30)
    res = _wall_residuals(a, b)
    assert res.size >= 100
    assert np.median(res) < 0.02
    # the wrong sign of the azimuth scatters the same returns off the walls
    wrong = _wall_residuals(_mirrored(a), _mirrored(b))
    assert wrong.size < 20 or np.median(wrong) > 0.1
