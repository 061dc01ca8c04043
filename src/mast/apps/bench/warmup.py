"""Compile the numba kernels once, before the processes a benchmark measures."""

from __future__ import annotations

import math

__all__ = ["compile_all"]


def compile_all() -> None:
    """Compile (or load from the cache) every kernel, through the code that calls them.

    A process that finds no cached machine code compiles each kernel on its
    first call: seconds and about 100 MB of compiler memory. Benchmarks call
    this once before they start the processes they measure, so that those
    load the cache as an installed tool does after its first run.
    """
    from mast.pipeline.locator import LocatorConfig, locate, locate_near
    from mast.pipeline.tracking import Prior
    from mast.runs.odometry import keyframe, scan_to_scan
    from mast.sim import paper_scene

    scene = paper_scene()
    for shot, sim in zip(scene.shots[:1], scene.simulate_all()[:1], strict=True):
        locate(sim.scan, scene.survey)
        # A window wider than the one searched from its centre alone: its grid search
        # (branch and bound on the likelihood tiles) is loaded too.
        prior = Prior(shot.pose, 0.3, math.radians(3.0))
        locate_near(sim.scan, scene.survey, prior, config=LocatorConfig())
        scan_to_scan(keyframe(sim.scan), sim.scan, range_sigma_m=0.01)  # the odometry's grid
