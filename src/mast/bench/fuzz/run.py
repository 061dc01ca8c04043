"""Judging each case against its seed's undamaged run, counting, and the benchmark itself."""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from mast.bench.fuzz.cases import fuzz_cases
from mast.bench.fuzz.children import Child, poll_case, run_case, start_case, vm_bytes
from mast.bench.fuzz.model import (
    AGREE_SIGMAS,
    DOCUMENTED,
    MEMORY_BOUND_BYTES,
    SAME_AZIMUTH_ARCSEC,
    SAME_POSITION_M,
    TIME_FACTOR,
    FuzzCase,
    FuzzResult,
    FuzzSummary,
)
from mast.bench.fuzz.seeds import BaseRun, make_seeds

__all__ = ["run_fuzz"]


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
    base: dict[str, BaseRun],
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
        seeds = make_seeds(tmp / "seeds")
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

        as_limit = vm_bytes("VmSize") + MEMORY_BOUND_BYTES + (256 << 20)
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
        base: dict[str, BaseRun] = {}
        for key, argv in base_argv.items():
            undamaged = FuzzCase("undamaged", key, argv, None)
            runs = [run_case(undamaged, tmp / f"base-{key}-{r}", as_limit, 120.0) for r in range(3)]
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
        cases = iter(enumerate(fuzz_cases(seeds, work, inputs, seed)))
        running: list[Child] = []
        while True:
            while len(running) < jobs and (nxt := next(cases, None)) is not None:
                k, case = nxt
                seed_run = base.get(case.seed or "")
                timeout = 60.0 if seed_run is None else max(TIME_FACTOR * seed_run[0] + 1.0, 5.0)
                running.append(start_case(case, work / f"c{k:06d}", as_limit, timeout * 1.5))
            if not running:
                break
            for child in list(running):
                got = poll_case(child)
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
    child: Child,
    got: tuple[int, float, int, int, str, str],
    base: dict[str, BaseRun],
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


def _count(s: FuzzSummary, r: FuzzResult, seed_run: BaseRun | None) -> None:
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
