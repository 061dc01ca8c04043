"""Shared fixtures: the simulator is the fixture factory."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from mast.sim import Scene, paper_scene


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
