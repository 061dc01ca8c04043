"""Figures: the paper's Figure 3 for one scan, readable at mine coordinates.

(a) the segmentation in the scanner frame; (b) the aligned returns over the
surveyed beacons in the mine frame, with the scanner, its azimuth and its
95 % error ellipse; (c) a close-up of each beacon the fix used, with its
residuals. A scan with no fix still shows the scan, its segmentation, the
survey and the reason.

Mine coordinates are drawn as metres from a round origin (a multiple of 100 m
or more) that the axis labels and the caption state, e.g. ``E − 512 000 (m)``:
full UTM-sized coordinates do not fit on tick labels, and the trailing digits
a surveyor reads off an axis are the coordinate's own. Small coordinates (a
local grid under 10 km) are drawn as they are.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Ellipse
from matplotlib.ticker import MaxNLocator, ScalarFormatter
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.frames import yaw_of_azimuth
from mast.core.geometry import PanelSet
from mast.core.pose import Pose2D, format_dms
from mast.core.scan import Scan
from mast.errors import InputError
from mast.io.outputs import PLOT_SUFFIXES, save_figure
from mast.pipeline.locator import NO_FIX_REASONS, Fix, segmented
from mast.pipeline.segmentation import Segment
from mast.report.html import axis_label, group_thousands, plot_origin

__all__ = ["PLOT_SUFFIXES", "fix_figure", "plot_fix"]


#: Resolution of raster plots (dots per inch).
DPI = 100

#: Close-ups per row, and the most drawn (the rest are named in the caption).
CLOSEUP_COLUMNS = 4
MAX_CLOSEUPS = 8

_WIDTH_IN = 15.0
_USED = "tab:blue"
_SCANNER = "tab:red"
_EXCLUDED = "tab:orange"
_CLOSEUP_RATIO = 0.8
_OTHER = "0.72"
_NICE = (1.0, 2.0, 5.0)
_TEST_WORDS = {"pass": "passed", "too_small": "too small", "too_large": "too large"}

LegendLoc = Literal["best", "lower left", "upper right", "upper left", "lower right"]


def plot_fix(scan: Scan, survey: Survey, fix: Fix, path: str | Path, *, title: str = "") -> None:
    """Write the figure of one scan's fix (or no fix) to ``path``.

    The format follows the suffix (one of :data:`PLOT_SUFFIXES`). The figure is
    rendered in memory and written in one go.

    Raises
    ------
    InputError
        The suffix is not one a plot can be written as.
    OutputError
        The file cannot be written (no such folder, permissions, a full disk).
    """
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in PLOT_SUFFIXES:
        raise InputError(
            f"unknown plot file type {target.suffix or '(no suffix)'!r}; "
            f"use one of {', '.join(sorted(PLOT_SUFFIXES))}",
            path=target,
        )
    fig = fix_figure(scan, survey, fix, title=title)
    save_figure(fig, target, dpi=DPI)
    fig.clear()


def fix_figure(scan: Scan, survey: Survey, fix: Fix, *, title: str = "") -> Figure:
    """The figure :func:`plot_fix` writes, as a matplotlib Figure (not shown anywhere).

    Its axes carry labels naming them: ``"scanner"``, ``"mine"`` and
    ``"closeup:<beacon id>"``.
    """
    # A scan fixed near a prior was not segmented: its straight pieces are made now.
    seg, ident = segmented(fix, scan, survey)
    fix = replace(fix, segmentation=seg, identification=ident)
    ok = fix.ok and fix.pose is not None and fix.adjustment is not None
    shown = [b for b in fix.beacons if b in survey][:MAX_CLOSEUPS] if ok else []
    if ok:
        assert fix.pose is not None
        view = _frame(
            np.vstack([survey[b].edges for b in fix.beacons] + [fix.pose.position[None, :]]),
            pad=1.5,
            min_span=6.0,
        )
    else:
        view = _survey_view(survey, fix)
    origin = _Origin.for_view(view)
    scan_view = _scanner_view(scan, survey, fix)
    ratio = _box_ratio(view, 0.6, 0.9)
    # a fix shows the same ground in both frames, in boxes of one shape
    scan_ratio = ratio if ok else _box_ratio(scan_view, 0.5, 0.9)
    columns = max(3, min(len(shown), CLOSEUP_COLUMNS))
    rows = math.ceil(len(shown) / columns)
    map_in = (_WIDTH_IN / 2 - 1.0) * max(ratio, scan_ratio) + 1.2
    row_in = (_WIDTH_IN / columns - 0.9) * _CLOSEUP_RATIO + 1.4
    fig = Figure(figsize=(_WIDTH_IN, map_in + rows * row_in + 1.3), layout="constrained")
    grid = fig.add_gridspec(1 + rows, 1, height_ratios=[map_in] + [row_in] * rows)
    top = grid[0].subgridspec(1, 2)
    ax_scan = fig.add_subplot(top[0, 0], label="scanner")
    _scanner_panel(ax_scan, scan, survey, fix, scan_view, scan_ratio)
    ax_mine = fig.add_subplot(top[0, 1], label="mine")
    ellipse = _mine_panel(ax_mine, scan, survey, fix, view, origin, ratio)
    residual_scale: float | None = None
    if shown:
        closeups = _Closeups.build(scan, survey, fix, shown)
        residual_scale = closeups.scale if closeups.residuals_m is not None else None
        # half-columns, so that a short row sits in the middle
        cells = grid[1:].subgridspec(rows, 2 * columns)
        for k, bid in enumerate(shown):
            row, col = divmod(k, columns)
            start = 2 * col + columns - min(columns, len(shown) - row * columns)
            ax = fig.add_subplot(cells[row, start : start + 2], label=f"closeup:{bid}")
            closeups.draw(ax, bid, origin)
    fig.suptitle(_headline(fix, title), fontsize=12)
    fig.supxlabel(_caption(fix, origin, shown, ellipse, residual_scale), fontsize=9, color="0.25")
    return fig


# --------------------------------------------------------------------------- coordinates


@dataclass(frozen=True, slots=True)
class _Origin:
    """The round point mine-frame axes count their metres from."""

    easting: float
    northing: float

    @classmethod
    def for_view(cls, view: NDArray[np.float64]) -> _Origin:
        """Zero for coordinates under 10 km; else a multiple of 100 m (or more, for a
        wide view) just below the view, so tick labels keep the coordinate's own digits."""
        return cls(*plot_origin(np.asarray(view, dtype=float)))

    @property
    def xy(self) -> NDArray[np.float64]:
        return np.array([self.easting, self.northing])

    @property
    def is_zero(self) -> bool:
        return self.easting == 0.0 and self.northing == 0.0

    @property
    def xlabel(self) -> str:
        return axis_label("E", self.easting) if not self.is_zero else "Easting E (m)"

    @property
    def ylabel(self) -> str:
        return axis_label("N", self.northing) if not self.is_zero else "Northing N (m)"

    def local(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(points, dtype=float) - self.xy


def _frame(points: NDArray[np.float64], *, pad: float, min_span: float) -> NDArray[np.float64]:
    """``[[xmin, ymin], [xmax, ymax]]`` around the points, at least min_span wide, padded
    by ``pad`` metres or a tenth of their extent, whichever is more (room for labels)."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    pad = max(pad, 0.1 * float(np.max(np.ptp(p, axis=0))))
    lo, hi = p.min(axis=0) - pad, p.max(axis=0) + pad
    grow = np.maximum(min_span - (hi - lo), 0.0) / 2
    return np.array([lo - grow, hi + grow])


def _survey_view(survey: Survey, fix: Fix) -> NDArray[np.float64]:
    """Where a no-fix plot looks: the prior's window if there was one, else the survey."""
    prior = fix.config.prior
    if prior is not None:
        r = max(prior.radius_m, 1.0) + 5.0
        c = prior.pose.position
        return np.array([c - r, c + r])
    edges = np.vstack([b.edges for b in survey]) if len(survey) else np.zeros((1, 2))
    return _frame(edges, pad=2.0, min_span=6.0)


def _box_ratio(view: NDArray[np.float64], lo: float, hi: float) -> float:
    """Height over width of a view, kept between ``lo`` and ``hi``."""
    w, h = view[1] - view[0]
    return min(max(float(h / w), lo), hi)


def _fit_box(ax: Axes, view: NDArray[np.float64], ratio: float) -> None:
    """Equal aspect in a box of the given height/width: the view grown to fill it."""
    (x0, y0), (x1, y1) = view
    w, h = x1 - x0, y1 - y0
    if h / w < ratio:
        grow = (ratio * w - h) / 2
        y0, y1 = y0 - grow, y1 + grow
    else:
        grow = (h / ratio - w) / 2
        x0, x1 = x0 - grow, x1 + grow
    ax.set_box_aspect(ratio)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal", adjustable="datalim")


def _ticks(ax: Axes, bins: int) -> None:
    """Few ticks, full numbers: no offset, no scientific notation."""
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]))
        fmt = ScalarFormatter(useOffset=False)
        fmt.set_scientific(False)
        axis.set_major_formatter(fmt)
    ax.tick_params(labelsize=8)
    ax.grid(True, color="0.92", lw=0.6, zorder=0)


def _nice_floor(x: float, most: float = 1000.0) -> float:
    """The largest 1, 2 or 5 times a power of ten not above ``x``, from 1 to ``most``."""
    if not x > 1.0:
        return 1.0
    if not x < most:
        return most
    p = 10.0 ** math.floor(math.log10(x))
    return max(m * p for m in _NICE if m * p <= x)


def _times(k: float) -> str:
    return f"×{k:g}"


def _legend(ax: Axes, *, loc: LegendLoc = "best", fontsize: float = 8, table: bool = False) -> None:
    """A legend only where something is labelled; a ``table`` has text lines, no symbols."""
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    if table:
        ax.legend(
            handles,
            labels,
            loc=loc,
            fontsize=fontsize,
            framealpha=0.85,
            handlelength=0,
            handletextpad=0,
            markerscale=0,
        )
    else:
        ax.legend(handles, labels, loc=loc, fontsize=fontsize, framealpha=0.85)


# --------------------------------------------------------------------------- panels


def _identified(fix: Fix, survey: Survey) -> dict[int, tuple[str, int]]:
    """Segment index -> (beacon id, panel number) of the panels to mark in the scan.

    With a fix: the segments holding the returns the adjustment used, named by the
    panel most of those returns lie on. Without: the segments of identified corners.
    """
    out: dict[int, tuple[str, int]] = {}
    if fix.ok:
        panels = PanelSet.from_survey(survey)
        beam_panel = dict(
            zip(fix.observations.tolist(), fix.observation_panels.tolist(), strict=True)
        )
        for seg in fix.segments:
            hits = [beam_panel[b] for b in seg.beams.tolist() if b in beam_panel]
            if hits:
                k = max(set(hits), key=hits.count)
                out[seg.index] = (panels.ids[panels.beacon[k]], int(panels.panel[k]))
        return out
    for node in fix.nodes:
        for s, p in zip(node.segments, node.panels, strict=True):
            out.setdefault(s, (node.beacon, p))
    return out


def _beacon_colours(ids: Sequence[str]) -> dict[str, str]:
    palette = ["tab:blue", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive"]
    return {b: palette[k % len(palette)] for k, b in enumerate(ids)}


def _scanner_view(scan: Scan, survey: Survey, fix: Fix) -> NDArray[np.float64]:
    """What panel (a) frames: the scanner and the beacons used, or the whole scan."""
    if fix.ok and fix.pose is not None:
        corners = [fix.pose.mine_to_scanner(survey[b].edges) for b in fix.beacons]
        return _frame(np.vstack([np.zeros((1, 2)), *corners]), pad=1.5, min_span=6.0)
    return _frame(np.vstack([np.zeros((1, 2)), scan.points()[1]]), pad=1.0, min_span=6.0)


def _scanner_panel(
    ax: Axes, scan: Scan, survey: Survey, fix: Fix, view: NDArray[np.float64], ratio: float
) -> None:
    """(a) Returns, segments and identified panels in the scanner frame."""
    _, pts = scan.points()
    if len(pts):
        ax.plot(pts[:, 0], pts[:, 1], ".", ms=2, color=_OTHER, label="returns", zorder=1)
    segments = fix.segments
    ident = _identified(fix, survey)
    names = sorted({b for b, _ in ident.values()}, key=lambda b: (b not in fix.beacons, b))
    colours = _beacon_colours(names)
    lines = [np.array([s.start, s.end]) for s in segments if s.index not in ident]
    if lines:
        ax.add_collection(
            LineCollection(lines, colors="0.35", linewidths=1.0, label="segments", zorder=2)
        )
    # one label per run of consecutive segments identified as the same beacon
    runs: list[tuple[str, list[Segment], set[int]]] = []
    for seg in sorted((g for g in segments if g.index in ident), key=lambda g: g.index):
        b, p = ident[seg.index]
        if runs and runs[-1][0] == b and runs[-1][1][-1].index == seg.index - 1:
            runs[-1][1].append(seg)
            runs[-1][2].add(p)
        else:
            runs.append((b, [seg], {p}))
        ax.plot(
            [seg.start[0], seg.end[0]],
            [seg.start[1], seg.end[1]],
            "-",
            lw=3.5,
            zorder=3,
            color=colours[b],
            solid_capstyle="butt",
        )
    for b, segs, panels in runs:
        where = np.mean([g.midpoint for g in segs], axis=0)
        text = f"{b} " + ", ".join(f"P{p}" for p in sorted(panels))
        _label_away(ax, text, where, where, view, color=colours[b])
    if runs:
        used = "segments on the panels used" if fix.ok else "segments of identified corners"
        ax.plot([], [], "-", lw=3.5, color="0.3", label=used)
    nodes = [
        n.node_scanner
        for n in fix.nodes
        if all(ident.get(g, ("",))[0] == n.beacon for g in n.segments)
    ]
    if nodes:
        ns = np.array(nodes)
        ax.plot(ns[:, 0], ns[:, 1], "kx", ms=7, mew=1.5, label="identified edges", zorder=4)
    span = float(np.max(view[1] - view[0]))
    _scanner_marker(ax, np.zeros(2), 0.0, 0.08 * span, "+x")
    _fit_box(ax, view, ratio)
    _ticks(ax, 6)
    ax.set_xlabel("x forward (m)")
    ax.set_ylabel("y left (m)")
    empty = "" if len(pts) else " (no valid return)"
    ax.set_title(f"(a) Segmentation, scanner frame{empty}", fontsize=11)
    _legend(ax, loc="best")


def _label_away(
    ax: Axes,
    text: str,
    at: NDArray[np.float64],
    direction: NDArray[np.float64],
    view: NDArray[np.float64] | None = None,
    **kw: object,
) -> None:
    """Label a point, pushed along ``direction`` so it does not cover what is there;
    near the rim of ``view`` the text runs inwards, so that it stays inside."""
    d = np.asarray(direction, dtype=float)
    n = float(np.hypot(*d))
    dx, dy = (16 * d / n) if n > 0 else (0.0, 16.0)
    ha = "left" if dx > 5 else "right" if dx < -5 else "center"
    va = "bottom" if dy > 5 else "top" if dy < -5 else "center"
    if view is not None:
        fx, fy = (np.asarray(at, dtype=float) - view[0]) / (view[1] - view[0])
        if fx < 0.25:
            ha, dx = "left", max(dx, 0.0)
        elif fx > 0.75:
            ha, dx = "right", min(dx, 0.0)
        if fy < 0.12:
            va, dy = "bottom", max(dy, 8.0)
        elif fy > 0.88:
            va, dy = "top", min(dy, -8.0)
        if abs(dx) <= 5 and abs(dy) <= 5:  # pushed nowhere: above or below instead
            dy = 12.0 if d[1] >= 0 else -12.0
            va = "bottom" if dy > 0 else "top"
    style: dict[str, object] = {"fontsize": 9, "fontweight": "bold", **kw}
    ax.annotate(
        text,
        (float(at[0]), float(at[1])),
        xytext=(float(dx), float(dy)),
        textcoords="offset points",
        ha=ha,
        va=va,
        **style,  # type: ignore[arg-type]
    )


def _scanner_marker(
    ax: Axes, at: NDArray[np.float64], bearing_ccw: float, length: float, text: str
) -> None:
    """The scanner: a triangle, an arrow along ``bearing_ccw`` (counter-clockwise from +x)."""
    ax.plot([at[0]], [at[1]], "^", ms=9, color=_SCANNER, label="scanner", zorder=6)
    tip = at + length * np.array([math.cos(bearing_ccw), math.sin(bearing_ccw)])
    ax.annotate(
        "",
        xy=(float(tip[0]), float(tip[1])),
        xytext=(float(at[0]), float(at[1])),
        arrowprops={"arrowstyle": "-|>", "color": _SCANNER, "lw": 1.8, "shrinkA": 0, "shrinkB": 0},
        zorder=6,
    )
    ax.annotate(
        text,
        (float(tip[0]), float(tip[1])),
        xytext=(6 * math.cos(bearing_ccw), 6 * math.sin(bearing_ccw)),
        textcoords="offset points",
        ha="left" if math.cos(bearing_ccw) > -0.3 else "right",
        va="bottom" if math.sin(bearing_ccw) > -0.3 else "top",
        fontsize=9,
        color=_SCANNER,
    )


def _in_view(survey: Survey, view: NDArray[np.float64]) -> list[str]:
    lo, hi = view
    return [
        b.id
        for b in survey
        if np.all(b.edges.max(axis=0) >= lo) and np.all(b.edges.min(axis=0) <= hi)
    ]


def _mine_panel(
    ax: Axes,
    scan: Scan,
    survey: Survey,
    fix: Fix,
    view: NDArray[np.float64],
    origin: _Origin,
    ratio: float,
) -> float | None:
    """(b) The survey and, with a fix, the aligned returns, scanner, azimuth and ellipse.

    Returns the ellipse's exaggeration (None when none is drawn).
    """
    local_view = view - origin.xy
    span = float(np.max(local_view[1] - local_view[0]))
    centre = local_view.mean(axis=0)
    pose = fix.pose if fix.ok else None
    here = origin.local(pose.position) if pose is not None else centre
    used, excluded = set(fix.beacons), set(fix.excluded_beacons)
    if pose is None:  # no fix: the beacons the scan's corners were taken for
        used = {n.beacon for n in fix.nodes}
    ids = _in_view(survey, view)
    crowded = len(ids) > 40
    first = {"used": True, "excluded": True, "other": True}
    for bid in ids:
        e = origin.local(survey[bid].edges)
        kind = "used" if bid in used else "excluded" if bid in excluded else "other"
        colour = {"used": "k", "excluded": _EXCLUDED, "other": "0.45"}[kind]
        label = {
            "used": "surveyed beacons used"
            if pose is not None
            else "beacons identified in the scan",
            "excluded": "beacon left out (disagrees with the others)",
            "other": "other surveyed beacons" if pose is not None else "surveyed beacons",
        }[kind]
        ax.plot(
            e[:, 0],
            e[:, 1],
            "-",
            color=colour,
            lw=2.0 if kind != "other" else 1.2,
            marker="o" if span < 200 else "s",
            ms=2.5 if span < 200 else 3.5,
            zorder=4 if kind != "other" else 3,
            label=label if first[kind] else None,
        )
        first[kind] = False
        if kind != "other" or not crowded:
            c = e.mean(axis=0)
            away = c - here if float(np.hypot(*(c - here))) > 1e-6 else np.array([1.0, 0.0])
            tip = e[int(np.argmax(e @ away))]  # the edge farthest that way
            _label_away(ax, bid, tip, away, local_view, color=colour)
    ellipse_scale: float | None = None
    if pose is not None and fix.adjustment is not None:
        beams, pts = scan.points()
        mine = origin.local(pose.scanner_to_mine(pts))
        obs = np.isin(beams, fix.observations)
        ax.plot(mine[~obs, 0], mine[~obs, 1], ".", ms=2, color=_OTHER, label="returns", zorder=1)
        ax.plot(
            mine[obs, 0],
            mine[obs, 1],
            ".",
            ms=3,
            color=_USED,
            label=f"returns used ({fix.points_used})",
            zorder=2,
        )
        ell = fix.adjustment.ellipse()
        _scanner_marker(
            ax,
            here,
            yaw_of_azimuth(pose.azimuth),
            0.12 * span,
            f"Az {format_dms(pose.azimuth_deg, decimals=0)}",
        )
        if ell.semi_major_m > 1e-7:
            ellipse_scale = _nice_floor(0.06 * span / ell.semi_major_m)
            ax.add_patch(
                Ellipse(
                    (float(here[0]), float(here[1])),
                    2 * ell.semi_major_m * ellipse_scale,
                    2 * ell.semi_minor_m * ellipse_scale,
                    angle=math.degrees(yaw_of_azimuth(ell.azimuth_rad)),
                    fill=False,
                    color=_SCANNER,
                    lw=1.5,
                    zorder=5,
                    label=f"95 % error ellipse {_times(ellipse_scale)} "
                    f"(a {1000 * ell.semi_major_m:.1f} mm, b {1000 * ell.semi_minor_m:.1f} mm)",
                )
            )
        ax.set_title("(b) Aligned returns over the surveyed beacons, mine frame", fontsize=11)
    else:
        prior = fix.config.prior
        if prior is not None:
            c = origin.local(prior.pose.position)
            ax.add_patch(
                Circle(
                    (float(c[0]), float(c[1])),
                    prior.radius_m,
                    fill=False,
                    ls="--",
                    color=_SCANNER,
                    label="prior window",
                )
            )
        title = "(b) Surveyed beacons, mine frame"
        ax.set_title(title + " (no fix: the scan cannot be placed)", fontsize=11)
    _fit_box(ax, local_view, ratio)
    _ticks(ax, 6)
    ax.set_xlabel(origin.xlabel)
    ax.set_ylabel(origin.ylabel)
    _legend(ax, loc="best")
    return ellipse_scale


@dataclass(frozen=True, eq=False)
class _Closeups:
    """What every close-up shares: the returns in the mine frame and the residuals."""

    survey: Survey
    fix: Fix
    pose: Pose2D
    returns: NDArray[np.float64]
    used: NDArray[np.float64]
    used_beacon: NDArray[np.intp]
    feet: NDArray[np.float64]
    outward: NDArray[np.float64]
    residuals_m: NDArray[np.float64] | None
    scale: float
    ids: tuple[str, ...]

    @classmethod
    def build(cls, scan: Scan, survey: Survey, fix: Fix, shown: Sequence[str]) -> _Closeups:
        assert fix.pose is not None
        assert fix.adjustment is not None
        pose = fix.pose
        panels = PanelSet.from_survey(survey)
        _, pts = scan.points()
        obs = np.asarray(fix.observations, dtype=np.intp)
        used = pose.beam_to_mine(scan.angles_rad[obs], scan.ranges_m[obs])
        k = np.asarray(fix.observation_panels, dtype=np.intp)
        a, n = panels.a[k], panels.normal[k]
        feet = used - np.einsum("ij,ij->i", used - a, n)[:, None] * n
        side = np.sign(np.einsum("ij,ij->i", feet - pose.position, n))
        outward = n * np.where(side == 0, 1.0, side)[:, None]
        v = np.asarray(fix.adjustment.residuals_m, dtype=float)
        residuals = v if v.shape == (len(obs),) else None
        scale = 1.0
        if residuals is not None and residuals.size and float(np.max(np.abs(residuals))) > 0:
            size = max(float(np.max(np.ptp(survey[b].edges, axis=0))) for b in shown) + 0.6
            scale = _nice_floor(0.12 * size / float(np.max(np.abs(residuals))))
        return cls(
            survey,
            fix,
            pose,
            pose.scanner_to_mine(pts),
            used,
            panels.beacon[k],
            feet,
            outward,
            residuals,
            scale,
            panels.ids,
        )

    def draw(self, ax: Axes, bid: str, origin: _Origin) -> None:
        edges = self.survey[bid].edges
        view = _frame(edges, pad=0.3, min_span=1.0)
        lo, hi = view
        near = np.all((self.returns >= lo - 0.5) & (self.returns <= hi + 0.5), axis=1)
        mine = np.flatnonzero(self.used_beacon == self.ids.index(bid))
        here = origin.local(self.pose.position)
        e = origin.local(edges)
        r = origin.local(self.returns[near])
        ax.plot(r[:, 0], r[:, 1], ".", ms=2, color=_OTHER, zorder=1)
        ax.plot(e[:, 0], e[:, 1], "k-", lw=1.6, zorder=3)
        ax.plot(e[:, 0], e[:, 1], "ko", ms=3, zorder=3)
        u = origin.local(self.used[mine])
        ax.plot(u[:, 0], u[:, 1], ".", ms=3, color=_USED, zorder=4)
        if self.residuals_m is not None and mine.size:
            feet = origin.local(self.feet[mine])
            tips = feet + (self.scale * self.residuals_m[mine])[:, None] * self.outward[mine]
            ax.add_collection(
                LineCollection(
                    list(np.stack([feet, tips], axis=1)),
                    colors=_SCANNER,
                    linewidths=0.6,
                    zorder=5,
                )
            )
        res = self.fix.residuals
        for j in (1, 2, 3):
            mid = 0.5 * (e[j - 1] + e[j])
            d = e[j] - e[j - 1]
            normal = np.array([-d[1], d[0]])
            if float(normal @ (mid - here)) < 0:
                normal = -normal
            group = None if res is None else res.per_panel.get((bid, j))
            colour = "k" if group is not None else "0.5"
            _label_away(ax, f"P{j}", mid, normal, fontsize=8, color=colour)
            if group is not None:  # the panel's residuals, as a line of a table
                rms, w = 1000 * group.rms_m, group.max_abs_w
                ax.plot(
                    [],
                    [],
                    ls="none",
                    label=f"P{j}: {group.returns} returns, RMS {rms:.1f} mm, max |w| {w:.1f}",
                )
        _fit_box(ax, view - origin.xy, _CLOSEUP_RATIO)
        _ticks(ax, 4)
        ax.set_xlabel(origin.xlabel, fontsize=8)
        ax.set_ylabel(origin.ylabel, fontsize=8)
        ax.set_title(_closeup_title(bid, self.fix), fontsize=9)
        _legend(ax, loc="best", fontsize=7, table=True)


def _closeup_title(bid: str, fix: Fix) -> str:
    panels = ", ".join(str(p) for p in sorted(fix.panels.get(bid, [])))
    lines = [f"(c) {bid}: panels {panels}"]
    res = fix.residuals
    group = None if res is None else res.per_beacon.get(bid)
    if group is not None:
        rms, w = 1000 * group.rms_m, group.max_abs_w
        lines.append(f"{group.returns} returns, RMS {rms:.1f} mm, max |w| {w:.1f}")
    test = None if res is None else res.beacon_tests.get(bid)
    if test is not None:
        verdict = "fails" if test.failed else "passes"
        lines.append(f"left-out test {test.ratio:.2f} × critical ({verdict})")
    return "\n".join(lines)


# --------------------------------------------------------------------------- words


def _headline(fix: Fix, title: str) -> str:
    lines = [title] if title else []
    if fix.ok and fix.pose is not None and fix.adjustment is not None:
        p, s = fix.pose, fix.adjustment.sigma
        lines.append(
            f"FIX  E {group_thousands(p.easting, 3)} m   N {group_thousands(p.northing, 3)} m   "
            f"Az {format_dms(p.azimuth_deg)}   "
            f"(σ {1000 * s[0]:.1f} mm, {1000 * s[1]:.1f} mm, "
            f"{format_dms(math.degrees(s[2]), signed=True)})   "
            f"beacons {', '.join(fix.beacons)}; global test {_TEST_WORDS[fix.adjustment.test_code]}"
        )
    else:
        reason = fix.reason or "no_fix"
        detail = fix.detail or NO_FIX_REASONS.get(reason, "")
        lines += textwrap.wrap(f"NO FIX ({reason}): {detail}", 130)
    return "\n".join(lines)


def _caption(
    fix: Fix, origin: _Origin, shown: Sequence[str], ellipse: float | None, residuals: float | None
) -> str:
    if origin.is_zero:
        frame = "Mine frame in metres (E, N)"
    else:
        frame = (
            f"Mine frame in metres from the origin E {group_thousands(origin.easting)} m, "
            f"N {group_thousands(origin.northing)} m"
        )
    parts = [f"{frame}; grid north up, azimuth clockwise from grid north."]
    if ellipse is not None:
        parts.append(f"Error ellipse drawn {_times(ellipse)} its size.")
    if residuals is not None:
        parts.append(
            f"Residual ticks {_times(residuals)}: measured minus computed range, "
            "drawn away from the scanner when the return lies behind the panel."
        )
    left = [b for b in fix.beacons if b not in shown] if fix.ok else []
    if left:
        parts.append(f"Close-ups of {', '.join(left)} not drawn.")
    return "\n".join(textwrap.wrap(" ".join(parts), 170))
