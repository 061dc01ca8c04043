"""``mast live`` against both scanner emulators and a replay, and the faults a vehicle meets.

Where live and ``mast locate`` (on the scans live recorded) both fix a scan, the poses
agree within 0.1 mm and 1 arc-second.
"""

from __future__ import annotations

import json
import math
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
from itertools import pairwise
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from mast.errors import InputError
from mast.io.bags import list_topics, read_laserscans
from mast.live.emulate import Emulator, EmulatorFaults
from mast.live.record import McapRecorder
from mast.live.session import LiveSummary, run_live
from mast.live.sources import open_source, read_run
from mast.live.stream import SourceOptions
from mast.pipeline.locator import LocatorConfig
from tests._cli import run_mast_text
from tests.test_live.conftest import Drive

SCHEMA = Path(__file__).resolve().parents[2] / "docs" / "fix.schema.json"
#: The drive's scanner noise (12 mm), as ``--scanner lms1xx-0.5`` gives it.
CONFIG = LocatorConfig(range_sigma_m=0.012)


def _live(
    url: str,
    drive: Drive,
    *,
    record: Path | None = None,
    max_scans: int | None = None,
    options: SourceOptions | None = None,
) -> tuple[list[dict[str, Any]], LiveSummary, list[str]]:
    records: list[dict[str, Any]] = []
    warnings: list[str] = []
    recorder = McapRecorder(record) if record is not None else None
    try:
        summary = run_live(
            open_source(url, options),
            drive.survey,
            emit=records.append,
            config=CONFIG,
            sinks=(recorder,) if recorder else (),
            max_scans=max_scans,
            warn=warnings.append,
        )
    finally:
        if recorder is not None:
            recorder.close()
    return records, summary, warnings


def _assert_agree_with_locate(records: list[dict[str, Any]], recording: Path, drive: Drive) -> None:
    done = run_mast_text(
        "locate", str(recording), "-b", str(drive.beacons), "--range-sigma", "0.012",
        "--format", "json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    located = {r["stamp_ns"]: r for r in map(json.loads, lines)}
    assert len(located) == len(lines), "two scans with one stamp: records cannot be paired"
    both = 0
    for live in records:
        other = located[live["stamp_ns"]]  # every located scan was recorded, with its stamp
        if live["status"] == other["status"] == "fix":
            both += 1
            d = math.hypot(live["easting"] - other["easting"], live["northing"] - other["northing"])
            assert d < 1e-4
            assert abs(live["azimuth_deg"] - other["azimuth_deg"]) * 3600 < 1.0
    # a loaded host locates the slow scans, those owing no fix, more often: the share is
    # of the located scans that owe one
    assert both >= sum(drive.owed[r["scan"]] for r in records) // 2


@pytest.mark.parametrize("kind", ["sick", "hokuyo"])
def test_live_from_an_emulator_fixes_as_locate_does(
    kind: str, drive: Drive, tmp_path: Path
) -> None:
    recording = tmp_path / "run.mcap"
    with Emulator(kind, read_run(drive.bag)) as emulator:
        records, summary, warnings = _live(
            f"{kind}://127.0.0.1:{emulator.port}", drive, record=recording, max_scans=drive.scans
        )
    assert warnings == []
    assert summary.received == drive.scans
    assert summary.located == len(records) == drive.scans - summary.dropped
    assert sum(r["dropped"] for r in records) == summary.dropped
    # how many scans a loaded host drops is the machine's business, not the test's: every
    # scan located is counted, and most of the located scans that owe a fix are fixed (a
    # busy host locates the slow scans, those without two beacons, more often than not)
    assert summary.located >= 2
    owed = [r for r in records if drive.owed[r["scan"]]]
    assert sum(r["status"] == "fix" for r in owed) >= len(owed) // 2
    first = records[0]
    assert first["source"] == f"{kind}://127.0.0.1:{emulator.port}"
    assert first["tracking"] is False
    assert first["track_lost"] is False
    assert any(r["tracking"] and r["status"] == "fix" for r in records)
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA.read_text(encoding="utf-8")))
    for r in records:
        assert r["latency_ms"] >= 0
        assert not list(validator.iter_errors(r))
    # stamped by the scanner's clock: the run's 20 ms spacing, not the host's arrival times
    # (the emulator's clock counts from its start, so the spacing is kept within its jitter)
    spacing = [
        (b["stamp_ns"] - a["stamp_ns"]) / (b["scan"] - a["scan"]) for a, b in pairwise(records)
    ]
    assert statistics.median(spacing) == pytest.approx(20e6, abs=0.5e6)
    # the recording holds every scan received, in ROS 2 MCAP, and locate reads it back
    topics = {t.topic: t for t in list_topics(recording)}
    assert topics["/scan"].count == drive.scans
    assert topics["/mast/pose"].count == summary.fixed
    assert topics["/mast/fix"].count == summary.located
    _assert_agree_with_locate(records, recording, drive)


def test_a_replay_plays_a_bag_at_its_rate_and_fixes_as_locate_does(
    drive: Drive, tmp_path: Path
) -> None:
    recording = tmp_path / "run.mcap"
    t0 = time.perf_counter()
    records, summary, _ = _live(f"replay://{drive.bag}?rate=2", drive, record=recording)
    elapsed = time.perf_counter() - t0
    assert summary.received == drive.scans
    # 120 scans at 50 Hz, twice as fast: 1.2 s of stamps
    assert elapsed >= (drive.scans - 1) / 100 * 0.95
    stamps = [s.stamp_ns for s in read_run(drive.bag)]
    assert [r["stamp_ns"] for r in records] == [stamps[r["scan"]] for r in records]
    _assert_agree_with_locate(records, recording, drive)
    # and a survey run reads the recording as it reads any bag
    done = run_mast_text(
        "track", str(recording), "-b", str(drive.beacons), "--out", str(tmp_path / "run")
    )
    assert done.returncode == 0, done.stderr
    assert f"{drive.scans} scans" in done.stdout
    assert (tmp_path / "run" / "trajectory.csv").is_file()


def test_a_dropped_connection_is_reconnected_and_the_gap_reported(drive: Drive) -> None:
    faults = EmulatorFaults(drop_after=30)
    options = SourceOptions(backoff_s=(0.05, 0.5))
    with Emulator("sick", read_run(drive.bag), faults=faults) as emulator:
        records, summary, warnings = _live(
            f"sick://127.0.0.1:{emulator.port}", drive, max_scans=60, options=options
        )
    assert summary.reconnects == 1
    assert summary.received == 60
    assert any("connection was closed; reconnecting" in w for w in warnings)
    assert any("scans again after a gap" in w for w in warnings)
    gaps = [r for r in records if "gap_s" in r]
    assert len(gaps) == 1
    assert gaps[0]["gap_s"] >= 0.05  # at least the first wait of the backoff
    assert emulator.connections == 2


def test_a_scanner_that_stops_sending_is_reconnected_after_the_timeout(drive: Drive) -> None:
    faults = EmulatorFaults(stall_after=20)
    options = SourceOptions(timeout_s=0.3, backoff_s=(0.05, 0.5))
    with Emulator("hokuyo", read_run(drive.bag), faults=faults) as emulator:
        records, summary, warnings = _live(
            f"hokuyo://127.0.0.1:{emulator.port}", drive, max_scans=40, options=options
        )
    assert any("no scan for 0.3 s; reconnecting" in w for w in warnings)
    assert summary.reconnects == 1
    (gap,) = [r["gap_s"] for r in records if "gap_s" in r]
    assert gap >= 0.3


@pytest.mark.parametrize("kind", ["sick", "hokuyo"])
def test_malformed_telegrams_are_skipped_counted_and_named_once(kind: str, drive: Drive) -> None:
    faults = EmulatorFaults(corrupt_every=10)
    with Emulator(kind, read_run(drive.bag), faults=faults) as emulator:
        _, summary, warnings = _live(f"{kind}://127.0.0.1:{emulator.port}", drive, max_scans=45)
    assert summary.malformed == 4  # telegrams 10, 20, 30, 40 of the first 49 sent
    assert summary.received == 45
    malformed = [w for w in warnings if "malformed telegram skipped" in w]
    assert len(malformed) == 1
    assert ("LMDscandata" if kind == "sick" else "sum check") in malformed[0]


def test_a_port_nobody_listens_on_is_a_one_line_error(drive: Drive) -> None:
    with pytest.raises(InputError, match=r"cannot connect to sick://127\.0\.0\.1:1: "):
        _live("sick://127.0.0.1:1", drive)
    done = run_mast_text("live", "hokuyo://127.0.0.1:1", "-b", str(drive.beacons))
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.strip().splitlines() == [
        "mast: error: cannot connect to hokuyo://127.0.0.1:1: Connection refused"
    ]


def test_a_host_that_accepts_but_never_streams_is_an_error_not_a_wait(drive: Drive) -> None:
    import socket

    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        options = SourceOptions(timeout_s=0.3)
        with pytest.raises(InputError, match=r"connected, but no scan came .* a sick scanner"):
            _live(f"sick://127.0.0.1:{port}", drive, options=options)


def _start_live(drive: Drive, *args: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "mast", "live", *args, "-b", str(drive.beacons)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_or_sigterm_ends_the_run_with_a_complete_recording(
    drive: Drive, tmp_path: Path, signum: int, status: int
) -> None:
    recording = tmp_path / "run.mcap"
    proc = _start_live(drive, f"replay://{drive.bag}?rate=0.5", "--record", str(recording))
    assert proc.stdout is not None
    for _ in range(5):
        assert json.loads(proc.stdout.readline())["source"].startswith("replay://")
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == status
    assert (
        err.decode().strip().splitlines()[-1]
        == f"mast: interrupted; {recording} holds the scans received"
    )
    scans = list(read_laserscans(recording))
    assert 5 <= len(scans) < drive.scans
    assert not list(tmp_path.glob(".*.part"))  # no staging left behind


def test_a_closed_pipe_ends_the_run_cleanly(drive: Drive, tmp_path: Path) -> None:
    recording = tmp_path / "run.mcap"
    proc = _start_live(drive, f"replay://{drive.bag}", "--record", str(recording))
    assert proc.stdout is not None
    json.loads(proc.stdout.readline())
    proc.stdout.close()  # as `| head -n 1` does
    proc.wait(timeout=30)
    assert proc.returncode == 0
    assert proc.stderr is not None
    assert b"Traceback" not in proc.stderr.read()
    assert len(list(read_laserscans(recording))) >= 1


def test_a_slow_reader_costs_dropped_scans_not_memory_or_a_crash(drive: Drive) -> None:
    proc = _start_live(drive, f"replay://{drive.bag}")
    assert proc.stdout is not None
    # a reader that takes nothing until the replay (2.4 s after start-up) is over: the
    # pipe fills after a few dozen records and writing blocks
    threading.Event().wait(5.0)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    records = [json.loads(line) for line in out.splitlines()]
    assert records
    dropped = sum(r["dropped"] for r in records)
    assert dropped > 0  # the newest scan won while standard output was blocked
    assert len(records) + dropped == drive.scans
    assert f"{dropped} dropped" in err.decode()


def test_the_view_serves_the_scan_and_pose_channels_to_a_websocket_client(
    drive: Drive,
) -> None:
    from websockets.sync.client import connect

    from mast.live.view import LiveView

    view = LiveView(drive.survey, port=0)
    try:
        with connect(f"ws://127.0.0.1:{view.port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            channels: dict[str, int] = {}
            while "/pose" not in channels or "/scan" not in channels:
                message = ws.recv(timeout=5)
                if isinstance(message, str) and json.loads(message)["op"] == "advertise":
                    for c in json.loads(message)["channels"]:
                        channels[c["topic"]] = c["id"]
            wanted = {1: "/scan", 2: "/pose", 3: "/status"}
            ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [
                            {"id": k, "channelId": channels[t]} for k, t in wanted.items()
                        ],
                    }
                )
            )
            time.sleep(0.3)
            summary = run_live(
                open_source(f"replay://{drive.bag}?rate=4"),
                drive.survey,
                emit=lambda _r: None,
                config=CONFIG,
                sinks=(view,),
                max_scans=30,
            )
            assert summary.fixed > 0
            got: dict[str, int] = {}
            while True:
                try:
                    message = ws.recv(timeout=1)
                except TimeoutError:
                    break
                if isinstance(message, bytes) and message[0] == 1:  # message data
                    topic = wanted[int.from_bytes(message[1:5], "little")]
                    got[topic] = got.get(topic, 0) + 1
        assert got["/scan"] == summary.located
        assert got["/pose"] == summary.fixed
        assert got["/status"] == summary.located
    finally:
        view.close()


def test_the_recording_may_not_overwrite_the_run_being_replayed(drive: Drive) -> None:
    done = run_mast_text(
        "live", f"replay://{drive.bag}", "-b", str(drive.beacons), "--record", str(drive.bag)
    )
    assert done.returncode == 2
    assert "--record" in done.stderr


def test_an_emulator_on_a_port_in_use_is_bad_input(drive: Drive) -> None:
    first = Emulator("sick", read_run(drive.bag)).start()
    try:
        with pytest.raises(InputError, match=rf"cannot serve on 127\.0\.0\.1:{first.port}"):
            Emulator("sick", read_run(drive.bag), port=first.port)
    finally:
        first.stop()


def test_an_emulator_stamps_a_scan_when_it_was_due_not_when_sent(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A scanner stamps a scan when it measures it. An emulator on a loaded host sends
    late scans together; stamped on sending, two could share a stamp, and the comparison
    with locate above (by stamp) took one scan for the next: the likely cause of a
    failure seen once, fixes 34 mm apart, one scan's travel at the drive's 1.7 m/s and
    50 Hz. (Offline, neither half the scans dropped, 4 drives and 3 draws each, nor a
    float32 recording, 671 fixes, moved any fix by 0.1 mm.) Here the host stalls 70 ms
    once: the stamps keep the run's 20 ms spacing all the same."""
    from mast.core.scan import Scan
    from mast.live import emulate
    from mast.live.protocols import sick

    send, calls = emulate._send, [0]

    def stalling(conn: Any, data: bytes) -> bool:
        calls[0] += 1
        if calls[0] == 3:
            time.sleep(0.07)
        return send(conn, data)

    monkeypatch.setattr(emulate, "_send", stalling)
    angles = np.linspace(-2.0, 2.0, 181)
    scans = iter([Scan(angles, np.full(181, 5.0), stamp_ns=k * 20_000_000) for k in range(10)])
    stamps: list[int] = []
    with (
        emulate.Emulator("sick", scans) as emulator,
        socket.create_connection(("127.0.0.1", emulator.port), timeout=5.0) as conn,
    ):
        conn.sendall(sick.command("sEN LMDscandata 1"))
        buf = bytearray()
        while len(stamps) < 10:
            buf += conn.recv(65536)
            stamps += [
                sick.parse_scandata(t).time_since_startup_us
                for t in sick.split_telegrams(buf)
                if t.startswith(b"sSN")
            ]
    assert [b - a for a, b in pairwise(stamps)] == [20_000] * 9


def test_an_emulators_device_clock_only_goes_forward(drive: Drive) -> None:
    """A recording that repeats a stamp (or a poll answered while the stream is behind)
    still gets a device time one tick past the last telegram's."""
    from mast.live.protocols import hokuyo

    scan = next(read_run(drive.bag))
    with Emulator("hokuyo", read_run(drive.bag)) as emulator:
        t0 = emulator._t0_ns
        same = [emulator._telegram(scan, at_ns=t0 + 40_000_000) for _ in range(3)]
    stamps = [hokuyo.parse_distance_reply(hokuyo.split_replies(bytearray(t))[0]).timestamp_ms
              for t in same]  # fmt: skip
    assert stamps == [40, 41, 42]  # integer ticks: the same at any uptime


@pytest.mark.parametrize("uptime_h", [0.01, 9.5, 36.2, 73.0, 20 * 24 + 0.3])
def test_an_emulators_device_stamps_do_not_depend_on_the_hosts_uptime(
    drive: Drive, monkeypatch: pytest.MonkeyPatch, uptime_h: float
) -> None:
    """The host's clock is taken in integer nanoseconds whatever its uptime: telegrams
    due 20 ms apart carry device times exactly 20 000 us (SICK) and 20 ms (SCIP) apart."""
    from mast.live import emulate
    from mast.live.protocols import hokuyo, sick

    now = [int(uptime_h * 3600e9) + 123_456_789]
    monkeypatch.setattr(emulate.time, "perf_counter_ns", lambda: now[0])
    scan = next(read_run(drive.bag))
    for kind in ("sick", "hokuyo"):
        with Emulator(kind, read_run(drive.bag)) as emulator:
            t0 = emulator._t0_ns
            telegrams = [emulator._telegram(scan, at_ns=t0 + k * 20_000_000) for k in range(6)]
        if kind == "sick":
            bodies = [sick.split_telegrams(bytearray(t))[0] for t in telegrams]
            stamps = [sick.parse_scandata(b).time_since_startup_us for b in bodies]
            assert [b - a for a, b in pairwise(stamps)] == [20_000] * 5
        else:
            ms = [hokuyo.parse_distance_reply(hokuyo.split_replies(bytearray(t))[0]).timestamp_ms
                  for t in telegrams]  # fmt: skip
            assert [b - a for a, b in pairwise(ms)] == [20] * 5
