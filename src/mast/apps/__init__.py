"""Applications over the one pipeline: the ``mast`` command, reports, plots, the
demo, the paper's reproduction and the benchmarks. Nothing here does a stage's work."""

__all__: list[str] = []
