"""Scanner models and the simulation of one scan from a known pose."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mast.core.lines import fit_line
from mast.core.noise import DEFAULT_RANGE_SIGMA_M, NoiseModel
from mast.core.pose import Pose2D
from mast.core.scan import Scan
from mast.errors import InputError
from mast.sim.owed import OWED, OwedRule, owes_fix
from mast.sim.world import Surface, World

__all__ = [
    "SCANNERS",
    "ScannerModel",
    "SimulatedScan",
    "scanner_for",
    "scanner_model",
    "simulate_scan",
]


#: The smallest range sigma a scanner's returns are weighted with, metres.
MIN_WEIGHT_SIGMA_M = 1e-4


@dataclass(frozen=True, slots=True)
class ScannerModel:
    """A 2D scanner: beam layout, range limits and error model.

    Attributes
    ----------
    name : str
    fov_deg, resolution_deg : float
        Field of view, centred on +x, and beam spacing, degrees.
    range_min_m, range_max_m : float
        Returns outside these limits are reported as no return (``nan``).
    range_sigma_m : float
        Standard deviation of Gaussian range noise.
    range_bias_m : float
        Constant added to every range (a calibration error).
    angle_sigma_rad : float
        Standard deviation of the true beam direction about its nominal angle.
    dropout_prob : float
        Probability that a beam returns nothing.
    mixed_pixel_prob : float
        Probability that a beam straddling a range jump returns a range in
        between the two surfaces (a mixed pixel).
    beam_divergence_rad : float
        Full width of the beam footprint used to detect such straddles.
    """

    name: str
    fov_deg: float
    resolution_deg: float
    range_min_m: float = 0.05
    range_max_m: float = 30.0
    range_sigma_m: float = 0.0
    range_bias_m: float = 0.0
    angle_sigma_rad: float = 0.0
    dropout_prob: float = 0.0
    mixed_pixel_prob: float = 0.0
    beam_divergence_rad: float = math.radians(0.25)

    def __post_init__(self) -> None:
        if not 0 < self.fov_deg <= 360:
            raise InputError(
                f"scanner {self.name!r}: field of view {self.fov_deg}° not in (0, 360]"
            )
        if not 0 < self.resolution_deg <= self.fov_deg:
            raise InputError(f"scanner {self.name!r}: resolution {self.resolution_deg}° is invalid")
        if not 0 <= self.range_min_m < self.range_max_m:
            raise InputError(f"scanner {self.name!r}: range limits are invalid")
        for attr in ("range_sigma_m", "angle_sigma_rad", "beam_divergence_rad"):
            if getattr(self, attr) < 0:
                raise InputError(f"scanner {self.name!r}: {attr} must not be negative")
        for attr in ("dropout_prob", "mixed_pixel_prob"):
            if not 0 <= getattr(self, attr) <= 1:
                raise InputError(f"scanner {self.name!r}: {attr} must be in [0, 1]")

    @property
    def beam_count(self) -> int:
        if self.fov_deg >= 360 - 1e-9:
            return round(360.0 / self.resolution_deg)
        return round(self.fov_deg / self.resolution_deg) + 1

    @property
    def angle_min_rad(self) -> float:
        if self.fov_deg >= 360 - 1e-9:
            return -math.pi
        return -math.radians(self.resolution_deg) * (self.beam_count - 1) / 2

    def beam_angles(self) -> NDArray[np.float64]:
        """Nominal beam angles, radians, counter-clockwise from +x, increasing."""
        step = math.radians(self.resolution_deg)
        return np.asarray(self.angle_min_rad + step * np.arange(self.beam_count), dtype=np.float64)

    def noise(self, survey_sigma_m: float = 0.0) -> NoiseModel:
        """The precisions this scanner's returns are weighted with.

        The range sigma is at least :data:`MIN_WEIGHT_SIGMA_M`: a noise-free
        model's returns still get a finite weight.
        """
        return NoiseModel(
            max(self.range_sigma_m, MIN_WEIGHT_SIGMA_M), self.angle_sigma_rad, survey_sigma_m
        )

    def noise_free(self) -> ScannerModel:
        return replace(
            self,
            name=self.name + "-exact",
            range_sigma_m=0.0,
            range_bias_m=0.0,
            angle_sigma_rad=0.0,
            dropout_prob=0.0,
            mixed_pixel_prob=0.0,
        )


#: Named scanner models. Range noise figures are typical of the classes named, or their
#: data sheets' where cited. Only add to the end: scenarios and benchmarks name the
#: models they draw from (never an index into this table), so an entry added changes
#: no simulated scene.
SCANNERS: dict[str, ScannerModel] = {
    m.name: m
    for m in (
        ScannerModel("ideal-270-0.25", 270.0, 0.25, range_max_m=30.0),
        ScannerModel("ideal-270-0.5", 270.0, 0.5, range_max_m=30.0),
        ScannerModel("lms1xx-0.5", 270.0, 0.5, range_max_m=20.0, range_sigma_m=0.012),
        ScannerModel("lms1xx-0.25", 270.0, 0.25, range_max_m=20.0, range_sigma_m=0.012),
        ScannerModel("lms2xx-0.1667", 190.0, 1.0 / 6.0, range_max_m=30.0, range_sigma_m=0.008),
        ScannerModel("spinning-360-0.2", 360.0, 0.2, range_max_m=40.0, range_sigma_m=0.020),
        ScannerModel(
            "urg04lx", 240.0, 360.0 / 1024.0, range_min_m=0.02, range_max_m=5.6, range_sigma_m=0.01
        ),
        # SICK TiM5xx/7xx, 15 Hz: 270°, working range from 0.05 m, statistical error
        # (1σ) 20 mm, systematic ±60 mm (SICK online data sheets TiM551-2050001 and
        # TiM561-2050101, "Measurement error (typically)"; TiM571/TiM781 the same figures
        # with the 25 m range; the TiM781-2174101 data sheet 1096807 gives 0.05-25 m and
        # 15 Hz). Resolution 1° (TiM55x) or 0.33° (TiM56x/57x/78x: three measurements a
        # degree, 811 beams over 270°, SICK technical information 8015883 on LMDscandata).
        ScannerModel("tim551", 270.0, 1.0, range_max_m=10.0, range_sigma_m=0.020),
        ScannerModel("tim561", 270.0, 1.0 / 3.0, range_max_m=10.0, range_sigma_m=0.020),
        ScannerModel("tim571", 270.0, 1.0 / 3.0, range_max_m=25.0, range_sigma_m=0.020),
        ScannerModel("tim781", 270.0, 1.0 / 3.0, range_max_m=25.0, range_sigma_m=0.020),
        # Hokuyo UST-10LX / UST-20LX, 40 Hz: 270° at 0.25° (1081 steps; the sensor's own
        # PP reply: ARES 1440, AMIN 0, AMAX 1080, SCAN 2400 rpm), 0.06-10 m / 0.06-20 m
        # guaranteed, "accuracy ±40 mm" (Hokuyo UST-10LX/20LX specifications). The data
        # sheet gives a bound, not a σ: taken here as two sigmas, 20 mm.
        ScannerModel(
            "ust-10lx", 270.0, 0.25, range_min_m=0.06, range_max_m=10.0, range_sigma_m=0.020
        ),
        ScannerModel(
            "ust-20lx", 270.0, 0.25, range_min_m=0.06, range_max_m=20.0, range_sigma_m=0.020
        ),
    )
}


def scanner_model(name: str) -> ScannerModel:
    """Look up a named scanner model; the error lists the known names."""
    try:
        return SCANNERS[name]
    except KeyError:
        raise InputError(f"unknown scanner {name!r}; known: {', '.join(SCANNERS)}") from None


@dataclass(frozen=True, eq=False)
class SimulatedScan:
    """A simulated scan with what each beam really hit.

    Attributes
    ----------
    scan : Scan
        What the scanner reports.
    pose : Pose2D
        The true pose it was taken from.
    scanner : ScannerModel
    true_ranges_m : ndarray, shape (n,)
        Noise-free range along the nominal beam (``inf`` for no surface).
    surface_index : ndarray of int, shape (n,)
        Index into ``surfaces`` of the surface each beam hit (-1: none or dropped).
    surfaces : tuple of Surface
    """

    scan: Scan
    pose: Pose2D
    scanner: ScannerModel
    true_ranges_m: NDArray[np.float64]
    surface_index: NDArray[np.intp]
    surfaces: tuple[Surface, ...]
    _panel_cache: dict[tuple[str, int], int] = field(default_factory=dict, repr=False)

    def beacon_mask(self) -> NDArray[np.bool_]:
        """Beams with a valid return from a beacon panel."""
        kinds = np.array([s.kind == "beacon" for s in self.surfaces] + [False])
        return kinds[self.surface_index] & self.scan.valid

    def panel_hits(self) -> dict[tuple[str, int], int]:
        """Number of valid returns on each (beacon id, panel) that was hit."""
        if not self._panel_cache:
            ok = self.scan.valid & (self.surface_index >= 0)
            idx, counts = np.unique(self.surface_index[ok], return_counts=True)
            for i, c in zip(idx, counts, strict=True):
                s = self.surfaces[int(i)]
                if s.kind == "beacon":
                    self._panel_cache[(s.beacon, s.panel)] = int(c)
        return dict(self._panel_cache)

    def owes_fix(self, rule: OwedRule = OWED) -> bool:
        """Whether this scan is owed a fix (:func:`mast.sim.owed.owes_fix`), its panels
        counted by ``rule`` (:meth:`panels_seen`)."""
        return owes_fix(self.panels_seen(rule))

    def panels_seen(self, rule: OwedRule) -> dict[str, list[int]]:
        """The panels ``rule`` counts as shown, per beacon id: at least ``rule.min_points``
        returns, and not at grazing incidence (the beam within ``rule.min_incidence_deg``
        of the panel's plane at its returns' centroid: returns too sparse to draw a line
        through). Every caller names its rule (:mod:`mast.sim.owed`)."""
        min_points, min_incidence_deg = rule.min_points, rule.min_incidence_deg
        out: dict[str, list[int]] = {}
        ok = self.scan.valid
        _, pts_all = self.scan.points()
        beam_of = np.flatnonzero(ok)
        for (b, p), c in sorted(self.panel_hits().items()):
            if c < min_points:
                continue
            k = self.surfaces.index(Surface("beacon", b, p))
            sel = self.surface_index[beam_of] == k
            line = fit_line(pts_all[sel])
            along, centre = line.direction, line.centroid
            beam = centre / np.hypot(*centre)
            incidence = math.degrees(
                math.asin(min(1.0, abs(beam[0] * along[1] - beam[1] * along[0])))
            )
            if incidence >= min_incidence_deg:
                out.setdefault(b, []).append(p)
        return out


def scanner_for(
    name: str | None,
    *,
    fov_deg: float | None,
    resolution_deg: float | None,
    range_sigma_m: float | None,
    range_max_m: float | None,
    angle_sigma_rad: float | None,
) -> ScannerModel:
    """A named scanner model with any explicit figure replacing its own, or one built from
    the explicit figures (field of view and resolution required)."""
    options = {
        "fov_deg": fov_deg,
        "resolution_deg": resolution_deg,
        "range_sigma_m": range_sigma_m,
        "range_max_m": range_max_m,
        "angle_sigma_rad": angle_sigma_rad,
    }
    given: dict[str, float] = {k: v for k, v in options.items() if v is not None}
    if name is not None:
        model = scanner_model(name)
        return replace(model, name=model.name if not given else model.name + "-custom", **given)
    if fov_deg is None or resolution_deg is None:
        raise InputError(
            "give --scanner NAME (see mast scanners) or the scanner's --fov and --resolution"
        )
    given.setdefault("range_sigma_m", DEFAULT_RANGE_SIGMA_M)
    return ScannerModel("custom", **given)


def simulate_scan(
    world: World,
    pose: Pose2D,
    scanner: ScannerModel,
    *,
    rng: np.random.Generator | None = None,
    stamp_ns: int = 0,
    frame_id: str = "laser",
) -> SimulatedScan:
    """Ray-cast one scan from ``pose`` (vectorised over beams).

    A beam of nominal angle ``phi`` travels along mine bearing ``A - phi``
    (DESIGN.md), perturbed by ``angle_sigma_rad``; its range gets bias and
    Gaussian noise; returns outside the range limits, dropped beams and
    beams that hit nothing are ``nan``.
    """
    if rng is None:
        rng = np.random.default_rng(0)
    phi = scanner.beam_angles()
    n = phi.size
    true_dir = phi
    if scanner.angle_sigma_rad > 0:
        true_dir = phi + rng.normal(0.0, scanner.angle_sigma_rad, n)

    def cast(angles: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
        return world.raycast(pose.position, pose.beam_directions(angles))

    true_r, surf = cast(true_dir)
    r = true_r.copy()
    if scanner.mixed_pixel_prob > 0:
        half = scanner.beam_divergence_rad / 2
        r_lo, s_lo = cast(true_dir - half)
        r_hi, s_hi = cast(true_dir + half)
        # A footprint straddles a jump when its two halves hit different surfaces at
        # clearly different ranges (an oblique wall alone is no jump).
        both = np.isfinite(r_lo) & np.isfinite(r_hi) & (s_lo != s_hi)
        with np.errstate(invalid="ignore"):
            gap = np.abs(np.where(both, r_lo - r_hi, 0.0))
        jump = both & (gap > 0.1 + 3 * scanner.range_sigma_m)
        mixed = jump & (rng.random(n) < scanner.mixed_pixel_prob)
        w = rng.random(n)
        r = np.where(mixed, w * r_lo + (1 - w) * r_hi, r)
        surf = np.where(mixed, -1, surf)
    if scanner.range_sigma_m > 0:
        r = r + rng.normal(0.0, scanner.range_sigma_m, n)
    r = r + scanner.range_bias_m
    lost = ~np.isfinite(r) | (r < scanner.range_min_m) | (r > scanner.range_max_m)
    if scanner.dropout_prob > 0:
        lost |= rng.random(n) < scanner.dropout_prob
    r = np.where(lost, np.nan, r)
    surf = np.where(lost, -1, surf)
    scan = Scan.from_laserscan(
        angle_min=scanner.angle_min_rad,
        angle_increment=math.radians(scanner.resolution_deg),
        ranges=r,
        range_min=scanner.range_min_m,
        range_max=scanner.range_max_m,
        stamp_ns=stamp_ns,
        frame_id=frame_id,
    )
    # Truth is along the nominal beam (what a noise-free scanner would report).
    nominal_r = true_r if scanner.angle_sigma_rad == 0 else cast(phi)[0]
    return SimulatedScan(scan, pose, scanner, nominal_r, surf, world.surfaces)
