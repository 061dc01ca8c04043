"""Hokuyo UST, UTM and URG over SCIP 2.0 on TCP: the character encodings and sum
checks, the ``PP`` parameter reply and the ``MD``/``GD`` distance replies read into a
:class:`~mast.core.scan.Scan` and written, the client ``mast live hokuyo://HOST``
uses (:class:`HokuyoSource`) and the scanner's side ``mast emulate hokuyo`` answers
with (:class:`HokuyoEmulation`).

The client asks ``PP`` for the step geometry and range limits, then ``MD``
(continuous, every step, no clustering) streams the scans; ``QT`` stops them. The
emulator answers ``SCIP2.0``, ``PP`` (the step geometry of the run's scans: ``ARES``
from the angular step, ``AFRT`` at the forward beam, :func:`hokuyo_parameters`),
``MD`` (acknowledged with status ``00``, then one reply with status ``99`` per scan)
and ``QT``; anything else gets status ``0E``.

SCIP 2.0 (Hokuyo, "Communication Protocol Specification For SCIP2.0 Standard"):

* every line ends in LF; a reply ends in an empty line (LF LF);
* a reply echoes the command line, then a status line (two characters and a
  sum), then data lines, each its data and one sum character;
* the sum of a line is the low 6 bits of the sum of its bytes, plus 0x30;
* data are 6-bit groups, each a character ``0x30 + value``: distances in 3
  characters (``MD``/``GD``; 18 bits, millimetres), the time stamp in 4
  (24 bits, milliseconds); data lines of 64 characters carry the values on,
  split anywhere;
* a distance below the device's ``DMIN`` is an error code, not a range;
* step ``k`` lies at ``(k - AFRT) * 2 pi / ARES`` radians, counter-clockwise from
  forward, as in ``sensor_msgs/LaserScan``.
"""

from __future__ import annotations

import math
import socket
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.protocols.base import Emulation, Protocol
from mast.live.tcp import DeviceClock, TcpSource

__all__ = [
    "PROTOCOL",
    "DeviceParameters",
    "DistanceReply",
    "HokuyoEmulation",
    "HokuyoSource",
    "checksum",
    "decode",
    "encode",
    "encode_distance_reply",
    "encode_parameters",
    "hokuyo_parameters",
    "parse_distance_reply",
    "parse_parameters",
    "split_replies",
]

#: Characters per data line.
LINE_CHARS = 64
#: Longest reply accepted (a UST at 1081 steps is ~3.4 kB).
MAX_REPLY_BYTES = 1 << 20


def checksum(data: bytes) -> int:
    """The SCIP sum character of ``data``: low 6 bits of the byte sum, plus 0x30."""
    return (sum(data) & 0x3F) + 0x30


def encode(value: int, chars: int) -> bytes:
    """``value`` in ``chars`` 6-bit characters, most significant first."""
    return bytes(((value >> (6 * (chars - 1 - k))) & 0x3F) + 0x30 for k in range(chars))


def decode(data: bytes, chars: int) -> NDArray[np.int64]:
    """Values of ``chars`` characters each, from a run of SCIP data characters."""
    if len(data) % chars:
        raise InputError(
            f"SCIP: {len(data)} data characters are not whole {chars}-character values"
        )
    raw = np.frombuffer(data, dtype=np.uint8).astype(np.int64) - 0x30
    if raw.size and (raw.min() < 0 or raw.max() > 0x3F):
        raise InputError("SCIP: a data character is outside the 6-bit encoding")
    groups = raw.reshape(-1, chars)
    weights = 1 << (6 * np.arange(chars - 1, -1, -1, dtype=np.int64))
    return np.asarray(groups @ weights, dtype=np.int64)


def split_replies(buffer: bytearray) -> list[bytes]:
    """Take every complete reply (up to and without its LF LF) out of ``buffer``.

    A reply that grows beyond ``MAX_REPLY_BYTES`` without ending is dropped and
    reported as an empty entry, so the caller can count it as malformed.
    """
    out: list[bytes] = []
    while True:
        end = buffer.find(b"\n\n")
        if end < 0:
            if len(buffer) > MAX_REPLY_BYTES:
                buffer.clear()
                out.append(b"")
            return out
        out.append(bytes(buffer[:end]))
        del buffer[: end + 2]


def _checked(line: bytes, what: str) -> bytes:
    """A data or status line without its sum, after checking the sum."""
    if len(line) < 2:
        raise InputError(f"SCIP: {what} line {line!r} is too short to carry a sum")
    body, total = line[:-1], line[-1]
    if checksum(body) != total:
        raise InputError(f"SCIP: {what} line fails its sum check")
    return body


@dataclass(frozen=True, slots=True)
class DeviceParameters:
    """The ``PP`` reply: model, range limits and the step geometry."""

    model: str
    dmin_mm: int
    dmax_mm: int
    ares: int
    amin: int
    amax: int
    afrt: int
    scan_rpm: int

    @property
    def step_rad(self) -> float:
        return 2 * math.pi / self.ares

    def angle(self, step: int) -> float:
        """Scanner-frame angle of ``step``, radians."""
        return (step - self.afrt) * self.step_rad


def parse_parameters(reply: bytes) -> DeviceParameters:
    """Read a ``PP`` reply (command echo, status, ``NAME:value;sum`` lines)."""
    lines = reply.split(b"\n")
    if len(lines) < 2 or not lines[0].startswith(b"PP"):
        raise InputError("SCIP: not a PP reply")
    status = _checked(lines[1], "status") if len(lines[1]) > 2 else lines[1]
    if status[:2] != b"00":
        raise InputError(f"SCIP: PP refused with status {status[:2]!r}")
    fields: dict[str, str] = {}
    for line in lines[2:]:
        if not line:
            continue
        # "NAME:value;" then the sum of everything before the ';'
        if len(line) < 3 or line[-2:-1] != b";":
            raise InputError(f"SCIP: parameter line {line[:30]!r} is malformed")
        if checksum(line[:-2]) != line[-1]:
            raise InputError(f"SCIP: parameter line {line[:30]!r} fails its sum check")
        name, _, value = line[:-2].decode("ascii", "replace").partition(":")
        fields[name] = value
    try:
        p = DeviceParameters(
            model=fields.get("MODL", "?"),
            dmin_mm=int(fields["DMIN"]),
            dmax_mm=int(fields["DMAX"]),
            ares=int(fields["ARES"]),
            amin=int(fields["AMIN"]),
            amax=int(fields["AMAX"]),
            afrt=int(fields["AFRT"]),
            scan_rpm=int(fields["SCAN"]),
        )
    except (KeyError, ValueError):
        raise InputError(
            "SCIP: PP reply lacks a number among DMIN DMAX ARES AMIN AMAX AFRT SCAN"
        ) from None
    if not (
        0 < p.ares <= 1 << 20
        and 0 <= p.amin <= p.amax < p.ares + p.amin
        and 0 <= p.dmin_mm < p.dmax_mm
    ):
        raise InputError(
            f"SCIP: PP reply's step geometry is impossible (ARES {p.ares}, AMIN {p.amin}, "
            f"AMAX {p.amax}, DMIN {p.dmin_mm}, DMAX {p.dmax_mm})"
        )
    return p


def encode_parameters(p: DeviceParameters) -> bytes:
    """A ``PP`` reply (without the closing empty line's final LF)."""
    lines = [b"PP", b"00P"]
    for name, value in (
        ("MODL", p.model),
        ("DMIN", p.dmin_mm),
        ("DMAX", p.dmax_mm),
        ("ARES", p.ares),
        ("AMIN", p.amin),
        ("AMAX", p.amax),
        ("AFRT", p.afrt),
        ("SCAN", p.scan_rpm),
    ):
        body = f"{name}:{value}".encode("ascii")
        lines.append(body + b";" + bytes([checksum(body)]))
    return b"\n".join(lines) + b"\n\n"


@dataclass(frozen=True, slots=True)
class DistanceReply:
    """One ``MD``/``GD`` scan: the steps it covers, the device's time stamp and distances.

    ``distances_mm`` holds the raw values (error codes below ``DMIN`` included).
    """

    first_step: int
    last_step: int
    cluster: int
    timestamp_ms: int
    distances_mm: NDArray[np.int64]
    remaining: int = 0

    def to_scan(
        self, params: DeviceParameters, *, stamp_ns: int, range_max_m: float | None = None
    ) -> Scan:
        """The scan in the scanner frame; codes below ``DMIN`` and values above ``DMAX``
        are no return."""
        d = self.distances_mm.astype(np.float64)
        ok = (d >= params.dmin_mm) & (d <= params.dmax_mm)
        r = np.where(ok, d / 1000.0, np.nan)
        # A cluster of steps is one beam at the middle of the steps it groups.
        centre = self.first_step + 0.5 * (self.cluster - 1)
        return Scan.from_laserscan(
            angle_min=(centre - params.afrt) * params.step_rad,
            angle_increment=self.cluster * params.step_rad,
            ranges=r,
            range_min=params.dmin_mm / 1000.0,
            range_max=params.dmax_mm / 1000.0 if range_max_m is None else range_max_m,
            stamp_ns=stamp_ns,
        )


def parse_distance_reply(reply: bytes) -> DistanceReply:
    """Read an ``MD``/``GD`` reply carrying one scan (status ``99`` or ``00``).

    The command echo gives the steps, cluster and (``MD``) scans remaining;
    then the status, the 4-character time stamp and the data lines, each
    checked against its sum.
    """
    lines = reply.split(b"\n")
    echo = lines[0]
    if len(echo) < 12 or echo[:2] not in (b"MD", b"GD"):
        raise InputError(f"SCIP: not a distance reply: {echo[:20]!r}")
    try:
        first, last, cluster = int(echo[2:6]), int(echo[6:10]), int(echo[10:12])
        remaining = int(echo[13:15]) if echo[:2] == b"MD" and len(echo) >= 15 else 0
    except ValueError:
        raise InputError(f"SCIP: distance command {echo[:20]!r} has no step numbers") from None
    cluster = max(cluster, 1)
    if len(lines) < 3:
        raise InputError("SCIP: distance reply ends before its data")
    status = _checked(lines[1], "status")
    if status not in (b"99", b"00"):
        raise InputError(f"SCIP: distance reply with status {status!r} carries no scan")
    timestamp = int(decode(_checked(lines[2], "time stamp"), 4)[0])
    data = b"".join(_checked(line, "data") for line in lines[3:] if line)
    values = decode(data, 3)
    expected = (last - first) // cluster + 1
    if values.size != expected:
        raise InputError(f"SCIP: {values.size} distances for {expected} beams")
    return DistanceReply(first, last, cluster, timestamp, values, remaining)


def encode_distance_reply(
    distances_mm: NDArray[np.int64],
    *,
    first_step: int,
    timestamp_ms: int,
    remaining: int = 0,
    cluster: int = 1,
    interval: int = 0,
) -> bytes:
    """An ``MD`` reply of one scan (status ``99``), closed by its empty line."""
    last = first_step + cluster * distances_mm.size - 1
    echo = f"MD{first_step:04d}{last:04d}{cluster:02d}{interval:1d}{remaining:02d}".encode("ascii")
    stamp = encode(timestamp_ms & 0xFFFFFF, 4)
    data = b"".join(encode(int(v), 3) for v in np.clip(distances_mm, 0, (1 << 18) - 1))
    lines = [echo, b"99" + bytes([checksum(b"99")]), stamp + bytes([checksum(stamp)])]
    for k in range(0, len(data), LINE_CHARS):
        chunk = data[k : k + LINE_CHARS]
        lines.append(chunk + bytes([checksum(chunk)]))
    return b"\n".join(lines) + b"\n\n"


# --------------------------------------------------------------------------- client


class HokuyoSource(TcpSource):
    """Hokuyo UST / UTM, SCIP 2.0: the client."""

    scheme = "hokuyo"

    def _new_connection(self) -> None:
        self._clock = DeviceClock(24, 1_000_000)
        self._params: DeviceParameters | None = None

    def _start(self, sock: socket.socket) -> None:
        self._new_connection()
        sock.sendall(b"SCIP2.0\nPP\n")

    def _split(self, buffer: bytearray) -> list[bytes]:
        return split_replies(buffer)

    def _handle(self, telegram: bytes, sock: socket.socket, received_ns: int) -> Scan | None:
        if telegram.startswith(b"PP"):
            p = parse_parameters(telegram)
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
        reply = parse_distance_reply(telegram)
        lo, hi = self._limits(self._params.dmin_mm / 1000.0, self._params.dmax_mm / 1000.0)
        scan = reply.to_scan(
            self._params, stamp_ns=self._clock.stamp(reply.timestamp_ms, received_ns)
        )
        if (lo, hi) != (scan.range_min_m, scan.range_max_m):
            scan = scan.with_range_limits(lo, hi)
        return scan

    def _stop(self, sock: socket.socket) -> None:
        sock.sendall(b"QT\n")


# --------------------------------------------------------------------------- the scanner's side

#: The error code written for a beam without an echo (below DMIN, so read as no return).
NO_ECHO = 1


def hokuyo_parameters(scan: Scan, *, model: str = "MAST-EMULATED-UST") -> DeviceParameters:
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
    return DeviceParameters(
        model=model,
        dmin_mm=max(20, round(scan.range_min_m * 1000)),
        dmax_mm=round(dmax * 1000),
        ares=ares,
        amin=0,
        amax=len(scan) - 1,
        afrt=afrt,
        scan_rpm=2400,
    )


class HokuyoEmulation(Emulation):
    """A Hokuyo scanner answering SCIP 2.0, for ``mast emulate hokuyo``."""

    tick_ns = 1_000_000  # milliseconds

    def __init__(self, first: Scan) -> None:
        self.params = hokuyo_parameters(first)

    def requests(self, inbox: bytearray) -> list[bytes]:
        out = []
        while (end := inbox.find(b"\n")) >= 0:
            line = bytes(inbox[:end]).rstrip(b"\r")
            del inbox[: end + 1]
            if line:
                out.append(line)
        return out

    def answer(
        self, request: bytes, streaming: bool, poll: Callable[[], bytes | None]
    ) -> tuple[bytes, bool]:
        del poll  # SCIP's one-scan request (GD) is not emulated
        word = request[:2]
        if request == b"SCIP2.0":
            return b"SCIP2.0\n0Ee\n\n", streaming
        if word == b"PP":
            return encode_parameters(self.params), streaming
        if word == b"MD" and len(request) >= 15:
            return request + b"\n00P\n\n", True
        if word == b"QT":
            return b"QT\n00P\n\n", False
        return request + b"\n0Ee\n\n", streaming

    def encode(self, scan: Scan, *, ticks: int, counter: int, hz: float) -> bytes:
        del counter, hz  # an MD reply carries neither
        mm = np.where(scan.valid, np.rint(scan.ranges_m * 1000.0), NO_ECHO).astype(np.int64)
        return encode_distance_reply(mm, first_step=0, timestamp_ms=ticks)

    def corrupt(self, telegram: bytes) -> bytes:
        k = telegram.rfind(b"\n", 0, len(telegram) - 2) + 5  # inside the last data line
        return telegram[:k] + bytes([telegram[k] ^ 0x01]) + telegram[k + 1 :]

    def read_back(self, sent: bytes, stamp_ns: int) -> Scan:
        (reply,) = split_replies(bytearray(sent))
        return parse_distance_reply(reply).to_scan(self.params, stamp_ns=stamp_ns)


PROTOCOL = Protocol(
    name="hokuyo",
    wire="SCIP 2.0",
    models="Hokuyo UST / UTM",
    default_port=10940,
    source=HokuyoSource,
    emulation=HokuyoEmulation,
)
