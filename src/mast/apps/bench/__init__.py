"""Benchmarks that print and write figures (not timed tests): accuracy against the
Cramer-Rao bound and the honesty of the reported uncertainty, the detection limit
(fix rate against the evidence a scan holds), and locating against a mine-wide survey."""

from mast.apps.bench.accuracy import ACCURACY_CONFIGS, AccuracySummary, run_accuracy
from mast.apps.bench.detection import DetectionEvidence, detection_table
from mast.apps.bench.minewide import MinewideSummary, run_minewide

__all__ = [
    "ACCURACY_CONFIGS",
    "AccuracySummary",
    "DetectionEvidence",
    "MinewideSummary",
    "detection_table",
    "run_accuracy",
    "run_minewide",
]
