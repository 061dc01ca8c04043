"""SICK LMS1xx, LMS5xx and TiM5xx over CoLa-A (ASCII) on TCP: the telegrams' framing,
the ``LMDscandata`` scan telegram read into a :class:`~mast.core.scan.Scan` and
written, the client ``mast live sick://HOST`` uses (:class:`SickSource`) and the
scanner's side ``mast emulate sick`` answers with (:class:`SickEmulation`).

The client starts the stream with ``sEN LMDscandata 1`` and stops it with
``sEN LMDscandata 0``; every ``sSN LMDscandata`` telegram is a scan. The emulator
acknowledges ``sEN LMDscandata 1`` (``sEA LMDscandata 1``) and starts the stream,
``sEN LMDscandata 0`` stops it, ``sRN LMDscandata`` polls one scan (``sRA``);
anything else gets ``sFA`` (an error, as the device answers an unknown request).

A CoLa-A telegram is ``STX`` (0x02), space-separated tokens, ``ETX`` (0x03).
Numbers are hexadecimal (upper case) unless signed with ``+`` or ``-``, then
decimal. The fields of ``sSN LMDscandata`` / ``sRA LMDscandata``, in order
(SICK "Telegram listing, ranging sensors", and SICK's open drivers):

=====  ==========================================================
token  field
=====  ==========================================================
0, 1   command type (``sSN`` streamed, ``sRA`` polled), ``LMDscandata``
2      version number
3      device number
4      serial number
5, 6   device status (``0 0`` is ok)
7      telegram counter
8      scan counter
9      time since start-up, microseconds
10     time of transmission, microseconds
11, 12 input status
13, 14 output status
15     reserved byte A
16     scanning frequency, 1/100 Hz
17     measurement frequency, 100 Hz
18     number of encoders ``E``, then ``2 E`` tokens (position, speed)
..     number of 16-bit channels; each: content (``DIST1``, ``RSSI1`` ...),
       scale factor and offset (IEEE 754 float32 as 8 hex digits), start
       angle (int32, 1/10 000 degree), angular step (uint16, 1/10 000
       degree), number of values ``n``, then ``n`` values
..     number of 8-bit channels, the same layout; then position, name,
       comment, time (each ``0`` when absent, time as ``1 Y M D h m s us``),
       event
=====  ==========================================================

Angles: the telegram's 0 degree lies 90 degrees clockwise of the scanner's
forward axis (a 270 degree LMS1xx starts at -45 degrees), angles increasing
counter-clockwise, so a beam at telegram angle ``a`` is at ``a - 90`` degrees in
the scanner frame (x forward, y left), as in ``sensor_msgs/LaserScan``.
"""

from __future__ import annotations

import math
import socket
import struct
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.scan import Scan
from mast.errors import InputError
from mast.live.protocols.base import Emulation, Protocol
from mast.live.tcp import DeviceClock, TcpSource

__all__ = [
    "ETX",
    "PROTOCOL",
    "STX",
    "ScanTelegram",
    "SickEmulation",
    "SickSource",
    "command",
    "encode_scandata",
    "parse_scandata",
    "split_telegrams",
]

STX = b"\x02"
ETX = b"\x03"
#: Longest telegram accepted (an LMS5xx at 0.1667 degrees, two channels, is ~20 kB).
MAX_TELEGRAM_BYTES = 1 << 20
#: Telegram angle of the scanner's forward axis, degrees.
FORWARD_DEG = 90.0
#: Most values one channel may declare (a full circle at 1/10 000 degree steps is far less).
MAX_CHANNEL_VALUES = 100_000


def command(text: str) -> bytes:
    """One CoLa-A telegram: ``text`` framed by STX and ETX."""
    return STX + text.encode("ascii") + ETX


def split_telegrams(buffer: bytearray) -> list[bytes]:
    """Take every complete telegram out of ``buffer`` (the bytes between STX and ETX).

    Bytes before the first STX are dropped (a stream joined mid-telegram); an
    incomplete telegram stays in ``buffer`` for the next read. A telegram that
    grows beyond ``MAX_TELEGRAM_BYTES`` without its ETX is dropped and reported
    as an empty entry, so the caller can count it as malformed.
    """
    out: list[bytes] = []
    while True:
        start = buffer.find(STX)
        if start < 0:
            buffer.clear()
            return out
        if start:
            del buffer[:start]
        end = buffer.find(ETX, 1)
        if end < 0:
            if len(buffer) > MAX_TELEGRAM_BYTES:
                buffer.clear()
                out.append(b"")
            return out
        out.append(bytes(buffer[1:end]))
        del buffer[: end + 1]


@dataclass(frozen=True, slots=True)
class ScanTelegram:
    """What an ``LMDscandata`` telegram says of one scan.

    Attributes
    ----------
    device_status : int
        0 when the device reports itself ok.
    telegram_counter, scan_counter : int
    time_since_startup_us, transmission_time_us : int
        The device's own clock, microseconds.
    scan_frequency_hz : float
    start_angle_deg, step_deg : float
        First beam and angular step, telegram angles (see the module notes).
    distances_m : ndarray
        First distance channel (``DIST1``), metres, 0 where the device has no return.
    rssi : ndarray or None
        First remission channel (``RSSI1``), where sent.
    """

    device_status: int
    telegram_counter: int
    scan_counter: int
    time_since_startup_us: int
    transmission_time_us: int
    scan_frequency_hz: float
    start_angle_deg: float
    step_deg: float
    distances_m: NDArray[np.float64]
    rssi: NDArray[np.float64] | None = None

    def to_scan(self, *, range_min_m: float, range_max_m: float, stamp_ns: int) -> Scan:
        """The scan in the scanner frame (beam angles counter-clockwise from forward)."""
        r = np.where(self.distances_m > 0, self.distances_m, np.nan)
        return Scan.from_laserscan(
            angle_min=math.radians(self.start_angle_deg - FORWARD_DEG),
            angle_increment=math.radians(self.step_deg),
            ranges=r,
            range_min=range_min_m,
            range_max=range_max_m,
            intensities=self.rssi,
            stamp_ns=stamp_ns,
        )


def _number(token: bytes, what: str) -> int:
    try:
        if token[:1] in (b"+", b"-"):
            return int(token, 10)
        return int(token, 16)
    except ValueError:
        raise InputError(f"LMDscandata: {what} {token[:20]!r} is not a number") from None


def _float32(token: bytes, what: str) -> float:
    try:
        bits = int(token, 16) if len(token) == 8 and token[:1] not in (b"+", b"-") else -1
    except ValueError:
        bits = -1
    if bits < 0:
        raise InputError(f"LMDscandata: {what} {token[:20]!r} is not 8 hex digits")
    value = struct.unpack(">f", struct.pack(">I", bits))[0]
    if not math.isfinite(value):
        raise InputError(f"LMDscandata: {what} is not finite")
    return float(value)


class _Tokens:
    def __init__(self, body: bytes) -> None:
        self._t = body.split()
        self._at = 0

    def take(self, what: str) -> bytes:
        if self._at >= len(self._t):
            raise InputError(f"LMDscandata: telegram ends before its {what}")
        tok = self._t[self._at]
        self._at += 1
        return tok

    def number(self, what: str) -> int:
        return _number(self.take(what), what)

    def values(self, n: int, what: str) -> NDArray[np.float64]:
        if self._at + n > len(self._t):
            raise InputError(f"LMDscandata: {what} declares {n} values, the telegram holds fewer")
        chunk = self._t[self._at : self._at + n]
        self._at += n
        try:
            return np.array([int(t, 16) for t in chunk], dtype=np.float64)
        except ValueError:
            raise InputError(f"LMDscandata: a {what} value is not a hex number") from None


def _channel(
    tok: _Tokens,
) -> tuple[str, float, float, float, float, NDArray[np.float64]]:
    content = tok.take("channel content").decode("ascii", "replace")
    scale = _float32(tok.take("scale factor"), "scale factor")
    offset = _float32(tok.take("scale offset"), "scale offset")
    start = tok.number("start angle")
    if start >= 1 << 31:
        start -= 1 << 32  # int32 written as 8 hex digits
    step = tok.number("angular step")
    n = tok.number("number of values")
    if not 0 < n <= MAX_CHANNEL_VALUES:
        raise InputError(f"LMDscandata: channel {content} declares {n} values")
    if step <= 0:
        raise InputError(f"LMDscandata: channel {content} has angular step {step}")
    return content, scale, offset, start / 1e4, step / 1e4, tok.values(n, content)


def parse_scandata(body: bytes) -> ScanTelegram:
    """Read an ``sSN``/``sRA LMDscandata`` telegram (the bytes between STX and ETX).

    Raises :class:`~mast.errors.InputError` naming the field for any telegram
    that is not one, or is truncated or inconsistent.
    """
    tok = _Tokens(body)
    kind, name = tok.take("command type"), tok.take("command")
    if kind not in (b"sSN", b"sRA") or name != b"LMDscandata":
        raise InputError(f"not an LMDscandata telegram: {body[:30]!r}")
    tok.number("version")
    tok.number("device number")
    tok.take("serial number")
    status = (tok.number("device status") << 8) | tok.number("device status")
    telegram_counter = tok.number("telegram counter")
    scan_counter = tok.number("scan counter")
    since_startup = tok.number("time since start-up")
    transmission = tok.number("time of transmission")
    for what in ("input status", "input status", "output status", "output status", "reserved"):
        tok.number(what)
    frequency = tok.number("scanning frequency") / 100.0
    tok.number("measurement frequency")
    encoders = tok.number("number of encoders")
    if not 0 <= encoders <= 3:
        raise InputError(f"LMDscandata: {encoders} encoders")
    for _ in range(2 * encoders):
        tok.number("encoder")
    channels16 = tok.number("number of 16-bit channels")
    if not 0 <= channels16 <= 5:
        raise InputError(f"LMDscandata: {channels16} 16-bit channels")
    dist: tuple[float, float, NDArray[np.float64]] | None = None
    rssi: NDArray[np.float64] | None = None
    for _ in range(channels16):
        content, scale, offset, start, step, values = _channel(tok)
        if content == "DIST1" and dist is None:
            dist = (start, step, (values * scale + offset) / 1000.0)
        elif content == "RSSI1" and rssi is None:
            rssi = values * scale + offset
    channels8 = tok.number("number of 8-bit channels")
    if not 0 <= channels8 <= 5:
        raise InputError(f"LMDscandata: {channels8} 8-bit channels")
    for _ in range(channels8):
        content, scale, offset, _, _, values = _channel(tok)
        if content == "RSSI1" and rssi is None:
            rssi = values * scale + offset
    if dist is None:
        raise InputError("LMDscandata: no DIST1 channel (distances are not being sent)")
    start, step, distances = dist
    if rssi is not None and rssi.size != distances.size:
        rssi = None
    return ScanTelegram(
        device_status=status,
        telegram_counter=telegram_counter,
        scan_counter=scan_counter,
        time_since_startup_us=since_startup,
        transmission_time_us=transmission,
        scan_frequency_hz=frequency,
        start_angle_deg=start,
        step_deg=step,
        distances_m=distances,
        rssi=rssi,
    )


def encode_scandata(
    scan: Scan,
    *,
    scan_counter: int,
    time_since_startup_us: int,
    scan_frequency_hz: float,
    serial: str = "1A2B3C",
    scale: float = 1.0,
) -> bytes:
    """An ``sSN LMDscandata`` telegram (framed) of a scan with evenly spaced beams.

    Distances are written in millimetres divided by ``scale`` (0 for no return,
    as the device writes it), the start angle and step rounded to the
    telegram's 1/10 000 degree.
    """
    angles = scan.angles_rad
    step = float(angles[1] - angles[0]) if angles.size > 1 else math.radians(0.25)
    start_t = round((math.degrees(float(angles[0])) + FORWARD_DEG) * 1e4)
    step_t = round(math.degrees(step) * 1e4)
    r = np.where(scan.valid, scan.ranges_m, 0.0)
    mm = np.clip(np.rint(r * 1000.0 / scale), 0, 0xFFFF).astype(np.int64)
    scale_hex = struct.unpack(">I", struct.pack(">f", scale))[0]
    head = (
        f"sSN LMDscandata 1 1 {serial} 0 0 {scan_counter & 0xFFFF:X} {scan_counter & 0xFFFF:X} "
        f"{time_since_startup_us & 0xFFFFFFFF:X} {(time_since_startup_us + 800) & 0xFFFFFFFF:X} "
        f"0 0 0 0 0 {round(scan_frequency_hz * 100):X} 168 0 1 DIST1 {scale_hex:08X} 00000000 "
        f"{start_t & 0xFFFFFFFF:X} {step_t:X} {mm.size:X} "
    )
    values = " ".join(f"{v:X}" for v in mm.tolist())
    return command(head + values + " 0 0 0 0 0 0")


# --------------------------------------------------------------------------- client


class SickSource(TcpSource):
    """SICK LMS1xx / LMS5xx / TiM5xx, CoLa-A: the client."""

    scheme = "sick"
    #: Shortest range of the LMS1xx family, metres (the telegram does not carry it).
    RANGE_MIN_M = 0.05

    def _new_connection(self) -> None:
        self._clock = DeviceClock(32, 1_000)

    def _start(self, sock: socket.socket) -> None:
        self._new_connection()
        sock.sendall(command("sEN LMDscandata 1"))

    def _split(self, buffer: bytearray) -> list[bytes]:
        return split_telegrams(buffer)

    def _handle(self, telegram: bytes, sock: socket.socket, received_ns: int) -> Scan | None:
        head = telegram[:16]
        if not (head.startswith((b"sSN LMDscandata", b"sRA LMDscandata"))):
            if head.startswith(b"sFA"):
                raise InputError(f"the scanner refused a request: {telegram[:40]!r}")
            return None  # an acknowledgement (sEA LMDscandata 1) or another answer
        t = parse_scandata(telegram)
        lo, hi = self._limits(self.RANGE_MIN_M, math.inf)
        stamp = self._clock.stamp(t.time_since_startup_us, received_ns)
        return t.to_scan(range_min_m=lo, range_max_m=hi, stamp_ns=stamp)

    def _stop(self, sock: socket.socket) -> None:
        sock.sendall(command("sEN LMDscandata 0"))


# --------------------------------------------------------------------------- the scanner's side


class SickEmulation(Emulation):
    """A SICK scanner streaming CoLa-A, for ``mast emulate sick``."""

    tick_ns = 1_000  # time since start-up, microseconds

    def __init__(self, first: Scan) -> None:
        del first  # the telegram describes each scan whole

    def requests(self, inbox: bytearray) -> list[bytes]:
        return split_telegrams(inbox)

    def answer(
        self, request: bytes, streaming: bool, poll: Callable[[], bytes | None]
    ) -> tuple[bytes, bool]:
        if request == b"sEN LMDscandata 1":
            return command("sEA LMDscandata 1"), True
        if request == b"sEN LMDscandata 0":
            return command("sEA LMDscandata 0"), False
        if request == b"sRN LMDscandata" and (telegram := poll()) is not None:
            return telegram.replace(b"sSN", b"sRA", 1), streaming
        return command("sFA 2"), streaming

    def encode(self, scan: Scan, *, ticks: int, counter: int, hz: float) -> bytes:
        return encode_scandata(
            scan, scan_counter=counter, time_since_startup_us=ticks, scan_frequency_hz=hz
        )

    def corrupt(self, telegram: bytes) -> bytes:
        return telegram[: len(telegram) // 2] + ETX  # cut short

    def read_back(self, sent: bytes, stamp_ns: int) -> Scan:
        (telegram,) = split_telegrams(bytearray(sent))
        return parse_scandata(telegram).to_scan(
            range_min_m=SickSource.RANGE_MIN_M, range_max_m=math.inf, stamp_ns=stamp_ns
        )


PROTOCOL = Protocol(
    name="sick",
    wire="CoLa-A",
    models="SICK LMS1xx / LMS5xx / TiM5xx",
    default_port=2111,
    source=SickSource,
    emulation=SickEmulation,
)
