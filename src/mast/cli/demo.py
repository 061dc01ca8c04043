"""``mast demo``: the paper's Table 2 simulated, located and compared with the truth; a
simulated 3D lidar frame located in six degrees of freedom; a simulated drive served by
the SICK emulator and located live; a simulated SLAM cloud georeferenced."""

from __future__ import annotations

import csv
import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from mast.cli.root import app
from mast.core.pose import format_dms
from mast.io.outputs import check_output_folder

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table

__all__ = ["run_demo", "run_demo_3d"]


@app.command()
def demo(
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Keep the simulated files here (default: a temporary folder)."),
    ] = None,
) -> None:
    """Simulate the paper's layout, locate every scan, and compare with the truth (Table 2).

    \b
    Example: mast demo
    """
    if out is not None:
        check_output_folder(out)
    with tempfile.TemporaryDirectory(prefix="mast-demo-") as tmp:
        run_demo(out if out is not None else Path(tmp), echo=typer.echo, keep=out is not None)


def _table(title: str) -> Table:
    from rich.table import Table

    t = Table(title=title, title_justify="left", show_lines=False, pad_edge=False)
    for name in (
        "Pos",
        "Res",
        "True E",
        "True N",
        "Calc E",
        "Calc N",
        "95% E",
        "95% N",
        "dE mm",
        "dN mm",
        "True Az",
        "Calc Az",
        "95% Az",
        "Az error",
        "Beacons",
    ):
        t.add_column(
            name, justify="right" if name not in ("Pos", "Beacons") else "left", no_wrap=True
        )
    return t


def run_demo(folder: Path, *, echo: Callable[[str], object] = print, keep: bool = True) -> int:
    """Simulate the paper scenario (noise-free, then 12 mm noise) into ``folder``,
    locate every scan from the files written, and print Table-2-like comparisons.

    Returns the number of scans without a fix.
    """
    from rich.console import Console

    from mast.io import read_scan_csv, read_survey
    from mast.pipeline.locator import LocatorConfig, locate
    from mast.sim import build_scenario, write_scenario

    console = Console(width=200)
    missing = 0
    for noise in (False, True):
        scenes = build_scenario("paper", 0, noise=noise)
        target = folder / ("noisy" if noise else "noise-free")
        written = write_scenario(scenes, target, scenario="paper", seed=0)
        table = _table(
            "MAST on the paper's layout, "
            + (
                "12 mm range noise (σ given to the adjustment)"
                if noise
                else "noise-free, as in the paper"
            )
        )
        for w in written:
            survey = read_survey(w.survey)
            with w.truth.open(encoding="utf-8") as fh:
                truth = list(csv.DictReader(fh))
            for row, path in zip(truth, w.scans, strict=True):
                scan = read_scan_csv(path)
                # the simulated survey is exact: no survey error in the intervals
                cfg = LocatorConfig(
                    range_sigma_m=float(row["range_sigma_m"]) or 0.001, survey_sigma_m=0.0
                )
                fix = locate(scan, survey, config=cfg)
                pos, res = row["label"].split("@")
                te, tn, taz = (
                    float(row["easting"]),
                    float(row["northing"]),
                    float(row["azimuth_deg"]),
                )
                if not fix.ok or fix.pose is None or fix.adjustment is None:
                    missing += 1
                    table.add_row(
                        pos,
                        res,
                        f"{te:.3f}",
                        f"{tn:.3f}",
                        "—",
                        "—",
                        "",
                        "",
                        "",
                        "",
                        format_dms(taz),
                        f"no fix: {fix.reason}",
                        "",
                        "",
                        "",
                    )
                    continue
                ci = fix.adjustment.interval95()
                p = fix.pose
                daz = math.remainder(p.azimuth_deg - taz, 360.0)
                table.add_row(
                    pos,
                    res,
                    f"{te:.3f}",
                    f"{tn:.3f}",
                    f"{p.easting:.4f}",
                    f"{p.northing:.4f}",
                    f"±{1e3 * ci[0]:.1f}mm",
                    f"±{1e3 * ci[1]:.1f}mm",
                    f"{1e3 * (p.easting - te):+.3f}",
                    f"{1e3 * (p.northing - tn):+.3f}",
                    format_dms(taz),
                    format_dms(p.azimuth_deg),
                    "±" + format_dms(math.degrees(ci[2]), signed=True),
                    format_dms(daz, signed=True),
                    " ".join(
                        f"{b}:{''.join(map(str, sorted(ps)))}"
                        for b, ps in sorted(fix.panels.items())
                    ),
                )
            table.add_section()
        with console.capture() as cap:
            console.print(table)
        echo(cap.get().rstrip())
        echo("")
    run_demo_3d(echo, console)
    _live_demo(folder / "live", echo)
    _georef_demo(folder / "cloud", echo)
    _survey_in_demo(folder / "tls", echo)
    if keep:
        echo(f"Scans and surveys written to {folder}; `mast locate SCAN -b beacons.csv` runs one.")
    else:
        echo("The simulated files were temporary; `mast demo --out DIR` keeps them.")
    return missing


#: The 3D part's frame: a simulated drift's seed and the frame's index in it (a VLP-16 at
#: 2 cm, rolled and pitched on a grade; a frame owed a fix, and fixed).
DEMO_3D_SEED, DEMO_3D_FRAME = 4, 5


def run_demo_3d(echo: Callable[[str], object], console: Console | None = None) -> bool:
    """One simulated VLP-16 frame located in six degrees of freedom, printed beside its
    truth with the fix's sigmas. Returns whether it was fixed."""
    from rich.console import Console
    from rich.table import Table

    from mast.pipeline.adjust3d import UNBRACKETED
    from mast.pipeline.locator3d import Locator3DConfig, locate3d
    from mast.sim.lidar3d import random_drift_scene

    sigma_r = 0.02
    scene = random_drift_scene(
        DEMO_3D_SEED, frames=DEMO_3D_FRAME + 1, lidar="vlp16", range_sigma_m=sigma_r
    )
    sim = scene.simulate(DEMO_3D_FRAME)
    # the simulated survey is exact: no survey error in the sigmas
    fix = locate3d(
        sim.frame, scene.survey, config=Locator3DConfig(range_sigma_m=sigma_r, survey_sigma_m=0.0)
    )
    title = (
        f"3D: one simulated VLP-16 frame ({len(sim.frame)} points, {100 * sigma_r:g} cm range "
        f"noise) in a {scene.params['width_m']:.1f} m drift on a grade of "
        f"{100 * float(scene.params['grade']):+.1f} %, the vehicle rolled and pitched"  # type: ignore[arg-type]
    )
    t = sim.pose
    if not fix.ok or fix.pose is None or fix.adjustment is None:
        echo(f"{title}: no fix ({fix.reason}: {fix.detail})")
        echo("")
        return False
    p, cov = fix.pose, fix.adjustment.covariance
    sigma = [math.sqrt(float(cov[i, i])) for i in range(6)]
    echo(f"{title}; located in {1e3 * fix.elapsed_s:.0f} ms on beacons {', '.join(fix.beacons)}:")
    table = Table(pad_edge=False)
    for name in ("", "Truth", "MAST", "σ", "Error", "Error/σ"):
        table.add_column(name, justify="left" if not name else "right", no_wrap=True)
    turn = math.remainder(p.azimuth - t.azimuth, 2 * math.pi)
    deg = math.degrees
    rows: list[tuple[str, tuple[float, float, float, float], str]] = [
        # (name, (truth, MAST, error, sigma), format)
        ("Easting m", (t.easting, p.easting, p.easting - t.easting, sigma[0]), ".4f"),
        ("Northing m", (t.northing, p.northing, p.northing - t.northing, sigma[1]), ".4f"),
        ("Elevation m", (t.elevation, p.elevation, p.elevation - t.elevation, sigma[2]), ".4f"),
        ("Roll °", (deg(t.roll), deg(p.roll), deg(p.roll - t.roll), deg(sigma[3])), ".3f"),
        ("Pitch °", (deg(t.pitch), deg(p.pitch), deg(p.pitch - t.pitch), deg(sigma[4])), ".3f"),
        ("Azimuth °", (deg(t.azimuth), deg(p.azimuth), deg(turn), deg(sigma[5])), ".3f"),
    ]
    for name, (want, got, err, sig), fmt in rows:
        unknown = name.startswith("Elevation") and cov[2, 2] >= UNBRACKETED / 2
        table.add_row(
            name,
            format(want, fmt),
            format(got, fmt),
            "unobserved" if unknown else "±" + format(sig, fmt),
            format(err, "+" + fmt),
            "" if unknown else f"{err / sig:+.2f}",
        )
    console = console or Console(width=200)
    with console.capture() as cap:
        console.print(table)
    echo(cap.get().rstrip())
    echo("")
    return True


def _survey_in_demo(folder: Path, echo: Callable[[str], object]) -> None:
    """Tripod scans of a simulated drift surveyed in: each beacon's design, edges and top."""
    import math

    import numpy as np

    from mast.cloud.survey_in import SurveyInConfig, survey_in
    from mast.cloud.survey_in_outputs import write_survey_in
    from mast.io import read_survey
    from mast.sim.tls import TlsOptions, simulate_tls

    sim = folder / "sim"
    options = TlsOptions(length_m=24.0, beacons=3, designs=2, stations=2, step_rad=0.0006)
    scene = simulate_tls(sim, 1, options)
    designs = read_survey(scene.designs, apart=False)
    config = SurveyInConfig(noise_m=options.range_noise_m, station_sigma_m=0.0)
    result = survey_in([scene.e57], designs, config)
    out = folder / "survey"
    write_survey_in(result, out, clouds=[scene.e57], designs_file=scene.designs)
    truth = read_survey(scene.survey)
    worst = 0.0
    for f in result.beacons:
        centre = f.beacon.edges.mean(axis=0)
        t = min(truth, key=lambda t: math.dist(t.edges.mean(axis=0), centre))
        worst = max(worst, float(np.max(np.hypot(*(f.beacon.edges - t.edges).T))))
    echo(
        f"survey-in of simulated tripod scans ({len(scene.stations)} stations, "
        f"{scene.points} points): {len(result.beacons)} of {len(truth)} beacons surveyed in "
        f"with their designs ({result.partial} seen in part only), edges within "
        f"{1000 * worst:.2f} mm of the truth; files in {out}"
    )


def _georef_demo(folder: Path, echo: Callable[[str], object]) -> None:
    """A small simulated SLAM cloud put into the grid by ``mast georef``'s pipeline, one
    beacon kept out as a check."""
    import json

    from mast.cloud.georef import GeorefConfig
    from mast.cloud.run import run_georef
    from mast.sim.cloud import CloudOptions, simulate_cloud

    sim = folder / "sim"
    if not (sim / "truth.json").exists():
        simulate_cloud(sim, 2, CloudOptions(length_m=100.0, beacons=5, density=1500.0))
    out = folder / "georef"
    out.mkdir(parents=True, exist_ok=True)
    run = run_georef(sim / "cloud.laz", sim / "beacons.csv", out, GeorefConfig(checks=("B03",)))
    truth = json.loads((sim / "truth.json").read_text())
    r = run.result
    if r.solution is None:
        reason = r.refusal.reason if r.refusal else "?"
        echo(f"georef of a simulated SLAM cloud: not georeferenced ({reason})")
        return
    t = r.solution.transformation
    rot = math.remainder(t.rotation_deg - truth["rotation_deg"], 360.0)
    echo(
        f"georef of a simulated 100 m SLAM cloud ({r.cloud.count} points): "
        f"{sum(b.role == 'control' for b in r.beacons)} control beacons, rotation off the "
        f'truth by {3600 * rot:+.1f}", reference variance {r.solution.reference_variance:.2f} '
        f"({r.solution.chi2_test})"
        + "".join(f"; check {c.beacon} misclosure {1000 * c.horizontal_m:.1f} mm" for c in r.checks)
        + f"; files in {out}"
    )


#: Scans of the live part of the demo: 3 s of a drive at 50 Hz.
LIVE_DEMO_SCANS = 150


def _live_demo(folder: Path, echo: Callable[[str], object]) -> None:
    """A simulated drive served by the SICK emulator and located as it streams in."""
    import statistics

    from mast.live.emulate import Emulator
    from mast.live.session import run_live
    from mast.live.sources import open_source, read_run
    from mast.pipeline.locator import LocatorConfig
    from mast.sim import write_scenario
    from mast.sim.drive import drive_scene

    scene = drive_scene(0, scans=LIVE_DEMO_SCANS, rate_hz=50.0)
    beacons, bag = folder / scene.name / "beacons.csv", folder / scene.name / "scans_mcap"
    if not bag.exists():  # `mast demo --out DIR` again: the drive is there already
        write_scenario([scene], folder, fmt="mcap", scenario="drive")
    records: list[dict[str, object]] = []
    with Emulator("sick", read_run(bag)) as emulator:
        url = f"sick://127.0.0.1:{emulator.port}"
        summary = run_live(
            open_source(url),
            scene.survey,
            emit=records.append,
            config=LocatorConfig(range_sigma_m=0.012),
            max_scans=LIVE_DEMO_SCANS,
        )
    latency = statistics.median(float(r["latency_ms"]) for r in records)  # type: ignore[arg-type]
    echo(
        f"Live: a 50 Hz drive served by the SICK LMS1xx emulator (CoLa-A on {url}): "
        f"{summary.received} scans received, {summary.located} located, {summary.fixed} fixed, "
        f"{summary.dropped} dropped; latency from receipt to pose median {latency:.1f} ms."
    )
    for r in records[:: max(1, len(records) // 5)]:
        where = (
            f"E {r['easting']:.3f} N {r['northing']:.3f} Az {r['azimuth_dms']}"
            if r["status"] == "fix"
            else f"no fix: {r['reason']}"
        )
        echo(f"  scan {r['scan']:>4}  {where}  ({r['latency_ms']} ms)")
    echo(
        f"From a terminal: `mast emulate sick --from {bag} --port 2111 &` then "
        f"`mast live sick://127.0.0.1:2111 -b {beacons}`."
    )
    echo("")
