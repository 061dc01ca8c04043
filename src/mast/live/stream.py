"""What every live scan source gives: scans as they arrive, and what it counted.

A source is named by a URL and opened by :func:`mast.live.sources.open_source`: a
scanner on TCP speaking one of the protocols of :mod:`mast.live.protocols`, or a
recorded run replayed. :meth:`Source.scans` yields each scan as it is received
(:class:`Received`) until told to stop; :class:`SourceStats` counts scans, malformed
telegrams, reconnections and the time without scans.
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from mast.core.scan import Scan

__all__ = ["Received", "Source", "SourceOptions", "SourceStats"]


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


class Source(ABC):
    """A stream of scans (see the module)."""

    def __init__(self, url: str, options: SourceOptions) -> None:
        self.url = url
        self.options = options
        self.stats = SourceStats()

    @abstractmethod
    def scans(self, stop: threading.Event, warn: Callable[[str], None]) -> Iterator[Received]:
        """Every scan as it is received, until ``stop`` is set or the stream ends."""
