"""Sources named by URL, the scanner clock carried onto the host's, the newest-scan slot."""

from __future__ import annotations

import numpy as np
import pytest

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.protocols.hokuyo import HokuyoSource, hokuyo_parameters
from mast.live.protocols.sick import SickSource
from mast.live.session import LatestSlot
from mast.live.sources import ReplaySource, open_source, read_run
from mast.live.stream import Received
from mast.live.tcp import DeviceClock
from tests.test_live.conftest import Drive


def test_tcp_urls_take_the_published_default_ports() -> None:
    sick = open_source("sick://192.168.0.1")
    hokuyo = open_source("hokuyo://192.168.0.10")
    assert isinstance(sick, SickSource)
    assert (sick.host, sick.port, sick.url) == ("192.168.0.1", 2111, "sick://192.168.0.1:2111")
    assert isinstance(hokuyo, HokuyoSource)
    assert hokuyo.port == 10940
    assert open_source("sick://scanner.local:2112").port == 2112  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("url", "problem"),
    [
        ("lidar://host", "give sick://"),
        ("sick://host:99999", "port"),
        ("sick://host/scan", "expected sick://HOST"),
        ("replay://", "needs the run's path"),
        ("replay://x?speed=2", "unknown option 'speed'"),
        ("replay://x?rate=0", "rate must be a positive number"),
    ],
)
def test_a_bad_source_is_named_with_its_problem(url: str, problem: str) -> None:
    with pytest.raises(InputError, match=problem):
        open_source(url)


def test_a_replay_reads_its_run_before_the_stream_starts(drive: Drive, tmp_path) -> None:  # type: ignore[no-untyped-def]
    source = open_source(f"replay://{drive.bag}?rate=4")
    assert isinstance(source, ReplaySource)
    assert source.rate == 4.0
    with pytest.raises(InputError, match="run not found"):
        open_source(f"replay://{tmp_path / 'missing.bag'}")
    (tmp_path / "notes.csv").write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="no scan CSV"):
        open_source(f"replay://{tmp_path}")


def test_a_folder_of_scan_csvs_plays_in_name_order_at_its_rate(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from mast.io import write_scan_csv

    angles = np.radians(np.arange(-10.0, 10.5, 0.5))
    for k in (2, 0, 1):
        write_scan_csv(tmp_path / f"scan_{k}.csv", Scan(angles, np.full(angles.size, 1.0 + k)))
    (tmp_path / "beacons.csv").write_text("beacon_id,edge,easting,northing\n")
    scans = list(read_run(tmp_path, csv_hz=10.0))
    assert [s.ranges_m[0] for s in scans] == [1.0, 2.0, 3.0]
    assert [s.stamp_ns for s in scans] == [0, 100_000_000, 200_000_000]


def test_the_device_clock_unwraps_and_keeps_the_smallest_delay() -> None:
    clock = DeviceClock(bits=8, tick_ns=1_000_000)  # wraps every 256 ms
    host = 5_000_000_000
    # ticks 250, 4 (wrapped), 14, 24: 10 ms apart on the device, arriving 1, 3, 2, 6 ms late
    stamps = [
        clock.stamp(tick, host + 10_000_000 * k + late)
        for k, (tick, late) in enumerate(
            [(250, 1_000_000), (4, 3_000_000), (14, 2_000_000), (24, 6_000_000)]
        )
    ]
    # the scanner's own spacing, on the host clock with the least delay seen (1 ms)
    assert np.diff(stamps).tolist() == [10_000_000] * 3
    assert stamps[0] == host + 1_000_000
    # a scan arriving with less delay moves the offset onto it
    assert clock.stamp(34, host + 40_000_000) == host + 40_000_000
    # a device restart (its clock jumps back) is taken afresh
    assert clock.stamp(0, host + 10_000_000_000) == host + 10_000_000_000


def test_a_late_burst_keeps_the_scanners_spacing() -> None:
    clock = DeviceClock(bits=32, tick_ns=1_000)  # SICK: microseconds
    host = 10**12
    stamps = []
    for k in range(30):
        arrival = host + 20_000_000 * k + 2_000_000
        if 10 <= k <= 16:  # a 130 ms hiccup: seven scans arrive together
            arrival = host + 20_000_000 * 16 + 2_000_000 + 100_000 * (k - 10)
        stamps.append(clock.stamp(20_000 * k, arrival))
    assert np.diff(stamps).tolist() == [20_000_000] * 29


def test_the_slot_keeps_the_newest_scan_and_counts_the_rest() -> None:
    scan = Scan(np.array([0.0, 0.1]), np.array([1.0, 1.0]))
    slot = LatestSlot()
    for k in range(5):
        slot.put(k, Received(scan, k, float(k)))
    item = slot.take()
    assert item is not None
    assert (item[0], item[2]) == (4, 4)  # the newest, and the four it replaced
    assert slot.dropped == 4
    slot.put(5, Received(scan, 5, 5.0))
    item = slot.take()
    assert item is not None
    assert (item[0], item[2]) == (5, 0)
    slot.close()
    assert slot.take() is None


def test_a_gap_reported_on_a_dropped_scan_goes_on_with_the_scan_that_replaced_it() -> None:
    """A locator busy when the stream came back must still report the outage (the live
    reconnection test lost its gap record whenever the host was loaded)."""
    scan = Scan(np.array([0.0, 0.1]), np.array([1.0, 1.0]))
    slot = LatestSlot()
    slot.put(0, Received(scan, 0, 0.0, gap_s=0.25))
    slot.put(1, Received(scan, 1, 1.0))
    slot.put(2, Received(scan, 2, 2.0, gap_s=0.5))
    item = slot.take()
    assert item is not None
    assert item[0] == 2
    assert item[1].gap_s == pytest.approx(0.75)  # both outages, charged to the one record
    slot.put(3, Received(scan, 3, 3.0))
    item = slot.take()
    assert item is not None
    assert item[1].gap_s is None  # reported once


def test_hokuyo_parameters_put_the_forward_beam_on_the_front_step(drive: Drive) -> None:
    scan = next(read_run(drive.bag))
    p = hokuyo_parameters(scan)
    assert (p.ares, p.afrt, p.amin, p.amax) == (720, 270, 0, len(scan) - 1)
    assert p.angle(p.amin) == pytest.approx(scan.angles_rad[0], abs=1e-7)  # float32 in a bag
    skewed = Scan(scan.angles_rad + 0.001, scan.ranges_m)
    with pytest.raises(InputError, match="Hokuyo step grid"):
        hokuyo_parameters(skewed)
