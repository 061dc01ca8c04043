"""The one LAS/LAZ writer: whole files or none, the suffix decides compression, and
coordinates beyond int32's reach are found rather than wrapped."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest

from mast.errors import OutputError
from mast.io.las import (
    INT32_MAX,
    LAS_SCALE_M,
    LasWriter,
    gps_adjusted_time,
    las_integers,
    las_offsets,
    new_las_header,
)

ORIGIN = np.array([512_345.678, 7_001_234.5, 812.3])


def _points(n: int) -> np.ndarray:
    rng = np.random.default_rng(4)
    return ORIGIN + rng.uniform(-50.0, 50.0, (n, 3))


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_points_come_back_at_a_tenth_of_a_millimetre(tmp_path: Path, suffix: str) -> None:
    xyz = _points(3000)
    header = new_las_header(offsets=las_offsets(ORIGIN, 1.0), software="test", system="t")
    path = tmp_path / f"cloud{suffix}"
    with LasWriter(path, header) as las:
        for part in np.array_split(xyz, 3):
            rec = las.zeros(len(part))
            rec.X, rec.Y, rec.Z = las_integers(part, header.offsets)[0].T
            rec.gps_time = gps_adjusted_time(np.full(len(part), 1_700_000_000 * 10**9))
            assert las.write(rec) == len(part)
        assert not path.exists()  # only the temporary file until closed
        assert las.writing.exists()
    back = laspy.read(path)
    assert back.header.point_count == 3000
    assert back.header.are_points_compressed == (suffix == ".laz")
    assert back.header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD
    assert back.header.system_identifier == "t"
    got = np.column_stack([back.x, back.y, back.z])
    assert np.max(np.abs(got - xyz)) <= LAS_SCALE_M / 2 + 1e-9
    assert np.allclose(back.header.mins, xyz.min(axis=0), atol=LAS_SCALE_M)
    assert np.allclose(back.header.maxs, xyz.max(axis=0), atol=LAS_SCALE_M)


def test_a_failure_part_way_leaves_no_file(tmp_path: Path) -> None:
    header = new_las_header(offsets=las_offsets(ORIGIN, 1.0), software="test")
    path = tmp_path / "cloud.laz"
    las = LasWriter(path, header)

    def fail_part_way() -> None:
        with las:
            las.write(las.zeros(10))
            raise RuntimeError("stopped")

    with pytest.raises(RuntimeError, match="stopped"):
        fail_part_way()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(OutputError, match=r"cloud\.laz: already closed"):
        las.write(las.zeros(1))


def test_an_unwritable_place_names_the_file(tmp_path: Path) -> None:
    header = new_las_header(offsets=las_offsets(ORIGIN, 1.0), software="test")
    with pytest.raises(OutputError, match=r"nowhere/cloud\.las: cannot write"):
        LasWriter(tmp_path / "nowhere" / "cloud.las", header)


def test_coordinates_beyond_int32_are_found_not_wrapped() -> None:
    offsets = las_offsets(ORIGIN, 1000.0)
    assert offsets.tolist() == [512_000.0, 7_001_000.0, 1000.0]
    reach = INT32_MAX * LAS_SCALE_M
    xyz = np.array([ORIGIN, ORIGIN + [reach + 10.0, 0.0, 0.0], ORIGIN + [0.0, -reach - 1000, 0]])
    ints, far = las_integers(xyz, offsets)
    assert far == 2  # the farthest of the two beyond
    ints, far = las_integers(xyz[:1], offsets)
    assert far == -1
    assert ints.dtype == np.int32
    assert ints[0].tolist() == [3_456_780, 2_345_000, -1_877_000]
    assert las_integers(np.zeros((0, 3)), offsets)[1] == -1


def test_offsets_just_below_zero_are_zero_not_minus_zero() -> None:
    offsets = las_offsets([-0.3, 0.2, -0.4], 1.0)
    assert offsets.tolist() == [0.0, 0.0, 0.0]
    assert not np.any(np.signbit(offsets))


def test_a_library_failure_at_opening_leaves_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def half_open(path: Path, **_: object) -> None:
        Path(path).write_bytes(b"LASF")
        raise laspy.LaspyException("no LAZ backend")

    monkeypatch.setattr(laspy, "open", half_open)
    header = new_las_header(offsets=las_offsets(ORIGIN, 1.0), software="test")
    with pytest.raises(laspy.LaspyException, match="no LAZ backend"):
        LasWriter(tmp_path / "cloud.laz", header)
    assert list(tmp_path.iterdir()) == []


def test_a_georeferenced_copy_keeps_its_source_version(tmp_path: Path) -> None:
    from mast.cloud.io import open_cloud

    xyz = _points(500) - ORIGIN  # a local frame
    src = laspy.create(point_format=3, file_version="1.2")
    src.header.offsets = [0.0, 0.0, 0.0]
    src.header.scales = [0.001, 0.001, 0.001]
    src.x, src.y, src.z = xyz.T
    src.gps_time = np.arange(500, dtype=float)
    src.write(tmp_path / "local.las")
    shift = np.array([512_000.0, 7_001_000.0, 800.0])
    n = open_cloud(tmp_path / "local.las").write_georeferenced(
        tmp_path / "grid.laz", lambda p, t: p + shift, shift
    )
    out = laspy.read(tmp_path / "grid.laz")
    assert n == 500
    assert str(out.header.version) == "1.2"
    assert out.header.point_format.id == 3
    assert np.max(np.abs(np.column_stack([out.x, out.y, out.z]) - (xyz + shift))) < 0.001
