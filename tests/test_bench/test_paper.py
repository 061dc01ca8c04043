import math

import pytest

from mast.bench.paper import load_paper_table2


def test_table2_transcription_is_consistent() -> None:
    rows = load_paper_table2()
    assert len(rows) == 16
    assert {r.resolution_deg for r in rows} == {0.25, 0.5}
    for r in rows:
        # the true positions are those of the reconstructed layout
        assert r.true_e in (7.0, 10.932, 11.0, 14.863, 15.0)
        if r.az_err_arcsec is not None:
            assert abs(r.az_err_arcsec) < 20 * 60  # all under 20 arc-minutes
    p1 = next(r for r in rows if r.position == "P1" and r.resolution_deg == 0.5)
    assert p1.az_err_arcsec == pytest.approx(21.5)  # 0 0 21.5
    assert p1.err_n_m == pytest.approx(0.003)
    assert math.isclose(
        next(r for r in rows if r.position == "P5").ci95_az_arcsec or 0, 13 * 60 + 19.9
    )
