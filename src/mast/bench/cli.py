"""``mast bench``: the benchmarks' commands, each printing figures (not timed tests); and
``mast reproduce paper``, the paper's own experiments beside its Table 2."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from mast.cli.options import (
    DesignSeedOption,
    LogBeaconsOption,
    OldBeaconCountOption,
    RealDataOption,
    cell_progress,
    renamed,
)
from mast.cli.root import (
    CONTEXT,
    app,
)
from mast.errors import InputError
from mast.io.outputs import check_output_file, check_output_folder

bench_app = typer.Typer(
    help="Benchmarks that print figures (not timed tests).",
    no_args_is_help=True,
    context_settings=CONTEXT,
)
app.add_typer(bench_app, name="bench")

reproduce_app = typer.Typer(
    help="Re-run published experiments.", no_args_is_help=True, context_settings=CONTEXT
)
app.add_typer(reproduce_app, name="reproduce")


@reproduce_app.command("paper")
def reproduce_paper_cmd(
    out: Annotated[
        Path, typer.Option("--out", help="Folder for report.md, figures and results.csv.")
    ],
    draws: Annotated[int, typer.Option("--draws", min=1, help="Noisy draws per shot.")] = 30,
    seed: Annotated[int, typer.Option("--seed", help="Noise seed.")] = 0,
) -> None:
    """The MAST paper's experiments (Table 2 positions, wall yaws, beacon sizes), noise-free
    and with 12 mm range noise, reported beside the paper's published values.

    \b
    Example: mast reproduce paper --out paper/ --draws 5
    """
    from mast.bench.paper import reproduce_paper

    check_output_folder(out)
    reproduce_paper(out, draws=draws, seed=seed, echo=typer.echo)


@bench_app.command("accuracy")
def bench_accuracy(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    poses: Annotated[
        int, typer.Option("--poses", min=1, help="Owed poses per configuration.")
    ] = 40,
    draws: Annotated[int, typer.Option("--draws", min=1, help="Noise draws per pose.")] = 30,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """RMS error against the Cramer-Rao bound and coverage of the 95 % intervals,
    for the four scanner configurations (270° at 0.5° and 0.25°, 190° at 1/6°, 360° at 0.2°).

    \b
    Example: mast bench accuracy --poses 5 --draws 5
    """
    from mast.bench.accuracy import run_accuracy

    if out is not None:
        check_output_folder(out)
    run_accuracy(poses=poses, draws=draws, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("accuracy3d")
def bench_accuracy3d(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    frames: Annotated[
        int, typer.Option("--frames", min=1, help="Owed frames per configuration.")
    ] = 40,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the simulated drifts.")] = 0,
    lidar: Annotated[
        list[str] | None,
        typer.Option("--lidar", help="Only this lidar (vlp16, os1-64); may be repeated."),
    ] = None,
    range_sigma: Annotated[
        list[float] | None,
        typer.Option(
            "--range-sigma", help="Only this range sigma, metres (0.01, 0.02, 0.03); repeatable."
        ),
    ] = None,
) -> None:
    """The 3D locator against the six-parameter Cramer-Rao bound: fix rate where owed,
    wrong fixes, RMS/CRB and 95 % coverage per parameter, errors and time per frame, for
    VLP-16 and OS1-64 frames at 1, 2 and 3 cm, with and without look-alikes.

    \b
    Example: mast bench accuracy3d --frames 5 --lidar vlp16 --range-sigma 0.02
    """
    from mast.bench.accuracy3d import ACCURACY3D_CONFIGS, run_accuracy3d

    if out is not None:
        check_output_folder(out)
    configs = [
        c
        for c in ACCURACY3D_CONFIGS
        if (not lidar or c.lidar in lidar)
        and (not range_sigma or any(abs(c.range_sigma_m - s) < 1e-9 for s in range_sigma))
    ]
    if not configs:
        raise InputError(
            "no 3D configuration matches --lidar and --range-sigma; known: lidars vlp16 and "
            "os1-64, range sigmas 0.01, 0.02 and 0.03"
        )
    run_accuracy3d(configs=configs, frames=frames, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("survey")
def bench_survey(
    beacons: Annotated[
        int, typer.Option("--beacon-count", min=1, help="Beacons in the mine's survey.")
    ] = 10_000,
    range_max: Annotated[
        float,
        typer.Option(
            "--range-max", min=0.1, help="Scanner's longest range, metres (sets the index's reach)."
        ),
    ] = 80.0,
    old_beacons: OldBeaconCountOption = None,
) -> None:
    """A whole mine's survey read, checked and indexed: seconds, with a few designs and with
    every beacon its own.

    \b
    Example: mast bench survey --beacon-count 1000
    """
    from mast.bench.surveyload import run_survey_load

    beacons = _count(beacons, old_beacons, 10_000)
    run_survey_load(beacons=beacons, range_max_m=range_max, echo=typer.echo)


@bench_app.command("fuzz")
def bench_fuzz(
    inputs: Annotated[
        int, typer.Option("--inputs", min=1, help="Damaged or crafted inputs to run.")
    ] = 10_000,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the mutations.")] = 0,
    keep: Annotated[
        Path | None, typer.Option("--keep", help="Folder to copy failing cases into.")
    ] = None,
) -> None:
    """Damaged and crafted files through every reader and output path, each run in a
    child with memory, file-size and time limits: tracebacks, undocumented exit
    statuses, memory and time beyond bounds, fixes that differ, half-written outputs.

    \b
    Example: mast bench fuzz --inputs 50 --keep fuzz-failures/
    """
    from mast.bench.fuzz import run_fuzz

    if keep is not None:
        check_output_folder(keep, option="--keep")
    with cell_progress("fuzzing", unit="inputs") as progress:
        run_fuzz(inputs=inputs, seed=seed, echo=typer.echo, progress=progress, keep_failures=keep)


@bench_app.command("robustness")
def bench_robustness(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    hard: Annotated[
        int, typer.Option("--hard-scenes", min=0, help="Hostile scenes (5 scans each).")
    ] = 200,
    drift: Annotated[
        int, typer.Option("--drift-scenes", min=0, help="Many-beacon drifts (10 scans each).")
    ] = 40,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
    old_hard: Annotated[
        int | None, typer.Option("--hard", hidden=True, help="Old name of --hard-scenes.")
    ] = None,
    old_drift: Annotated[
        int | None, typer.Option("--drift", hidden=True, help="Old name of --drift-scenes.")
    ] = None,
) -> None:
    """Fix rate where two beacons each show two clean panels, wrong fixes and no-fix
    reasons, over hostile scenes and a many-beacon drift.

    \b
    Example: mast bench robustness --hard-scenes 10 --drift-scenes 2
    """
    from mast.bench.robustness import run_robustness

    hard = _count(hard, old_hard, 200, new="--hard-scenes", old="--hard")
    drift = _count(drift, old_drift, 40, new="--drift-scenes", old="--drift")

    if out is not None:
        check_output_folder(out)
    run_robustness(hard_scenes=hard, drift_scenes=drift, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("field")
def bench_field(
    out: Annotated[Path | None, typer.Option("--out", help="Folder for the CSV files.")] = None,
    scenes: Annotated[
        int, typer.Option("--scenes", min=1, help="Scenes per family (noisy, hostile).")
    ] = 200,
    poses: Annotated[int, typer.Option("--poses", min=1, help="Shots per scene.")] = 4,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """Scenes drawn as widely as the field (beacons of any shape bolted askew onto rough
    rock, five scanners from 8 to 20 mm, clutter shaped like panels, mixed pixels),
    scored as the independent scenes are: owed scans fixed, wrong fixes, RMS/CRB and
    95 % coverage.

    \b
    Example: mast bench field --scenes 5 --poses 2
    """
    from mast.bench.field import run_field

    if out is not None:
        check_output_folder(out)
    run_field(scenes=scenes, poses=poses, seed=seed, out_dir=out, echo=typer.echo)


@bench_app.command("minewide")
def bench_minewide(
    poses: Annotated[int, typer.Option("--poses", min=1, help="Owed scans located.")] = 40,
    copies: Annotated[
        int, typer.Option("--copies", min=0, help="Copies of the designs surveyed elsewhere.")
    ] = 184,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
    distinct: Annotated[
        bool,
        typer.Option(
            "--distinct", help="Each added beacon of a random design of its own, not a copy."
        ),
    ] = False,
) -> None:
    """The same scans against their local survey and a mine-wide one (the local beacons
    plus copies of their designs in other drifts): same fixes, and the time it costs.

    \b
    Example: mast bench minewide --poses 5 --copies 20
    """
    from mast.bench.minewide import run_minewide

    run_minewide(poses=poses, copies=copies, seed=seed, distinct=distinct, echo=typer.echo)


@bench_app.command("tracking")
def bench_tracking(
    poses: Annotated[
        int, typer.Option("--poses", min=1, help="Owed poses per configuration.")
    ] = 40,
    draws: Annotated[int, typer.Option("--draws", min=1, help="Noise draws per pose.")] = 3,
    seed: Annotated[int, typer.Option("--seed", help="First scene seed.")] = 0,
) -> None:
    """Tracking: the accuracy benchmark's owed scans with a prior within 0.5 m and 5 degrees
    (a fix owed on every one), and with a prior 1.5 m off (no fix owed).

    \b
    Example: mast bench tracking --poses 5 --draws 1
    """
    from mast.bench.tracking import run_tracking

    run_tracking(poses=poses, draws=draws, seed=seed, echo=typer.echo)


@bench_app.command("live")
def bench_live(
    scans: Annotated[int, typer.Option("--scans", min=100, help="Scans per scanner.")] = 30_000,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drive.")] = 0,
    kind: Annotated[
        list[str] | None, typer.Option("--kind", help="sick, hokuyo [default: both].")
    ] = None,
) -> None:
    """Live: a simulated drive with beacon gaps served by the SICK (50 Hz) and Hokuyo (40 Hz)
    emulators and located as it arrives (latency, drops, memory, CPU, owed scans fixed,
    recovery from a wrong prior).

    \b
    Example: mast bench live --scans 1000 --kind sick
    """
    from mast.bench.live import run_live_bench

    run_live_bench(scans=scans, seed=seed, kinds=tuple(kind or ("sick", "hokuyo")), echo=typer.echo)


@bench_app.command("ros2")
def bench_ros2(
    scans: Annotated[int, typer.Option("--scans", min=10, help="Scans per rate.")] = 2000,
    rate: Annotated[
        list[float] | None, typer.Option("--rate", help="Scan rate, Hz [default: 10 and 25].")
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drive.")] = 0,
    domain_id: Annotated[
        int, typer.Option("--domain-id", min=0, max=232, help="DDS domain the run uses.")
    ] = 201,
) -> None:
    """ROS 2: a simulated drive published on /scan over DDS (loopback) and located by
    `mast ros2` in its own process (latency to the pose, the node's overhead, scans
    dropped or lost, poses against mast locate's on the same bag).

    Example: mast bench ros2 --scans 500 --rate 25
    """
    from mast.bench.ros2 import run_ros2_bench

    run_ros2_bench(
        scans=scans,
        rates_hz=tuple(rate or (10.0, 25.0)),
        seed=seed,
        domain=domain_id,
        echo=typer.echo,
    )


@bench_app.command("longdrive")
def bench_longdrive(
    scans: Annotated[int, typer.Option("--scans", min=100, help="Scans per drive.")] = 10_000,
    seeds: Annotated[int, typer.Option("--seeds", min=1, help="Drives per scanner.")] = 5,
    workers: Annotated[int, typer.Option("--workers", min=1, help="Processes.")] = 2,
    out: Annotated[
        Path | None, typer.Option("--out", help="Folder for every scan's outcome (CSV).")
    ] = None,
) -> None:
    """Long drives: SICK (50 Hz) and Hokuyo (40 Hz) drives sent through their protocols and
    located in sequence as `mast locate RUN` and `mast live` do (owed scans fixed, wrong
    fixes listed, fixes outside their own 99 % ellipse, time a scan).

    \b
    Example: mast bench longdrive --scans 1000 --seeds 1 --workers 1
    """
    from mast.bench.longdrive import run_longdrive

    if out is not None:
        check_output_folder(out)
    run_longdrive(scans=scans, seeds=seeds, workers=workers, out_dir=out, echo=typer.echo)


@bench_app.command("georef")
def bench_georef(
    clouds: Annotated[int, typer.Option("--clouds", min=0, help="Clouds without drift.")] = 20,
    drift_clouds: Annotated[
        int, typer.Option("--drift-clouds", min=0, help="Clouds with 1 % drift.")
    ] = 6,
    large_points: Annotated[
        int, typer.Option("--large-points", min=0, help="Points of the large cloud (0: none).")
    ] = 50_000_000,
    density: Annotated[
        float, typer.Option("--density", min=100.0, help="Points per square metre.")
    ] = 2000.0,
    hard: Annotated[
        bool,
        typer.Option(
            "--hard",
            help="Clouds as rough as independent ones: density falling with range beyond "
            "4 m, rough rock right up to the beacons, three designs with shallow outer panels.",
        ),
    ] = False,
    out: Annotated[Path | None, typer.Option("--out", help="CSV of every cloud.")] = None,
) -> None:
    """Simulated SLAM clouds through mast georef: beacons found, check misclosures, honest
    bounds, drift corrected, and a large LAZ's time and memory.

    \b
    Example: mast bench georef --clouds 1 --drift-clouds 0 --large-points 0
    """
    from mast.bench.georef import run_georef_bench

    run_georef_bench(
        clouds=clouds,
        drift_clouds=drift_clouds,
        large_points=large_points,
        density=density,
        hard=hard,
        out=out,
        echo=typer.echo,
    )


@bench_app.command("survey-in")
def bench_survey_in(
    scenes: Annotated[int, typer.Option("--scenes", min=1, help="Simulated TLS scenes.")] = 12,
    far_scenes: Annotated[
        int,
        typer.Option(
            "--far-scenes",
            min=0,
            help="More scenes, of stations 45-50 m apart (beacons up to 25 m away).",
        ),
    ] = 0,
    seed: Annotated[int, typer.Option("--seed", help="First scene's seed.")] = 0,
    out: Annotated[Path | None, typer.Option("--out", help="CSV of every beacon.")] = None,
) -> None:
    """Simulated terrestrial scans through mast survey-in: beacons found with their
    designs, edge and elevation errors against sigma_m, a moved beacon named.

    \b
    Example: mast bench survey-in --scenes 2
    """
    from mast.bench.survey_in import run_survey_in_bench

    if out is not None:
        check_output_file(out, suffixes=(".csv",))
    run_survey_in_bench(scenes=scenes, far_scenes=far_scenes, seed=seed, out=out, echo=typer.echo)


@bench_app.command("dense")
def bench_dense(
    beams: Annotated[
        list[int] | None,
        typer.Argument(help="Beam counts to measure [default: 1081 10000 100000 1000000]."),
    ] = None,
    range_sigma: Annotated[
        float, typer.Option("--range-sigma", help="Range noise of the scans, metres.")
    ] = 0.0,
) -> None:
    """Dense scans: read and locate time and peak memory (each in a fresh process)
    against the beams of a scan, from a normal scan to a million beams.

    \b
    Example: mast bench dense 1081 10000
    """
    from mast.bench.dense import DEFAULT_BEAMS, run_dense

    run_dense(tuple(beams) if beams else DEFAULT_BEAMS, range_sigma_m=range_sigma, echo=typer.echo)


@bench_app.command("run")
def bench_run(
    scans: Annotated[
        list[int] | None,
        typer.Argument(help="Drive lengths in scans [default: 1000 10000]."),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drive.")] = 0,
) -> None:
    """Survey runs: simulated drives read and tracked (throughput, peak memory), the placed
    scans against the truth (fixed and carried by odometry) and their 95 % coverage.

    \b
    Example: mast bench run 1000
    """
    from mast.bench.runs import DEFAULT_SCANS, run_runs

    run_runs(tuple(scans) if scans else DEFAULT_SCANS, seed=seed, echo=typer.echo)


@bench_app.command("speed")
def bench_speed(
    scans: Annotated[
        int, typer.Option("--scans", min=0, help="Scans located at 1081 beams (0: skip).")
    ] = 300,
    scans_360: Annotated[
        int, typer.Option("--scans-360", min=0, help="Scans located at 1800 beams (0: skip).")
    ] = 100,
    bag: Annotated[
        list[int] | None,
        typer.Option(
            "--bag",
            min=0,
            help="Bag length read and located by mast locate, repeatable; 0 skips "
            "[default: 1000 3000].",
        ),
    ] = None,
    track: Annotated[
        list[int] | None,
        typer.Option(
            "--track",
            min=0,
            help="Bag length tracked by mast track, repeatable; 0 skips [default: 1000].",
        ),
    ] = None,
    minewide_poses: Annotated[
        int, typer.Option("--minewide-poses", min=0, help="Mine-wide scans (0: skip).")
    ] = 40,
    beacons: Annotated[
        int, typer.Option("--beacon-count", min=3, help="Beacons of the mine-wide survey.")
    ] = 200,
    startup_runs: Annotated[
        int, typer.Option("--startup-runs", min=0, help="Fresh 'mast --help' runs (0: skip).")
    ] = 5,
    tracked_scans: Annotated[
        int,
        typer.Option("--tracked-scans", min=0, help="Drive scans located in sequence (0: skip)."),
    ] = 600,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the drives and scenes.")] = 0,
    out: Annotated[
        Path | None, typer.Option("--out", help="Also write the figures to this text file.")
    ] = None,
    old_beacons: OldBeaconCountOption = None,
) -> None:
    """Speed: locate per scan and per stage (1081 and 1800 beams), bags read, located and
    tracked (each in a fresh process: throughput, peak memory), a 200-beacon survey,
    start-up, a peer (small_gicp point-to-plane ICP) on the same scans, and tracked
    scans (a drive located in sequence) per stage beside the peer from their priors.

    \b
    Example: mast bench speed --scans 50 --scans-360 0 --bag 0 --track 0 \\
      --minewide-poses 0 --startup-runs 1 --tracked-scans 0
    """
    from mast.bench.speed import DEFAULT_BAG_SCANS, DEFAULT_TRACK_SCANS, run_speed

    beacons = _count(beacons, old_beacons, 200)

    if out is not None:
        check_output_file(out, suffixes=(".txt", ".md", ".log"), option="--out")
    run_speed(
        scans=scans,
        scans_360=scans_360,
        bag_scans=tuple(n for n in bag if n) if bag else DEFAULT_BAG_SCANS,
        track_scans=tuple(n for n in track if n) if track else DEFAULT_TRACK_SCANS,
        minewide_poses=minewide_poses,
        survey_beacons=beacons,
        startup_runs=startup_runs,
        tracked_scans=tracked_scans,
        seed=seed,
        out=out,
        echo=typer.echo,
    )


@bench_app.command("clutter")
def bench_clutter(
    data: RealDataOption = Path("../shared/data"),
    beacons: LogBeaconsOption = 29,
    seed: DesignSeedOption = 0,
    priors: Annotated[
        bool,
        typer.Option(
            "--priors/--no-priors",
            help="Also locate every scan with a good prior (0.5 m, 5 deg) and a wrong one.",
        ),
    ] = True,
    old_beacons: OldBeaconCountOption = None,
) -> None:
    """Real clutter: beacons mounted on the real walls of CARMEN logs with corrected
    poses, ray-cast into every scan; fixes where owed and wrong fixes per log, also
    when tracking from a good or a wrong prior.

    \b
    Example: mast bench clutter --data ../shared/data --no-priors
    """
    from mast.bench.clutter import run_real_clutter

    beacons = _count(beacons, old_beacons, 29)

    if not data.is_dir():
        raise InputError("folder of real scans not found", path=data)
    run_real_clutter(data, beacons=beacons, seed=seed, priors=priors, echo=typer.echo)


@bench_app.command("reallog")
def bench_reallog(
    data: RealDataOption = Path("../shared/data"),
    beacons: LogBeaconsOption = 29,
    seed: DesignSeedOption = 0,
    max_gap: Annotated[
        float, typer.Option("--max-gap", min=0.0, help="As mast track's --max-gap, seconds.")
    ] = 3.0,
    old_beacons: OldBeaconCountOption = None,
) -> None:
    """Runs on real logs: beacons mounted on the real walls of CARMEN logs, the logs
    tracked as mast track does; error and 95 % coverage of the scans placed by odometry.

    \b
    Example: mast bench reallog --data ../shared/data --max-gap 3
    """
    from mast.bench.reallog import run_real_logs

    beacons = _count(beacons, old_beacons, 29)

    if not data.is_dir():
        raise InputError("folder of real scans not found", path=data)
    run_real_logs(data, beacons=beacons, seed=seed, max_gap_s=max_gap, echo=typer.echo)


@bench_app.command("real")
def bench_real(
    data: RealDataOption = Path("../shared/data"),
    every: Annotated[
        int, typer.Option("--every", min=1, help="Insert beacons into every Nth scan.")
    ] = 10,
) -> None:
    """Real scans by others: no fix without beacons; fixes with beacons ray-cast into them.

    \b
    Example: mast bench real --data ../shared/data --every 20
    """
    from mast.bench.realscans import run_real_scans

    if not data.is_dir():
        raise InputError("folder of real scans not found", path=data)
    run_real_scans(data, every=every, echo=typer.echo)


def _count(
    value: int,
    old_value: int | None,
    default: int,
    *,
    new: str = "--beacon-count",
    old: str = "--beacons",
) -> int:
    """A count given by its new option name or, for a release, its old one (which, in
    ``mast locate`` and the other field commands, names the survey file):
    :func:`mast.cli.options.renamed`."""
    given = renamed(value, old_value, new=new, old=old, default=default)
    return default if given is None else given
