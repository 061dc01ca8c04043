"""The package's layers, checked over its import graph.

Every import (at the top of a module, inside a function, or for type checking only) of
one MAST module by another is read from the source. A package imports only from the
layers below its own (never upward, never sideways into a sibling of its layer); no
modules import each other in a loop; and no module reaches into another package's
private names. The layers, lowest first, are the ones docs/design.md and the README's
layout section draw.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from functools import cache
from pathlib import Path

import pytest

import mast

SRC = Path(mast.__file__).resolve().parent

#: The layers, lowest first: a package may import from the layers below its own.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("errors",),  # what every module may raise
    ("limits",),  # the named read limits, and the errors past them
    ("core",),  # frames, scans, beacons, geometry, noise, survey index, compiled kernels
    ("io",),  # every file contract: readers and writers
    ("pipeline",),  # the per-scan method, stage by stage
    ("report", "sim"),  # the JSON record, text report and HTML kit; the simulator
    ("runs", "live"),  # survey runs (`mast track`); live streams (`mast live`)
    ("cloud", "plan"),  # georeferencing clouds (`mast georef`); planning layouts (`mast plan`)
    ("cli",),  # the command line, one module per command
    ("bench",),  # the benchmarks and `mast bench`
    ("program",),  # the whole program: the command line and its benchmarks
    ("__main__",),  # `python -m mast`
)

#: The package's root (``mast/__init__.py``) re-exports the core types and errors.
ROOT_MAY_IMPORT = frozenset({"core", "errors"})

#: Private modules any package may import, and why: ``core._kernels`` is the compiled
#: machine code of every hot loop (the pipeline's stages and the runs' odometry call it
#: directly; it is private so that no user takes a kernel for the library's interface).
PRIVATE_ALLOWED = frozenset({"mast.core._kernels"})


def _layer_of() -> dict[str, int]:
    return {name: k for k, names in enumerate(LAYERS) for name in names}


@cache
def _modules(src: Path = SRC) -> dict[str, Path]:
    found = {}
    for path in sorted(src.rglob("*.py")):
        parts = ("mast", *path.relative_to(src).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The MAST module ``name`` is, or is in (an imported name inside a module)."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


@cache
def _imports(src: Path = SRC) -> dict[str, set[tuple[str, str | None]]]:
    """Each module's imports: (the module imported, the name taken from it or None)."""
    modules = _modules(src)
    out: dict[str, set[tuple[str, str | None]]] = defaultdict(set)
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("mast"):
                        target = _resolve(alias.name, modules)
                        if target is not None:
                            out[module].add((target, None))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    origin = ".".join([*base, *([node.module] if node.module else [])])
                else:
                    origin = node.module or ""
                if not origin.startswith("mast"):
                    continue
                for alias in node.names:
                    full = f"{origin}.{alias.name}"
                    if full in modules:  # a submodule imported from its package
                        out[module].add((full, None))
                    else:
                        target = _resolve(origin, modules)
                        if target is not None:
                            out[module].add((target, alias.name))
    return out


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_every_package_has_a_layer() -> None:
    layer = _layer_of()
    missing = sorted({_package(m) for m in _modules()} - set(layer) - {""})
    assert not missing, f"packages with no layer in LAYERS: {missing}"


def test_no_import_goes_up_or_sideways() -> None:
    layer = _layer_of()
    bad: set[str] = set()
    for module, targets in _imports().items():
        mine = _package(module)
        for target, _ in targets:
            theirs = _package(target)
            if mine == theirs or theirs == "":
                continue  # within a package; the root's version and re-exports
            if mine == "":
                if theirs not in ROOT_MAY_IMPORT:
                    bad.add(f"{module} -> {target}")
            elif layer[theirs] >= layer[mine]:
                bad.add(f"{module} -> {target}")
    assert not bad, "imports up or sideways:\n" + "\n".join(sorted(bad))


def test_no_import_loop() -> None:
    graph = {m: {t for t, _ in ts if t != m} for m, ts in _imports().items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    loops: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                loops.append(sorted(component))

    for module in sorted(_modules()):
        if module not in index:
            visit(module)
    assert not loops, f"modules importing each other in a loop: {loops}"


def test_no_package_takes_another_packages_private_names() -> None:
    bad = []
    for module, targets in _imports().items():
        mine = _package(module)
        for target, name in targets:
            theirs = _package(target)
            if theirs == mine or target in PRIVATE_ALLOWED:
                continue
            private_module = any(
                p.startswith("_") and not p.startswith("__") for p in target.split(".")
            )
            private_name = name is not None and name.startswith("_") and not name.startswith("__")
            if private_module or private_name:
                bad.append(f"{module} takes {target}{'.' + name if name else ''}")
    assert not bad, "private names taken across packages:\n" + "\n".join(sorted(bad))


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from mast.core.pose import Pose2D\n", {("mast.core.pose", "Pose2D")}),
        ("from mast.core import pose\n", {("mast.core.pose", None)}),
        ("from mast.core import _kernels\n", {("mast.core._kernels", None)}),
        ("import mast.io.bags\n", {("mast.io.bags", None)}),
        ("def f():\n    from mast.sim.scene import Scene\n", {("mast.sim.scene", "Scene")}),
        ("from ..sim.scene import Scene\n", {("mast.sim.scene", "Scene")}),
        ("from . import other\n", {("mast.cli.other", None)}),
        ("import numpy\nfrom typing import Any\n", set()),
    ],
)
def test_the_graph_reads_every_form_of_import(
    source: str, expected: set[tuple[str, str | None]], tmp_path: Path
) -> None:
    # The checks above are only as good as the reading: each form of import is found.
    modules = ("__init__", "core/__init__", "core/pose", "core/_kernels", "io/__init__",
               "io/bags", "sim/__init__", "sim/scene", "cli/__init__", "cli/other")  # fmt: skip
    for module in modules:
        (tmp_path / f"{module}.py").parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f"{module}.py").write_text("")
    (tmp_path / "cli" / "probe.py").write_text(source)
    assert _imports(tmp_path).get("mast.cli.probe", set()) == expected
