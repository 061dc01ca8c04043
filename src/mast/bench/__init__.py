"""Benchmarks that print and write figures (not timed tests): accuracy against the
Cramér-Rao bound and the honesty of the reported uncertainty, robustness, the field's
scenes, speed, memory, mine-wide surveys, live streams, long drives and fuzzed inputs;
``mast bench`` (:mod:`mast.bench.cli`) runs each.

Nothing is imported here: a benchmark's child process imports only the module it needs
(:mod:`mast.bench.rss` after its measured work, for instance).
"""
