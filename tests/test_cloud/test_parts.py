"""The georeference's parts on their own: grids, the top edge, the adjustment, classes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mast.cloud.adjust import AdjustmentError, BeaconObs, adjust_transformation
from mast.cloud.detect import _top_edge
from mast.cloud.grid import PlanGrid, cell_keys, key_ij, pack_ij
from mast.cloud.outputs import accuracy_class


def test_cell_keys_round_trip_on_both_sides_of_the_origin() -> None:
    ij = np.array([[-5, 7], [0, 0], [123456, -98765], [-1, -1]], dtype=np.int64)
    keys = pack_ij(ij)
    assert np.all(keys > 0)
    assert np.array_equal(key_ij(keys), ij)
    # sorted keys sort by column then row
    assert np.array_equal(np.argsort(keys), np.lexsort((ij[:, 1], ij[:, 0])))
    xy = np.array([[-0.26, 0.35], [10.0, -3.0]])
    back = key_ij(cell_keys(xy, np.zeros(2), 0.05))
    assert np.array_equal(back, np.floor(xy / 0.05).astype(int))


def test_plan_grid_merges_chunks_into_min_max_count_and_bins() -> None:
    g = PlanGrid(np.zeros(2), 0.5)
    g.add(np.array([[0.1, 0.1, 1.0], [0.2, 0.2, 3.0]]), np.array([1, 2], dtype=np.uint64))
    g.add(np.array([[0.3, 0.1, -1.0], [2.0, 2.0, 5.0]]), np.array([4, 1], dtype=np.uint64))
    row, hit = g.at(np.array([[0.4, 0.4], [2.1, 2.1], [9.0, 9.0]]))
    assert hit.tolist() == [True, True, False]
    assert g.zmin[row[0]] == -1.0
    assert g.zmax[row[0]] == 3.0
    assert g.count[row[0]] == 3
    assert int(g.bins[row[0]]) == 7


@pytest.mark.parametrize("noise", [0.0, 0.005, 0.01])
def test_top_edge_is_unbiased_and_its_sigma_honest(noise: float) -> None:
    """Points spread evenly over a 0.6 m panel with Gaussian noise: the top comes back
    within its own sigma about as often as a normal distribution says."""
    rng = np.random.default_rng(1)
    errs, sigs = [], []
    for _ in range(300):
        z = rng.uniform(1.4, 2.0, 400) + rng.normal(0, noise, 400)
        top, sigma, bottom = _top_edge(z, max(noise, 0.002))
        errs.append(top - 2.0)
        sigs.append(sigma)
        assert abs(bottom - 1.4) < 0.05
    e, s = np.array(errs), np.array(sigs)
    assert abs(float(np.mean(e))) < 3 * float(np.std(e)) / math.sqrt(e.size) + 1e-4
    inside = float(np.mean(np.abs(e) <= 1.96 * s))
    assert 0.88 <= inside <= 0.995


def _beacons(
    rot: float, t: np.ndarray, dz: float, n: int, rng: np.random.Generator, sigma: float
) -> list[BeaconObs]:
    c, s = math.cos(rot), math.sin(rot)
    r = np.array([[c, -s], [s, c]])
    out = []
    for k in range(n):
        local = np.array([[10.0 * k, 3.0 + k % 2], [10.0 * k + 0.5, 3.3 + k % 2]])
        top = 1.0 + 0.1 * k
        grid = local @ r.T + t
        cov = np.array([np.eye(2) * sigma**2] * 2)
        out.append(
            BeaconObs(
                f"B{k}",
                (2, 3),
                local + rng.normal(0, sigma, local.shape),
                cov,
                top + rng.normal(0, sigma),
                sigma,
                grid,
                top + dz,
            )
        )
    return out


def test_adjustment_recovers_the_transformation_and_names_a_moved_beacon() -> None:
    rng = np.random.default_rng(3)
    t = np.array([452000.0, 7101000.0])
    obs = _beacons(0.7, t, -850.0, 6, rng, 0.002)
    sol = adjust_transformation(obs, survey_sigma_m=0.0, heights=True)
    assert sol.chi2_test == "pass"
    assert abs(math.radians(sol.transformation.rotation_deg) - 0.7) < 1e-3
    moved = list(obs)
    bad = moved[3]
    moved[3] = BeaconObs(
        bad.beacon,
        bad.edges,
        bad.cloud_xy,
        bad.cloud_cov,
        bad.top,
        bad.sigma_top,
        bad.grid_xy + 0.05,
        bad.grid_top,
    )
    sol = adjust_transformation(moved, survey_sigma_m=0.0, heights=True)
    assert sol.excluded == ["B3"]
    with pytest.raises(AdjustmentError, match="too_few"):
        adjust_transformation(obs[:1], survey_sigma_m=0.0, heights=True)
    with pytest.raises(AdjustmentError, match="helmert7 needs"):
        adjust_transformation(obs, model="helmert7", survey_sigma_m=0.0, heights=False)


def test_icsm_classes_follow_c_times_d_plus_0_2() -> None:
    # 20 m from control: allowance c * 0.22 mm
    assert accuracy_class(0.0002, 20.0) == "3A"
    assert accuracy_class(0.005, 20.0) == "C"
    assert accuracy_class(0.010, 20.0) == "D"
    assert accuracy_class(0.5, 20.0) is None
