"""MAST: Mobile Automated Scanner Triangulateration.

Geo-reference a 2D laser scanner in a mine grid from one horizontal scan of
surveyed wall-mounted three-panel beacons.
"""

from importlib.metadata import PackageNotFoundError, version

from mast.core.beacon import Beacon, BeaconTemplate, IdentifiabilityRules, Survey
from mast.core.pose import Pose2D, format_dms, parse_azimuth
from mast.core.scan import Scan
from mast.errors import BeaconError, InputError, MastError, NoFixError

try:
    __version__ = version("mast-survey")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = [
    "Beacon",
    "BeaconError",
    "BeaconTemplate",
    "IdentifiabilityRules",
    "InputError",
    "MastError",
    "NoFixError",
    "Pose2D",
    "Scan",
    "Survey",
    "__version__",
    "format_dms",
    "parse_azimuth",
]
