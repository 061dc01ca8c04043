"""Fuzzing benchmark: damaged and crafted inputs through every reader and output path.

Builds valid seed files (a survey, scan CSVs, ROS 1 bags plain and bz2, ROS 2
sqlite3 and MCAP bags, a drift CSV and DXF), then runs ``mast`` on damaged
copies of them (random bytes, truncations, bit flips, spliced ranges, values
no survey holds, huge lines, lying chunk sizes, decompression bombs, YAML
alias bombs, file names escaping the bag) and on hostile output paths (a
missing or read-only place, a file in the way, an unknown suffix, the input
itself, a name too long, a disk that fills part-way, a closed pipe).

Each case runs the real command line (:func:`mast.cli.main`) in a
forked child of one warmed-up process, under an address-space limit and a
file-size limit (the disk that fills), with a time limit. Per case it
records the exit status, the standard error, the child's peak resident
memory above what it inherited at the fork (``wait4``'s peak less the
resident size the child starts with, so a warmed-up parent of any size, a
test runner's included, does not count; the parent's shared-library pages
the child touches again are charged to it, as the kernel does not copy
file-backed mappings' page entries at a fork) and its time; and it counts
as failures:

* a traceback or an undocumented exit status (anything but 0, 2, 3, 4; an
  internal error, 70, is a bug), or an error that is not one ``mast:`` line;
* a peak of its own above 1 GiB or twice the undamaged run's, whichever is
  larger, or a run stopped by the address-space limit;
* a run taking more than ten times the undamaged file's processor time (and a
  second), or stopped by its time limit;
* a fix from a damaged file that differs from the undamaged file's fix of
  the same scan by more than five combined standard deviations (and 1 mm,
  1 arc-second), or is one where the undamaged file gave none;
* an output left behind half-written after a failure (a ``.part`` file, or
  the target of a failed write).

The package follows the benchmark's stages: :mod:`.seeds` (the undamaged inputs),
:mod:`.mutations` (the damage), :mod:`.cases` (each case's files and arguments),
:mod:`.children` (each case in a limited child process), :mod:`.run` (judging,
counting and :func:`run_fuzz`); :mod:`.model` holds the records and the bounds.
"""

from __future__ import annotations

from mast.bench.fuzz.model import FuzzCase, FuzzResult, FuzzSummary
from mast.bench.fuzz.run import run_fuzz

__all__ = ["FuzzCase", "FuzzResult", "FuzzSummary", "run_fuzz"]
