"""A scanner on TCP: connection, reconnection, time-outs, malformed telegrams and the
device's clock. What is sent and how replies are read is each protocol's
(:mod:`mast.live.protocols`); everything else about a scanner on a network is here.

A TCP source survives what a vehicle meets: a connection dropped mid-stream or a
scanner that stops sending (no scan for ``timeout_s``) is reconnected with backoff
and the gap reported; a malformed telegram is skipped and counted (one warning names
the first); a scanner that cannot be reached at all, or not again within
``give_up_s``, ends the stream with an :class:`~mast.errors.InputError` naming it.

Stamps: a scanner's own clock (SICK: microseconds since start-up, 32 bits; Hokuyo:
milliseconds, 24 bits) is unwrapped and carried onto the host's clock with the
smallest offset seen (:class:`DeviceClock`), so that stamps keep the scanner's spacing
and lag the scan by no more than the network does.
"""

from __future__ import annotations

import collections
import contextlib
import socket
import struct
import threading
import time
from abc import abstractmethod
from collections.abc import Callable, Iterator

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.stream import Received, Source, SourceOptions

__all__ = ["DeviceClock", "TcpSource"]


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


class TcpSource(Source):
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
