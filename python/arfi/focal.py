"""Results at the target, named as a user would: the tissue a hotter place lies in (a skull, scalp
or the water in front of the head). The focal peak and the hottest places themselves are found
in the core (``Field.focus()``): the local maximum of |p| reached by climbing from the target's
sample, and the hottest sample outside its -6 dB lobe when that is hotter.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def describe_tissue(tissue_at: Any, point_mm: list[float], target_mm: tuple[float, float, float]) -> str:
    """The tissue at ``point_mm`` as a user would name it: ``skull`` for a CT's bone, ``scalp`` for
    the target's own (soft) tissue where its straight path to the target crosses bone, else the
    tissue's own name (``brain``, ``water`` …). ``tissue_at`` maps points (n, 3) in mm to names."""
    p, t = np.asarray(point_mm, dtype=np.float64), np.asarray(target_mm, dtype=np.float64)
    names = tissue_at(p[None, :] + np.linspace(0.0, 1.0, 101)[:, None] * (t - p)[None, :])
    if names[0] == "bone":
        return "skull"
    return "scalp" if names[0] == names[-1] and "bone" in names[1:] else names[0]
