"""Paths the tests share."""

from pathlib import Path

#: ../shared/data beside the repository (real scans recorded by others).
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
