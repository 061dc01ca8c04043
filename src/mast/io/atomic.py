"""Writing a file whole or not at all.

Every output MAST writes goes to a temporary name beside its target and is
renamed onto the target only once complete and closed, so that a failure
part-way (a full disk, a signal, a bug) never leaves a half-written file
that looks like a result. A failure to write is an
:class:`~mast.errors.OutputError` naming the target (exit status 4).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any

from mast.errors import OutputError

__all__ = ["atomic_open", "atomic_path", "commit", "discard", "part_path", "write_atomic"]


def part_path(path: str | Path) -> Path:
    """The temporary name ``path`` is written under: hidden, beside it, per process."""
    final = Path(path)
    return final.with_name(f".{final.name}.{os.getpid()}.part")


def commit(tmp: Path, path: str | Path) -> None:
    """Rename the complete ``tmp`` onto ``path``; on failure remove it and raise an
    :class:`OutputError` naming ``path``."""
    try:
        os.replace(tmp, path)
    except OSError as err:
        discard(tmp)
        raise OutputError(f"cannot write: {err.strerror or err}", path=path) from None


def discard(tmp: Path) -> None:
    """Remove a temporary file or folder, if it is there."""
    with contextlib.suppress(OSError):
        if tmp.is_dir() and not tmp.is_symlink():
            shutil.rmtree(tmp)
        else:
            tmp.unlink()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` to write (a file or a folder); renamed onto
    ``path`` when the block ends without an error, removed when it does not."""
    final = Path(path)
    tmp = part_path(final)
    discard(tmp)
    try:
        yield tmp
    except OSError as err:
        discard(tmp)
        raise OutputError(f"cannot write: {err.strerror or err}", path=final) from None
    except BaseException:
        discard(tmp)
        raise
    commit(tmp, final)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``open(path, mode, ...)`` on a temporary name, renamed onto ``path`` once closed."""
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` as the whole of ``path`` (see :func:`atomic_path`)."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)


def write_lines(path: str | Path, lines: Iterable[str]) -> int:
    """Write ``lines`` (each without its newline); the number of lines after the first."""
    rows = -1
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as f:
        for line in lines:
            f.write(line)
            f.write("\n")
            rows += 1
    return max(rows, 0)
