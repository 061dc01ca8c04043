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


def test_laserscan_needs_positive_increment() -> None:
    with pytest.raises(InputError, match="must be positive"):
        Scan.from_laserscan(angle_min=0.0, angle_increment=-0.01, ranges=[1.0, 2.0])


def test_uniformity() -> None:
    assert Scan.from_laserscan(angle_min=-1.0, angle_increment=0.01, ranges=np.ones(100)).is_uniform
    assert not Scan([0.0, 0.1, 0.3], [1.0, 1.0, 1.0]).is_uniform
