"""What MAST needs of a scanner protocol: to read the scanner live and to be it.

A protocol is one module of :mod:`mast.live.protocols` holding all three of its
parts: the codec (framing, the scan telegram read and written), the client
(:class:`~mast.live.tcp.TcpSource`: what ``mast live`` sends and how it reads the
replies) and the scanner's side (:class:`Emulation`: how ``mast emulate`` answers).
The module's ``PROTOCOL`` names them; :data:`mast.live.protocols.PROTOCOLS` lists
every one. A new protocol is a new module and one entry there.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

from mast.core.scan import Scan
from mast.live.tcp import TcpSource

__all__ = ["Emulation", "Protocol"]


class Emulation(ABC):
    """The scanner's side of a protocol, serving one run.

    Made for the run's first scan (:attr:`Protocol.emulation`), which sets what the
    device reports of itself (a Hokuyo's step geometry); the transport, pacing and
    faults are :class:`mast.live.emulate.Emulator`'s.
    """

    #: One tick of the device's clock, nanoseconds (the stamp its telegrams carry).
    tick_ns: int

    @abstractmethod
    def requests(self, inbox: bytearray) -> list[bytes]:
        """Every complete request taken out of ``inbox`` (the rest stays in it)."""

    @abstractmethod
    def answer(
        self, request: bytes, streaming: bool, poll: Callable[[], bytes | None]
    ) -> tuple[bytes, bool]:
        """The reply to ``request`` and whether the stream runs after it; ``poll`` gives the
        next scan's telegram (None when the run is served), for a request of one scan."""

    @abstractmethod
    def encode(self, scan: Scan, *, ticks: int, counter: int, hz: float) -> bytes:
        """``scan`` as the device sends it: device clock ``ticks``, scan ``counter``, ``hz``
        scans a second; ranges in whole millimetres, no return as the protocol codes it."""

    @abstractmethod
    def corrupt(self, telegram: bytes) -> bytes:
        """``telegram`` made malformed the way a bad line makes it (for the fault tests)."""

    @abstractmethod
    def read_back(self, sent: bytes, stamp_ns: int) -> Scan:
        """The scan the protocol's client reads from one ``encode``-d telegram, stamped
        ``stamp_ns``: what a scan looks like after the wire."""


@dataclass(frozen=True, slots=True)
class Protocol:
    """One scanner protocol.

    Attributes
    ----------
    name : str
        Its URL scheme (``mast live NAME://HOST``) and ``mast emulate`` kind.
    wire : str
        The protocol's own name (CoLa-A, SCIP 2.0).
    models : str
        The scanner families that speak it.
    default_port : int
        The TCP port the scanners listen on.
    source : type[TcpSource]
        The client.
    emulation : Callable[[Scan], Emulation]
        The scanner's side, for a run starting with the given scan.
    """

    name: str
    wire: str
    models: str
    default_port: int
    source: type[TcpSource]
    emulation: Callable[[Scan], Emulation]

    @property
    def url(self) -> str:
        """How a scanner of this protocol is named: ``sick://HOST[:PORT]``."""
        return f"{self.name}://HOST[:PORT]"
