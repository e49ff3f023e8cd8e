"""Results at the target: the focal peak of a field near the target, and any hotter place elsewhere
named by the tissue it lies in (a skull, scalp or the water in front of the head is never reported
as the focus).

The focal peak is the local maximum of |p| reached by climbing from the target's point (on a
plane, the point of the beam's axis there; along the axis, the sample nearest the target's depth):
the lobe the target lies in, not the hottest point of the map. Its -6 dB region is the connected
set of samples at or above half of it; the hottest sample outside that region is reported as
``hottest`` only when it is hotter than the focal peak.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray


def climb(values: NDArray[np.float64], start: tuple[int, ...]) -> tuple[int, ...]:
    """The local maximum reached from ``start`` by steepest ascent over the neighbours (8 in 2-D,
    2 in 1-D) of a non-negative map."""
    pos = tuple(int(i) for i in start)
    offsets = [o for o in np.ndindex(*(3,) * values.ndim) if any(v != 1 for v in o)]
    while True:
        best, best_value = pos, values[pos]
        for o in offsets:
            q = tuple(p + d - 1 for p, d in zip(pos, o))
            if all(0 <= v < n for v, n in zip(q, values.shape)) and values[q] > best_value:
                best, best_value = q, values[q]
        if best == pos:
            return pos
        pos = best


def region_6db(values: NDArray[np.float64], peak: tuple[int, ...]) -> NDArray[np.bool_]:
    """The samples at or above half of ``values[peak]`` connected to the peak (edge neighbours)."""
    level = 0.5 * values[peak]
    inside = np.zeros(values.shape, dtype=bool)
    stack = [peak]
    inside[peak] = True
    while stack:
        p = stack.pop()
        for axis in range(values.ndim):
            for step in (-1, 1):
                q = p[:axis] + (p[axis] + step,) + p[axis + 1:]
                if 0 <= q[axis] < values.shape[axis] and not inside[q] and values[q] >= level:
                    inside[q] = True
                    stack.append(q)
    return inside


def focal_and_hottest(values: NDArray[np.float64], start: tuple[int, ...]) -> tuple[tuple[int, ...], tuple[int, ...] | None]:
    """The focal peak's index climbing from ``start``, and the hottest index outside its -6 dB
    region when that is hotter than the peak (else None)."""
    peak = climb(values, start)
    outside = np.where(region_6db(values, peak), -np.inf, values)
    hot = tuple(int(i) for i in np.unravel_index(int(np.argmax(outside)), values.shape))
    return peak, (hot if outside[hot] > values[peak] else None)


def plane_focus(pressure: NDArray[np.complex128], x_mm: NDArray[np.float64], y_mm: NDArray[np.float64],
                at_mm: tuple[float, float]) -> dict[str, Any]:
    """The focal peak on a plane near the point ``at_mm`` (x, y) and any hotter place elsewhere:
    ``peak_pa``, ``peak_mm`` (x, y), ``hottest_pa`` and ``hottest_mm`` (None when the peak is the
    hottest place)."""
    mag = np.abs(pressure)
    start = (int(np.argmin(np.abs(np.asarray(y_mm) - at_mm[1]))), int(np.argmin(np.abs(np.asarray(x_mm) - at_mm[0]))))
    (j, i), hot = focal_and_hottest(mag, start)
    out: dict[str, Any] = {"peak_pa": float(mag[j, i]), "peak_mm": [float(x_mm[i]), float(y_mm[j])],
                           "hottest_pa": None, "hottest_mm": None}
    if hot is not None:
        out["hottest_pa"], out["hottest_mm"] = float(mag[hot]), [float(x_mm[hot[1]]), float(y_mm[hot[0]])]
    return out


def axis_focus(axis_pressure: NDArray[np.complex128], axis_mm: NDArray[np.float64], target_z_mm: float) -> dict[str, Any]:
    """The focal peak along the beam's axis near the target's depth and any hotter sample elsewhere
    on it: ``peak_pa``, ``peak_mm`` (x, y, z), ``hottest_pa``, ``hottest_mm`` (None when the peak
    is the hottest). ``axis_mm`` holds the samples' positions, shape (n, 3)."""
    mag = np.abs(axis_pressure)
    (k,), hot = focal_and_hottest(mag, (int(np.argmin(np.abs(axis_mm[:, 2] - target_z_mm))),))
    out: dict[str, Any] = {"peak_pa": float(mag[k]), "peak_mm": [float(v) for v in axis_mm[k]], "hottest_pa": None,
                           "hottest_mm": None}
    if hot is not None:
        out["hottest_pa"], out["hottest_mm"] = float(mag[hot]), [float(v) for v in axis_mm[hot[0]]]
    return out


def describe_tissue(tissue_at: Any, point_mm: list[float], target_mm: tuple[float, float, float]) -> str:
    """The tissue at ``point_mm`` as a user would name it: ``skull`` for a CT's bone, ``scalp`` for
    the target's own (soft) tissue where its straight path to the target crosses bone, else the
    tissue's own name (``brain``, ``water`` …). ``tissue_at`` maps points (n, 3) in mm to names."""
    p, t = np.asarray(point_mm, dtype=np.float64), np.asarray(target_mm, dtype=np.float64)
    names = tissue_at(p[None, :] + np.linspace(0.0, 1.0, 101)[:, None] * (t - p)[None, :])
    if names[0] == "bone":
        return "skull"
    return "scalp" if names[0] == names[-1] and "bone" in names[1:] else names[0]
