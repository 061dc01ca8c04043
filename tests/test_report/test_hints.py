"""The hints a run earns: each one a measured fact about the scans it names.

The paper's layout with 12 mm range noise (`mast simulate --scenario paper --noise`)
located with the default 10 mm: some scans are refused by the global test, and the
hint names the sigma that fixes them. The same scans against the survey with easting
and northing exchanged: nothing fixes, and the hint says so.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from mast.core.beacon import Survey
from mast.pipeline.locator import LocatorConfig, locate
from mast.report.hints import Hints, swapped_survey
from mast.sim.scenarios import Scene, paper_scenario


@pytest.fixture(scope="module")
def noisy() -> Scene:
    return paper_scenario(0, noise=True)[0]  # converging walls, 12 mm


def _run(scene: Scene, survey: Survey, config: LocatorConfig) -> Hints:
    hints = Hints(survey, config)
    for sim in scene.iter_simulated():
        hints.add(sim.scan, locate(sim.scan, survey, config=config))
    return hints


def test_a_range_sigma_below_the_scatter_earns_the_sigma_that_fixes(noisy: Scene) -> None:
    hints = _run(noisy, noisy.survey, LocatorConfig(range_sigma_m=0.010))
    assert hints.rejected >= 1
    (line,) = hints.lines()
    m = re.search(r"with --range-sigma (\S+) (all (\d+)|(\d+) of the (\d+)) fix:", line)
    assert m is not None, line
    sigma = float(m[1])
    fixed, tried = (int(m[3]), int(m[3])) if m[3] else (int(m[4]), int(m[5]))
    assert sigma == pytest.approx(0.012, abs=0.0011)
    assert 2 * fixed >= tried == hints.rejected
    assert f"{hints.rejected} of {hints.scans} scans were refused" in line
    assert "--scanner" in line
    # and it is true: with that sigma, the run has no scan refused
    again = _run(noisy, noisy.survey, LocatorConfig(range_sigma_m=sigma))
    assert again.rejected < hints.rejected
    assert again.lines() == []


def test_a_run_that_fits_its_sigma_earns_no_hint(noisy: Scene) -> None:
    assert _run(noisy, noisy.survey, LocatorConfig(range_sigma_m=0.012)).lines() == []


def test_a_survey_with_easting_and_northing_exchanged_is_named(noisy: Scene) -> None:
    mirror = swapped_survey(noisy.survey)
    for a, b in zip(mirror, noisy.survey, strict=True):
        assert np.array_equal(a.edges, b.edges[:, ::-1])
    hints = _run(noisy, mirror, LocatorConfig(range_sigma_m=0.012))
    assert hints.fixed == 0
    (line,) = hints.lines()
    assert line.startswith("hint: no scan fixed, but with easting and northing exchanged")
    assert "are its columns beacon,edge,easting,northing" in line


def test_a_layout_that_is_its_own_mirror_image_cannot_tell_a_swapped_survey() -> None:
    """The stated limit: the paper's parallel walls hold two beacons that are mirror
    images of each other about the drift's axis, so the exchanged survey is the same
    layout turned, and the scans fix in it. No scan can tell; the docs say so."""
    scene = paper_scenario(0, noise=True)[1]
    hints = _run(scene, swapped_survey(scene.survey), LocatorConfig(range_sigma_m=0.012))
    assert hints.fixed == hints.scans
    assert hints.lines() == []
