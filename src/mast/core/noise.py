"""The one noise model every stage uses: range, beam angle and survey precision."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_ANGLE_SIGMA_RAD",
    "DEFAULT_RANGE_SIGMA_M",
    "DEFAULT_SURVEY_SIGMA_M",
    "NoiseModel",
]

#: A typical 2D scanner's range precision (metres) and beam-angle precision (radians).
DEFAULT_RANGE_SIGMA_M = 0.01
DEFAULT_ANGLE_SIGMA_RAD = 0.0
#: A surveyed edge coordinate's precision (metres): a total station at a few tens of metres.
DEFAULT_SURVEY_SIGMA_M = 0.003


@dataclass(frozen=True, slots=True)
class NoiseModel:
    """A-priori precisions of a scan's observations and of the survey.

    Attributes
    ----------
    range_sigma_m : float
        Standard deviation of one range, metres.
    angle_sigma_rad : float
        Standard deviation of one beam angle, radians.
    survey_sigma_m : float
        Standard deviation of a surveyed edge coordinate, metres (0 for an
        exact, simulated survey).
    """

    range_sigma_m: float = DEFAULT_RANGE_SIGMA_M
    angle_sigma_rad: float = DEFAULT_ANGLE_SIGMA_RAD
    survey_sigma_m: float = DEFAULT_SURVEY_SIGMA_M

    def variance(self, d_range_d_angle: ArrayLike) -> NDArray[np.float64]:
        """Variance of a range observation: ``sigma_r^2 + (d rho / d phi * sigma_phi)^2``.

        ``d_range_d_angle`` is how fast the predicted range changes with the beam
        angle (:func:`mast.pipeline.adjustment.range_model`): a beam meeting a
        surface obliquely turns its angle error into a range error.
        """
        d = np.asarray(d_range_d_angle, dtype=float)
        return np.asarray(self.range_sigma_m**2 + (d * self.angle_sigma_rad) ** 2)

    def gate_variance(self, d_range_d_angle: ArrayLike) -> NDArray[np.float64]:
        """Variance of a range about a surveyed panel: the observation's and the survey's."""
        return np.asarray(self.variance(d_range_d_angle) + self.survey_sigma_m**2)

    @property
    def gate_sigma_m(self) -> float:
        """Standard deviation of a return about its surveyed panel, angle error aside."""
        return float(np.hypot(self.range_sigma_m, self.survey_sigma_m))
