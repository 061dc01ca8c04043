"""The MAST locator: one scan and a beacon survey in, a fix (or a reasoned no-fix) out.

A short chain of the paper's stages (``mast.pipeline``), each in its own module:

1. :func:`~mast.pipeline.segmentation.segment_scan` — PCA line segmentation;
2. :func:`~mast.pipeline.identification.identify_panels` — Table 1 identification;
3. :func:`~mast.pipeline.hypotheses.pose_hypotheses` — pose hypotheses (or, with a
   prior, :func:`~mast.pipeline.tracking.prior_hypotheses`; when the corners give no
   fix, :func:`~mast.pipeline.hypotheses.panel_hypotheses` from two middle panels);
4. :func:`~mast.pipeline.verification.verify` — ICP and every beam's verdict;
5. :func:`~mast.pipeline.adjustment.adjust_on_panels` — least squares, then
   :mod:`~mast.pipeline.integrity` (data snooping, beacon tests) and the global test.

With a prior, stages 3-4 run first without stages 1-2: the prior names the beacons,
and the scan is segmented only when its corners must decide (:func:`_prior_first`).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from numpy.typing import NDArray

from mast.core.beacon import Survey
from mast.core.geometry import PanelSet
from mast.core.index import SurveyIndex
from mast.core.noise import (
    DEFAULT_ANGLE_SIGMA_RAD,
    DEFAULT_RANGE_SIGMA_M,
    DEFAULT_SURVEY_SIGMA_M,
    NoiseModel,
)
from mast.core.pose import Pose2D
from mast.core.quantiles import chi2_sf
from mast.core.scan import Scan
from mast.core.stats import BeaconTest
from mast.pipeline.adjustment import (
    Adjustment,
    Observations,
    adjust_on_panels,
    survey_covariance,
)
from mast.pipeline.alignment import Similarity
from mast.pipeline.bounds import cramer_rao_bound
from mast.pipeline.hypotheses import (
    Hypothesis,
    HypothesisConfig,
    panel_hypotheses,
    pose_hypotheses,
)
from mast.pipeline.identification import (
    IdentificationConfig,
    NodeMatch,
    PanelIdentification,
    identify_panels,
)
from mast.pipeline.integrity import (
    Residuals,
    exclude_inconsistent,
    residual_summary,
    snoop,
)
from mast.pipeline.segmentation import Segment, Segmentation, SegmentationConfig, segment_scan
from mast.pipeline.tracking import (
    Prior,
    TrackingConfig,
    VehicleLimits,
    centre_hypotheses,
    prior_hypotheses,
    window_may_fix,
)
from mast.pipeline.verification import Refinement, VerificationConfig, Verified, verify

__all__ = [
    "NO_FIX_REASONS",
    "STAGES",
    "Fix",
    "FixedPose",
    "Locator",
    "LocatorConfig",
    "Prior",
    "SequenceConfig",
    "SequenceLocator",
    "SequenceStep",
    "Verified",
    "locate",
    "locate_again",
    "locate_near",
    "locate_sequence",
    "survey_index",
]

#: Every reason a scan can get no fix, with what it means.
NO_FIX_REASONS: dict[str, str] = {
    "no_beacon": "no corner of the scan matches any surveyed beacon's panels",
    "one_beacon": "beacon panels were confirmed on fewer than two beacons",
    "inconsistent": "the identified beacons do not agree with their surveyed geometry",
    "ambiguous": "two different poses explain the scan equally well",
    "degenerate_geometry": "the panels seen do not determine position and azimuth",
    "rejected": "the adjusted fix fails its global test: the returns do not fit the beacons",
}

#: The stages a fix's time is split into (:attr:`Fix.stages_s`), in the order of a global
#: search (with a prior, the window and verification come first, segmentation after
#: them when the corners must decide).
STAGES: dict[str, str] = {
    "segmentation": "the scan cut into straight lines",
    "window": "a prior's window: the bound on what it can fix, and its grid search",
    "identification": "corners of the lines identified as beacon edges",
    "hypotheses": "poses from the identified corners, or from two middle panels",
    "verification": "ICP from every hypothesis, and every beam's verdict on it",
    "adjustment": "least squares, data snooping, the beacon and global tests, the bound",
}


@dataclass(frozen=True, slots=True)
class LocatorConfig:
    """Everything the locator can be told; defaults suit a typical 2D scanner.

    The three precisions are the one source of the noise model every stage
    is given (:attr:`noise`).

    Attributes
    ----------
    range_sigma_m : float
        A-priori standard deviation of one range.
    angle_sigma_rad : float
        A-priori standard deviation of one beam angle.
    survey_sigma_m : float
        Standard deviation of surveyed edge coordinates: widens the gates and
        adds its share to the fix's covariance (0 for a simulated, exact survey).
    min_beacons : int
        Beacons that must support a fix.
    min_cornered : int
        Of those, beacons on whose surveyed edge an identified corner of the
        scan must land (the others may be confirmed by their returns alone).
    ambiguity_log_ratio : float
        A second, different pose whose tempered beam log-likelihood is within
        this of the best one's makes the scan ambiguous.
    likelihood_tempering : float
        Beams per independent piece of evidence: the beam model's
        log-likelihoods are divided by this before poses are compared. A
        panel's returns share its survey and mounting error and mixed pixels
        come in runs, so independent beams overstate the evidence (Thrun,
        Burgard and Fox 2005, sec. 6.3.4); untempered, one beam more or less
        on an edge (some 7 nats) would decide between two poses that two
        look-alike beacons make equally good.
    reject_alpha : float
        Significance of the global test beyond which a fix is refused: its
        returns do not fit the surveyed beacons (clutter taken for them).
    prior : Prior, optional
        Where the scanner is believed to be. No pose outside its window is
        fixed; a narrow one (see :class:`TrackingConfig`) is searched directly
        first, without identification, and when that gives no fix the global
        search runs as without a prior, its verified poses kept inside the
        window (a prior only adds fixes).
    prior_margin_m, prior_margin_rad : float
        How far outside the prior's window a pose may be estimated and still
        count as inside: a true pose on the rim is estimated a few millimetres
        either side of it.
    """

    range_sigma_m: float = DEFAULT_RANGE_SIGMA_M
    angle_sigma_rad: float = DEFAULT_ANGLE_SIGMA_RAD
    survey_sigma_m: float = DEFAULT_SURVEY_SIGMA_M
    min_beacons: int = 2
    min_cornered: int = 1
    ambiguity_log_ratio: float = math.log(1e4)
    likelihood_tempering: float = 5.0
    reject_alpha: float = 1e-3
    prior: Prior | None = None
    prior_margin_m: float = 0.05
    prior_margin_rad: float = math.radians(0.5)
    segmentation: SegmentationConfig = field(default_factory=SegmentationConfig)
    identification: IdentificationConfig = field(default_factory=IdentificationConfig)
    hypotheses: HypothesisConfig = field(default_factory=HypothesisConfig)
    verification: VerificationConfig = field(default_factory=VerificationConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)

    def __post_init__(self) -> None:
        # The one check of the precisions, whoever gives them (an option, a settings
        # file, a library call): each message starts with the field it is about.
        if not 0.0 < self.range_sigma_m < math.inf:
            raise ValueError(
                "range_sigma_m must be a positive number of metres (10 mm is 0.01), "
                f"got {self.range_sigma_m!r}"
            )
        for name, unit in (("angle_sigma_rad", "radians"), ("survey_sigma_m", "metres")):
            value = getattr(self, name)
            if not 0.0 <= value < math.inf:
                raise ValueError(f"{name} must be a non-negative number of {unit}, got {value!r}")

    @property
    def noise(self) -> NoiseModel:
        return NoiseModel(self.range_sigma_m, self.angle_sigma_rad, self.survey_sigma_m)


@dataclass(frozen=True, eq=False)
class Fix:
    """What the locator concluded about one scan.

    ``status`` is ``"fix"`` with ``pose`` and ``adjustment``, or ``"no_fix"``
    with ``reason`` (a key of :data:`NO_FIX_REASONS`) and ``detail``.
    The remaining fields keep what each stage found, for people debugging.
    """

    status: str
    pose: Pose2D | None
    adjustment: Adjustment | None
    beacons: tuple[str, ...]
    panels: dict[str, list[int]]
    points_used: int
    reason: str | None
    detail: str
    segmentation: Segmentation | None
    """The scan's segments and corners; None for a scan fixed near a prior without them
    (:func:`_prior_first`)."""
    identification: PanelIdentification | None
    """The corners and panels identified in the segmentation; None without it."""
    hypotheses: tuple[Hypothesis, ...]
    verified: tuple[Verified, ...]
    chosen: Verified | None
    observations: NDArray[np.intp]
    """Beam indices used in the adjustment."""
    observation_panels: NDArray[np.intp]
    """Panel (index into the survey's PanelSet) of each observation."""
    elapsed_s: float
    config: LocatorConfig
    crb: NDArray[np.float64] | None = None
    """Cramer-Rao bound of (E, N, A) for the returns used, at the fixed pose."""
    excluded_beacons: tuple[str, ...] = ()
    """Beacons seen but left out because their ranges disagree with the others
    (moved or mis-surveyed)."""
    outliers_removed: int = 0
    """Returns removed by data snooping."""
    residuals: Residuals | None = None
    """Residuals of the adjustment (overall, per beacon and panel, beacon tests): of the
    fix, or of the adjustment a fix was refused on (``inconsistent``, ``rejected``)."""
    stages_s: dict[str, float] = field(default_factory=dict)
    """Seconds spent in each stage (:data:`STAGES`) up to this result; what they leave of
    ``elapsed_s`` is the locator's own bookkeeping (choosing between poses, the record)."""
    refused: tuple[float, int] | None = None
    """The reference variance and degrees of freedom of an adjustment its global test
    refused (``rejected``): what a hint on the range sigma is worked out from."""

    @property
    def ok(self) -> bool:
        return self.status == "fix"

    @property
    def segments(self) -> tuple[Segment, ...]:
        """The scan's straight pieces (none for a scan fixed without its segmentation)."""
        return () if self.segmentation is None else self.segmentation.segments

    @property
    def nodes(self) -> tuple[NodeMatch, ...]:
        """The identified corners (none for a scan fixed without its segmentation)."""
        return () if self.identification is None else self.identification.nodes

    @property
    def similarity(self) -> Similarity | None:
        return None if self.chosen is None else self.chosen.hypothesis.similarity

    @property
    def icp_iterations(self) -> int:
        return 0 if self.chosen is None else self.chosen.icp.iterations


#: Most survey indexes kept (least recently used dropped first).
_INDEX_CACHE_SIZE = 8
_INDEX_CACHE: OrderedDict[tuple[int, float], tuple[Survey, SurveyIndex, PanelSet]] = OrderedDict()


def survey_index(survey: Survey, range_max_m: float = math.inf) -> tuple[SurveyIndex, PanelSet]:
    """The survey's index and panels for a scanner of this range, built once per survey
    object and range (a run reuses them). Edge pairs farther apart than twice the
    range are left out of the index: no scan sees both."""
    key = (id(survey), float(range_max_m))
    hit = _INDEX_CACHE.get(key)
    if hit is not None and hit[0] is survey:
        _INDEX_CACHE.move_to_end(key)
    else:
        while len(_INDEX_CACHE) >= _INDEX_CACHE_SIZE:
            _INDEX_CACHE.popitem(last=False)
        reach = 2.0 * range_max_m + 1.0
        hit = (
            survey,
            SurveyIndex.from_survey(survey, reach_m=reach),
            PanelSet.from_survey(survey),
        )
        _INDEX_CACHE[key] = hit
    return hit[1], hit[2]


def _choose(verified: list[Verified], cfg: LocatorConfig) -> tuple[Verified | None, str, str]:
    """The best verified pose, or why there is none: (best, reason, detail)."""
    # Every beacon the beams confirm counts, but a fix needs ``min_cornered`` whose
    # identified corners land on their surveyed edges: shape tells beacons apart.
    # A tracked prior already says which beacon is which.
    # Without a corner (a pose from two middle panels) every beacon must prove its shape.
    confirmed = [v for v in verified if len(v.supported) >= cfg.min_beacons]
    full = [
        v
        for v in confirmed
        if len(v.shaped if v.hypothesis.kind == "prior" else v.cornered) >= cfg.min_cornered
        or (v.hypothesis.kind == "panels" and len(v.shaped) >= cfg.min_beacons)
    ]
    if not full:
        best = verified[0] if verified else None
        names = ", ".join(best.supported) if best else ""
        if not names:
            return None, "one_beacon", "no beacon is confirmed by the beams"
        if best is not None and len(best.supported) >= cfg.min_beacons:
            return (
                None,
                "one_beacon",
                f"beacons {names} lie where the pose puts them, but no identified corner"
                " lands on a surveyed edge (shape does not tell which beacon is which)",
            )
        return None, "one_beacon", f"only beacon {names} confirmed by the beams"
    # A pose whose beacons lie on their surveyed panels within their noise comes before
    # one that reads rock beside them, or another shape, as theirs.
    full.sort(key=lambda v: (not v.misfit, v.log_likelihood), reverse=True)
    best = full[0]
    # Any other pose whose beacons prove their shape competes within the margin,
    # unless it has fewer beacons identified by their own corners than the best
    # (up to two): then an identified corner that lands on its surveyed edge at
    # the best pose lands nowhere at the other, and the other must explain the
    # scan better to compete. A pose one beacon short of a fix competes within
    # the margin too when its beacon is identified by a corner while the best
    # rests on a single identified corner: the best's second beacon, confirmed
    # by its returns alone, must then add more than the margin to what the
    # other explains (on a long drive, a look-alike pair 80-290 m away was
    # fixed with 5 mm sigmas from one beacon's corner and a few returns of rock
    # read as its neighbour, 7-27 log-units ahead of the true one-beacon
    # reading). A tracked pose whose second beacon merely lies where the pose
    # puts it is doubtful likewise: a pose with one shaped beacon that explains
    # the scan better competes. A fix on two identified corners, each on its
    # own surveyed edge, is not undone by one corner read another way. A pose from two
    # middle panels alone is: any corner identified on its surveyed edge at another
    # pose reads the scan by a beacon's shape, where the two middle panels only by
    # their lengths (on a long drive, a beacon in view read as a look-alike 65 m away
    # with rock as its neighbour, 53 log-units ahead of its own one-corner reading).
    margin = cfg.ambiguity_log_ratio * cfg.likelihood_tempering
    from_panels = best.hypothesis.kind == "panels"
    proven_corners = _proven_corners(best, cfg)
    doubtful = len(proven_corners) < cfg.min_beacons
    tracked_best = best.hypothesis.kind == "prior" and len(best.shaped) < cfg.min_beacons
    proven = min(len(proven_corners), cfg.min_beacons)
    share = cfg.verification.same_reading_share
    for other in verified:
        if (
            other is best
            or other.same_pose(best.pose, cfg.verification)
            or other.reads_alike(best, share)
        ):
            continue  # the same reading of the scan: not a second place
        if other.misfit and not best.misfit:
            continue  # its beacons' returns do not lie on their panels: not a reading of them
        if from_panels and other.cornered:
            slack = math.inf
        elif (len(other.shaped) >= cfg.min_beacons and len(other.cornered) >= proven) or (
            other.cornered and doubtful
        ):
            slack = margin
        elif len(other.supported) >= cfg.min_beacons or (tracked_best and other.shaped):
            slack = 0.0
        else:
            continue  # one beacon, not even identified by a corner: a wall's bend can do that
        if other.log_likelihood >= best.log_likelihood - slack:
            return (
                None,
                "ambiguous",
                f"poses {best.pose} ({', '.join(best.supported)}) and "
                f"{other.pose} ({', '.join(other.supported)}) fit equally well",
            )
    return best, "", ""


def _ranked_together(first: list[Verified], then: list[Verified]) -> list[Verified]:
    """Two searches' verified poses as one list, most supported first, then by likelihood
    (the first search's before the second's where they tie)."""
    if not first:
        return then
    return sorted([*first, *then], key=lambda v: v.rank, reverse=True)


def _settled(verified: list[Verified], cfg: LocatorConfig, corners: bool = True) -> bool:
    """Whether poses on fewer than ``min_beacons`` beacons' returns can no longer change
    what :func:`_choose` makes of ``verified``: it picks a best pose with ``min_beacons``
    beacons each identified by its own corner and proven by its beams
    (:func:`_proven_corners`). Then another pose competes only if it has
    ``min_beacons`` supporting beacons, which those poses cannot have. Without
    ``corners`` (a prior's search on a scan not segmented, where no pose has a beacon
    identified by its corner), a best pose from the prior with ``min_beacons`` beacons
    that show their shape settles it too: another then competes only with
    ``min_beacons`` supporting beacons or with a corner of its own."""
    best, _, _ = _choose(_admitted(verified, cfg), cfg)
    if best is None:
        return False
    if len(_proven_corners(best, cfg)) >= cfg.min_beacons:
        return True
    return not corners and best.hypothesis.kind == "prior" and len(best.shaped) >= cfg.min_beacons


def _proven_corners(v: Verified, cfg: LocatorConfig) -> list[str]:
    """The beacons of ``v`` identified by their own corners whose beams prove them too:
    as many predicted beams hit them as two panels need returns (``2 *
    min_panel_points``). A corner of rock beside one panel, read as a node, comes
    with a few hits only (on a long drive, 4 for a look-alike's neighbour 64 m from
    the truth)."""
    need = 2 * cfg.verification.min_panel_points
    return [b for b in v.cornered if v.checks[b].hit >= need]


def _admitted(verified: list[Verified], cfg: LocatorConfig) -> list[Verified]:
    """The verified poses within the prior (with its margin), or all without one."""
    if cfg.prior is None:
        return verified
    margin = (cfg.prior_margin_m, cfg.prior_margin_rad)
    return [v for v in verified if cfg.prior.admits(v.pose, *margin)]


class Locator:
    """A survey made ready to locate scans against, and the one way scans are located.

    What belongs to the survey is built once, on the first scan from a scanner of a
    given range, and kept for every scan after it: the survey's index of edge pairs,
    its panel set (:func:`survey_index`, shared with every locator of the same survey
    object), and the likelihood tiles of the prior's window search (per panel set,
    :func:`~mast.pipeline.tracking.prior_hypotheses`). Each scan is then a short chain
    of stage calls, :data:`STAGES`, timed on the result (:attr:`Fix.stages_s`).

    Parameters
    ----------
    survey : Survey
    config : LocatorConfig, optional
        Its ``prior``, when given, confines every scan (see :func:`locate`).
    """

    def __init__(self, survey: Survey, config: LocatorConfig | None = None) -> None:
        self.survey = survey
        self.config = config or LocatorConfig()
        self._ready: dict[float, tuple[SurveyIndex, PanelSet]] = {}

    def ready(self, range_max_m: float = math.inf) -> tuple[SurveyIndex, PanelSet]:
        """The survey's index and panels for a scanner of this range (built once)."""
        hit = self._ready.get(range_max_m)
        if hit is None:
            hit = self._ready[range_max_m] = survey_index(self.survey, range_max_m)
        return hit

    def locate(self, scan: Scan, prior: Prior | None = None, *, narrow: Prior | None = None) -> Fix:
        """Fix the scanner's pose from ``scan``.

        Without ``prior``, as :func:`locate`. With it (a prediction, such as the last
        fix), the scan is searched near the prediction first and from scratch when that
        gives no fix, as :func:`locate_near`; ``narrow`` is a window inside ``prior``
        searched before it.
        """
        return self._near(scan, prior, narrow)[0]

    def _near(
        self, scan: Scan, prior: Prior | None, narrow: Prior | None = None
    ) -> tuple[Fix, bool]:
        """:meth:`locate`, and whether a prior was tried and gave no fix."""
        cfg = self.config
        ready = self.ready(scan.range_max_m)
        if cfg.prior is None and prior is not None:
            # The priors' own searches, then the global one not narrowed by them.
            if narrow is not None and _inside(narrow, prior):
                return _prior_first(scan, ready, cfg, (narrow, prior), cfg)
            return _prior_first(scan, ready, cfg, (prior,), cfg)
        # The config's own prior (if any) confines the scan: its search, then the global
        # one kept inside its window.
        confined = () if cfg.prior is None else (cfg.prior,)
        return _prior_first(scan, ready, cfg, confined, cfg)[0], False


def segmentation_of(fix: Fix, scan: Scan) -> Segmentation:
    """The segmentation of the scan ``fix`` was made from, made now (with the fix's
    configuration) when the locator fixed it without one, near a prior: for maps,
    which draw a scan's straight pieces."""
    return fix.segmentation or segment_scan(scan, fix.config.segmentation)


def segmented(fix: Fix, scan: Scan, survey: Survey) -> tuple[Segmentation, PanelIdentification]:
    """:func:`segmentation_of` and the identification of its corners: for figures."""
    if fix.segmentation is not None and fix.identification is not None:
        return fix.segmentation, fix.identification
    cfg = fix.config
    seg = segmentation_of(fix, scan)
    index, panels = survey_index(survey, scan.range_max_m)
    ident = identify_panels(
        seg,
        index.representatives,
        cfg.identification,
        survey_sigma_m=panels.worst_survey_sigma(cfg.noise.survey_sigma_m),
    )
    return seg, ident


def locate(scan: Scan, survey: Survey, *, config: LocatorConfig | None = None) -> Fix:
    """Fix the scanner's pose from one scan of surveyed beacons.

    With a prior (``config.prior``) the poses its window holds are searched
    first, directly (:func:`~mast.pipeline.tracking.prior_hypotheses`); when
    that gives no fix, the global search runs as without a prior, its verified
    poses kept only inside the window. A prior thus only adds fixes: a pose the
    global search fixes inside the window is fixed with the prior too, and no
    pose outside it ever is.

    Parameters
    ----------
    scan : Scan
        One horizontal scan, scanner frame.
    survey : Survey
        The surveyed beacons.
    config : LocatorConfig, optional

    Returns
    -------
    Fix
        ``status == "fix"`` with the adjusted pose and its statistics, or
        ``"no_fix"`` with a reason from :data:`NO_FIX_REASONS`. The locator
        never raises for what a scan contains.
    """
    return Locator(survey, config).locate(scan)


def locate_again(fix: Fix, scan: Scan, survey: Survey, config: LocatorConfig) -> Fix:
    """:func:`locate` of ``scan`` again, without a prior, under ``config`` (other
    verification or adjustment rules), on the segmentation and identified corners the
    global search that gave ``fix`` made of the same scan (against the same survey):
    the same result as :func:`locate`, without segmenting and identifying the scan
    twice (its ``stages_s`` and ``elapsed_s`` count the stages run again only).
    ``config`` must segment and identify as ``fix``'s did (the same segmentation and
    identification settings and survey sigma); a fix found without its segmentation
    (near a prior), or a ``config`` with a prior, is located from scratch."""
    was = fix.config
    if config.prior is not None or fix.segmentation is None or fix.identification is None:
        return locate(scan, survey, config=config)
    if (config.segmentation, config.identification, config.noise.survey_sigma_m) != (
        was.segmentation,
        was.identification,
        was.noise.survey_sigma_m,
    ):
        raise ValueError("locate_again: the configuration must segment and identify as the fix's")
    t0 = time.perf_counter()
    ready = survey_index(survey, scan.range_max_m)
    return _locate(scan, ready, config, t0, _Clock(), fix.segmentation, ident=fix.identification)


class _Clock:
    """Seconds one scan's location spent in each stage (:data:`STAGES`)."""

    __slots__ = ("spent",)

    def __init__(self) -> None:
        self.spent: dict[str, float] = {}

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.spent[stage] = self.spent.get(stage, 0.0) + time.perf_counter() - t0


@dataclass(slots=True)
class _Window:
    """A prior's search: the hypotheses of ``within.prior``'s window in batches, the
    window's centre (``first``, when narrow) before its grid's (made by ``grid`` the
    first time they are needed, and kept for a second search of the same window)."""

    within: LocatorConfig
    first: list[Hypothesis]
    grid: Callable[[], list[list[Hypothesis]]]
    searched: list[list[Hypothesis]] | None = None

    def batches(self, clock: _Clock) -> Iterator[list[Hypothesis]]:
        if self.first:
            yield self.first
        if self.searched is None:
            with clock("window"):
                self.searched = self.grid()
        yield from self.searched


def _uncontested(fix: Fix, cfg: LocatorConfig) -> bool:
    """Whether ``fix`` is the only pose its search confirmed (others are the same pose).

    Without the scan's corners two readings a few centimetres and tenths of a degree
    apart can both be confirmed, the wrong one by a stray return on a beacon's second
    panel: on a long drive a tracked fix 20 mm and 0.33 degrees off, where the corners
    put the other 5 mm and 0.02 degrees off. Such a scan is judged with its corners.
    """
    best = fix.chosen
    return best is not None and all(
        v is best or v.same_pose(best.pose, cfg.verification) for v in fix.verified
    )


def _prior_first(
    scan: Scan,
    ready: tuple[SurveyIndex, PanelSet],
    searched: LocatorConfig,
    priors: Sequence[Prior],
    fallback: LocatorConfig,
) -> tuple[Fix, bool]:
    """Each prior's own search in turn (``searched`` with that prior), then, when none
    gives a fix, the global search under ``fallback``, against the survey's index and
    panels (``ready``); and whether a prior was tried and gave no fix. A prediction's
    narrow window comes before the wide one around it: the first costs a few grid
    poses, and a scan it does not fix is searched as if it had not been tried. A window
    in which no pose could be fixed (:func:`~mast.pipeline.tracking.window_may_fix`) is
    not searched.

    A prior's search runs first without segmenting the scan: the prior names the
    beacons, and a pose whose beacons each show two panels' returns on their panels, no
    more past their edges, and one of them its bend, needs no corner to be fixed
    (:func:`~mast.pipeline.verification.verify` without ``ident``) when no other pose is
    confirmed (:func:`_uncontested`). Only when that gives no fix is the scan segmented
    and its corners identified, and the same poses judged again with a beacon's corner
    on its surveyed edge as proof of its shape (their ICP kept from the first time); a
    later prior's search and the global one use that segmentation. A pose fixed without
    corners is one the search with them confirms too (a corner only adds to a beacon's
    support); a scan that search would fix is fixed by it, unless the first one does.
    A tracked scan fixed in the first search costs no segmentation. Two limits of the
    first search: a narrow window's centre is one hypothesis, so its fix has no other
    pose to be contested by; and poses on one beacon's returns are left unjudged once
    the best pose has two beacons that show their shape (:func:`_settled`), so one with
    an identified corner, which the corners would let compete, is not seen.
    """
    t0 = time.perf_counter()
    clock = _Clock()
    seg: Segmentation | None = None
    ident: PanelIdentification | None = None
    memo: dict[int, Refinement] = {}

    def tracked(
        window: _Window,
        segmented: Segmentation | None,
        corners: PanelIdentification | None,
    ) -> Fix | None:
        # The window's centre alone when it is narrow, then the best grid poses, then
        # poses from other basins of the window, each only when those before give no fix.
        verified: tuple[Verified, ...] = ()
        within = window.within
        for batch in window.batches(clock):
            fix = _locate(
                scan, ready, within, t0, clock, segmented,
                from_prior=batch, before=verified, ident=corners, icp_memo=memo,
            )  # fmt: skip
            if fix.ok and (segmented is not None or _uncontested(fix, within)):
                return fix
            if fix.ok:
                return None  # another pose was confirmed too: the corners must choose
            verified = fix.verified
        return None

    if priors:
        _, panels = ready
        points = scan.points()[1]
    for prior in priors:
        within = replace(searched, prior=prior)
        with clock("window"):
            may_fix = window_may_fix(
                points,
                panels,
                prior,
                scan.range_max_m,
                gate_m=within.verification.gate_sigmas * within.noise.gate_sigma_m,
                margin_m=within.prior_margin_m,
                margin_rad=within.prior_margin_rad,
                min_beacons=within.min_beacons,
                min_panel_points=within.verification.min_panel_points,
            )
        if not may_fix:
            continue  # no pose in the window could be fixed: its search is skipped
        with clock("window"):
            window = _Window(
                within,
                centre_hypotheses(prior, within.tracking),
                partial(prior_hypotheses, points, panels, prior, scan.range_max_m, within.tracking),
            )
        if seg is None:
            fix = tracked(window, None, None)
            if fix is not None:
                return fix, False
            with clock("segmentation"):
                seg = segment_scan(scan, searched.segmentation)
            ident = _identified(seg, ready, searched, clock)
        # With the segmentation (corners or none), as every prior's search was before the
        # first search came: the poses judged already cost only their corners' part.
        fix = tracked(window, seg, ident)
        if fix is not None:
            return fix, False
    if seg is None:
        with clock("segmentation"):
            seg = segment_scan(scan, searched.segmentation)
    return _locate(scan, ready, fallback, t0, clock, seg, ident=ident), bool(priors)


def _identified(
    seg: Segmentation, ready: tuple[SurveyIndex, PanelSet], cfg: LocatorConfig, clock: _Clock
) -> PanelIdentification:
    """Stage 2: the scan's segments identified as beacon panels and corners."""
    with clock("identification"):
        return identify_panels(
            seg,
            ready[0].representatives,
            cfg.identification,
            survey_sigma_m=ready[1].worst_survey_sigma(cfg.noise.survey_sigma_m),
        )


def _locate(
    scan: Scan,
    ready: tuple[SurveyIndex, PanelSet],
    cfg: LocatorConfig,
    t0: float,
    clock: _Clock,
    seg: Segmentation | None,
    *,
    from_prior: list[Hypothesis] | None = None,
    before: tuple[Verified, ...] = (),
    ident: PanelIdentification | None = None,
    icp_memo: dict[int, Refinement] | None = None,
) -> Fix:
    """:func:`locate` from hypotheses of the prior's own search (``from_prior``, a
    batch of :func:`~mast.pipeline.tracking.prior_hypotheses`, or the window's centre,
    :func:`~mast.pipeline.tracking.centre_hypotheses`) or, without them, from the
    global ones (kept inside the prior's window, if there is one), on the scan's
    segmentation ``seg`` (made once for both) and its identification ``ident`` (made
    here when not given), against the survey's index and panels (``ready``); ``t0`` is
    when it began, ``clock`` what each stage has taken so far. The poses an earlier
    batch verified (``before``) compete with this batch's. The prior's poses are
    verified against the identified corners too: a beacon whose corner the scan shows
    is held to it, however the pose was found. Without ``seg`` (a prior's search on a
    scan not segmented) no corner is identified; ``icp_memo`` keeps the hypotheses' ICP
    for a second verification of the same ones."""
    noise = cfg.noise
    index, panels = ready
    found: dict[str, object] = {"config": cfg, "hypotheses": (), "verified": (), "chosen": None}

    def finish(
        status: str = "no_fix", reason: str | None = None, detail: str = "", **kw: object
    ) -> Fix:
        fields: dict[str, object] = {
            "status": status,
            "reason": reason,
            "detail": detail,
            "pose": None,
            "adjustment": None,
            "beacons": (),
            "panels": {},
            "points_used": 0,
            "observations": np.zeros(0, dtype=np.intp),
            "observation_panels": np.zeros(0, dtype=np.intp),
            **found,
            **kw,
        }
        now = time.perf_counter()
        if adjusting is not None:
            clock.spent["adjustment"] = clock.spent.get("adjustment", 0.0) + now - adjusting
        fields["elapsed_s"] = now - t0
        fields["stages_s"] = dict(clock.spent)
        return Fix(**fields)  # type: ignore[arg-type]

    adjusting: float | None = None  # when stage 5 began

    # Stages 1-3: segments (given), identified panels, pose hypotheses.
    found["segmentation"] = seg
    known = ident if ident is not None or seg is None else _identified(seg, ready, cfg, clock)
    found["identification"] = known
    if from_prior is not None:
        hyps = from_prior
    elif seg is None or known is None:
        raise ValueError("the global search needs the scan's segmentation")
    else:
        # Not narrowed by the prior here: ICP may carry a start from outside the window
        # into it, and a pose the global search finds inside must not be lost.
        with clock("hypotheses"):
            hyps = (
                pose_hypotheses(
                    known,
                    seg,
                    index,
                    cfg.hypotheses,
                    survey_sigma_m=panels.worst_survey_sigma(noise.survey_sigma_m),
                )
                if known.nodes
                else []
            )
    found["hypotheses"] = tuple(hyps)

    def verified_of(hypotheses: list[Hypothesis]) -> list[Verified]:
        """Stage 4: ICP and every beam's verdict, the poses inside the prior's window."""
        with clock("verification"):
            kept = verify(
                hypotheses,
                scan,
                panels,
                index,
                known,
                seg,
                noise,
                cfg.verification,
                settled=lambda kept: _settled(kept, cfg, corners=seg is not None),
                min_beacons=cfg.min_beacons,
                icp_memo=icp_memo,
            )
        return _admitted(kept, cfg)

    # The best pose by likelihood, unless ambiguous, or why there is none.
    verified = _ranked_together(list(before), verified_of(hyps) if hyps else [])
    best, reason, detail = _choose(verified, cfg)
    if not verified:
        where = "" if cfg.prior is None else f" within the prior {cfg.prior.pose}"
        reason, detail = "inconsistent", f"no pose hypothesis{where} is confirmed by the beams"
        if seg is None or known is None:
            pass  # a prior's search, its poses confirmed or not
        elif from_prior is None and not known.nodes:
            reason = "no_beacon"
            detail = f"{len(seg.segments)} segments, no beacon corner identified"
        elif from_prior is None and not hyps:
            seen = sorted({b for n in known.nodes for b in index.beacons_like(n.beacon)})
            detail = f"no pose from the corners of beacons {', '.join(seen[:6])}"
    if best is None and from_prior is None and seg is not None:
        # Stage 3b, when the corners give no fix: two beacons' middle panels.
        with clock("hypotheses"):
            free = panel_hypotheses(seg, index, cfg.hypotheses)
        found["hypotheses"] = (*hyps, *free)
        on_panels = verified_of(free) if free else []
        if on_panels:
            both = _ranked_together(verified, on_panels)
            best, why, said = _choose(both, cfg)
            if not verified:
                reason, detail = why, said
            verified = both
    found["verified"] = tuple(verified)
    found["chosen"] = best or (verified[0] if verified else None)
    if best is None:
        return finish(reason=reason, detail=detail)
    # Stage 5: adjustment on every beacon the beams confirm, then integrity and the global test.
    adjusting = time.perf_counter()
    agree = set(best.supported) | {
        b
        for b, c in best.checks.items()
        if c.coverage >= cfg.verification.min_coverage
        and c.hit >= cfg.verification.min_panel_points
    }
    keep = np.flatnonzero(np.isin(panels.beacon, [panels.number[b] for b in agree]))
    gate_sigmas = cfg.verification.gate_sigmas
    adjusted = adjust_on_panels(scan, best.pose, panels, keep, noise=noise, gate_sigmas=gate_sigmas)
    if isinstance(adjusted, str):
        return finish(reason="degenerate_geometry", detail=adjusted)
    obs, adj = adjusted
    obs, adj, outliers = snoop(obs, adj, noise=noise)

    def summary(
        obs: Observations, adj: Adjustment, tests: list[BeaconTest[int]] | None = None
    ) -> Residuals:
        return residual_summary(
            obs, adj, ids=panels.ids, panel_numbers=panels.panel, noise=noise, tests=tests
        )

    cleaned = exclude_inconsistent(obs, adj, noise=noise, min_beacons=cfg.min_beacons)
    if isinstance(cleaned, list):
        res = summary(obs, adj)
        names = sorted(panels.ids[b] for b in cleaned)
        ratios = sorted(res.beacon_tests.items(), key=lambda kv: -kv[1].ratio)
        most = (
            "; each beacon's test against the pose the others give, in multiples of its "
            "0.1 % critical value: " + ", ".join(f"{b} {t.ratio:.2f}" for b, t in ratios)
            if ratios
            else ""
        )
        return finish(
            reason="inconsistent",
            detail=f"the beacons seen disagree with each other; {' or '.join(names)} "
            f"may have been moved or mis-surveyed{most}",
            residuals=res,
        )
    obs, adj, excluded, more, tests = cleaned
    kept = np.unique(obs.beacon)
    if kept.size < cfg.min_beacons:
        # The beams confirmed two beacons at the verified pose, but the adjustment's gate
        # and data snooping kept the returns of fewer: one beacon's corner alone then
        # steers the pose (found on a drive: 1.5 m off with a 5 cm sigma). No fix.
        kept_names = ", ".join(sorted(panels.ids[b] for b in kept)) or "none"
        return finish(
            reason="one_beacon",
            detail=f"only beacon {kept_names} kept returns in the adjustment (of "
            f"{', '.join(best.supported)} confirmed at the verified pose)",
            residuals=summary(obs, adj, tests),
        )
    if adj.dof > 0 and chi2_sf(adj.reference_variance * adj.dof, adj.dof) < cfg.reject_alpha:
        return finish(
            reason="rejected",
            detail=f"reference variance {adj.reference_variance:.2f} on {adj.dof} degrees "
            "of freedom: the returns do not fit the surveyed beacons",
            residuals=summary(obs, adj, tests),
            refused=(float(adj.reference_variance), int(adj.dof)),
        )
    if np.any(obs.survey_var > 0):
        adj = replace(adj, covariance=adj.covariance + survey_covariance(adj, obs))
    panels_used: dict[str, list[int]] = {}
    for k in np.unique(obs.panel):
        panels_used.setdefault(panels.ids[panels.beacon[k]], []).append(int(panels.panel[k]))
    return finish(
        status="fix",
        pose=adj.pose,
        adjustment=adj,
        beacons=tuple(sorted(panels_used)),
        panels=panels_used,
        points_used=len(obs),
        observations=obs.beam,
        observation_panels=obs.panel,
        crb=cramer_rao_bound(adj.pose, obs.angles_rad, obs.normals, obs.offsets, noise=noise),
        excluded_beacons=tuple(panels.ids[b] for b in excluded),
        outliers_removed=outliers + more,
        residuals=summary(obs, adj, tests),
    )


@dataclass(frozen=True, slots=True)
class FixedPose:
    """A fixed pose of a sequence: when, where, and its covariance (E, N, A)."""

    stamp_ns: int
    pose: Pose2D
    covariance: NDArray[np.float64]


def _inside(inner: Prior, outer: Prior) -> bool:
    """Whether every pose ``inner`` admits, ``outer`` admits too."""
    if inner.azimuth_tolerance_rad is None or outer.azimuth_tolerance_rad is None:
        return False
    d = math.hypot(
        inner.pose.easting - outer.pose.easting, inner.pose.northing - outer.pose.northing
    )
    da = abs(math.remainder(inner.pose.azimuth - outer.pose.azimuth, math.tau))
    return (
        d + inner.radius_m <= outer.radius_m
        and da + inner.azimuth_tolerance_rad <= outer.azimuth_tolerance_rad
    )


@dataclass(frozen=True, slots=True)
class SequenceConfig:
    """How a scan sequence passes each fix on as the next scan's prior.

    Attributes
    ----------
    max_gap_s : float
        Scans further apart in time than this get no prior from each other.
    radius_m : float
        Largest radius of the prior around the previous fix.
    azimuth_tolerance_rad : float
        Largest azimuth window of the prior around the previous fix.
    vehicle : VehicleLimits
        What the vehicle can do: the wide window is as wide as it can have moved
        since the previous fix, plus its jolts, up to the largest window; the
        prediction's window (:meth:`predicted`) as far as it can have strayed from
        constant velocity, plus its jolts.
    prediction_sigmas : float
        The prediction's window holds this many of its standard deviations (from
        the two fixes' covariances) on top of that.
    """

    max_gap_s: float = 0.5
    radius_m: float = 0.5
    azimuth_tolerance_rad: float = math.radians(5.0)
    vehicle: VehicleLimits = field(default_factory=VehicleLimits)
    prediction_sigmas: float = 3.0

    def predicted(self, before: FixedPose, last: FixedPose, stamp_ns: int) -> Prior | None:
        """The window about ``last`` carried on to ``stamp_ns`` at the velocity since
        ``before`` (constant velocity), or None when either gap is longer than
        ``max_gap_s``. The secant velocity is that of the middle of the two fixes: with
        an acceleration ``a`` the prediction is off by ``a dt (dt + dt_fix) / 2``."""
        dt_fix = (last.stamp_ns - before.stamp_ns) * 1e-9
        dt = (stamp_ns - last.stamp_ns) * 1e-9
        if not (0.0 < dt_fix <= self.max_gap_s and 0.0 <= dt <= self.max_gap_s):
            return None
        k = dt / dt_fix
        p0, p1 = before.pose, last.pose
        turn = math.remainder(p1.azimuth - p0.azimuth, math.tau)
        pose = Pose2D(
            p1.easting + k * (p1.easting - p0.easting),
            p1.northing + k * (p1.northing - p0.northing),
            (p1.azimuth + k * turn) % math.tau,
        )
        cov = (1.0 + k) ** 2 * last.covariance + k**2 * before.covariance
        sigma_m = math.sqrt(max(float(np.linalg.eigvalsh(cov[:2, :2])[-1]), 0.0))
        sigma_rad = math.sqrt(max(float(cov[2, 2]), 0.0))
        unseen = 0.5 * dt * (dt + dt_fix)
        v = self.vehicle
        return Prior(
            pose,
            v.jolt_m + self.prediction_sigmas * sigma_m + v.max_accel_mps2 * unseen,
            v.jolt_rad + self.prediction_sigmas * sigma_rad + v.max_yaw_accel_rad_s2 * unseen,
        )

    def prior(self, pose: Pose2D, elapsed_s: float) -> Prior:
        """The window around ``pose``, ``elapsed_s`` after it was fixed."""
        return Prior(
            pose,
            min(self.radius_m, self.vehicle.jolt_m + self.vehicle.max_speed_mps * elapsed_s),
            min(
                self.azimuth_tolerance_rad,
                self.vehicle.jolt_rad + self.vehicle.max_turn_rad_s * elapsed_s,
            ),
        )


def locate_near(
    scan: Scan,
    survey: Survey,
    prior: Prior | None,
    *,
    config: LocatorConfig | None = None,
    narrow: Prior | None = None,
) -> Fix:
    """Locate a scan near a predicted pose first, from scratch when that gives no fix.

    The prior only narrows the search; a scan it cannot fix is located as if there
    were none, so a prediction can add fixes but never steer one. A prior in
    ``config`` takes precedence. ``narrow``, a window inside ``prior`` (the
    prediction's own few standard deviations), is searched before it: a scan it does
    not fix is searched as without it.
    """
    return Locator(survey, config).locate(scan, prior, narrow=narrow)


@dataclass(frozen=True, slots=True)
class SequenceStep:
    """One scan of a sequence located: the fix and how it was found.

    Attributes
    ----------
    fix : Fix
    tracked : bool
        The previous fix was close enough in time to be tried as the prior.
    track_lost : bool
        It was tried and gave no fix: the scan was located from scratch
        (global identification) instead, fixed or not.
    """

    fix: Fix
    tracked: bool
    track_lost: bool


class SequenceLocator:
    """Locate the scans of a sequence one at a time, each near the previous fix.

    A scan within ``max_gap_s`` of the last fixed one is first searched near that
    fix (:func:`locate_near`); when that gives no fix, or the gap is longer, the
    scan is located from scratch. A prior given in ``config`` applies to every
    scan and is never replaced. This is the one tracking rule of ``mast locate``
    on a bag and of ``mast live``.
    """

    def __init__(
        self,
        survey: Survey,
        *,
        config: LocatorConfig | None = None,
        sequence: SequenceConfig = SequenceConfig(),
    ) -> None:
        self.locator = Locator(survey, config)
        self.survey = survey
        self.config = self.locator.config
        self.sequence = sequence
        self._last: FixedPose | None = None
        self._before: FixedPose | None = None

    @property
    def last_pose(self) -> Pose2D | None:
        """The last fixed pose, the next scan's prior when close in time."""
        return None if self._last is None else self._last.pose

    @property
    def last_stamp_ns(self) -> int:
        """Stamp of the last fixed scan (0 before the first fix)."""
        return 0 if self._last is None else self._last.stamp_ns

    def assume(self, pose: Pose2D | None, stamp_ns: int = 0) -> None:
        """Take ``pose`` (at ``stamp_ns``) as the last fix, or forget it (None); either
        way no velocity is known until the next two fixes."""
        self._before = None
        self._last = None if pose is None else FixedPose(stamp_ns, pose, np.zeros((3, 3)))

    def step(self, scan: Scan) -> SequenceStep:
        """Locate ``scan`` and remember its pose when fixed.

        Near the last fix, the constant-velocity prediction of the last two
        (:meth:`SequenceConfig.predicted`) is searched first, then the window of all
        the vehicle can have done since the last fix, then the whole survey.
        """
        cfg, seq = self.config, self.sequence
        prior = narrow = None
        last = self._last
        if last is not None and abs(scan.stamp_ns - last.stamp_ns) <= seq.max_gap_s * 1e9:
            prior = seq.prior(last.pose, abs(scan.stamp_ns - last.stamp_ns) / 1e9)
            if self._before is not None:
                narrow = seq.predicted(self._before, last, scan.stamp_ns)
        fix, lost = self.locator._near(scan, prior, narrow)
        tracked = cfg.prior is None and prior is not None
        if fix.ok and fix.pose is not None and fix.adjustment is not None:
            self._before = last
            self._last = FixedPose(scan.stamp_ns, fix.pose, fix.adjustment.covariance)
        return SequenceStep(fix, tracked, lost)


def locate_sequence(
    scans: Iterable[Scan],
    survey: Survey,
    *,
    config: LocatorConfig | None = None,
    sequence: SequenceConfig = SequenceConfig(),
) -> Iterator[Fix]:
    """Fix every scan of a sequence, each with the previous fix as its prior when close in time
    (:class:`SequenceLocator`)."""
    tracker = SequenceLocator(survey, config=config, sequence=sequence)
    for scan in scans:
        yield tracker.step(scan).fix
