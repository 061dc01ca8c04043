"""The outputs of a run, each reopened with its own library (laspy, ezdxf, a browser).

The inputs are synthetic: a three-beacon survey at UTM-sized coordinates
(E 512 300, N 7 012 300), a few dozen placed scans along a straight drift
with a fix every fifth scan and a gap where scans were not placed, and fix
records with the keys of docs/fix.schema.json.
"""

from __future__ import annotations

import csv
import html
import json
import math
import re
import shutil
import subprocess
import warnings
from pathlib import Path
from typing import Any

import ezdxf
import laspy
import numpy as np
import pytest

from mast.core.beacon import Beacon, Survey
from mast.core.pose import Pose2D, format_dms
from mast.core.trajectory import PlacedScan, Trajectory
from mast.errors import InputError, OutputError
from mast.io.las import gps_adjusted_time
from mast.io.trajectory import TRAJECTORY_HEADER, write_trajectory_csv, write_trajectory_tum
from mast.runs.model import RunSummary
from mast.runs.outputs import (
    DXF_LAYERS,
    LasMapWriter,
    write_map_dxf,
    write_report_html,
)

E0, N0 = 512_300.0, 7_012_300.0
#: 2023-11-14 22:13:20 UTC, in nanoseconds: a ROS stamp of today's size.
T0_NS = 1_700_000_000_123_456_789
STEP_NS = 40_000_000  # 25 Hz
AZIMUTH_DEG = 63.25
N_SCANS = 40
GAP = range(22, 26)  # scans not placed (no fix and no chain to one)


def _survey() -> Survey:
    # A 2:3:1 beacon (0.4, 0.6, 0.2 m) with 30 degree deflections, three times along
    # the drift's left wall, each with 0.1 mm decimals.
    shape = np.array([[0.0, 0.0], [0.4, 0.0], [0.9196, 0.3], [1.0928, 0.2]])
    return Survey(
        Beacon(f"B{k + 1}", shape + [E0 + 3.1234 + 8.0 * k, N0 + 6.5678 + 4.0 * k])
        for k in range(3)
    )


def _placed() -> list[PlacedScan]:
    az = math.radians(AZIMUTH_DEG)
    out = []
    for i in range(N_SCANS):
        if i in GAP:
            continue
        fix = i % 5 == 0
        s = 0.002 if fix else 0.002 + 0.001 * (i % 5)
        cov = np.diag([s**2, (1.5 * s) ** 2, math.radians(0.01 + 0.005 * (i % 5)) ** 2])
        d = 0.35 * i
        pose = Pose2D(E0 + 5.1234 + d * math.sin(az), N0 + 2.5678 + d * math.cos(az), az)
        out.append(PlacedScan(i, T0_NS + i * STEP_NS, pose, cov, "fix" if fix else "odometry"))
    return out


def _record(p: PlacedScan, dof: int, rv: float) -> dict[str, Any]:
    s = p.sigma
    return {
        "source": "run.bag",
        "scan": p.scan,
        "stamp_ns": p.stamp_ns,
        "topic": "/scan",
        "status": "fix",
        "easting": p.pose.easting,
        "northing": p.pose.northing,
        "azimuth_deg": p.pose.azimuth_deg,
        "azimuth_dms": format_dms(p.pose.azimuth_deg),
        "sigma_easting_m": float(s[0]),
        "sigma_northing_m": float(s[1]),
        "sigma_azimuth_deg": math.degrees(s[2]),
        "reference_variance": rv,
        "degrees_of_freedom": dof,
        "chi2_test": "pass" if 0.8 < rv < 1.2 else "too_large",
        "beacons": ["B1", "B2"],
    }


def _records(placed: list[PlacedScan]) -> list[dict[str, Any]]:
    rng = np.random.default_rng(3)
    recs = []
    for k, p in enumerate(x for x in placed if x.source == "fix"):
        dof = 200 + 40 * k
        recs.append(_record(p, dof, float(rng.chisquare(dof) / dof)))
    recs.append(
        {
            "scan": 23,
            "stamp_ns": T0_NS + 23 * STEP_NS,
            "status": "no_fix",
            "easting": None,
            "northing": None,
            "azimuth_deg": None,
            "reason": "one_beacon",
            "beacons": [],
        }
    )
    return recs


def _summary(records: list[dict[str, Any]], run: str = "drift 7 <north>.bag") -> RunSummary:
    fixes = [r for r in records if r["status"] == "fix"]
    return RunSummary(
        run=run,
        topic="/scan",
        scans=N_SCANS,
        fixes=len(fixes),
        placed=N_SCANS - len(GAP),
        skipped=1,
        reasons={"one_beacon": 3, "no_beacon": 1},
        reference_variances=[(r["reference_variance"], r["degrees_of_freedom"]) for r in fixes],
        elapsed_s=2.5,
    )


def _scan_points(p: PlacedScan, n: int = 181) -> np.ndarray:
    """Returns of a scan in a 4 m wide drift, in the mine frame (some beams without one)."""
    phi = np.linspace(-math.pi / 2, math.pi / 2, n)
    # Scanner frame: walls at y = +2 and y = -2 (ranges 2/|sin phi|, capped at 30 m).
    r = np.minimum(2.0 / np.maximum(np.abs(np.sin(phi)), 1e-9), 30.0)
    pts = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    pts[::17] = np.nan  # no return
    return p.pose.scanner_to_mine(pts)


def _wall_pieces(placed: list[PlacedScan]) -> list[np.ndarray]:
    """Two straight wall pieces per fixed scan, mapped to the mine frame."""
    pieces = []
    for p in placed:
        if p.source == "fix":
            for y in (2.0, -2.0):
                pieces.append(p.pose.scanner_to_mine(np.array([[-1.0, y], [0.0, y], [1.0, y]])))
    return pieces


# --------------------------------------------------------------------------- trajectory


def test_csv_has_the_contract_header_and_reads_back_exactly(tmp_path: Path) -> None:
    placed = _placed()
    path = tmp_path / "trajectory.csv"
    assert write_trajectory_csv(path, placed) == len(placed)
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0] == TRAJECTORY_HEADER
    assert lines[0] == (
        "stamp_ns,easting,northing,azimuth_deg,sigma_easting_m,sigma_northing_m,"
        "sigma_azimuth_deg,source"
    )
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(placed)
    for row, p in zip(rows, placed, strict=True):
        assert int(row["stamp_ns"]) == p.stamp_ns
        # Full precision: the same doubles back, hence 0.1 mm at UTM size and better.
        assert float(row["easting"]) == p.pose.easting
        assert float(row["northing"]) == p.pose.northing
        assert float(row["azimuth_deg"]) == p.pose.azimuth_deg
        assert float(row["sigma_easting_m"]) == p.sigma[0]
        assert float(row["sigma_northing_m"]) == p.sigma[1]
        assert float(row["sigma_azimuth_deg"]) == pytest.approx(math.degrees(p.sigma[2]))
        assert row["source"] == p.source
    assert rows[0]["easting"] == repr(E0 + 5.1234)


def _tum_rows(path: Path) -> list[list[str]]:
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("#")
    return [line.split(" ") for line in lines if not line.startswith("#")]


def test_tum_is_eight_floats_per_line_with_nanosecond_stamps(tmp_path: Path) -> None:
    placed = _placed()
    path = tmp_path / "trajectory.tum"
    assert write_trajectory_tum(path, placed) == len(placed)
    text = path.read_text(encoding="utf-8")
    assert "\n\n" not in text
    assert not any(line.endswith(" ") for line in text.splitlines())  # evo refuses them
    rows = _tum_rows(path)
    assert len(rows) == len(placed)
    for row, p in zip(rows, placed, strict=True):
        assert len(row) == 8
        values = [float(v) for v in row]
        # Stamp: the integer nanoseconds, digit for digit.
        whole, frac = row[0].split(".")
        assert int(whole) * 1_000_000_000 + int(frac) == p.stamp_ns
        assert len(frac) == 9
        assert values[1] == p.pose.easting
        assert values[2] == p.pose.northing
        assert values[3] == 0.0
        assert values[4] == values[5] == 0.0
        assert math.hypot(values[6], values[7]) == pytest.approx(1.0)


@pytest.mark.parametrize("azimuth_deg", [0.0, 90.0, 180.0, 270.0, 359.0])
def test_tum_yaw_is_ninety_degrees_minus_azimuth(tmp_path: Path, azimuth_deg: float) -> None:
    p = PlacedScan(0, T0_NS, Pose2D.from_degrees(E0, N0, azimuth_deg), np.eye(3) * 1e-6, "fix")
    path = tmp_path / "t.tum"
    write_trajectory_tum(path, [p])
    (row,) = _tum_rows(path)
    qz, qw = float(row[6]), float(row[7])
    assert qw >= 0.0
    yaw = math.degrees(2.0 * math.atan2(qz, qw))
    expected = 90.0 - azimuth_deg
    assert (yaw - expected + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
    # And back: the azimuth from the quaternion is the pose's.
    assert (90.0 - yaw) % 360.0 == pytest.approx(azimuth_deg % 360.0, abs=1e-9)


def test_trajectory_to_a_missing_folder_is_an_output_error(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=r"nowhere.*trajectory\.csv: cannot write"):
        write_trajectory_csv(tmp_path / "nowhere" / "trajectory.csv", _placed())
    with pytest.raises(OutputError, match=r"trajectory\.tum: cannot write"):
        write_trajectory_tum(tmp_path / "nowhere" / "trajectory.tum", _placed())


# --------------------------------------------------------------------------- LAS


def test_las_gives_the_points_back_to_a_tenth_of_a_millimetre(tmp_path: Path) -> None:
    placed = _placed()
    path = tmp_path / "map.las"
    expected = []
    with LasMapWriter(path, origin_e=E0 + 0.4, origin_n=N0 - 0.3) as las:
        for k, p in enumerate(placed):
            pts = _scan_points(p)
            inten = np.linspace(0.0, 300.0, len(pts)) if k % 2 else None
            n = las.add(p.scan, p.stamp_ns, pts, inten)
            keep = np.all(np.isfinite(pts), axis=1)
            assert n == int(keep.sum())
            for q in pts[keep]:
                expected.append((q[0], q[1], p.scan, p.stamp_ns))
    assert las.count == len(expected)
    assert las.close() == len(expected)  # closing twice is harmless

    cloud = laspy.read(path)
    assert cloud.header.point_count == len(expected)
    assert cloud.header.version.major == 1
    assert cloud.header.version.minor == 4
    assert list(cloud.header.offsets[:2]) == [E0, N0]  # rounded to whole metres
    assert list(cloud.header.scales) == [1e-4] * 3
    assert cloud.header.global_encoding.gps_time_type == laspy.header.GpsTimeType.STANDARD
    e = np.array([x[0] for x in expected])
    n = np.array([x[1] for x in expected])
    # 0.1 mm quantum: every coordinate within half of it, at UTM size.
    assert np.max(np.abs(np.asarray(cloud.x) - e)) <= 0.5e-4 + 1e-9
    assert np.max(np.abs(np.asarray(cloud.y) - n)) <= 0.5e-4 + 1e-9
    assert np.all(np.asarray(cloud.z) == 0.0)
    assert np.array_equal(np.asarray(cloud.scan_index), [x[2] for x in expected])
    assert cloud.scan_index.dtype == np.uint32
    # gps_time: Adjusted Standard GPS Time = Unix + 18 leap seconds - 315964800 - 1e9.
    stamps = np.array([x[3] for x in expected], dtype=np.int64)
    want = (stamps - (315_964_800 - 18 + 1_000_000_000) * 1_000_000_000) / 1e9
    assert np.max(np.abs(np.asarray(cloud.gps_time) - want)) < 1e-6
    assert np.all(np.asarray(cloud.return_number) == 1)


def test_las_quantum_at_utm_size_is_exact(tmp_path: Path) -> None:
    path = tmp_path / "map.las"
    pts = np.array([[512334.1234, 7012345.6789], [512300.0001, 7012299.9999]])
    with LasMapWriter(path, origin_e=E0, origin_n=N0) as las:
        las.add(7, T0_NS, pts, np.array([12.4, 70000.0]))
    cloud = laspy.read(path)
    assert [round(float(v), 4) for v in cloud.x] == [512334.1234, 512300.0001]
    assert [round(float(v), 4) for v in cloud.y] == [7012345.6789, 7012299.9999]
    assert list(cloud.intensity) == [12, 65535]  # rounded, clipped to uint16


def test_las_streams_instead_of_accumulating(tmp_path: Path) -> None:
    """Each add() reaches the file: its size grows before close(), scan by scan; the map
    is written under a temporary name and appears under its own once complete."""
    path = tmp_path / "map.las"
    p = _placed()[0]
    pts = np.repeat(p.pose.position[None, :], 2000, axis=0) + np.arange(2000)[:, None] * 1e-3
    with LasMapWriter(path, origin_e=E0, origin_n=N0) as las:
        las.add(0, p.stamp_ns, pts)
        first = las.writing.stat().st_size
        las.add(1, p.stamp_ns, pts)
        second = las.writing.stat().st_size
        assert not path.exists()
    assert path.is_file()
    assert not las.writing.exists()
    # A point of format 6 with a uint32 extra dimension is 34 bytes.
    assert first > 2000 * 34 * 0.8
    assert second >= first + 2000 * 34 * 0.8


def test_las_gps_time_follows_the_leap_seconds() -> None:
    # 2016-12-31 (17 leap seconds) and 2017-01-02 (18): Unix seconds 1483142400, 1483315200.
    t = gps_adjusted_time(np.array([1_483_142_400, 1_483_315_200]) * 1_000_000_000)
    assert t.tolist() == [
        1_483_142_400 + 17 - 315_964_800 - 1e9,
        1_483_315_200 + 18 - 1_315_964_800,
    ]


def test_las_errors_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=r"map\.las: cannot write"):
        LasMapWriter(tmp_path / "nowhere" / "map.las", origin_e=E0, origin_n=N0)
    las = LasMapWriter(tmp_path / "map.las", origin_e=E0, origin_n=N0)
    with pytest.raises(InputError, match=r"points_mine must have shape \(n, 2\) or \(n, 3\)"):
        las.add(0, T0_NS, np.zeros((3, 4)))
    with pytest.raises(InputError, match=r"intensity must have shape \(2,\)"):
        las.add(0, T0_NS, np.zeros((2, 2)) + [E0, N0], np.zeros(3))
    with pytest.raises(InputError, match=r"scan 4: .* more than 215 km from the map origin"):
        las.add(4, T0_NS, np.array([[E0 + 300_000.0, N0]]))
    las.close()
    with pytest.raises(OutputError, match=r"map\.las: already closed"):
        las.add(0, T0_NS, np.zeros((1, 2)) + [E0, N0])


# --------------------------------------------------------------------------- DXF


def test_dxf_audits_clean_with_the_four_layers(tmp_path: Path) -> None:
    placed = _placed()
    survey = _survey()
    fixes = [p for p in placed if p.source == "fix"]
    walls = _wall_pieces(placed)
    walls.append(np.array([[E0, N0]]))  # one point: not a polyline, skipped
    walls.append(np.array([[E0, N0], [np.nan, N0], [E0 + 1.0, N0 + 1.0]]))  # NaN row dropped
    path = tmp_path / "map.dxf"
    write_map_dxf(path, survey, placed, walls, fixes)

    doc = ezdxf.readfile(path)
    auditor = doc.audit()
    assert not auditor.has_errors, [str(e) for e in auditor.errors]
    assert doc.header["$INSUNITS"] == 6
    for name in DXF_LAYERS:
        assert name in doc.layers
    msp = doc.modelspace()

    def on(layer: str, kind: str) -> list[Any]:
        return list(msp.query(f'{kind}[layer=="{layer}"]'))

    assert len(on("MAST_WALLS", "LWPOLYLINE")) == 2 * len(fixes) + 1
    assert len(on("MAST_WALLS", "*")) == 2 * len(fixes) + 1
    beacons = on("MAST_BEACONS", "LWPOLYLINE")
    texts = on("MAST_BEACONS", "TEXT")
    assert len(beacons) == len(texts) == len(survey)
    assert sorted(t.dxf.text for t in texts) == ["B1", "B2", "B3"]
    # Surveyed edges back exactly (DXF holds doubles).
    for b, poly in zip(survey, beacons, strict=True):
        assert np.array_equal(np.array([v[:2] for v in poly.get_points("xy")]), b.edges)
    # The trajectory is broken at the unplaced scans: two stretches.
    traj = on("MAST_TRAJECTORY", "LWPOLYLINE")
    assert len(traj) == 2
    assert len(on("MAST_TRAJECTORY", "*")) == 2
    assert sum(len(t) for t in traj) == len(placed)
    first = np.array(traj[0].get_points("xy"))[0]
    assert first.tolist() == [placed[0].pose.easting, placed[0].pose.northing]
    circles = on("MAST_FIXES", "CIRCLE")
    ticks = on("MAST_FIXES", "LINE")
    assert len(circles) == len(ticks) == len(fixes)
    # The tick points along the azimuth (clockwise from north).
    t = ticks[0]
    d = np.array(t.dxf.end)[:2] - np.array(t.dxf.start)[:2]
    az = math.degrees(math.atan2(d[0], d[1])) % 360.0
    assert az == pytest.approx(AZIMUTH_DEG)


def test_dxf_to_a_missing_folder_is_an_output_error(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=r"map\.dxf: cannot write"):
        write_map_dxf(tmp_path / "nowhere" / "map.dxf", _survey(), [], [], [])


# --------------------------------------------------------------------------- HTML


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The report of the synthetic run, written with every warning an error."""
    placed = _placed()
    records = _records(placed)
    walls = np.vstack([_scan_points(p) for p in placed])
    path = tmp_path_factory.mktemp("report") / "report.html"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_report_html(path, _summary(records), placed, records, _survey(), walls)
    return path


def test_report_has_the_summary_figures_and_table(report: Path) -> None:
    text = report.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    # Escaped: the run's name is text, not markup.
    assert "drift 7 &lt;north&gt;.bag" in text
    assert "<north>" not in text
    for words in ("Scans read", "Fixed from beacons", "Placed in the mine grid", "scans/s"):
        assert words in text
    assert "16.0 scans/s" in text  # 40 scans in 2.5 s
    assert "one_beacon" in text
    assert "no_beacon" in text
    assert text.count("<svg") == 3
    assert "Axes in metres from E 512\u2009300, N 7\u2009012\u2009300" in text
    assert "mixture" in text
    # Self-contained: nothing to fetch, no script.
    assert not re.search(r"""(?:src|href)\s*=\s*["']?(?:https?:)?//""", text)
    assert "<script" not in text
    assert "<link" not in text
    # The table: one row per fix, azimuths in D°MM'SS.S", sigma in mm.
    fixes = [r for r in _records(_placed()) if r["status"] == "fix"]
    table = text[text.index("<table class='fixes'>") :]
    assert table.count("<tr>") == len(fixes) + 1
    assert html.escape(format_dms(AZIMUTH_DEG)) in table
    assert "<td class='n'>2.00</td>" in table  # sigma E of a fix, 2 mm


def test_report_table_is_capped_with_a_note(tmp_path: Path) -> None:
    placed = _placed()
    records = _records(placed)
    path = tmp_path / "report.html"
    write_report_html(
        path, _summary(records), placed, records, _survey(), np.zeros((0, 2)), max_table_rows=3
    )
    text = path.read_text(encoding="utf-8")
    table = text[text.index("<table class='fixes'>") :]
    assert table.count("<tr>") == 3 + 1
    n_fix = sum(r["status"] == "fix" for r in records)
    assert f"The first 3 of {n_fix} fixes are listed" in text


def test_report_of_a_run_without_fixes(tmp_path: Path) -> None:
    path = tmp_path / "report.html"
    summary = RunSummary(run="empty.bag", scans=5, reasons={"no_beacon": 5}, elapsed_s=0.0)
    write_report_html(path, summary, [], [], _survey(), np.zeros((0, 2)))
    text = path.read_text(encoding="utf-8")
    assert "No fix: no reference variance to show." in text
    assert text.count("<svg") == 1  # the survey alone


def test_report_to_a_missing_folder_is_an_output_error(tmp_path: Path) -> None:
    with pytest.raises(OutputError, match=r"report\.html: cannot write"):
        write_report_html(
            tmp_path / "nowhere" / "report.html",
            RunSummary(run="r"),
            [],
            [],
            _survey(),
            np.zeros((0, 2)),
        )


# --------------------------------------------------------------------------- browser

#: Put first in <head> of a copy of the page: records every uncaught error, failed
#: resource load, unhandled rejection and console.error, then, once the page has
#: loaded, writes them with the number and size of the rendered <svg> into the DOM.
_RECORDER = """<script>
window.__mastErrors = [];
window.addEventListener('error', function (e) {
  var t = e.target;
  window.__mastErrors.push(t && t !== window && (t.src || t.href)
    ? 'resource failed: ' + (t.src || t.href) : 'uncaught: ' + e.message);
}, true);
window.addEventListener('unhandledrejection', function (e) {
  window.__mastErrors.push('unhandled rejection: ' + e.reason);
});
var __mastConsoleError = console.error;
console.error = function () {
  window.__mastErrors.push('console.error: ' + Array.prototype.join.call(arguments, ' '));
  __mastConsoleError.apply(console, arguments);
};
window.addEventListener('load', function () {
  var svgs = Array.prototype.slice.call(document.querySelectorAll('figure svg'));
  var out = document.createElement('pre');
  out.id = 'mast-check';
  out.textContent = JSON.stringify({
    errors: window.__mastErrors,
    svgs: svgs.map(function (s) {
      var r = s.getBoundingClientRect();
      return [r.width, r.height, s.querySelectorAll('path, use, image').length];
    })
  });
  document.body.appendChild(out);
});
</script>"""


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    pytest.skip(
        "no chromium on PATH and it could not be installed (make test installs Debian's "
        "chromium with apt-get when run as root): the report's render check needs a browser"
    )


def _render(page: Path, tmp_path: Path) -> dict[str, Any]:
    """Open ``page`` with the recorder in headless Chromium; what the recorder wrote."""
    text = page.read_text(encoding="utf-8")
    probe = tmp_path / f"probe-{page.name}"
    probe.write_text(text.replace("<head>", "<head>" + _RECORDER, 1), encoding="utf-8")
    done = subprocess.run(
        [
            _chromium(),
            "--headless=new",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'chromium-profile'}",
            # No network: anything the page tried to fetch would fail and be recorded.
            "--host-resolver-rules=MAP * ~NOTFOUND",
            "--virtual-time-budget=5000",
            "--dump-dom",
            probe.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=90,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    found = re.search(r'<pre id="mast-check">(.*?)</pre>', done.stdout, re.DOTALL)
    assert found, f"the recorder did not run; DOM: {done.stdout[:500]!r}"
    result: dict[str, Any] = json.loads(html.unescape(found.group(1)))
    return result


def test_report_renders_in_chromium_without_errors(report: Path, tmp_path: Path) -> None:
    """The report renders in headless Chromium with no error and its three figures drawn.

    How: a copy of the page gets, first in its ``<head>``, a small script that
    records uncaught errors and failed resource loads (a capturing ``error``
    listener on window), unhandled promise rejections and ``console.error``
    calls, and on ``load`` writes them, with the size and mark count of every
    ``<svg>`` in a ``<figure>``, as JSON into a ``<pre>`` appended to the body.
    Chromium's ``--dump-dom`` prints the DOM after the page settled
    (``--virtual-time-budget``), and the test reads the JSON back. Reading the
    DOM is exact where scraping Chromium's stderr log is not (its format
    changes between versions and it is full of sandbox and D-Bus noise); the
    recorder's own output proves it ran, and the control test below proves it
    catches errors. Host resolution is disabled, so a page that fetched
    anything would fail to load it and show it as an error.
    """
    result = _render(report, tmp_path)
    assert result["errors"] == []
    assert len(result["svgs"]) == 3
    for width, height, marks in result["svgs"]:
        assert width > 100
        assert height > 100
        assert marks > 10


def test_the_render_check_catches_errors(tmp_path: Path) -> None:
    """Control: a page with a script error and a missing image fails the check."""
    page = tmp_path / "broken.html"
    page.write_text(
        "<!DOCTYPE html><html><head><meta charset='utf-8'></head><body>"
        "<img src='missing.png'><script>notDefined();</script></body></html>",
        encoding="utf-8",
    )
    errors = _render(page, tmp_path)["errors"]
    assert any(e.startswith("uncaught:") and "notDefined" in e for e in errors), errors
    assert any(e.startswith("resource failed:") and "missing.png" in e for e in errors), errors


def test_a_dense_run_draws_by_distance_in_the_dxf(tmp_path: Path) -> None:
    # 2 000 scans 1 cm apart, every one fixed: 20 m of drift.
    az = math.radians(AZIMUTH_DEG)
    cov = np.diag([1e-6, 1e-6, 1e-8])
    placed = Trajectory(
        [
            PlacedScan(
                i,
                T0_NS + i * STEP_NS,
                Pose2D(E0 + 0.01 * i * math.sin(az), N0 + 0.01 * i * math.cos(az), az),
                cov,
                "fix",
            )
            for i in range(2000)
        ]
    )
    assert len(placed) == 2000
    assert placed[-1].pose.easting == pytest.approx(E0 + 19.99 * math.sin(az))
    assert placed[5].covariance.tolist() == cov.tolist()
    path = tmp_path / "map.dxf"
    write_map_dxf(path, _survey(), placed, [], iter(placed))
    msp = ezdxf.readfile(path).modelspace()
    (traj,) = msp.query('LWPOLYLINE[layer=="MAST_TRAJECTORY"]')
    xy = np.array(traj.get_points("xy"))
    # A vertex every 10 cm (11 where rounding puts one a hair short) and the last
    # scan's: the path, not the scans.
    assert 180 <= len(xy) <= 201
    assert np.max(np.hypot(*np.diff(xy, axis=0).T)) < 0.111
    assert xy[-1].tolist() == [placed[-1].pose.easting, placed[-1].pose.northing]
    assert len(msp.query('CIRCLE[layer=="MAST_FIXES"]')) in (19, 20)
