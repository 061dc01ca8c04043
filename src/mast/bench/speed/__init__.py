"""Speed benchmark (issue 11): a fix per scan, whole runs, a mine-wide survey, start-up,
and a general-purpose registration library beside MAST on the same scans.

Six measurements, printed as tables (figures, not timed assertions):

1. ``locate`` per scan, one core, on scans held in memory (no file parsing): a
   simulated drive (:func:`mast.sim.drive_scene`, 270 deg at 0.25 deg, 1081 beams,
   12 mm noise), keeping the scans that give a fix or show two beacons (five
   returns or more each); the same drive seen by the simulator's 360 deg scanner
   at 0.2 deg (1800 beams). Median, 95th percentile and maximum, with the pose
   errors against the truth. Then per stage: the stage functions the locator
   calls (segmentation, identification, hypotheses, verification with its ICP,
   adjustment with the integrity tests) are wrapped with a clock for a second
   pass; what no stage function covers (the survey index lookup, the choice
   between verified poses, the global test, the record) is ``other``. Last, the
   functions with the most own time under ``cProfile``.
2. Whole runs: simulated drive bags through reading only (``read_laserscans``),
   ``mast locate BAG --format json`` (standard output to ``/dev/null``) and
   ``mast track BAG --out DIR``, each in a fresh process timed from before its
   first ``mast`` import to its exit, with that process's peak resident memory.
3. A mine-wide survey: the mine-wide benchmark's owed scans
   (:func:`mast.bench.minewide.run_minewide`, 1081 beams) against their
   scene's own two or three beacons and against a survey of ``beacons`` (the
   same plus copies of their designs in other drifts, out of reach).
4. Start-up: ``mast --help`` in a fresh process.
5. Peer: small_gicp's point-to-plane ICP aligning each fixed scan's beacon returns
   (the beams the simulator says hit a beacon: a head start MAST does not get)
   to the surveyed panels, sampled every 5 mm and extruded +-10 mm vertically so
   that small_gicp can estimate their normals (its Python API takes no given
   normals), starting from the true pose moved 0.2 m and 2 deg. Its time per scan
   and pose error beside ``locate``'s on the same scans. small_gicp is optional
   (``pip install 'mast-survey[bench]'``); without it the benchmark says so.
6. Tracked scans: a 25 Hz drive located in sequence
   (:class:`~mast.pipeline.locator.SequenceLocator`, each scan first near the last
   fix), its scans timed apart by how they were found (fixed by the prior's own
   search, prior tried then the global search, no prior), the tracked fixes' time
   per stage (as the locator clocks them on each fix, ``Fix.stages_s``) and errors,
   and the peer on the same scans'
   beacon returns from the pose of each fix's prior.

Run: ``mast bench speed`` (or ``python -m mast.bench.speed``).

The package follows the measurements: :mod:`.scans` (the scans timed), :mod:`.stages`
(1, a fix per scan and per stage), :mod:`.runs` (2, 3, 4 and 6: whole runs, the
mine-wide survey, start-up, tracked scans), :mod:`.peer` (5), :mod:`.run` (the
benchmark and its tables); :mod:`.model` holds the figures' records and the defaults.
"""

from __future__ import annotations

from mast.bench.speed.model import (
    DEFAULT_BAG_SCANS,
    DEFAULT_LOCATE_SCANS,
    DEFAULT_SCANS_360,
    DEFAULT_TRACK_SCANS,
    DEFAULT_TRACKED_SCANS,
    PEER_MISSING,
    LocateSpeed,
    PeerSpeed,
    ProcessRun,
    SpeedFigures,
    StartupSpeed,
    Stats,
    TrackedSpeed,
)
from mast.bench.speed.peer import measure_peer
from mast.bench.speed.run import run_speed
from mast.bench.speed.runs import measure_minewide, measure_runs, measure_startup, measure_tracked
from mast.bench.speed.scans import KeptScans, kept_scans
from mast.bench.speed.stages import measure_locate

__all__ = [
    "DEFAULT_BAG_SCANS",
    "DEFAULT_LOCATE_SCANS",
    "DEFAULT_SCANS_360",
    "DEFAULT_TRACKED_SCANS",
    "DEFAULT_TRACK_SCANS",
    "PEER_MISSING",
    "KeptScans",
    "LocateSpeed",
    "PeerSpeed",
    "ProcessRun",
    "SpeedFigures",
    "StartupSpeed",
    "Stats",
    "TrackedSpeed",
    "kept_scans",
    "measure_locate",
    "measure_minewide",
    "measure_peer",
    "measure_runs",
    "measure_startup",
    "measure_tracked",
    "run_speed",
]
