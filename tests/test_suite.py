"""The suite's own arrangements: the tests the workers may spread (tests/conftest.py)."""

from __future__ import annotations

import pytest

from tests.conftest import SPREAD, _spread, named_test


@pytest.mark.parametrize("nodeid", SPREAD)
def test_every_spread_test_is_a_test(nodeid: str) -> None:
    assert nodeid.split("::")[1].startswith("test_")
    assert callable(named_test(nodeid)), nodeid


def test_no_spread_test_needs_a_module_scoped_fixture(request: pytest.FixtureRequest) -> None:
    """A test of SPREAD may run on the other worker than its module's others: a
    module-scoped fixture of its module would then be built twice (or, were it shared
    state, differ). Checked on the spread tests this session collected (all of them in
    ``make test``)."""
    for item in request.session.items:
        if _spread(item.nodeid) is None:
            continue
        info = getattr(item, "_fixtureinfo", None)
        assert info is not None, item.nodeid
        for name, defs in info.name2fixturedefs.items():
            assert defs[-1].scope in ("function", "session"), f"{item.nodeid}: {name}"


def test_a_spread_test_is_known_by_its_name_with_or_without_parameters() -> None:
    first = SPREAD[0]
    assert _spread(first) == 0
    assert _spread(f"{first}[mast demo]") == 0
    assert _spread(f"{first}_not") is None
    assert _spread("tests/test_readme.py::test_the_readme_has_its_commands") is None
