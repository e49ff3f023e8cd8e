"""Results of calibration and hybrid estimation (what ``arfi calibrate`` and ``arfi estimate``
report), and the metrics that score a correction: recovered fraction, gain and phase error."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._core import (
    METHODS,
    Calibration,
    Estimate,
    EstimateOptions,
    EstimatePriorCheck,
    EstimateSupport,
    NextAcquisition,
    NuisanceFit,
    ShiftCandidate,
)
from ._core import phase_error as _phase_error
from ._core import wrap_phases as _wrap_phases

__all__ = [
    "METHODS",
    "Calibration",
    "Estimate",
    "EstimateOptions",
    "EstimatePriorCheck",
    "EstimateSupport",
    "NextAcquisition",
    "NuisanceFit",
    "ShiftCandidate",
    "gain",
    "phase_error",
    "recovered_fraction",
    "wrap",
]


def recovered_fraction(focal_corrected: float, focal_ideal: float) -> float:
    """Focal ARFI of the corrected beam over that of the ideal beam (paper: 0.83 for the
    16-aberration case, 0.39 for 1024)."""
    return float(focal_corrected / focal_ideal)


def gain(focal_corrected: float, focal_aberrated: float) -> float:
    """Corrected over aberrated focal ARFI, minus one (paper: +44 % for 16 aberrations, +52 % for 1024)."""
    return float(focal_corrected / focal_aberrated - 1.0)


def wrap(p: ArrayLike) -> NDArray[np.float64]:
    """Wraps phases to (-pi, pi]."""
    return _wrap_phases(np.ascontiguousarray(p, dtype=np.float64))


def phase_error(estimate: ArrayLike, truth: ArrayLike) -> float:
    """RMS of the wrapped difference estimate − truth after removing the best common offset (paper:
    0.42 rad for 16 aberrations, 2.10 rad for 1024)."""
    return _phase_error(
        np.ascontiguousarray(estimate, dtype=np.float64).ravel(), np.ascontiguousarray(truth, dtype=np.float64).ravel()
    )
