"""Results of the model-discrepancy workflow (SPEC §5 ``arfi diagnose``, §7)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class Diagnosis:
    """The effects added to the model, in order, and the gap before and after.

    Each entry of ``effects`` has ``name``, ``params`` (names carry their units), ``cost_before``,
    ``cost_after``, ``evidence`` (the BIC gain in units of the noise variance) and the
    ``candidates`` tried at that step; ``rejected`` are the candidates of the last round, none of
    which had positive evidence."""

    effects: list[dict[str, Any]]
    rejected: list[dict[str, Any]]
    cost_initial: float
    cost_final: float
    noise_floor: float
    """Noise standard deviation (rad) from the image background."""
    n_pixels: int
    residual_rms_initial: float
    residual_rms_final: float
    model_initial: NDArray[np.float64] = field(repr=False)
    model_final: NDArray[np.float64] = field(repr=False)

    @property
    def names(self) -> list[str]:
        """Names of the effects added, in order."""
        return [e["name"] for e in self.effects]

    def to_dict(self) -> dict[str, Any]:
        """The JSON of SPEC §5 (without the model images)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("model_initial", "model_final")}
