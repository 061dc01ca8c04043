"""``mast ros2``: a ROS 2 participant over DDS that locates a robot's ``/scan`` and
publishes the pose, without a ROS installation."""

from __future__ import annotations

import contextlib
import math
from typing import TYPE_CHECKING, Annotated

import typer

from mast.cli.live import run_stream, stream_setup
from mast.cli.options import (
    AngleSigmaDegOption,
    AngleSigmaOption,
    AzimuthToleranceOption,
    BeaconsOption,
    CrsOption,
    NearOption,
    RadiusOption,
    RangeMaxOption,
    RangeMinOption,
    RangeSigmaOption,
    ScannerOption,
    SurveySigmaOption,
    check_seconds,
)
from mast.cli.root import app
from mast.cli.settings import ConfigOption

if TYPE_CHECKING:
    from mast.live.session import Sink


@app.command()
def ros2(
    beacons: BeaconsOption,
    scan_topic: Annotated[
        str, typer.Option("--scan-topic", help="The sensor_msgs/LaserScan topic to locate.")
    ] = "/scan",
    frame: Annotated[
        str,
        typer.Option(
            "--frame",
            help="Frame id of the grid in the poses and /tf (x = easting, y = northing).",
        ),
    ] = "map",
    domain_id: Annotated[
        int | None,
        typer.Option(
            "--domain-id",
            help="DDS domain (ROS_DOMAIN_ID's meaning; default: $ROS_DOMAIN_ID, else 0).",
            show_default=False,
        ),
    ] = None,
    tf: Annotated[
        bool,
        typer.Option(
            "--tf/--no-tf",
            help="Publish the grid-to-scanner transform on /tf (--no-tf where the robot's "
            "tree already gives the scanner frame a parent).",
        ),
    ] = True,
    range_sigma: RangeSigmaOption = None,
    angle_sigma_deg: AngleSigmaDegOption = None,
    scanner: ScannerOption = None,
    survey_sigma: SurveySigmaOption = None,
    config: ConfigOption = None,
    range_min: RangeMinOption = None,
    range_max: RangeMaxOption = None,
    near: NearOption = None,
    radius: RadiusOption = 10.0,
    azimuth_tolerance: AzimuthToleranceOption = 30.0,
    timeout: Annotated[
        float,
        typer.Option("--timeout", help="Seconds without a scan before saying so on stderr."),
    ] = 2.0,
    give_up: Annotated[
        float | None,
        typer.Option(
            "--give-up", help="Seconds without a scan before ending (default: run until stopped)."
        ),
    ] = None,
    max_scans: Annotated[
        int | None,
        typer.Option("--max-scans", min=1, help="End after this many scans received."),
    ] = None,
    crs: CrsOption = None,
    angle_sigma: AngleSigmaOption = None,
) -> None:
    """Locate a ROS 2 robot's laser scans as they arrive, over DDS (Eclipse Cyclone DDS;
    no ROS installation needed, wire-compatible with every ROS 2 middleware).

    Subscribes to --scan-topic (sensor_msgs/LaserScan, best effort: reliable and
    best-effort publishers alike) and publishes, per fix, a
    geometry_msgs/PoseWithCovarianceStamped on /mast/pose stamped as its scan (frame
    --frame, x = easting, y = northing, yaw = 90° - azimuth; covariance in x, y, z, roll,
    pitch, yaw with 1e6 on the axes a 2D fix does not observe), the transform from
    --frame to the scan's frame_id on /tf, and every located scan's JSON record (as
    `mast live` prints it, also on standard output) on /mast/fix as std_msgs/String.
    The newest scan is located first when locating falls behind (the others counted
    as dropped). Cyclone DDS takes its network settings from CYCLONEDDS_URI.

    Runs until Ctrl-C or SIGTERM (status 130 or 143), --give-up seconds without a
    scan or --max-scans (status 0; 3 when no scan was fixed), or standard output
    closed (status 0). Status 2 on bad input (a domain that cannot be joined).

    Example: mast ros2 -b examples/beacons.csv --scanner lms1xx-0.25 --frame map
    """
    from mast.cli.warmup import compile_all
    from mast.live.ros2 import Ros2Publisher, Ros2Source, leave, participant, ros2_domain
    from mast.live.stream import SourceOptions

    domain = ros2_domain() if domain_id is None else domain_id
    url = f"ros2://{scan_topic}?domain={domain}"
    setup = stream_setup(
        "ros2",
        url,
        beacons,
        config=config,
        precision=(range_sigma, angle_sigma, scanner, survey_sigma),
        angle_sigma_deg=angle_sigma_deg,
        near=(near, radius, azimuth_tolerance),
        range_limits=(range_min, range_max),
        crs=crs,
    )
    check_seconds("--timeout", timeout)
    if give_up is not None:
        check_seconds("--give-up", give_up)
    options = SourceOptions(
        range_min_m=range_min,
        range_max_m=range_max,
        timeout_s=timeout,
        give_up_s=math.inf if give_up is None else give_up,
    )
    # Ready before joining: a peer that matches a node still compiling would send it
    # scans it locates seconds late (the first run after installing compiles for long).
    compile_all()
    dp = participant(domain)
    stream = Ros2Source(dp, scan_topic, options, url=url)
    publisher = Ros2Publisher(dp, frame=frame, tf=tf)

    def open_sinks(stack: contextlib.ExitStack[bool | None]) -> list[Sink]:
        stack.callback(leave, dp)  # after the run: the last poses acknowledged
        return [publisher]

    def ready() -> None:
        typer.echo(
            f"mast: listening on {scan_topic} in DDS domain {domain}; poses on /mast/pose "
            f"in frame {frame!r}" + (", /tf" if tf else "") + ", records on /mast/fix",
            err=True,
        )

    run_stream(setup, stream, open_sinks, max_scans=max_scans, ready=ready)
