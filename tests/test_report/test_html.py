"""The one HTML and figure kit: numbers and map axes printed alike in every report."""

from __future__ import annotations

import numpy as np

from mast.report.html import axis_label, escape, group_thousands, plot_origin


def test_thousands_are_grouped_by_thin_spaces() -> None:
    assert group_thousands(7_012_000.0) == "7\u2009012\u2009000"
    assert group_thousands(512_006.99912, 3) == "512\u2009006.999"


def test_axes_count_from_a_round_origin_and_say_so_on_either_side_of_zero() -> None:
    near = np.array([[12.0, 30.0], [40.0, 90.0]])
    assert plot_origin(near) == (0.0, 0.0)
    assert axis_label("Easting", 0.0) == "Easting (m)"
    utm = np.array([[512_006.9, 7_012_007.0], [512_030.0, 7_012_050.0]])
    assert plot_origin(utm) == (512_000.0, 7_012_000.0)
    assert axis_label("E", 512_000.0) == "E − 512\u2009000 (m)"
    west = np.array([[-20_450.0, 3.0], [-20_420.0, 40.0]])
    e0, _ = plot_origin(west)
    assert e0 == -20_500.0
    assert axis_label("E", e0) == "E + 20\u2009500 (m)"  # E - (-20 500)


def test_text_is_escaped_for_html() -> None:
    assert escape('<b>"B1" & B2</b>') == "&lt;b&gt;&quot;B1&quot; &amp; B2&lt;/b&gt;"
