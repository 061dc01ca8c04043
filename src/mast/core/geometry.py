"""Plane geometry shared by the locator and the simulator: rays against segments,
points against panels."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey

__all__ = ["CHUNK_ELEMENTS", "PanelSet", "first_hits"]

#: Rays x segments (or points x panels) that one step of the geometry tests holds at
#: once: each of their temporaries stays at a couple of megabytes however many beams
#: a scan has and however many panels a survey has (results do not depend on it).
CHUNK_ELEMENTS = 1 << 18


def first_hits(
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Distance along each ray to the first segment it crosses.

    Parameters
    ----------
    origin : ndarray, shape (2,)
    directions : ndarray, shape (n, 2)
        Unit ray directions.
    seg_a, seg_b : ndarray, shape (m, 2)
        Segment end points.

    Returns
    -------
    t : ndarray, shape (n,)
        Distance to the first crossing, ``inf`` for none.
    index : ndarray of int, shape (n,)
        Index of the segment crossed first, -1 for none.

    Compiled (:func:`mast.core._kernels.first_hits`, no (rays x segments)
    arrays); :func:`_first_hits_reference` is the same in numpy.
    """
    from mast.core._kernels import first_hits as kernel

    def flat(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.ascontiguousarray(v, dtype=float).reshape(-1, 2)

    return kernel(  # type: ignore[no-any-return]
        np.ascontiguousarray(origin, dtype=float).reshape(2),
        flat(directions),
        flat(seg_a),
        flat(seg_b),
    )


def _first_hits_reference(
    origin: NDArray[np.float64],
    directions: NDArray[np.float64],
    seg_a: NDArray[np.float64],
    seg_b: NDArray[np.float64],
    *,
    chunk_elements: int = CHUNK_ELEMENTS,
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """:func:`first_hits` in numpy, in chunks of ``chunk_elements`` (the tests compare)."""
    n = directions.shape[0]
    best = np.full(n, np.inf)
    which = np.full(n, -1, dtype=np.intp)
    m = seg_a.shape[0]
    if m == 0 or n == 0:
        return best, which
    e = seg_b - seg_a
    w = seg_a - origin
    # o + t d = a + s e:  t = (w x e) / (d x e),  s = (w x d) / (d x e)
    w_x_e = w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]
    step = max(1, chunk_elements // m)
    for lo in range(0, n, step):
        d = directions[lo : lo + step]
        den = d[:, :1] * e[None, :, 1] - d[:, 1:] * e[None, :, 0]
        w_x_d = w[None, :, 0] * d[:, 1:] - w[None, :, 1] * d[:, :1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = w_x_e[None, :] / den
            s = w_x_d / den
        ok = (den != 0) & (t > 1e-12) & (s >= 0.0) & (s <= 1.0)
        t = np.where(ok, t, np.inf)
        j = np.argmin(t, axis=1)
        tj = t[np.arange(t.shape[0]), j]
        hit = np.isfinite(tj)
        best[lo : lo + step] = tj
        which[lo : lo + step] = np.where(hit, j, -1)
    return best, which


#: Surveys with more panels than this are searched for the panels near a point in a tree.
_NEAR_SCAN_PANELS = 256


@dataclass(frozen=True, eq=False)
class PanelSet:
    """Every surveyed panel of a survey as arrays, mine frame.

    Attributes
    ----------
    a, b : ndarray, shape (k, 2)
        Panel end points (edges ``e_j`` and ``e_j+1``).
    direction, normal : ndarray, shape (k, 2)
    length : ndarray, shape (k,)
    beacon : ndarray of int, shape (k,)
        Index of the beacon in ``ids``.
    panel : ndarray of int, shape (k,)
        Panel number 1..3.
    ids : tuple of str
    edge_sigma_m : ndarray, shape (k, 2), optional
        The survey's standard deviation of each panel's two edges (``sigma_m``), NaN
        where the survey leaves it out; None when it gives none.
    """

    a: NDArray[np.float64]
    b: NDArray[np.float64]
    direction: NDArray[np.float64]
    normal: NDArray[np.float64]
    length: NDArray[np.float64]
    beacon: NDArray[np.intp]
    panel: NDArray[np.intp]
    ids: tuple[str, ...]
    edge_sigma_m: NDArray[np.float64] | None = None

    @classmethod
    def from_survey(cls, survey: Survey) -> PanelSet:
        a, b, bi, pi, sig = [], [], [], [], []
        for k, beacon in enumerate(survey):
            s = beacon.edge_sigmas_m
            for j in range(3):
                a.append(beacon.edges[j])
                b.append(beacon.edges[j + 1])
                bi.append(k)
                pi.append(j + 1)
                sig.append((math.nan, math.nan) if s is None else (s[j], s[j + 1]))
        given = any(b.edge_sigmas_m is not None for b in survey)
        aa = np.array(a, dtype=float).reshape(-1, 2)
        bb = np.array(b, dtype=float).reshape(-1, 2)
        v = bb - aa
        length = np.hypot(v[:, 0], v[:, 1])
        d = v / length[:, None]
        nrm = np.stack([-d[:, 1], d[:, 0]], axis=1)
        return cls(
            aa,
            bb,
            d,
            nrm,
            length,
            np.array(bi, dtype=np.intp),
            np.array(pi, dtype=np.intp),
            tuple(survey.ids),
            np.array(sig, dtype=float).reshape(-1, 2) if given else None,
        )

    def __len__(self) -> int:
        return int(self.length.size)

    def survey_variance(self, sigma_m: float) -> NDArray[np.float64]:
        """Each panel's surveyed position variance across its face, metres squared:
        the mean of its two edges' variances, each edge's from the survey's ``sigma_m``
        where it gives one, else ``sigma_m`` (the one ``--survey-sigma`` for all).

        A panel whose edges are off by ``d_a`` and ``d_b`` is off by
        ``(1 - t) d_a + t d_b`` across its face at ``t`` along it: a variance between
        a quarter of their sum (its middle) and either edge's (its ends), and a turn.
        The mean of the two is taken as one shift of the whole panel, as one
        ``sigma_m`` for every edge always has been: a conservative stand-in (on
        simulated scans with every edge's survey error drawn, the fixes' 95 %
        intervals held 99 % of them)."""
        key = float(sigma_m)
        memo = self._survey_variances
        hit = memo.get(key)
        if hit is None:
            s2 = key**2  # as the one survey variance was formed before (pow, not x * x)
            if self.edge_sigma_m is None:
                hit = np.full(len(self), s2)
            else:
                v = np.where(np.isnan(self.edge_sigma_m), s2, self.edge_sigma_m**2)
                hit = 0.5 * (v[:, 0] + v[:, 1])
            hit.setflags(write=False)
            memo[key] = hit
        return hit

    def worst_survey_sigma(self, sigma_m: float) -> float:
        """The largest standard deviation of any edge (``sigma_m`` for those the survey
        leaves without one): the tolerance of tests made before it is known which panel
        a return is on."""
        if self.edge_sigma_m is None:
            return float(sigma_m)
        given = self.edge_sigma_m[~np.isnan(self.edge_sigma_m)]
        worst = float(given.max()) if given.size else float(sigma_m)
        return worst if given.size == self.edge_sigma_m.size else max(worst, float(sigma_m))

    @functools.cached_property
    def _survey_variances(self) -> dict[float, NDArray[np.float64]]:
        return {}

    @functools.cached_property
    def _mid(self) -> NDArray[np.float64]:
        return 0.5 * (self.a + self.b)

    @functools.cached_property
    def number(self) -> dict[str, int]:
        """Position of each beacon id in :attr:`ids` (the value in :attr:`beacon`)."""
        return {bid: k for k, bid in enumerate(self.ids)}

    @functools.cached_property
    def _mid_tree(self) -> Any:  # a scipy cKDTree (scipy is imported only when needed)
        from scipy.spatial import cKDTree

        return cKDTree(self._mid)

    def near(self, position: NDArray[np.float64], radius_m: float) -> NDArray[np.intp]:
        """Indices of the panels any part of which lies within ``radius_m`` of ``position``,
        in order. A whole mine's survey is searched in a k-d tree of the panels' middles."""
        mid = self._mid
        if len(self) > _NEAR_SCAN_PANELS:
            half = 0.5 * float(self.length.max())
            ball = self._mid_tree.query_ball_point(np.asarray(position), radius_m + half)
            found: NDArray[np.intp] = np.sort(np.asarray(ball, dtype=np.intp))
            d = np.hypot(mid[found, 0] - position[0], mid[found, 1] - position[1])
            within: NDArray[np.intp] = found[d <= radius_m + 0.5 * self.length[found]]
            return within
        d = np.hypot(mid[:, 0] - position[0], mid[:, 1] - position[1])
        return np.flatnonzero(d <= radius_m + 0.5 * self.length)

    def near_many(self, positions: NDArray[np.float64], radius_m: float) -> list[NDArray[np.intp]]:
        """:meth:`near` of each of ``positions`` (shape (k, 2)), the same panels in the
        same order, looked up together: one query of the k-d tree for all of them."""
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        if pos.shape[0] == 0:
            return []
        mid = self._mid
        if len(self) <= _NEAR_SCAN_PANELS:
            d = np.hypot(mid[None, :, 0] - pos[:, 0, None], mid[None, :, 1] - pos[:, 1, None])
            close = d <= radius_m + 0.5 * self.length[None, :]
            return [np.flatnonzero(row) for row in close]
        half = 0.5 * float(self.length.max())
        balls = self._mid_tree.query_ball_point(pos, radius_m + half)
        sizes = np.array([len(b) for b in balls], dtype=np.intp)
        found = np.fromiter(
            (k for ball in balls for k in ball), dtype=np.intp, count=int(sizes.sum())
        )
        owner = np.repeat(np.arange(pos.shape[0]), sizes)
        d = np.hypot(mid[found, 0] - pos[owner, 0], mid[found, 1] - pos[owner, 1])
        keep = d <= radius_m + 0.5 * self.length[found]
        # By position, then panel: each position's panels in increasing order.
        order = np.lexsort((found, owner))
        found, owner, keep = found[order], owner[order], keep[order]
        ends = np.cumsum(sizes)
        return [
            chunk[inside]
            for chunk, inside in zip(
                np.split(found, ends[:-1]), np.split(keep, ends[:-1]), strict=True
            )
        ]

    def project(
        self, points_mine: NDArray[np.float64], panels: NDArray[np.intp]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Each point in each panel's frame: distance along it from ``a`` and across it.

        Returns ``(t, s)``, both of shape ``(points, panels)``; ``s`` is signed
        along the panel's normal.
        """
        rel = points_mine[:, None, :] - self.a[None, panels, :]
        t = np.einsum("nkj,kj->nk", rel, self.direction[panels])
        s = np.einsum("nkj,kj->nk", rel, self.normal[panels])
        return t, s

    def within(
        self,
        points_mine: NDArray[np.float64],
        reach_m: float,
        *,
        subset: NDArray[np.intp] | None = None,
    ) -> tuple[NDArray[np.bool_], NDArray[np.intp]]:
        """Points within ``reach_m`` (Euclidean) of any panel segment, and those panels.

        Returns a mask over the points and the indices of the panels (of
        ``subset``) that have any point within ``reach_m``. Compiled
        (:func:`mast.core._kernels.within`); :meth:`_within_reference` is
        the same in numpy.
        """
        from mast.core._kernels import within

        panels = np.arange(len(self)) if subset is None else subset
        n = points_mine.shape[0]
        if n == 0 or panels.size == 0:
            return np.zeros(n, dtype=bool), np.zeros(0, dtype=np.intp)
        near, reached = within(
            np.ascontiguousarray(points_mine, dtype=float).reshape(-1, 2),
            self.a,
            self.direction,
            self.normal,
            self.length,
            np.ascontiguousarray(panels, dtype=np.intp),
            float(reach_m),
        )
        return near, panels[reached]

    def _within_reference(
        self,
        points_mine: NDArray[np.float64],
        reach_m: float,
        *,
        subset: NDArray[np.intp] | None = None,
    ) -> tuple[NDArray[np.bool_], NDArray[np.intp]]:
        """:meth:`within` in numpy (the tests compare the two)."""
        panels = np.arange(len(self)) if subset is None else subset
        n = points_mine.shape[0]
        if n == 0 or panels.size == 0:
            return np.zeros(n, dtype=bool), np.zeros(0, dtype=np.intp)
        near = np.zeros(n, dtype=bool)
        reached = np.zeros(panels.size, dtype=bool)
        step = max(1, CHUNK_ELEMENTS // panels.size)
        for lo in range(0, n, step):
            t, s = self.project(points_mine[lo : lo + step], panels)
            over = np.maximum(np.maximum(-t, t - self.length[panels][None, :]), 0.0)
            close = over**2 + s**2 <= reach_m**2
            near[lo : lo + step] = np.any(close, axis=1)
            reached |= np.any(close, axis=0)
        return near, panels[reached]

    def reach_tallies(
        self,
        points_mine: NDArray[np.float64],
        ranges: NDArray[np.float64],
        reach_m: float,
        per_range: float,
        after_m: float = 0.0,
        *,
        subset: NDArray[np.intp] | None = None,
    ) -> tuple[NDArray[np.int64], NDArray[np.intp], NDArray[np.int64]]:
        """How many points lie within ``reach_m + per_range * range + after_m`` of each
        panel (of ``subset``; a point counts for every panel it is that close to), and
        of any panel of each beacon (a point counts once for a beacon); ``ranges`` is
        each point's range. Returns the panels' tallies, the beacons of ``subset``'s
        panels (their positions in :attr:`ids`, increasing) and theirs: the cost is
        the panels', not the survey's. Compiled
        (:func:`mast.core._kernels.reach_tallies`); :meth:`_reach_tallies_reference`
        is the same in numpy."""
        from mast.core._kernels import reach_tallies

        panels = np.arange(len(self)) if subset is None else subset
        beacons, owner = np.unique(self.beacon[panels], return_inverse=True)
        if points_mine.shape[0] == 0 or panels.size == 0:
            none = np.zeros(beacons.size, dtype=np.int64)
            return np.zeros(panels.size, dtype=np.int64), beacons, none
        per_panel, per_beacon = reach_tallies(
            np.ascontiguousarray(points_mine, dtype=float).reshape(-1, 2),
            np.ascontiguousarray(ranges, dtype=float),
            self.a[panels],
            self.direction[panels],
            self.normal[panels],
            self.length[panels],
            owner.astype(np.intp),
            np.arange(panels.size, dtype=np.intp),
            float(reach_m),
            float(per_range),
            float(after_m),
            beacons.size,
        )
        return per_panel, beacons, per_beacon

    def of_beacon(self, number: int) -> NDArray[np.intp]:
        """The panels of beacon ``number`` (its position in :attr:`ids`), in order."""
        order, starts = self._by_beacon
        return order[starts[number] : starts[number + 1]]

    @functools.cached_property
    def _by_beacon(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        order = np.argsort(self.beacon, kind="stable").astype(np.intp)
        counts = np.bincount(self.beacon, minlength=len(self.ids))
        return order, np.concatenate([[0], np.cumsum(counts)]).astype(np.intp)

    @functools.cached_property
    def chords(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per panel, its beacon's wall: the ends e1 and e4 of the line of the beacon's
        free ends (its first panel's ``a``, its last panel's ``b``), one row a panel."""
        if not len(self):
            return self.a, self.b
        order = np.lexsort((self.panel, self.beacon))  # by beacon, then panel number
        owner = self.beacon[order]
        cut = owner[1:] != owner[:-1]
        head = np.zeros(len(self.ids), dtype=np.intp)
        tail = np.zeros(len(self.ids), dtype=np.intp)
        head[owner[np.r_[True, cut]]] = order[np.r_[True, cut]]
        tail[owner[np.r_[cut, True]]] = order[np.r_[cut, True]]
        return self.a[head[self.beacon]], self.b[tail[self.beacon]]

    @functools.cached_property
    def discs(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per beacon (by position in :attr:`ids`), a disc holding all its panels: the
        middle of their ends' box, and the farthest end's distance from it (a hair
        more, against rounding)."""
        centre = np.zeros((len(self.ids), 2))
        radius = np.zeros(len(self.ids))
        ends = np.concatenate([self.a, self.b])
        owner = np.concatenate([self.beacon, self.beacon])
        lo = np.full((len(self.ids), 2), np.inf)
        hi = np.full((len(self.ids), 2), -np.inf)
        np.minimum.at(lo, owner, ends)
        np.maximum.at(hi, owner, ends)
        seen = np.isfinite(lo[:, 0])
        centre[seen] = 0.5 * (lo[seen] + hi[seen])
        far = np.hypot(*(ends - centre[owner]).T)
        np.maximum.at(radius, owner, far)
        return centre, radius * (1.0 + 1e-9) + 1e-9

    def _reach_tallies_reference(
        self,
        points_mine: NDArray[np.float64],
        ranges: NDArray[np.float64],
        reach_m: float,
        per_range: float,
        after_m: float = 0.0,
        *,
        subset: NDArray[np.intp] | None = None,
    ) -> tuple[NDArray[np.int64], NDArray[np.intp], NDArray[np.int64]]:
        """:meth:`reach_tallies` in numpy (the tests compare the two)."""
        panels = np.arange(len(self)) if subset is None else subset
        beacons = np.unique(self.beacon[panels])
        per_beacon = np.zeros(beacons.size, dtype=np.int64)
        if points_mine.shape[0] == 0 or panels.size == 0:
            return np.zeros(panels.size, dtype=np.int64), beacons, per_beacon
        reach = reach_m + np.asarray(ranges, dtype=float) * per_range + after_m
        t, s = self.project(points_mine, panels)
        beyond = np.maximum(np.maximum(-t, t - self.length[panels][None, :]), 0.0)
        close = beyond**2 + s**2 <= (reach**2)[:, None]
        owner = self.beacon[panels]
        for k, b in enumerate(beacons):
            per_beacon[k] = int(np.any(close[:, owner == b], axis=1).sum())
        return close.sum(axis=0).astype(np.int64), beacons, per_beacon

    def associate(
        self,
        points_mine: NDArray[np.float64],
        gate: float | NDArray[np.float64],
        *,
        subset: NDArray[np.intp] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """Nearest panel of each point, within ``gate`` of its line and inside its extent.

        Returns the panel index per point (-1 for none) and the signed distance
        from the panel's line (along its normal). Compiled
        (:func:`mast.core._kernels.associate`); :meth:`_associate_reference`
        is the same in numpy.
        """
        from mast.core._kernels import associate

        panels = np.arange(len(self)) if subset is None else subset
        pts = np.ascontiguousarray(points_mine, dtype=float).reshape(-1, 2)
        gates = np.asarray(gate, dtype=float).reshape(-1)
        if gates.size not in (1, pts.shape[0]):
            gates = gates[:1]
        if pts.shape[0] == 0 or panels.size == 0 or gates.size == 0:
            return np.full(pts.shape[0], -1, dtype=np.intp), np.full(pts.shape[0], np.inf)
        return associate(  # type: ignore[no-any-return]
            pts,
            self.a,
            self.direction,
            self.normal,
            self.length,
            np.ascontiguousarray(panels, dtype=np.intp),
            np.ascontiguousarray(gates),
        )

    def _associate_reference(
        self,
        points_mine: NDArray[np.float64],
        gate: float | NDArray[np.float64],
        *,
        subset: NDArray[np.intp] | None = None,
    ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """:meth:`associate` in numpy (the tests compare the two)."""
        n = points_mine.shape[0]
        idx = np.full(n, -1, dtype=np.intp)
        dist = np.full(n, np.inf)
        panels = np.arange(len(self)) if subset is None else subset
        if n == 0 or panels.size == 0:
            return idx, dist
        # A gate per point (or one for all), as a column that broadcasts over the panels.
        gates = np.asarray(gate, dtype=float).reshape(-1, 1) if np.ndim(gate) else None
        per_point = gates is not None and gates.shape[0] == n
        step = max(1, CHUNK_ELEMENTS // panels.size)
        for lo in range(0, n, step):
            hi = min(lo + step, n)
            t, s = self.project(points_mine[lo:hi], panels)
            g = np.broadcast_to(
                gate if gates is None else gates[lo:hi] if per_point else gates, s.shape
            )
            ok = (t >= 0) & (t <= self.length[panels][None, :]) & (np.abs(s) <= g)
            score = np.where(ok, np.abs(s), np.inf)
            j = np.argmin(score, axis=1)
            rows = np.arange(hi - lo)
            found = np.isfinite(score[rows, j])
            idx[lo:hi][found] = panels[j[found]]
            dist[lo:hi][found] = s[rows, j][found]
        return idx, dist
