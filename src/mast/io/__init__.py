"""Reading and writing MAST's file contracts (DESIGN.md, "File contracts").

Every reader raises :class:`mast.errors.InputError` naming the file, the line
(where there is one) and the problem.
"""

from mast.io.bags import bag_kind, list_topics, read_laserscans, write_laserscans
from mast.io.beacons_csv import read_survey, write_survey
from mast.io.pointclouds import read_pointclouds, write_pointclouds
from mast.io.scan_csv import read_scan_csv, write_scan_csv

__all__ = [
    "bag_kind",
    "list_topics",
    "read_laserscans",
    "read_pointclouds",
    "read_scan_csv",
    "read_survey",
    "write_laserscans",
    "write_pointclouds",
    "write_scan_csv",
    "write_survey",
]
