"""Where live scans come from: a SICK or Hokuyo scanner on TCP, or a recorded run replayed.

A source is named by a URL (:func:`open_source`):

* ``sick://HOST[:PORT]``: LMS1xx / LMS5xx / TiM5xx, CoLa-A on TCP (port 2111).
  The stream is started with ``sEN LMDscandata 1`` and stopped with
  ``sEN LMDscandata 0``; every ``sSN LMDscandata`` telegram is a scan.
* ``hokuyo://HOST[:PORT]``: UST / UTM, SCIP 2.0 on TCP (port 10940). ``PP`` gives the
  step geometry and range limits, then ``MD`` (continuous, every step, no
  clustering) streams the scans; ``QT`` stops them.
* ``replay://RUN[?rate=F&hz=H&topic=T]``: any run ``mast locate`` reads (ROS 1 bag,
  ROS 2 bag folder or ``.mcap`` file, or a folder of scan CSVs), sent at its
  recorded rate times ``F``; a CSV folder has no stamps and plays at ``H`` scans a
  second (default 25); ``T`` chooses a bag's LaserScan topic.

:meth:`Source.scans` yields each scan as it is received (:class:`Received`) until
told to stop. A TCP source survives what a vehicle meets: a connection dropped
mid-stream or a scanner that stops sending (no scan for ``timeout_s``) is
reconnected with backoff and the gap reported; a malformed telegram is skipped
and counted (one warning names the first); a scanner that cannot be reached at
all, or not again within ``give_up_s``, ends the stream with an
:class:`~mast.errors.InputError` naming it.

Stamps: a scanner's own clock (SICK: microseconds since start-up, 32 bits;
Hokuyo: milliseconds, 24 bits) is unwrapped and carried onto the host's clock
with the smallest offset seen (:class:`DeviceClock`), so that stamps keep the
scanner's spacing and lag the scan by no more than the network does.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import math
import socket
import struct
import threading
import time
import urllib.parse
from abc import ABC, abstractmethod
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mast.core.scan import Scan
from mast.errors import InputError
from mast.io.scans import DEFAULT_CSV_HZ
from mast.live import cola, scip

__all__ = [
    "DEFAULT_PORTS",
    "DeviceClock",
    "Received",
    "Source",
    "SourceOptions",
    "SourceStats",
    "open_source",
    "read_run",
]

#: Default TCP port of each scanner family.
DEFAULT_PORTS = {"sick": 2111, "hokuyo": 10940}


@dataclass(frozen=True, slots=True)
class SourceOptions:
    """How a source is read.

    Attributes
    ----------
    range_min_m, range_max_m : float or None
        Valid ranges; None: the device's (Hokuyo ``PP``, a bag's) or 0 / unlimited.
    connect_timeout_s : float
        Longest wait for a connection.
    timeout_s : float
        A connected scanner that sends no scan for this long is reconnected.
    give_up_s : float
        A scanner lost for this long (no connection, no scans) ends the run.
    backoff_s : tuple of float
        First and longest wait between reconnection attempts (doubling).
    """

    range_min_m: float | None = None
    range_max_m: float | None = None
    connect_timeout_s: float = 3.0
    timeout_s: float = 2.0
    give_up_s: float = 60.0
    backoff_s: tuple[float, float] = (0.2, 5.0)


@dataclass(frozen=True, slots=True)
class Received:
    """One scan as it arrived.

    Attributes
    ----------
    scan : Scan
        With its stamp (the scanner's clock carried onto the host's, or the run's).
    received_ns : int
        Host wall-clock time the scan's last byte was read, Unix ns.
    received_s : float
        The same instant on the monotonic clock (``time.perf_counter``), for latency.
    gap_s : float or None
        On the first scan after a reconnection: how long no scan came.
    """

    scan: Scan
    received_ns: int
    received_s: float
    gap_s: float | None = None


@dataclass(slots=True)
class SourceStats:
    """What a source has counted so far (read by the session, written by the reader)."""

    scans: int = 0
    malformed: int = 0
    reconnects: int = 0
    gap_s: float = 0.0
    first_malformed: str = ""


class DeviceClock:
    """A scanner's wrapping counter carried onto the host's clock.

    The counter is unwrapped (``bits`` wide, ``tick_ns`` a tick) and offset onto
    the host clock by the smallest ``received - device`` difference over the last
    ``window_ns`` of host time: the scan with the least transport delay. A late
    burst (a network hiccup, a pause of the host) does not move the offset, as
    earlier quick scans are still in the window; a drift between the two clocks
    is followed as old minima leave it; a device restarted (its counter jumping)
    gives a smaller difference, which is taken at once.
    """

    def __init__(self, bits: int, tick_ns: int, window_ns: int = 5_000_000_000) -> None:
        self._mod = 1 << bits
        self._tick_ns = tick_ns
        self._window_ns = window_ns
        self._last: int | None = None
        self._ticks = 0
        # (received_ns, difference), differences increasing: a sliding-window minimum
        self._minima: collections.deque[tuple[int, int]] = collections.deque()

    def stamp(self, counter: int, received_ns: int) -> int:
        """The host-clock stamp of a scan the device stamped ``counter``."""
        counter %= self._mod
        if self._last is None:
            self._ticks = counter
        else:
            self._ticks += (counter - self._last) % self._mod
        self._last = counter
        device_ns = self._ticks * self._tick_ns
        difference = received_ns - device_ns
        minima = self._minima
        while minima and minima[-1][1] >= difference:
            minima.pop()
        minima.append((received_ns, difference))
        while minima[0][0] < received_ns - self._window_ns:
            minima.popleft()
        return device_ns + minima[0][1]


class Source(ABC):
    """A stream of scans (see the module)."""

    def __init__(self, url: str, options: SourceOptions) -> None:
        self.url = url
        self.options = options
        self.stats = SourceStats()

    @abstractmethod
    def scans(self, stop: threading.Event, warn: Callable[[str], None]) -> Iterator[Received]:
        """Every scan as it is received, until ``stop`` is set or the stream ends."""


# --------------------------------------------------------------------------- TCP scanners


class _TcpSource(Source):
    """A scanner on TCP: connection, reconnection, time-outs and malformed telegrams;
    the protocol (what to send, how replies are framed and read) is the subclass's."""

    scheme = ""

    def __init__(self, url: str, host: str, port: int, options: SourceOptions) -> None:
        super().__init__(url, options)
        self.host, self.port = host, port
        self._wait = options.backoff_s[0]
        self._why_lost = ""

    # -- the protocol
    @abstractmethod
    def _start(self, sock: socket.socket) -> None:
        """Ask for the stream (a new connection)."""

    @abstractmethod
    def _split(self, buffer: bytearray) -> list[bytes]:
        """Complete telegrams out of ``buffer`` (an empty one: too long, malformed)."""

    @abstractmethod
    def _handle(self, telegram: bytes, sock: socket.socket, received_ns: int) -> Scan | None:
        """A telegram read: its scan, or None (an acknowledgement); InputError if malformed."""

    @abstractmethod
    def _stop(self, sock: socket.socket) -> None:
        """Ask the scanner to stop the stream (the run is ending)."""

    # -- the transport
    def _connect(self) -> socket.socket:
        sock = socket.create_connection(
            (self.host, self.port), timeout=self.options.connect_timeout_s
        )
        sock.settimeout(0.1)  # short reads, so that a stop request is seen at once
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return sock

    def _reconnect(self, stop: threading.Event, last_scan: float) -> socket.socket | None:
        """A new connection after the waits of the backoff (which grow with every attempt
        of one outage); an InputError once ``give_up_s`` have passed since the last scan."""
        while True:
            left = self.options.give_up_s - (time.perf_counter() - last_scan)
            if left <= 0:
                raise InputError(
                    f"{self.url}: scanner lost; no scan for {self.options.give_up_s:g} s "
                    f"({self._why_lost})"
                )
            if stop.wait(min(self._wait, left)):
                return None
            self._wait = min(2 * self._wait, self.options.backoff_s[1])
            try:
                return self._connect()
            except OSError as err:
                self._why_lost = f"cannot connect: {_why(err)}"

    def scans(self, stop: threading.Event, warn: Callable[[str], None]) -> Iterator[Received]:
        try:
            sock: socket.socket | None = self._connect()
        except OSError as err:
            raise InputError(f"cannot connect to {self.url}: {_why(err)}") from None
        last_scan = time.perf_counter()
        self._wait = self.options.backoff_s[0]
        gap = False  # the stream was lost since the last scan
        try:
            while sock is not None and not stop.is_set():
                try:
                    self._start(sock)
                    for received in self._stream(sock, stop, warn):
                        self._wait = self.options.backoff_s[0]
                        if gap:
                            waited = received.received_s - last_scan
                            self.stats.gap_s += waited
                            warn(f"{self.url}: scans again after a gap of {waited:.1f} s")
                            received = Received(
                                received.scan, received.received_ns, received.received_s, waited
                            )
                            gap = False
                        last_scan = received.received_s
                        yield received
                except (_LostError, OSError) as err:
                    why = _why(err) if isinstance(err, OSError) else str(err)
                    if self.stats.scans == 0:
                        # Never a scan: not a scanner streaming there (or not this kind).
                        if self.stats.malformed:
                            why += (
                                f"; {self.stats.malformed} malformed telegrams, the first: "
                                f"{self.stats.first_malformed}"
                            )
                        raise InputError(
                            f"{self.url}: connected, but no scan came ({why}); is it a "
                            f"{self.scheme} scanner?"
                        ) from None
                    if not gap:  # one warning an outage, however many attempts it takes
                        warn(f"{self.url}: {why}; reconnecting")
                    self._why_lost = why
                    gap = True
                if stop.is_set():
                    break
                self._close(sock, polite=False)
                sock = None
                self.stats.reconnects += 1
                sock = self._reconnect(stop, last_scan)
        finally:  # the run ends (stopped, or the reader closed this generator)
            if sock is not None:
                self._close(sock, polite=True)

    def _close(self, sock: socket.socket, *, polite: bool) -> None:
        with contextlib.suppress(OSError):
            if polite:
                sock.settimeout(0.5)
                self._stop(sock)
        with contextlib.suppress(OSError):
            sock.close()

    def _stream(
        self, sock: socket.socket, stop: threading.Event, warn: Callable[[str], None]
    ) -> Iterator[Received]:
        buffer = bytearray()
        last_scan = time.perf_counter()
        while not stop.is_set():
            try:
                chunk = sock.recv(1 << 16)
            except TimeoutError:
                chunk = None
            now = time.perf_counter()
            if chunk == b"":
                raise _LostError("the connection was closed")
            if chunk is not None:
                buffer += chunk
                received_ns = time.time_ns()
                for telegram in self._split(buffer):
                    try:
                        if not telegram:
                            raise InputError("a telegram longer than any scanner sends")
                        scan = self._handle(telegram, sock, received_ns)
                    except InputError as err:
                        self._malformed(err.problem, warn)
                        continue
                    except (ValueError, ArithmeticError, struct.error) as err:
                        # a telegram no check foresaw: skipped like any malformed one
                        self._malformed(f"{type(err).__name__}: {err}", warn)
                        continue
                    if scan is not None:
                        last_scan = now
                        self.stats.scans += 1
                        yield Received(scan, received_ns, now)
            if now - last_scan > self.options.timeout_s:
                raise _LostError(f"no scan for {self.options.timeout_s:g} s")

    def _new_connection(self) -> None:
        """Forget per-connection state (the device may have restarted)."""

    def _malformed(self, problem: str, warn: Callable[[str], None]) -> None:
        self.stats.malformed += 1
        if self.stats.malformed == 1:
            self.stats.first_malformed = problem
            warn(
                f"{self.url}: malformed telegram skipped ({problem}); "
                "further ones are counted, not shown"
            )

    def _limits(self, range_min: float, range_max: float) -> tuple[float, float]:
        o = self.options
        return (
            range_min if o.range_min_m is None else o.range_min_m,
            range_max if o.range_max_m is None else o.range_max_m,
        )


class _LostError(Exception):
    """The scanner closed the connection or stopped sending."""


def _why(err: OSError) -> str:
    if isinstance(err, TimeoutError | socket.timeout):
        return "timed out"
    return str(err.strerror or err)


class SickSource(_TcpSource):
    """SICK LMS1xx / LMS5xx / TiM5xx, CoLa-A (:mod:`mast.live.cola`)."""

    scheme = "sick"
    #: Shortest range of the LMS1xx family, metres (the telegram does not carry it).
    RANGE_MIN_M = 0.05

    def _new_connection(self) -> None:
        self._clock = DeviceClock(32, 1_000)

    def _start(self, sock: socket.socket) -> None:
        self._new_connection()
        sock.sendall(cola.command("sEN LMDscandata 1"))

    def _split(self, buffer: bytearray) -> list[bytes]:
        return cola.split_telegrams(buffer)

    def _handle(self, telegram: bytes, sock: socket.socket, received_ns: int) -> Scan | None:
        head = telegram[:16]
        if not (head.startswith((b"sSN LMDscandata", b"sRA LMDscandata"))):
            if head.startswith(b"sFA"):
                raise InputError(f"the scanner refused a request: {telegram[:40]!r}")
            return None  # an acknowledgement (sEA LMDscandata 1) or another answer
        t = cola.parse_scandata(telegram)
        lo, hi = self._limits(self.RANGE_MIN_M, math.inf)
        stamp = self._clock.stamp(t.time_since_startup_us, received_ns)
        return t.to_scan(range_min_m=lo, range_max_m=hi, stamp_ns=stamp)

    def _stop(self, sock: socket.socket) -> None:
        sock.sendall(cola.command("sEN LMDscandata 0"))


class HokuyoSource(_TcpSource):
    """Hokuyo UST / UTM, SCIP 2.0 (:mod:`mast.live.scip`)."""

    scheme = "hokuyo"

    def _new_connection(self) -> None:
        self._clock = DeviceClock(24, 1_000_000)
        self._params: scip.DeviceParameters | None = None

    def _start(self, sock: socket.socket) -> None:
        self._new_connection()
        sock.sendall(b"SCIP2.0\nPP\n")

    def _split(self, buffer: bytearray) -> list[bytes]:
        return scip.split_replies(buffer)

    def _handle(self, telegram: bytes, sock: socket.socket, received_ns: int) -> Scan | None:
        if telegram.startswith(b"PP"):
            p = scip.parse_parameters(telegram)
            self._params = p
            sock.sendall(f"MD{p.amin:04d}{p.amax:04d}00000\n".encode("ascii"))
            return None
        if not telegram.startswith(b"MD"):
            return None  # SCIP2.0, QT and other answers
        lines = telegram.split(b"\n")
        if len(lines) == 2 and lines[1][:2] == b"00":
            return None  # MD acknowledged; the scans follow
        if self._params is None:
            raise InputError("a distance reply before the device's parameters (PP)")
        reply = scip.parse_distance_reply(telegram)
        lo, hi = self._limits(self._params.dmin_mm / 1000.0, self._params.dmax_mm / 1000.0)
        scan = reply.to_scan(
            self._params, stamp_ns=self._clock.stamp(reply.timestamp_ms, received_ns)
        )
        if (lo, hi) != (scan.range_min_m, scan.range_max_m):
            scan = scan.with_range_limits(lo, hi)
        return scan

    def _stop(self, sock: socket.socket) -> None:
        sock.sendall(b"QT\n")


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
        t0: float | None = None
        s0 = 0
        for scan in scans:
            if o.range_min_m is not None or o.range_max_m is not None:
                scan = scan.with_range_limits(o.range_min_m, o.range_max_m)
            if t0 is None:
                t0, s0 = time.perf_counter(), scan.stamp_ns
            due = t0 + (scan.stamp_ns - s0) / 1e9 / self.rate
            while not stop.is_set():
                left = due - time.perf_counter()
                if left <= 0:
                    break
                stop.wait(min(left, 0.1)) if left > 0.002 else time.sleep(0)
            if stop.is_set():
                return
            self.stats.scans += 1
            yield Received(scan, time.time_ns(), time.perf_counter())


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
    if not sep or scheme not in ("sick", "hokuyo", "replay"):
        raise InputError(
            f"source {text!r}: give sick://HOST[:PORT], hokuyo://HOST[:PORT] or replay://RUN"
        )
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
        port = parts.port or DEFAULT_PORTS[scheme]
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


def open_source(text: str, options: SourceOptions | None = None) -> Source:
    """The source a URL names (see the module); a bad URL is an InputError naming it."""
    o = options or SourceOptions()
    u = _parse(text)
    if u.scheme == "replay":
        rate = _positive(u.query.get("rate", "1"), "rate", text)
        hz = _positive(u.query.get("hz", str(DEFAULT_CSV_HZ)), "hz", text)
        path = Path(urllib.parse.unquote(u.path))
        return ReplaySource(text, path, rate, hz, o, topic=u.query.get("topic"))
    cls: type[_TcpSource] = SickSource if u.scheme == "sick" else HokuyoSource
    return cls(f"{u.scheme}://{u.host}:{u.port}", u.host, u.port, o)
