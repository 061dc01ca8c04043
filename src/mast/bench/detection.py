"""Detection limit: how much of two beacons a scan must show before it gets a fix.

A pose is *owed* a fix when, noise-free, two beacons each show two panels with
at least 3 returns seen at 10 degrees or more from grazing
(:meth:`~mast.sim.scanner.SimulatedScan.owes_fix`). Whether the fix comes under
noise depends on how much more than that the scan shows. Two measures of that
evidence are taken from the simulator's noise-free truth scan of the pose (see
:func:`detection_evidence`), and :func:`detection_table` bins the accuracy
benchmark's draws by each, giving the fix rate and why the others got none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.lines import fit_line
from mast.pipeline.locator import NO_FIX_REASONS
from mast.sim.owed import OWED, OwedRule
from mast.sim.scanner import SimulatedScan
from mast.sim.world import Surface

__all__ = [
    "DIRECTION_SIGMA_BINS_DEG",
    "RETURNS_BINS",
    "DetectionBin",
    "DetectionEvidence",
    "detection_bins",
    "detection_evidence",
    "detection_rows",
    "detection_table",
]

#: Lower edges of the bins of ``evidence_returns`` (the last is open-ended).
RETURNS_BINS: tuple[float, ...] = (3, 5, 8, 12, 20, 40)
#: Lower edges of the bins of ``evidence_direction_sigma_deg``, degrees.
DIRECTION_SIGMA_BINS_DEG: tuple[float, ...] = (0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 10.0)

#: A line through two returns already has a direction: panels with fewer are
#: not ranked (the owed rule itself asks for 3, so no owed pose depends on them).
_RANKED = OwedRule(2, OWED.min_incidence_deg)


@dataclass(frozen=True, slots=True)
class DetectionEvidence:
    """What a noise-free scan shows of the two beacons that make a pose owed.

    Per beacon, only panels seen at 10 degrees or more from grazing count (as
    in :meth:`~mast.sim.scanner.SimulatedScan.panels_seen`), ranked by their
    returns; a beacon's *score* is the returns on its second-best panel (0
    with fewer than two panels). The two best-seen beacons are those of the
    highest scores, ties going to the nearer beacon.

    Attributes
    ----------
    returns : int
        The lower of the two best-seen beacons' scores: the number the owed
        rule thresholds (a pose is owed exactly when it is 3 or more).
    range_m : float
        The larger of the distances from the scanner to those two beacons'
        centroids (mean of the four surveyed edges), metres; ``nan`` when
        ``returns`` is 0.
    direction_sigma_deg : float
        The largest, over those two beacons' two best panels each (four
        panels), of the standard deviation of the direction of a line fitted
        to the panel's returns under the scanner's range noise, degrees:
        ``sigma_r * rms(|n . u_i|) / sqrt(sum_i (t_i - mean t)^2)``, with
        ``n`` the panel's normal, ``u_i`` the unit beam of return ``i`` and
        ``t_i`` its position along the panel (the total-least-squares
        formula the segmentation gives each line, evaluated on the
        noise-free returns with the true ``sigma_r``). It folds the panel's
        seen length, its returns, its incidence and the noise into one
        dimensionless figure, the one panel identification compares
        deflection angles with; ``nan`` when ``returns`` is 0.
    beacons : tuple of str
        The two best-seen beacons, the stronger first.
    """

    returns: int
    range_m: float
    direction_sigma_deg: float
    beacons: tuple[str, ...]


def detection_evidence(
    truth: SimulatedScan, survey: Survey, *, range_sigma_m: float
) -> DetectionEvidence:
    """The evidence a noise-free scan holds for a fix (see :class:`DetectionEvidence`).

    Parameters
    ----------
    truth : SimulatedScan
        The scan simulated from the true pose with the scanner's noise-free model.
    survey : Survey
        The scene's beacons (for their centroids).
    range_sigma_m : float
        The scanner's range noise, metres (``truth`` has none).
    """
    hits = truth.panel_hits()
    seen = truth.panels_seen(_RANKED)
    position = truth.pose.position
    ranked: list[tuple[int, float, str, list[int]]] = []
    for b, panels in seen.items():
        best = sorted(panels, key=lambda p: hits[(b, p)], reverse=True)[:2]
        score = hits[(b, best[1])] if len(best) == 2 else 0
        dist = float(np.hypot(*(survey[b].centroid - position)))
        ranked.append((score, dist, b, best))
    ranked.sort(key=lambda r: (-r[0], r[1]))
    if len(ranked) < 2 or ranked[1][0] == 0:
        return DetectionEvidence(0, math.nan, math.nan, tuple(r[2] for r in ranked[:2]))
    top = ranked[:2]
    sigmas = [
        _direction_sigma_rad(truth, b, p, range_sigma_m) for _, _, b, best in top for p in best
    ]
    return DetectionEvidence(
        returns=top[1][0],
        range_m=max(r[1] for r in top),
        direction_sigma_deg=math.degrees(max(sigmas)),
        beacons=(top[0][2], top[1][2]),
    )


def _direction_sigma_rad(truth: SimulatedScan, beacon: str, panel: int, sigma_m: float) -> float:
    """Direction standard deviation of a TLS line through one panel's returns."""
    beams, pts_all = truth.scan.points()
    k = truth.surfaces.index(Surface("beacon", beacon, panel))
    pts = pts_all[truth.surface_index[beams] == k]
    line = fit_line(pts)
    u = pts / np.hypot(pts[:, 0], pts[:, 1])[:, None]
    perp = sigma_m * math.sqrt(float(np.mean((u @ line.normal) ** 2)))
    spread = line.t_spread
    return perp / math.sqrt(spread) if spread > 0 else math.inf


@dataclass(frozen=True, slots=True)
class DetectionBin:
    """Draws of one configuration whose evidence falls in one bin.

    Attributes
    ----------
    measure : str
        The row column binned (``evidence_returns`` or ``evidence_direction_sigma_deg``).
    config : str
    label : str
        The bin as printed, e.g. ``"5-7"``.
    low, high : float
        The bin holds ``low <= value < high``.
    draws, fixed : int
    misses : dict of str to int
        Draws without a fix, by reason (every key of ``NO_FIX_REASONS``).
    """

    measure: str
    config: str
    label: str
    low: float
    high: float
    draws: int
    fixed: int
    misses: dict[str, int]

    @property
    def fix_rate(self) -> float:
        return self.fixed / self.draws if self.draws else math.nan


#: The tables: row column, its bin edges, how a bin is labelled, the column header.
_MEASURES: tuple[tuple[str, tuple[float, ...], str, str], ...] = (
    ("evidence_returns", RETURNS_BINS, "int", "returns on the weaker beacon's 2nd panel"),
    (
        "evidence_direction_sigma_deg",
        DIRECTION_SIGMA_BINS_DEG,
        "deg",
        "direction sigma of the weakest panel, degrees",
    ),
)


def _label(low: float, high: float, kind: str) -> str:
    if kind == "int":
        if math.isinf(high):
            return f">={low:g}"
        return f"{low:g}" if high - low == 1 else f"{low:g}-{high - 1:g}"
    if math.isinf(high):
        return f">={low:g}"
    return f"<{high:g}" if low == 0 else f"{low:g}-{high:g}"


def detection_bins(
    rows_by_config: Mapping[str, Sequence[Mapping[str, object]]],
) -> list[DetectionBin]:
    """Bin every configuration's draws by each evidence measure.

    Parameters
    ----------
    rows_by_config : mapping of str to rows
        The accuracy benchmark's per-draw rows (with ``fixed``, ``reason`` and
        the ``evidence_*`` columns), per configuration.

    Returns
    -------
    list of DetectionBin
        Per measure, configuration and bin, in that order. Draws below the
        first edge (or with no evidence) go to a bin ``<edge`` (or ``none``),
        listed only when not empty.
    """
    out: list[DetectionBin] = []
    for measure, edges, kind, _ in _MEASURES:
        for config, rows in rows_by_config.items():
            values = np.array([float(r[measure]) for r in rows])  # type: ignore[arg-type]
            groups = [
                (_label(lo, hi, kind), lo, hi, (values >= lo) & (values < hi))
                for lo, hi in zip(edges, (*edges[1:], math.inf), strict=True)
            ]
            # Below the first edge, and no evidence at all: only when they occur.
            below: NDArray[np.bool_] = values < edges[0]
            if np.any(below):
                groups.insert(0, (f"<{edges[0]:g}", -math.inf, edges[0], below))
            nan: NDArray[np.bool_] = np.isnan(values)
            if np.any(nan):
                groups.append(("none", math.nan, math.nan, nan))
            for label, lo, hi, sel in groups:
                chosen = [r for r, s in zip(rows, sel, strict=True) if s]
                misses = dict.fromkeys(NO_FIX_REASONS, 0)
                for r in chosen:
                    if not r["fixed"]:
                        reason = str(r["reason"])
                        misses[reason] = misses.get(reason, 0) + 1
                out.append(
                    DetectionBin(
                        measure=measure,
                        config=config,
                        label=label,
                        low=lo,
                        high=hi,
                        draws=len(chosen),
                        fixed=sum(1 for r in chosen if r["fixed"]),
                        misses=misses,
                    )
                )
    return out


def detection_table(rows_by_config: Mapping[str, Sequence[Mapping[str, object]]]) -> str:
    """Two text tables of :func:`detection_bins`: fix rate and the share of the
    misses by reason, per configuration and bin of each evidence measure.

    Reasons no draw of any configuration gave are left out of the columns.
    """
    bins = detection_bins(rows_by_config)
    reasons = [k for k in NO_FIX_REASONS if any(b.misses.get(k, 0) for b in bins)]
    reasons += sorted({k for b in bins for k, n in b.misses.items() if n} - set(reasons))
    width = max([len(c) for c in rows_by_config] + [6])
    lines: list[str] = []
    for measure, _, _, title in _MEASURES:
        lines.append(f"Fix rate by {title} ({measure}); misses by reason, % of the bin's misses")
        head = f"{'config':<{width}} {'bin':>9} {'draws':>6} {'fix %':>6}"
        head += "".join(f" {k[:12]:>12}" for k in reasons)
        lines.append(head)
        for b in bins:
            if b.measure != measure:
                continue
            missed = b.draws - b.fixed
            line = f"{b.config:<{width}} {b.label:>9} {b.draws:>6} "
            line += f"{100 * b.fix_rate:>6.1f}" if b.draws else f"{'-':>6}"
            for k in reasons:
                cell = f"{100 * b.misses.get(k, 0) / missed:.0f}" if missed else "-"
                line += f" {cell:>12}"
            lines.append(line)
        lines.append("")
    return "\n".join(lines[:-1])


def detection_rows(bins: Sequence[DetectionBin]) -> list[dict[str, object]]:
    """:class:`DetectionBin` records flattened for a CSV file (``miss_<reason>`` counts)."""
    return [
        {
            "measure": b.measure,
            "config": b.config,
            "bin": b.label,
            "low": b.low,
            "high": b.high,
            "draws": b.draws,
            "fixed": b.fixed,
            "fix_rate": b.fix_rate,
            **{f"miss_{k}": n for k, n in b.misses.items()},
        }
        for b in bins
    ]
