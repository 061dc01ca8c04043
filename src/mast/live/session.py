"""The live loop: scans from a source located as they arrive, the newest scan first.

Two threads. The reader takes every scan off the source as it arrives (and
into the recording, when there is one) and leaves it in a one-scan slot
(:class:`LatestSlot`); a scan still there when the next arrives is replaced and
counted as dropped, so that the queue never grows and a pose is never older
than the scan being located. The locator takes the slot's scan, locates it
with the previous fix as its prior (:class:`~mast.pipeline.locator.SequenceLocator`,
the same rule as ``mast locate`` on a bag), and hands the record on.

Each record is the ``locate`` record of a scan in a sequence (DESIGN.md, "A fix")
with: ``source``; ``scan`` (the scan's number in the stream, counting dropped
ones); ``stamp_ns`` (the scan's stamp); ``received_ns`` (host clock when its
last byte arrived); ``latency_ms`` (from then to the record being written);
``tracking`` (the previous fix was tried as the prior); ``track_lost`` (it was
tried and gave no fix, so the scan was located from scratch); ``dropped``
(scans replaced unlocated since the previous record); and ``gap_s`` on the first
scan after the scanner was lost.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from mast.core.beacon import Survey
from mast.core.heap import QuietCollector
from mast.core.scan import Scan
from mast.live.sources import FrameReplaySource, ReceivedFrame
from mast.live.stream import Received, Source
from mast.pipeline.locator import Fix, LocatorConfig, SequenceConfig, SequenceLocator
from mast.report.record import ReportInputs, fix_record

if TYPE_CHECKING:
    from mast.core.pose3d import Frame3D
    from mast.pipeline.locator3d import Fix3D

__all__ = ["LatestSlot", "LiveSummary", "Sink", "run_live", "run_live3d"]


class Sink(Protocol):
    """Something that takes every received scan and every record (a recording, a view)."""

    def scan(self, scan: Scan) -> None: ...

    def fix(self, scan: Scan, fix: Fix, record: dict[str, Any]) -> None: ...


_Item = TypeVar("_Item", Received, ReceivedFrame)


class LatestSlot(Generic[_Item]):
    """A one-item hand-over between threads where the newest item wins (a scan, or a 3D
    lidar's frame)."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._item: tuple[int, _Item] | None = None
        self._closed = False
        self._dropped_since_take = 0
        self.error: BaseException | None = None
        self.dropped = 0

    def put(self, index: int, item: _Item) -> None:
        """Hand over ``item``, replacing one not taken yet: that one is counted as dropped,
        and a gap it reported goes on with the item that replaced it (the first record
        after an outage says so even when a busy locator never saw its first scan)."""
        with self._cond:
            if self._item is not None:
                self.dropped += 1
                self._dropped_since_take += 1
                gap = self._item[1].gap_s
                if gap is not None:
                    item = replace(item, gap_s=gap + (item.gap_s or 0.0))
            self._item = (index, item)
            self._cond.notify()

    def close(self, error: BaseException | None = None) -> None:
        with self._cond:
            self._closed = True
            self.error = error
            self._cond.notify()

    def take(self, stop: threading.Event | None = None) -> tuple[int, _Item, int] | None:
        """The newest item and how many were replaced since the last take, waiting for
        one; None once closed and empty, or when ``stop`` is set."""
        with self._cond:
            while self._item is None and not self._closed:
                if stop is not None and stop.is_set():
                    return None
                self._cond.wait(0.1)  # short waits: Ctrl-C and stop requests are seen at once
            if self._item is None:
                return None
            (index, item), self._item = self._item, None
            dropped, self._dropped_since_take = self._dropped_since_take, 0
            return index, item, dropped


@dataclass(slots=True)
class LiveSummary:
    """How a live run went."""

    received: int = 0
    located: int = 0
    fixed: int = 0
    dropped: int = 0
    malformed: int = 0
    reconnects: int = 0
    gap_s: float = 0.0
    track_lost: int = 0
    elapsed_s: float = 0.0
    pipe_closed: bool = False
    interrupted: bool = False


def _start_reader(
    items: Iterable[_Item],
    slot: LatestSlot[_Item],
    stop: threading.Event,
    max_scans: int | None,
    each: Callable[[_Item], None] | None = None,
) -> threading.Thread:
    """The reader thread, started: every item off the source into ``slot`` (``each``
    called on it first), until the source ends, ``max_scans`` are in or ``stop`` is set
    by the source; its error, if any, handed to the locating thread through the slot."""

    def read() -> None:
        error: BaseException | None = None
        try:
            for index, received in enumerate(items):
                if each is not None:
                    each(received)
                slot.put(index, received)
                if max_scans is not None and index + 1 >= max_scans:
                    break
        except BaseException as err:  # handed to the locating thread
            error = err
        finally:
            stop.set()
            slot.close(error)

    reader = threading.Thread(target=read, name="mast-live-reader", daemon=True)
    reader.start()
    return reader


def run_live(
    source: Source,
    survey: Survey,
    *,
    emit: Callable[[dict[str, Any]], None],
    config: LocatorConfig | None = None,
    sequence: SequenceConfig | None = None,
    inputs: ReportInputs | None = None,
    sinks: tuple[Sink, ...] = (),
    max_scans: int | None = None,
    warn: Callable[[str], None] = lambda _text: None,
    before_step: Callable[[int, SequenceLocator], None] | None = None,
    interrupt: threading.Event | None = None,
) -> LiveSummary:
    """Locate ``source``'s scans as they arrive until it ends, ``max_scans`` have been
    received, ``emit`` finds its reader gone (``BrokenPipeError``, ``pipe_closed``) or
    Ctrl-C is pressed (``interrupted``).

    ``emit`` gets each record (see the module); every sink gets every received
    scan (from the reader thread) and every record. ``before_step`` is called
    with each scan's number and the tracker before it is located (the benchmark
    injects a wrong prior with it). Setting ``interrupt`` (from a signal handler)
    ends the run between two scans, as Ctrl-C does anywhere. An error of the source
    (a scanner that cannot be reached) is raised here, after the thread has stopped.
    """
    summary = LiveSummary()
    tracker = SequenceLocator(survey, config=config, sequence=sequence or SequenceConfig())
    slot: LatestSlot[Received] = LatestSlot()
    stop = threading.Event()
    inputs = inputs or ReportInputs()

    def shown(received: Received) -> None:
        for sink in sinks:
            sink.scan(received.scan)

    t0 = time.perf_counter()
    reader = _start_reader(source.scans(stop, warn), slot, stop, max_scans, shown)
    # The survey's index, kernels and session, alive once the first scan is located,
    # frozen: the collector's full passes over them were the largest latencies.
    try:
        with QuietCollector() as heap:
            while (item := slot.take(interrupt)) is not None:
                if interrupt is not None and interrupt.is_set():
                    break
                index, received, dropped = item
                scan = received.scan
                if before_step is not None:
                    before_step(index, tracker)
                step = tracker.step(scan)
                now = replace(inputs, computed_utc=datetime.now(UTC))
                record = fix_record(step.fix, source=source.url, index=index, scan=scan, inputs=now)
                record.update(
                    received_ns=received.received_ns,
                    tracking=step.tracked,
                    track_lost=step.track_lost,
                    dropped=dropped,
                )
                if received.gap_s is not None:
                    record["gap_s"] = round(received.gap_s, 3)
                record["latency_ms"] = round((time.perf_counter() - received.received_s) * 1e3, 3)
                summary.located += 1
                summary.fixed += step.fix.ok
                summary.track_lost += step.track_lost
                for sink in sinks:  # first: a pose on the robot's bus is the urgent output
                    sink.fix(scan, step.fix, record)
                try:
                    emit(record)
                except BrokenPipeError:
                    summary.pipe_closed = True
                    break
                heap.step()
    except KeyboardInterrupt:
        summary.interrupted = True
    finally:
        if interrupt is not None and interrupt.is_set():
            summary.interrupted = True
        stop.set()
        reader.join(5.0)
        stats = source.stats
        summary.received = stats.scans
        summary.dropped = slot.dropped
        summary.malformed = stats.malformed
        summary.reconnects = stats.reconnects
        summary.gap_s = stats.gap_s
        summary.elapsed_s = time.perf_counter() - t0
    if slot.error is not None and not (summary.pipe_closed or summary.interrupted):
        raise slot.error
    return summary


def run_live3d(
    source: FrameReplaySource,
    *,
    locate: Callable[[Frame3D], Fix3D],
    record: Callable[[Fix3D, int, Frame3D, ReportInputs], dict[str, Any]],
    emit: Callable[[dict[str, Any]], None],
    inputs: ReportInputs | None = None,
    max_scans: int | None = None,
    warn: Callable[[str], None] = lambda _text: None,
    interrupt: threading.Event | None = None,
) -> LiveSummary:
    """:func:`run_live` for a 3D lidar's frames: each frame located on its own by
    ``locate`` (:func:`mast.pipeline.locator3d.locate3d` with its settings: the 2D
    prior does not apply to a tilted sensor, so ``tracking`` and ``track_lost`` are
    always false), its record made by ``record`` (the 3D record) with the live keys
    added as in 2D, the newest frame first when locating falls behind."""
    summary = LiveSummary()
    slot: LatestSlot[ReceivedFrame] = LatestSlot()
    stop = threading.Event()
    inputs = inputs or ReportInputs()

    t0 = time.perf_counter()
    reader = _start_reader(source.frames(stop, warn), slot, stop, max_scans)
    try:
        with QuietCollector() as heap:
            while (item := slot.take(interrupt)) is not None:
                if interrupt is not None and interrupt.is_set():
                    break
                index, received, dropped = item
                fix = locate(received.frame)
                now = replace(inputs, computed_utc=datetime.now(UTC))
                rec = record(fix, index, received.frame, now)
                rec.update(
                    received_ns=received.received_ns,
                    tracking=False,
                    track_lost=False,
                    dropped=dropped,
                )
                rec["latency_ms"] = round((time.perf_counter() - received.received_s) * 1e3, 3)
                summary.located += 1
                summary.fixed += fix.ok
                try:
                    emit(rec)
                except BrokenPipeError:
                    summary.pipe_closed = True
                    break
                heap.step()
    except KeyboardInterrupt:
        summary.interrupted = True
    finally:
        if interrupt is not None and interrupt.is_set():
            summary.interrupted = True
        stop.set()
        reader.join(5.0)
        summary.received = source.stats.scans
        summary.dropped = slot.dropped
        summary.malformed = source.stats.malformed
        summary.elapsed_s = time.perf_counter() - t0
    if slot.error is not None and not (summary.pipe_closed or summary.interrupted):
        raise slot.error
    return summary
