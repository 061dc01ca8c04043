"""A run, scan by scan: each located near where odometry says the scanner is, the
motion between scans measured, then fixes and motions smoothed in a pose graph.

:class:`RunTracker` is the streaming half (one scan in, one :class:`Step` out,
memory independent of the run's length); :func:`smooth` places every scan
chained by odometry to at least one fix, with GTSAM (Dellaert and Kaess,
*Factor Graphs for Robot Perception*, 2017): a fix is a prior factor with its
own covariance, a motion a between factor with its own, both behind a Huber
kernel so that one bad factor cannot drag the run; each placed scan gets its
marginal covariance.

Frames: GTSAM's ``Pose2(x, y, theta)`` is (easting, northing, 90° − azimuth);
its covariances live in the pose's own (body) frame, and are turned to and
from (easting, northing, azimuth) covariances by ``J = diag(R(theta), -1)``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.frames import azimuth_of_yaw, body_jacobian, yaw_of_azimuth
from mast.core.pose import Pose2D
from mast.core.posegraph import solve
from mast.core.scan import Scan
from mast.core.trajectory import PlacedScan
from mast.pipeline.locator import Fix, Locator, LocatorConfig
from mast.pipeline.tracking import Prior, VehicleLimits
from mast.runs.odometry import (
    Keyframe,
    Motion,
    OdometryConfig,
    keyframe,
    recover_motion,
    scan_to_scan,
)

__all__ = ["Node", "RunTracker", "Smoother", "Step", "TrackConfig", "smooth"]


#: The turn odometry's checks allow beyond the vehicle's turn rate (the scanner's jolts
#: as the motion estimate sees them), radians.
_TURN_SLACK_RAD = 0.02


@dataclass(frozen=True, slots=True)
class TrackConfig:
    """How a run is tracked and smoothed.

    Attributes
    ----------
    locator : LocatorConfig
        The one locator's settings (precisions, tests).
    odometry : OdometryConfig
    max_gap_s : float
        Scans further apart in time are not chained by odometry.
    prior_radius_m, max_prior_radius_m : float
        The search window around the predicted pose: three of its standard
        deviations, within these bounds.
    prior_azimuth_rad, max_prior_azimuth_rad : float
        The same for the azimuth.
    vehicle : VehicleLimits
        What a vehicle underground can do, and the scanner's jolts. Searched first:
        the window of three standard deviations of the prediction without the lower
        bounds above, widened by the jolts; a scan it does not fix is searched in
        the window above, then from scratch. A motion beyond the vehicle's speed and
        turn rate (ICP slid along a smooth drift, or locked onto the wrong wall) is
        searched for again over all the vehicle could have done
        (:func:`recover_motion`), and failing that replaced by the constant-velocity
        motion with the uncertainty the acceleration allows. When the scans are so
        far apart in time that the constant-velocity guess may be off by more than
        ICP's widest gate (a log that kept a scan every metre or two), every step
        is searched that way, and every scan becomes a keyframe.
    huber_k : float
        Huber kernel threshold, in standard deviations, of every factor.
    keyframe_m, keyframe_rad : float
        Scans are matched to a keyframe, not to the scan before them: odometry
        errors then add up once per keyframe (every two metres), not once
        per scan (every few centimetres at 25 Hz). A scan this far from its
        keyframe becomes the next one. (On the simulated drive of ``mast
        bench run``, dead reckoning over 50 m drifted 24 mm RMS with keyframes
        every metre, 19 mm every two metres and 32 mm every three: errors per
        keyframe against overlap lost.)
    max_search_yaw_rad : float
        Widest turn either way that search looks for.
    max_coast_m : float
        A scan whose motion can only be coasted (constant velocity), with its
        position's standard deviation then beyond this, breaks the chain; the
        run starts again at the next fix. A pose known to metres is no survey
        position, and a stretch of such motions leaves the pose graph too
        poorly posed to solve.
    """

    locator: LocatorConfig = field(default_factory=LocatorConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    max_gap_s: float = 0.5
    prior_radius_m: float = 0.5
    max_prior_radius_m: float = 1.0
    prior_azimuth_rad: float = math.radians(5.0)
    max_prior_azimuth_rad: float = math.radians(10.0)
    vehicle: VehicleLimits = field(default_factory=VehicleLimits)
    huber_k: float = 1.345
    keyframe_m: float = 2.0
    keyframe_rad: float = math.radians(5.0)
    max_search_yaw_rad: float = math.radians(45.0)
    max_coast_m: float = 1.0


@dataclass(frozen=True, slots=True)
class Step:
    """What one scan of a run gave: its fix (or no-fix) and its motion since the last scan.

    ``motion`` is the scan's pose in the frame of its keyframe ``ref`` (an
    earlier scan of the run); None when the scan is not chained to the run
    before it (a time gap, or its returns did not find the keyframe's walls).
    """

    scan: int
    stamp_ns: int
    fix: Fix
    motion: Motion | None
    ref: int | None
    predicted: Pose2D | None


def compose(
    pose: Pose2D, cov: NDArray[np.float64], motion: Motion
) -> tuple[Pose2D, NDArray[np.float64]]:
    """The pose after ``motion`` and its covariance (E, N, A), first-order propagation."""
    th = yaw_of_azimuth(pose.azimuth)
    c, s = math.cos(th), math.sin(th)
    de = c * motion.dx - s * motion.dy
    dn = s * motion.dx + c * motion.dy
    new = Pose2D(pose.easting + de, pose.northing + dn, (pose.azimuth - motion.dtheta) % math.tau)
    # d new / d old (E, N, A): the rotation of the step with the azimuth.
    jp = np.array([[1.0, 0.0, dn], [0.0, 1.0, -de], [0.0, 0.0, 1.0]])
    jm = body_jacobian(th)
    return new, jp @ cov @ jp.T + jm @ motion.covariance @ jm.T


class RunTracker:
    """Locate the scans of a run one at a time, each near its dead-reckoned pose.

    The pose is carried from the last fix by the motions between scans; the
    next scan is searched within a window of about three of its standard
    deviations (:meth:`~mast.pipeline.locator.Locator.locate`), and from scratch
    when that gives no fix. Memory does not grow with the run.
    """

    def __init__(self, survey: Survey, config: TrackConfig | None = None) -> None:
        self.survey = survey
        self.config = config or TrackConfig()
        self.locator = Locator(survey, self.config.locator)
        self._stamp: int | None = None
        # The keyframe: its scan index, lines, and pose with covariance (if placed).
        self._key: tuple[int, Keyframe] | None = None
        self._key_pose: Pose2D | None = None
        self._key_cov = np.zeros((3, 3))
        self._key_stamp = 0
        self._last: Motion | None = None
        self._velocity = (0.0, 0.0, 0.0)

    def _prior(self, pose: Pose2D, cov: NDArray[np.float64]) -> tuple[Prior, Prior]:
        """The window about the predicted pose, and the narrow one searched first."""
        cfg = self.config
        pos = float(np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2])[-1], 0.0)))
        radius = min(max(3.0 * pos, cfg.prior_radius_m), cfg.max_prior_radius_m)
        az = math.sqrt(max(cov[2, 2], 0.0))
        tol = min(max(3.0 * az, cfg.prior_azimuth_rad), cfg.max_prior_azimuth_rad)
        narrow = Prior(pose, cfg.vehicle.jolt_m + 3.0 * pos, cfg.vehicle.jolt_rad + 3.0 * az)
        return Prior(pose, radius, tol), narrow

    def step(self, index: int, scan: Scan) -> Step:
        """Locate one scan (the next of the run) and measure its motion."""
        cfg = self.config
        motion = None
        ref = None
        wide = False
        if (
            self._key is not None
            and self._stamp is not None
            and 0 <= scan.stamp_ns - self._stamp <= cfg.max_gap_s * 1e9
        ):
            ref, key = self._key
            dt = (scan.stamp_ns - self._stamp) * 1e-9
            # Constant velocity: the last scan's place in the keyframe, one more step on.
            v = self._velocity
            step = (v[0] * dt, v[1] * dt, v[2] * dt)
            last, last_cov = (0.0, 0.0, 0.0), np.zeros((3, 3))
            if self._last is not None:
                last = (self._last.dx, self._last.dy, self._last.dtheta)
                last_cov = self._last.covariance
            guess = _chain(last, step)
            since_key = (scan.stamp_ns - self._key_stamp) * 1e-9
            # How far the constant-velocity guess can be off: what the vehicle's
            # acceleration and turn rate allow since the last scan.
            reach = self._slack(dt)
            turn = min(
                cfg.vehicle.max_turn_rad_s * max(dt, 0.04) + _TURN_SLACK_RAD, cfg.max_search_yaw_rad
            )
            motion = None
            wide = reach > max(cfg.odometry.gates_m)
            if not wide:
                motion = scan_to_scan(
                    key,
                    scan,
                    guess=guess,
                    range_sigma_m=cfg.locator.range_sigma_m,
                    config=cfg.odometry,
                )
            if motion is None or not self._plausible(motion, guess, since_key):
                # Outside ICP's basin: search all the vehicle could have done since.
                motion = recover_motion(
                    key,
                    scan,
                    guess=guess,
                    radius_m=reach,
                    yaw_rad=turn,
                    range_sigma_m=cfg.locator.range_sigma_m,
                    config=cfg.odometry,
                )
            coast = self._coasting(guess, last_cov, dt)
            if motion is None or not self._plausible(motion, guess, since_key):
                motion = coast
            elif coast is not None:
                motion = _fused(motion, coast)
            if motion is not None:
                inc = _chain(_inverse(last), (motion.dx, motion.dy, motion.dtheta))
                self._velocity = (inc[0] / dt, inc[1] / dt, inc[2] / dt) if dt > 0 else v
            else:
                self._velocity = (0.0, 0.0, 0.0)
        else:
            self._velocity = (0.0, 0.0, 0.0)
        predicted, cov = None, np.zeros((3, 3))
        if motion is not None and self._key_pose is not None:
            predicted, cov = compose(self._key_pose, self._key_cov, motion)
        prior, narrow = (None, None) if predicted is None else self._prior(predicted, cov)
        fix = self.locator.locate(scan, prior, narrow=narrow)
        pose: Pose2D | None = predicted
        if fix.ok and fix.pose is not None and fix.adjustment is not None:
            pose, cov = fix.pose, fix.adjustment.covariance.copy()
        self._stamp = scan.stamp_ns
        # A new keyframe when the chain broke, the scanner moved far enough from the
        # last one, or this scan is fixed (the best-known pose to carry on from).
        if (
            motion is None
            or wide
            or fix.ok
            or math.hypot(motion.dx, motion.dy) > cfg.keyframe_m
            or abs(motion.dtheta) > cfg.keyframe_rad
        ):
            self._key = (index, keyframe(scan, cfg.odometry))
            self._key_stamp = scan.stamp_ns
            self._key_pose, self._key_cov = pose, cov
            self._last = None
        else:
            self._last = motion
        return Step(
            index, scan.stamp_ns, fix, motion, ref if motion is not None else None, predicted
        )

    def _plausible(
        self, motion: Motion, guess: tuple[float, float, float], since_key: float
    ) -> bool:
        """Whether a vehicle can have made this motion: not beyond its speed and turn
        rate, and not further from constant velocity than its acceleration allows."""
        cfg = self.config
        v = cfg.vehicle
        far = math.hypot(motion.dx, motion.dy) > v.max_speed_mps * since_key + v.jolt_m
        turned = abs(motion.dtheta) > v.max_turn_rad_s * since_key + _TURN_SLACK_RAD
        off = math.hypot(motion.dx - guess[0], motion.dy - guess[1]) > self._slack(since_key)
        return not (far or turned or off)

    def _slack(self, seconds: float) -> float:
        """How far the vehicle can stray from constant velocity in ``seconds``, metres."""
        v = self.config.vehicle
        return v.jolt_m + v.max_accel_mps2 * max(seconds, 0.04)

    def _coasting(
        self, guess: tuple[float, float, float], last_cov: NDArray[np.float64], dt: float
    ) -> Motion | None:
        """The constant-velocity motion, as uncertain as the last motion and the vehicle's
        acceleration since it make it: the run goes on through a scan whose returns did
        not find the keyframe's walls. None (the chain breaks) when that leaves the
        position less certain than ``max_coast_m``."""
        s = self._slack(dt)
        yaw = _TURN_SLACK_RAD + self.config.vehicle.max_turn_rad_s * 0.1 * max(dt, 0.04)
        cov = last_cov + np.diag([s**2, s**2, yaw**2])
        if math.sqrt(max(np.linalg.eigvalsh(cov[:2, :2])[-1], 0.0)) > self.config.max_coast_m:
            return None
        return Motion(*guess, cov, 0, math.nan)


def _fused(motion: Motion, prediction: Motion) -> Motion:
    """The measured motion combined with the vehicle's constant-velocity prediction.

    Along a smooth drift the scans do not tell how far the vehicle went; there
    the measured motion is arbitrary and its variance huge, and the prediction
    (as uncertain as the acceleration allows) is what is known. Elsewhere the
    measurement dominates and is unchanged to a fraction of its sigma. This also
    keeps a pose graph of several such motions in a row well posed.
    """
    a = np.linalg.inv(motion.covariance)
    b = np.linalg.inv(prediction.covariance)
    x = np.array([motion.dx, motion.dy, motion.dtheta])
    g = np.array([prediction.dx, prediction.dy, prediction.dtheta])
    g[2] = x[2] + math.remainder(g[2] - x[2], math.tau)
    cov = np.linalg.inv(a + b)
    mean = cov @ (a @ x + b @ g)
    return Motion(
        float(mean[0]),
        float(mean[1]),
        math.remainder(float(mean[2]), math.tau),
        (cov + cov.T) / 2,
        motion.matches,
        motion.rms_m,
    )


def _chain(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> tuple[float, float, float]:
    """Relative pose ``b`` (in ``a``'s frame) after ``a``: (dx, dy, dtheta) composition."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])


def _inverse(a: tuple[float, float, float]) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2])


@dataclass(frozen=True, slots=True)
class Node:
    """What smoothing needs of one scan (a few numbers).

    ``fix`` is the scan's pose and covariance (E, N, A) from beacons; ``carried``
    marks a prior that is not a fix but what the run before it says of the
    scan (see :class:`Smoother`).
    """

    scan: int
    stamp_ns: int
    fix: tuple[Pose2D, NDArray[np.float64]] | None
    motion: Motion | None
    ref: int | None
    carried: bool = False

    @classmethod
    def of(cls, step: Step) -> Node:
        fix = None
        if step.fix.ok and step.fix.pose is not None and step.fix.adjustment is not None:
            fix = (step.fix.pose, step.fix.adjustment.covariance.copy())
        return cls(step.scan, step.stamp_ns, fix, step.motion, step.ref)

    @property
    def fixed(self) -> bool:
        """Whether the scan was fixed from beacons."""
        return self.fix is not None and not self.carried


class Smoother:
    """Fixed-lag smoothing of a run's pose graph, in windows: memory bounded by the
    longest stretch between fixes, not by the run's length.

    Scans are pushed in time order; each comes back placed (:class:`PlacedScan`)
    once ``margin`` fixes have been seen after it, smoothed in a window that
    also holds ``margin`` fixes before it: a scan in a stretch without beacons
    is smoothed between the fixes at both of its ends, as in the whole graph
    (fixes further away change it by a small fraction of its standard
    deviation, which the tests check). A window starts at a fix (a keyframe:
    no later scan refers to a scan before it), so the scans before it can be
    dropped.

    A stretch longer than ``max_nodes`` scans without a fix is cut: its first
    half is placed from the fixes before it only (larger, honest standard
    deviations), and the scan where it was cut carries the marginal of its
    pose as a prior into the rest (no fix after it was in the window, so this
    counts nothing twice). Scans before the run's first fix wait for it, up
    to ``max_nodes``; beyond that the oldest are dropped unplaced.
    """

    def __init__(
        self,
        config: TrackConfig | None = None,
        *,
        margin: int = 20,
        batch: int = 500,
        max_nodes: int = 5000,
    ) -> None:
        if margin < 1 or batch < 1 or max_nodes < 2 * batch:
            raise ValueError("margin and batch must be positive and max_nodes >= 2 * batch")
        self.config = config or TrackConfig()
        self.margin, self.batch, self.max_nodes = margin, batch, max_nodes
        self._buf: list[Node] = []
        self._members: set[int] = set()
        self._done = 0  # nodes at the front of the buffer already placed
        self.dropped = 0  # scans dropped unplaced (no fix within max_nodes)

    def push(self, node: Node) -> list[PlacedScan]:
        """Add the run's next scan; returns the scans placed for good by it."""
        out: list[PlacedScan] = []
        if self._buf and not (node.motion is not None and node.ref in self._members):
            out = self.finish()
        self._buf.append(node)
        self._members.add(node.scan)
        if node.fixed:
            fixes = [i for i, n in enumerate(self._buf) if n.fixed]
            if len(fixes) >= self.margin and fixes[-self.margin] - self._done >= self.batch:
                out += self._advance(fixes[-self.margin])
        if len(self._buf) > self.max_nodes:
            out += self._cut()
        return out

    def finish(self) -> list[PlacedScan]:
        """Place what is left (the end of a chain, or of the run)."""
        out: list[PlacedScan] = []
        if any(n.fix is not None for n in self._buf):
            out = self._solve(self._buf)[self._done :]
        self._buf, self._members, self._done = [], set(), 0
        return out

    def _advance(self, end: int) -> list[PlacedScan]:
        """Place the buffer's nodes up to ``end`` and drop what no later window needs."""
        out = self._solve(self._buf)[self._done : end]
        before = [i for i, n in enumerate(self._buf[:end]) if n.fixed]
        start = before[-self.margin] if len(before) >= self.margin else 0
        self._trim(self._cut_point(start), end)
        return out

    def _cut(self) -> list[PlacedScan]:
        """The buffer is full: place its older half with what is known now."""
        buf = self._buf
        end = len(buf) - self.max_nodes // 2
        start = self._cut_point(end)
        fixes = [i for i, n in enumerate(buf) if n.fix is not None]
        if not fixes:
            self.dropped += start
            self._trim(start, max(end, start))
            return []
        out = self._solve(buf)[self._done : end]
        if any(i <= start for i in fixes):
            # The marginal of the scan where the window now starts, from everything
            # before it (and no fix after it, which stays in the window).
            after = [i for i in fixes if i > start]
            p = self._solve(buf[: after[0]] if after else buf)[start]
            buf[start] = replace(
                buf[start], fix=(p.pose, p.covariance), carried=not buf[start].fixed
            )
        self._trim(start, end)
        return out

    def _cut_point(self, limit: int) -> int:
        """The last index up to ``limit`` that no later scan of the buffer refers before."""
        pos = {n.scan: i for i, n in enumerate(self._buf)}
        lowest = len(self._buf)
        best = 0
        for i in range(len(self._buf) - 1, -1, -1):
            if i <= limit and lowest >= i:
                best = i
                break
            ref = self._buf[i].ref
            if ref is not None and self._buf[i].motion is not None:
                lowest = min(lowest, pos.get(ref, 0))
        return best

    def _trim(self, start: int, end: int) -> None:
        self._buf = self._buf[start:]
        self._members = {n.scan for n in self._buf}
        self._done = max(end - start, 0)

    def _solve(self, window: Sequence[Node]) -> list[PlacedScan]:
        """Smooth one window (a chain starting at a fix or at the chain's start)."""
        import gtsam

        if not any(n.fix is not None for n in window):
            raise RuntimeError("a window without a fix cannot be placed")
        huber = gtsam.noiseModel.mEstimator.Huber.Create(self.config.huber_k)

        def robust(cov: NDArray[np.float64], *, kernel: bool = True) -> gtsam.noiseModel.Base:
            gauss = gtsam.noiseModel.Gaussian.Covariance((cov + cov.T) / 2)
            return gtsam.noiseModel.Robust.Create(huber, gauss) if kernel else gauss

        graph = gtsam.NonlinearFactorGraph()
        # Dead reckoning in the window's own frame (its first scan at the origin) ...
        local: dict[int, gtsam.Pose2] = {}
        for n in window:
            if n.motion is None or n.ref is None or n.ref not in local:
                local[n.scan] = gtsam.Pose2()
                continue
            m = n.motion
            local[n.scan] = local[n.ref].compose(gtsam.Pose2(m.dx, m.dy, m.dtheta))
            # The motion's covariance is in the keyframe's frame; GTSAM's error of a
            # between factor lives in the frame of the relative pose itself.
            jm = np.eye(3)
            jm[:2, :2] = body_jacobian(m.dtheta)[:2, :2].T
            graph.add(
                gtsam.BetweenFactorPose2(
                    n.ref,
                    n.scan,
                    gtsam.Pose2(m.dx, m.dy, m.dtheta),
                    robust(jm @ m.covariance @ jm.T),
                )
            )
        anchor = None
        for n in window:
            if n.fix is not None:
                pose, cov = n.fix
                th = yaw_of_azimuth(pose.azimuth)
                jinv = np.linalg.inv(body_jacobian(th))
                graph.add(
                    gtsam.PriorFactorPose2(
                        n.scan,
                        gtsam.Pose2(pose.easting, pose.northing, th),
                        # What the run before a cut said is no measurement that can
                        # be an outlier: its marginal, as it is.
                        robust(jinv @ cov @ jinv.T, kernel=not n.carried),
                    )
                )
                anchor = anchor or n
        # ... moved onto the first fix: the optimiser's starting point.
        assert anchor is not None
        assert anchor.fix is not None
        p0 = anchor.fix[0]
        to_mine = gtsam.Pose2(p0.easting, p0.northing, yaw_of_azimuth(p0.azimuth)).compose(
            local[anchor.scan].inverse()
        )
        values = gtsam.Values()
        for n in window:
            values.insert(n.scan, to_mine.compose(local[n.scan]))
        result = solve(graph, values)
        marginals = gtsam.Marginals(graph, result)
        placed = []
        for n in window:
            p = result.atPose2(n.scan)
            j = body_jacobian(p.theta())
            cov = j @ marginals.marginalCovariance(n.scan) @ j.T
            placed.append(
                PlacedScan(
                    n.scan,
                    n.stamp_ns,
                    Pose2D(p.x(), p.y(), azimuth_of_yaw(p.theta())),
                    (cov + cov.T) / 2,
                    "fix" if n.fixed else "odometry",
                )
            )
        return placed


def smooth(nodes: Iterable[Node], config: TrackConfig | None = None) -> list[PlacedScan]:
    """Every scan chained by odometry to a fix, placed by the smoothed pose graph
    (:class:`Smoother`); scans of a chain without any fix are left out."""
    smoother = Smoother(config)
    placed: list[PlacedScan] = []
    for n in nodes:
        placed += smoother.push(n)
    return placed + smoother.finish()
