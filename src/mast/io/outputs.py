"""Output paths checked before any work starts, so that a long run never ends in a
traceback over where to write: a missing folder is created, a wrong kind of
path is bad input (exit 2), a place that cannot be written is an
:class:`~mast.errors.OutputError` (exit 4)."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from mast.errors import InputError, OutputError

__all__ = [
    "PLOT_SUFFIXES",
    "check_output_file",
    "check_output_folder",
    "save_figure",
    "write_bytes",
]

#: File suffixes a plot can be written as (matplotlib's Agg and vector back-ends); here,
#: not in the plotting module, so that checking a path does not import matplotlib.
PLOT_SUFFIXES = frozenset(
    {".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps", ".ps"}
)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and a.samefile(b)
    except OSError:
        return False


def check_output_folder(path: Path, *, option: str = "--out", force: bool | None = None) -> Path:
    """Make sure ``path`` is a folder that can be written into, creating it if missing.

    ``force`` given (a run's folder): a folder that holds files already is refused unless
    it is True, so that a second run does not write over the first without a word."""
    if path.exists() and not path.is_dir():
        raise InputError(f"{option} must be a folder, and this is a file", path=path)
    if force is False and path.is_dir() and any(path.iterdir()):
        raise InputError(
            f"holds files already (an earlier run?): give {option} an empty or new folder, "
            "or --force to write over them",
            path=path,
        )
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise OutputError(f"cannot create the folder: {err.strerror}", path=path) from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise OutputError("cannot write into the folder: permission denied", path=path)
    return path


def check_output_file(
    path: Path,
    *,
    suffixes: Iterable[str],
    inputs: Iterable[Path] = (),
    option: str = "--plot",
) -> Path:
    """Make sure ``path`` names a file of a known kind that can be written.

    Its folder is created if missing. A folder, an unknown suffix or one of
    the ``inputs`` is bad input; a place that cannot be written is an
    :class:`OutputError`.
    """
    known = sorted(suffixes)
    example = ".png" if ".png" in known else known[0]
    if path.is_dir():
        raise InputError(
            f"{option} must name a file (such as fix{example}), not a folder", path=path
        )
    if path.suffix.lower() not in known:
        raise InputError(
            f"{option}: unknown file type {path.suffix or '(no suffix)'!r}; "
            f"use one of {', '.join(known)}",
            path=path,
        )
    for given in inputs:
        if _same_file(path, given):
            raise InputError(f"{option} would overwrite an input file", path=path)
    check_output_folder(path.parent if str(path.parent) else Path("."), option=option)
    if path.exists() and not os.access(path, os.W_OK):
        raise OutputError("cannot overwrite the file: permission denied", path=path)
    return path


def write_bytes(path: Path, data: bytes) -> None:
    """Write a whole file, turning a failure (full disk, permissions) into an OutputError."""
    from mast.io.atomic import write_atomic

    write_atomic(path, data)


def save_figure(fig: Any, path: Path, **kwargs: Any) -> None:
    """Save a matplotlib figure: drawn in memory in the format of ``path``'s suffix, then
    written whole by :func:`write_bytes`, so that a failed write (a full disk) is an
    :class:`OutputError` rather than an error the plotting library swallows."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lower().lstrip(".") or "png", **kwargs)
    write_bytes(path, buf.getvalue())
