import math

import numpy as np
import pytest

from mast import InputError, Pose2D
from mast.sim import SCANNERS, ScannerModel, Surface, WorldBuilder, scanner_model, simulate_scan


def test_beam_layout() -> None:
    m = ScannerModel("t", 270.0, 0.5)
    a = m.beam_angles()
    assert a.size == 541
    assert a[0] == pytest.approx(-math.radians(135))
    assert a[-1] == pytest.approx(math.radians(135))
    full = ScannerModel("f", 360.0, 0.2)
    assert full.beam_count == 1800
    assert full.beam_angles()[-1] < math.pi  # no beam twice


def test_named_models_and_errors() -> None:
    assert scanner_model("lms1xx-0.5").range_sigma_m == 0.012
    assert set(SCANNERS) >= {"lms1xx-0.5", "lms1xx-0.25", "lms2xx-0.1667", "spinning-360-0.2"}
    with pytest.raises(InputError, match="unknown scanner 'x'; known: "):
        scanner_model("x")
    with pytest.raises(InputError, match="field of view"):
        ScannerModel("bad", 400.0, 0.5)
    with pytest.raises(InputError, match="dropout_prob must be in"):
        ScannerModel("bad", 270.0, 0.5, dropout_prob=2.0)


def _wall_world() -> tuple[WorldBuilder, Pose2D]:
    wb = WorldBuilder()
    wb.polyline([[-50.0, 10.0], [50.0, 10.0]], Surface("wall"))
    return wb, Pose2D(0.0, 0.0, 0.0)


def test_noise_bias_and_dropout_statistics() -> None:
    wb, pose = _wall_world()
    m = ScannerModel("n", 120.0, 0.05, range_sigma_m=0.02, range_bias_m=0.01, dropout_prob=0.1)
    sim = simulate_scan(wb.build(), pose, m, rng=np.random.default_rng(1))
    ok = sim.scan.valid
    err = sim.scan.ranges_m[ok] - sim.true_ranges_m[ok]
    assert err.mean() == pytest.approx(0.01, abs=0.002)
    assert err.std() == pytest.approx(0.02, rel=0.08)
    assert 1 - ok.mean() == pytest.approx(0.1, abs=0.03)


def test_mixed_pixels_fall_between_the_surfaces() -> None:
    wb = WorldBuilder()
    wb.polyline([[-50.0, 10.0], [50.0, 10.0]], Surface("wall"))
    wb.polyline([[-0.5, 5.0], [0.5, 5.0]], Surface("clutter"))
    m = ScannerModel("m", 90.0, 0.25, mixed_pixel_prob=1.0, beam_divergence_rad=math.radians(0.5))
    sim = simulate_scan(wb.build(), Pose2D(0, 0, 0), m, rng=np.random.default_rng(2))
    r = sim.scan.ranges_m
    mixed = sim.scan.valid & (sim.surface_index == -1)
    assert mixed.sum() >= 2
    assert np.all((r[mixed] > 5.0) & (r[mixed] < 10.0 / math.cos(math.radians(10))))


def test_range_limits_give_no_return() -> None:
    wb, pose = _wall_world()
    sim = simulate_scan(wb.build(), pose, ScannerModel("r", 180.0, 1.0, range_max_m=12.0))
    r = sim.true_ranges_m
    assert not sim.scan.valid[r > 12.0].any()
    assert sim.scan.valid[r <= 12.0].all()
