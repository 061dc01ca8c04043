"""MAST: Mobile Automated Scanner Triangulateration.

Geo-reference a 2D laser scanner in a mine grid from one horizontal scan of
surveyed wall-mounted three-panel beacons.
"""

from importlib.metadata import PackageNotFoundError, version

from .beacon import Beacon, BeaconTemplate, IdentifiabilityRules, Survey
from .errors import BeaconError, InputError, MastError, NoFixError
from .pose import Pose2D, format_dms, parse_azimuth
from .scan import Scan

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
