"""Core types shared by every stage: poses and frames, scans, surveyed beacons,
plane geometry against the surveyed panels, and the one noise model."""

from mast.core.beacon import Beacon, BeaconTemplate, IdentifiabilityRules, Survey
from mast.core.geometry import PanelSet, first_hits
from mast.core.pose import Pose2D, format_dms, parse_azimuth
from mast.core.scan import Scan

__all__ = [
    "Beacon",
    "BeaconTemplate",
    "IdentifiabilityRules",
    "PanelSet",
    "Pose2D",
    "Scan",
    "Survey",
    "first_hits",
    "format_dms",
    "parse_azimuth",
]
