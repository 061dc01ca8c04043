"""What ``mast survey-in`` writes: the survey file, and a report a surveyor signs off.

* ``beacons.csv``: the survey contract with ``elevation`` (each edge's top),
  ``sigma_m`` (each edge's horizontal standard deviation) and ``design``;
* ``report.txt`` and ``report.html`` (the same text, a page that renders offline): per
  beacon its design, the points and plane-fit RMS of each panel, each panel's tilt from
  vertical (said when beyond :data:`TILT_WARNING_DEG`: the paper asks for levelled,
  vertical panels), its measured length beside the design's, the panels' tops and how
  well they agree, and each edge with its sigma; with a previous survey, each edge's
  displacement and whether it moved; the grid's CRS (``--crs``) when given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from mast import __version__
from mast.cloud.survey_in import MOVED_ALPHA, SAME_BEACON_M, SurveyIn
from mast.io.atomic import write_atomic
from mast.io.beacons_csv import write_survey
from mast.io.crs import GridCrs
from mast.report.html import CSS, escape

__all__ = ["TILT_WARNING_DEG", "SurveyInFiles", "write_survey_in"]

#: A panel tilted more than this from vertical is named in the report.
TILT_WARNING_DEG = 1.0


@dataclass(frozen=True, slots=True)
class SurveyInFiles:
    survey: Path
    report_txt: Path
    report_html: Path


def write_survey_in(
    result: SurveyIn,
    out: Path,
    *,
    clouds: list[Path],
    designs_file: Path,
    crs: GridCrs | None = None,
) -> SurveyInFiles:
    """Write the survey and the reports into ``out`` (created); the reports name the
    grid's ``crs`` when given."""
    out.mkdir(parents=True, exist_ok=True)
    survey = out / "beacons.csv"
    if result.beacons:
        write_survey(survey, result.survey)
    else:  # no survey rather than an earlier run's left beside this report
        survey.unlink(missing_ok=True)
    text = report_text(result, clouds=clouds, designs_file=designs_file, crs=crs)
    txt = out / "report.txt"
    write_atomic(txt, text.encode("utf-8"))
    html = out / "report.html"
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>MAST survey-in</title><style>{CSS}</style></head><body>"
        f"<h1>Beacons surveyed in</h1><pre>{escape(text)}</pre></body></html>\n"
    )
    write_atomic(html, page.encode("utf-8"))
    return SurveyInFiles(survey, txt, html)


def report_text(
    result: SurveyIn, *, clouds: list[Path], designs_file: Path, crs: GridCrs | None = None
) -> str:
    lines: list[str] = []
    add = lines.append
    add("MAST survey-in: beacon edges from terrestrial laser scans")
    add("=" * 57)
    add(f"clouds           {', '.join(str(c) for c in clouds)}  ({result.points} points)")
    add(f"designs          {designs_file}  ({', '.join(result.designs.ids)})")
    add(f"noise            {1000 * result.pieces.segmentation.noise_m:.2f} mm (given)")
    if crs is not None:
        add(f"grid CRS         {crs.line()}")
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S")
    add(f"computed         {when} UTC, mast {__version__}")
    add("")
    add(
        f"{len(result.beacons)} beacon(s) surveyed in; {result.partial} seen in part (one "
        f"corner: scan them from another station); {result.rejected} shape(s) that no "
        "design holds, left out"
    )
    for c in result.edge_on:
        add(
            f"  a middle panel seen edge-on at E {c[0]:.3f} N {c[1]:.3f}, between outer panels "
            "of a design, not surveyed: its points do not fit the design (too few, too "
            "short, or off its angles: mixed returns); scan it from another station"
        )
    for f in result.beacons:
        b = f.beacon
        add("")
        title = f"{b.id}  (design {b.design})"
        if f.previous is not None:
            title += f"  was {f.previous} within {SAME_BEACON_M:g} m"
        add(title)
        add("-" * len(title))
        for k, p in enumerate(f.panels):
            tilt = p.tilt_deg
            warn = f"  TILTED more than {TILT_WARNING_DEG:g} deg" if tilt > TILT_WARNING_DEG else ""
            add(
                f"  P{k + 1}  {f.points_per_panel[k]:7d} pts  plane RMS "
                f"{1000 * p.plane_rms_m:5.2f} mm  tilt {tilt:5.2f} deg  length seen "
                f"{1000 * f.panel_lengths_m[k]:6.1f} of {1000 * f.design_lengths_m[k]:6.1f} mm"
                f"  top {p.top_m:.4f} m{warn}"
            )
        tops = np.array([p.top_m for p in f.panels])
        add(
            f"  top  {b.elevations[0] if b.elevations is not None else math.nan:.4f} m "
            f"(sigma {1000 * f.sigma_top_m:.2f} mm; panels' tops within "
            f"{1000 * float(np.ptp(tops)):.1f} mm)"
        )
        sig = b.edge_sigmas_m if b.edge_sigmas_m is not None else np.full(4, math.nan)
        for k in range(4):
            e, n = b.edges[k]
            line = f"  e{k + 1}   E {e:.4f}  N {n:.4f}  sigma {1000 * sig[k]:.2f} mm"
            if f.previous is not None:
                verdict = (
                    "untested (the previous survey gives no sigma_m)"
                    if f.moved[k] is None
                    else ("MOVED" if f.moved[k] else "not moved") + f" (at {100 * MOVED_ALPHA:g} %)"
                )
                line += f"  moved {1000 * f.displacement_m[k]:.1f} mm: {verdict}"
            add(line)
    if result.previous_missing:
        add("")
        add("Previous beacons not found: " + ", ".join(result.previous_missing))
    return "\n".join(lines) + "\n"
