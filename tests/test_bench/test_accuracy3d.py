"""The accuracy benchmark's 3D configurations (bench.accuracy3d): the wrong-fix rule
catches a pose off by more than it allows and lets one within it pass, the benchmark
counts by it, its tables and rows hold every figure, and a short run of the real locator
goes through, from the library and from `mast bench accuracy3d`."""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from mast.bench.accuracy3d import (
    ACCURACY3D_CONFIGS,
    SHORT,
    Accuracy3DConfig,
    is_far_3d,
    is_wrong_3d,
    run_accuracy3d,
    summarise_3d,
    table_3d,
)
from mast.core.beacon import Survey
from mast.core.pose3d import Frame3D, Pose3D
from mast.pipeline.adjust3d import UNBRACKETED, Adjustment3D, PanelPlanes
from mast.pipeline.locator3d import Fix3D, Locator3DConfig
from mast.program import app
from mast.sim.lidar3d import simulate_frames
from tests._cli import run_mast_text

CONFIG = Accuracy3DConfig("vlp16", 0.02, False)
TRUTH = Pose3D.from_degrees(1000.0, 2000.0, -300.0, 40.0, 3.0, -2.0)
SIGMAS = np.array([0.002, 0.002, 0.01, 0.001, 0.001, 0.0005])


def _fix(pose: Pose3D, sigmas: np.ndarray = SIGMAS) -> Fix3D:
    """A fix at ``pose`` with a diagonal covariance of ``sigmas``."""
    adj = Adjustment3D(pose, np.diag(sigmas**2), 1.0, 500, 0.5, 505, 3, 2)
    return Fix3D("fix", pose, adj, None, "", None, np.array([0.0, 0.0, 1.0]))  # type: ignore[arg-type]


def _moved(pose: Pose3D, **by: float) -> Pose3D:
    fields = {"easting", "northing", "elevation", "azimuth", "pitch", "roll"}
    assert set(by) <= fields
    return replace(pose, **{k: getattr(pose, k) + v for k, v in by.items()})


@pytest.mark.parametrize(
    ("by", "wrong"),
    [
        ({}, False),
        ({"easting": 0.04}, False),
        ({"easting": 0.06}, True),
        ({"northing": -0.04, "easting": 0.04}, True),  # 0.057 m in plan
        ({"elevation": 0.06}, True),
        ({"azimuth": math.radians(0.2)}, False),
        ({"azimuth": math.radians(-0.3)}, True),
        ({"azimuth": math.radians(359.8)}, False),  # the same heading, wrapped
        ({"roll": math.radians(0.3)}, True),
        ({"pitch": math.radians(-0.3)}, True),
    ],
)
def test_the_wrong_fix_rule(by: dict[str, float], wrong: bool) -> None:
    # SIGMAS are 2 mm, 1 cm, 0.06 deg and 0.03 deg: each pose off is outside five
    assert is_wrong_3d(_fix(_moved(TRUTH, **by)), TRUTH) is wrong


def test_a_fix_off_within_five_of_its_sigmas_is_far_but_not_wrong() -> None:
    # a tilt the panels hold loosely (0.45 deg): 1.1 deg off in roll is 2.4 sigma
    loose = SIGMAS.copy()
    loose[3] = math.radians(0.45)
    off = _fix(_moved(TRUTH, roll=math.radians(1.1)), loose)
    assert not is_wrong_3d(off, TRUTH)
    assert is_far_3d(off, TRUTH)
    # past five sigmas, it is wrong; within the tolerances, sigmas do not matter
    assert is_wrong_3d(_fix(_moved(TRUTH, roll=math.radians(2.5)), loose), TRUTH)
    tight = _fix(_moved(TRUTH, azimuth=math.radians(0.2)), SIGMAS / 100)
    assert not is_wrong_3d(tight, TRUTH)
    assert not is_far_3d(tight, TRUTH)
    assert not is_far_3d(_fix(_moved(TRUTH, easting=0.09)), TRUTH)
    assert is_far_3d(_fix(_moved(TRUTH, easting=0.11)), TRUTH)


def test_an_elevation_the_fix_says_it_does_not_know_is_not_held_against_it() -> None:
    unknown = SIGMAS.copy()
    unknown[2] = math.sqrt(UNBRACKETED)
    assert not is_wrong_3d(_fix(_moved(TRUTH, elevation=5.0), unknown), TRUTH)
    assert not is_far_3d(_fix(_moved(TRUTH, elevation=5.0), unknown), TRUTH)
    assert is_wrong_3d(_fix(_moved(TRUTH, elevation=5.0, easting=0.2), unknown), TRUTH)


def test_a_no_fix_is_never_wrong() -> None:
    refused = replace(_fix(_moved(TRUTH, easting=3.0)), status="no_fix", reason="one_beacon")
    assert not is_wrong_3d(refused, TRUTH)


#: The benchmark's frames' truths, by their points, simulated as the benchmark asks.
_TRUTHS: dict[bytes, Pose3D] = {}
_STREAM = simulate_frames(0, 40, lidar=CONFIG.lidar, range_sigma_m=CONFIG.range_sigma_m)


def _truth_of(frame: Frame3D) -> Pose3D:
    key = frame.points.tobytes()
    while key not in _TRUTHS:
        _, sim = next(_STREAM)
        _TRUTHS[sim.frame.points.tobytes()] = sim.pose
    return _TRUTHS[key]


def _truth_locator(offset: dict[str, float]):  # type: ignore[no-untyped-def]
    """A stand-in locator that fixes every frame at its true pose moved by ``offset`` (the
    benchmark's frames are the simulator's, deterministic per seed)."""

    def locate(
        frame: Frame3D, survey: Survey, config: Locator3DConfig, planes: PanelPlanes
    ) -> Fix3D:
        return _fix(_moved(_truth_of(frame), **offset))

    return locate


@pytest.mark.parametrize(
    ("offset", "all_wrong"),
    [({}, False), ({"northing": 0.2}, True), ({"azimuth": math.radians(2.0)}, True)],
)
def test_the_benchmark_counts_wrong_fixes_by_its_rule(
    offset: dict[str, float], all_wrong: bool
) -> None:
    lines: list[str] = []
    (s,) = run_accuracy3d(
        configs=[CONFIG], frames=2, locator=_truth_locator(offset), echo=lines.append
    )
    assert s.owed == 2
    assert s.owed_fixed == 2
    assert s.fix_rate == 1.0
    # every frame located is fixed, owed or not, and counts
    assert s.wrong == (s.frames if all_wrong else 0)
    assert s.far == s.wrong  # 0.2 m and 2 deg are far off too
    if not offset:
        assert all(r == 0.0 for r in s.ratio[:2])  # no error at all
        assert s.ratio_points[:2] == (0.0, 0.0)
        assert math.isnan(s.ratio_points[2])  # the points hold no elevation
        assert s.coverage == (1.0,) * 6
    else:
        assert min(s.coverage) == 0.0
    assert s.config in lines[0]


def test_the_tilt_held_fix_rate_counts_only_the_owed_frames_whose_bound_holds_the_tilt() -> None:
    def row(owed: int, fixed: int, held: int | None) -> dict[str, object]:
        r: dict[str, object] = {"owed": owed, "fixed": fixed, "wrong": 0, "reason": "",
                                "elapsed_ms": 1.0, "points": 1000}  # fmt: skip
        if held is not None:
            r["tilt_held"] = held
        return r

    rows = [row(1, 1, 1), row(1, 0, 1), row(1, 0, 0), row(1, 1, 0), row(0, 1, None)]
    s = summarise_3d("x", rows, 1.0)
    assert (s.owed, s.owed_fixed, s.owed_tilt_held) == (4, 2, 2)
    assert s.tilt_held_fix_rate == 0.5
    assert "2, 50.0" in table_3d([s])
    none = summarise_3d("x", [row(1, 0, 0)], 1.0)
    assert none.owed_tilt_held == 0
    assert math.isnan(none.tilt_held_fix_rate)


def test_a_short_run_of_the_locator_fills_its_tables_and_rows(tmp_path: Path) -> None:
    lines: list[str] = []
    (s,) = run_accuracy3d(configs=[CONFIG], frames=2, out_dir=tmp_path, echo=lines.append)
    assert s.config == "vlp16-2cm"
    assert s.owed == 2
    assert s.frames >= 2
    assert 0 <= s.owed_fixed <= s.owed
    assert s.wrong >= 0
    assert len(s.ratio) == len(s.coverage) == len(s.sigma_over_crb) == 6
    assert s.time_median_ms > 0
    assert s.ms_per_kpoint_median > 0
    assert 25_000 < s.points_median < 32_000  # a VLP-16's frame
    table = lines[0]
    for heading in (
        "owed",
        "fix %",
        "WRONG",
        "> 0.1 m, 1°",
        "ms / 1000 pts",
        "points' own",
        *SHORT,
    ):
        assert heading in table
    assert "vlp16-2cm" in table
    rows = (tmp_path / "accuracy3d_vlp16-2cm.csv").read_text().splitlines()
    assert len(rows) == s.frames + 1
    assert {"owed", "fixed", "wrong", "far", "reason", "elapsed_ms", "points"} <= set(
        rows[0].split(",")
    )
    summary = (tmp_path / "accuracy3d_summary.csv").read_text().splitlines()
    assert {"ratio_E", "coverage_A", "sigma_over_crb_Z", "wrong", "far"} <= set(
        summary[0].split(",")
    )


def test_a_run_is_the_same_for_the_same_seed() -> None:
    def run() -> dict[str, object]:
        (summary,) = run_accuracy3d(configs=[CONFIG], frames=1, echo=lambda _: None)
        times = ("time_median_ms", "time_p95_ms", "ms_per_kpoint_median", "seconds")
        return {k: v for k, v in asdict(summary).items() if k not in times}

    first, second = run(), run()
    assert repr(first) == repr(second)  # (NaN where nothing was fixed: not equal to itself)
    assert first["owed"] == 1


def test_the_configurations_are_the_issues() -> None:
    names = {c.name for c in ACCURACY3D_CONFIGS}
    assert len(names) == 12
    assert {"vlp16-1cm", "os1-64-3cm-lookalikes"} <= names


def test_the_command_chooses_its_configurations() -> None:
    none = run_mast_text("bench", "accuracy3d", "--lidar", "hdl32")
    assert none.returncode == 2
    assert none.stderr.strip().splitlines() == [
        "mast: error: no 3D configuration matches --lidar and --range-sigma; known: lidars "
        "vlp16 and os1-64, range sigmas 0.01, 0.02 and 0.03"
    ]
    assert (
        "Example: mast bench accuracy3d"
        in CliRunner().invoke(app, ["bench", "accuracy3d", "--help"]).output
    )
