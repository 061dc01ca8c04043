"""Scanner emulators: a recorded or simulated run served over the real protocol on TCP.

``mast emulate sick|hokuyo --from RUN --port N`` answers as the scanner would:

* ``sick``: CoLa-A. ``sEN LMDscandata 1`` is acknowledged (``sEA LMDscandata 1``)
  and starts the stream of ``sSN LMDscandata`` telegrams, ``sEN LMDscandata 0``
  stops it, ``sRN LMDscandata`` polls one scan (``sRA``); anything else gets
  ``sFA`` (an error, as the device answers an unknown request).
* ``hokuyo``: SCIP 2.0. ``SCIP2.0``, ``PP`` (the step geometry of the run's
  scans: ``ARES`` from the angular step, ``AFRT`` at the forward beam), ``MD``
  (acknowledged with status ``00``, then one reply with status ``99`` per scan)
  and ``QT``; anything else gets status ``0E``.

Scans are sent at the run's recorded spacing (or ``hz`` a second); the device's
clock counts from the emulator's start. One client is served at a time; a
client that reconnects picks the run up where it was left, as a scanner keeps
scanning. :class:`EmulatorFaults` injects what a vehicle meets, for the tests:
a dropped connection, a scanner that stops sending, malformed telegrams.
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live import cola, scip

__all__ = ["KINDS", "Emulator", "EmulatorFaults", "encode_scan", "hokuyo_parameters"]

KINDS = ("sick", "hokuyo")
#: Hokuyo's error code for a beam without an echo (below DMIN, so read as no return).
_NO_ECHO = 1


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


def hokuyo_parameters(scan: Scan, *, model: str = "MAST-EMULATED-UST") -> scip.DeviceParameters:
    """``PP`` parameters under which the steps of ``scan`` are the device's steps."""
    inc = scan.angle_increment
    ares = round(2 * math.pi / inc)
    step = 2 * math.pi / ares
    afrt = round(-float(scan.angles_rad[0]) / step)
    if not scan.is_uniform or abs(-afrt * step - float(scan.angles_rad[0])) > 1e-6:
        raise InputError(
            "the run's beams do not fall on a Hokuyo step grid (2 pi / ARES from forward)"
        )
    dmax = scan.range_max_m if math.isfinite(scan.range_max_m) else 60.0
    return scip.DeviceParameters(
        model=model,
        dmin_mm=max(20, round(scan.range_min_m * 1000)),
        dmax_mm=round(dmax * 1000),
        ares=ares,
        amin=0,
        amax=len(scan) - 1,
        afrt=afrt,
        scan_rpm=2400,
    )


def encode_scan(kind: str, scan: Scan, *, ticks: int, counter: int, hz: float) -> bytes:
    """``scan`` as a ``kind`` scanner sends it: a framed ``sSN LMDscandata`` telegram
    (``sick``; device clock ``ticks`` in microseconds, scan ``counter``, ``hz`` scans a
    second) or an ``MD`` reply (``hokuyo``; ``ticks`` in milliseconds), ranges in whole
    millimetres and a beam without an echo as each protocol codes it."""
    if kind == "sick":
        return cola.encode_scandata(
            scan, scan_counter=counter, time_since_startup_us=ticks, scan_frequency_hz=hz
        )
    if kind == "hokuyo":
        mm = np.where(scan.valid, np.rint(scan.ranges_m * 1000.0), _NO_ECHO).astype(np.int64)
        return scip.encode_distance_reply(mm, first_step=0, timestamp_ms=ticks)
    raise InputError(f"unknown scanner kind {kind!r}; known: {', '.join(KINDS)}")


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
        if kind not in KINDS:
            raise InputError(f"unknown scanner kind {kind!r}; known: {', '.join(KINDS)}")
        self.kind = kind
        self._scans = scans
        self._next: Scan | None = next(scans, None)
        if self._next is None:
            raise InputError("the run holds no scan to serve")
        self._params = hokuyo_parameters(self._next) if kind == "hokuyo" else None
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
        self._tick_ns = 1_000 if kind == "sick" else 1_000_000
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
                for request in self._requests(inbox):
                    answer, streaming_now = self._answer(request, streaming)
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
                telegram = self._corrupt(telegram)
            if not _send(conn, telegram):
                return
            self._sent += 1
            self._next = next(self._scans, None)
            if not self._dropped and f.drop_after is not None and self._sent >= f.drop_after:
                self._dropped = True
                return

    def _requests(self, inbox: bytearray) -> list[bytes]:
        if self.kind == "sick":
            return cola.split_telegrams(inbox)
        out = []
        while (end := inbox.find(b"\n")) >= 0:
            line = bytes(inbox[:end]).rstrip(b"\r")
            del inbox[: end + 1]
            if line:
                out.append(line)
        return out

    def _answer(self, request: bytes, streaming: bool) -> tuple[bytes, bool]:
        """The reply to one request and whether the stream runs after it."""
        if self.kind == "sick":
            if request == b"sEN LMDscandata 1":
                return cola.command("sEA LMDscandata 1"), True
            if request == b"sEN LMDscandata 0":
                return cola.command("sEA LMDscandata 0"), False
            if request == b"sRN LMDscandata" and self._next is not None:
                telegram = self._telegram(self._next).replace(b"sSN", b"sRA", 1)
                return telegram, streaming
            return cola.command("sFA 2"), streaming
        assert self._params is not None
        word = request[:2]
        if request == b"SCIP2.0":
            return b"SCIP2.0\n0Ee\n\n", streaming
        if word == b"PP":
            return scip.encode_parameters(self._params), streaming
        if word == b"MD" and len(request) >= 15:
            return request + b"\n00P\n\n", True
        if word == b"QT":
            return b"QT\n00P\n\n", False
        return request + b"\n0Ee\n\n", streaming

    def _telegram(self, scan: Scan, *, at_ns: int | None = None) -> bytes:
        """``scan`` as the scanner sends it, stamped by the device clock at ``at_ns``
        (perf_counter_ns; now when not given), one tick after the last telegram at least:
        a device's counter only goes forward, even where a recording repeats a stamp."""
        at = time.perf_counter_ns() if at_ns is None else at_ns
        ticks = max((at - self._t0_ns) // self._tick_ns, self._last_tick + 1)
        self._last_tick = ticks
        return encode_scan(self.kind, scan, ticks=ticks, counter=self._sent, hz=self.hz or 25.0)

    def _corrupt(self, telegram: bytes) -> bytes:
        if self.kind == "sick":
            return telegram[: len(telegram) // 2] + cola.ETX  # cut short
        k = telegram.rfind(b"\n", 0, len(telegram) - 2) + 5  # inside the last data line
        return telegram[:k] + bytes([telegram[k] ^ 0x01]) + telegram[k + 1 :]


def _send(conn: socket.socket, data: bytes) -> bool:
    try:
        conn.sendall(data)
    except OSError:
        return False
    return True
