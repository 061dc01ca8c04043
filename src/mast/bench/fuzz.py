"""Fuzzing benchmark: damaged and crafted inputs through every reader and output path.

Builds valid seed files (a survey, scan CSVs, ROS 1 bags plain and bz2, ROS 2
sqlite3 and MCAP bags, a drift CSV and DXF), then runs ``mast`` on damaged
copies of them (random bytes, truncations, bit flips, spliced ranges, values
no survey holds, huge lines, lying chunk sizes, decompression bombs, YAML
alias bombs, file names escaping the bag) and on hostile output paths (a
missing or read-only place, a file in the way, an unknown suffix, the input
itself, a name too long, a disk that fills part-way, a closed pipe).

Each case runs the real command line (:func:`mast.cli.main`) in a
forked child of one warmed-up process, under an address-space limit and a
file-size limit (the disk that fills), with a time limit. Per case it
records the exit status, the standard error, the child's peak resident
memory above what it inherited at the fork (``wait4``'s peak less the
resident size the child starts with, so a warmed-up parent of any size, a
test runner's included, does not count; the parent's shared-library pages
the child touches again are charged to it, as the kernel does not copy
file-backed mappings' page entries at a fork) and its time; and it counts
as failures:

* a traceback or an undocumented exit status (anything but 0, 2, 3, 4; an
  internal error, 70, is a bug), or an error that is not one ``mast:`` line;
* a peak of its own above 1 GiB or twice the undamaged run's, whichever is
  larger, or a run stopped by the address-space limit;
* a run taking more than ten times the undamaged file's processor time (and a
  second), or stopped by its time limit;
* a fix from a damaged file that differs from the undamaged file's fix of
  the same scan by more than five combined standard deviations (and 1 mm,
  1 arc-second), or is one where the undamaged file gave none;
* an output left behind half-written after a failure (a ``.part`` file, or
  the target of a failed write).
"""

from __future__ import annotations

import bz2
import contextlib
import functools
import json
import math
import os
import resource
import shutil
import signal
import statistics
import struct
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["FuzzCase", "FuzzResult", "FuzzSummary", "run_fuzz"]

#: Exit statuses ``mast`` documents (success, bad input, no fix, cannot write).
DOCUMENTED = frozenset({0, 2, 3, 4})
#: The memory bound: 1 GiB, or twice the undamaged run's peak if that is larger.
MEMORY_BOUND_BYTES = 1 << 30
#: A damaged run may take this many times the undamaged run's time (plus a second).
TIME_FACTOR = 10.0
#: A fix differs from the undamaged one beyond this many combined standard deviations ...
AGREE_SIGMAS = 5.0
#: ... and these.
SAME_POSITION_M = 1e-3
SAME_AZIMUTH_ARCSEC = 1.0


@dataclass(frozen=True, slots=True)
class FuzzCase:
    """One run of ``mast``: its family, what was done to the input, the arguments, and
    the seed whose undamaged run it is judged against (None for output-path cases)."""

    family: str
    mutation: str
    argv: tuple[str, ...]
    seed: str | None
    expect: frozenset[int] = DOCUMENTED
    file_limit: int | None = None
    stdout: str | None = None  # "full" (/dev/full) or "closed" (a pipe closed at once)
    outputs: tuple[str, ...] = ()  # targets that must not be left half-written


@dataclass(frozen=True, slots=True)
class FuzzResult:
    case: FuzzCase
    status: int
    seconds: float
    peak_bytes: int
    stderr: str
    stdout: str
    problems: tuple[str, ...]


@dataclass(slots=True)
class FuzzSummary:
    cases: int = 0
    by_family: dict[str, int] = field(default_factory=dict)
    by_status: dict[int, int] = field(default_factory=dict)
    tracebacks: int = 0
    undocumented: int = 0
    not_one_line: int = 0
    over_memory: int = 0
    over_time: int = 0
    wrong_fixes: int = 0
    half_written: int = 0
    unexpected_status: int = 0
    peak_bytes: int = 0  # a case's own peak, above what it inherited
    inherited_bytes: int = 0  # the resident memory a child starts with (the largest)
    worst_time_ratio: float = 0.0
    seconds: float = 0.0
    failures: list[FuzzResult] = field(default_factory=list)
    slowest: list[tuple[float, str]] = field(default_factory=list)

    @property
    def failed(self) -> int:
        return len(self.failures)

    def line(self) -> str:
        statuses = ", ".join(f"{k}: {v}" for k, v in sorted(self.by_status.items()))
        return (
            f"{self.cases} inputs ({len(self.by_family)} families) in {self.seconds:.0f} s: "
            f"failures {self.failed} (tracebacks {self.tracebacks}, undocumented status "
            f"{self.undocumented}, not one line {self.not_one_line}, over memory "
            f"{self.over_memory}, over time {self.over_time}, fixes differing {self.wrong_fixes}, "
            f"half-written outputs {self.half_written}, unexpected status "
            f"{self.unexpected_status}); exit statuses {{{statuses}}}; peak memory "
            f"{self.peak_bytes / 2**20:.0f} MiB above the {self.inherited_bytes / 2**20:.0f} MiB "
            f"a child inherits; worst time {self.worst_time_ratio:.1f}x undamaged"
        )


# --------------------------------------------------------------------------- seeds


#: An undamaged run: its processor seconds, its peak bytes, its fixes by stamp, and the
#: true poses (E, N, azimuth in degrees) of the scans it holds.
_Base = tuple[float, int, dict[int, tuple[float, ...]], list[tuple[float, float, float]]]


@dataclass(frozen=True, slots=True)
class _Seeds:
    root: Path
    survey: Path
    scans: tuple[Path, ...]
    bag1: Path
    bag1_bz2: Path
    ros2_sqlite: Path
    ros2_mcap: Path
    drift_csv: Path
    drift_dxf: Path
    bomb: Path
    truth: tuple[tuple[float, float, float], ...]


def _make_seeds(root: Path) -> _Seeds:
    from dataclasses import replace

    from mast.io.bags import write_laserscans
    from mast.io.scan_csv import read_scan_csv
    from mast.sim.scenarios import build_scenario, write_scenario

    written = write_scenario(build_scenario("paper", 0, noise=True)[:1], root / "sim")
    scene = written[0]
    scans = tuple(scene.scans[:3])
    loaded = [read_scan_csv(p) for p in scene.scans]
    stamped = [replace(s, stamp_ns=i * 40_000_000) for i, s in enumerate(loaded)]
    bag1 = root / "run.bag"
    write_laserscans(bag1, stamped, kind="rosbag1")
    bag1_bz2 = root / "run_bz2.bag"
    write_laserscans(bag1_bz2, stamped, kind="rosbag1", compression="bz2")
    ros2_sqlite = root / "run_db3"
    write_laserscans(ros2_sqlite, stamped, kind="sqlite3")
    ros2_mcap = root / "run_mcap"
    write_laserscans(ros2_mcap, stamped, kind="mcap")
    drift_csv = root / "drift.csv"
    drift_csv.write_text(
        "wall,vertex,easting,northing\n"
        "L,1,500000.0,7000000.0\nL,2,500040.0,7000000.0\n"
        "R,1,500000.0,7000005.0\nR,2,500040.0,7000005.0\n",
        encoding="utf-8",
    )
    drift_dxf = root / "drift.dxf"
    _write_drift_dxf(drift_dxf)
    bomb = root / "bomb.bag"
    _bz2_bomb_bag(bomb, 1536 << 20)
    return _Seeds(
        root,
        scene.survey,
        scans,
        bag1,
        bag1_bz2,
        ros2_sqlite,
        ros2_mcap,
        drift_csv,
        drift_dxf,
        bomb,
        _truth(scene.truth),
    )


def _truth(path: Path) -> tuple[tuple[float, float, float], ...]:
    import csv

    with path.open(encoding="utf-8", newline="") as fh:
        return tuple(
            (float(r["easting"]), float(r["northing"]), float(r["azimuth_deg"]))
            for r in csv.DictReader(fh)
        )


def _write_drift_dxf(path: Path) -> None:
    from mast.io.dxf import new_dxf, save_dxf

    doc, msp = new_dxf({"W": 7})
    msp.add_lwpolyline([(500000.0, 7000000.0), (500040.0, 7000000.0)], dxfattribs={"layer": "W"})
    msp.add_lwpolyline([(500000.0, 7000005.0), (500040.0, 7000005.0)], dxfattribs={"layer": "W"})
    save_dxf(doc, path)


# --------------------------------------------------------------------------- mutations

_BAD_NUMBERS = (
    "1e300", "-1e300", "nan", "inf", "-inf", "", "1e-320", "9" * 400, "0x10", "1,5", "--1",
    "١٢٣", "1e8", "-0", "   ", "NaN", "+inf", "1_000",
)  # fmt: skip


def _bitflip(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    if not data:
        return "bitflip", data
    b = bytearray(data)
    k = int(rng.integers(1, 9))
    for _ in range(k):
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
    return f"bitflip x{k}", bytes(b)


def _truncate(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    n = int(rng.integers(0, max(len(data), 1)))
    return f"truncate at {n}", data[:n]


def _random(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    n = int(rng.integers(0, 4096))
    return f"random {n} bytes", rng.bytes(n)


def _splice(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    if len(data) < 2:
        return "splice", data
    i, j = sorted(int(x) for x in rng.integers(0, len(data), size=2))
    kind = int(rng.integers(0, 3))
    if kind == 0:
        return f"delete {i}:{j}", data[:i] + data[j:]
    if kind == 1:
        return f"repeat {i}:{j}", data[:j] + data[i:j] + data[j:]
    return f"insert {j - i} random at {i}", data[:i] + rng.bytes(j - i) + data[i:]


def _text_value(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """A number of a CSV swapped for one no file should hold."""
    lines = data.split(b"\n")
    body = [k for k in range(1, len(lines)) if b"," in lines[k]]
    if not body:
        return "value", data
    k = body[int(rng.integers(0, len(body)))]
    cells = lines[k].split(b",")
    c = int(rng.integers(0, len(cells)))
    bad = _BAD_NUMBERS[int(rng.integers(0, len(_BAD_NUMBERS)))]
    cells[c] = bad.encode()
    lines[k] = b",".join(cells)
    return f"line {k + 1} field {c + 1} = {bad[:12]!r}", b"\n".join(lines)


def _text_lines(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """Lines of a CSV repeated, swapped, dropped or blown up."""
    lines = data.split(b"\n")
    if len(lines) < 3:
        return "lines", data
    k = int(rng.integers(1, len(lines) - 1))
    kind = int(rng.integers(0, 6))
    if kind == 0:
        return f"repeat lines from {k + 1}", b"\n".join(lines + lines[k:])
    if kind == 1:
        j = int(rng.integers(1, len(lines) - 1))
        lines[k], lines[j] = lines[j], lines[k]
        return f"swap lines {k + 1} and {j + 1}", b"\n".join(lines)
    if kind == 2:
        return f"drop line {k + 1}", b"\n".join(lines[:k] + lines[k + 1 :])
    if kind == 3:
        return "a 6 MB line", b"\n".join([*lines[:k], b"1," * 3_000_000, *lines[k:]])
    if kind == 4:
        return "NUL bytes", data[:k] + b"\x00" * 16 + data[k:]
    return "header only", lines[0] + b"\n"


def _lying_chunk(data: bytes, rng: np.random.Generator) -> tuple[str, bytes]:
    """A ROS 1 chunk header's decompressed ``size`` changed (smaller or larger)."""
    at = data.find(b"size=", 13)
    if at < 0:
        return "lying size", data
    new = int(rng.choice([0, 1, 64, 2**31, 2**32 - 1]))
    return f"chunk size = {new}", data[: at + 5] + struct.pack("<I", new) + data[at + 9 :]


def _mutate(
    data: bytes, rng: np.random.Generator, *, text: bool, bag1: bool = False
) -> tuple[str, bytes]:
    ops: list[Callable[[bytes, np.random.Generator], tuple[str, bytes]]] = [
        _bitflip,
        _bitflip,
        _truncate,
        _random,
        _splice,
    ]
    if text:
        ops += [_text_value, _text_value, _text_value, _text_lines, _text_lines]
    if bag1:
        ops += [_lying_chunk, _lying_chunk]
    return ops[int(rng.integers(0, len(ops)))](data, rng)


def _bz2_bomb_bag(path: Path, inflated: int) -> None:
    """A ROS 1 bag of one bz2 chunk that declares 1 KiB and inflates to ``inflated`` bytes."""

    def record(fields: dict[str, bytes], data: bytes) -> bytes:
        head = b"".join(
            struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v
            for k, v in fields.items()
        )
        return struct.pack("<I", len(head)) + head + struct.pack("<I", len(data)) + data

    bomb = bz2.compress(b"\x00" * inflated, 9)
    header = record(
        {
            "op": b"\x03",
            "index_pos": struct.pack("<Q", 0),
            "conn_count": struct.pack("<I", 0),
            "chunk_count": struct.pack("<I", 1),
        },
        b" " * 4000,
    )
    chunk = record({"op": b"\x05", "compression": b"bz2", "size": struct.pack("<I", 1024)}, bomb)
    path.write_bytes(b"#ROSBAG V2.0\n" + header + chunk)


_YAML_BOMB = (
    'a: &a ["x","x","x","x","x","x","x","x","x"]\n'
    + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},"
        f"*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},*{chr(97 + i)},"
        f"*{chr(97 + i)}]\n"
        for i in range(8)
    )
    + "rosbag2_bagfile_information: *i\n"
)


def _metadata_attack(text: str, rng: np.random.Generator) -> tuple[str, str]:
    kind = int(rng.integers(0, 5))
    if kind == 0:
        return "YAML alias bomb", _YAML_BOMB
    if kind == 1:
        return "storage name ../../etc", text.replace("- run_", "- ../../../etc/run_", 1)
    if kind == 2:
        return "storage name absolute", text.replace("- run_", "- /tmp/run_", 1)
    if kind == 3:
        return "2 MB metadata", text + "# " + "x" * 2_000_000 + "\n"
    return "metadata not YAML", "{{{{ [[[ :\n\t- !!python/object/apply:os.system ['true']\n"


# --------------------------------------------------------------------------- cases


def _cases(seeds: _Seeds, work: Path, n: int, seed: int) -> Iterator[FuzzCase]:
    """``n`` cases drawn over the families, their files written under ``work``."""
    rng = np.random.default_rng(seed)
    survey_bytes = seeds.survey.read_bytes()
    scan_bytes = [p.read_bytes() for p in seeds.scans]
    families = [
        ("survey", 5),
        ("scan_csv", 5),
        ("bag1", 3),
        ("bag1_bz2", 3),
        ("ros2_sqlite", 2),
        ("ros2_mcap", 2),
        ("metadata", 1),
        ("drift_csv", 1),
        ("drift_dxf", 1),
        ("output", 2),
        ("disk_full", 2),
    ]
    names = [f for f, _ in families]
    weights = np.array([w for _, w in families], dtype=float)
    weights /= weights.sum()
    survey = str(seeds.survey)
    for k in range(n):
        fam = names[int(rng.choice(len(names), p=weights))]
        d = work / f"c{k:06d}"
        d.mkdir()
        argv: tuple[str, ...]
        if fam == "survey":
            what, data = _mutate(survey_bytes, rng, text=True)
            (d / "beacons.csv").write_bytes(data)
            argv = ("locate", str(seeds.scans[0]), "-b", str(d / "beacons.csv"), "--format", "json")
            yield FuzzCase(fam, what, argv, "scan0")
        elif fam == "scan_csv":
            i = int(rng.integers(0, len(scan_bytes)))
            what, data = _mutate(scan_bytes[i], rng, text=True)
            (d / "scan.csv").write_bytes(data)
            argv = ("locate", str(d / "scan.csv"), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, f"scan{i}")
        elif fam in ("bag1", "bag1_bz2"):
            src = seeds.bag1 if fam == "bag1" else seeds.bag1_bz2
            if fam == "bag1_bz2" and rng.random() < 0.1:
                what = "bz2 bomb: 1 KiB declared, 1.5 GiB inflated"
                shutil.copy(seeds.bomb, d / "run.bag")
            else:
                what, data = _mutate(src.read_bytes(), rng, text=False, bag1=True)
                (d / "run.bag").write_bytes(data)
            argv = ("locate", str(d / "run.bag"), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, fam)
        elif fam in ("ros2_sqlite", "ros2_mcap"):
            src = seeds.ros2_sqlite if fam == "ros2_sqlite" else seeds.ros2_mcap
            bag = d / src.name
            shutil.copytree(src, bag)
            storage = next(p for p in bag.iterdir() if p.name != "metadata.yaml")
            what, data = _mutate(storage.read_bytes(), rng, text=False)
            storage.write_bytes(data)
            argv = ("locate", str(bag), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, fam)
        elif fam == "metadata":
            src = seeds.ros2_mcap if rng.random() < 0.5 else seeds.ros2_sqlite
            bag = d / src.name
            shutil.copytree(src, bag)
            meta = bag / "metadata.yaml"
            if rng.random() < 0.5:
                what, text = _metadata_attack(meta.read_text(encoding="utf-8"), rng)
                meta.write_text(text, encoding="utf-8")
            else:
                what, data = _mutate(meta.read_bytes(), rng, text=True)
                meta.write_bytes(data)
            argv = ("locate", str(bag), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, None, frozenset({0, 2, 3}))
        elif fam in ("drift_csv", "drift_dxf"):
            src = seeds.drift_csv if fam == "drift_csv" else seeds.drift_dxf
            what, data = _mutate(src.read_bytes(), rng, text=fam == "drift_csv")
            target = d / src.name
            target.write_bytes(data)
            argv = (
                "plan", "--drift", str(target), "--beacons", survey, "--out", str(d / "plan"),
                "--scanner", "lms1xx-0.5", "--check",
            )  # fmt: skip
            yield FuzzCase(fam, what, argv, None, frozenset({0, 2}))
        elif fam == "output":
            yield _output_case(seeds, d, rng)
        else:
            yield _disk_full_case(seeds, d, rng)


def _output_case(seeds: _Seeds, d: Path, rng: np.random.Generator) -> FuzzCase:
    scan, survey = str(seeds.scans[0]), str(seeds.survey)
    base = ("locate", scan, "-b", survey, "--format", "json")
    kind = int(rng.integers(0, 10))
    if kind == 0:
        return FuzzCase(
            "output",
            "plot into a missing folder",
            (*base, "--plot", str(d / "a/b/fix.png")),
            None,
            frozenset({0}),
        )
    if kind == 1:
        (d / "file").write_text("x")
        return FuzzCase(
            "output",
            "plot under a file",
            (*base, "--plot", str(d / "file/fix.png")),
            None,
            frozenset({2, 4}),
        )
    if kind == 2:
        return FuzzCase(
            "output",
            "plot with an unknown suffix",
            (*base, "--plot", str(d / "fix.xyz")),
            None,
            frozenset({2}),
        )
    if kind == 3:
        return FuzzCase(
            "output", "plot onto the survey", (*base, "--plot", survey), None, frozenset({2})
        )
    if kind == 4:
        return FuzzCase(
            "output",
            "plot name too long",
            (*base, "--plot", str(d / ("x" * 300 + ".png"))),
            None,
            frozenset({4}),
        )
    if kind == 5:
        return FuzzCase(
            "output", "standard output on a full disk", base, None, frozenset({4}), stdout="full"
        )
    if kind == 6:
        return FuzzCase(
            "output", "standard output closed", base, None, frozenset({0, 4}), stdout="closed"
        )
    if kind == 7:
        (d / "file").write_text("x")
        return FuzzCase(
            "output",
            "simulate onto a file",
            ("simulate", "--out", str(d / "file")),
            None,
            frozenset({2}),
        )
    if kind == 8:
        return FuzzCase(
            "output",
            "simulate into /proc",
            ("simulate", "--out", "/proc/mast-fuzz/x"),
            None,
            frozenset({4}),
        )
    (d / "fix.png").mkdir()
    plot = (*base, "--plot", str(d / "fix.png"))
    return FuzzCase("output", "plot onto a folder", plot, None, frozenset({2, 4}))


def _disk_full_case(seeds: _Seeds, d: Path, rng: np.random.Generator) -> FuzzCase:
    """A command whose disk fills after a random number of bytes (a file-size limit)."""
    limit = int(rng.integers(0, 200_000))
    kind = int(rng.integers(0, 4))
    scan, survey = str(seeds.scans[0]), str(seeds.survey)
    if kind == 0:
        out = d / "fix.png"
        argv: tuple[str, ...] = (
            "locate",
            scan,
            "-b",
            survey,
            "--format",
            "json",
            "--plot",
            str(out),
        )
        outputs: tuple[str, ...] = (str(out),)
    elif kind == 1:
        argv, outputs = ("simulate", "--out", str(d / "sim")), ()
    elif kind == 2:
        argv, outputs = ("simulate", "--out", str(d / "sim"), "--format", "mcap"), ()
    else:
        argv = ("track", str(seeds.bag1), "-b", survey, "--out", str(d / "track"))
        outputs = ()
    what = f"disk full after {limit} bytes: {argv[0]}"
    return FuzzCase("disk_full", what, argv, None, DOCUMENTED, limit, outputs=outputs)


# --------------------------------------------------------------------------- running


def _vm(field: str) -> int:
    """This process's ``VmSize`` or ``VmRSS`` (``/proc/self/status``), bytes."""
    with open("/proc/self/status", encoding="ascii") as fh:
        for line in fh:
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) * 1024
    return 0  # pragma: no cover - Linux only


def _child(case: FuzzCase, out: Path, err: Path, as_limit: int) -> None:
    """In the forked child: limits, redirections, then ``mast`` itself; never returns.
    First of all it writes the resident size it starts with (what it holds of the
    parent's pages) to ``.rss0`` beside ``out``, which the parent subtracts."""
    status = 70
    try:
        with contextlib.suppress(OSError):  # without it the whole peak is charged
            (out.parent / ".rss0").write_text(str(_vm("VmRSS")), encoding="ascii")
        os.setsid()
        resource.setrlimit(resource.RLIMIT_AS, (as_limit, as_limit))
        if case.file_limit is not None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (case.file_limit, case.file_limit))
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        if case.stdout == "full":
            fd = os.open("/dev/full", os.O_WRONLY)
        elif case.stdout == "closed":
            r, fd = os.pipe()
            os.close(r)
        else:
            fd = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(os.open(err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644), 2)
        signal.signal(signal.SIGPIPE, signal.SIG_DFL if case.stdout != "closed" else signal.SIG_IGN)
        sys.stdout = open(1, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
        sys.stderr = open(2, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
        sys.argv = ["mast", *case.argv]
        from mast.cli import main

        main()
        status = 0
    except SystemExit as exc:
        code = exc.code
        status = code if isinstance(code, int) else (0 if code is None else 1)
    except BaseException:
        import traceback

        with contextlib.suppress(Exception):
            traceback.print_exc()
            sys.stderr.flush()
        status = 1
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(status)


@dataclass(slots=True)
class _Child:
    """A case running in a forked child."""

    pid: int
    case: FuzzCase
    folder: Path
    started: float
    timeout_s: float
    killed: bool = False


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None (another C library)."""
    import ctypes

    try:
        trim: Callable[[int], int] = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    return trim


def _trim_heap() -> bool:
    """Give the C heap's free pages back to the system (glibc ``malloc_trim``) before a
    fork: a page the parent freed but still holds is resident in the child from the
    start, so the child's allocations reuse it without its peak growing; trimmed, what
    a case allocates shows in its peak. False without glibc (nothing done)."""
    trim = _malloc_trim()
    if trim is None:
        return False  # pragma: no cover - glibc here
    trim(0)
    return True


def _start(case: FuzzCase, folder: Path, as_limit: int, timeout_s: float) -> _Child:
    folder.mkdir(parents=True, exist_ok=True)
    _trim_heap()
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - runs in the child
        _child(case, folder / ".stdout", folder / ".stderr", as_limit)
    return _Child(pid, case, folder, t0, timeout_s)


def _poll(child: _Child) -> tuple[int, float, int, int, str, str] | None:
    """The child's (status, seconds, peak bytes of its own, bytes inherited, stdout,
    stderr) once it has ended, else None; past its time limit it is killed (status -9)."""
    done, wstatus, usage = os.wait4(child.pid, os.WNOHANG)
    now = time.perf_counter()
    if not done:
        if now - child.started > child.timeout_s and not child.killed:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(child.pid, signal.SIGKILL)
            child.killed = True
        return None
    status = os.WEXITSTATUS(wstatus) if os.WIFEXITED(wstatus) else -os.WTERMSIG(wstatus)
    if child.killed:
        status = -9
    out, err = child.folder / ".stdout", child.folder / ".stderr"
    text_out = out.read_text(encoding="utf-8", errors="replace") if out.exists() else ""
    text_err = err.read_text(encoding="utf-8", errors="replace") if err.exists() else ""
    # Processor time, not wall time: what the run cost, whatever else the machine did.
    cpu = float(usage.ru_utime + usage.ru_stime)
    # ru_maxrss counts the parent's pages the child was forked with; what the case itself
    # took is the peak less that. No record (the child died at once): the whole peak.
    rss0 = child.folder / ".rss0"
    inherited = 0
    with contextlib.suppress(OSError, ValueError):
        inherited = int(rss0.read_text(encoding="ascii"))
    peak = int(usage.ru_maxrss) * 1024
    return status, cpu, max(peak - inherited, 0), inherited, text_out, text_err


def _run(
    case: FuzzCase, folder: Path, as_limit: int, timeout_s: float
) -> tuple[int, float, int, int, str, str]:
    """One case, waited for."""
    child = _start(case, folder, as_limit, timeout_s)
    while (got := _poll(child)) is None:
        time.sleep(0.002)
    return got


def _fixes(stdout: str) -> dict[int, tuple[float, ...]]:
    """Each fixed scan's (E, N, azimuth in degrees, sigma E, sigma N, sigma azimuth), by its
    time stamp (a damaged bag may lose messages, so a scan's place in the output is no
    name for it)."""
    found: dict[int, tuple[float, ...]] = {}
    keys = (
        "easting",
        "northing",
        "azimuth_deg",
        "sigma_easting_m",
        "sigma_northing_m",
        "sigma_azimuth_deg",
    )
    for line in stdout.splitlines():
        with contextlib.suppress(ValueError, KeyError, TypeError):
            rec = json.loads(line)
            if rec.get("status") == "fix":
                found[int(rec.get("stamp_ns", 0))] = tuple(float(rec[k]) for k in keys)
    return found


def _differs(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    """Whether two fixes of one scan disagree beyond their uncertainty: more than
    :data:`AGREE_SIGMAS` combined standard deviations (and 1 mm, 1 arc-second) in
    easting, northing or azimuth. A damaged file holds less or other data than the
    undamaged one, so its fix may move within its uncertainty; a wrong fix (another
    beacon, another place) is off by metres."""
    de, dn = abs(a[0] - b[0]), abs(a[1] - b[1])
    daz = abs((a[2] - b[2] + 180.0) % 360.0 - 180.0)
    return (
        de > max(AGREE_SIGMAS * math.hypot(a[3], b[3]), SAME_POSITION_M)
        or dn > max(AGREE_SIGMAS * math.hypot(a[4], b[4]), SAME_POSITION_M)
        or daz > max(AGREE_SIGMAS * math.hypot(a[5], b[5]), SAME_AZIMUTH_ARCSEC / 3600.0)
    )


def _judge(
    case: FuzzCase,
    status: int,
    seconds: float,
    peak: int,
    out: str,
    err: str,
    base: dict[str, _Base],
) -> tuple[str, ...]:
    problems: list[str] = []
    if "Traceback (most recent call last)" in err or status == 1:
        problems.append("traceback")
    if status not in DOCUMENTED:
        problems.append(f"undocumented status {status}")
    elif status not in case.expect:
        problems.append(f"unexpected status {status}")
    lines = [ln for ln in err.splitlines() if ln.strip()]
    quiet = case.stdout == "closed" and status == 4 and not lines  # a closed pipe: no word
    if (
        status in (2, 4)
        and not quiet
        and not (lines and all(ln.startswith("mast: ") for ln in lines))
    ):
        problems.append("not one line")
    if "out of memory" in err:
        problems.append("over memory")
    seed = base.get(case.seed or "")
    limit = MEMORY_BOUND_BYTES if seed is None else max(MEMORY_BOUND_BYTES, 2 * seed[1])
    if peak > limit:
        problems.append("over memory")
    if status == -9 or (seed is not None and seconds > TIME_FACTOR * seed[0] + 1.0):
        problems.append("over time")
    if seed is not None:
        ref, truth = seed[2], seed[3]
        for stamp, got in _fixes(out).items():
            r = ref.get(stamp)
            if r is not None and _differs(got, r):
                problems.append("fix differs from the undamaged file's")
                break
            # No undamaged fix of this scan (or its stamp was damaged): a true pose of the
            # seed's scans must agree with it.
            if r is None and all(_differs(got, (*t, 0.0, 0.0, 0.0)) for t in truth):
                problems.append("fix away from every true pose")
                break
    if status != 0:
        for target in case.outputs:
            if Path(target).exists():
                problems.append("half-written output")
    return tuple(dict.fromkeys(problems))


def run_fuzz(
    *,
    inputs: int = 10_000,
    seed: int = 0,
    echo: Callable[[str], object] = print,
    progress: Callable[[int, int], None] | None = None,
    keep_failures: Path | None = None,
    jobs: int | None = None,
) -> FuzzSummary:
    """Run ``inputs`` damaged or crafted inputs through ``mast``; count what went wrong.

    Parameters
    ----------
    inputs : int
        Cases to run (each a forked child of this process).
    seed : int
        Seed of the mutations.
    echo : callable
        Receives the summary line, then one line per failure.
    progress : callable, optional
        Told (cases done, cases in all) after each case.
    keep_failures : Path, optional
        A folder to copy each failing case's files into.
    jobs : int, optional
        Cases run at once (default: the processor count). Times are judged with
        the undamaged runs measured alone, so a loaded machine errs towards "too slow".
    """
    from mast.cli import main  # noqa: F401 - imported (and compiled) once, before forking
    from mast.io.scan_csv import read_scan_csv
    from mast.pipeline.locator import locate

    t_start = time.perf_counter()
    jobs = max(1, jobs or os.cpu_count() or 1)
    summary = FuzzSummary()
    with tempfile.TemporaryDirectory(prefix="mast-fuzz-") as tmp_name:
        tmp = Path(tmp_name)
        seeds = _make_seeds(tmp / "seeds")
        from mast.io import read_survey

        survey = read_survey(seeds.survey)
        locate(read_scan_csv(seeds.scans[0]), survey)  # compile the kernels before forking
        # What the commands import on the way, imported once here rather than in each child.
        import ezdxf.recover  # noqa: F401
        import rosbags.rosbag1
        import rosbags.rosbag2  # noqa: F401

        import mast.plan.run
        import mast.report.plot
        import mast.runs.run  # noqa: F401

        as_limit = _vm("VmSize") + MEMORY_BOUND_BYTES + (256 << 20)
        # The undamaged runs: time, peak memory and fixes each damaged one is judged by.
        survey_s = str(seeds.survey)
        base_argv = {
            **{
                f"scan{i}": ("locate", str(p), "-b", survey_s, "--format", "json")
                for i, p in enumerate(seeds.scans)
            },
            "bag1": ("locate", str(seeds.bag1), "-b", survey_s, "--format", "json"),
            "bag1_bz2": ("locate", str(seeds.bag1_bz2), "-b", survey_s, "--format", "json"),
            "ros2_sqlite": ("locate", str(seeds.ros2_sqlite), "-b", survey_s, "--format", "json"),
            "ros2_mcap": ("locate", str(seeds.ros2_mcap), "-b", survey_s, "--format", "json"),
        }  # fmt: skip
        base: dict[str, _Base] = {}
        for key, argv in base_argv.items():
            undamaged = FuzzCase("undamaged", key, argv, None)
            runs = [_run(undamaged, tmp / f"base-{key}-{r}", as_limit, 120.0) for r in range(3)]
            status = runs[0][0]
            if status not in (0, 3):  # a fix, or an honest no-fix
                raise RuntimeError(f"the undamaged {key} fails (exit {status}): {runs[0][5]}")
            truth = (
                list(seeds.truth)
                if key.startswith(("bag", "ros2"))
                else [seeds.truth[int(key[4:])]]
            )
            base[key] = (
                statistics.median(r[1] for r in runs),
                max(r[2] for r in runs),
                _fixes(runs[0][4]),
                truth,
            )
        work = tmp / "cases"
        work.mkdir()
        cases = iter(enumerate(_cases(seeds, work, inputs, seed)))
        running: list[_Child] = []
        while True:
            while len(running) < jobs and (nxt := next(cases, None)) is not None:
                k, case = nxt
                seed_run = base.get(case.seed or "")
                timeout = 60.0 if seed_run is None else max(TIME_FACTOR * seed_run[0] + 1.0, 5.0)
                running.append(_start(case, work / f"c{k:06d}", as_limit, timeout * 1.5))
            if not running:
                break
            for child in list(running):
                got = _poll(child)
                if got is None:
                    continue
                running.remove(child)
                _finish(child, got, base, summary, keep_failures)
                if progress is not None:
                    progress(summary.cases, inputs)
            time.sleep(0.002)
    summary.seconds = time.perf_counter() - t_start
    echo(summary.line())
    echo("families: " + ", ".join(f"{k} {v}" for k, v in sorted(summary.by_family.items())))
    echo("slowest: " + "; ".join(f"{what} {t:.2f} s" for t, what in summary.slowest[::-1]))
    for r in summary.failures[:50]:
        first = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else ""
        echo(
            f"  {r.case.family} ({r.case.mutation}): exit {r.status}, "
            f"{', '.join(r.problems)}: {first[:200]}"
        )
    return summary


def _finish(
    child: _Child,
    got: tuple[int, float, int, int, str, str],
    base: dict[str, _Base],
    summary: FuzzSummary,
    keep_failures: Path | None,
) -> None:
    """Judge an ended case, count it, keep it if it failed, and remove its files."""
    case = child.case
    status, seconds, peak, inherited, out, err = got
    summary.inherited_bytes = max(summary.inherited_bytes, inherited)
    problems = _judge(case, status, seconds, peak, out, err, base)
    left = next(child.folder.glob("**/.*.part"), None)
    if left is not None:
        problems = (*problems, f"half-written output {left.name}")
    result = FuzzResult(case, status, seconds, peak, err[-2000:], out[-500:], problems)
    _count(summary, result, base.get(case.seed or ""))
    if problems and keep_failures is not None:
        _keep(result, keep_failures, len(summary.failures))
    shutil.rmtree(child.folder, ignore_errors=True)


def _count(s: FuzzSummary, r: FuzzResult, seed_run: _Base | None) -> None:
    s.cases += 1
    s.by_family[r.case.family] = s.by_family.get(r.case.family, 0) + 1
    s.by_status[r.status] = s.by_status.get(r.status, 0) + 1
    s.peak_bytes = max(s.peak_bytes, r.peak_bytes)
    s.slowest = sorted([*s.slowest, (r.seconds, f"{r.case.family} ({r.case.mutation})")])[-5:]
    if seed_run is not None and seed_run[0] > 0:
        s.worst_time_ratio = max(s.worst_time_ratio, r.seconds / seed_run[0])
    p = " ".join(r.problems)
    s.tracebacks += "traceback" in p
    s.undocumented += "undocumented" in p
    s.unexpected_status += "unexpected status" in p
    s.not_one_line += "not one line" in p
    s.over_memory += "over memory" in p
    s.over_time += "over time" in p
    s.wrong_fixes += "fix" in p
    s.half_written += "half-written" in p
    if r.problems:
        s.failures.append(r)


def _keep(r: FuzzResult, folder: Path, k: int) -> None:
    dest = folder / f"failure_{k:04d}"
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "case.json").write_text(
        json.dumps(
            {
                "family": r.case.family,
                "mutation": r.case.mutation,
                "argv": list(r.case.argv),
                "status": r.status,
                "seconds": r.seconds,
                "peak_bytes": r.peak_bytes,
                "problems": list(r.problems),
                "stderr": r.stderr,
                "stdout": r.stdout,
            },
            indent=2,
        ),
        encoding="utf-8",
    )
    for a in r.case.argv:
        p = Path(a)
        if a.startswith("/tmp") and p.is_file():
            shutil.copy(p, dest / p.name)
        elif a.startswith("/tmp") and p.is_dir() and "cases" in p.parts:
            shutil.copytree(p, dest / p.name, dirs_exist_ok=True)
