"""Results at the target (:mod:`arfi.focal`): a hotter place than the focus is named by its tissue.
The focal peak and the hottest places are found by the core (``Field.focus()``; tested in
crates/has-core/src/focal.rs and through a simulation in test_simulation.py and test_chain.py)."""

from __future__ import annotations

import numpy as np

from arfi.focal import describe_tissue


def test_tissue_names_read_as_a_user_would():
    # A skull shell 60-67 mm from the origin; soft tissue inside and outside (the scalp is the soft
    # tissue whose path to the target crosses bone), water beyond 72 mm.
    def tissue_at(points: np.ndarray) -> list[str]:
        r = np.linalg.norm(points - np.array([0.0, 0.0, 150.0]), axis=1)
        return ["bone" if 60 <= v < 67 else "water" if v >= 72 else "brain" for v in r]

    target = (10.0, 0.0, 140.0)
    assert describe_tissue(tissue_at, [0.0, 63.0, 150.0], target) == "skull"
    assert describe_tissue(tissue_at, [0.0, 70.0, 150.0], target) == "scalp"
    assert describe_tissue(tissue_at, [0.0, 30.0, 150.0], target) == "brain"
    assert describe_tissue(tissue_at, [0.0, 80.0, 150.0], target) == "water"
