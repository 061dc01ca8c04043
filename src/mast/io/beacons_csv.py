"""The beacon survey file: ``beacon,edge,easting,northing[,elevation][,sigma_m][,design]``.

``sigma_m`` (optional, per edge) is the standard deviation of that edge's easting and
northing, metres, where the survey gives one (``mast survey-in`` does); ``design``
(optional, per beacon: the same on its four rows) names the design it is built to.
An empty field leaves it out for that edge or beacon."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mast import limits
from mast.core.beacon import Beacon, IdentifiabilityRules, Survey
from mast.errors import BeaconError, InputError, quoted
from mast.io._csv import CsvRows, parse_number, parse_within
from mast.io.atomic import atomic_open

__all__ = ["COINCIDENT_M", "read_survey", "write_survey"]

_DEFAULT_RULES = IdentifiabilityRules()
#: A panel longer than this is no beacon's (they are tens of centimetres), metres.
MAX_PANEL_M = 10.0
#: Two surveyed edge points closer than this are one point surveyed twice, metres.
COINCIDENT_M = 1e-3


def _crosses(
    a0: NDArray[np.float64],
    a1: NDArray[np.float64],
    b0: NDArray[np.float64],
    b1: NDArray[np.float64],
) -> bool:
    """Whether the segments a0-a1 and b0-b1 cross or touch."""

    def side(p: NDArray[np.float64], q: NDArray[np.float64], r: NDArray[np.float64]) -> float:
        return float((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

    d1, d2 = side(a0, a1, b0), side(a0, a1, b1)
    d3, d4 = side(b0, b1, a0), side(b0, b1, a1)
    return d1 * d2 <= 0 and d3 * d4 <= 0


def _check_shape(bid: str, xy: NDArray[np.float64], lines: list[int], path: Path) -> None:
    """Refuse a beacon with two edges at one point, whose panels cross (folded on itself),
    or with a panel longer than :data:`MAX_PANEL_M` (a survey in millimetres, most
    likely: say so)."""
    for k in range(3):
        length = math.dist(xy[k], xy[k + 1])
        if length > MAX_PANEL_M:
            raise InputError(
                f"beacon {quoted(bid)}: panel P{k + 1} (edges {k + 1}-{k + 2}) is {length:.6g} m "
                "long where a beacon's panels are tens of centimetres: is the survey in "
                "millimetres? Easting and northing are metres",
                path=path,
                line=lines[k + 1],
            )
    for i in range(4):
        for j in range(i + 1, 4):
            if math.dist(xy[i], xy[j]) < COINCIDENT_M:
                raise InputError(
                    f"beacon {quoted(bid)}: edges {i + 1} and {j + 1} are the same point "
                    f"(less than {COINCIDENT_M * 1000:g} mm apart; line {lines[i]} and this one)",
                    path=path,
                    line=lines[j],
                )
    if _crosses(xy[0], xy[1], xy[2], xy[3]):
        raise InputError(
            f"beacon {quoted(bid)} is folded on itself: its panels P1 (edges 1-2) and P3 "
            "(edges 3-4) cross; edges must be in polyline order along the beacon",
            path=path,
            line=lines[3],
        )


def _check_apart(
    beacons: list[Beacon], rows: dict[str, dict[int, tuple[float, float, float, int]]], path: Path
) -> None:
    """Refuse two beacons sharing an edge point (a beacon surveyed twice under two ids)."""
    from scipy.spatial import cKDTree

    xy = np.concatenate([b.edges for b in beacons])
    close = cKDTree(xy).query_pairs(COINCIDENT_M, output_type="ndarray")
    for i, j in sorted(map(tuple, close.tolist())):
        a, b = beacons[i // 4], beacons[j // 4]
        if a.id == b.id:
            continue  # within one beacon: checked with its shape
        line_a = rows[a.id][i % 4 + 1][3]
        line_b = rows[b.id][j % 4 + 1][3]
        first, second = sorted((line_a, line_b))
        raise InputError(
            f"beacons {quoted(a.id)} and {quoted(b.id)} share an edge point (edge {i % 4 + 1} "
            f"and edge {j % 4 + 1} less than {COINCIDENT_M * 1000:g} mm apart, lines {first} and "
            f"{second}): one beacon surveyed twice?",
            path=path,
            line=second,
        )


def read_survey(
    path: str | Path,
    *,
    rules: IdentifiabilityRules | None = _DEFAULT_RULES,
    apart: bool = True,
) -> Survey:
    """Read a beacon survey CSV (DESIGN.md, "Beacon survey file").

    One row per surveyed edge; ``edge`` is 1..4 in polyline order and every
    beacon has exactly four. Each beacon is checked to be identifiable under
    ``rules`` (pass ``None`` to skip, e.g. to inspect a bad survey), and no two
    beacons to share an edge point unless ``apart`` is False (a designs file: one
    beacon per design, each in its own frame, often all at one origin).

    Raises
    ------
    InputError
        Naming the file, the line and the problem.
    """
    rows = CsvRows(
        path,
        required=("beacon", "edge", "easting", "northing"),
        optional=("elevation", "sigma_m", "design"),
    )
    p = rows.path
    edges: dict[str, dict[int, tuple[float, float, float, int]]] = {}
    sigmas: dict[tuple[str, int], float] = {}
    designs: dict[str, tuple[str, int]] = {}
    last_id: str | None = None
    for line, f in rows:
        bid = f["beacon"].strip()
        if not bid:
            raise InputError("column 'beacon' is empty", path=p, line=line)
        e = parse_number(f["edge"], column="edge", path=p, line=line)
        if e != int(e) or not 1 <= e <= 4:
            raise InputError(
                f"column 'edge': {quoted(f['edge'].strip())} is not an edge number 1..4",
                path=p,
                line=line,
            )
        k = int(e)
        east = parse_within(f["easting"], column="easting", path=p, line=line)
        north = parse_within(f["northing"], column="northing", path=p, line=line)
        elev = math.nan
        if rows.has("elevation") and f["elevation"].strip():
            elev = parse_within(
                f["elevation"],
                column="elevation",
                path=p,
                line=line,
                bound="MAX_ELEVATION_M",
                what="elevation",
            )
        got = edges.get(bid)
        if got is None:
            if len(edges) >= limits.MAX_BEACONS:
                raise InputError(
                    f"more than {limits.MAX_BEACONS} beacons, the most MAST takes in one survey "
                    "(mast.limits.MAX_BEACONS)",
                    path=p,
                    line=line,
                )
            got = edges[bid] = {}
        elif bid != last_id and len(got) == 4:
            first = min(v[3] for v in got.values())
            raise InputError(
                f"beacon id {quoted(bid)} is used twice: a beacon of that id was given "
                f"on lines {first}-{max(v[3] for v in got.values())}",
                path=p,
                line=line,
            )
        if k in got:
            raise InputError(
                f"beacon {quoted(bid)} edge {k} given twice (first on line {got[k][3]})",
                path=p,
                line=line,
            )
        got[k] = (east, north, elev, line)
        if rows.has("sigma_m") and f["sigma_m"].strip():
            sigmas[(bid, k)] = _sigma(f["sigma_m"], p, line)
        if rows.has("design") and f["design"].strip():
            name = f["design"].strip()
            before = designs.setdefault(bid, (name, line))
            if before[0] != name:
                raise InputError(
                    f"beacon {quoted(bid)} is of design {quoted(before[0])} on line {before[1]} "
                    f"and {quoted(name)} here: a beacon has one design",
                    path=p,
                    line=line,
                )
        last_id = bid
    if not edges:
        raise InputError("no beacon rows after the header", path=p, line=rows.header_line)
    beacons = []
    for bid, got in edges.items():
        first = min(v[3] for v in got.values())
        if len(got) != 4:
            missing = [str(k) for k in range(1, 5) if k not in got]
            raise InputError(
                f"beacon {quoted(bid)} has {len(got)} edge(s); edge(s) {', '.join(missing)} "
                "missing (every beacon needs edges 1, 2, 3 and 4)",
                path=p,
                line=first,
            )
        xy = np.array([[got[k][0], got[k][1]] for k in range(1, 5)])
        _check_shape(bid, xy, [got[k][3] for k in range(1, 5)], p)
        z = np.array([got[k][2] for k in range(1, 5)])
        s = np.array([sigmas.get((bid, k), math.nan) for k in range(1, 5)])
        beacon = Beacon(
            bid,
            xy,
            None if np.all(np.isnan(z)) else z,
            None if np.all(np.isnan(s)) else s,
            designs[bid][0] if bid in designs else None,
        )
        if rules is not None:
            problems = beacon.identifiability_problems(rules)
            if problems:
                raise BeaconError(
                    f"beacon {quoted(bid)} is not identifiable: " + "; ".join(problems),
                    path=p,
                    line=first,
                )
        beacons.append(beacon)
    if apart:
        _check_apart(beacons, edges, p)
    return Survey(beacons, source=str(p))


def _sigma(text: str, path: Path, line: int) -> float:
    value = parse_within(
        text,
        column="sigma_m",
        path=path,
        line=line,
        bound="MAX_SURVEY_SIGMA_M",
        what="survey standard deviation",
    )
    if value < 0:
        raise InputError(
            f"column 'sigma_m': {value:g} is negative; a standard deviation is 0 or more",
            path=path,
            line=line,
        )
    return value


def write_survey(path: str | Path, survey: Survey) -> None:
    """Write a survey in the beacon CSV contract (full double precision); ``elevation``,
    ``sigma_m`` and ``design`` only when some beacon has them."""
    with_z = any(b.elevations is not None for b in survey)
    with_s = any(b.edge_sigmas_m is not None for b in survey)
    with_d = any(b.design is not None for b in survey)
    header = ["beacon", "edge", "easting", "northing"]
    header += ["elevation"] * with_z + ["sigma_m"] * with_s + ["design"] * with_d
    with atomic_open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for b in survey:
            for k in range(4):
                row = [b.id, k + 1, repr(float(b.edges[k, 0])), repr(float(b.edges[k, 1]))]
                for present, values in ((with_z, b.elevations), (with_s, b.edge_sigmas_m)):
                    if present:
                        v = math.nan if values is None else float(values[k])
                        row.append("" if math.isnan(v) else repr(v))
                if with_d:
                    row.append(b.design or "")
                w.writerow(row)
