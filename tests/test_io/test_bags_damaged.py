"""Bags as they come from the field: a bad message is skipped and named, a bag cut short
gives every scan of its intact chunks (issue 10, item 3)."""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from mast import InputError, Scan
from mast.io import read_laserscans, write_laserscans

N = 400


@pytest.fixture(scope="module")
def scans() -> list[Scan]:
    rng = np.random.default_rng(7)
    return [
        Scan.from_laserscan(
            angle_min=-math.radians(135),
            angle_increment=math.radians(0.25),
            ranges=rng.uniform(0.5, 25, 1081),
            range_max=30.0,
            stamp_ns=1_700_000_000_000_000_000 + i * 40_000_000,
            frame_id="laser",
        )
        for i in range(N)
    ]


def test_a_ros1_bag_cut_short_gives_the_scans_of_its_intact_chunks(
    tmp_path: Path, scans: list[Scan]
) -> None:
    whole = tmp_path / "run.bag"
    write_laserscans(whole, scans, kind="rosbag1")
    data = whole.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.8)])
    told: list[str] = []
    got = list(read_laserscans(cut, on_skip=told.append))
    assert 0 < len(got) < N
    for a, b in zip(got, scans, strict=False):
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_allclose(a.ranges_m, b.ranges_m, rtol=1e-6)
    assert len(told) == 1
    assert "cut short" in told[0]
    assert f"the {len(got)} message(s) of /scan before it are kept" in told[0]
    with pytest.raises(InputError, match="cut short"):
        list(read_laserscans(cut))  # strict readers still refuse it


def test_a_bag_cut_before_any_chunk_is_a_clear_error(tmp_path: Path, scans: list[Scan]) -> None:
    whole = tmp_path / "run.bag"
    write_laserscans(whole, scans[:50], kind="rosbag1")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(whole.read_bytes()[:5000])
    with pytest.raises(InputError, match="no intact message before the damage"):
        list(read_laserscans(cut, on_skip=lambda _: None))


def test_an_undecodable_ros1_message_is_skipped_and_named(
    tmp_path: Path, scans: list[Scan]
) -> None:
    path = tmp_path / "run.bag"
    write_laserscans(path, scans[:60], kind="rosbag1")
    data = bytearray(path.read_bytes())
    marker = b"\x05\x00\x00\x00laser"  # the header's frame_id of every message
    at = -1
    for _ in range(10):  # the 10th message
        at = data.index(marker, at + 1)
    data[at : at + 4] = b"\xf0\xff\xff\x7f"  # a frame_id two gigabytes long
    path.write_bytes(bytes(data))
    told: list[str] = []
    got = list(read_laserscans(path, on_skip=told.append))
    assert len(got) == 59
    assert len(told) == 1
    assert "message 10 of /scan cannot be decoded" in told[0]
    assert told[0].endswith("skipped")
    with pytest.raises(InputError, match="message 10 of /scan cannot be decoded"):
        list(read_laserscans(path))


def test_an_undecodable_ros2_message_is_skipped(tmp_path: Path, scans: list[Scan]) -> None:
    path = tmp_path / "run_db3"
    write_laserscans(path, scans[:30], kind="sqlite3")
    (db,) = path.glob("*.db3")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = ? WHERE id = 7", (b"\x00\x01garbage",))
    told: list[str] = []
    got = list(read_laserscans(path, on_skip=told.append))
    assert len(got) == 29
    assert len(told) == 1
    assert "message 7 of /scan cannot be decoded" in told[0]
