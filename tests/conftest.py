"""Shared fixtures (the simulator is the fixture factory), and how the test workers
share the tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from mast.sim import Scene, paper_scene

#: The tests that may run on another worker than their module's others, heaviest first:
#: they need none of their module's module-scoped fixtures, and no port or folder of
#: theirs (:func:`pytest_xdist_make_scheduler`; tests/test_suite.py checks both).
SPREAD = (
    "tests/test_readme.py::test_every_readme_command_runs_on_the_examples",
    "tests/test_cloud/test_georef.py::test_drift_is_corrected_along_the_trajectory",
    "tests/test_pipeline/test_tracking.py::"
    "test_the_window_search_ranks_and_picks_its_poses_as_the_reference",
    "tests/test_io/test_hostile.py::test_the_fuzzing_campaign_finds_nothing",
    "tests/test_cli/test_commands.py::test_demo_prints_the_table2_comparison",
    "tests/test_io/test_hostile.py::test_segmentation_memory_is_linear_in_the_beams",
    "tests/test_pipeline/test_locator3d.py::test_no_simulated_frame_gets_a_wrong_or_overconfident_fix",
    "tests/test_cloud/test_georef.py::"
    "test_with_drift_a_beacon_detection_missed_is_found_where_the_correction_puts_it",
    "tests/test_cloud/test_georef.py::test_a_cloud_too_sparse_for_beacons_is_refused_saying_so",
)


def _spread(nodeid: str) -> int | None:
    """Where the test of ``nodeid`` (its parameters aside) is in :data:`SPREAD`."""
    test = nodeid.split("[", 1)[0]
    return SPREAD.index(test) if test in SPREAD else None


@pytest.hookimpl(tryfirst=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """Under ``--dist loadscope`` (the Makefile's), each module's tests on one worker, as
    ``--dist loadfile`` sends them, so that its module-scoped fixtures are built once;
    but each test of :data:`SPREAD` a unit of its own, sent first (the workers put them
    first: :func:`pytest_collection_modifyitems`), so that the two workers share the
    heaviest and neither is left with a long one at the end. (``--dist loadgroup`` would
    do this by marks, but it renames the items' ``_nodeid``, which pytest 9 no longer
    reads: with pytest-xdist 3.8 its groups are silently not kept.)"""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class Scheduling(LoadScopeScheduling):  # type: ignore[misc]
        def _split_scope(self, nodeid: str) -> str:
            return nodeid if _spread(nodeid) is not None else nodeid.split("::", 1)[0]

    config.option.loadscopereorder = False  # the collection's order, heaviest first
    return Scheduling(config, log)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The tests of :data:`SPREAD` first, in its order; the rest as collected."""
    items.sort(key=lambda item: (_spread(item.nodeid) is None, _spread(item.nodeid) or 0))


def pytest_sessionstart(session: pytest.Session) -> None:
    """Under xdist (``-n``), the controller compiles the numba kernels into their cache
    before the workers start, once: else each worker, and each ``mast`` process the
    tests start in the first minutes, compiles them again (a minute of a core each)."""
    from mast.cli.warmup import compile_3d

    config = session.config
    if hasattr(config, "workerinput") or not config.getoption("numprocesses", None):
        return
    compile_3d()  # every kernel the 2D and 3D locators and the odometry call


def named_test(nodeid: str) -> Callable[..., Any]:
    """The test function a node id (``path::name``, no parameters) names."""
    import importlib

    path, name = nodeid.split("::")
    module = importlib.import_module(path.removesuffix(".py").replace("/", "."))
    test: Callable[..., Any] = getattr(module, name)
    return test


@pytest.fixture
def write_text(tmp_path: Path) -> Callable[..., Path]:
    """Write a text (or bytes) file in tmp_path and return its path."""

    def _write(name: str, content: str | bytes) -> Path:
        p = tmp_path / name
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content, encoding="utf-8")
        return p

    return _write


@pytest.fixture(scope="session")
def parallel_scene() -> Scene:
    return paper_scene("parallel")
