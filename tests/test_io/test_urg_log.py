from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from mast import InputError
from mast.io.urg_log import URG04LX_BEAMS, read_urg_log
from tests._paths import SHARED_DATA

LOGS = SHARED_DATA / "breezyslam_urg04lx"


@pytest.mark.skipif(not LOGS.is_dir(), reason="shared data not present")
def test_reads_the_real_logs() -> None:
    scans = list(read_urg_log(LOGS / "exp1.dat"))
    assert len(scans) == 756
    assert all(len(s) == URG04LX_BEAMS for s in scans)
    s = scans[0]
    assert s.angles_rad[0] == pytest.approx(-s.angles_rad[-1])
    assert np.degrees(s.angles_rad[-1] - s.angles_rad[0]) == pytest.approx(681 * 360 / 1024)
    # zeros are no-returns: about half the beams
    assert 0.3 < 1 - np.mean([x.valid.mean() for x in scans]) < 0.7
    assert len(list(read_urg_log(LOGS / "exp2.dat"))) == 641


def test_malformed_lines_are_named(write_text: Callable[..., Path]) -> None:
    good = " ".join(["1000"] + ["0"] * 23 + ["1500"] * URG04LX_BEAMS + ["0"])
    p = write_text("log.dat", good + "\n" + "1 2 3\n")
    it = read_urg_log(p)
    assert len(next(it)) == URG04LX_BEAMS
    with pytest.raises(InputError, match=r"log\.dat, line 2: 3 fields; a URG-04LX log line needs"):
        next(it)
    p = write_text("bad.dat", good.replace("1500", "x", 1) + "\n")
    with pytest.raises(InputError, match=r"bad\.dat, line 1: a field is not a number"):
        list(read_urg_log(p))
