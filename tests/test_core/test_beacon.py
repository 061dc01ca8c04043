import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from mast import Beacon, BeaconError, InputError, Survey
from mast.sim import paper_design

HAT = [[0.0, 0.0], [0.3, 0.4], [1.2, 0.4], [1.35, 0.2]]


def test_template_from_edges() -> None:
    t = Beacon("A", HAT).template
    assert_allclose(t.panel_lengths, [0.5, 0.9, math.hypot(0.15, 0.2)])
    assert_allclose(t.directions[0], [0.6, 0.8])
    assert_allclose(t.normals[0], [-0.8, 0.6])
    # P1 heads up-right, P2 right: a clockwise (negative) turn at e2.
    assert t.deflections[0] == pytest.approx(-math.atan2(0.8, 0.6))
    assert t.deflections[1] == pytest.approx(-math.atan2(0.2, 0.15))
    assert_allclose(t.centroids[1], [0.75, 0.4])
    assert t.centroid_distances[0] == pytest.approx(math.hypot(0.75 - 0.15, 0.4 - 0.2))


def test_template_is_frame_invariant() -> None:
    e = np.array(HAT)
    c, s = math.cos(1.1), math.sin(1.1)
    moved = e @ np.array([[c, -s], [s, c]]).T + [5000.0, 7000.0]
    a, b = Beacon("a", e).template, Beacon("b", moved).template
    assert_allclose(a.panel_lengths, b.panel_lengths, atol=1e-9)
    assert_allclose(a.deflections, b.deflections, atol=1e-12)
    assert_allclose(a.centroid_distances, b.centroid_distances, atol=1e-9)


def test_paper_design_is_identifiable() -> None:
    d = paper_design(1.0, 0.2)
    b = Beacon("P", d.edges_local)
    assert b.identifiability_problems() == []
    assert_allclose(b.template.panel_lengths / b.template.panel_lengths[2], [2, 3, 1])


@pytest.mark.parametrize(
    ("edges", "message"),
    [
        ([[0, 0], [0.5, 0.3], [1.0, 0.0], [1.5, 0.3]], "P1 .* and P2 .* differ by less than 10 %"),
        ([[0, 0], [0.5, 0.0], [1.4, 0.01], [1.6, 0.2]], "deflection at e2 is 0.64°"),
        ([[0, 0], [0.01, 0.0], [0.9, 0.3], [1.2, 0.0]], "panel P1 is 0.010 m long"),
        ([[0, 0], [1.0, 0.0], [0.0, 0.001], [0.5, 0.3]], "folded back"),
    ],
)
def test_unidentifiable_beacons_are_named(edges: list[list[float]], message: str) -> None:
    b = Beacon("W7", edges)
    with pytest.raises(BeaconError, match=rf"beacon 'W7' is not identifiable: .*{message}"):
        b.check_identifiable()


def test_beacon_shape_errors() -> None:
    with pytest.raises(BeaconError, match="needs 4 edges"):
        Beacon("x", [[0, 0], [1, 1]])
    with pytest.raises(BeaconError, match="not finite"):
        Beacon("x", [[0, 0], [1, 1], [2, 0], [np.inf, 1]])


def test_survey_lookup_and_duplicates() -> None:
    s = Survey([Beacon("A", HAT), Beacon("B", np.array(HAT) + 10)])
    assert s.ids == ["A", "B"]
    assert s["B"].edges[0, 0] == 10
    assert "A" in s
    assert len(s) == 2
    with pytest.raises(KeyError, match="no beacon 'Z'"):
        s["Z"]
    with pytest.raises(InputError, match="beacon 'A' appears twice"):
        Survey([Beacon("A", HAT), Beacon("A", HAT)])
