"""Files from the field and from strangers: bounded reading, plausibility, untrusted content."""

from __future__ import annotations

import os
import re
import struct
import threading
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mast import limits
from mast.core.scan import Scan
from mast.errors import InputError, OutputError, quoted, shorten
from mast.io import read_laserscans, read_scan_csv, read_survey, write_laserscans
from mast.io.drift import read_drift
from mast.pipeline.segmentation import segment_scan

GOOD = """beacon,edge,easting,northing
B1,1,100.0,200.0
B1,2,100.3539,200.2
B1,3,100.9637,200.2
B1,4,101.0,200.0
"""
SECOND = """B2,1,110.0,200.0
B2,2,110.3539,200.2
B2,3,110.9637,200.2
B2,4,111.0,200.0
"""


def _scans(n: int = 4) -> list[Scan]:
    angles = np.linspace(-2.0, 2.0, 361)
    return [Scan(angles, 5.0 + 0.1 * np.cos(angles + k), stamp_ns=k * 40_000_000) for k in range(n)]


# --------------------------------------------------------------------------- bounded reading


def test_an_endless_device_is_refused_at_once() -> None:
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=r"/dev/zero, line 1: contains a NUL byte"):
        read_survey("/dev/zero")
    assert time.perf_counter() - t0 < 5.0


def test_a_pipe_is_read_only_up_to_the_limit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(limits, "MAX_TEXT_BYTES", 1 << 20)
    fifo = tmp_path / "survey.csv"
    os.mkfifo(fifo)
    stop = threading.Event()

    def feed() -> None:  # an endless writer of plausible lines
        try:
            with open(fifo, "wb") as fh:
                fh.write(GOOD.encode())
                row = b"B9,1,1.0,2.0\n" * 1000
                while not stop.is_set():
                    fh.write(row)
        except BrokenPipeError:  # the reader stopped at its limit
            return

    writer = threading.Thread(target=feed, daemon=True)
    writer.start()
    with pytest.raises(InputError, match=r"more than 1 MiB: larger than MAST reads"):
        read_survey(fifo)
    stop.set()


def test_a_large_regular_file_is_refused_before_it_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(limits, "MAX_TEXT_BYTES", 1000)
    p = tmp_path / "scan.csv"
    p.write_text("angle_rad,range_m\n" + "0.1,1.0\n" * 200)
    with pytest.raises(InputError, match=r"scan\.csv: 1.58 KiB: larger than the 1000 bytes"):
        read_scan_csv(p)


def test_a_long_line_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(limits, "MAX_LINE_BYTES", 4096)
    p = tmp_path / "beacons.csv"
    p.write_text(GOOD + "B2,1," + "1," * 5000 + "\n")
    with pytest.raises(InputError, match=r"beacons\.csv, line 6: line longer than 4 KiB"):
        read_survey(p)
    scan = tmp_path / "scan.csv"  # the streaming reader hands it to the whole-file one
    scan.write_text("angle_rad,range_m\n0.1,1.0\n" + "0.2," + "9" * 5000 + "\n")
    with pytest.raises(InputError, match=r"scan\.csv, line 3: line longer than 4 KiB"):
        read_scan_csv(scan)


def test_a_scan_of_too_many_beams_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(limits, "MAX_BEAMS", 100)
    p = tmp_path / "scan.csv"
    p.write_text("angle_rad,range_m\n" + "".join(f"{k * 1e-3},1.0\n" for k in range(150)))
    with pytest.raises(InputError, match=r"line 102: more than 100 beams"):
        read_scan_csv(p)
    with pytest.raises(InputError, match=r"scan has 150 beams, more than the 100"):
        Scan(np.linspace(0, 1, 150), np.ones(150))


def test_segmentation_memory_is_linear_in_the_beams() -> None:
    n = 200_000
    a = np.linspace(-2.3, 2.3, n)
    r = 5 + 0.5 * np.sin(7 * a) + np.random.default_rng(0).normal(0, 0.01, n)
    tracemalloc.start()
    try:
        segment_scan(Scan(a, r))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # 128 candidate pieces a beam would be 1 KiB a beam and more; the blocked partition
    # holds a few arrays of the beams and one block of candidates.
    assert peak / n < 400


# --------------------------------------------------------------------------- bags


def test_a_bz2_chunk_inflating_past_its_declared_size_is_refused(tmp_path: Path) -> None:
    from mast.bench.fuzz.mutations import bz2_bomb_bag

    bomb = tmp_path / "bomb.bag"
    bz2_bomb_bag(bomb, 64 << 20)  # declares 1 KiB
    tracemalloc.start()
    try:
        with pytest.raises(InputError, match="decompresses beyond its declared size"):
            list(read_laserscans(bomb))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 8 << 20


@pytest.mark.parametrize(
    ("size", "message"), [(64, "beyond its declared size"), (2**32 - 1, "beyond the limit")]
)
def test_a_lying_chunk_size_is_refused_by_the_indexed_reader(
    tmp_path: Path, size: int, message: str
) -> None:
    bag = tmp_path / "bz.bag"
    write_laserscans(bag, _scans(), compression="bz2")
    assert len(list(read_laserscans(bag))) == 4
    data = bag.read_bytes()
    at = data.find(b"size=", 13)
    bag.write_bytes(data[: at + 5] + struct.pack("<I", size) + data[at + 9 :])
    with pytest.raises(InputError, match=message):
        list(read_laserscans(bag))


def test_a_pipe_is_not_a_bag(tmp_path: Path) -> None:
    fifo = tmp_path / "run.bag"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        list(read_laserscans(fifo))


def test_damaged_angle_fields_are_refused(tmp_path: Path) -> None:
    from rosbags.typesys import Stores, get_typestore

    from mast.io.bags import LASERSCAN, _to_scan

    store = get_typestore(Stores.ROS2_HUMBLE)
    bag = tmp_path / "run"
    write_laserscans(bag, _scans(1), kind="mcap")
    from rosbags.rosbag2 import Reader

    with Reader(bag) as reader:
        _, _, raw = next(iter(reader.messages()))
    msg = store.deserialize_cdr(raw, LASERSCAN)
    _to_scan(msg, bag, 1)  # as written: consistent
    msg.angle_increment *= 1.01
    with pytest.raises(InputError, match=r"misses angle_max .* the message is damaged"):
        _to_scan(msg, bag, 1)


_ALIAS_BOMB = (
    'a: &a ["x","x","x","x","x","x","x","x","x"]\n'
    "b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n"
    "c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\n"
    "rosbag2_bagfile_information: *c\n"
)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: _ALIAS_BOMB, "uses a YAML anchor or alias"),
        (lambda t: t.replace("- run_0", "- ../../etc/run_0", 1), "outside the bag's folder"),
        (lambda t: t.replace("- run_0", "- /tmp/run_0", 1), "outside the bag's folder"),
        (lambda t: t + "# " + "x" * (2 << 20) + "\n", "larger than the 1 MiB"),
        (lambda t: "[[[[ : {", "not valid YAML"),
        (lambda t: "- a\n- b\n", "not a ROS 2 bag's metadata"),
    ],
)
def test_ros2_metadata_is_read_safely(
    tmp_path: Path, edit: Callable[[str], str], message: str
) -> None:
    bag = tmp_path / "run"
    write_laserscans(bag, _scans(), kind="mcap")
    meta = bag / "metadata.yaml"
    assert "- run.mcap" in meta.read_text()
    text = meta.read_text().replace("- run.mcap", "- run_0.mcap")
    (bag / "run.mcap").rename(bag / "run_0.mcap")
    meta.write_text(text)
    assert len(list(read_laserscans(bag))) == 4  # renamed consistently: still a bag
    meta.write_text(edit(text))
    with pytest.raises(InputError, match=message):
        list(read_laserscans(bag))


def test_a_bag_is_written_whole_or_not_at_all(tmp_path: Path) -> None:
    def failing() -> object:
        yield from _scans(2)
        raise OSError(28, "No space left on device")

    for kind in ("rosbag1", "mcap"):
        target = tmp_path / f"run_{kind}"
        with pytest.raises(OutputError, match="No space left"):
            write_laserscans(target, failing(), kind=kind)  # type: ignore[arg-type]
        assert not target.exists()
        assert [p.name for p in tmp_path.iterdir()] == []


# --------------------------------------------------------------------------- plausibility


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (
            GOOD.replace("100.3539", "1e300"),
            r"line 3: column 'easting': 1e\+300 m is beyond ±1e\+08 m",
        ),
        (GOOD.replace("100.3539,200.2", "100.0,200.0"), r"line 3: beacon 'B1': edges 1 and 2 are"),
        (
            "beacon,edge,easting,northing\nB1,1,100.0,200.0\nB1,2,101.0,200.0\n"
            "B1,3,100.5,200.5\nB1,4,100.5,199.5\n",
            r"line 5: beacon 'B1' is folded on itself",
        ),
        (GOOD + SECOND + GOOD.split("\n", 1)[1], r"line 10: beacon id 'B1' is used twice"),
        (
            GOOD + SECOND.replace("110.", "101.").replace("111.0", "102.0"),
            r"line 6: beacons 'B1' and 'B2' share an edge point",
        ),
    ],
)
def test_implausible_surveys_are_named(
    write_text: Callable[..., Path], content: str, message: str
) -> None:
    with pytest.raises(InputError, match=message):
        read_survey(write_text("b.csv", content), rules=None)


def test_a_survey_in_millimetres_says_so_through_the_mast_process(tmp_path: Path) -> None:
    """The paper's hat with its coordinates in millimetres: one line naming the file, the
    line and the panel, asking whether the survey is in millimetres; exit 2."""
    from tests._cli import run_mast_text

    design = np.array([[0.0, 0.0], [0.3, 0.16], [0.9, 0.16], [1.08, 0.06]])
    rows = ["beacon,edge,easting,northing"]
    for b, shift in (("B1", 0.0), ("B2", 10.0)):
        for k, (e, n) in enumerate(1000.0 * (design + [25_000.0 + shift, 71_000.0]), 1):
            rows.append(f"{b},{k},{e:.1f},{n:.1f}")
    survey = tmp_path / "mm.csv"
    survey.write_text("\n".join(rows) + "\n")
    scan = tmp_path / "scan.csv"
    scan.write_text("angle_rad,range_m\n0.0,5.0\n0.01,5.0\n0.02,5.0\n")
    done = run_mast_text("locate", str(scan), "-b", str(survey))
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert f"{survey}, line 3: beacon 'B1': panel P1 (edges 1-2) is 340 m long" in line
    assert "is the survey in millimetres?" in line


def test_a_survey_of_too_many_beacons_is_named(
    write_text: Callable[..., Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(limits, "MAX_BEACONS", 1)
    with pytest.raises(InputError, match=r"line 6: more than 1 beacons"):
        read_survey(write_text("b.csv", GOOD + SECOND))


def test_user_values_are_cut_in_messages() -> None:
    assert quoted("x" * 10) == "'xxxxxxxxxx'"
    long = quoted("y" * 100_000)
    assert len(long) < 100
    assert long.endswith("(100000 characters)")
    line = shorten("bad value " + "z" * 100_000 + "\x0b\nend")
    assert len(line) < 200
    assert "\n" not in line
    assert "\x0b" not in line


@pytest.mark.parametrize("option", ["--near", "--format", "--scanner"])
def test_a_huge_command_line_value_is_echoed_cut(tmp_path: Path, option: str) -> None:
    from tests._cli import run_mast_text

    survey = tmp_path / "b.csv"
    survey.write_text(GOOD + SECOND)
    scan = tmp_path / "s.csv"
    scan.write_text("angle_rad,range_m\n0.0,1.5\n0.1,1.6\n")
    done = run_mast_text("locate", str(scan), "-b", str(survey), option, "x" * 100_000)
    assert done.returncode == 2
    assert len(done.stderr) < 600
    assert re.search(r"\(1000\d\d characters\)", done.stderr)
    assert "Traceback" not in done.stderr


def test_a_drift_far_too_long_is_refused(write_text: Callable[..., Path]) -> None:
    text = "wall,vertex,easting,northing\nL,1,0,0\nL,2,500000,0\nR,1,0,5\nR,2,500000,5\n"
    with pytest.raises(InputError, match=r"walls 1000 km long in all"):
        read_drift(write_text("d.csv", text))


# --------------------------------------------------------------------------- fuzzing

_FILES = {"survey": GOOD + SECOND, "scan": "angle_rad,range_m\n0.0,1.5\n0.1,1.6\n0.2,\n"}


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    which=st.sampled_from(["survey", "scan", "drift"]),
    data=st.one_of(
        st.binary(max_size=2000),
        st.tuples(st.sampled_from(list(_FILES.values())), st.integers(0, 400), st.integers(0, 7)),
    ),
)
def test_any_bytes_are_read_or_refused_with_a_named_error(
    tmp_path: Path, which: str, data: bytes | tuple[str, int, int]
) -> None:
    if isinstance(data, tuple):  # a valid file with one bit flipped
        text, at, bit = data
        raw = bytearray(text.encode())
        raw[at % len(raw)] ^= 1 << bit
        data = bytes(raw)
    p = tmp_path / f"fuzz_{which}.csv"
    p.write_bytes(data)
    reader = {"survey": read_survey, "scan": read_scan_csv, "drift": read_drift}[which]
    try:
        reader(p)
    except InputError as err:
        message = str(err)
    else:
        return
    assert str(p) in message
    assert "\n" not in shorten(message)


def test_the_fuzzing_campaign_finds_nothing(tmp_path: Path) -> None:
    """A short run of ``mast bench fuzz``: every case in a child under memory, file-size
    and time limits; no traceback, no undocumented status, no bound exceeded, no fix that
    differs from the undamaged file's, no half-written output."""
    from mast.bench.fuzz import run_fuzz

    lines: list[str] = []
    summary = run_fuzz(inputs=120, seed=11, echo=lines.append, keep_failures=tmp_path / "kept")
    assert summary.cases == 120
    assert len(summary.by_family) >= 9
    assert summary.failed == 0, "\n".join(lines)
    assert summary.peak_bytes < limits.MAX_TEXT_BYTES * 8
    assert not (tmp_path / "kept").exists()


def test_a_fuzz_case_is_charged_only_its_own_memory(tmp_path: Path) -> None:
    """A case runs in a child forked from a warmed-up process (late in the test suite, a
    large one): its peak is what it took itself, not the parent's pages it was forked
    with, and a case that does take memory is charged it."""
    from mast.bench.fuzz import FuzzCase
    from mast.bench.fuzz.children import run_case, vm_bytes

    ballast = np.ones(400 * 2**20 // 8)  # a parent holding 400 MiB, touched
    limit = vm_bytes("VmSize") + (2 << 30)
    status, _, peak, inherited, out, _ = run_case(
        FuzzCase("t", "help", ("--help",), None), tmp_path / "a", limit, 60.0
    )
    assert status == 0
    assert "locate" in out
    assert inherited > 400 * 2**20 > 4 * peak
    del ballast
    # A case that does take memory is charged it: a 200 000-beam scan (a room seen at
    # 0.0018 deg), whose points, segments and hypotheses take tens of MiB more than the
    # same room at 1 000 beams (imports and library pages alike in both).
    sim = tmp_path / "sim"
    status, *_ = run_case(FuzzCase("t", "sim", ("simulate", "--out", str(sim)), None),
                      tmp_path / "b", limit, 60.0)  # fmt: skip
    assert status == 0
    survey = next(sim.rglob("beacons.csv"))
    peaks = []
    for n in (1_000, 200_000):
        scan = tmp_path / f"room{n}.csv"
        angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
        np.savetxt(scan, np.c_[angles, np.full(n, 5.0)], delimiter=",", fmt="%.7f",
                   header="angle_rad,range_m", comments="")  # fmt: skip
        status, _, peak, _, _, _ = run_case(
            FuzzCase("t", "room", ("locate", str(scan), "-b", str(survey)), None),
            tmp_path / f"c{n}", limit, 60.0,
        )  # fmt: skip
        assert status == 3  # a round room: no beacon, an honest no-fix
        peaks.append(peak)
    assert peaks[1] - peaks[0] > 20 * 2**20, peaks


def test_the_parent_gives_its_free_heap_back_before_a_fork() -> None:
    """Freed C-heap blocks stay resident (and a forked child would reuse them unseen)
    until malloc_trim gives them back: then the resident size drops."""
    import ctypes

    from mast.bench.fuzz.children import trim_heap, vm_bytes

    libc = ctypes.CDLL(None)
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    blocks = [libc.malloc(4096) for _ in range(40_000)]  # 160 MiB in small blocks
    for b in blocks:
        ctypes.memset(b, 1, 4096)
    keep = libc.malloc(64)  # above them: the heap's top cannot just shrink
    for b in blocks:
        libc.free(b)
    held = vm_bytes("VmRSS")
    assert trim_heap()
    assert vm_bytes("VmRSS") < held - 100 * 2**20
    libc.free(keep)


def test_no_file_content_is_evaluated() -> None:
    """No pickle, eval, exec or unsafe YAML loader anywhere in MAST's source."""
    root = Path(__file__).resolve().parents[2] / "src" / "mast"
    banned = re.compile(r"\bimport pickle\b|\bpickle\.|\beval\(|\bexec\(|typ=.unsafe|yaml\.load\(")
    found = [
        f"{p.relative_to(root)}:{k}"
        for p in root.rglob("*.py")
        for k, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if banned.search(line) and not line.lstrip().startswith("#")
    ]
    assert found == []


@pytest.mark.parametrize("kind", ["bz2", "lz4", "zstd"])
def test_every_chunk_compression_stops_at_its_declared_size(kind: str) -> None:
    """ROS 1 (bz2, lz4) and MCAP (lz4, zstd) chunks share one bounded decompression."""
    import bz2

    import lz4.frame  # type: ignore[import-untyped]
    from backports import zstd

    from mast.io.ros1_tolerant import BagFormatError, inflate

    raw = b"\x00" * (8 << 20)
    packed = {"bz2": bz2.compress, "lz4": lz4.frame.compress, "zstd": zstd.compress}[kind](raw)
    assert inflate(kind, packed, len(raw), "chunk") == raw
    with pytest.raises(BagFormatError, match="chunk decompresses beyond its declared size"):
        inflate(kind, packed, 1024, "chunk")
    with pytest.raises(BagFormatError, match="declares 4294967295 bytes, beyond the limit"):
        inflate(kind, packed, 2**32 - 1, "chunk")
