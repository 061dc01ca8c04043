"""The package's exceptions: one root, a few meaningful kinds.

Library code raises these; only the command line turns them into a one-line
message and an exit status (2 for bad input, 3 for no fix, 4 when an output
cannot be written).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["BeaconError", "InputError", "MastError", "NoFixError", "OutputError"]


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
