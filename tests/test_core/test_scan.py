import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from mast import InputError, Scan


def test_points_follow_rep103() -> None:
    scan = Scan.from_laserscan(
        angle_min=-math.pi / 2, angle_increment=math.pi / 2, ranges=[2.0, 3.0, 4.0]
    )
    idx, pts = scan.points()
    assert idx.tolist() == [0, 1, 2]
    assert_allclose(pts, [[0.0, -2.0], [3.0, 0.0], [0.0, 4.0]], atol=1e-15)


def test_no_return_values_are_masked() -> None:
    scan = Scan(
        np.arange(7) * 0.1,
        [1.0, np.nan, np.inf, 0.0, -1.0, 50.0, 0.01],
        range_min_m=0.05,
        range_max_m=30.0,
    )
    assert scan.valid.tolist() == [True, False, False, False, False, False, False]
    assert scan.points()[1].shape == (1, 2)


def test_scan_is_immutable() -> None:
    scan = Scan([0.0, 0.1], [1.0, 2.0])
    with pytest.raises(ValueError, match="read-only"):
        scan.ranges_m[0] = 5.0


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"angles_rad": [0.0, 0.1], "ranges_m": [1.0]}, "2 angles but 1 ranges"),
        ({"angles_rad": [0.0, 0.0], "ranges_m": [1.0, 1.0]}, "strictly increase"),
        ({"angles_rad": [0.0, np.nan], "ranges_m": [1.0, 1.0]}, "not a finite number"),
        (
            {"angles_rad": [0.0], "ranges_m": [1.0], "range_min_m": 5.0, "range_max_m": 1.0},
            "not a valid interval",
        ),
        (
            {"angles_rad": [0.0, 0.1], "ranges_m": [1.0, 1.0], "intensities": [1.0]},
            "1 intensities for 2 ranges",
        ),
    ],
)
def test_scan_rejects_inconsistent_input(kwargs: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message):
        Scan(**kwargs)  # type: ignore[arg-type]


def test_laserscan_refuses_a_zero_increment() -> None:
    with pytest.raises(InputError, match="angle_increment is 0"):
        Scan.from_laserscan(angle_min=0.0, angle_increment=0.0, ranges=[1.0, 2.0])


def test_a_negative_increment_is_the_same_beams_in_reverse() -> None:
    # ROS allows angle_min > angle_max with a negative increment (a scanner mounted
    # upside down sweeps clockwise): each range keeps its own angle.
    from mast.pipeline import LocatorConfig, locate
    from mast.sim import paper_scene

    scene = paper_scene("parallel")
    up = scene.simulate_all()[2].scan
    n = len(up)
    down = Scan.from_laserscan(
        angle_min=float(up.angles_rad[-1]),
        angle_increment=-up.angle_increment,
        ranges=up.ranges_m[::-1],
        intensities=np.arange(n, dtype=float)[::-1],
    )
    np.testing.assert_allclose(down.angles_rad, up.angles_rad, atol=1e-12)
    np.testing.assert_array_equal(down.ranges_m, up.ranges_m)
    assert down.intensities is not None
    np.testing.assert_array_equal(down.intensities, np.arange(n))
    cfg = LocatorConfig(range_sigma_m=0.005)
    a, b = locate(up, scene.survey, config=cfg), locate(down, scene.survey, config=cfg)
    assert a.ok
    assert b.ok
    assert a.pose is not None
    assert b.pose is not None
    assert abs(a.pose.easting - b.pose.easting) < 1e-9
    assert abs(a.pose.azimuth_deg - b.pose.azimuth_deg) < 1e-7


def test_uniformity() -> None:
    assert Scan.from_laserscan(angle_min=-1.0, angle_increment=0.01, ranges=np.ones(100)).is_uniform
    assert not Scan([0.0, 0.1, 0.3], [1.0, 1.0, 1.0]).is_uniform


def test_ranges_beyond_the_limits_in_another_unit_get_a_hint() -> None:
    # A narrow drift scanned by a 5.6 m scanner, ranges written in millimetres:
    # the median (about 600) is no proof by itself, but no beam is within the limits.
    ranges = np.linspace(300.0, 900.0, 200)
    with pytest.raises(InputError, match=r"no range lies within .* look like millimetres"):
        Scan.from_laserscan(
            angle_min=-2.0, angle_increment=0.02, ranges=ranges, range_min=0.02, range_max=5.6
        )


def test_a_scan_without_any_echo_is_not_a_unit_mistake() -> None:
    # Drivers report "no echo" just beyond the longest range: a scan, with no valid return.
    scan = Scan.from_laserscan(
        angle_min=-2.0, angle_increment=0.02, ranges=np.full(200, 65.533), range_max=30.0
    )
    assert not scan.valid.any()
