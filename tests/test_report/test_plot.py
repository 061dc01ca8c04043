"""The fix plot at mine coordinates: readable axes, labelled close-ups, no warnings."""

from __future__ import annotations

import itertools
import math
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse
from matplotlib.text import Text
from matplotlib.ticker import ScalarFormatter

from mast import Beacon, Pose2D, Scan, Survey
from mast.errors import InputError, OutputError
from mast.pipeline.locator import Fix, LocatorConfig, locate
from mast.report.plot import PLOT_SUFFIXES, fix_figure, plot_fix
from mast.sim import build_scenario

#: Where the paper's scene is moved to: a UTM-sized easting and northing.
OFFSET = np.array([512_000.0, 7_012_000.0])
CONFIG = LocatorConfig(range_sigma_m=0.012)


def _shifted(survey: Survey) -> Survey:
    return Survey(Beacon(b.id, b.edges + OFFSET, b.elevations) for b in survey)


@pytest.fixture(scope="module")
def utm() -> tuple[Scan, Survey, Fix]:
    """Scan 0 of the paper's parallel walls (12 mm noise), its survey moved to UTM size."""
    scene = build_scenario("paper", 0, noise=True)[1]
    survey = _shifted(scene.survey)
    shot = scene.shots[0]
    scan = scene.simulate_all()[0].scan  # the scanner frame does not move
    fix = locate(scan, survey, config=CONFIG)
    assert fix.ok, fix.detail
    assert fix.pose is not None
    truth = Pose2D(shot.pose.easting + OFFSET[0], shot.pose.northing + OFFSET[1], shot.pose.azimuth)
    assert math.hypot(fix.pose.easting - truth.easting, fix.pose.northing - truth.northing) < 0.05
    return scan, survey, fix


@pytest.fixture(scope="module")
def no_fix(utm: tuple[Scan, Survey, Fix]) -> tuple[Scan, Survey, Fix]:
    """The same scan against a survey of one beacon: no fix."""
    scan, survey, _ = utm
    one = Survey([survey["B1"]])
    fix = locate(scan, one, config=CONFIG)
    assert not fix.ok
    return scan, one, fix


def _drawn(scan: Scan, survey: Survey, fix: Fix, title: str = "") -> Figure:
    """The figure, laid out and drawn (tick labels and extents final), warnings as errors."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = fix_figure(scan, survey, fix, title=title)
        FigureCanvasAgg(fig).draw()  # type: ignore[no-untyped-call]
    return fig


def _axes(fig: Figure, label: str) -> Axes:
    (ax,) = [a for a in fig.axes if a.get_label() == label]
    return ax


def _closeups(fig: Figure) -> dict[str, Axes]:
    return {
        str(a.get_label()).split(":", 1)[1]: a
        for a in fig.axes
        if str(a.get_label()).startswith("closeup:")
    }


def _shown(labels: list[Text], lo: float, hi: float, ticks: np.ndarray) -> list[Text]:
    return [
        t
        for t, v in zip(labels, ticks, strict=True)
        if t.get_visible() and t.get_text() and lo - 1e-9 <= v <= hi + 1e-9
    ]


def _number(text: str) -> float:
    return float(text.replace("−", "-"))


def _grouped(text: str) -> float:
    """``"E − 512\u2009000 (m)"`` (thin spaces) -> 512000.0; ``"Easting E (m)"`` -> 0."""
    m = re.search(r"([−+]) ([\d\u2009]+) \(m\)", text)
    if m is None:
        return 0.0
    value = float(m.group(2).replace("\u2009", ""))
    return value if m.group(1) == "−" else -value


# --------------------------------------------------------------------------- files


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("suffix", [".png", ".svg", ".pdf"])
def test_utm_fix_written_without_a_warning(
    utm: tuple[Scan, Survey, Fix], tmp_path: Path, suffix: str
) -> None:
    scan, survey, fix = utm
    path = tmp_path / f"fix{suffix}"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plot_fix(scan, survey, fix, path, title="scan_000.csv")
    data = path.read_bytes()
    magic = {".png": b"\x89PNG", ".svg": b"<?xml", ".pdf": b"%PDF"}[suffix]
    assert data.startswith(magic)
    assert suffix in PLOT_SUFFIXES


def test_plot_leaves_no_figure_open(utm: tuple[Scan, Survey, Fix], tmp_path: Path) -> None:
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    plot_fix(*utm, tmp_path / "fix.png")
    assert plt.get_fignums() == before


@pytest.mark.parametrize("name", ["fix.txt", "fix", "fix.png.bak"])
def test_unknown_suffix_is_bad_input(
    utm: tuple[Scan, Survey, Fix], tmp_path: Path, name: str
) -> None:
    with pytest.raises(InputError, match="unknown plot file type"):
        plot_fix(*utm, tmp_path / name)
    assert not (tmp_path / name).exists()


def test_upper_case_suffix_is_known(utm: tuple[Scan, Survey, Fix], tmp_path: Path) -> None:
    plot_fix(*utm, tmp_path / "FIX.PNG")
    assert (tmp_path / "FIX.PNG").read_bytes().startswith(b"\x89PNG")


def test_missing_folder_is_an_output_error(utm: tuple[Scan, Survey, Fix], tmp_path: Path) -> None:
    target = tmp_path / "no" / "such" / "fix.png"
    with pytest.raises(OutputError, match="cannot write") as err:
        plot_fix(*utm, target)
    assert err.value.path == str(target)
    assert "No such file or directory" in str(err.value)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes anywhere")
def test_read_only_folder_is_an_output_error(utm: tuple[Scan, Survey, Fix], tmp_path: Path) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="cannot write: Permission denied"):
            plot_fix(*utm, folder / "fix.png")
    finally:
        folder.chmod(0o700)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_full_disk_is_an_output_error(
    utm: tuple[Scan, Survey, Fix], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # every file written takes no byte (/dev/full): what a full disk does to a write
    import builtins

    import mast.io.atomic

    def full(_path: object, mode: str = "r", **kw: object) -> object:
        return builtins.open("/dev/full", mode, **kw)  # type: ignore[call-overload]

    monkeypatch.setattr(mast.io.atomic, "open", full, raising=False)
    target = tmp_path / "fix.png"
    with pytest.raises(OutputError, match="cannot write: No space left on device"):
        plot_fix(*utm, target)
    assert list(tmp_path.iterdir()) == []  # no plot, and no half of one


# --------------------------------------------------------------------------- coordinates


def test_no_axis_uses_an_offset_or_scientific_notation(utm: tuple[Scan, Survey, Fix]) -> None:
    fig = _drawn(*utm)
    assert len(fig.axes) == 4  # scanner, mine, two close-ups
    for ax in fig.axes:
        for axis, lim, ticks in (
            (ax.xaxis, ax.get_xlim(), ax.get_xticks()),
            (ax.yaxis, ax.get_ylim(), ax.get_yticks()),
        ):
            fmt = axis.get_major_formatter()
            assert isinstance(fmt, ScalarFormatter)
            assert fmt.get_offset() == "", (ax.get_label(), fmt.get_offset())
            assert axis.get_offset_text().get_text() == ""
            labels = _shown(axis.get_ticklabels(), min(lim), max(lim), ticks)
            assert 2 <= len(labels) <= 8, (ax.get_label(), [t.get_text() for t in labels])
            for t in labels:
                assert "e" not in t.get_text().lower(), t.get_text()
                # a label says the value of its tick, no hidden multiplier
                assert _number(t.get_text()) == pytest.approx(t.get_position()[axis is ax.yaxis])


def test_mine_axes_count_from_a_stated_round_origin(utm: tuple[Scan, Survey, Fix]) -> None:
    scan, survey, fix = utm
    assert fix.pose is not None
    fig = _drawn(scan, survey, fix)
    mine = _axes(fig, "mine")
    e0, n0 = _grouped(mine.get_xlabel()), _grouped(mine.get_ylabel())
    assert (e0, n0) == (512_000.0, 7_012_000.0)
    assert mine.get_xlabel() == "E − 512\u2009000 (m)"
    assert mine.get_ylabel() == "N − 7\u2009012\u2009000 (m)"
    # the origin is printed on the figure, and the scanner's full coordinates too
    caption = fig.get_supxlabel()
    assert "E 512\u2009000 m, N 7\u2009012\u2009000 m" in caption
    full = f"E {fix.pose.easting:,.3f} m   N {fix.pose.northing:,.3f} m".replace(",", "\u2009")
    assert full in fig.get_suptitle()  # e.g. "E 512 006.999 m   N 7 012 007.002 m"
    # the scanner drawn at its coordinate minus the stated origin
    (scanner,) = [ln for ln in mine.get_lines() if ln.get_label() == "scanner"]
    x, y = np.asarray(scanner.get_xdata())[0], np.asarray(scanner.get_ydata())[0]
    assert x + e0 == pytest.approx(fix.pose.easting, abs=1e-9)
    assert y + n0 == pytest.approx(fix.pose.northing, abs=1e-9)
    # every close-up counts from the same origin
    for ax in _closeups(fig).values():
        assert (ax.get_xlabel(), ax.get_ylabel()) == (mine.get_xlabel(), mine.get_ylabel())


def test_small_coordinates_are_drawn_as_they_are() -> None:
    scene = build_scenario("paper", 0, noise=True)[1]
    scan = scene.simulate_all()[0].scan
    fix = locate(scan, scene.survey, config=CONFIG)
    fig = _drawn(scan, scene.survey, fix)
    assert _axes(fig, "mine").get_xlabel() == "Easting E (m)"
    assert _axes(fig, "mine").get_ylabel() == "Northing N (m)"
    assert "origin" not in fig.get_supxlabel()


def test_tick_labels_do_not_overlap(utm: tuple[Scan, Survey, Fix]) -> None:
    fig = _drawn(*utm)
    canvas = fig.canvas
    assert isinstance(canvas, FigureCanvasAgg)
    renderer = canvas.get_renderer()  # type: ignore[no-untyped-call]
    for ax in fig.axes:
        for axis, lim, ticks in (
            (ax.xaxis, ax.get_xlim(), ax.get_xticks()),
            (ax.yaxis, ax.get_ylim(), ax.get_yticks()),
        ):
            boxes = [
                t.get_window_extent(renderer)
                for t in _shown(axis.get_ticklabels(), min(lim), max(lim), ticks)
            ]
            for a, b in itertools.combinations(boxes, 2):
                assert not a.overlaps(b), (ax.get_label(), a, b)


def test_map_panels_have_equal_aspect_and_frame_the_scanner_and_its_beacons(
    utm: tuple[Scan, Survey, Fix],
) -> None:
    scan, survey, fix = utm
    assert fix.pose is not None
    fig = _drawn(scan, survey, fix)
    for ax in fig.axes:
        assert ax.get_aspect() == 1.0, ax.get_label()
        # one metre is as long across as up, on the page
        (x0, y0), (x1, y1) = ax.transData.transform([[0.0, 0.0], [1.0, 1.0]])
        assert x1 - x0 == pytest.approx(y1 - y0, rel=1e-3), ax.get_label()
    mine = _axes(fig, "mine")
    box = mine.get_window_extent()
    assert 0.55 <= box.height / box.width <= 1.0  # a panel, not a strip
    origin = np.array([_grouped(mine.get_xlabel()), _grouped(mine.get_ylabel())])
    shown = np.vstack([survey[b].edges for b in fix.beacons] + [fix.pose.position[None, :]])
    local = shown - origin
    (xa, xb), (ya, yb) = mine.get_xlim(), mine.get_ylim()
    assert np.all((local[:, 0] > xa) & (local[:, 0] < xb))
    assert np.all((local[:, 1] > ya) & (local[:, 1] < yb))
    # framed on them: no more than a few metres beyond what it must show
    extent = np.ptp(local, axis=0)
    assert xb - xa < 2 * extent.max() + 6
    assert yb - ya < 2 * extent.max() + 6


# --------------------------------------------------------------------------- content


def test_closeups_are_labelled_with_their_residuals(utm: tuple[Scan, Survey, Fix]) -> None:
    scan, survey, fix = utm
    assert fix.residuals is not None
    fig = _drawn(scan, survey, fix)
    closeups = _closeups(fig)
    assert sorted(closeups) == sorted(fix.beacons) == ["B1", "B2"]
    for bid, ax in closeups.items():
        group = fix.residuals.per_beacon[bid]
        title = ax.get_title()
        assert title.startswith(f"(c) {bid}: panels ")
        assert f"RMS {1000 * group.rms_m:.1f} mm, max |w| {group.max_abs_w:.1f}" in title
        assert f"{group.returns} returns" in title
        assert "critical" in title  # the beacon's left-out test
        assert ax.get_xlabel() == "E − 512\u2009000 (m)"
        assert ax.get_ylabel() == "N − 7\u2009012\u2009000 (m)"
        # the panels are named on the plot, their residuals listed in its legend
        texts = {t.get_text() for t in ax.texts}
        assert {"P1", "P2", "P3"} <= texts
        legend = ax.get_legend()
        assert legend is not None
        rows = [t.get_text() for t in legend.get_texts()]
        for (b, p), g in fix.residuals.per_panel.items():
            if b == bid:
                assert f"P{p}: {g.returns} returns, RMS {1000 * g.rms_m:.1f} mm" in " ".join(rows)
        # one residual tick per return used on the beacon
        (ticks,) = ax.collections
        assert isinstance(ticks, LineCollection)
        assert len(ticks.get_segments()) == group.returns


def test_ellipse_and_azimuth_arrow_at_the_scanner(utm: tuple[Scan, Survey, Fix]) -> None:
    scan, survey, fix = utm
    assert fix.pose is not None
    assert fix.adjustment is not None
    fig = _drawn(scan, survey, fix)
    mine = _axes(fig, "mine")
    origin = np.array([_grouped(mine.get_xlabel()), _grouped(mine.get_ylabel())])
    here = fix.pose.position - origin
    (ellipse,) = [p for p in mine.patches if isinstance(p, Ellipse)]
    label = str(ellipse.get_label())
    m = re.match(r"95 % error ellipse ×(\d+) \(a ([\d.]+) mm, b ([\d.]+) mm\)", label)
    assert m is not None, label
    scale = float(m.group(1))
    ell = fix.adjustment.ellipse()
    assert ellipse.center == pytest.approx(tuple(here))
    assert ellipse.width == pytest.approx(2 * ell.semi_major_m * scale)
    assert ellipse.height == pytest.approx(2 * ell.semi_minor_m * scale)
    assert f"Error ellipse drawn ×{scale:g}" in fig.get_supxlabel()
    # the arrow points along the azimuth, clockwise from grid north
    arrows = [a for a in mine.texts if getattr(a, "arrow_patch", None) is not None]
    (arrow,) = arrows
    tail, tip = np.array(arrow.xyann), np.array(arrow.xy)  # type: ignore[attr-defined]
    assert tail == pytest.approx(here)
    d = (tip - tail) / np.hypot(*(tip - tail))
    az = fix.pose.azimuth
    assert d == pytest.approx([math.sin(az), math.cos(az)])
    assert any(t.get_text().startswith("Az ") for t in mine.texts)


def test_legends_only_where_something_is_labelled(utm: tuple[Scan, Survey, Fix]) -> None:
    fig = _drawn(*utm)
    for ax in fig.axes:
        _, labels = ax.get_legend_handles_labels()
        legend = ax.get_legend()
        if not labels:
            assert legend is None, ax.get_label()
        else:
            assert legend is not None, ax.get_label()
            assert all(t.get_text() for t in legend.get_texts())
    assert _axes(fig, "mine").get_legend() is not None


def test_no_fix_shows_scan_survey_and_reason_without_a_warning(
    no_fix: tuple[Scan, Survey, Fix], tmp_path: Path
) -> None:
    scan, survey, fix = no_fix
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plot_fix(scan, survey, fix, tmp_path / "nofix.png", title="scan_000.csv")
        plot_fix(scan, survey, fix, tmp_path / "nofix.svg")
    fig = _drawn(scan, survey, fix, title="scan_000.csv")
    assert sorted(str(a.get_label()) for a in fig.axes) == ["mine", "scanner"]  # no close-ups
    assert f"NO FIX ({fix.reason})" in fig.get_suptitle()
    assert "scan_000.csv" in fig.get_suptitle()
    scanner, mine = _axes(fig, "scanner"), _axes(fig, "mine")
    assert any(ln.get_label() == "returns" for ln in scanner.get_lines())  # the scan
    assert scanner.collections  # its segments
    assert any(t.get_text() == "B1" for t in mine.texts)  # the survey
    assert not mine.patches  # no ellipse: there is no pose
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is not None:  # never an empty one
            assert [t.get_text() for t in legend.get_texts()]
        if not ax.get_legend_handles_labels()[1]:
            assert legend is None
    assert mine.get_xlabel() == "E − 512\u2009000 (m)"


def test_scan_without_returns_plots_without_a_warning(
    utm: tuple[Scan, Survey, Fix], tmp_path: Path
) -> None:
    scan, survey, _ = utm
    blank = Scan(scan.angles_rad, np.full_like(scan.ranges_m, np.nan))
    fix = locate(blank, survey, config=CONFIG)
    assert fix.reason == "no_beacon"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plot_fix(blank, survey, fix, tmp_path / "blank.png")
    fig = _drawn(blank, survey, fix)
    scanner = _axes(fig, "scanner")
    assert "no valid return" in scanner.get_title()
    legend = scanner.get_legend()
    assert legend is not None
    assert [t.get_text() for t in legend.get_texts()] == ["scanner"]


def test_a_folder_in_the_way_is_an_output_error(
    utm: tuple[Scan, Survey, Fix], tmp_path: Path
) -> None:
    target = tmp_path / "fix.png"
    target.mkdir()
    with pytest.raises(OutputError, match="cannot write: Is a directory"):
        plot_fix(*utm, target)
    assert target.is_dir()  # left as it was
