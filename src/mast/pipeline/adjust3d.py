"""The six parameters of a 3D sensor's pose from the returns on surveyed beacon panels.

Each panel is a vertical rectangle; in plan it is the segment between two surveyed
edges, and its top is at the elevation the survey gives (DESIGN.md: an edge's
elevation is its top end). Two kinds of evidence, each from the frame alone:

* **Panel points** (easting, northing, azimuth, pitch, roll). A return on panel k,
  moved into the grid by the pose, lies in the panel's vertical plane
  ``n_k · X = d_k``: its residual is ``n_k · (R p + t) - d_k``. A tilt about the
  panel's horizontal axis moves its returns off the plane in proportion to their
  height, so panels of different directions (the deflection angles, two beacons)
  observe pitch and roll. The elevation does not enter (the plane is vertical).
  Gauss-Newton with analytic derivatives of ``R = Rz(yaw) Ry(pitch) Rx(roll)``; each
  return weighed by its range sigma projected on the panel's normal; the survey's
  sigma, shared by every return of a panel, is propagated into the covariance after
  (as in 2D, :func:`mast.pipeline.adjustment.survey_covariance`).
* **Top edges** (elevation). Every ray that crosses a panel's plane inside its plan
  extent either hit the panel (it crossed below the top) or went over it (it
  crossed above: its return lies beyond the plane). With the tilt known, each
  crossing's height relative to the sensor is known, so the sensor's elevation ``Z``
  is bracketed: ``h_k - Z`` is at least the highest hit and below the lowest
  crossing over, on every panel. The estimate is the middle of the tightest bracket
  and its sigma that of a uniform over it (width / sqrt 12), widened by the height
  noise of the returns that set its ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.frames import yaw_of_azimuth
from mast.core.pose import normalize_azimuth
from mast.core.pose3d import Pose3D, rotation_rpy
from mast.core.quantiles import chi2_sf
from mast.core.stats import w_critical

__all__ = ["Adjustment3D", "PanelPlanes", "adjust_pose"]

#: Order of the parameters in :attr:`Adjustment3D.covariance` (as the record names them).
PARAMETERS = ("easting_m", "northing_m", "elevation_m", "roll_rad", "pitch_rad", "azimuth_rad")
#: Variance of the elevation when no top edge brackets it: not observed (m²).
UNBRACKETED = 1e6


@dataclass(frozen=True, slots=True)
class PanelPlanes:
    """Every surveyed panel as a vertical plane, in survey order.

    ``normal`` (k, 2) unit horizontal normals and ``offset`` (k,) with ``n · X = d``
    on the plane; ``start`` (k, 2) and ``along`` (k, 2) the first edge and the unit
    direction to the second, ``length`` (k,); ``top`` (k,) the top's elevation
    (NaN where the survey has none); ``beacon`` and ``panel`` (1..3) name them."""

    normal: NDArray[np.float64]
    offset: NDArray[np.float64]
    start: NDArray[np.float64]
    along: NDArray[np.float64]
    length: NDArray[np.float64]
    top: NDArray[np.float64]
    beacon: tuple[str, ...]
    panel: tuple[int, ...]
    wall_sine: NDArray[np.float64]
    """(k, 2): at each end of a panel, the sine of its angle to the beacon's chord e1-e4
    (the wall's direction) where that end is the beacon's free end (e1 of P1, e4 of
    P3); 1 elsewhere. Near a wall end the wall above and below a panel is within a
    gate of its plane for gate / sine: those returns are not the panel's."""

    @classmethod
    def of(cls, survey: Survey) -> PanelPlanes:
        starts, alongs, lengths, tops, ids, panels, sines = [], [], [], [], [], [], []
        for b in survey:
            chord = b.edges[3] - b.edges[0]
            chord = chord / np.hypot(*chord)
            for k in range(3):
                a, c = b.edges[k], b.edges[k + 1]
                u = c - a
                length = float(np.hypot(*u))
                sine = abs(float(u[0] * chord[1] - u[1] * chord[0])) / length
                sines.append((sine if k == 0 else 1.0, sine if k == 2 else 1.0))
                starts.append(a)
                alongs.append(u / length)
                lengths.append(length)
                z = b.elevations
                tops.append(np.nan if z is None else 0.5 * float(z[k] + z[k + 1]))
                ids.append(b.id)
                panels.append(k + 1)
        start = np.array(starts, dtype=float).reshape(-1, 2)
        along = np.array(alongs, dtype=float).reshape(-1, 2)
        normal = np.stack([along[:, 1], -along[:, 0]], axis=1)
        return cls(
            normal=normal,
            offset=np.einsum("ij,ij->i", normal, start),
            start=start,
            along=along,
            length=np.array(lengths),
            top=np.array(tops),
            beacon=tuple(ids),
            panel=tuple(panels),
            wall_sine=np.array(sines, dtype=float).reshape(-1, 2),
        )

    def crossing(
        self, k: int, origin: NDArray[np.float64], rel: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Where the rays from ``origin`` to ``origin + rel`` (n, 3) cross panel ``k``'s
        plane: how far along each ray (1 at its return), how far along the panel from
        its first edge, and at what elevation."""
        n = self.normal[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (self.offset[k] - origin[:2] @ n) / (rel[:, :2] @ n)
        cross = origin + s[:, None] * rel
        return s, (cross[:, :2] - self.start[k]) @ self.along[k], cross[:, 2]

    def assign(
        self,
        grid: NDArray[np.float64],
        origin: NDArray[np.float64],
        gate_m: float,
        *,
        top_margin_m: float = math.inf,
        clear_m: float | None = None,
        bottoms: NDArray[np.float64] | None = None,
    ) -> NDArray[np.intp]:
        """The panel each grid point (n, 3), seen from the sensor at ``origin``, lies
        on, or -1: within ``gate_m`` of its plane along its ray; the ray crossing it
        inside the panel's plan extent (kept clear of the wall at a free end by
        ``clear_m``, twice the gate unless given, over :attr:`wall_sine`, and by it at
        a joint), not above its top by more than ``top_margin_m`` where the top is
        known, and not below ``bottoms`` (per panel, where given: the survey has no
        bottom edge, the data do); within the gate of no other panel. Where the ray
        crosses, not where the return lies: a return's range noise moves it along its
        ray, and choosing by its own place would keep, near an end, those whose noise
        pointed one way."""
        clear = 2.0 * gate_m if clear_m is None else clear_m
        o = np.asarray(origin, dtype=float).reshape(3)
        rel = grid - o
        reach = np.linalg.norm(rel, axis=1)
        which = np.full(len(grid), -1, dtype=np.intp)
        best = np.full(len(grid), gate_m)
        claims = np.zeros(len(grid), dtype=np.intp)
        for k in range(len(self)):
            s, t, z = self.crossing(k, o, rel)
            # how far along its ray the return lies from the plane: its range error,
            # were it on the panel (a gate on it keeps both signs of the noise alike)
            off = np.abs(1.0 - s) * reach
            lo = clear / max(float(self.wall_sine[k, 0]), 0.2)
            hi = self.length[k] - clear / max(float(self.wall_sine[k, 1]), 0.2)
            on = (off < gate_m) & (t > lo) & (t < hi) & (s > 0)
            if math.isfinite(self.top[k]) and math.isfinite(top_margin_m):
                on &= z <= self.top[k] + top_margin_m
            if bottoms is not None and math.isfinite(bottoms[k]):
                on &= z >= bottoms[k]
            claims += on
            closer = on & (off < best)
            which[closer], best[closer] = k, off[closer]
        which[claims > 1] = -1  # near a joint, within the gate of two panels: neither's
        return which

    def __len__(self) -> int:
        return len(self.beacon)

    def bottoms(
        self,
        grid: NDArray[np.float64],
        origin: NDArray[np.float64],
        which: NDArray[np.intp],
        margin_m: float,
    ) -> NDArray[np.float64]:
        """Each panel's bottom as its returns show it: the lowest crossing of the middle
        half of the panel (where no wall is near its plane) less ``margin_m``; NaN for a
        panel without returns there. Near a free end the wall below a panel is within
        the gate of its plane; below this it is not taken for the panel."""
        o = np.asarray(origin, dtype=float).reshape(3)
        out = np.full(len(self), np.nan)
        for k in np.unique(which[which >= 0]):
            mine = grid[which == k]
            t = (mine[:, :2] - self.start[k]) @ self.along[k]
            mid = np.abs(t - self.length[k] / 2) < self.length[k] / 4
            if mid.any():
                _, _, z = self.crossing(k, o, mine[mid] - o)
                out[k] = float(z.min()) - margin_m
        return out


@dataclass(frozen=True, slots=True)
class Adjustment3D:
    """A 3D pose adjusted on panel returns and bracketed by top edges.

    ``covariance`` is 6×6 in :data:`PARAMETERS` order (metres and radians); the
    elevation's variance is :data:`UNBRACKETED` where no top edge bracketed it."""

    pose: Pose3D
    covariance: NDArray[np.float64]
    reference_variance: float
    dof: int
    test_p: float
    """The global test's p-value (the chance of a reference variance this far above 1)."""
    returns: int
    iterations: int
    top_edges: int
    """Panels whose top edge bracketed the elevation (none: its variance is
    :data:`UNBRACKETED`)."""


def _derivatives(roll: float, pitch: float, yaw: float) -> tuple[NDArray[np.float64], ...]:
    """R and its derivatives by roll, pitch and yaw."""
    Kx = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    Ky = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    Kz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    Rz, Ry, Rx = (
        rotation_rpy(0.0, 0.0, yaw),
        rotation_rpy(0.0, pitch, 0.0),
        rotation_rpy(roll, 0.0, 0.0),
    )
    return Rz @ Ry @ Rx, Rz @ Ry @ Rx @ Kx, Rz @ Ry @ Ky @ Rx, Kz @ Rz @ Ry @ Rx


def _top_edges(
    grid: NDArray[np.float64],
    rel: NDArray[np.float64],
    which: NDArray[np.intp],
    origin: NDArray[np.float64],
    planes: PanelPlanes,
    gate_m: float,
    inset_m: float = 0.02,
) -> list[tuple[int, int, int, float]]:
    """For each panel with a top, both hit and passed over inside its plan extent: the
    panel, its highest hit, its lowest crossing over and where along that ray (0..1)
    the crossing is. ``grid`` the returns in the grid, ``rel`` the same relative to the
    sensor origin ``origin``."""
    found = []
    for k in range(len(planes)):
        if not math.isfinite(planes.top[k]):
            continue
        on = np.flatnonzero(which == k)
        if on.size == 0:
            continue
        n, d = planes.normal[k], planes.offset[k]
        across = grid[:, :2] @ n - d
        side = float(origin[:2] @ n - d)
        s, t, _ = planes.crossing(k, origin, rel)  # s: where each ray crosses, 0..1
        over = (s > 0) & (s < 1) & (t > inset_m) & (t < planes.length[k] - inset_m)
        over &= (across * side < 0) & (np.abs(across) >= gate_m) & (rel[:, 2] > 0)
        if not over.any():
            continue
        above = np.flatnonzero(over)
        b = int(above[np.argmin(s[above] * rel[above, 2])])
        a = int(on[np.argmax(rel[on, 2])])
        found.append((k, a, b, float(s[b])))
    return found


@dataclass(slots=True)
class _Solved:
    x: NDArray[np.float64]  # (E, N, A, pitch, roll, Z)
    J: NDArray[np.float64]
    W: NDArray[np.float64]
    v: NDArray[np.float64]
    N: NDArray[np.float64]
    n_points: int
    tops: int
    iterations: int


def _solve(
    p: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    x0: NDArray[np.float64],
    range_sigma_m: float,
    survey_sigma_m: float,
    gate_m: float,
    iterations: int,
) -> _Solved:
    """Gauss-Newton over (E, N, A, pitch, roll, Z) (see :func:`adjust_pose`)."""
    mine = which >= 0
    pts, k_of = p[mine], which[mine]
    n_k, d_k = planes.normal[k_of], planes.offset[k_of]
    ray = pts / np.linalg.norm(pts, axis=1)[:, None]
    x = x0.copy()
    done = 0
    while True:
        done += 1
        R, dR_roll, dR_pitch, dR_yaw = _derivatives(x[4], x[3], yaw_of_azimuth(x[2]))
        g = pts @ R.T
        v = np.einsum("ij,ij->i", n_k, g[:, :2] + x[:2]) - d_k
        J = np.zeros((len(pts), 6))
        J[:, 0], J[:, 1] = n_k[:, 0], n_k[:, 1]
        J[:, 2] = -np.einsum("ij,ij->i", n_k, (pts @ dR_yaw.T)[:, :2])  # d yaw / d A = -1
        J[:, 3] = np.einsum("ij,ij->i", n_k, (pts @ dR_pitch.T)[:, :2])
        J[:, 4] = np.einsum("ij,ij->i", n_k, (pts @ dR_roll.T)[:, :2])
        # the range noise along the ray, seen across the panel
        cos_inc = np.abs(np.einsum("ij,ij->i", n_k, (ray @ R.T)[:, :2]))
        W = 1.0 / np.maximum(range_sigma_m * cos_inc, 1e-3 * range_sigma_m) ** 2
        rel = p @ R.T
        origin = np.array([x[0], x[1], x[5]])
        tops = _top_edges(rel + origin, rel, which, origin, planes, gate_m)
        rows, vt, wt = [], [], []
        for k, a, b, sb in tops:
            za, zb = rel[a, 2], sb * rel[b, 2]
            width = abs(zb - za)
            dz = [(p[a] @ dR[2] + sb * (p[b] @ dR[2])) / 2 for dR in (dR_pitch, dR_roll)]
            rows.append([0.0, 0.0, 0.0, dz[0], dz[1], 1.0])
            vt.append(x[5] + (za + zb) / 2 - planes.top[k])
            wt.append(1.0 / (width**2 / 12.0 + range_sigma_m**2 + survey_sigma_m**2))
        if rows:
            J = np.vstack([J, rows])
            v = np.concatenate([v, vt])
            W = np.concatenate([W, wt])
        N = J.T @ (W[:, None] * J)
        if not rows:
            N[5, 5] += 1.0 / UNBRACKETED  # the elevation unobserved: kept, with no weight
        step = np.linalg.solve(N, -(J.T @ (W * v)))
        x += step
        if done >= iterations or np.all(np.abs(step) < [1e-7, 1e-7, 1e-9, 1e-9, 1e-9, 1e-7]):
            return _Solved(x, J, W, v, N, len(pts), len(tops), done)


def adjust_pose(
    points: NDArray[np.float64],
    which: NDArray[np.intp],
    planes: PanelPlanes,
    start: Pose3D,
    *,
    range_sigma_m: float,
    survey_sigma_m: float,
    gate_m: float,
    iterations: int = 12,
    snooping_rounds: int = 6,
) -> Adjustment3D:
    """All six parameters from a frame's returns ``points`` (sensor frame, (n, 3)), those
    on panels named by ``which`` (indices into ``planes``, -1 for none), from ``start``
    (see the module). The top edges enter as one observation each of the sensor's
    elevation: the middle of the panel's bracket, with the variance of a uniform over
    it, its derivatives by pitch and roll those of the two returns that set it.

    Returns that are not the panel's (the wall just above, below or beside one, within
    the gate of its plane) are found by data snooping: Baarda's w-test on each
    panel return's standardised residual, those beyond the critical value of the
    largest of n left out, and the adjustment run again."""
    p = np.asarray(points, dtype=float)
    which = np.asarray(which, dtype=np.intp).copy()
    x = np.array(
        [start.easting, start.northing, start.azimuth, start.pitch, start.roll, start.elevation]
    )
    solved = _solve(p, which, planes, x, range_sigma_m, survey_sigma_m, gate_m, iterations)
    for _ in range(snooping_rounds):
        n = solved.n_points
        Q = np.linalg.inv(solved.N)
        Jp, Wp = solved.J[:n], solved.W[:n]
        leverage = np.einsum("ij,jk,ik->i", Jp, Q, Jp) * Wp
        w = solved.v[:n] * np.sqrt(Wp) / np.sqrt(np.maximum(1.0 - leverage, 1e-9))
        bad = np.abs(w) > w_critical(n)
        if not bad.any():
            break
        which[np.flatnonzero(which >= 0)[bad]] = -1
        solved = _solve(
            p, which, planes, solved.x, range_sigma_m, survey_sigma_m, gate_m, iterations
        )
    x, J, W, v, n_points = solved.x, solved.J, solved.W, solved.v, solved.n_points
    k_of = which[which >= 0]
    Q = np.linalg.inv(solved.N)
    dof = n_points - 5
    s0 = float(W[:n_points] @ (v[:n_points] ** 2)) / dof if dof > 0 else math.nan
    # The survey's error is one offset per panel, shared by all its returns.
    G = Q @ (J.T * W)
    cov = Q.copy()
    for k in np.unique(k_of):
        g = G[:, :n_points][:, k_of == k].sum(axis=1)
        cov += survey_sigma_m**2 * np.outer(g, g)
    # (E, N, A, pitch, roll, Z) → (E, N, Z, roll, pitch, A)
    order = [0, 1, 5, 4, 3, 2]
    pose = Pose3D(x[0], x[1], x[5], normalize_azimuth(x[2]), x[3], x[4])
    return Adjustment3D(
        pose=pose,
        covariance=np.asarray(cov[np.ix_(order, order)], dtype=np.float64),
        reference_variance=s0,
        dof=dof,
        test_p=float(chi2_sf(s0 * dof, dof)) if dof > 0 else 1.0,
        returns=n_points,
        iterations=solved.iterations,
        top_edges=solved.tops,
    )
