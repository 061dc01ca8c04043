"""Shared pieces of the CSV readers: decoding, header checks, number parsing."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterator
from pathlib import Path

from mast.errors import InputError

__all__ = ["CsvRows", "parse_number"]


def parse_number(
    text: str,
    *,
    column: str,
    path: Path,
    line: int,
    finite: bool = True,
) -> float:
    """Parse one numeric field; errors name the file, line and column."""
    s = text.strip()
    if not s:
        raise InputError(f"column {column!r} is empty", path=path, line=line)
    try:
        value = float(s)
    except ValueError:
        raise InputError(
            f"column {column!r}: {s[:40]!r} is not a number", path=path, line=line
        ) from None
    if finite and not math.isfinite(value):
        raise InputError(f"column {column!r}: {s!r} is not a finite number", path=path, line=line)
    return value


class CsvRows:
    """Read a CSV file with a header row, as (line number, {column: text}) pairs.

    Column names are matched without regard to case or surrounding spaces;
    extra columns are ignored. Blank lines are skipped.
    """

    def __init__(
        self, path: str | Path, *, required: tuple[str, ...], optional: tuple[str, ...] = ()
    ):
        self.path = Path(path)
        try:
            raw = self.path.read_bytes()
        except FileNotFoundError:
            raise InputError("file not found", path=self.path) from None
        except IsADirectoryError:
            raise InputError("is a folder, not a CSV file", path=self.path) from None
        except OSError as err:
            raise InputError(f"cannot read: {err.strerror}", path=self.path) from None
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError as err:
            line = raw[: err.start].count(b"\n") + 1
            raise InputError(
                f"not UTF-8 text (byte 0x{raw[err.start]:02x} at offset {err.start})",
                path=self.path,
                line=line,
            ) from None
        if "\x00" in text:
            line = text[: text.index("\x00")].count("\n") + 1
            raise InputError("contains a NUL byte; not a text CSV file", path=self.path, line=line)
        self._reader = csv.reader(io.StringIO(text, newline=""))
        header: list[str] | None = None
        try:
            for row in self._reader:
                if any(cell.strip() for cell in row):
                    header = row
                    break
        except csv.Error as err:
            raise InputError(
                f"malformed CSV: {err}", path=self.path, line=self._reader.line_num
            ) from None
        if header is None:
            raise InputError("file is empty; expected a header row", path=self.path)
        self.header_line = self._reader.line_num
        names = [h.strip().lower() for h in header]
        missing = [c for c in required if c not in names]
        found = ",".join(n for n in names if n)
        if missing:
            raise InputError(
                f"header lacks required column(s) {', '.join(missing)} "
                f"(expected {','.join(required)}; found {found or 'nothing'})",
                path=self.path,
                line=self.header_line,
            )
        self.columns: dict[str, int] = {}
        for c in (*required, *optional):
            if c in names:
                self.columns[c] = names.index(c)
        self._required = required

    def has(self, column: str) -> bool:
        return column in self.columns

    def __iter__(self) -> Iterator[tuple[int, dict[str, str]]]:
        width = max(self.columns[c] for c in self._required) + 1
        try:
            for row in self._reader:
                line = self._reader.line_num
                if not any(cell.strip() for cell in row):
                    continue
                if len(row) < width:
                    absent = [c for c in self._required if self.columns[c] >= len(row)]
                    raise InputError(
                        f"row has {len(row)} field(s); column(s) {', '.join(absent)} missing",
                        path=self.path,
                        line=line,
                    )
                # A short row may leave optional columns out: they read as empty.
                yield line, {c: row[i] if i < len(row) else "" for c, i in self.columns.items()}
        except csv.Error as err:
            raise InputError(
                f"malformed CSV: {err}", path=self.path, line=self._reader.line_num
            ) from None
