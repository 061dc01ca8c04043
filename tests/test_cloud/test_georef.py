"""mast georef end to end: a simulated SLAM cloud into the grid, its outputs reopened by
their own libraries, refusals, other formats, drift and bad input."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from subprocess import CompletedProcess
from typing import Any

import numpy as np
import pytest

from mast.sim.cloud import CloudOptions, CloudScenario, simulate_cloud
from tests._cli import run_mast_text

DOCS = Path(__file__).resolve().parents[2] / "docs"
#: The grid the module's georef names (--crs, a WKT file): UTM 35S with EGM96 heights.
GRID_CRS = "EPSG:32735+5773"


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> CloudScenario:
    return simulate_cloud(
        tmp_path_factory.mktemp("cloud"),
        2,
        CloudOptions(length_m=100.0, beacons=5, density=1500.0),
    )


@pytest.fixture(scope="module")
def truth(scene: CloudScenario) -> dict[str, Any]:
    out: dict[str, Any] = json.loads(scene.truth.read_text())
    return out


@pytest.fixture(scope="module")
def georef(scene: CloudScenario, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("georef")
    from pyproj import CRS

    wkt = out.parent / "grid.wkt"
    wkt.write_text(CRS.from_user_input(GRID_CRS).to_wkt(pretty=True), encoding="utf-8")
    done = _georef(scene.cloud, scene.survey, out, "--check", "B03", "--crs", str(wkt))
    assert done.returncode == 0, done.stderr
    assert "check B03" in done.stdout
    return out


def _georef(cloud: Path, survey: Path, out: Path, *args: str) -> CompletedProcess[str]:
    """``mast georef CLOUD -b SURVEY --out OUT ARGS`` in its own process."""
    return run_mast_text("georef", str(cloud), "-b", str(survey), "--out", str(out), *args)


def _to_grid(truth: dict[str, Any], xyz: np.ndarray) -> np.ndarray:
    rot = math.radians(truth["rotation_deg"])
    c, s = math.cos(rot), math.sin(rot)
    return np.column_stack(
        [
            c * xyz[:, 0] - s * xyz[:, 1] + truth["easting_m"],
            s * xyz[:, 0] + c * xyz[:, 1] + truth["northing_m"],
            xyz[:, 2] + truth["elevation_m"],
        ]
    )


def test_every_output_is_written(georef: Path) -> None:
    for name in (
        "georeferenced.laz",
        "transform.json",
        "beacons_found.csv",
        "report.txt",
        "report.html",
        "plan.png",
    ):
        assert (georef / name).stat().st_size > 0, name


def test_the_laz_keeps_every_attribute_and_is_in_the_grid(
    scene: CloudScenario, georef: Path, truth: dict[str, Any]
) -> None:
    import laspy

    src = laspy.read(scene.cloud)
    out = laspy.read(georef / "georeferenced.laz")
    assert len(out.points) == len(src.points)
    assert set(src.point_format.dimension_names) <= set(out.point_format.dimension_names)
    for dim in ("intensity", "gps_time", "range", "classification", "point_source_id"):
        assert np.array_equal(np.asarray(out[dim]), np.asarray(src[dim])), dim
    # seven-digit grid coordinates at 0.1 mm
    assert np.allclose(out.header.scales, 1e-4)
    local = np.column_stack([src.x, src.y, src.z])
    grid = np.column_stack([out.x, out.y, out.z])
    assert float(np.min(grid[:, 1])) > 1e6
    err = grid - _to_grid(truth, local)
    # the transformation's own error at the far ends of a 100 m cloud: millimetres
    assert float(np.max(np.abs(err[:, :2]))) < 0.03
    assert float(np.max(np.abs(err[:, 2]))) < 0.03


def test_the_crs_given_is_in_the_cloud_transform_json_and_the_reports(georef: Path) -> None:
    import laspy
    from pyproj import CRS

    grid = CRS.from_user_input(GRID_CRS)
    header = laspy.read(georef / "georeferenced.laz").header
    assert header.global_encoding.wkt
    crs = header.parse_crs()
    assert crs is not None
    assert crs.equals(grid)
    record = json.loads((georef / "transform.json").read_text())
    assert record["crs"]["name"] == grid.name
    assert CRS.from_wkt(record["crs"]["wkt"]).equals(grid)
    assert "epsg" not in record["crs"]  # a compound CRS is no single EPSG entry
    for name in ("report.txt", "report.html"):
        assert f"grid CRS         {grid.name}" in (georef / name).read_text(encoding="utf-8")


def test_transform_json_validates_and_matches_the_truth(
    georef: Path, truth: dict[str, Any]
) -> None:
    import jsonschema

    record = json.loads((georef / "transform.json").read_text())
    schema = json.loads((DOCS / "transform.schema.json").read_text())
    jsonschema.validate(record, schema)
    assert record["model"] == "4-parameter"
    assert record["heights_controlled"] is True
    assert record["chi2_test"] == "pass"
    assert record["beacons"]["check"] == ["B03"]
    assert sorted(record["beacons"]["control"]) == ["B01", "B02", "B04", "B05"]
    m = np.array(record["matrix"])
    centre = np.array(record["centre_cloud"])
    expect = _to_grid(truth, centre[None, :])[0]
    got = m[:3, :3] @ centre + m[:3, 3]
    sig = record["sigmas"]
    assert abs(got[0] - expect[0]) < 4 * sig["easting_m"] + 0.002
    assert abs(got[1] - expect[1]) < 4 * sig["northing_m"] + 0.002
    assert abs(got[2] - expect[2]) < 4 * sig["elevation_m"] + 0.002
    rot = math.remainder(math.radians(record["rotation_deg"] - truth["rotation_deg"]), 2 * math.pi)
    assert abs(rot) < 4 * sig["rotation_rad"] + 1e-5


def test_beacons_found_names_every_beacon_with_its_role(georef: Path) -> None:
    with (georef / "beacons_found.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    roles = {r["beacon"]: r["role"] for r in rows}
    assert roles == {
        "B01": "control",
        "B02": "control",
        "B03": "check",
        "B04": "control",
        "B05": "control",
    }
    for r in rows:
        assert int(r["points"]) > 100
        assert abs(float(r["residual_e_m"])) < 0.03
        assert abs(float(r["residual_z_m"])) < 0.03


def test_the_report_states_tests_residuals_and_class(georef: Path) -> None:
    text = (georef / "report.txt").read_text()
    assert "global test" in text
    assert "PASS" in text
    assert "Check beacons" in text
    assert "B03" in text
    assert "ICSM SP1 class" in text


def test_the_report_renders_in_chromium(georef: Path, tmp_path: Path) -> None:
    from tests.test_runs.test_outputs import _render

    result = _render(georef / "report.html", tmp_path)
    assert result["errors"] == []
    assert len(result["svgs"]) == 1
    width, height, marks = result["svgs"][0]
    assert width > 100
    assert height > 100
    assert marks > 10


def test_too_few_beacons_is_refused_with_its_reason(scene: CloudScenario, tmp_path: Path) -> None:
    # an earlier run's result in the folder (written over: --force) must not outlive the
    # refusal
    for stale in ("georeferenced.laz", "transform.json", "plan.png"):
        (tmp_path / stale).write_bytes(b"old")
    done = _georef(scene.cloud, scene.survey, tmp_path, "--check", "B01,B02,B03,B04", "--force")
    assert done.returncode == 3, done.stderr
    assert "too_few" in done.stderr
    assert "1 control beacon" in done.stderr
    for stale in ("georeferenced.laz", "transform.json", "plan.png"):
        assert not (tmp_path / stale).exists(), stale
    assert "NO GEOREFERENCE" in (tmp_path / "report.txt").read_text()


def test_helmert7_needs_three_and_finds_a_unit_scale(scene: CloudScenario, tmp_path: Path) -> None:
    done = _georef(scene.cloud, scene.survey, tmp_path, "--model", "helmert7")
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "transform.json").read_text())
    assert record["model"] == "helmert7"
    assert abs(record["scale"] - 1.0) < 4 * record["sigmas"]["scale"] + 1e-5


def _copy_as(scene: CloudScenario, path: Path) -> None:
    """The cloud as PLY (with its times) or E57 (pye57 writes no time stamps)."""
    import laspy

    las = laspy.read(scene.cloud)
    x, y, z = (np.asarray(v, dtype=float) for v in (las.x, las.y, las.z))
    t = np.asarray(las.gps_time, dtype=float)
    inten = np.asarray(las.intensity)
    if path.suffix == ".ply":
        from plyfile import PlyData, PlyElement

        v = np.empty(
            x.size,
            dtype=[
                ("x", "f8"),
                ("y", "f8"),
                ("z", "f8"),
                ("intensity", "u2"),
                ("time", "f8"),
                ("red", "u1"),
                ("green", "u1"),
                ("blue", "u1"),
                ("classification", "u1"),  # a LAS name, not LAS's meaning: kept apart
            ],
        )
        v["x"], v["y"], v["z"], v["intensity"], v["time"] = x, y, z, inten, t
        v["red"], v["green"], v["blue"], v["classification"] = 255, 128, 0, 7
        PlyData([PlyElement.describe(v, "vertex")]).write(str(path))
    else:
        import pye57

        e57 = pye57.E57(str(path), mode="w")
        e57.write_scan_raw(
            {
                "cartesianX": x,
                "cartesianY": y,
                "cartesianZ": z,
                "intensity": inten.astype(float) / 65535.0,
            }
        )
        e57.close()


@pytest.mark.parametrize("suffix", [".ply", ".e57"])
def test_ply_and_e57_give_the_same_transformation(
    scene: CloudScenario, georef: Path, tmp_path: Path, suffix: str
) -> None:
    import laspy

    cloud = tmp_path / f"cloud{suffix}"
    _copy_as(scene, cloud)
    out = tmp_path / "out"
    done = _georef(cloud, scene.survey, out, "--check", "B03")
    assert done.returncode == 0, done.stderr
    a = np.array(json.loads((georef / "transform.json").read_text())["matrix"])
    b = np.array(json.loads((out / "transform.json").read_text())["matrix"])
    assert np.allclose(a, b, atol=1e-6)
    las = laspy.read(out / "georeferenced.laz")
    assert "intensity" in las.point_format.dimension_names
    assert float(np.min(las.y)) > 1e6
    if suffix == ".ply":
        assert int(np.max(las.red)) == 255 * 257  # 8-bit colour in LAS's 16 bits
        assert np.all(np.asarray(las["ply_classification"]) == 7)
        assert np.all(np.asarray(las.classification) == 0)


def test_e57_point_times_are_a_clear_error(scene: CloudScenario, tmp_path: Path) -> None:
    cloud = tmp_path / "cloud.e57"
    _copy_as(scene, cloud)
    done = _georef(cloud, scene.survey, tmp_path / "o", "--time-field", "timeStamp")
    assert done.returncode == 2
    assert "cloud.e57" in done.stderr
    assert "gps_time" in done.stderr


def test_drift_is_corrected_along_the_trajectory(tmp_path: Path) -> None:
    scene = simulate_cloud(
        tmp_path / "sim",
        4,
        CloudOptions(length_m=160.0, beacons=7, density=1500.0, drift=0.01),
    )
    out = tmp_path / "out"
    done = _georef(
        scene.cloud, scene.survey, out, "--check", "B04", "--trajectory", str(scene.trajectory)
    )
    assert done.returncode == 0, done.stderr
    with (out / "beacons_found.csv").open() as fh:
        rows = [r for r in csv.DictReader(fh) if r["beacon"] == "B04"]
    assert rows
    before = max(math.hypot(float(r["residual_e_m"]), float(r["residual_n_m"])) for r in rows)
    after = max(
        math.hypot(float(r["residual_e_after_m"]), float(r["residual_n_after_m"])) for r in rows
    )
    # A 160 m cloud with 1 % drift has its heading turn fastest (the simulator's drift
    # knots are 27 m apart here, 170 m on a 1 km drift): B04, before the sharpest turn
    # of the drift, comes within 5 cm; the 3 cm target is the benchmark's, on 300-1000 m.
    assert after < 0.05
    assert after < before / 3
    import jsonschema

    record = json.loads((out / "transform.json").read_text())
    jsonschema.validate(record, json.loads((DOCS / "transform.schema.json").read_text()))
    dc = record["drift_correction"]
    assert dc["keyframes"] > 100
    # every control beacon tested against the graph without it, the check against the graph
    tested = {t["beacon"]: t for t in dc["beacon_tests"]}
    assert tested["B04"]["role"] == "check"
    assert set(record["beacons"]["control"]) <= set(tested)
    assert all(t["passed"] and t["dof"] in (3, 5) for t in tested.values())
    assert dc["excluded"] == []
    assert "against the graph solved without it" in (out / "report.txt").read_text()
    assert dc["statistic_per_dof"] > 0
    assert "control statistics per degree of freedom" in (out / "report.txt").read_text()
    # B03 moved 0.3 m after its survey: it fails its test against the rest and is left
    # out, rather than the graph bending the cloud onto it
    with scene.survey.open() as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        if r["beacon"] == "B03":
            r["easting"] = f"{float(r['easting']) + 0.3:.4f}"
    moved = tmp_path / "moved.csv"
    with moved.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    bent = _georef(
        scene.cloud, moved, tmp_path / "bent", "--check", "B04", "--trajectory",
        str(scene.trajectory),
    )  # fmt: skip
    assert bent.returncode == 0, bent.stderr
    record = json.loads((tmp_path / "bent" / "transform.json").read_text())
    assert record["drift_correction"]["excluded"] == ["B03"]
    assert record["beacons"]["excluded"] == ["B03"]
    assert all(
        t["passed"] for t in record["drift_correction"]["beacon_tests"] if t["beacon"] != "B03"
    )
    # a drift model far tighter than the SLAM's: too many beacons fail their tests, the
    # run is refused and writes no cloud, transformation or plan (nor fitted coordinates)
    tight = tmp_path / "tight"
    refused = _georef(
        scene.cloud, scene.survey, tight, "--trajectory", str(scene.trajectory),
        "--drift", "0.00002",
    )  # fmt: skip
    assert refused.returncode == 3, refused.stderr
    assert "inconsistent" in refused.stderr
    assert "--drift" in refused.stderr
    for gone in ("georeferenced.laz", "transform.json", "plan.png"):
        assert not (tight / gone).exists()
    assert "NO GEOREFERENCE" in (tight / "report.txt").read_text()
    with (tight / "beacons_found.csv").open() as fh:
        assert not any(r["fitted_easting"] for r in csv.DictReader(fh))
    # without the trajectory the same cloud fits no one transformation: refused
    rigid = _georef(scene.cloud, scene.survey, tmp_path / "rigid")
    assert rigid.returncode == 3
    assert "--trajectory" in rigid.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--band", "2,1"], "Z0 must be below Z1"),
        (["--band", "x"], "two heights"),
        (["--band", "0,inf"], "finite"),
        (["--check", "B99"], "not in the survey"),
        (["--model", "helmert6"], "--model must be one of"),
    ],
)
def test_bad_options_are_one_line_errors(
    scene: CloudScenario, tmp_path: Path, args: list[str], message: str
) -> None:
    done = _georef(scene.cloud, scene.survey, tmp_path, *args)
    assert done.returncode == 2
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_bad_files_are_one_line_errors_naming_them(scene: CloudScenario, tmp_path: Path) -> None:
    txt = tmp_path / "cloud.xyz"
    txt.write_text("1 2 3\n")
    done = _georef(txt, scene.survey, tmp_path / "o")
    assert done.returncode == 2
    assert "cloud.xyz" in done.stderr
    broken = tmp_path / "broken.laz"
    broken.write_bytes(scene.cloud.read_bytes()[:5000])
    done = _georef(broken, scene.survey, tmp_path / "o")
    assert done.returncode == 2, done.stderr
    assert "broken.laz" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1
    traj = tmp_path / "t.tum"
    traj.write_text("# t x y z qx qy qz qw\n1 2 3\n")
    done = _georef(scene.cloud, scene.survey, tmp_path / "o", "--trajectory", str(traj))
    assert done.returncode == 2
    assert "t.tum, line 2" in done.stderr


def test_the_report_gives_the_walls_density(georef: Path) -> None:
    """The simulated cloud has 1 500 points per square metre of every surface: the
    report's measure of the walls lands within a tenth of it, and says it is enough."""
    (line,) = [s for s in (georef / "report.txt").read_text().splitlines() if "wall density" in s]
    density = float(line.split()[2])
    assert 1350 <= density <= 1650, line
    assert "TOO SPARSE" not in line


def test_a_cloud_too_sparse_for_beacons_is_refused_saying_so(tmp_path: Path) -> None:
    sparse = simulate_cloud(
        tmp_path / "sim", 2, CloudOptions(length_m=60.0, beacons=2, density=400.0)
    )
    done = _georef(sparse.cloud, sparse.survey, tmp_path / "geo")
    assert done.returncode == 3, done.stderr
    assert "too sparse for beacons: " in done.stderr
    assert "points per m² on the walls, beacons need about 1200" in done.stderr
    density = float(done.stderr.split("too sparse for beacons: ")[1].split()[0])
    assert 340 <= density <= 460


def test_the_surveys_own_sigma_m_weighs_each_control_edge(scene: CloudScenario) -> None:
    """A survey's ``sigma_m`` per edge in place of ``--survey-sigma``: equal to it, the
    same transformation; larger on one beacon, that beacon counts for less and the
    transformation is less certain."""
    from mast.cloud.georef import GeorefConfig, georeference
    from mast.cloud.io import open_cloud
    from mast.core.beacon import Beacon, Survey
    from mast.io import read_survey

    survey = read_survey(scene.survey)
    cloud = open_cloud(scene.cloud)

    def solved(s: Survey) -> tuple[np.ndarray, np.ndarray]:
        result = georeference(cloud, s, GeorefConfig(survey_sigma_m=0.003))
        assert result.solution is not None, result.refusal
        t = result.solution.transformation
        return t.params, t.covariance

    def given(sigma: dict[str, float]) -> Survey:
        return Survey(
            Beacon(b.id, b.edges, b.elevations, [sigma.get(b.id, 0.003)] * 4) for b in survey
        )

    p0, c0 = solved(survey)
    p1, c1 = solved(given({}))
    np.testing.assert_array_equal(p0, p1)
    np.testing.assert_array_equal(c0, c1)
    p2, c2 = solved(given({"B02": 0.03}))
    assert np.all(np.diag(c2) > np.diag(c0))
    assert np.allclose(p2[:2], p0[:2], atol=0.02)


def _unmatched(monkeypatch: pytest.MonkeyPatch, beacons: set[str]) -> None:
    """Detection misses ``beacons``: their detections are matched to nothing."""
    import dataclasses

    import mast.cloud.georef as georef_module

    real = georef_module.match_beacons

    def missing(*args: Any, **kwargs: Any) -> Any:
        match = real(*args, **kwargs)
        kept = {d: b for d, b in match.assigned.items() if b not in beacons}
        return dataclasses.replace(match, assigned=kept)

    monkeypatch.setattr(georef_module, "match_beacons", missing)


def test_beacons_detection_missed_are_found_where_the_others_put_them(
    scene: CloudScenario, truth: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A control and a check detection missed are sought where the transformation from
    the rest puts them, and found where they are; a surveyed beacon where the cloud has
    none (B02's design 3 m along the wall from it) is not."""
    from mast.cloud.georef import SOUGHT, GeorefConfig, georeference
    from mast.cloud.io import open_cloud
    from mast.core.beacon import Beacon, Survey
    from mast.io import read_survey

    survey = read_survey(scene.survey)
    b2 = survey["B02"]
    along = (b2.edges[3] - b2.edges[0]) / np.hypot(*(b2.edges[3] - b2.edges[0]))
    ghost = Beacon("B99", b2.edges + 3.0 * along, b2.elevations)
    survey = Survey([*survey, ghost])
    _unmatched(monkeypatch, {"B02", "B03"})
    result = georeference(open_cloud(scene.cloud), survey, GeorefConfig(checks=("B03",)))
    assert result.refusal is None, result.refusal
    fates = {fb.beacon: fb for fb in result.beacons}
    assert fates["B02"].role == "control"
    assert fates["B02"].why == SOUGHT
    assert fates["B03"].role == "check"
    assert fates["B03"].why == SOUGHT
    assert fates["B99"].role == "not_found"
    local = {b["id"]: np.array(b["edges_local"]) for b in truth["beacons"]}
    for b in ("B02", "B03"):
        obs = fates[b].obs
        assert obs is not None
        assert np.max(np.hypot(*(obs.cloud_xy - local[b][1:3, :2]).T)) < 0.01
        assert abs(obs.top - local[b][0, 2]) < 0.015
    assert not result.checks[0].failed
    from mast.cloud.georef import explain_missing
    from mast.cloud.outputs import _before_after, report_text

    text = report_text(result, explain_missing(result), _before_after(result, None), None)
    assert "2 not detected on its own, found where the others put it" in text


def test_a_beacon_sought_is_fitted_to_every_point_of_its_panels_not_only_the_candidates(
    scene: CloudScenario, truth: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The column test keeps a panel's points only where it finds panel-like columns:
    here it keeps the outer third of B02's P1 and nothing else of it. Sought, B02 is
    fitted to the whole panel from the cloud (one more pass about it), not to that
    third."""
    import dataclasses

    import mast.cloud.georef as georef_module
    from mast.cloud.detect import Candidates
    from mast.cloud.georef import SOUGHT, GeorefConfig, georeference
    from mast.cloud.io import open_cloud
    from mast.io import read_survey

    local = np.array(next(b for b in truth["beacons"] if b["id"] == "B02")["edges_local"])
    e1, e2 = local[0, :2], local[1, :2]
    real = georef_module.find_candidates

    def thinned(*args: Any, **kwargs: Any) -> Candidates:
        cand: Candidates = real(*args, **kwargs)
        d = e2 - e1
        t = (cand.xyz[:, :2] - e1) @ d / float(d @ d)
        off = np.abs((cand.xyz[:, :2] - e1) @ np.array([-d[1], d[0]])) / math.hypot(*d)
        keep = ~((off < 0.05) & (t > 0.33) & (t < 1.2))
        time = None if cand.time is None else cand.time[keep]
        return dataclasses.replace(cand, xyz=cand.xyz[keep], core=cand.core[keep], time=time)

    monkeypatch.setattr(georef_module, "find_candidates", thinned)
    _unmatched(monkeypatch, {"B02"})
    result = georeference(open_cloud(scene.cloud), read_survey(scene.survey), GeorefConfig())
    found = {fb.beacon: fb for fb in result.beacons}["B02"]
    assert found.why == SOUGHT
    assert found.obs is not None
    assert np.max(np.hypot(*(found.obs.cloud_xy - local[1:3, :2]).T)) < 0.006


def test_with_drift_a_beacon_detection_missed_is_found_where_the_correction_puts_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from mast.cloud.georef import SOUGHT, GeorefConfig, georeference
    from mast.cloud.io import open_cloud
    from mast.io import read_survey
    from mast.io.trajectory import read_trajectory

    scene = simulate_cloud(
        tmp_path / "sim", 4, CloudOptions(length_m=160.0, beacons=7, density=1500.0, drift=0.01)
    )
    truth = json.loads(scene.truth.read_text())
    _unmatched(monkeypatch, {"B05"})
    result = georeference(
        open_cloud(scene.cloud),
        read_survey(scene.survey),
        GeorefConfig(),
        trajectory=read_trajectory(scene.trajectory),
    )
    assert result.refusal is None
    assert result.drift is not None
    found = {fb.beacon: fb for fb in result.beacons}["B05"]
    assert found.role == "control"
    assert found.why == SOUGHT
    assert found.obs is not None
    local = np.array(next(b for b in truth["beacons"] if b["id"] == "B05")["edges_local"])
    assert np.max(np.hypot(*(found.obs.cloud_xy - local[1:3, :2]).T)) < 0.01
