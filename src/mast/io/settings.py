"""A run's settings as a TOML file: read onto MAST's configuration dataclasses
(``--config FILE.toml``), and the effective configuration written back beside the
results (``config.toml``), so that a run can be repeated exactly.

The file has one table a configuration (``[locator]``, ``[track]``, ``[sequence]``), and
one sub-table a nested one (``[locator.verification]``); every key is a field of the
dataclass of that name, with the units its name says. What a file leaves out keeps its
default. A key no configuration has, a value of the wrong kind (every setting is a
count, a flag, or a length, angle, share or threshold of 0 or more), or a value the
configuration refuses is bad input naming the file, the line and the key; a table the
command does not use is left alone (one file can serve ``mast locate`` and ``mast
track``). Fields that are inputs rather than settings (a prior's pose, given by
``--near``) are neither read nor written.

Written, the settings are one canonical text (:func:`settings_text`: every field, in the
dataclasses' order), so that the same settings always have the same SHA-256
(:func:`fingerprint`), which is what a JSON record names its configuration by.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
import tomllib
import types
import typing
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any, TypeVar

import tomli_w

from mast.errors import InputError
from mast.limits import MAX_METADATA_BYTES, read_bounded

__all__ = ["fingerprint", "from_table", "line_of", "read_settings", "settings_text"]

T = TypeVar("T")

#: Fields that are inputs of a run, not its settings: never read from or written to a file.
NOT_SETTINGS = frozenset({"prior"})


def read_settings(path: str | Path) -> tuple[dict[str, Any], str]:
    """The tables of a settings file, and its text (for the lines of later errors)."""
    p = Path(path)
    raw = read_bounded(p, limit=MAX_METADATA_BYTES, what="settings file", name="MAX_METADATA_BYTES")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise InputError("not UTF-8 text", path=p, line=line) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as err:
        found = re.search(r"\(at line (\d+), column \d+\)", str(err))
        what = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(err)) or "not TOML"
        at = int(found.group(1)) if found else None
        raise InputError(f"not a TOML settings file: {what}", path=p, line=at) from None


def line_of(text: str, table: str, key: str | None) -> int | None:
    """The line of ``key`` in ``[table]`` (of the table's header when ``key`` is None)."""
    current = ""
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        header = re.fullmatch(r"\[\s*([^\[\]]+?)\s*\]\s*(#.*)?", line)
        if header:
            current = re.sub(r"\s*\.\s*", ".", header.group(1)).replace('"', "")
            if key is None and current == table:
                return number
            continue
        if key is not None and current == table and re.match(rf'"?{re.escape(key)}"?\s*=', line):
            return number
    return None


def _value(kind: Any, value: Any) -> Any:
    """``value`` as a field of type ``kind``, or raise TypeError saying what was expected."""
    origin = typing.get_origin(kind)
    if origin in (types.UnionType, typing.Union):
        options = [k for k in typing.get_args(kind) if k is not type(None)]
        return _value(options[0], value)
    if kind is bool:
        if not isinstance(value, bool):
            raise TypeError("true or false")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise TypeError("a whole number, 0 or more")
        return value
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise TypeError("a number")
        if math.isnan(value) or value < 0:
            raise TypeError("a number, 0 or more")
        return float(value)
    if kind is str:
        if not isinstance(value, str):
            raise TypeError("a string")
        return value
    if origin is tuple:
        (item, *_rest) = typing.get_args(kind)
        if not isinstance(value, list):
            raise TypeError("a list")
        return tuple(_value(item, v) for v in value)
    raise TypeError(f"a {kind}")  # pragma: no cover - a field type no configuration has


def from_table(cls: type[T], table: Mapping[str, Any], *, path: Path, text: str, where: str) -> T:
    """An instance of the dataclass ``cls`` from ``table`` (the TOML table ``[where]``);
    what the table leaves out keeps ``cls``'s default."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    kw: dict[str, Any] = {}
    for key, value in table.items():
        line = line_of(text, where, key)
        if key not in fields or key in NOT_SETTINGS:
            known = ", ".join(sorted(set(fields) - NOT_SETTINGS))
            raise InputError(
                f"[{where}] has no setting {key!r}; known: {known}", path=path, line=line
            )
        kind = hints[key]
        if isinstance(kind, type) and dataclasses.is_dataclass(kind):
            if not isinstance(value, dict):
                raise InputError(f"[{where}] {key} must be a table", path=path, line=line)
            kw[key] = from_table(kind, value, path=path, text=text, where=f"{where}.{key}")
            continue
        try:
            kw[key] = _value(kind, value)
        except TypeError as err:
            raise InputError(
                f"[{where}] {key} must be {err}, not {value!r}", path=path, line=line
            ) from None
    try:
        return cls(**kw)
    except (TypeError, ValueError) as err:
        # A configuration's refusal names its field first: the line is that key's.
        named = next((k for k in table if str(err).startswith(f"{k} ")), None)
        at = line_of(text, where, named)
        raise InputError(f"[{where}] {err}", path=path, line=at) from None


def _table(obj: object) -> dict[str, Any]:
    out: dict[str, Any] = {}
    nested: dict[str, Any] = {}
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        if f.name in NOT_SETTINGS or value is None:
            continue
        if dataclasses.is_dataclass(value):
            nested[f.name] = _table(value)
        elif isinstance(value, tuple):
            out[f.name] = list(value)
        else:
            out[f.name] = value
    return {**out, **nested}  # a table's own keys before its sub-tables


def settings_text(tables: Mapping[str, object], *, skip: Collection[str] = ()) -> str:
    """The TOML text of configuration dataclasses, one table each (``tables``: name ->
    instance), their fields in ``skip`` left out (a field another table holds); every
    float written so that it reads back to the same float."""
    data: dict[str, Any] = {}
    for name, obj in tables.items():
        table = _table(obj)
        for key in skip:
            table.pop(key, None)
        data[name] = table
    return tomli_w.dumps(data)


def fingerprint(text: str) -> str:
    """The SHA-256 of a settings text (what a JSON record names its configuration by)."""
    return hashlib.sha256(text.encode("utf-8")).hexdigest()
