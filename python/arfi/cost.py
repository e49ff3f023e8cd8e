"""The hybrid cost (paper Eq. 4) as an object: evaluate it, its gradient and its kernels."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from arfi.checks import as_phases


@dataclass(frozen=True)
class CostTerm:
    """One image as the cost sees it. Each masked pixel ``i`` is a Hermitian form in the group
    drives ``v_g = exp(i·(phi_g + offset_g))``::

        d_i = sum_g diagonal[i, g] + 2·Re sum_{g<h} upper[i, k(g, h)]·conj(v_g)·v_h

    with the pairs ``(g, h)`` in row order ``(0,1), (0,2), …, (G-2, G-1)`` (``numpy.triu_indices(G, 1)``).
    The kernels are in rad (the calibrated amplitude is applied)."""

    diagonal: NDArray[np.float64]
    """``K_i[g, g]``, shape (n_pixels, G), rad."""
    upper: NDArray[np.complex128]
    """``K_i[g, h]`` for ``g < h``, shape (n_pixels, G·(G-1)/2), rad."""
    measured_rad: NDArray[np.float64]
    """The measured ARFI phase at the masked pixels, shape (n_pixels,)."""
    offset_rad: NDArray[np.float64]
    """The known phases added to every group for this image, shape (G,)."""


class CostModel:
    """``J(phi) = sum_k sum_{i in mask_k} (s·d_k,i(phi + offset_k) - m_k,i)²`` over the images, with
    ``s = 1`` or, with ``fit_amplitude``, the least-squares amplitude scale for each ``phi``. This is
    what ``Simulation.estimate`` minimises; use it to drive your own optimiser (e.g.
    ``scipy.optimize.minimize(model.cost_and_gradient, x0, jac=True)``) or to check the model.
    Build it with ``Simulation.cost_model``."""

    def __init__(self, core: Any):
        self._core = core

    @property
    def n_groups(self) -> int:
        """Number of phases the cost takes."""
        return int(self._core.n_groups)

    @property
    def n_pixels(self) -> int:
        """Masked pixels over all images."""
        return int(self._core.n_pixels)

    @property
    def fit_amplitude(self) -> bool:
        return bool(self._core.fit_amplitude)

    @property
    def noise_rad(self) -> float:
        """Noise standard deviation of the images' backgrounds (rad, RMS over images)."""
        return float(self._core.noise_rad)

    def cost(self, phases: ArrayLike) -> float:
        """``J`` (rad²) at group phases (rad)."""
        return float(self._core.cost(self._phases(phases)))

    def cost_and_gradient(self, phases: ArrayLike) -> tuple[float, NDArray[np.float64]]:
        """``J`` (rad²) and ``∂J/∂phi_g`` (rad²/rad), analytic."""
        j, g = self._core.cost_and_gradient(self._phases(phases))
        return float(j), g

    def scale(self, phases: ArrayLike) -> float:
        """The amplitude scale ``s`` at ``phases`` (1 unless ``fit_amplitude``)."""
        return float(self._core.scale(self._phases(phases)))

    def terms(self) -> list[CostTerm]:
        """Per image: the kernels of its masked pixels, the measured values and the offsets."""
        return [CostTerm(**t) for t in self._core.terms()]

    def _phases(self, phases: ArrayLike) -> NDArray[np.float64]:
        p = as_phases(phases, "phases")
        assert p is not None
        return p

    def __repr__(self) -> str:
        return f"CostModel(n_groups={self.n_groups}, n_pixels={self.n_pixels}, fit_amplitude={self.fit_amplitude})"
