"""The package's exceptions: one root, a few meaningful kinds.

Library code raises these; only the command line turns them into a one-line
message and an exit status (2 for bad input, 3 for no fix, 4 when an output
cannot be written).
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "BeaconError",
    "InputError",
    "MastError",
    "NoFixError",
    "OutputError",
    "describe",
    "printable",
    "quoted",
    "shorten",
]

#: Longest piece of a user's value an error message repeats.
ECHO_CHARS = 60


class MastError(Exception):
    """Root of every error MAST raises on purpose."""


class InputError(MastError):
    """A file or a value given to MAST is malformed or inconsistent.

    The message names the file and, where there is one, the line.
    """

    def __init__(self, problem: str, *, path: str | Path | None = None, line: int | None = None):
        self.problem = problem
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = self.path if line is None else f"{self.path}, line {line}"
            where += ": "
        super().__init__(where + problem)


class OutputError(MastError):
    """An output (a file, a folder, standard output) cannot be written; names it."""

    def __init__(self, problem: str, *, path: str | Path | None = None):
        self.problem = problem
        self.path = None if path is None else str(path)
        super().__init__(problem if self.path is None else f"{self.path}: {problem}")


class BeaconError(InputError):
    """A beacon's geometry cannot be identified in a scan (lengths, deflections)."""


class NoFixError(MastError):
    """The locator could not produce a trustworthy fix; ``reason`` says why."""

    def __init__(self, reason: str, detail: str):
        self.reason = reason
        self.detail = detail
        super().__init__(f"no fix ({reason}): {detail}")


def quoted(value: object, limit: int = ECHO_CHARS) -> str:
    """``repr(value)`` for an error message, cut to about ``limit`` characters."""
    text = repr(value) if isinstance(value, str) else repr(str(value))
    if len(text) <= limit:
        return text
    return f"{text[: limit - 1]}...' ({len(str(value))} characters)"


def printable(text: str) -> str:
    """``text`` on one line: control characters and line separators written as escapes
    (``\\x0b``)."""
    return "".join(
        ch if ch == " " or not _unprintable(ch) else ch.encode("unicode_escape").decode("ascii")
        for ch in text
    )


def shorten(message: str, limit: int = ECHO_CHARS) -> str:
    """``message`` on one line (:func:`printable`), with every run of more than ``limit``
    characters without a space cut short (a long value a user typed or a file held)."""
    words = printable(message).split(" ")
    out = [w if len(w) <= limit else f"{w[: limit - 1]}...({len(w)} characters)" for w in words]
    return " ".join(out)


def describe(err: MastError, limit: int = ECHO_CHARS) -> str:
    """An error as one line: the file it names, whole however long its path (the user
    must be able to find it), then the line and the problem, the problem's long runs
    cut short (:func:`shorten`)."""
    path = getattr(err, "path", None)
    problem = getattr(err, "problem", None)
    if path is None or problem is None:
        return shorten(str(err), limit)
    line = getattr(err, "line", None)
    where = printable(str(path)) + ("" if line is None else f", line {line}")
    return f"{where}: {shorten(problem, limit)}"


def _unprintable(ch: str) -> bool:
    import unicodedata

    return unicodedata.category(ch) in {"Cc", "Cf", "Zl", "Zp", "Cs"} or ch.isspace()
