"""Drift outlines read from CSV and DXF, the centreline and the grid of cells."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mast.core.walls import Drift, Wall
from mast.errors import InputError
from mast.io.drift import read_drift
from mast.plan.drift import build_grid, centreline, wall_distance
from mast.sim.tunnel import Tunnel
from tests.test_plan._scenes import ORIGIN, straight_drift

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "plan"


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_example_csv_and_dxf_give_the_same_walls() -> None:
    csv = read_drift(EXAMPLE / "drift.csv")
    dxf = read_drift(EXAMPLE / "drift.dxf")
    assert [w.points.shape for w in csv.walls] == [w.points.shape for w in dxf.walls]
    for a, b in zip(csv.walls, dxf.walls, strict=True):
        np.testing.assert_allclose(a.points, b.points, atol=1e-9)
    assert [w.id for w in csv.walls] == ["north", "south"]


def test_csv_vertices_are_ordered_by_number(tmp_path: Path) -> None:
    p = _write(
        tmp_path / "d.csv",
        "wall,vertex,easting,northing\nw,2,10,0\nw,1,0,0\nw,3,20,0\nv,1,0,5\nv,2,20,5\n",
    )
    d = read_drift(p)
    np.testing.assert_array_equal(d.walls[0].points[:, 0], [0, 10, 20])
    assert d.length_m == pytest.approx(40.0)


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("wall,vertex,easting\nw,1,0\n", 1, "northing"),
        ("wall,vertex,easting,northing\nw,1,0,0\nw,1,5,0\n", 3, "given twice"),
        ("wall,vertex,easting,northing\nw,1,0,0\nw,2,x,0\n", 3, "not a number"),
        (
            "wall,vertex,easting,northing\nw,1,0,0\nw,2,1e300,0\n",
            3,
            "not a plausible grid coordinate",
        ),
        ("wall,vertex,easting,northing\nw,1.5,0,0\n", 2, "whole number"),
        ("wall,vertex,easting,northing\nw,1,0,0\nv,1,0,5\nv,2,9,5\n", 2, "one vertex"),
        ("wall,vertex,easting,northing\n,1,0,0\n", 2, "empty"),
    ],
)
def test_bad_csv_names_the_line(tmp_path: Path, text: str, line: int, words: str) -> None:
    p = _write(tmp_path / "d.csv", text)
    with pytest.raises(InputError) as err:
        read_drift(p)
    assert str(p) in str(err.value)
    assert words in str(err.value)
    assert err.value.line == line


def test_bad_dxf_is_bad_input(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="DXF"):
        read_drift(_write(tmp_path / "d.dxf", "this is not a drawing\n"))
    with pytest.raises(InputError, match="not found"):
        read_drift(tmp_path / "missing.dxf")
    with pytest.raises(InputError, match="layers with polylines: WALLS"):
        read_drift(EXAMPLE / "drift.dxf", layers=("rock",))
    assert len(read_drift(EXAMPLE / "drift.dxf", layers=("walls",)).walls) == 2


def _true_distance(tunnel: Tunnel, points: np.ndarray) -> np.ndarray:
    c = tunnel.centreline
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(c, axis=0).T))])
    ss = np.linspace(0.0, s[-1], 40_000)
    dense = np.stack([np.interp(ss, s, c[:, 0]), np.interp(ss, s, c[:, 1])], axis=1)
    return np.array([np.min(np.hypot(*(dense - p).T)) for p in points])


@pytest.mark.parametrize("bend", [0.0, 50.0])
def test_centreline_follows_the_drift(bend: float) -> None:
    az = np.radians(
        np.concatenate([np.full(30, 20.0), np.linspace(20, 20 + bend, 21), np.full(30, 20 + bend)])
    )
    centre = ORIGIN + np.vstack([[0.0, 0.0], np.cumsum(np.stack([np.sin(az), np.cos(az)], 1), 0)])
    tunnel = Tunnel(centre, 4.5)
    left, right = tunnel.walls()
    drift = Drift((Wall("l", left), Wall("r", right)))
    line = centreline(drift)
    assert np.max(_true_distance(tunnel, line)) < 0.02
    length = float(np.sum(np.hypot(*np.diff(line, axis=0).T)))
    assert tunnel.length_m - 5.0 < length <= tunnel.length_m + 0.1
    # from the end nearer the first wall's first vertex
    assert np.hypot(*(line[0] - centre[0])) < 3.0


def test_grid_cells_keep_the_margin_and_headings_follow_the_drift() -> None:
    _, drift = straight_drift(length_m=30.0, width_m=6.0, azimuth_deg=30.0)
    grid = build_grid(drift, 2.0, 1.0, 0.5)
    np.testing.assert_allclose(grid.offsets_m, [-2, -1, 0, 1, 2])
    assert grid.inside.all()
    clear = wall_distance(drift, grid.xy.reshape(-1, 2))
    assert clear.min() >= 0.99
    np.testing.assert_allclose(np.degrees(grid.azimuth_rad), 30.0, atol=0.05)
    assert grid.corners().shape == (len(grid.stations_m) + 1, 6, 2)
    # positive offsets lie to the left of the direction of travel (azimuth 30 -> left is NW)
    d = grid.xy[0, 4] - grid.xy[0, 2]
    assert d[0] < 0 < d[1]


def test_a_lone_wall_is_no_drift() -> None:
    drift = Drift((Wall("w", np.array([[0.0, 0.0], [50.0, 0.0]])),), source="one.csv")
    with pytest.raises(InputError, match="enclose no drift"):
        centreline(drift)
