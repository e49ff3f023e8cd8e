"""The ladder of ``arfi reproduce``: for the same seeded aberrations, what each path to a
correction recovers, side by side.

Rungs, each on the same repeat's aberration, calibration and noisy images:

1. *single image (paper)*: the paper's loop 1, 16 group phases from one aberrated image;
2. *loop 2*: the paper's loop 2, three more acquisitions with the current correction applied;
3. *diversity*: three more images with seeded random known group phases (per element for the
   1024-aberration case, from three defocused images: :func:`defocused_images`);
4. *CT-like prediction alone*: a seeded prediction of the aberration with a realistic error
   (:func:`predicted_aberration`), subtracted as it is;
5. *prediction + MR-ARFI*: the posterior estimate from the prediction and the images (one image
   per group for the 16-aberration case; the aberrated and three defocused images per element for
   1024, with the prediction's errors as a smooth field). The element basis of rung 3 serves
   rung 5 (the same images).

Each rung reports the mean recovered fraction (focal ARFI of the corrected beam over the ideal,
on noise-free images), how many estimates the method flagged ambiguous, and the seconds spent.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from arfi.analysis.loop import loop2
from arfi.estimation import recovered_fraction
from arfi.simulation import Simulation

#: The prediction's error model: a smooth field over the aperture (15 mm correlation length,
#: 5 rad peak to peak) plus independent per-element jitter (0.3 rad), about 1.3 rad RMS: CT-based
#: skull simulations err where skull thickness or sound speed is misjudged, which varies over
#: centimetres, and miss element-scale detail. Alone such a prediction leaves about 0.7 of the
#: ideal focal ARFI (0.85 of the focal pressure: ARFI scales with intensity).
PREDICTION_ERROR = {"correlation_length_mm": 15.0, "peak_to_peak_rad": 5.0, "jitter_rad": 0.3}
#: The expected error per predicted phase that the posterior is given (rad). Smaller than the
#: error's RMS, which includes jitter no image resolves, so a prior of the full RMS lets the images'
#: noise move the phases more than they inform them (BENCHMARKS.md, "Ladder constants").
PREDICTION_STD_RAD = 0.8
#: Per element, the prediction's errors are given to the posterior as a smooth field correlated
#: over the error model's length (``prior_correlation_mm``): 1024 independent errors are more than
#: 4 images determine, a smooth field is not (BENCHMARKS.md, "Ladder constants").
PREDICTION_CORRELATION_MM = PREDICTION_ERROR["correlation_length_mm"]
#: Extra acquisitions per repeat for the loop-2 and diversity rungs.
EXTRA_IMAGES = 3

#: Per element (the 1024 case) the diversity images are defocused: the focus moved along the beam
#: axis by these (mm) with known phases (``Simulation.focus_shift_phases``). A defocused beam stays
#: bright over more pixels and tells an aberration from its twin, so it informs more per image
#: than random known group phases (BENCHMARKS.md, "Ladder constants").
DEFOCUS_MM = (5.0, -5.0, 10.0)

RUNGS = ["single image (paper)", "loop 2", "diversity", "CT-like prediction alone", "prediction + MR-ARFI"]


@dataclass
class Rung:
    """One rung over the repeats."""

    name: str
    what: str
    """What was estimated from what."""
    recovered_fractions: list[float]
    ambiguous: int
    seconds: float

    @property
    def mean_recovered_fraction(self) -> float:
        return float(np.mean(self.recovered_fractions))

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "what": self.what,
            "recovered_fractions": self.recovered_fractions,
            "mean_recovered_fraction": self.mean_recovered_fraction,
            "ambiguous": self.ambiguous,
            "seconds": self.seconds,
        }


def predicted_aberration(sim: Simulation, applied: NDArray[np.float64], seed: int) -> NDArray[np.float64]:
    """A CT-like prediction of the per-element aberration ``applied``: it plus a seeded error
    drawn from :data:`PREDICTION_ERROR` (seed ``1000 + seed``, independent of the aberration's)."""
    return np.asarray(applied, dtype=np.float64) + sim.skull_phases(1000 + seed, **PREDICTION_ERROR)


class Ladder:
    """Collects each rung's results over the repeats of ``case`` (16 or 1024)."""

    def __init__(self, case: int) -> None:
        per_element = case == 1024
        self.what = {
            RUNGS[0]: "16 group phases, 1 image",
            RUNGS[1]: f"16 group phases, 1 + {EXTRA_IMAGES} loop-2 images",
            RUNGS[2]: (
                f"1024 element phases, 1 + {len(DEFOCUS_MM)} images with the focus moved by "
                f"{', '.join(f'{z:+g}' for z in DEFOCUS_MM)} mm along the axis"
                if per_element
                else f"16 group phases, 1 + {EXTRA_IMAGES} images with known random phases"
            ),
            RUNGS[3]: f"prediction error {PREDICTION_ERROR['peak_to_peak_rad']:g} rad peak to peak over "
            f"{PREDICTION_ERROR['correlation_length_mm']:g} mm + {PREDICTION_ERROR['jitter_rad']:g} rad jitter",
            RUNGS[4]: (
                f"1024 element phases, smooth prior ({PREDICTION_STD_RAD} rad over {PREDICTION_CORRELATION_MM:g} mm) + "
                "1 + "
                f"{len(DEFOCUS_MM)} defocused images"
                if per_element
                else f"16 group phases, prior ({PREDICTION_STD_RAD} rad) + 1 image"
            ),
        }
        self.values: dict[str, list[float]] = {n: [] for n in RUNGS}
        self.flags = {n: 0 for n in RUNGS}
        self.seconds = {n: 0.0 for n in RUNGS}

    def add(self, name: str, fraction: float, ambiguous: bool, seconds: float) -> None:
        self.values[name].append(fraction)
        self.flags[name] += int(ambiguous)
        self.seconds[name] += seconds

    def rungs(self) -> list[Rung]:
        return [Rung(n, self.what[n], self.values[n], self.flags[n], self.seconds[n]) for n in RUNGS]


def defocused_images(
    sim: Simulation, applied: NDArray[np.float64], aberrated: NDArray[np.float64], noise: float, seed: int
) -> tuple[list[NDArray[np.float64]], list[Any]]:
    """The aberrated image and one noisy image per :data:`DEFOCUS_MM` step (noise seeds
    ``70_000 + 100·seed + k``), with their known per-element phases (None for the first)."""
    images, known = [aberrated], [None]  # type: list[NDArray[np.float64]], list[NDArray[np.float64] | None]
    for k, dz in enumerate(DEFOCUS_MM):
        d = sim.focus_shift_phases((0.0, 0.0, dz))
        images.append(sim.arfi_image(applied + d, noise_rad=noise, seed=70_000 + 100 * seed + k))
        known.append(d)
    return images, known


def climb(
    sim: Simulation,
    model: Simulation,
    case: int,
    applied: NDArray[np.float64],
    images: list[NDArray[np.float64]],
    known: list[Any],
    acquire: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    seed: int,
    focus: Callable[[NDArray[np.float64]], float],
    rungs: Ladder,
    paper: tuple[float, bool, float] | None = None,
) -> None:
    """Runs the rungs for one repeat and adds them to ``rungs``. ``images``/``known``: the
    aberrated image and the diversity images with their known group phases; ``acquire(added)``:
    a new noisy image with per-group phases added; ``focus(correction)``: the recovered fraction
    of a per-element correction; ``paper``: the study's own paper-faithful result (recovered
    fraction, ambiguous, seconds), when it ran one, instead of running it again."""
    if paper is None:
        t = time.perf_counter()
        est = model.estimate(images[:1], method="nelder-mead", seed=seed)
        paper = (focus(est.phases_rad[model.groups]), est.ambiguous, time.perf_counter() - t)
    rungs.add(RUNGS[0], *paper)

    t = time.perf_counter()
    loop = loop2(model, images[0], acquire, iterations=EXTRA_IMAGES, method="lbfgs", seed=seed)
    last = loop.steps[-1].estimate
    rungs.add(
        RUNGS[1],
        focus(loop.correction_rad[model.groups]),
        bool(last is not None and last.ambiguous),
        time.perf_counter() - t,
    )

    fitted = model.with_groups(sim.n_elements) if case == 1024 else model
    t = time.perf_counter()
    est = fitted.estimate(images, known, method="lbfgs", seed=seed)
    rungs.add(RUNGS[2], focus(est.phases_rad[fitted.groups]), est.ambiguous, time.perf_counter() - t)

    prediction = predicted_aberration(sim, applied, seed)
    rungs.add(RUNGS[3], focus(prediction), False, 0.0)

    t = time.perf_counter()
    data, data_known, length = (images, known, PREDICTION_CORRELATION_MM) if case == 1024 else (images[:1], None, None)
    est = fitted.estimate(
        data,
        data_known,
        method="lbfgs",
        seed=seed,
        prior=prediction,
        prior_std_rad=PREDICTION_STD_RAD,
        prior_correlation_mm=length,
    )
    rungs.add(RUNGS[4], focus(est.phases_rad[fitted.groups]), est.ambiguous, time.perf_counter() - t)


def summary_line(ladder: list[Rung], paper: float) -> str:
    """One line: each rung's mean recovered fraction, next to the paper's."""
    parts = ", ".join(f"{r.name} {r.mean_recovered_fraction:.2f}" for r in ladder)
    return f"recovered fraction by path: {parts} (paper {paper})"


def focus_of(
    sim: Simulation, applied: NDArray[np.float64], ideal_peak: float
) -> Callable[[NDArray[np.float64]], float]:
    """The recovered fraction of a per-element correction of the aberration ``applied``."""

    def focus(correction: NDArray[np.float64]) -> float:
        return recovered_fraction(sim.focal_arfi(sim.arfi_image(applied - np.asarray(correction)))[0], ideal_peak)

    return focus
