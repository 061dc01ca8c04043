"""Scanner emulators: a recorded or simulated run served over the real protocol on TCP.

``mast emulate KIND --from RUN --port N`` answers as a scanner of that protocol would
(:mod:`mast.live.protocols`: ``sick`` CoLa-A, ``hokuyo`` SCIP 2.0; each protocol's
module says which requests it answers and how).

Scans are sent at the run's recorded spacing (or ``hz`` a second); the device's
clock counts from the emulator's start. One client is served at a time; a
client that reconnects picks the run up where it was left, as a scanner keeps
scanning. :class:`EmulatorFaults` injects what a vehicle meets, for the tests:
a dropped connection, a scanner that stops sending, malformed telegrams.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.protocols import PROTOCOLS, protocol

__all__ = ["KINDS", "Emulator", "EmulatorFaults"]

#: The kinds of scanner an emulator can be: every protocol's name.
KINDS = tuple(PROTOCOLS)


@dataclass(frozen=True, slots=True)
class EmulatorFaults:
    """Faults to inject, each once (None: never).

    Attributes
    ----------
    drop_after : int or None
        Close the connection after this many scans have been sent.
    stall_after : int or None
        Stop sending after this many scans, the connection left open, until the
        client reconnects.
    corrupt_every : int or None
        Send every n-th scan telegram malformed (cut short, or a failed sum).
    """

    drop_after: int | None = None
    stall_after: int | None = None
    corrupt_every: int | None = None


class Emulator:
    """Serve ``scans`` as a ``kind`` scanner on ``host:port`` (0: a free port) in a thread.

    Use :meth:`start`, then :attr:`port`; :meth:`wait` returns when the run has
    been served (every scan sent) or :meth:`stop` was called.
    """

    def __init__(
        self,
        kind: str,
        scans: Iterator[Scan],
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        hz: float | None = None,
        faults: EmulatorFaults = EmulatorFaults(),
    ) -> None:
        self.protocol = protocol(kind)
        self.kind = kind
        self._scans = scans
        self._next: Scan | None = next(scans, None)
        if self._next is None:
            raise InputError("the run holds no scan to serve")
        self._device = self.protocol.emulation(self._next)
        self.hz = hz
        self.faults = faults
        try:
            self._server = socket.create_server((host, port))
        except OSError as err:
            raise InputError(f"cannot serve on {host}:{port}: {err.strerror or err}") from None
        self._server.settimeout(0.1)
        self.port: int = self._server.getsockname()[1]
        self._stop = threading.Event()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"mast-emulate-{kind}", daemon=True)
        # The device clock in integer ticks of the protocol (SICK: 1 us, SCIP: 1 ms),
        # counted from the host's perf_counter_ns: float seconds since boot truncated to
        # ticks gave 40, 40, 41 for three telegrams a tick apart at some uptimes.
        self._tick_ns = self._device.tick_ns
        self._t0_ns = time.perf_counter_ns()
        self._sent = 0
        self._last_tick = -1  # the device time of the last telegram, in ticks
        self._first_stamp = self._next.stamp_ns
        self._clock_start_ns: int | None = None
        self._sent_at_start = 0
        self._dropped = self._stalled = False
        self.connections = 0
        self.error: BaseException | None = None

    @property
    def sent(self) -> int:
        """Scans sent so far."""
        return self._sent

    def start(self) -> Emulator:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)

    def wait(self, timeout: float | None = None) -> bool:
        """Until the run is served; False on time-out."""
        return self._done.wait(timeout)

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ serving

    def _run(self) -> None:
        try:
            while not self._stop.is_set() and self._next is not None:
                try:
                    conn, _ = self._server.accept()
                except TimeoutError:
                    continue
                self.connections += 1
                with conn:
                    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    conn.settimeout(2.0)  # a client that stops reading is dropped, not waited on
                    self._serve(conn)
        except BaseException as err:  # pragma: no cover - reported to whoever waits
            self.error = err
        finally:
            self._server.close()
            close = getattr(self._scans, "close", None)
            if close is not None:
                close()  # a bag reader, closed with its generator
            self._done.set()

    def _due_ns(self, scan: Scan) -> int:
        """When ``scan`` is to be sent (perf_counter_ns)."""
        if self._clock_start_ns is None:
            self._clock_start_ns = time.perf_counter_ns()
        if self.hz is not None:
            return self._clock_start_ns + round((self._sent - self._sent_at_start) * 1e9 / self.hz)
        return self._clock_start_ns + (scan.stamp_ns - self._first_stamp)

    def _serve(self, conn: socket.socket) -> None:
        inbox = bytearray()
        streaming = False
        stalled = False
        while not self._stop.is_set() and self._next is not None:
            due = self._due_ns(self._next) if streaming and not stalled else None
            wait = 0.05 if due is None else min(max(due - time.perf_counter_ns(), 0) / 1e9, 0.05)
            readable, _, _ = select.select([conn], [], [], wait)
            if readable:
                try:
                    data = conn.recv(4096)
                except OSError:
                    return
                if not data:
                    return  # the client went away
                inbox += data
                for request in self._device.requests(inbox):
                    answer, streaming_now = self._device.answer(request, streaming, self._poll)
                    if answer and not _send(conn, answer):
                        return
                    if streaming_now and not streaming:
                        self._clock_start_ns = None  # pace from now on
                        self._first_stamp = self._next.stamp_ns
                        self._sent_at_start = self._sent
                    streaming = streaming_now
                continue
            if due is None or time.perf_counter_ns() < due:
                continue
            f = self.faults
            if not self._stalled and f.stall_after is not None and self._sent >= f.stall_after:
                self._stalled = stalled = True
                continue
            # stamped when it was due (acquired), not when sent: a loaded host sending two
            # late scans in one millisecond must not give them one stamp
            telegram = self._telegram(self._next, at_ns=due)
            if f.corrupt_every and (self._sent + 1) % f.corrupt_every == 0:
                telegram = self._device.corrupt(telegram)
            if not _send(conn, telegram):
                return
            self._sent += 1
            self._next = next(self._scans, None)
            if not self._dropped and f.drop_after is not None and self._sent >= f.drop_after:
                self._dropped = True
                return

    def _poll(self) -> bytes | None:
        """The next scan's telegram, for a request of one scan; None when served."""
        return None if self._next is None else self._telegram(self._next)

    def _telegram(self, scan: Scan, *, at_ns: int | None = None) -> bytes:
        """``scan`` as the scanner sends it, stamped by the device clock at ``at_ns``
        (perf_counter_ns; now when not given), one tick after the last telegram at least:
        a device's counter only goes forward, even where a recording repeats a stamp."""
        at = time.perf_counter_ns() if at_ns is None else at_ns
        ticks = max((at - self._t0_ns) // self._tick_ns, self._last_tick + 1)
        self._last_tick = ticks
        return self._device.encode(scan, ticks=ticks, counter=self._sent, hz=self.hz or 25.0)


def _send(conn: socket.socket, data: bytes) -> bool:
    try:
        conn.sendall(data)
    except OSError:
        return False
    return True
