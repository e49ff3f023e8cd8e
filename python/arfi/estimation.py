"""Results of calibration and hybrid estimation (what ``arfi calibrate`` and ``arfi estimate``
report), and the metrics that score a correction: recovered fraction, gain and phase error."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: The estimators of ``Simulation.estimate`` (``method``).
METHODS = ("nelder-mead", "pso", "lbfgs")


@dataclass(frozen=True)
class Calibration:
    """Broadening filter fitted to a no-aberration image (paper Eq. 2)."""

    broadening_width_mm: float
    amplitude: float
    """Scale from broadened force density (N/m³) to ARFI phase (rad)."""
    cost: float
    n_pixels: int
    noise_rad: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Estimate:
    """A hybrid estimate of the aberration, one phase per group (or per element with one group
    per element). Subtract ``phases_rad`` to correct."""

    phases_rad: NDArray[np.float64]
    cost: float
    evaluations: int
    seconds: float
    ambiguous: bool
    """True when clearly different solutions fit within the noise (see ``worst_recovery`` and ``suggested_phases_rad``);
    per element with a prior, end points of searches of the element posterior from draws of the prior."""
    method: str
    stop: str
    """Why the search ended: ``"converged"``, ``"evaluation limit"``, ``"time limit"``, ``"interrupted"``, or
    ``"prediction kept"`` (no search: see ``kept_prediction``)."""
    noise_floor: float
    n_pixels: int
    scale: float
    margin: float
    worst_recovery: float
    """The least focus (of the ideal) a correction with ``phases_rad`` leaves if another candidate were the truth
    (1 with one candidate); ``ambiguous`` when below 0.9."""
    candidate_phases_rad: list[list[float]]
    candidate_costs: list[float]
    candidate_recoveries: list[float]
    suggested_phases_rad: NDArray[np.float64]
    """Known group phases to add for one more acquisition that would best separate the candidates; per element with
    ``suggest=True`` (or with a prior, when ``ambiguous``), the known per-element phases of ``next_acquisition``; per
    element with a prior otherwise zeros."""
    suggested_separation: float
    cost_history: NDArray[np.float64] = field(repr=False)
    misfit: float = float("nan")
    """Best cost over its noise expectation, ``cost / (n_pixels·noise_floor²)``: about 1 when the model explains the images."""
    model_mismatch: bool = False
    """The cost is above the 95 % chi-square point of the noise and the misfit above 1.2 (what the model leaves is at
    least 0.45 of the noise's RMS): the model cannot explain the images (e.g. element-level aberrations fitted with
    group phases) and the correction may make the focus worse; check it with loop 2. Not judged (False) when
    ``kept_prediction``: nothing was fitted."""
    group_phases_rad: NDArray[np.float64] | None = None
    """Per-element estimation without a prior: the default-group estimate that warm-started it (with a prior the
    search starts from the prediction)."""
    underdetermined: bool = False
    """Per-element estimation only: the images cannot determine a phase per element: one acquisition (one image, or
    repeats with the same known phases), or, without a prior, fewer masked pixels than phases. Then also
    ``ambiguous``, unless the prediction was kept (``kept_prediction``)."""
    kept_prediction: bool = False
    """Per-element estimation with a prior from one acquisition (one image, or repeats with the same known phases):
    ``phases_rad`` is the prediction itself, unsearched. One in-focus image cannot check a per-element correction of a
    prediction (a correction that fits it better than the truth can leave less focus than the prediction), so the
    prediction is kept until a second acquisition with other known phases (e.g. ``next_acquisition``, a defocus) is
    given: over six skull screens this gave up a mean gain of 0.03 of the ideal focus so as never to lose one (seed 1
    lost 0.19). ``misfit`` then measures the prediction against the image, and ``model_mismatch`` is not judged."""
    prior_used: bool = False
    """A predicted aberration entered the estimate (the posterior optimum; ``ambiguous`` judged on the posterior)."""
    posterior_cost: float | None = None
    """With a prior: the minimised negative log posterior (at the prediction when ``kept_prediction``), ``cost / (2·noise_floor²) + Σ (1 - cos(phi - prior)) / prior_std_rad²``."""
    nuisance: dict[str, Any] | None = None
    """Per-element estimates that fitted nuisance parameters (``fit_nuisance``): ``fitted`` (their names), ``scale``,
    ``broadening_width_mm``, ``shift_mm`` (u, v), and per image ``background_offset_rad`` and
    ``background_slope_rad_per_mm`` (u, v); the model's values for those not fitted."""
    next_acquisition: dict[str, Any] | None = None
    """Per-element estimates made with ``suggest=True``: the next image to take, as a focus shift
    ``focus_shift_mm`` (x, y, z; its known phases are ``suggested_phases_rad``, or
    ``Simulation.focus_shift_phases``), chosen among ``candidates`` (each ``focus_shift_mm`` and
    ``expected_focus``) for raising most the focal intensity the correction is expected to leave
    (relative to the ideal, on the linearised posterior): ``expected_focus_now`` from the images so
    far, ``expected_focus`` with the suggested one added."""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k, v in d.items():
            if isinstance(v, np.ndarray):
                d[k] = v.tolist()
        return d


def recovered_fraction(focal_corrected: float, focal_ideal: float) -> float:
    """Focal ARFI of the corrected beam over that of the ideal beam (paper: 0.83 for the
    16-aberration case, 0.39 for 1024)."""
    return float(focal_corrected / focal_ideal)


def gain(focal_corrected: float, focal_aberrated: float) -> float:
    """Corrected over aberrated focal ARFI, minus one (paper: +44 % for 16 aberrations, +52 % for 1024)."""
    return float(focal_corrected / focal_aberrated - 1.0)


def wrap(p: ArrayLike) -> NDArray[np.float64]:
    """Wraps phases to (-pi, pi]."""
    w = np.mod(np.asarray(p, dtype=np.float64) + np.pi, 2 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def phase_error(estimate: ArrayLike, truth: ArrayLike) -> float:
    """RMS of the wrapped difference estimate − truth after removing the best common offset (paper:
    0.42 rad for 16 aberrations, 2.10 rad for 1024)."""
    d = np.asarray(estimate, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    offset = np.angle(np.sum(np.exp(1j * d)))
    return float(np.sqrt(np.mean(wrap(d - offset) ** 2)))
