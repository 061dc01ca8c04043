"""ROS 2 benchmark: a simulated drive published on ``/scan`` over DDS, located by ``mast ros2``.

The drive (:func:`mast.sim.drive.drive_scene`, 0.5°, 541 beams, 12 mm) is written
to a bag, with which scans owe a fix. ``mast ros2`` runs in its own process, as on
a robot, with ``--scanner lms1xx-0.5``'s precisions; this process publishes the
bag's scans on ``/scan`` as a driver does (best effort) at ``rate_hz``, and listens
to ``/mast/pose`` and ``/mast/fix`` over loopback. It prints:

* scans published, located, dropped by the node and lost on the way;
* latency from a scan's publication to its pose's arrival (median, p95, max), the
  locator's own time per scan (the record's ``elapsed_ms``) and their difference,
  the node's overhead (DDS both ways, the hand-over, the record and the messages);
* the poses against ``mast locate``'s on the same bag: fixed by both, fixed by one
  only, and the largest difference in position and azimuth;
* fixes farther than 0.1 m from the truth.

Run: ``mast bench ros2 [--scans 2000] [--rate 25]``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Ros2Figures", "run_ros2_bench"]

#: The named scanner model whose precisions the drive's scanner has (270°, 0.5°, 12 mm).
SCANNER = "lms1xx-0.5"


@dataclass(frozen=True, slots=True)
class Ros2Figures:
    rate_hz: float
    published: int
    located: int
    dropped: int
    lost: int
    fixed: int
    latency_ms: tuple[float, float, float]
    locator_ms: tuple[float, float, float]
    overhead_ms: tuple[float, float, float]
    both_fixed: int
    only_ros2: int
    only_locate: int
    max_position_mm: float
    max_azimuth_arcsec: float
    wrong: int

    def lines(self) -> list[str]:
        def spread(name: str, v: tuple[float, float, float]) -> str:
            return f"  {name}, ms: median {v[0]:.2f}  p95 {v[1]:.2f}  max {v[2]:.2f}"

        return [
            f"mast ros2, {self.published} scans published at {self.rate_hz:g} Hz (best effort)",
            f"  located {self.located}, dropped by the node {self.dropped}, "
            f"lost on the way {self.lost}; fixed {self.fixed}",
            spread("publication -> pose received", self.latency_ms),
            spread("the locator (record elapsed_ms)", self.locator_ms),
            spread("overhead (the difference)", self.overhead_ms),
            f"  against mast locate on the same bag: both fixed {self.both_fixed}, only ros2 "
            f"{self.only_ros2}, only locate {self.only_locate}; largest difference "
            f"{self.max_position_mm:.4f} mm and {self.max_azimuth_arcsec:.4f}″",
            f"  fixes farther than 0.1 m from the truth: {self.wrong}",
        ]


def _spread(values: Any) -> tuple[float, float, float]:
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return (math.nan, math.nan, math.nan)
    return (float(np.median(a)), float(np.percentile(a, 95)), float(a.max()))


def _locate(bag: Path, survey: Path) -> dict[int, dict[str, Any]]:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "mast",
            "locate",
            str(bag),
            "-b",
            str(survey),
            "--scanner",
            SCANNER,
            "--format",
            "json",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode not in (0, 3):
        raise RuntimeError(f"mast locate failed: {done.stderr.strip()}")
    return {r["stamp_ns"]: r for r in map(json.loads, done.stdout.splitlines())}


def _one(
    scans: int, rate_hz: float, seed: int, domain: int, folder: Path, echo: Callable[[str], None]
) -> Ros2Figures:
    from cyclonedds.core import Listener, Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.internal import InvalidSample
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    from mast.bench.live import simulate_drive
    from mast.core.scan import stamp_of
    from mast.live.ros2 import ScanPublisher
    from mast.live.ros2_msgs import PoseWithCovarianceStamped, String, dds_topic
    from mast.live.sources import paced, read_run

    t0 = time.perf_counter()
    survey, bag, truth = simulate_drive(folder, scans, rate_hz, seed)
    echo(f"{scans} scans at {rate_hz:g} Hz simulated in {time.perf_counter() - t0:.0f} s")
    located = _locate(bag, survey)
    dp = DomainParticipant(domain)
    arrived: dict[int, float] = {}  # pose stamp -> perf_counter at arrival
    records: list[dict[str, Any]] = []
    lock = threading.Lock()

    def on_pose(reader: DataReader[Any]) -> None:
        now = time.perf_counter()
        with lock:
            for msg in reader.take(N=64):
                if isinstance(msg, InvalidSample):  # the node has left
                    continue
                arrived[stamp_of(msg.header.stamp.sec, msg.header.stamp.nanosec)] = now

    def on_fix(reader: DataReader[Any]) -> None:
        with lock:
            records.extend(
                json.loads(s.data) for s in reader.take(N=64) if not isinstance(s, InvalidSample)
            )

    qos = Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(1000),
    )
    readers = [  # kept: a reader dropped is deleted
        DataReader(
            dp,
            Topic(dp, dds_topic("/mast/pose"), PoseWithCovarianceStamped),
            qos=qos,
            listener=Listener(on_data_available=on_pose),  # type: ignore[no-untyped-call]
        ),
        DataReader(
            dp,
            Topic(dp, dds_topic("/mast/fix"), String),
            qos=qos,
            listener=Listener(on_data_available=on_fix),  # type: ignore[no-untyped-call]
        ),
    ]
    publisher = ScanPublisher(dp, "/scan", reliable=False)
    node = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mast",
            "ros2",
            "-b",
            str(survey),
            "--scanner",
            SCANNER,
            "--domain-id",
            str(domain),
            "--max-scans",
            str(scans),
            "--give-up",
            "5",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    sent: dict[int, float] = {}
    try:
        assert node.stderr is not None
        node.stderr.readline()  # "listening ...": the node is up
        while publisher.matched() == 0:
            time.sleep(0.01)
        for scan in paced(read_run(bag), threading.Event(), hz=rate_hz):
            sent[scan.stamp_ns] = time.perf_counter()
            publisher.publish(scan)
        _, err = node.communicate(timeout=120)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait(10)
    time.sleep(0.5)  # the last samples' listeners
    del readers
    summary = err.strip().splitlines()[-1] if err.strip() else ""
    echo(f"  the node: {summary}")
    with lock:
        recs = {r["stamp_ns"]: r for r in records}
        poses = dict(arrived)
    dropped = sum(r["dropped"] for r in recs.values())  # each record counts those before it
    latency, locator, overhead = [], [], []
    for stamp, t_pose in poses.items():
        e2e = 1e3 * (t_pose - sent[stamp])
        latency.append(e2e)
        locator.append(recs[stamp]["elapsed_ms"])
        overhead.append(e2e - recs[stamp]["elapsed_ms"])
    stamps = list(sent)
    both = only_ros2 = only_locate = wrong = 0
    dpos = daz = 0.0
    for k, stamp in enumerate(stamps):
        mine, ref = recs.get(stamp), located[stamp]
        if mine is None:
            continue
        a, b = mine["status"] == "fix", ref["status"] == "fix"
        both += a and b
        only_ros2 += a and not b
        only_locate += b and not a
        if a:
            e, n, _ = truth[k]
            wrong += math.hypot(mine["easting"] - e, mine["northing"] - n) > 0.1
        if a and b:
            dpos = max(
                dpos,
                1e3
                * math.hypot(mine["easting"] - ref["easting"], mine["northing"] - ref["northing"]),
            )
            turn = (mine["azimuth_deg"] - ref["azimuth_deg"] + 180.0) % 360.0 - 180.0
            daz = max(daz, abs(turn) * 3600)
    return Ros2Figures(
        rate_hz=rate_hz,
        published=len(sent),
        located=len(recs),
        dropped=dropped,
        lost=len(sent) - len(recs) - dropped,
        fixed=sum(r["status"] == "fix" for r in recs.values()),
        latency_ms=_spread(latency),
        locator_ms=_spread(locator),
        overhead_ms=_spread(overhead),
        both_fixed=both,
        only_ros2=only_ros2,
        only_locate=only_locate,
        max_position_mm=dpos,
        max_azimuth_arcsec=daz,
        wrong=wrong,
    )


def run_ros2_bench(
    *,
    scans: int = 2000,
    rates_hz: tuple[float, ...] = (10.0, 25.0),
    seed: int = 0,
    domain: int = 201,
    echo: Callable[[str], None] = print,
) -> list[Ros2Figures]:
    """Run the benchmark (see the module) at each rate and print its figures."""
    from mast.live.ros2 import LOOPBACK_CONFIG

    # loopback only: the figures are the node's, not the network's
    os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK_CONFIG)
    out = []
    for rate in rates_hz:
        with tempfile.TemporaryDirectory(prefix="mast-bench-ros2-") as tmp:
            figures = _one(scans, rate, seed, domain, Path(tmp), echo)
        for line in figures.lines():
            echo(line)
        out.append(figures)
    return out
