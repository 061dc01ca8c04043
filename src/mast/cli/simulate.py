"""``mast simulate``: a named scenario's scans, survey and truth written to a folder."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from mast.cli.options import (
    SimulatedFormat,
    renamed,
)
from mast.cli.root import (
    app,
)
from mast.errors import InputError
from mast.io.outputs import check_output_folder


@app.command()
def simulate(
    out: Annotated[Path, typer.Option("--out", help="Folder to write into (created if missing).")],
    scenario: Annotated[
        str,
        typer.Option(
            "--scenario",
            help=(
                "Scenario name: paper, random, drive (a vehicle driving a drift at the "
                "scanner's rate, beacons in stretches with 30-60 m gaps between; streamed), "
                "cloud (a 3D SLAM point cloud of a drift with beacons, for mast georef) or "
                "tls (tripod laser scans of a drift already in the grid, for mast survey-in)."
            ),
        ),
    ] = "paper",
    seed: Annotated[int, typer.Option("--seed", help="Random seed (noise, random scenes).")] = 0,
    fmt: Annotated[
        SimulatedFormat,
        typer.Option(
            "--scan-format",
            help=(
                "How the scans are written: csv: one file per scan; bag: ROS 1 bag; "
                "ros2: ROS 2 sqlite3 bag; mcap: ROS 2 MCAP bag."
            ),
        ),
    ] = SimulatedFormat.csv,
    noisy: Annotated[
        bool | None,
        typer.Option(
            "--noisy/--noise-free",
            help="Add realistic noise: 12 mm range noise to scans, 10 mm to a cloud's points "
            "(default: noise-free for paper and random, noisy for drive and cloud).",
            show_default=False,
        ),
    ] = None,
    scans: Annotated[
        int | None,
        typer.Option(
            "--scans", min=1, help="drive: number of scans (default 500; 10000 is ~800 m)."
        ),
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(
            "--rate", help="drive: scans per second, Hz (default 25 at 0.25°; 50 gives 0.5°)."
        ),
    ] = None,
    length: Annotated[
        float | None,
        typer.Option("--length", min=40.0, help="cloud: drift length, metres (default 300)."),
    ] = None,
    beacon_count: Annotated[
        int | None,
        typer.Option("--beacon-count", min=2, help="cloud: beacons mounted (default 12)."),
    ] = None,
    drift: Annotated[
        float | None,
        typer.Option(
            "--drift",
            min=0.0,
            max=0.2,
            help="cloud: the SLAM's drift, a fraction of the distance travelled (0.01 = 1 %).",
        ),
    ] = None,
    density: Annotated[
        float | None,
        typer.Option(
            "--density",
            min=1.0,
            help="cloud: points per square metre (default 2000; georef needs about 1200).",
        ),
    ] = None,
    old_format: Annotated[
        SimulatedFormat | None,
        typer.Option("--format", hidden=True, help="Old name of --scan-format."),
    ] = None,
    old_noise: Annotated[
        bool | None,
        typer.Option("--noise/--no-noise", hidden=True, help="Old name of --noisy/--noise-free."),
    ] = None,
) -> None:
    """Simulate a scenario: per scene, beacons.csv, the scans and truth.csv; or, with
    --scenario cloud, a 3D SLAM cloud of a drift (cloud.laz, beacons.csv with elevations,
    trajectory.tum, truth.json); or, with --scenario tls, tripod scans of a drift in the
    grid (scans.e57, designs.csv, beacons.csv, truth.json). The folder layout:
    docs/simulate.md.

    \b
    Example: mast simulate --scenario random --seed 7 --scan-format bag --out sim-random/
    """
    from mast.sim import build_scenario, write_scenario

    written_as = renamed(
        fmt, old_format, new="--scan-format", old="--format", default=SimulatedFormat.csv
    )
    assert written_as is not None
    noise = renamed(noisy, old_noise, new="--noisy/--noise-free", old="--noise/--no-noise")

    options = {k: v for k, v in (("scans", scans), ("rate_hz", rate)) if v is not None}
    cloud_options = {
        k: v
        for k, v in (
            ("length_m", length),
            ("beacons", beacon_count),
            ("drift", drift),
            ("density", density),
        )
        if v is not None
    }
    if options and scenario != "drive":
        raise InputError("--scans and --rate apply to --scenario drive only")
    if cloud_options and scenario != "cloud":
        raise InputError(
            "--length, --beacon-count, --drift and --density apply to --scenario cloud"
        )
    check_output_folder(out)
    if scenario == "tls":
        from mast.sim.tls import TlsOptions, simulate_tls

        # a phase-based scanner's 1.5 mm unless --noise-free
        tls = simulate_tls(out, seed, TlsOptions(range_noise_m=0.0 if noise is False else 0.0015))
        typer.echo(
            f"{tls.e57}: {tls.points} points from {len(tls.stations)} stations, "
            f"{len(tls.beacons)} beacons; designs {tls.designs.name}, survey "
            f"{tls.survey.name}, truth {tls.truth.name}"
        )
        return
    if scenario == "cloud":
        from mast.sim.cloud import CloudOptions, simulate_cloud

        noise_m = None if noise is None else (0.01 if noise else 0.0)
        opts = CloudOptions(**cloud_options)  # type: ignore[arg-type]
        if noise_m is not None:
            opts = replace(opts, noise_m=noise_m)
        sim = simulate_cloud(out, seed, opts)
        typer.echo(
            f"{sim.cloud}: {sim.points} points, {sim.beacons} beacons in {sim.survey.name}, "
            f"trajectory {sim.trajectory.name}, truth {sim.truth.name}"
        )
        return
    scenes = build_scenario(scenario, seed, noise=noise, **options)
    written = write_scenario(scenes, out, fmt=written_as.value, scenario=scenario, seed=seed)
    for w in written:
        typer.echo(f"{w.folder}: {w.count} scan(s), survey {w.survey.name}, truth {w.truth.name}")
    typer.echo(f"wrote {sum(w.count for w in written)} scan(s) in {len(written)} scene(s) to {out}")
