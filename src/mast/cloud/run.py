"""``mast georef`` as one call: read the cloud, the survey and the SLAM trajectory,
georeference (:func:`mast.cloud.georef.georeference`) and write every output
(:func:`mast.cloud.outputs.write_outputs`); as :mod:`mast.runs.run` is for ``mast track``."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from mast.cloud.georef import Georef, GeorefConfig, georeference
from mast.cloud.io import open_cloud
from mast.cloud.outputs import Outputs, write_outputs
from mast.errors import InputError
from mast.io.crs import GridCrs

__all__ = ["GeorefRun", "run_georef"]


@dataclass(frozen=True, eq=False)
class GeorefRun:
    """What a georef run found and the files it wrote."""

    result: Georef
    outputs: Outputs


def run_georef(
    cloud_path: Path,
    survey_path: Path,
    out: Path,
    config: GeorefConfig,
    *,
    trajectory_path: Path | None = None,
    time_field: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    crs: GridCrs | None = None,
) -> GeorefRun:
    """Read, georeference, write; a refusal still writes the beacons and the reports.
    The grid's ``crs``, given, is written into every output that holds grid
    coordinates."""
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
    outputs = write_outputs(result, out, progress=progress, survey_file=str(survey_path), crs=crs)
    return GeorefRun(result, outputs)
