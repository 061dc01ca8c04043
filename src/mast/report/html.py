"""The kit every HTML report is made with: one style sheet, escaping, numbers as survey
sheets print them, map axes counted from a round origin, and matplotlib figures inline
as SVG (no network, no files beside the page).

``mast track``'s run report and ``mast georef``'s report both use it, so that the two
print numbers and draw their axes alike.
"""

from __future__ import annotations

import html
import io
import math
import re
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CSS",
    "axis_label",
    "escape",
    "group_thousands",
    "inline_svg",
    "new_figure",
    "plot_origin",
]

#: The reports' one style sheet.
CSS: Final = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #222;
       max-width: 1100px; margin: 1.5em auto; padding: 0 1em; line-height: 1.4; }
h1 { font-size: 1.6em; margin-bottom: 0.1em; }
h2 { font-size: 1.2em; margin-top: 1.8em; border-bottom: 1px solid #ccc; }
.sub { color: #555; margin-top: 0; }
table { border-collapse: collapse; font-size: 0.9em; }
th, td { padding: 0.2em 0.6em; border-bottom: 1px solid #e4e4e4; text-align: left; }
td.n, th.n { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
table.summary th { font-weight: normal; color: #555; }
figure { margin: 1em 0; }
figure svg { max-width: 100%; height: auto; }
figcaption { font-size: 0.9em; color: #444; }
.note { color: #8a5a00; }
.test-pass { color: #1b6e20; } .test-too_small, .test-too_large { color: #a33; }
footer { margin-top: 2em; font-size: 0.8em; color: #777; }
"""


def escape(value: object) -> str:
    """``value`` as text safe inside an HTML element or a quoted attribute."""
    return html.escape(str(value), quote=True)


def group_thousands(value: float, decimals: int = 0) -> str:
    """A number with its thousands grouped by thin spaces, as survey sheets print them."""
    return f"{value:,.{decimals}f}".replace(",", "\u2009")


def plot_origin(points: NDArray[np.float64]) -> tuple[float, float]:
    """Round point a map's axes count from: zero for coordinates under 10 km, else a
    multiple of 100 m (or a larger power of ten for a wide view) just below them."""
    if len(points) == 0 or float(np.max(np.abs(points))) < 10_000.0:
        return 0.0, 0.0
    lo, hi = points.min(axis=0), points.max(axis=0)
    span = float(np.max(hi - lo))
    step = 10.0 ** max(2, math.ceil(math.log10(max(span, 1.0))))
    return (math.floor(float(lo[0]) / step) * step, math.floor(float(lo[1]) / step) * step)


def axis_label(name: str, value: float) -> str:
    """A map axis' label, naming the origin (:func:`plot_origin`) it counts from: ``E −
    12 300 (m)`` counts from E = 12 300 m, ``E + 500 (m)`` from E = −500 m."""
    if value == 0.0:
        return f"{name} (m)"
    sign = "−" if value > 0 else "+"
    return f"{name} {sign} {group_thousands(abs(value))} (m)"


def inline_svg(fig: Any, name: str) -> str:
    """A matplotlib figure as inline ``<svg>`` (no XML prolog, DOCTYPE or metadata).

    Each figure gets its own hash salt: the ids of its clip paths and markers
    are then unique in the page (several SVGs share one id space) and the
    same from run to run.
    """
    import matplotlib as mpl

    buf = io.StringIO()
    with mpl.rc_context({"svg.hashsalt": f"mast-{name}", "svg.fonttype": "none"}):
        fig.savefig(buf, format="svg", metadata={"Date": None})
    text = buf.getvalue()
    start = text.find("<svg")
    text = text[start:]
    text = re.sub(r"<metadata>.*?</metadata>\s*", "", text, count=1, flags=re.DOTALL)
    return text.replace("<svg ", f'<svg role="img" aria-label="{escape(name)}" ', 1)


def new_figure(width_in: float, height_in: float, rows: int = 1) -> tuple[Any, Any]:
    """A figure of ``rows`` axes sharing x, laid out to fit.

    Figure objects, not pyplot: nothing is registered with a GUI back-end or kept alive
    by pyplot's figure manager, so there is nothing to close and no state leaks.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    return fig, axes
