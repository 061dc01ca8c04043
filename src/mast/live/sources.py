"""Where live scans come from: a scanner on TCP, or a recorded run replayed.

A source is named by a URL (:func:`open_source`):

* ``sick://HOST[:PORT]``: SICK LMS1xx / LMS5xx / TiM5xx, CoLa-A on TCP (port 2111).
* ``hokuyo://HOST[:PORT]``: Hokuyo UST / UTM, SCIP 2.0 on TCP (port 10940).
* ``replay://RUN[?rate=F&hz=H&topic=T]``: any run ``mast locate`` reads (ROS 1 bag,
  ROS 2 bag folder or ``.mcap`` file, or a folder of scan CSVs), sent at its
  recorded rate times ``F``; a CSV folder has no stamps and plays at ``H`` scans a
  second (default 25); ``T`` chooses a bag's LaserScan topic, or a PointCloud2 topic
  of a 3D lidar (:class:`FrameReplaySource`, whose frames are located in 3D).

The scanners' schemes are the protocols of :mod:`mast.live.protocols` (each with
its client, reconnection and device clock in :mod:`mast.live.tcp`); what every
source yields is :mod:`mast.live.stream`'s.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
import urllib.parse
from collections.abc import Callable, Generator, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

from mast.core.pose3d import Frame3D
from mast.core.scan import Scan
from mast.errors import InputError
from mast.io.scans import DEFAULT_CSV_HZ
from mast.live.protocols import PROTOCOLS
from mast.live.stream import Received, Source, SourceOptions

__all__ = [
    "FrameReplaySource",
    "ReceivedFrame",
    "ReplaySource",
    "cloud_topic",
    "open_frame_source",
    "open_source",
    "paced",
    "read_run",
]


# --------------------------------------------------------------------------- replay


def read_run(
    path: Path, *, csv_hz: float = DEFAULT_CSV_HZ, topic: str | None = None
) -> Generator[Scan, None, None]:
    """The scans of a recorded run, one at a time (:func:`mast.io.scans.open_scans`): a
    bag (ROS 1, ROS 2 folder or ``.mcap`` file; ``topic`` when it holds several LaserScan
    topics) or a folder of scan CSVs (every ``*.csv`` whose header starts with
    ``angle_rad``, in name order, stamped ``1 / csv_hz`` apart from 0)."""
    from mast.io.scans import open_scans

    return open_scans(path, topic=topic, csv_hz=csv_hz, what="run").scans


class ReplaySource(Source):
    """A recorded run sent at its recorded rate (times ``rate``), stamps as recorded."""

    def __init__(
        self,
        url: str,
        path: Path,
        rate: float,
        csv_hz: float,
        options: SourceOptions,
        topic: str | None = None,
    ) -> None:
        super().__init__(url, options)
        self.path, self.rate, self.csv_hz = path, rate, csv_hz
        # Read the first scan now: a run that cannot be read is an error before the run.
        self._scans = read_run(path, csv_hz=csv_hz, topic=topic)
        self._first = next(self._scans, None)
        if self._first is None:
            raise InputError("run holds no scan", path=path)

    def scans(self, stop: threading.Event, warn: Callable[[str], None]) -> Iterator[Received]:
        del warn
        first = self._first
        assert first is not None
        try:
            yield from self._paced(itertools.chain([first], self._scans), stop)
        finally:
            self._scans.close()  # the bag reader, also when the run ends early

    def _paced(self, scans: Iterator[Scan], stop: threading.Event) -> Iterator[Received]:
        o = self.options
        for scan in paced(scans, stop, rate=self.rate):
            if o.range_min_m is not None or o.range_max_m is not None:
                scan = scan.with_range_limits(o.range_min_m, o.range_max_m)
            self.stats.scans += 1
            yield Received(scan, time.time_ns(), time.perf_counter())


def cloud_topic(path: Path, topic: str | None) -> str | None:
    """The PointCloud2 topic a recorded run is read from, or None when it is read as
    LaserScans (a scan CSV or a folder of them; a bag whose ``topic`` carries LaserScan;
    without ``topic``, a bag with a LaserScan topic). A bag with no LaserScan topic and
    one PointCloud2 topic is a 3D run; the message type decides, not the options. A path
    that is no bag, or a bag too damaged to list its topics, is left to the 2D reader to
    say what is wrong (None)."""
    from mast.io.bags import LASERSCAN, list_topics
    from mast.io.pointclouds import POINTCLOUD2
    from mast.io.scans import FORMATS, scan_format

    try:
        if scan_format(path, what="run") is not FORMATS[-1]:
            return None
        topics = list_topics(path)
    except InputError:
        return None
    if topic is not None:
        return topic if any(t.topic == topic and t.msgtype == POINTCLOUD2 for t in topics) else None
    if any(t.msgtype == LASERSCAN for t in topics):
        return None
    clouds = sorted({t.topic for t in topics if t.msgtype == POINTCLOUD2})
    return clouds[0] if len(clouds) == 1 else None


@dataclass(frozen=True, slots=True)
class ReceivedFrame:
    """One 3D lidar frame as it arrived (:class:`~mast.live.stream.Received`'s fields,
    a :class:`~mast.core.pose3d.Frame3D` for the scan)."""

    frame: Frame3D
    received_ns: int
    received_s: float
    gap_s: float | None = None


class FrameReplaySource:
    """A recorded run's PointCloud2 frames (a 3D lidar's), sent at the recorded rate
    times ``rate``, stamps as recorded; the frame count in ``stats`` as a scan source's.
    A damaged message is skipped and counted as malformed (as from the field)."""

    def __init__(self, url: str, path: Path, rate: float, topic: str) -> None:
        from mast.io.pointclouds import read_pointclouds
        from mast.live.stream import SourceStats

        self.url, self.path, self.rate, self.topic = url, path, rate, topic
        self.stats = SourceStats()
        self._skipped: list[str] = []
        self._frames = read_pointclouds(path, topic, on_skip=self._skipped.append)
        # Read the first frame now: a run that cannot be read is an error before the run.
        self._first = next(self._frames, None)
        if self._first is None:
            raise InputError(f"run holds no PointCloud2 frame on {topic}", path=path)

    def frames(self, stop: threading.Event, warn: Callable[[str], None]) -> Iterator[ReceivedFrame]:
        """Every frame when it is due, until the run ends or ``stop`` is set."""
        first = self._first
        assert first is not None
        try:
            for frame in paced(itertools.chain([first], self._frames), stop, rate=self.rate):
                while self._skipped:
                    self.stats.malformed += 1
                    warn(self._skipped.pop(0))
                self.stats.scans += 1
                yield ReceivedFrame(frame, time.time_ns(), time.perf_counter())
        finally:
            if isinstance(self._frames, Generator):
                self._frames.close()  # the bag reader, also when the run ends early


_Stamped = TypeVar("_Stamped", Scan, Frame3D)


def paced(
    scans: Iterable[_Stamped],
    stop: threading.Event,
    *,
    rate: float = 1.0,
    hz: float | None = None,
) -> Iterator[_Stamped]:
    """Each scan when it is due: at its recorded spacing divided by ``rate``, or ``hz`` a
    second; until the scans end or ``stop`` is set."""
    t0: float | None = None
    s0 = 0
    for n, scan in enumerate(scans):
        if t0 is None:
            t0, s0 = time.perf_counter(), scan.stamp_ns
        due = t0 + (n / hz if hz is not None else (scan.stamp_ns - s0) / 1e9 / rate)
        while not stop.is_set():
            left = due - time.perf_counter()
            if left <= 0:
                break
            stop.wait(min(left, 0.1)) if left > 0.002 else time.sleep(0)
        if stop.is_set():
            return
        yield scan


# --------------------------------------------------------------------------- URLs


@dataclass(frozen=True, slots=True)
class _Url:
    scheme: str
    host: str = ""
    port: int = 0
    path: str = ""
    query: dict[str, str] = field(default_factory=dict)


def _parse(text: str) -> _Url:
    scheme, sep, rest = text.partition("://")
    if not sep or (scheme not in PROTOCOLS and scheme != "replay"):
        scanners = ", ".join(p.url for p in PROTOCOLS.values())
        raise InputError(f"source {text!r}: give {scanners} or replay://RUN")
    if scheme == "replay":
        path, _, query = rest.partition("?")
        if not path:
            raise InputError(f"source {text!r}: replay:// needs the run's path")
        try:
            q = dict(urllib.parse.parse_qsl(query, strict_parsing=bool(query)))
        except ValueError:
            raise InputError(f"source {text!r}: query {query!r} is not key=value&...") from None
        unknown = sorted(set(q) - {"rate", "hz", "topic"})
        if unknown:
            raise InputError(f"source {text!r}: unknown option {unknown[0]!r} (rate, hz, topic)")
        return _Url(scheme, path=path, query=q)
    parts = urllib.parse.urlsplit(text)
    try:
        port = parts.port or PROTOCOLS[scheme].default_port
    except ValueError:
        raise InputError(f"source {text!r}: the port is not a number in 1-65535") from None
    if not parts.hostname or parts.path not in ("", "/") or parts.query:
        raise InputError(f"source {text!r}: expected {scheme}://HOST[:PORT]")
    return _Url(scheme, host=parts.hostname, port=port)


def _positive(text: str, what: str, source: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"source {source!r}: {what} must be a positive number, got {text!r}")
    return value


def open_frame_source(text: str) -> FrameReplaySource | None:
    """The 3D lidar frames a ``replay://`` URL names: a :class:`FrameReplaySource` when
    its run is read as PointCloud2 (:func:`cloud_topic`), None for a scan source (opened
    by :func:`open_source`). A bad URL is an InputError naming it."""
    u = _parse(text)
    if u.scheme != "replay":
        return None
    path = Path(urllib.parse.unquote(u.path))
    clouds = cloud_topic(path, u.query.get("topic"))
    if clouds is None:
        return None
    return FrameReplaySource(text, path, _positive(u.query.get("rate", "1"), "rate", text), clouds)


def open_source(text: str, options: SourceOptions | None = None) -> Source:
    """The source a URL names (see the module); a bad URL is an InputError naming it."""
    o = options or SourceOptions()
    u = _parse(text)
    if u.scheme == "replay":
        rate = _positive(u.query.get("rate", "1"), "rate", text)
        hz = _positive(u.query.get("hz", str(DEFAULT_CSV_HZ)), "hz", text)
        path = Path(urllib.parse.unquote(u.path))
        return ReplaySource(text, path, rate, hz, o, topic=u.query.get("topic"))
    return PROTOCOLS[u.scheme].source(f"{u.scheme}://{u.host}:{u.port}", u.host, u.port, o)
