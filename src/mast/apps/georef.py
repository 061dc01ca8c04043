"""``mast georef``: put a 3D SLAM cloud into the mine grid (a thin application over
:func:`mast.cloud.georef.georeference` and :func:`mast.cloud.outputs.write_outputs`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mast.cloud.georef import Georef, GeorefConfig, georeference
from mast.cloud.io import open_cloud
from mast.cloud.outputs import Outputs, write_outputs
from mast.errors import InputError

__all__ = ["GeorefRun", "parse_band", "parse_checks", "run_georef"]


@dataclass(frozen=True, eq=False)
class GeorefRun:
    result: Georef
    outputs: Outputs


def parse_checks(text: str | None) -> tuple[str, ...]:
    """``B7,B9`` -> ``("B7", "B9")``; an empty name is bad input."""
    if text is None:
        return ()
    names = tuple(t.strip() for t in text.split(","))
    if any(not n for n in names):
        raise InputError(f"--check: an empty beacon name in {text!r}")
    return names


def parse_band(text: str | None) -> tuple[float, float] | None:
    """``Z0,Z1`` in the cloud's frame, ``Z0 < Z1``."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        z0, z1 = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"--band must be two heights Z0,Z1 in metres, got {text!r}") from None
    if not (math.isfinite(z0) and math.isfinite(z1)):
        raise InputError(f"--band: heights must be finite numbers, got {text!r}")
    if not z0 < z1:
        raise InputError(f"--band: Z0 must be below Z1, got {text!r}")
    return z0, z1


def run_georef(
    cloud_path: Path,
    survey_path: Path,
    out: Path,
    config: GeorefConfig,
    *,
    trajectory_path: Path | None = None,
    time_field: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> GeorefRun:
    """Read, georeference, write; a refusal still writes the beacons and the reports."""
    from mast.io import read_survey
    from mast.io.trajectory import read_trajectory

    survey = read_survey(survey_path)
    cloud = open_cloud(cloud_path, time_field=time_field)
    trajectory = read_trajectory(trajectory_path) if trajectory_path is not None else None
    if trajectory is not None and cloud.time_field is None:
        raise InputError(
            "--trajectory needs the points' times: this cloud has no gps_time "
            "(name its time attribute with --time-field)",
            path=cloud_path,
        )
    result = georeference(cloud, survey, config, trajectory=trajectory, progress=progress)
    outputs = write_outputs(result, out, progress=progress, survey_file=str(survey_path))
    return GeorefRun(result, outputs)
