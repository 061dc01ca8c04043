"""Shared pieces of the CSV readers: decoding, header checks, number parsing."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType
from typing import Any

from mast import limits
from mast.errors import InputError
from mast.limits import read_bounded

__all__ = [
    "STREAM_CHUNK_BYTES",
    "CsvRows",
    "CsvStream",
    "IrregularError",
    "parse_number",
    "parse_within",
    "read_header",
]

#: Bytes the streaming reader (:class:`CsvStream`) takes from the disk at a time: its
#: memory, whatever the size of the file.
STREAM_CHUNK_BYTES = 1 << 16


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


def parse_within(
    text: str,
    *,
    column: str,
    path: Path,
    line: int,
    bound: str = "MAX_COORDINATE_M",
    what: str = "grid coordinate",
) -> float:
    """A finite number no larger in magnitude than ``mast.limits.<bound>`` (metres);
    errors name the file, line, column and the bound."""
    value = parse_number(text, column=column, path=path, line=line)
    most = float(getattr(limits, bound))
    if abs(value) > most:
        raise InputError(
            f"column {column!r}: {value:g} m is beyond ±{most:g} m, not a plausible {what} "
            f"(mast.limits.{bound})",
            path=path,
            line=line,
        )
    return value


def read_header(
    reader: Any, path: Path, *, required: tuple[str, ...], optional: tuple[str, ...] = ()
) -> tuple[int, dict[str, int]]:
    """Read up to the first non-blank row of a ``csv.reader`` and check it as the header.

    Returns the header's line number and the position of every required and
    optional column found (column names matched without regard to case or
    surrounding spaces; the first of repeated names counts).
    """
    header: list[str] | None = None
    try:
        for row in reader:
            if any(cell.strip() for cell in row):
                header = row
                break
    except csv.Error as err:
        raise InputError(f"malformed CSV: {err}", path=path, line=reader.line_num) from None
    if header is None:
        raise InputError("file is empty; expected a header row", path=path)
    header_line = int(reader.line_num)
    names = [h.strip().lower() for h in header]
    missing = [c for c in required if c not in names]
    found = ",".join(n for n in names if n)
    if missing:
        raise InputError(
            f"header lacks required column(s) {', '.join(missing)} "
            f"(expected {','.join(required)}; found {found or 'nothing'})",
            path=path,
            line=header_line,
        )
    columns = {c: names.index(c) for c in (*required, *optional) if c in names}
    return header_line, columns


class IrregularError(Exception):
    """The streaming reader met something it leaves to the whole-file reader.

    :class:`CsvStream` judges only plain, valid input; anything else (a bad
    byte, a NUL, malformed CSV, a value it does not read itself) raises this,
    and its caller reads the file again with :class:`CsvRows`, which either
    accepts it or names the file, the line and the problem as always.
    """


class _NulGuard(io.RawIOBase):
    """A raw binary file that refuses (:class:`IrregularError`) any chunk holding a NUL byte."""

    def __init__(self, raw: io.RawIOBase):
        super().__init__()
        self._raw = raw
        self._since_newline = 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        n = self._raw.readinto(buffer)
        if n:
            data = memoryview(buffer)[:n].tobytes()
            if data.find(b"\x00") >= 0:
                raise IrregularError("NUL byte")
            try:  # every line of the chunk, with what came of the first before it
                limits.check_lines(data, "", carried=self._since_newline)
            except InputError:
                raise IrregularError("long line") from None
            last = data.rfind(b"\n")
            self._since_newline = (self._since_newline + n) if last < 0 else n - last - 1
        return int(n or 0)

    def close(self) -> None:
        self._raw.close()
        super().close()


class CsvStream:
    """Stream a CSV file with a header row: rows as lists of text, a chunk at a time.

    Memory stays at :data:`STREAM_CHUNK_BYTES` and one row whatever the size of
    the file (where :class:`CsvRows` holds the whole file, decoded). Decoding
    (UTF-8, a byte-order mark skipped), line endings and quoting are those of
    :class:`CsvRows`. It judges no error itself: a decoding error surfaces as
    ``UnicodeDecodeError``, a NUL byte as :class:`IrregularError`, malformed CSV as
    ``csv.Error``, a bad header as :class:`~mast.errors.InputError`; callers
    fall back to :class:`CsvRows` for all of them, so that every error is named
    exactly as the whole-file reader names it. Use it as a context manager.
    """

    def __init__(
        self, path: str | Path, *, required: tuple[str, ...], optional: tuple[str, ...] = ()
    ):
        self.path = Path(path)
        if not self.path.is_file():  # a pipe or a device is read once, whole, by CsvRows
            raise IrregularError("not a regular file")
        raw = io.FileIO(self.path, "r")
        self._text = io.TextIOWrapper(
            io.BufferedReader(_NulGuard(raw), STREAM_CHUNK_BYTES),
            encoding="utf-8-sig",
            newline="",
        )
        try:
            self.reader = csv.reader(self._text)
            self.header_line, self.columns = read_header(
                self.reader, self.path, required=required, optional=optional
            )
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        self._text.close()

    def __enter__(self) -> CsvStream:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class CsvRows:
    """Read a CSV file with a header row, as (line number, {column: text}) pairs.

    Column names are matched without regard to case or surrounding spaces;
    extra columns are ignored. Blank lines are skipped.
    """

    def __init__(
        self, path: str | Path, *, required: tuple[str, ...], optional: tuple[str, ...] = ()
    ):
        self.path = Path(path)
        raw = read_bounded(self.path, what="CSV file")
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
        self.header_line, self.columns = read_header(
            self._reader, self.path, required=required, optional=optional
        )
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
