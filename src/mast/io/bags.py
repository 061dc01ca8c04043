"""``sensor_msgs/LaserScan`` sequences in ROS 1 and ROS 2 bags, through rosbags.

ROS 1 bags are single ``.bag`` files (recognised by their ``#ROSBAG V2.0``
magic whatever their name); ROS 2 bags are folders with a ``metadata.yaml``
and sqlite3 (``.db3``) or MCAP storage. No ROS installation is needed.

Opening a bag, choosing a topic, and reading its messages one at a time with damaged
ones skipped and named are written once here for every message type
(:func:`_read_messages`); :mod:`mast.io.pointclouds` reads ``PointCloud2`` through them.
"""

from __future__ import annotations

import functools
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any, Literal, TypeVar

from mast import limits
from mast.core.scan import Scan
from mast.errors import InputError, OutputError, quoted
from mast.io.atomic import atomic_path
from mast.limits import read_bounded

__all__ = [
    "BagKind",
    "bag_kind",
    "laserscan_topic",
    "list_topics",
    "read_laserscans",
    "write_laserscans",
]

LASERSCAN = "sensor_msgs/msg/LaserScan"
_T = TypeVar("_T")
#: Turns one deserialised message (its index in the topic, from 1) into a record, or
#: raises :class:`InputError` saying what is wrong with it.
_Convert = Callable[[Any, Path, int], _T]
BagKind = Literal["rosbag1", "sqlite3", "mcap"]
_ROS1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
#: Chunk size of the ROS 1 bags MAST writes (rosbag record's default, 768 KiB).
ROS1_CHUNK_BYTES = 768 * 1024


def bag_kind(path: str | Path) -> Literal["rosbag1", "rosbag2"]:
    """Tell a ROS 1 bag file from a ROS 2 bag folder, or raise :class:`InputError`."""
    p = Path(path)
    if p.is_dir():
        if (p / "metadata.yaml").is_file():
            return "rosbag2"
        raise InputError("folder is not a ROS 2 bag (no metadata.yaml in it)", path=p)
    if not p.exists():
        raise InputError("bag not found", path=p)
    if not p.is_file():
        # A bag is read by seeking to its index: a pipe or a device cannot be one.
        raise InputError(
            "not a regular file (a pipe or a device); a bag must be a file or a folder", path=p
        )
    try:
        with p.open("rb") as fh:
            head = fh.read(len(_ROS1_MAGIC))
    except OSError as err:
        raise InputError(f"cannot read bag: {err.strerror}", path=p) from None
    if head == _ROS1_MAGIC:
        return "rosbag1"
    if p.suffix in {".db3", ".mcap"} and (p.parent / "metadata.yaml").is_file():
        return "rosbag2"
    if p.suffix == ".mcap" and head.startswith(_MCAP_MAGIC):
        return "rosbag2"  # a bare ROS 2 MCAP file (as ``mast live --record`` writes)
    if p.suffix in {".db3", ".mcap"}:
        raise InputError(
            "a ROS 2 bag is a folder with metadata.yaml (or an MCAP file); this storage file "
            "has none beside it",
            path=p,
        )
    raise InputError("not a ROS 1 bag (no '#ROSBAG V2.0' header) nor a ROS 2 bag folder", path=p)


@dataclass(frozen=True, slots=True)
class TopicInfo:
    topic: str
    msgtype: str
    count: int


def _open(path: Path) -> tuple[Any, Any, bool]:
    from rosbags.typesys import Stores, get_typestore

    kind = bag_kind(path)
    try:
        if kind == "rosbag1":
            from rosbags.rosbag1 import Reader as Reader1

            if path.is_dir():  # pragma: no cover - bag_kind only returns rosbag1 for files
                raise InputError("expected a ROS 1 bag file", path=path)
            reader: Any = Reader1(path)
            store = get_typestore(Stores.ROS1_NOETIC)
            ros1 = True
            reader.open()
            _bound_ros1_chunks(reader, path)
        else:
            from rosbags.rosbag2 import Reader as Reader2

            folder = path if path.is_dir() else path.parent
            bare = path.is_file() and not (folder / "metadata.yaml").is_file()
            if not bare:
                check_metadata(folder)
            _bound_mcap_chunks()
            reader = Reader2(path if bare else folder)
            store = get_typestore(Stores.ROS2_HUMBLE)
            ros1 = False
            reader.open()
    except InputError:
        raise
    except Exception as err:  # rosbags raises several kinds (ReaderError, AssertionError, ...)
        raise InputError(f"unreadable bag: {_describe(err)}", path=path) from None
    return reader, store, ros1


def _bound_ros1_chunks(reader: Any, path: Path) -> None:
    """Make every chunk of an opened ROS 1 reader decompress to at most the size its
    header declares (and :data:`mast.limits.MAX_BAG_CHUNK_BYTES`): rosbags would
    otherwise decompress a lying chunk whole, however large it grows."""
    from mast.io.ros1_tolerant import chunk_fields, decompress_chunk

    with path.open("rb") as fh:
        for pos, chunk in list(reader.chunks.items()):
            fields = chunk_fields(fh, pos)
            reader.chunks[pos] = chunk._replace(
                decompressor=functools.partial(decompress_chunk, fields, pos=pos)
            )


def _bound_mcap_chunks() -> None:
    """Make rosbags' MCAP reader decompress a chunk as a ROS 1 chunk is
    (:func:`mast.io.ros1_tolerant.inflate`): never past its declared size nor the limit."""
    from rosbags.rosbag2 import storage_mcap

    from mast.io.ros1_tolerant import inflate

    table = storage_mcap.DECOMPRESSORS
    table["zstd"] = lambda data, size: inflate("zstd", data, size, "MCAP chunk")
    table["lz4"] = lambda data, size: inflate("lz4", data, size, "MCAP chunk")


def check_metadata(folder: Path) -> None:
    """Check a ROS 2 bag's ``metadata.yaml`` before rosbags reads it.

    It must be a regular file of at most :data:`mast.limits.MAX_METADATA_BYTES`,
    plain YAML without anchors or aliases (none are written by ROS 2, and an
    alias is how a few bytes expand into an exhaustive document), nested no
    deeper than 32, and every storage file it names must lie inside the bag's
    folder (no absolute path, no ``..``).
    """
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError
    from ruamel.yaml.events import AliasEvent, CollectionEndEvent, CollectionStartEvent

    meta = folder / "metadata.yaml"
    raw = read_bounded(
        meta, limit=limits.MAX_METADATA_BYTES, what="metadata file", name="MAX_METADATA_BYTES"
    )
    try:
        text = raw.decode("utf-8")
        depth = 0
        for event in YAML(typ="safe").parse(text):
            if isinstance(event, AliasEvent) or getattr(event, "anchor", None):
                line = event.start_mark.line + 1 if event.start_mark else None
                raise InputError(
                    "uses a YAML anchor or alias; a ROS 2 bag's metadata has none",
                    path=meta,
                    line=line,
                )
            if isinstance(event, CollectionStartEvent):
                depth += 1
                if depth > 32:
                    raise InputError("nested more than 32 deep", path=meta)
            elif isinstance(event, CollectionEndEvent):
                depth -= 1
        doc = YAML(typ="safe").load(text)
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", path=meta) from None
    except YAMLError as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InputError(f"not valid YAML ({first})", path=meta) from None
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    names = info.get("relative_file_paths") if isinstance(info, dict) else None
    if not isinstance(names, list):
        raise InputError(
            "lacks rosbag2_bagfile_information.relative_file_paths; not a ROS 2 bag's metadata",
            path=meta,
        )
    for name in names:
        pure = PurePosixPath(str(name))
        if pure.is_absolute() or ".." in pure.parts or "\\" in str(name):
            raise InputError(
                f"names the storage file {quoted(str(name))} outside the bag's folder; "
                "only files inside it are read",
                path=meta,
            )


def _describe(err: BaseException) -> str:
    text = str(err).strip().splitlines()[0] if str(err).strip() else ""
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def list_topics(path: str | Path) -> list[TopicInfo]:
    """Topics of a bag with their message types and counts."""
    p = Path(path)
    reader, _, _ = _open(p)
    try:
        counts: dict[tuple[str, str], int] = {}
        for c in reader.connections:
            key = (c.topic, c.msgtype)
            counts[key] = counts.get(key, 0) + int(getattr(c, "msgcount", 0) or 0)
        return [TopicInfo(t, m, n) for (t, m), n in sorted(counts.items())]
    finally:
        reader.close()


def indexed_count(
    path: str | Path,
    topic: str | None,
    choose: Callable[[str | Path, str | None], str | None],
) -> int | None:
    """How many messages the topic ``choose(path, topic)`` picks holds, from the bag's
    index or metadata (no message is read); None when that is not known (a damaged bag,
    no such topic). For a progress bar's total, never a limit."""
    try:
        name = choose(path, topic)
        n = sum(t.count for t in list_topics(path) if t.topic == name)
    except InputError:
        return None
    return n or None


def read_laserscans(
    path: str | Path,
    *,
    topic: str | None = None,
    on_skip: Callable[[str], None] | None = None,
) -> Iterator[Scan]:
    """Yield the ``LaserScan`` messages of ``topic`` in time order, one at a time.

    With ``topic=None`` the bag must hold exactly one LaserScan topic. A topic
    that is missing, or not LaserScan, is an :class:`InputError` listing the
    bag's topics.

    Without ``on_skip`` any damage is an :class:`InputError`. With it, bags
    are read as they come from the field: a message that cannot be decoded is
    skipped and ``on_skip`` told which one and why; a bag cut short (or whose
    storage fails part-way) gives every scan before the damage, and
    ``on_skip`` is told where the reading stopped.
    """
    yield from _read_messages(
        Path(path), LASERSCAN, _to_scan, topic=topic, on_skip=on_skip, what="scans"
    )


def _read_messages(
    p: Path,
    msgtype: str,
    convert: _Convert[_T],
    *,
    topic: str | None,
    on_skip: Callable[[str], None] | None,
    what: str,
) -> Iterator[_T]:
    """The messages of type ``msgtype`` on ``topic`` (or the bag's one such topic), each
    made a record by ``convert``, as :func:`read_laserscans` describes; ``what`` names
    the records in a message to ``on_skip`` ("scans", "frames")."""
    try:
        reader, store, ros1 = _open(p)
    except InputError as err:
        if bag_kind(p) != "rosbag1":
            raise
        # A damaged or missing index (strict readers refuse it) need not mean lost messages.
        yield from _read_tolerant(p, topic, err, on_skip, msgtype, convert)
        return
    try:
        conns = list(reader.connections)
        name = _choose_topic([(c.topic, c.msgtype) for c in conns], topic, p, msgtype)
        chosen = [c for c in conns if c.topic == name]
        index = 0
        messages = reader.messages(connections=chosen)
        while True:
            try:
                conn, _t, raw = next(messages)
            except StopIteration:
                break
            except Exception as err:
                problem = f"unreadable bag after message {index} of {name}: {_describe(err)}"
                if on_skip is None:
                    raise InputError(problem, path=p) from None
                on_skip(f"{p}: {problem}; the {what} before it are kept")
                break
            index += 1
            record = _decode(store, ros1, conn.msgtype, raw, p, name, index, on_skip, convert)
            if record is not None:
                yield record
    finally:
        reader.close()


def _decode(
    store: Any,
    ros1: bool,
    msgtype: str,
    raw: bytes,
    path: Path,
    topic: str,
    index: int,
    on_skip: Callable[[str], None] | None,
    convert: _Convert[_T],
) -> _T | None:
    """One message as ``convert`` makes it; None (after telling ``on_skip``) when it
    cannot be decoded."""
    try:
        msg = store.deserialize_ros1(raw, msgtype) if ros1 else store.deserialize_cdr(raw, msgtype)
        return convert(msg, path, index)
    except Exception as err:
        problem = err.problem if isinstance(err, InputError) else _describe(err)
        if isinstance(err, InputError) and problem.startswith(f"message {index}: "):
            problem = problem[len(f"message {index}: ") :]
        text = f"message {index} of {topic} cannot be decoded: {problem}"
        if on_skip is None:
            raise InputError(text, path=path) from None
        on_skip(f"{path}: {text}; skipped")
        return None


def laserscan_topic(path: str | Path, topic: str | None = None) -> str | None:
    """The LaserScan topic :func:`read_laserscans` reads, or None when the bag's index
    is too damaged to list its topics (the tolerant reader may still read it)."""
    try:
        topics = list_topics(path)
    except InputError:
        return topic
    return _choose_topic([(t.topic, t.msgtype) for t in topics], topic, Path(path))


def _choose_topic(
    topics: list[tuple[str, str]], topic: str | None, path: Path, msgtype: str = LASERSCAN
) -> str:
    """The ``msgtype`` topic to read among ``(topic, msgtype)`` pairs, or an error listing
    them.

    With ``topic=None`` the bag must hold exactly one topic of ``msgtype``.
    """
    listing = ", ".join(f"{t} ({ty})" for t, ty in sorted(set(topics))) or "none"
    short = msgtype.rsplit("/", 1)[-1]
    if topic is None:
        names = sorted({t for t, ty in topics if ty == msgtype})
        if len(names) != 1:
            what = f"no {short} topic" if not names else f"several {short} topics"
            raise InputError(
                f"bag has {what}; choose one with --topic. Topics: {listing}", path=path
            )
        return names[0]
    types = {ty for t, ty in topics if t == topic}
    if not types:
        raise InputError(f"bag has no topic {topic!r}. Topics: {listing}", path=path)
    if types != {msgtype}:
        other = sorted(types - {msgtype})[0]
        raise InputError(f"topic {topic!r} carries {other}, not {msgtype}", path=path)
    return topic


def _read_tolerant(
    path: Path,
    topic: str | None,
    strict_error: InputError,
    on_skip: Callable[[str], None] | None,
    msgtype: str,
    convert: _Convert[_T],
) -> Iterator[_T]:
    """ROS 1 messages by walking the records (see :mod:`mast.io.ros1_tolerant`): a first
    walk finds the topics, a second yields the chosen one's records, one chunk at a
    time."""
    from rosbags.typesys import Stores, get_typestore

    from mast.io.ros1_tolerant import BagFormatError, iter_ros1_bag

    damage: list[str] = []

    def walk() -> Iterator[Any]:
        try:
            yield from iter_ros1_bag(path, on_damage=damage.append if on_skip else None)
        except BagFormatError as err:
            raise InputError(
                f"{strict_error.problem}; the records cannot be walked either ({err})", path=path
            ) from None

    # ROS 1 names types "pkg/Type"; rosbags and this module say "pkg/msg/Type".
    def type_of(m: Any) -> str:
        t = str(m.msgtype)
        return t if "/msg/" in t else t.replace("/", "/msg/", 1)

    topics = sorted({(m.topic, type_of(m)) for m in walk()})
    if not topics and damage:
        raise InputError(f"no intact message before the damage: {damage[0]}", path=path)
    topic = _choose_topic(topics, topic, path, msgtype)
    damage.clear()
    store = get_typestore(Stores.ROS1_NOETIC)
    index = 0
    for m in walk():
        if m.topic != topic:
            continue
        index += 1
        record = _decode(store, True, msgtype, m.data, path, topic, index, on_skip, convert)
        if record is not None:
            yield record
    if damage and on_skip is not None:
        on_skip(f"{path}: {damage[0]}; the {index} message(s) of {topic} before it are kept")


def _to_scan(msg: Any, path: Path, index: int) -> Scan:
    try:
        return Scan.from_message(msg)
    except InputError as err:
        raise InputError(f"message {index}: {err.problem}", path=path) from None


def write_laserscans(
    path: str | Path,
    scans: Iterable[Scan],
    *,
    kind: BagKind = "rosbag1",
    topic: str = "/scan",
    compression: Literal["none", "bz2", "lz4"] = "none",
) -> int:
    """Write scans as ``LaserScan`` messages; returns the number written.

    ``kind`` is ``"rosbag1"`` (a ``.bag`` file), ``"sqlite3"`` or ``"mcap"``
    (ROS 2 bag folders); ``compression`` (``"bz2"`` or ``"lz4"``) compresses a ROS 1
    bag's chunks. Beams must be evenly spaced, as a LaserScan has one
    ``angle_increment``. Each scan's ``stamp_ns`` is its bag time.
    """
    return _write_messages(
        Path(path),
        ((int(s.stamp_ns), s) for s in scans),
        LASERSCAN,
        laserscan_bytes,
        kind=kind,
        topic=topic,
        compression=compression,
    )


def _write_messages(
    p: Path,
    records: Iterable[tuple[int, _T]],
    msgtype: str,
    serialise: Callable[..., bytes],
    *,
    kind: BagKind,
    topic: str,
    compression: str = "none",
) -> int:
    """Write ``(bag time ns, record)`` pairs on ``topic`` as ``msgtype`` messages, each
    made by ``serialise(store, record, seq, ros1=...)``, whole or not at all; returns the
    number written."""
    from rosbags.typesys import Stores, get_typestore

    if p.exists():
        raise InputError("exists already; not overwriting a bag", path=p)
    ros1 = kind == "rosbag1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)

    def write(target: Path) -> int:
        return _write_into(
            target,
            records,
            msgtype,
            serialise,
            kind=kind,
            topic=topic,
            store=store,
            compression=compression,
        )

    # Whole or not at all: written under a temporary name, renamed when complete. A ROS 2
    # bag names its storage file after its folder, so it is staged in a temporary folder
    # under its own name.
    if ros1:
        with atomic_path(p) as tmp:
            n = write(tmp)
        return n
    try:
        staging = tempfile.TemporaryDirectory(dir=p.parent, prefix=f".{p.name}.")
        with staging as stage:
            staged = Path(stage) / p.name
            n = write(staged)
            os.replace(staged, p)
    except OSError as err:
        raise OutputError(f"cannot write: {err.strerror or err}", path=p) from None
    return n


def _write_into(
    path: Path,
    records: Iterable[tuple[int, _T]],
    msgtype: str,
    serialise: Callable[..., bytes],
    *,
    kind: BagKind,
    topic: str,
    store: Any,
    compression: str = "none",
) -> int:
    """:func:`_write_messages` into ``path`` (a temporary name its caller renames)."""
    if kind == "rosbag1":
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(path)
        # rosbag record's chunk size: a bag cut short loses at most one chunk of messages.
        writer.chunk_threshold = ROS1_CHUNK_BYTES
        if compression != "none":  # as rosbag record --bz2 / --lz4 writes
            writer.set_compression(Writer1.CompressionFormat[compression.upper()])
    else:
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=Writer2.VERSION_LATEST, storage_plugin=plugin)
    n = 0
    with writer:
        conn = writer.add_connection(topic, msgtype, typestore=store)
        for seq, (stamp_ns, record) in enumerate(records):
            writer.write(conn, stamp_ns, serialise(store, record, seq, ros1=kind == "rosbag1"))
            n += 1
    return n


def laserscan_bytes(store: Any, scan: Scan, seq: int, *, ros1: bool) -> bytes:
    """``scan`` as a serialised ``LaserScan`` (ROS 1, or ROS 2 CDR) of ``store``'s types."""
    try:
        f = scan.message_fields()
    except InputError as err:
        raise InputError(f"scan {seq}: {err.problem}") from None
    LaserScan = store.types[LASERSCAN]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    sec, nsec = f.pop("stamp")
    header_kw: dict[str, Any] = {
        "stamp": Time(sec=sec, nanosec=nsec),
        "frame_id": f.pop("frame_id"),
    }
    if ros1:
        header_kw["seq"] = seq
    msg = LaserScan(header=Header(**header_kw), **f)
    raw = store.serialize_ros1(msg, LASERSCAN) if ros1 else store.serialize_cdr(msg, LASERSCAN)
    return bytes(raw)
