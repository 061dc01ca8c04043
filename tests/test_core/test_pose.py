import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from mast import InputError, Pose2D, format_dms, parse_azimuth

# (scanner azimuth, mine bearing of a target) in all four quadrants, and the
# beam angle phi = A - bearing under which the scanner must see it.
QUADRANTS = [(a, b) for a in (30.0, 120.0, 210.0, 300.0) for b in (45.0, 135.0, 225.0, 315.0)]


@pytest.mark.parametrize(("azimuth_deg", "bearing_deg"), QUADRANTS)
def test_beam_formula_matches_design_in_all_quadrants(
    azimuth_deg: float, bearing_deg: float
) -> None:
    pose = Pose2D.from_degrees(100.0, 200.0, azimuth_deg)
    r = 7.5
    b = math.radians(bearing_deg)
    target = np.array([100.0 + r * math.sin(b), 200.0 + r * math.cos(b)])
    phi = math.radians(azimuth_deg - bearing_deg)
    # scanner -> mine with DESIGN.md's formula
    assert_allclose(pose.beam_to_mine(phi, r), target, atol=1e-12)
    # the same through the rotation matrix on scanner-frame points
    assert_allclose(
        pose.scanner_to_mine([[r * math.cos(phi), r * math.sin(phi)]])[0], target, atol=1e-12
    )
    # mine -> scanner gives back the beam angle (counter-clockwise from +x)
    got = float(pose.beam_angle_to(target[None, :])[0])
    assert math.isclose(math.remainder(got - phi, 2 * math.pi), 0.0, abs_tol=1e-12)


def test_facing_north_east_is_to_the_right() -> None:
    pose = Pose2D.from_degrees(0.0, 0.0, 0.0)
    # A point due east of a north-facing scanner is on its right: y < 0, phi = -90 deg.
    q = pose.mine_to_scanner([[5.0, 0.0]])[0]
    assert_allclose(q, [0.0, -5.0], atol=1e-12)
    # Facing east, a point due north is on the left: phi = +90 deg.
    pose = Pose2D.from_degrees(0.0, 0.0, 90.0)
    assert_allclose(pose.mine_to_scanner([[0.0, 5.0]])[0], [0.0, 5.0], atol=1e-12)


def test_rotation_is_proper() -> None:
    r = Pose2D.from_degrees(0, 0, 37.0).rotation()
    assert math.isclose(float(np.linalg.det(r)), 1.0)
    # Counter-clockwise by 90 - A
    theta = math.radians(90 - 37.0)
    assert_allclose(
        r, [[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]], atol=1e-15
    )


coords = st.floats(-1e6, 1e7, allow_nan=False)
angles = st.floats(-4 * math.pi, 4 * math.pi, allow_nan=False)


@given(
    coords,
    coords,
    angles,
    st.lists(st.tuples(st.floats(-100, 100), st.floats(-100, 100)), min_size=1, max_size=5),
)
def test_mine_scanner_mine_is_identity(
    e: float, n: float, a: float, pts: list[tuple[float, float]]
) -> None:
    pose = Pose2D(e, n, a)
    p = np.array(pts) + [e, n]
    assert_allclose(
        pose.scanner_to_mine(pose.mine_to_scanner(p)), p, atol=1e-8 * (1 + abs(e) + abs(n))
    )
    q = np.array(pts)
    assert_allclose(
        pose.mine_to_scanner(pose.scanner_to_mine(q)), q, atol=1e-8 * (1 + abs(e) + abs(n))
    )


def test_azimuth_deg_wraps_into_0_360() -> None:
    assert Pose2D(0, 0, -math.radians(10)).azimuth_deg == pytest.approx(350.0)
    assert Pose2D(0, 0, math.radians(720)).azimuth_deg == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("deg", "text"),
    [
        (0.0, "0°00'00.0\""),
        (359.99999, "0°00'00.0\""),  # rounds up and wraps
        (12.5, "12°30'00.0\""),
        (359.0 + 59 / 60 + 59.94 / 3600, "359°59'59.9\""),
        (10.0 + 59.99999 / 60, "11°00'00.0\""),  # carry into degrees
        (-10.0, "350°00'00.0\""),
    ],
)
def test_format_dms(deg: float, text: str) -> None:
    assert format_dms(deg) == text


def test_format_dms_signed_keeps_sign() -> None:
    assert format_dms(-0.5, signed=True) == "-0°30'00.0\""
    assert format_dms(1 / 3600, signed=True, decimals=2) == "0°00'01.00\""


@pytest.mark.parametrize(
    ("text", "deg"),
    [
        ("123.5", 123.5),
        ("123°30'00.0\"", 123.5),
        ("123 30 0", 123.5),
        ("123d30m36s", 123.51),
        ("-0°30'", -0.5),
        ("359°59'59.9\"", 359 + 59 / 60 + 59.9 / 3600),
    ],
)
def test_parse_azimuth(text: str, deg: float) -> None:
    assert parse_azimuth(text) == pytest.approx(deg, abs=1e-12)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("north", "neither decimal degrees"),
        ("12°75'00\"", "below 60"),
        ("nan", "not a finite number"),
    ],
)
def test_parse_azimuth_errors(text: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_azimuth(text)


@given(st.floats(0, 360, allow_nan=False, exclude_max=True))
def test_dms_round_trip(deg: float) -> None:
    back = parse_azimuth(format_dms(deg, decimals=3))
    assert math.isclose(math.remainder(back - deg, 360.0), 0.0, abs_tol=0.0005 / 3600 + 1e-12)
