"""The figures the speed benchmark measures, its defaults and the stages it clocks."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.bench.minewide import MinewideSummary

__all__ = [
    "DEFAULT_BAG_SCANS",
    "DEFAULT_LOCATE_SCANS",
    "DEFAULT_MINEWIDE_POSES",
    "DEFAULT_SCANS_360",
    "DEFAULT_STARTUP_RUNS",
    "DEFAULT_SURVEY_BEACONS",
    "DEFAULT_TRACKED_SCANS",
    "DEFAULT_TRACK_SCANS",
    "IN_VIEW_RETURNS",
    "OTHER_STAGE",
    "PEER_EPSILON",
    "PEER_HEIGHTS_M",
    "PEER_MAX_CORRESPONDENCE_M",
    "PEER_MAX_ITERATIONS",
    "PEER_MISSING",
    "PEER_NEIGHBOURS",
    "PEER_OFFSET_M",
    "PEER_STEP_M",
    "PEER_TURN_DEG",
    "PROFILE_SCANS",
    "PROFILE_TOP",
    "SCANNER_360",
    "STAGES",
    "LocateSpeed",
    "PeerSpeed",
    "ProcessRun",
    "SpeedFigures",
    "StartupSpeed",
    "Stats",
    "TrackedSpeed",
]

#: Scans located per scanner: 1081 beams, then the 360 degree scanner's 1800.
DEFAULT_LOCATE_SCANS = 300
DEFAULT_SCANS_360 = 100
#: Bag lengths read and located by ``mast locate``, and those tracked (``mast track``
#: runs at about 10 scans a second today).
DEFAULT_BAG_SCANS = (1_000, 3_000)
DEFAULT_TRACK_SCANS = (1_000,)
#: The mine-wide survey's size, and the owed scans located against it.
DEFAULT_SURVEY_BEACONS = 200
DEFAULT_MINEWIDE_POSES = 40
#: ``mast --help`` runs, of which the median is quoted.
DEFAULT_STARTUP_RUNS = 5

#: Scans of a 25 Hz drive located in sequence, each near the last fix (section 6).
DEFAULT_TRACKED_SCANS = 600

#: The simulator's 360 degree scanner (1800 beams at 0.2 degrees).
SCANNER_360 = "spinning-360-0.2"
#: A beacon is in view with at least this many valid returns.
IN_VIEW_RETURNS = 5
#: Scans profiled with cProfile, and the functions listed.
PROFILE_SCANS = 50
PROFILE_TOP = 8

#: The peer's start: the true pose moved this far in a random direction and turned
#: this much either way.
PEER_OFFSET_M = 0.2
PEER_TURN_DEG = 2.0
#: The peer's model: panels sampled every ``PEER_STEP_M`` along and at these heights
#: (a vertical strip, so that a neighbourhood has a plane's normal), normals from
#: ``PEER_NEIGHBOURS`` neighbours.
PEER_STEP_M = 0.005
PEER_HEIGHTS_M = (-0.010, -0.005, 0.0, 0.005, 0.010)
PEER_NEIGHBOURS = 20
#: The peer's registration settings: correspondences within a metre (0.2 m and 2 deg
#: move a return 20 m away by 0.9 m), convergence far tighter than its defaults
#: (0.1 deg, 1 mm) so that its accuracy is not cut short, iterations to match.
PEER_MAX_CORRESPONDENCE_M = 1.0
PEER_MAX_ITERATIONS = 100
PEER_EPSILON = 1e-7
#: What the benchmark says when the peer library is not installed.
PEER_MISSING = (
    "peer not installed: pip install 'mast-survey[bench]' "
    "(from a checkout: pip install -e '.[bench]')"
)

#: The stage functions the locator calls, by their names in ``mast.pipeline.locator``.
STAGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("segmentation", ("segment_scan",)),
    ("identification", ("identify_panels",)),
    ("hypotheses", ("pose_hypotheses", "prior_hypotheses")),
    ("verification (ICP)", ("verify",)),
    (
        "adjustment + integrity",
        (
            "adjust_on_panels",
            "snoop",
            "exclude_inconsistent",
            "residual_summary",
            "cramer_rao_bound",
            "survey_covariance",
        ),
    ),
)
OTHER_STAGE = "other"


@dataclass(frozen=True, slots=True)
class Stats:
    """Median, 95th percentile, maximum and mean of some values (``nan`` when none)."""

    median: float
    p95: float
    max: float
    mean: float
    count: int

    @classmethod
    def of(cls, values: Sequence[float] | NDArray[np.float64]) -> Stats:
        v = np.asarray(values, dtype=float)
        if v.size == 0:
            return cls(math.nan, math.nan, math.nan, math.nan, 0)
        return cls(
            float(np.median(v)),
            float(np.percentile(v, 95)),
            float(np.max(v)),
            float(np.mean(v)),
            int(v.size),
        )

    def cells(self, fmt: str = "8.2f") -> str:
        return f"{self.median:{fmt}} {self.p95:{fmt}} {self.max:{fmt}}"


@dataclass(frozen=True, slots=True)
class LocateSpeed:
    """``locate`` on scans held in memory: per-scan times, per stage, and the errors.

    Times in milliseconds; errors of the fixes against the truth, position in mm
    and azimuth in arc-seconds; ``hot`` is (function, share of the profiled time).
    """

    scanner: str
    beams: int
    scans: int
    fixed: int
    time_ms: Stats
    stages_ms: tuple[tuple[str, Stats], ...]
    wrapped_total_ms: Stats
    position_err_mm: Stats
    azimuth_err_arcsec: Stats
    hot: tuple[tuple[str, float], ...]
    profiled_scans: int


@dataclass(frozen=True, slots=True)
class ProcessRun:
    """One step of a whole run in a fresh process: its time, its peak memory."""

    step: str
    scans: int
    seconds: float
    peak_mb: float
    exit_code: int

    @property
    def scans_per_s(self) -> float:
        return self.scans / self.seconds if self.seconds > 0 else math.nan


@dataclass(frozen=True, slots=True)
class StartupSpeed:
    """Wall time of ``mast --help`` and of a bare interpreter, fresh processes, seconds."""

    help_s: tuple[float, ...]
    python_s: tuple[float, ...]

    @property
    def help_median_s(self) -> float:
        return statistics.median(self.help_s)

    @property
    def python_median_s(self) -> float:
        return statistics.median(self.python_s)


@dataclass(frozen=True, slots=True)
class PeerSpeed:
    """The peer and ``locate`` on the same scans: time (ms) and pose errors."""

    library: str
    scans: int
    model_points: int
    model_build_ms: float
    time_ms: Stats
    position_err_mm: Stats
    azimuth_err_arcsec: Stats
    converged: float
    mast_time_ms: Stats
    mast_position_err_mm: Stats
    mast_azimuth_err_arcsec: Stats


@dataclass(frozen=True, slots=True)
class TrackedSpeed:
    """A drive located in sequence (:class:`~mast.pipeline.locator.SequenceLocator`).

    Milliseconds per scan by how it was found: ``tracked_ms`` the scans fixed by their
    prior's own search (``narrow`` of them in the constant-velocity window), ``lost_ms``
    those whose prior was tried and gave no fix (then the global search ran), and
    ``global_ms`` those without a prior. ``stages_ms`` splits the tracked fixes' time
    as section 1 does; the errors are those of the tracked fixes. ``peer_*``: the
    peer from each tracked fix's prior pose on the same scans (empty without it).
    """

    scans: int
    rate_hz: float
    fixed: int
    narrow: int
    tracked_ms: Stats
    lost_ms: Stats
    global_ms: Stats
    stages_ms: tuple[tuple[str, Stats], ...]
    position_err_mm: Stats
    azimuth_err_arcsec: Stats
    peer_ms: Stats
    peer_position_err_mm: Stats
    peer_azimuth_err_arcsec: Stats


@dataclass(frozen=True, slots=True)
class SpeedFigures:
    """Everything the benchmark measured, and the lines it printed."""

    locate: tuple[LocateSpeed, ...]
    runs: tuple[ProcessRun, ...]
    minewide: MinewideSummary | None
    startup: StartupSpeed | None
    peer: PeerSpeed | None
    peer_note: str
    lines: tuple[str, ...]
    tracked: TrackedSpeed | None = None
