"""Errors as one line: the file named whole, the problem's long runs cut short."""

from __future__ import annotations

from mast.errors import InputError, NoFixError, OutputError, describe, shorten


def test_a_long_path_is_named_whole_and_a_long_value_is_cut() -> None:
    path = "/tmp/" + "deep/" * 30 + "scan.csv"
    value = "x" * 500
    line = describe(InputError(f"column 'range_m': {value!r} is not a number", path=path, line=7))
    assert line.startswith(f"{path}, line 7: column 'range_m': ")
    assert "(502 characters)" in line
    assert len(line) < len(path) + 150


def test_control_characters_in_a_path_or_problem_are_escaped() -> None:
    line = describe(OutputError("cannot write\nhere", path="out\x0bdir/file.las"))
    assert "\n" not in line
    assert "\x0b" not in line
    assert line.startswith("out\\x0bdir/file.las: cannot write\\nhere")


def test_an_error_without_a_file_is_shortened_as_before() -> None:
    err = NoFixError("rejected", "y" * 300)
    assert describe(err) == shorten(str(err))
    assert describe(InputError("no file")) == "no file"
