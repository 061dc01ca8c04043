"""Figures: the paper's Figure 3 for one scan (segmentation in the scanner frame,
aligned panels over the surveyed beacons in the mine frame)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mast.core.beacon import Survey
from mast.core.scan import Scan
from mast.pipeline.locator import Fix

__all__ = ["PLOT_SUFFIXES", "plot_fix"]

#: File suffixes a plot can be written as (matplotlib's Agg and vector back-ends).
PLOT_SUFFIXES = frozenset(
    {".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps", ".ps"}
)


def plot_fix(scan: Scan, survey: Survey, fix: Fix, path: str | Path, *, title: str = "") -> None:
    """Write a two-panel PNG (or any format matplotlib knows by the suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    shown = list(fix.beacons)[:4] if fix.ok else []
    fig = plt.figure(figsize=(14, 9.5 if shown else 6.2))
    rows = 2 if shown else 1
    grid = fig.add_gridspec(rows, max(len(shown), 2), height_ratios=[1.4, 1] if shown else [1])
    half = max(len(shown), 2) // 2
    ax1 = fig.add_subplot(grid[0, :half])
    ax2 = fig.add_subplot(grid[0, half:])
    beams, pts = scan.points()
    ax1.plot(pts[:, 0], pts[:, 1], ".", ms=2, color="0.75", label="returns")
    cmap = plt.get_cmap("tab20")
    used_segments: dict[int, str] = {}
    for n in fix.identification.nodes:
        if n.beacon in fix.beacons:
            for s, p in zip(n.segments, n.panels, strict=True):
                used_segments[s] = f"{n.beacon} P{p}"
    for seg in fix.segmentation.segments:
        color = cmap(seg.index % 20)
        lw = 3.0 if seg.index in used_segments else 1.0
        ax1.plot([seg.start[0], seg.end[0]], [seg.start[1], seg.end[1]], "-", lw=lw, color=color)
        if seg.index in used_segments:
            ax1.annotate(
                used_segments[seg.index],
                (float(seg.midpoint[0]), float(seg.midpoint[1])),
                fontsize=8,
                xytext=(4, 4),
                textcoords="offset points",
            )
    nodes = [n for n in fix.identification.nodes if n.beacon in fix.beacons]
    if nodes:
        ns = np.array([n.node_scanner for n in nodes])
        ax1.plot(ns[:, 0], ns[:, 1], "kx", ms=8, label="identified edges")
    ax1.plot([0], [0], "r^", ms=9, label="scanner")
    ax1.annotate(
        "", xy=(1.0, 0.0), xytext=(0.0, 0.0), arrowprops={"arrowstyle": "->", "color": "r"}
    )
    ax1.set_aspect("equal")
    ax1.set_xlabel("x forward (m)")
    ax1.set_ylabel("y left (m)")
    ax1.set_title("Segmentation, scanner frame")
    ax1.legend(loc="best", fontsize=8)
    for beacon in survey:
        ax2.plot(beacon.edges[:, 0], beacon.edges[:, 1], "k-", lw=1.5)
        ax2.plot(beacon.edges[:, 0], beacon.edges[:, 1], "ko", ms=3)
        first = (float(beacon.edges[0, 0]), float(beacon.edges[0, 1]))
        ax2.annotate(beacon.id, first, fontsize=9, xytext=(4, -10), textcoords="offset points")
    if fix.ok and fix.pose is not None and fix.adjustment is not None:
        pose = fix.pose
        mine = pose.scanner_to_mine(pts)
        near = np.hypot(*(mine - pose.position).T) < 40
        ax2.plot(mine[near, 0], mine[near, 1], ".", ms=2, color="0.8")
        obs = np.isin(beams, fix.observations)
        ax2.plot(mine[obs, 0], mine[obs, 1], ".", ms=4, color="tab:blue", label="returns used")
        ax2.plot([pose.easting], [pose.northing], "r^", ms=9, label="scanner")
        az = pose.azimuth
        ax2.annotate(
            "",
            xy=(pose.easting + math.sin(az), pose.northing + math.cos(az)),
            xytext=(pose.easting, pose.northing),
            arrowprops={"arrowstyle": "->", "color": "r"},
        )
        ell = fix.adjustment.ellipse()
        scale = 0.5 / max(ell.semi_major_m, 1e-9)
        ax2.add_patch(
            Ellipse(
                (pose.easting, pose.northing),
                2 * ell.semi_major_m * scale,
                2 * ell.semi_minor_m * scale,
                angle=90 - math.degrees(ell.azimuth_rad),
                fill=False,
                color="r",
                label=f"95% ellipse ×{scale:.0f}",
            )
        )
        ax2.set_title(f"Mine frame: {pose}", fontsize=10)
        # frame the scanner and the beacons it used
        used_edges = np.vstack([survey[b].edges for b in fix.beacons] + [pose.position[None, :]])
        lo, hi = used_edges.min(axis=0) - 1.5, used_edges.max(axis=0) + 1.5
        ax2.set_xlim(lo[0], hi[0])
        ax2.set_ylim(lo[1], hi[1])
        obs_pts = mine[obs]
        for k, bid in enumerate(shown):
            ax = fig.add_subplot(grid[1, k])
            e = survey[bid].edges
            ax.plot(e[:, 0], e[:, 1], "k-", lw=1.2, label="surveyed")
            ax.plot(mine[near, 0], mine[near, 1], ".", ms=2, color="0.8")
            ax.plot(obs_pts[:, 0], obs_pts[:, 1], ".", ms=4, color="tab:blue")
            c = e.mean(axis=0)
            span = max(float(np.ptp(e[:, 0])), float(np.ptp(e[:, 1]))) / 2 + 0.3
            ax.set_xlim(c[0] - span, c[0] + span)
            ax.set_ylim(c[1] - span, c[1] + span)
            ax.set_aspect("equal")
            ax.set_title(
                f"{bid}: panels {','.join(map(str, sorted(fix.panels.get(bid, []))))}", fontsize=9
            )
            ax.ticklabel_format(useOffset=False)
            ax.tick_params(labelsize=7)
    else:
        ax2.set_title(f"No fix: {fix.reason}")
    ax2.set_aspect("equal")
    ax2.set_xlabel("Easting (m)")
    ax2.set_ylabel("Northing (m)")
    ax2.ticklabel_format(useOffset=False)
    ax2.legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
