"""Benchmarks that print and write figures (not timed tests): accuracy against the
Cramer-Rao bound and the honesty of the reported uncertainty."""

from mast.apps.bench.accuracy import ACCURACY_CONFIGS, AccuracySummary, run_accuracy

__all__ = ["ACCURACY_CONFIGS", "AccuracySummary", "run_accuracy"]
