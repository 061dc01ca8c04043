"""The cases: each seed damaged each way, and hostile output paths."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mast.bench.fuzz.model import DOCUMENTED, FuzzCase
from mast.bench.fuzz.mutations import metadata_attack, mutate
from mast.bench.fuzz.seeds import Seeds

__all__ = ["fuzz_cases"]


def fuzz_cases(seeds: Seeds, work: Path, n: int, seed: int) -> Iterator[FuzzCase]:
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
            what, data = mutate(survey_bytes, rng, text=True)
            (d / "beacons.csv").write_bytes(data)
            argv = ("locate", str(seeds.scans[0]), "-b", str(d / "beacons.csv"), "--format", "json")
            yield FuzzCase(fam, what, argv, "scan0")
        elif fam == "scan_csv":
            i = int(rng.integers(0, len(scan_bytes)))
            what, data = mutate(scan_bytes[i], rng, text=True)
            (d / "scan.csv").write_bytes(data)
            argv = ("locate", str(d / "scan.csv"), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, f"scan{i}")
        elif fam in ("bag1", "bag1_bz2"):
            src = seeds.bag1 if fam == "bag1" else seeds.bag1_bz2
            if fam == "bag1_bz2" and rng.random() < 0.1:
                what = "bz2 bomb: 1 KiB declared, 1.5 GiB inflated"
                shutil.copy(seeds.bomb, d / "run.bag")
            else:
                what, data = mutate(src.read_bytes(), rng, text=False, bag1=True)
                (d / "run.bag").write_bytes(data)
            argv = ("locate", str(d / "run.bag"), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, fam)
        elif fam in ("ros2_sqlite", "ros2_mcap"):
            src = seeds.ros2_sqlite if fam == "ros2_sqlite" else seeds.ros2_mcap
            bag = d / src.name
            shutil.copytree(src, bag)
            storage = next(p for p in bag.iterdir() if p.name != "metadata.yaml")
            what, data = mutate(storage.read_bytes(), rng, text=False)
            storage.write_bytes(data)
            argv = ("locate", str(bag), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, fam)
        elif fam == "metadata":
            src = seeds.ros2_mcap if rng.random() < 0.5 else seeds.ros2_sqlite
            bag = d / src.name
            shutil.copytree(src, bag)
            meta = bag / "metadata.yaml"
            if rng.random() < 0.5:
                what, text = metadata_attack(meta.read_text(encoding="utf-8"), rng)
                meta.write_text(text, encoding="utf-8")
            else:
                what, data = mutate(meta.read_bytes(), rng, text=True)
                meta.write_bytes(data)
            argv = ("locate", str(bag), "-b", survey, "--format", "json")
            yield FuzzCase(fam, what, argv, None, frozenset({0, 2, 3}))
        elif fam in ("drift_csv", "drift_dxf"):
            src = seeds.drift_csv if fam == "drift_csv" else seeds.drift_dxf
            what, data = mutate(src.read_bytes(), rng, text=fam == "drift_csv")
            target = d / src.name
            target.write_bytes(data)
            argv = (
                "plan", "--walls", str(target), "--beacons", survey, "--out", str(d / "plan"),
                "--scanner", "lms1xx-0.5", "--dry-run",
            )  # fmt: skip
            yield FuzzCase(fam, what, argv, None, frozenset({0, 2}))
        elif fam == "output":
            yield _output_case(seeds, d, rng)
        else:
            yield _disk_full_case(seeds, d, rng)


def _output_case(seeds: Seeds, d: Path, rng: np.random.Generator) -> FuzzCase:
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


def _disk_full_case(seeds: Seeds, d: Path, rng: np.random.Generator) -> FuzzCase:
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
        argv, outputs = ("simulate", "--out", str(d / "sim"), "--scan-format", "mcap"), ()
    else:
        argv = ("track", str(seeds.bag1), "-b", survey, "--out", str(d / "track"))
        outputs = ()
    what = f"disk full after {limit} bytes: {argv[0]}"
    return FuzzCase("disk_full", what, argv, None, DOCUMENTED, limit, outputs=outputs)
