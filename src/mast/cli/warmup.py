"""Compile the numba kernels once, before the scans a command or a benchmark times.

The warm-up locates the example scan that ships with MAST (``mast/data/example``: the
paper's parallel layout from P1, 1081 beams, 10 mm range noise) against its two-beacon
survey, read as any scan and survey are: no simulator is run. The 3D locator's kernels
are compiled by locating the demo's simulated VLP-16 frame (:func:`compile_3d`).
"""

from __future__ import annotations

import math
from importlib.resources import as_file, files

__all__ = ["compile_3d", "compile_all"]


def compile_all() -> None:
    """Compile (or load from the cache) every kernel, through the code that calls them.

    A process that finds no cached machine code compiles each kernel on its first call:
    seconds and about 100 MB of compiler memory. ``mast live`` calls this before its
    first scan, and benchmarks before the processes they measure, so that those load the
    cache as an installed tool does after its first run.
    """
    from mast.io import read_scan_csv, read_survey
    from mast.pipeline.locator import LocatorConfig, locate, locate_near
    from mast.pipeline.tracking import Prior
    from mast.runs.odometry import keyframe, scan_to_scan

    example = files("mast").joinpath("data/example")
    with as_file(example.joinpath("scan.csv")) as scan_path:
        scan = read_scan_csv(scan_path)
    with as_file(example.joinpath("beacons.csv")) as survey_path:
        survey = read_survey(survey_path)
    fix = locate(scan, survey)
    if fix.pose is None:  # pragma: no cover - the example is fixed; a broken install is not
        raise RuntimeError("the example scan shipped with MAST gave no fix")
    # A window wider than the one searched from its centre alone: its grid search (branch
    # and bound on the likelihood tiles) is loaded too.
    locate_near(scan, survey, Prior(fix.pose, 0.3, math.radians(3.0)), config=LocatorConfig())
    scan_to_scan(keyframe(scan), scan, range_sigma_m=0.01)  # the odometry's grid


def compile_3d() -> bool:
    """Compile (or load from the cache) the 3D locator's kernels, and the 2D ones its
    plan views call (:func:`compile_all`: one frame's plan views need not meet every
    2D kernel), by locating the simulated VLP-16 frame ``mast demo`` locates (a frame
    owed a fix, so that every stage runs). ``mast live`` calls this before a 3D lidar's
    first frame: without it, that frame waits for the compiler (about a minute and a
    half where nothing is cached yet). Returns whether the frame was fixed (it is: a
    test holds the simulator to it)."""
    from mast.cli.demo import DEMO_3D_FRAME, DEMO_3D_SEED
    from mast.pipeline.locator3d import Locator3DConfig, locate3d
    from mast.sim.lidar3d import random_drift_scene

    compile_all()
    scene = random_drift_scene(
        DEMO_3D_SEED, frames=DEMO_3D_FRAME + 1, lidar="vlp16", range_sigma_m=0.02
    )
    sim = scene.simulate(DEMO_3D_FRAME)
    return locate3d(sim.frame, scene.survey, config=Locator3DConfig(range_sigma_m=0.02)).ok
