"""The paper's loop 2 (Vyas et al. 2014, Fig. 1): successive MR-ARFI images, each taken with the
current correction applied, all fitted jointly; the correction kept is the one whose *measured*
focus is highest, so a correction that the scanner shows to be worse is never kept."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi.checks import as_phases
from arfi.estimation import Estimate, phase_error
from arfi.simulation import Simulation


@dataclass(frozen=True)
class LoopStep:
    """One acquisition of the loop: the correction applied for it and its measured focus."""

    correction_rad: NDArray[np.float64]
    """Per group (or element); the image was taken with ``-correction_rad`` added to the steering."""
    focal_measured_rad: float
    """Focal ARFI of the measured image: its maximum ARFI phase (rad)."""
    focal_robust_rad: float
    """The mean of the 3 x 3 pixels around the maximum of the 3 x 3-smoothed image, the value the
    loop compares (a ninth of the noise variance, and less biased by noise than the maximum)."""
    estimate: Estimate | None = field(default=None, repr=False)
    """The joint estimate that proposed this correction (None for the first image)."""


@dataclass(frozen=True)
class LoopResult:
    """Outcome of :func:`loop2`."""

    correction_rad: NDArray[np.float64]
    """The correction kept: subtract it from the drive phases (zero when none was measured better)."""
    kept: int
    """Index in ``steps`` of the kept correction (0 = no correction)."""
    steps: list[LoopStep]
    margin_rad: float
    """How much higher a measured focus had to be than the kept one to replace it."""
    images: list[NDArray[np.float64]] = field(repr=False)
    known: list[NDArray[np.float64] | None] = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {
            "correction_rad": self.correction_rad.tolist(),
            "kept": self.kept,
            "margin_rad": self.margin_rad,
            "focal_measured_rad": [s.focal_measured_rad for s in self.steps],
            "focal_robust_rad": [s.focal_robust_rad for s in self.steps],
            "ambiguous": [None if s.estimate is None else s.estimate.ambiguous for s in self.steps],
        }


def robust_focal(image: NDArray[np.float64], region: NDArray[np.bool_] | None = None) -> float:
    """The largest 3 x 3 box mean of the image (the mean over the 3 x 3 pixels centred on the
    maximum of the box-smoothed image) among the pixels of ``region`` (default: all), e.g.
    ``Simulation.focal_region``; pixels without signal (NaN) are left out of each mean."""
    padded = np.pad(np.asarray(image, dtype=np.float64), 1, mode="edge")
    n0, n1 = image.shape
    boxes = np.stack([padded[a : a + n0, b : b + n1] for a in range(3) for b in range(3)])
    counts = np.sum(np.isfinite(boxes), axis=0)
    smooth = np.where(counts > 0, np.nansum(boxes, axis=0) / np.maximum(counts, 1), np.nan)
    if region is not None:
        smooth = np.where(region, smooth, np.nan)
    return float(np.nanmax(smooth))


def loop2(
    sim: Simulation,
    image: ArrayLike,
    acquire: Callable[[NDArray[np.float64]], ArrayLike],
    iterations: int = 2,
    known: ArrayLike | None = None,
    extra_images: Sequence[ArrayLike] | None = None,
    extra_known: Sequence[ArrayLike | None] | None = None,
    margin_sigma: float = 2.0,
    **estimate_options: Any,
) -> LoopResult:
    """Runs loop 2 from a first (aberrated) ``image`` taken with ``known`` phases added.

    Each iteration estimates the aberration jointly from every image so far (``sim.estimate``
    with ``estimate_options``), calls ``acquire(added)`` for a new image with ``added =
    -correction`` (rad, per group or element, added to the steering: an image sidecar's
    ``applied_phases_rad``)
    and measures its focal ARFI. A correction replaces the kept one only if its measured focus is
    higher (:func:`robust_focal`, noise ``σ/3`` for noise floor ``σ``) by ``margin_sigma·√2·σ/3``, so noise alone
    rarely makes it
    switch; the loop ends early when a new estimate repeats the last correction (within 0.05 rad).
    ``extra_images`` (with ``extra_known``) are further images for the joint fit, e.g. diversity
    acquisitions."""
    if not 1 <= int(iterations) <= 20:
        raise ValueError(f"iterations: must be between 1 and 20, got {iterations}")
    if not (np.isfinite(margin_sigma) and margin_sigma >= 0):
        raise ValueError(f"margin_sigma: must be a finite number >= 0, got {margin_sigma}")
    if not callable(acquire):
        raise ValueError("acquire: must be a callable taking the added phases (rad) and returning an image")
    extra = list(extra_images or [])
    extra_k = list(extra_known) if extra_known is not None else [None] * len(extra)
    if len(extra_k) != len(extra):
        raise ValueError(f"extra_known: has {len(extra_k)} entries for {len(extra)} extra images")
    first = np.asarray(image, dtype=np.float64)
    images: list[NDArray[np.float64]] = [first, *[np.asarray(e, dtype=np.float64) for e in extra]]
    knowns: list[NDArray[np.float64] | None] = [as_phases(known, "known")] + [
        as_phases(k, f"extra_known[{i}]") for i, k in enumerate(extra_k)
    ]
    region = sim.focal_region
    steps = [
        LoopStep(
            correction_rad=np.zeros(sim.n_groups),
            focal_measured_rad=sim.focal_arfi(first)[0],
            focal_robust_rad=robust_focal(first, region),
        )
    ]
    kept, margin = 0, 0.0
    for _ in range(int(iterations)):
        est = sim.estimate(images, knowns, **estimate_options)
        correction = np.asarray(est.phases_rad, dtype=np.float64)
        if len(steps) > 1 and phase_error(correction, steps[-1].correction_rad) < 0.05:
            break
        added = -correction
        new = np.asarray(acquire(added), dtype=np.float64)
        if new.shape != first.shape or np.any(np.isinf(new)) or not np.any(np.isfinite(new)):
            raise ValueError(
                f"acquire: returned an image of shape {new.shape} (or with infinite values, or all NaN); expected "
                f"{first.shape}"
            )
        images.append(new)
        knowns.append(added)
        steps.append(
            LoopStep(
                correction_rad=correction,
                focal_measured_rad=sim.focal_arfi(new)[0],
                focal_robust_rad=robust_focal(new, region),
                estimate=est,
            )
        )
        margin = margin_sigma * np.sqrt(2.0) * est.noise_floor / 3.0
        if steps[-1].focal_robust_rad > steps[kept].focal_robust_rad + margin:
            kept = len(steps) - 1
    return LoopResult(
        correction_rad=steps[kept].correction_rad,
        kept=kept,
        steps=steps,
        margin_rad=float(margin),
        images=images,
        known=knowns,
    )
