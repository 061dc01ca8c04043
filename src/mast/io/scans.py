"""One door to every recorded scan: :func:`open_scans` reads whatever a path is (a scan
CSV, a folder of scan CSVs, a ROS 1 bag, a ROS 2 bag folder or an MCAP file), one scan
at a time, for ``mast locate``, ``track``, ``live`` (``replay://``), ``emulate`` and the
benchmarks alike.

Each format is one :class:`ScanFormat` in :data:`FORMATS`, tried in order: which paths
it claims, the topic its scans come from, and its reader (the reading itself lives in
the format's own module: :mod:`mast.io.scan_csv`, :mod:`mast.io.bags`). A new format
is a reader module and one entry here; every command reads it at once.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass, replace
from pathlib import Path

from mast.core.scan import Scan
from mast.errors import InputError

__all__ = [
    "DEFAULT_CSV_HZ",
    "FORMATS",
    "ScanFormat",
    "ScanReading",
    "ScanRun",
    "open_scans",
    "scan_count",
    "scan_format",
]

#: Scans of a folder of scan CSVs are stamped this many a second apart, from 0.
DEFAULT_CSV_HZ = 25.0


@dataclass(frozen=True, slots=True)
class ScanReading:
    """How a run is read: the topic (a bag with several), the scan CSVs' rate, range
    limits over the recorded ones, and who is told of each message a damaged bag skips
    (without one, damage is an error)."""

    topic: str | None = None
    csv_hz: float = DEFAULT_CSV_HZ
    range_min_m: float | None = None
    range_max_m: float | None = None
    on_skip: Callable[[str], None] | None = None


def _no_topic(_path: Path, _topic: str | None) -> None:
    return None


def _one(_path: Path, _topic: str | None) -> int:
    return 1


@dataclass(frozen=True, slots=True)
class ScanFormat:
    """A kind of scan file: its name, whether it claims a path, whether it holds a run
    (many scans) or one scan, the topic a path's scans come from, its reader, and how
    many scans a path holds without reading them (None when that is not known: a
    progress bar's total, never a limit)."""

    name: str
    claims: Callable[[Path], bool]
    sequence: bool
    topic_of: Callable[[Path, str | None], str | None]
    read: Callable[[Path, ScanReading], Generator[Scan, None, None]]
    count: Callable[[Path, str | None], int | None] = _one


def _is_scan_csv(path: Path) -> bool:
    """Whether ``path``'s header (its first non-blank line) names the columns a scan CSV
    has (``angle_rad`` and ``range_m``, in any order and case, as :func:`read_scan_csv`
    takes them)."""
    try:
        with path.open("rb") as fh:
            head = fh.read(4096)
    except OSError:
        return False
    text = head.lstrip(b"\xef\xbb\xbf").decode("utf-8", errors="replace")
    first = next((line for line in text.splitlines() if line.strip()), "")
    columns = {c.strip().strip('"').lower() for c in first.split(",")}
    return {"angle_rad", "range_m"} <= columns


def _csv_claims(path: Path) -> bool:
    return path.is_file() and path.suffix.lower() in {".csv", ".txt"}


def _csv_read(path: Path, how: ScanReading) -> Generator[Scan, None, None]:
    from mast.io.scan_csv import read_scan_csv

    yield read_scan_csv(
        path,
        range_min_m=how.range_min_m or 0.0,
        range_max_m=how.range_max_m or math.inf,
    )


def _scan_csvs(folder: Path) -> list[Path]:
    """The scan CSVs in ``folder`` (``*.csv`` in any case), in name order."""
    return sorted(
        p
        for p in folder.iterdir()
        if p.suffix.lower() == ".csv" and p.is_file() and _is_scan_csv(p)
    )


def _folder_claims(path: Path) -> bool:
    if not path.is_dir() or (path / "metadata.yaml").is_file():
        return False
    if not _scan_csvs(path):
        raise InputError(
            "folder holds no scan CSV (angle_rad,range_m) and is not a ROS 2 bag "
            "(no metadata.yaml in it)",
            path=path,
        )
    return True


def _folder_read(path: Path, how: ScanReading) -> Generator[Scan, None, None]:
    from mast.io.scan_csv import read_scan_csv

    files = _scan_csvs(path)
    step_ns = round(1e9 / how.csv_hz)
    for k, f in enumerate(files):
        scan = replace(read_scan_csv(f), stamp_ns=k * step_ns)
        yield scan.with_range_limits(how.range_min_m, how.range_max_m)


def _folder_count(path: Path, _topic: str | None) -> int:
    return len(_scan_csvs(path))


def _bag_claims(path: Path) -> bool:
    from mast.io.bags import bag_kind

    bag_kind(path)  # a clear error for a path that is no bag either
    return True


def _bag_topic(path: Path, topic: str | None) -> str | None:
    from mast.io.bags import laserscan_topic

    return laserscan_topic(path, topic)


def _bag_count(path: Path, topic: str | None) -> int | None:
    """The LaserScan messages of the topic read, from the bag's index or metadata (no
    message is read); None for a bag whose index does not say (a damaged one)."""
    from mast.io.bags import indexed_count, laserscan_topic

    return indexed_count(path, topic, laserscan_topic)


def _bag_read(path: Path, how: ScanReading) -> Generator[Scan, None, None]:
    from mast.io.bags import read_laserscans

    for scan in read_laserscans(path, topic=how.topic, on_skip=how.on_skip):
        yield scan.with_range_limits(how.range_min_m, how.range_max_m)


#: Every format MAST reads scans from, tried in this order (the last, bags, claims what
#: is left and says why a path is none of them).
FORMATS: tuple[ScanFormat, ...] = (
    ScanFormat("scan CSV", _csv_claims, False, _no_topic, _csv_read),
    ScanFormat("folder of scan CSVs", _folder_claims, True, _no_topic, _folder_read, _folder_count),
    ScanFormat(
        "ROS bag (ROS 1, ROS 2 folder or MCAP)",
        _bag_claims,
        True,
        _bag_topic,
        _bag_read,
        _bag_count,
    ),
)


def scan_format(path: Path, *, what: str = "scan file") -> ScanFormat:
    """The format of the scans at ``path``; a path that is none is an :class:`InputError`
    naming it (``what`` a missing one was to be)."""
    if not path.exists():
        raise InputError(f"{what} not found", path=path)
    for fmt in FORMATS:
        if fmt.claims(path):
            return fmt
    raise InputError("no scan file MAST reads", path=path)  # pragma: no cover - bags claim


@dataclass(frozen=True, slots=True)
class ScanRun:
    """Recorded scans opened: their format, the scans, read one at a time as they are
    taken (a bag's are never all in memory), and the topic asked for."""

    path: Path
    format: ScanFormat
    scans: Generator[Scan, None, None]
    asked_topic: str | None = None

    @property
    def topic(self) -> str | None:
        """The topic the scans come from (a bag's; looked up when asked: it opens the
        bag)."""
        return self.format.topic_of(self.path, self.asked_topic)

    @property
    def count(self) -> int | None:
        """How many scans there are, from the bag's index or the folder's files (read
        when asked), or None when unknown (:func:`scan_count`)."""
        return self.format.count(self.path, self.asked_topic)


def open_scans(
    path: Path,
    *,
    topic: str | None = None,
    csv_hz: float = DEFAULT_CSV_HZ,
    range_min_m: float | None = None,
    range_max_m: float | None = None,
    on_skip: Callable[[str], None] | None = None,
    what: str = "scan file",
) -> ScanRun:
    """The scans at ``path``, whatever it holds (:data:`FORMATS`), with ``topic`` (a bag
    with several), ``csv_hz`` (a folder of scan CSVs), range limits over the recorded
    ones, and ``on_skip`` told of each message a damaged bag skips."""
    fmt = scan_format(path, what=what)
    how = ScanReading(topic, csv_hz, range_min_m, range_max_m, on_skip)
    return ScanRun(path, fmt, fmt.read(path, how), topic)


def scan_count(path: Path, *, topic: str | None = None) -> int | None:
    """How many scans ``path`` holds, without reading them: 1 for a scan CSV, the scan
    CSVs of a folder, a bag's LaserScan messages on ``topic`` from its index or
    metadata; None when that is not known. For a progress bar's total, never a limit:
    a damaged bag may give fewer."""
    fmt = scan_format(path)
    return fmt.count(path, topic)
