"""Trajectory files: ``trajectory.csv`` (a file contract: docs/design.md, "A run") and
TUM (``t x y z qx qy qz qw``, for trajectory tools such as evo), written from a run's
placed scans, and read back (either kind) as the scanner's path a point cloud's drift
correction follows (``mast georef --trajectory``).

Frames (docs/design.md, "Frames and units"): mine frame E = x, N = y in metres; azimuth
clockwise from grid north; a TUM heading (yaw) is counter-clockwise from +E, so
``yaw = 90° − azimuth`` (:mod:`mast.core.frames`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Final, Protocol

import numpy as np
from numpy.typing import NDArray

from mast.core.frames import yaw_of_azimuth, yaw_quaternion
from mast.core.pose3d import Pose3D
from mast.core.trajectory import PlacedScan, ScannerPath
from mast.errors import InputError
from mast.io.atomic import write_lines

__all__ = [
    "TRAJECTORY3D_HEADER",
    "TRAJECTORY_HEADER",
    "TUM3D_HEADER",
    "TUM_HEADER",
    "Placed3D",
    "read_trajectory",
    "rotation_quaternion",
    "tum_quaternion",
    "write_trajectory3d_csv",
    "write_trajectory3d_tum",
    "write_trajectory_csv",
    "write_trajectory_tum",
]

#: Header of ``trajectory.csv`` (a file contract: docs/design.md, "A run").
TRAJECTORY_HEADER: Final = (
    "stamp_ns,easting,northing,azimuth_deg,"
    "sigma_easting_m,sigma_northing_m,sigma_azimuth_deg,source"
)

#: Header comment of ``trajectory.tum``; TUM readers (evo) skip lines starting with '#'.
TUM_HEADER: Final = (
    "# timestamp_s x_easting_m y_northing_m z_m qx qy qz qw (yaw = 90 deg - azimuth)"
)

#: Header of a 3D run's ``trajectory.csv``: 2D's columns, then the elevation, roll and
#: pitch and their sigmas (``sigma_elevation_m`` empty where it was not observed).
TRAJECTORY3D_HEADER: Final = (
    TRAJECTORY_HEADER
    + ",elevation_m,roll_deg,pitch_deg,sigma_elevation_m,sigma_roll_deg,sigma_pitch_deg"
)

#: Header comment of a 3D run's ``trajectory.tum``.
TUM3D_HEADER: Final = (
    "# timestamp_s x_easting_m y_northing_m z_elevation_m qx qy qz qw "
    "(sensor to grid, R = Rz(yaw) Ry(pitch) Rx(roll), yaw = 90 deg - azimuth)"
)


class Placed3D(Protocol):
    """A frame placed in 3D (:class:`mast.runs.frames3d.PlacedFrame`)."""

    @property
    def stamp_ns(self) -> int: ...

    @property
    def pose(self) -> Pose3D: ...

    @property
    def sigma(self) -> NDArray[np.float64]:
        """Sigmas of (easting, northing, elevation, roll, pitch, azimuth), metres and
        radians; the elevation's NaN where it was not observed."""
        ...


def _seconds(stamp_ns: int) -> str:
    """``stamp_ns`` as decimal seconds with all nine digits, without going through a float."""
    sign = "-" if stamp_ns < 0 else ""
    s, ns = divmod(abs(int(stamp_ns)), 1_000_000_000)
    return f"{sign}{s}.{ns:09d}"


def _num(value: float) -> str:
    """Shortest text that reads back as the same double (a Python float's repr)."""
    return repr(float(value))


def write_trajectory_csv(path: str | Path, placed: Iterable[PlacedScan]) -> int:
    """Write ``trajectory.csv``: one row per placed scan, in the given order.

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists).
    placed : iterable of PlacedScan
        The placed scans, in time order.

    Returns
    -------
    int
        Rows written (without the header).

    Notes
    -----
    The header is :data:`TRAJECTORY_HEADER` (a file contract). Floats are
    written as their shortest exact representation (Python's ``repr``), so a
    UTM coordinate such as 512334.1234 reads back as the same double;
    ``azimuth_deg`` is in [0, 360), ``sigma_azimuth_deg`` in degrees, and
    ``source`` is ``fix`` or ``odometry``.

    Raises
    ------
    OutputError
        The file cannot be written.
    """

    def rows() -> Iterator[str]:
        yield TRAJECTORY_HEADER
        for p in placed:
            s = p.sigma
            yield ",".join(
                (
                    str(int(p.stamp_ns)),
                    _num(p.pose.easting),
                    _num(p.pose.northing),
                    _num(p.pose.azimuth_deg),
                    _num(s[0]),
                    _num(s[1]),
                    _num(math.degrees(s[2])),
                    p.source,
                )
            )

    return write_lines(path, rows())


def tum_quaternion(azimuth_rad: float) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` of a rotation about z by ``yaw = 90° − azimuth``.

    The yaw is wrapped to (−180°, 180°] first, so that ``qw >= 0``.
    """
    yaw = yaw_of_azimuth(azimuth_rad)
    return yaw_quaternion(-((math.pi - yaw) % math.tau - math.pi))  # yaw in (-pi, pi]


def write_trajectory_tum(path: str | Path, placed: Iterable[PlacedScan]) -> int:
    """Write ``trajectory.tum``: the placed poses in the TUM RGB-D trajectory format.

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists).
    placed : iterable of PlacedScan
        The placed scans, in time order.

    Returns
    -------
    int
        Poses written.

    Notes
    -----
    One line per pose, ``t x y z qx qy qz qw`` separated by single spaces
    (no trailing space: evo refuses one), after one comment line starting
    with ``#`` (:data:`TUM_HEADER`), which TUM readers skip. ``t`` is the
    stamp in seconds with all nine decimals, formatted from the integer
    nanoseconds; ``x`` = easting, ``y`` = northing, ``z`` = 0 (metres); the
    orientation is the rotation about z by ``yaw = 90° − azimuth`` (the
    scanner's +x counter-clockwise from +E), a unit quaternion with
    ``qw >= 0``.

    References
    ----------
    TUM RGB-D benchmark, file formats:
    https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats

    Raises
    ------
    OutputError
        The file cannot be written.
    """

    def rows() -> Iterator[str]:
        yield TUM_HEADER
        for p in placed:
            qx, qy, qz, qw = tum_quaternion(p.pose.azimuth)
            yield " ".join(
                (
                    _seconds(p.stamp_ns),
                    _num(p.pose.easting),
                    _num(p.pose.northing),
                    "0.0",
                    _num(qx),
                    _num(qy),
                    _num(qz),
                    _num(qw),
                )
            )

    return write_lines(path, rows())


def read_trajectory(path: str | Path) -> ScannerPath:
    """Read a TUM file (``t x y z qx qy qz qw``) or a ``mast track`` trajectory CSV."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read: {err}", path=p) from None
    lines = text.splitlines()
    first = next((ln for ln in lines if ln.strip() and not ln.startswith("#")), "")
    if first.startswith("stamp_ns"):
        return _read_track_csv(p, lines)
    rows = []
    for no, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split()
        if len(parts) != 8:
            raise InputError(
                f"a TUM pose has 8 numbers (t x y z qx qy qz qw), this line {len(parts)}",
                path=p,
                line=no,
            )
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            raise InputError("not a number in a TUM pose", path=p, line=no) from None
        if not all(math.isfinite(v) for v in vals):
            raise InputError("a TUM pose with a value that is not finite", path=p, line=no)
        rows.append(vals)
    return _trajectory(p, np.array(rows).reshape(-1, 8))


def _trajectory(p: Path, a: NDArray[np.float64]) -> ScannerPath:
    if a.shape[0] < 2:
        raise InputError("a trajectory needs at least two poses", path=p)
    t = a[:, 0]
    if np.any(np.diff(t) <= 0):
        bad = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 2
        raise InputError(f"times must increase (pose {bad} does not)", path=p)
    qx, qy, qz, qw = a[:, 4], a[:, 5], a[:, 6], a[:, 7]
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy**2 + qz**2))
    return ScannerPath(t, a[:, 1:4].copy(), np.unwrap(yaw), p)


def _read_track_csv(p: Path, lines: list[str]) -> ScannerPath:
    import csv

    reader = csv.DictReader(lines)
    rows = []
    for no, row in enumerate(reader, 2):
        try:
            t = int(row["stamp_ns"]) * 1e-9
            e, n, az = float(row["easting"]), float(row["northing"]), float(row["azimuth_deg"])
            z = float(row.get("elevation_m") or 0.0)  # a 3D run's trajectory has it
        except (KeyError, TypeError, ValueError):
            raise InputError(
                "a track trajectory row needs stamp_ns, easting, northing, azimuth_deg",
                path=p,
                line=no,
            ) from None
        rows.append([t, e, n, z, *yaw_quaternion(yaw_of_azimuth(math.radians(az)))])
    return _trajectory(p, np.array(rows).reshape(-1, 8))


def rotation_quaternion(R: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """``(qx, qy, qz, qw)`` of a rotation matrix, unit and with ``qw >= 0`` (Shepperd's
    method: the largest of the four squares taken first, so no component is found from
    a small difference)."""
    m = np.asarray(R, dtype=float)
    tr = float(m[0, 0] + m[1, 1] + m[2, 2])
    squares = (tr, float(m[0, 0]), float(m[1, 1]), float(m[2, 2]))
    k = int(np.argmax(squares))
    if k == 0:
        s = math.sqrt(1.0 + tr) * 2
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4)
    elif k == 1:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = (s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif k == 2:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s)
    v = np.array(q, dtype=float)
    v /= np.linalg.norm(v)
    if v[3] < 0:
        v = -v
    return float(v[0]), float(v[1]), float(v[2]), float(v[3])


def write_trajectory3d_csv(path: str | Path, placed: Iterable[Placed3D]) -> int:
    """Write a 3D run's ``trajectory.csv`` (:data:`TRAJECTORY3D_HEADER`): the 2D columns
    (``source`` ``fix``: a 3D run places only its fixes), then the elevation, roll and
    pitch in degrees and their sigmas, numbers as :func:`write_trajectory_csv` writes
    them; an elevation not observed has an empty ``sigma_elevation_m``. Returns the
    rows written."""

    def rows() -> Iterator[str]:
        yield TRAJECTORY3D_HEADER
        for p in placed:
            s = p.sigma
            pose = p.pose
            yield ",".join(
                (
                    str(int(p.stamp_ns)),
                    _num(pose.easting),
                    _num(pose.northing),
                    _num(math.degrees(pose.azimuth) % 360.0),
                    _num(s[0]),
                    _num(s[1]),
                    _num(math.degrees(s[5])),
                    "fix",
                    _num(pose.elevation),
                    _num(math.degrees(pose.roll)),
                    _num(math.degrees(pose.pitch)),
                    _num(s[2]) if math.isfinite(s[2]) else "",
                    _num(math.degrees(s[3])),
                    _num(math.degrees(s[4])),
                )
            )

    return write_lines(path, rows())


def write_trajectory3d_tum(path: str | Path, placed: Iterable[Placed3D]) -> int:
    """Write a 3D run's ``trajectory.tum``: ``t x y z qx qy qz qw`` as
    :func:`write_trajectory_tum` writes them, with ``z`` the elevation and the full
    sensor-to-grid rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)``, ``yaw = 90° − azimuth``
    (:mod:`mast.core.pose3d`), as a unit quaternion with ``qw >= 0``
    (:func:`rotation_quaternion`). Returns the poses written."""

    def rows() -> Iterator[str]:
        yield TUM3D_HEADER
        for p in placed:
            pose = p.pose
            qx, qy, qz, qw = rotation_quaternion(pose.rotation)
            yield " ".join(
                (
                    _seconds(p.stamp_ns),
                    _num(pose.easting),
                    _num(pose.northing),
                    _num(pose.elevation),
                    _num(qx),
                    _num(qy),
                    _num(qz),
                    _num(qw),
                )
            )

    return write_lines(path, rows())
