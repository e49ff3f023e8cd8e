"""The hybrid cost (paper Eq. 4) and its gradient in plain NumPy, from the per-pixel group kernels
that ``arfi.CostModel.terms()`` exposes: the same algorithm as has-core's ``HybridCost``
(crates/has-core/src/inverse/cost/mod.rs), written for the benchmark and used by the tests as a reference.

Each masked pixel is ``d_i = Σ_g K_i[g,g] + 2·Re Σ_{g<h} K_i[g,h]·conj(v_g)·v_h`` with
``v = exp(i·(phi + offset))``; ``J = Σ (s·d - m)²``; ``∂J/∂phi_g = 4·s·Im(conj(v_g)·(R v)_g)``
with ``R = Σ_i r_i·K_i`` (Hermitian), ``r = s·d - m``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

import numpy as np
from numpy.typing import NDArray


@cache
def _pairs(g: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The pairs ``g < h`` in the kernels' row order."""
    return np.triu_indices(g, 1)


def _drives(term, phases: NDArray[np.float64]) -> NDArray[np.complex128]:
    return np.exp(1j * (phases + term.offset_rad))


def images(terms: Sequence, phases: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """The model at the masked pixels of every term, rad."""
    a, b = _pairs(len(phases))
    out = []
    for t in terms:
        v = _drives(t, phases)
        out.append(t.diagonal.sum(axis=1) + 2.0 * (t.upper @ (np.conj(v[a]) * v[b])).real)
    return out


def _scale(terms: Sequence, model: list[NDArray[np.float64]], fit_amplitude: bool) -> float:
    if not fit_amplitude:
        return 1.0
    d = np.concatenate(model)
    dd = float(d @ d)
    return float(d @ np.concatenate([t.measured_rad for t in terms])) / dd if dd > 0 else 1.0


def cost(terms: Sequence, phases: NDArray[np.float64], fit_amplitude: bool = False) -> float:
    """``J`` (rad²)."""
    model = images(terms, phases)
    s = _scale(terms, model, fit_amplitude)
    return float(sum(np.sum((s * d - t.measured_rad) ** 2) for d, t in zip(model, terms)))


def cost_and_gradient(
    terms: Sequence, phases: NDArray[np.float64], fit_amplitude: bool = False
) -> tuple[float, NDArray[np.float64]]:
    """``J`` and ``∂J/∂phi`` (the fitted scale drops out of the gradient: envelope theorem)."""
    g = len(phases)
    a, b = _pairs(g)
    model = images(terms, phases)
    s = _scale(terms, model, fit_amplitude)
    total, grad = 0.0, np.zeros(g)
    for t, d in zip(terms, model):
        v = _drives(t, phases)
        r = s * d - t.measured_rad
        total += float(r @ r)
        big_r = np.diag((r @ t.diagonal).astype(np.complex128))
        upper = r @ t.upper
        big_r[a, b] = upper
        big_r[b, a] = np.conj(upper)
        grad += 4.0 * s * (np.conj(v) * (big_r @ v)).imag
    return total, grad
