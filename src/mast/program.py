"""The ``mast`` program: the field's commands (:mod:`mast.cli`) and the benchmarks'
``mast bench`` group (:mod:`mast.bench.cli`) on one command line; ``mast`` and
``python -m mast`` run :func:`main`."""

from mast.bench.cli import bench_app
from mast.cli import app, main

__all__ = ["app", "bench_app", "main"]
