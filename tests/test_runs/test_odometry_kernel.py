"""The compiled scan-to-keyframe ICP against its numpy reference.

The kernel searches the keyframe by bearing and sums in its own order, so the
motions agree to rounding, not to the bit; every refusal and every count of
matched returns must agree exactly.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.runs import odometry
from mast.sim import drive_scene


def test_scan_to_scan_kernel_matches_the_reference() -> None:
    sims = list(drive_scene(0, scans=60).iter_simulated())
    found = refused = 0
    for k in range(1, len(sims), 3):
        key = odometry.keyframe(sims[k - 1].scan)
        # from standing still, from a nudge, and from a start far outside ICP's basin
        for guess in ((0.0, 0.0, 0.0), (0.1, -0.05, 0.02), (2.5, 1.5, 0.6)):
            got = odometry.scan_to_scan(key, sims[k].scan, guess=guess, range_sigma_m=0.01)
            ref = odometry._scan_to_scan_reference(
                key, sims[k].scan, guess=guess, range_sigma_m=0.01
            )
            assert (got is None) == (ref is None)
            if ref is None or got is None:
                refused += 1
                continue
            found += 1
            assert got.matches == ref.matches
            assert got.dx == pytest.approx(ref.dx, abs=1e-12)
            assert got.dy == pytest.approx(ref.dy, abs=1e-12)
            assert abs(math.remainder(got.dtheta - ref.dtheta, 2 * math.pi)) < 1e-13
            assert got.rms_m == pytest.approx(ref.rms_m, rel=1e-10)
            scale = np.sqrt(np.outer(np.diag(ref.covariance), np.diag(ref.covariance)))
            np.testing.assert_allclose(
                got.covariance / scale, ref.covariance / scale, rtol=0, atol=1e-9
            )
    assert found > 20
    assert refused > 0  # the far starts were refused alike


def test_an_empty_keyframe_gives_no_motion() -> None:
    sims = list(drive_scene(0, scans=2).iter_simulated())
    empty = odometry.keyframe(sims[0].scan.__class__(sims[0].scan.angles_rad[:2], [1.0, 1.0]))
    assert len(empty) == 0
    assert odometry.scan_to_scan(empty, sims[1].scan, range_sigma_m=0.01) is None
