"""The beacon survey file: ``beacon,edge,easting,northing[,elevation]``."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from mast.core.beacon import Beacon, IdentifiabilityRules, Survey
from mast.errors import BeaconError, InputError
from mast.io._csv import CsvRows, parse_number

__all__ = ["read_survey", "write_survey"]

_DEFAULT_RULES = IdentifiabilityRules()


def read_survey(
    path: str | Path,
    *,
    rules: IdentifiabilityRules | None = _DEFAULT_RULES,
) -> Survey:
    """Read a beacon survey CSV (DESIGN.md, "Beacon survey file").

    One row per surveyed edge; ``edge`` is 1..4 in polyline order and every
    beacon has exactly four. Each beacon is checked to be identifiable under
    ``rules`` (pass ``None`` to skip, e.g. to inspect a bad survey).

    Raises
    ------
    InputError
        Naming the file, the line and the problem.
    """
    rows = CsvRows(
        path,
        required=("beacon", "edge", "easting", "northing"),
        optional=("elevation",),
    )
    p = rows.path
    edges: dict[str, dict[int, tuple[float, float, float, int]]] = {}
    for line, f in rows:
        bid = f["beacon"].strip()
        if not bid:
            raise InputError("column 'beacon' is empty", path=p, line=line)
        e = parse_number(f["edge"], column="edge", path=p, line=line)
        if e != int(e) or not 1 <= e <= 4:
            raise InputError(
                f"column 'edge': {f['edge'].strip()!r} is not an edge number 1..4",
                path=p,
                line=line,
            )
        k = int(e)
        east = parse_number(f["easting"], column="easting", path=p, line=line)
        north = parse_number(f["northing"], column="northing", path=p, line=line)
        elev = math.nan
        if rows.has("elevation") and f["elevation"].strip():
            elev = parse_number(f["elevation"], column="elevation", path=p, line=line)
        got = edges.setdefault(bid, {})
        if k in got:
            raise InputError(
                f"beacon {bid!r} edge {k} given twice (first on line {got[k][3]})",
                path=p,
                line=line,
            )
        got[k] = (east, north, elev, line)
    if not edges:
        raise InputError("no beacon rows after the header", path=p, line=rows.header_line)
    beacons = []
    for bid, got in edges.items():
        first = min(v[3] for v in got.values())
        if len(got) != 4:
            missing = [str(k) for k in range(1, 5) if k not in got]
            raise InputError(
                f"beacon {bid!r} has {len(got)} edge(s); edge(s) {', '.join(missing)} missing "
                "(every beacon needs edges 1, 2, 3 and 4)",
                path=p,
                line=first,
            )
        xy = np.array([[got[k][0], got[k][1]] for k in range(1, 5)])
        z = np.array([got[k][2] for k in range(1, 5)])
        beacon = Beacon(bid, xy, None if np.all(np.isnan(z)) else z)
        if rules is not None:
            problems = beacon.identifiability_problems(rules)
            if problems:
                raise BeaconError(
                    f"beacon {bid!r} is not identifiable: " + "; ".join(problems),
                    path=p,
                    line=first,
                )
        beacons.append(beacon)
    return Survey(beacons, source=str(p))


def write_survey(path: str | Path, survey: Survey) -> None:
    """Write a survey in the beacon CSV contract (full double precision)."""
    with_z = any(b.elevations is not None for b in survey)
    with Path(path).open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["beacon", "edge", "easting", "northing", *(["elevation"] if with_z else [])])
        for b in survey:
            for k in range(4):
                row = [b.id, k + 1, repr(float(b.edges[k, 0])), repr(float(b.edges[k, 1]))]
                if with_z:
                    z = math.nan if b.elevations is None else float(b.elevations[k])
                    row.append("" if math.isnan(z) else repr(z))
                w.writerow(row)
