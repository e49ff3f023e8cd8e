"""Checks of user input at the Python boundary: each returns the value in the form the core
takes, or raises ``ValueError`` naming the parameter (complex values are refused, not cast)."""

from __future__ import annotations

from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray


def real_array(value: Any, name: str) -> NDArray[np.float64]:
    """``value`` as a float64 array; complex input is refused rather than cast (which drops the
    imaginary part). Raises ValueError naming `name`."""
    try:
        mixed = not isinstance(value, np.ndarray) or value.dtype == object  # a list may hold one complex
        if np.iscomplexobj(value) or (
            mixed and any(np.iscomplexobj(v) for v in np.ravel(np.asarray(value, dtype=object)))
        ):
            raise ValueError(f"{name}: must be real, got complex values")
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as e:
        if str(e).startswith(name):
            raise
        raise ValueError(f"{name}: not numeric ({e})") from None


def as_point_mm(value: ArrayLike, name: str) -> tuple[float, float, float]:
    """Three finite numbers (x, y, z in mm) as a tuple; ValueError naming ``name`` otherwise."""
    a = real_array(value, name)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: must be three finite numbers (x, y, z in mm), got {value!r}")
    return float(a[0]), float(a[1]), float(a[2])


@overload
def as_phases(phases: None, name: str = "phases") -> None: ...
@overload
def as_phases(phases: ArrayLike, name: str = "phases") -> NDArray[np.float64]: ...
def as_phases(phases: ArrayLike | None, name: str = "phases") -> NDArray[np.float64] | None:
    """Phases (rad) as a 1-D float64 array, or None. Raises ValueError naming `name`."""
    if phases is None:
        return None
    a = real_array(phases, name)
    if a.ndim != 1:
        raise ValueError(f"{name}: must be one-dimensional, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return np.ascontiguousarray(a)


def as_number(value: Any, name: str, low: float = -np.inf, low_open: bool = False) -> float:
    """A finite real number >= ``low`` (> ``low`` when ``low_open``). Raises ValueError naming `name`."""
    try:
        if np.iscomplexobj(value):
            raise TypeError
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name}: must be a number, got {value!r}") from None
    if isinstance(value, (bool, np.bool_, str, bytes)) or not np.isfinite(x) or x < low or (low_open and x == low):
        bound = "" if low == -np.inf else f" {'>' if low_open else '>='} {low:g}"
        raise ValueError(f"{name}: must be a finite number{bound}, got {value!r}")
    return x


def as_count(value: Any, name: str, low: int = 0, high: int = 2**64 - 1) -> int:
    """An integer in [low, high]. Raises ValueError naming `name`."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not low <= int(value) <= high:
        raise ValueError(f"{name}: must be an integer in [{low}, {high}], got {value!r}")
    return int(value)


def as_image(image: ArrayLike, name: str) -> NDArray[np.float64]:
    """A 2-D real image as a contiguous float64 array. Raises ValueError naming `name`."""
    a = real_array(image, name)
    if a.ndim != 2:
        raise ValueError(f"{name}: must be a 2-D image, got shape {a.shape}")
    return np.ascontiguousarray(a)
