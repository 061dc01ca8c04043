"""What a survey run produces, shared by the tracker and the writers of its outputs."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["RunSummary"]


@dataclass(slots=True)
class RunSummary:
    """Counts and statistics of a run, for the report.

    Attributes
    ----------
    run : str
        The bag, as given.
    topic : str or None
        The LaserScan topic read.
    scans : int
        LaserScan messages read (decoded).
    fixes : int
        Scans fixed from beacons.
    placed : int
        Scans placed (fixed, or carried by odometry from a fix).
    skipped : int
        Messages that could not be decoded (each named in a warning).
    reasons : dict
        No-fix reason -> number of scans.
    reference_variances : list of (float, int)
        Reference variance and its degrees of freedom of every fix.
    chi2_tests : dict
        Outcome of the global test (``pass``, ``too_small``, ``too_large``) ->
        number of fixes.
    first_stamp_ns, last_stamp_ns : int or None
        Time stamps of the first and last scan read.
    elapsed_s : float
        Wall-clock time of the run.
    coasted : int
        Scans whose returns did not find their keyframe's walls (or moved in a way no
        vehicle can) and were carried at constant velocity, with its uncertainty.
    gaps : int
        Scans that came more than ``TrackConfig.max_gap_s`` after the scan before
        them: not chained by odometry (placed only if fixed, or by the scans after).
    """

    run: str
    topic: str | None = None
    scans: int = 0
    fixes: int = 0
    placed: int = 0
    skipped: int = 0
    reasons: dict[str, int] = field(default_factory=dict)
    reference_variances: list[tuple[float, int]] = field(default_factory=list)
    chi2_tests: dict[str, int] = field(default_factory=dict)
    first_stamp_ns: int | None = None
    last_stamp_ns: int | None = None
    elapsed_s: float = 0.0
    coasted: int = 0
    gaps: int = 0
