"""A small ray caster for the 3D tests: the paper's layout as vertical rectangles (each
panel 0.8 m tall below its surveyed top, each beacon's wall through its free ends)
seen by a VLP-16's rings, the nearest rectangle hit by each ray."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core.pose3d import Frame3D, Pose3D
from mast.sim.scenarios import paper_scene

RINGS_DEG = np.arange(-15.0, 16.0, 2.0)  # a VLP-16's


def paper_walls(scene_variant: str) -> tuple[list[tuple[Any, ...]], Any]:
    scene = paper_scene(scene_variant)
    walls = []
    for b in scene.survey:
        top = float(b.elevations[0]) if b.elevations is not None else 1.5
        for k in range(3):  # each panel: a vertical rectangle 0.8 m tall below its top
            walls.append((b.edges[k], b.edges[k + 1], top - 0.8, top))
    for b in scene.survey:  # each beacon's wall runs through its free ends e1 and e4
        e1, e4 = b.edges[0], b.edges[3]
        t = (e4 - e1) / np.linalg.norm(e4 - e1)
        walls.append((e1 - 40 * t, e1 + 40 * t, -10.0, 10.0))
    return walls, scene


def cast(pose: Pose3D, walls: list[tuple[Any, ...]], noise_m: float, seed: int) -> Frame3D:
    """Every ring's rays from the sensor at ``pose``, the nearest vertical rectangle hit."""
    return cast_labelled(pose, walls, noise_m, seed)[0]


def cast_labelled(
    pose: Pose3D, walls: list[tuple[Any, ...]], noise_m: float, seed: int
) -> tuple[Frame3D, NDArray[np.intp]]:
    """:func:`cast`, and for each return the index in ``walls`` of the rectangle it hit
    (the panels first, in survey order)."""
    rng = np.random.default_rng(seed)
    az = np.radians(np.arange(-180.0, 180.0, 0.2))
    el = np.radians(RINGS_DEG)
    A, E = np.meshgrid(az, el)
    d_sensor = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(
        -1, 3
    )
    d = d_sensor @ pose.rotation.T
    o = pose.position
    best = np.full(len(d), np.inf)
    label = np.full(len(d), -1, dtype=np.intp)
    for i, (a, b, zlo, zhi) in enumerate(walls):
        u = b - a
        den = d[:, 0] * (-u[1]) - d[:, 1] * (-u[0])
        with np.errstate(divide="ignore", invalid="ignore"):
            rx, ry = a[0] - o[0], a[1] - o[1]
            t = (rx * (-u[1]) - ry * (-u[0])) / den
            s = (d[:, 0] * ry - d[:, 1] * rx) / den
        z = o[2] + t * d[:, 2]
        hit = (t > 0.05) & (s >= 0) & (s <= 1) & (z >= zlo) & (z <= zhi) & (t < best)
        best[hit], label[hit] = t[hit], i
    ok = np.isfinite(best) & (best < 30.0)
    r = best[ok] + rng.normal(0.0, noise_m, int(ok.sum()))
    return Frame3D(d_sensor[ok] * r[:, None]), label[ok]
