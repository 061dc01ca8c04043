"""What a survey run produces, shared by the tracker and the writers of its outputs."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from mast.core.pose import Pose2D

__all__ = ["PlacedScan", "RunSummary"]


@dataclass(frozen=True, slots=True)
class PlacedScan:
    """One scan placed in the mine grid.

    Attributes
    ----------
    scan : int
        Index of the LaserScan message on its topic, from 0.
    stamp_ns : int
        The message header's time stamp, nanoseconds since the Unix epoch.
    pose : Pose2D
        Smoothed pose (easting, northing, azimuth clockwise from grid north).
    covariance : ndarray, shape (3, 3)
        Marginal covariance of (easting [m], northing [m], azimuth [rad]).
    source : {"fix", "odometry"}
        ``fix`` when the scan itself was fixed from beacons, ``odometry`` when it
        was carried from fixes by scan-to-scan odometry.
    """

    scan: int
    stamp_ns: int
    pose: Pose2D
    covariance: NDArray[np.float64]
    source: Literal["fix", "odometry"]

    @property
    def sigma(self) -> NDArray[np.float64]:
        """Standard deviations of (easting [m], northing [m], azimuth [rad])."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))


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
    elapsed_s : float
        Wall-clock time of the run.
    coasted : int
        Scans whose returns did not find their keyframe's walls (or moved in a way no
        vehicle can) and were carried at constant velocity, with its uncertainty.
    """

    run: str
    topic: str | None = None
    scans: int = 0
    fixes: int = 0
    placed: int = 0
    skipped: int = 0
    reasons: dict[str, int] = field(default_factory=dict)
    reference_variances: list[tuple[float, int]] = field(default_factory=list)
    elapsed_s: float = 0.0
    coasted: int = 0
