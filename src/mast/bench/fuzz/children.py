"""Each case in a forked child of one warmed-up process, under memory, file-size and
time limits."""

from __future__ import annotations

import contextlib
import functools
import os
import resource
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mast.bench.fuzz.model import FuzzCase

__all__ = ["Child", "poll_case", "run_case", "start_case", "trim_heap", "vm_bytes"]


def vm_bytes(field: str) -> int:
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
            (out.parent / ".rss0").write_text(str(vm_bytes("VmRSS")), encoding="ascii")
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
class Child:
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


def trim_heap() -> bool:
    """Give the C heap's free pages back to the system (glibc ``malloc_trim``) before a
    fork: a page the parent freed but still holds is resident in the child from the
    start, so the child's allocations reuse it without its peak growing; trimmed, what
    a case allocates shows in its peak. False without glibc (nothing done)."""
    trim = _malloc_trim()
    if trim is None:
        return False  # pragma: no cover - glibc here
    trim(0)
    return True


def start_case(case: FuzzCase, folder: Path, as_limit: int, timeout_s: float) -> Child:
    folder.mkdir(parents=True, exist_ok=True)
    trim_heap()
    t0 = time.perf_counter()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - runs in the child
        _child(case, folder / ".stdout", folder / ".stderr", as_limit)
    return Child(pid, case, folder, t0, timeout_s)


def poll_case(child: Child) -> tuple[int, float, int, int, str, str] | None:
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


def run_case(
    case: FuzzCase, folder: Path, as_limit: int, timeout_s: float
) -> tuple[int, float, int, int, str, str]:
    """One case, waited for."""
    child = start_case(case, folder, as_limit, timeout_s)
    while (got := poll_case(child)) is None:
        time.sleep(0.002)
    return got
