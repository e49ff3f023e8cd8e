"""Results at the target (:mod:`arfi.focal`): the focal peak is the lobe the target lies in, and a
hotter place elsewhere is reported as such, named by its tissue."""

from __future__ import annotations

import numpy as np

from arfi.focal import axis_focus, describe_tissue, plane_focus


def gaussian_map(x: np.ndarray, y: np.ndarray, spots: list[tuple[float, float, float, float]]) -> np.ndarray:
    """|p| of Gaussian spots (amplitude, x, y, width), shape (ny, nx)."""
    X, Y = np.meshgrid(x, y)
    return sum(a * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / (2 * w ** 2)) for a, cx, cy, w in spots)


def test_the_focal_peak_is_the_lobe_at_the_target_and_a_hotter_place_is_named_apart():
    x = y = np.arange(-80.0, 80.5, 0.5)
    # A focus of 0.3 MPa at (10.5, -1) mm, a skull-side hot spot of 0.6 MPa at (-60, -30) mm.
    p = gaussian_map(x, y, [(0.3e6, 10.5, -1.0, 2.0), (0.6e6, -60.0, -30.0, 3.0)]).astype(np.complex128)
    r = plane_focus(p, x, y, (10.0, 0.0))
    assert r["peak_mm"] == [10.5, -1.0] and abs(r["peak_pa"] - 0.3e6) < 1.0
    assert r["hottest_mm"] == [-60.0, -30.0] and abs(r["hottest_pa"] - 0.6e6) < 1.0
    # Without the hot spot nothing else is reported (the focus's own -6 dB lobe is excluded).
    r = plane_focus(gaussian_map(x, y, [(0.3e6, 10.5, -1.0, 2.0)]).astype(np.complex128), x, y, (10.0, 0.0))
    assert r["hottest_pa"] is None and r["hottest_mm"] is None


def test_along_the_axis_the_scalp_peak_before_the_focus_is_not_the_focus():
    z = np.arange(0.0, 200.0, 0.5)
    mag = 0.2e6 * np.exp(-((z - 138.0) / 6.0) ** 2) + 1.0e6 * np.exp(-((z - 90.0) / 1.5) ** 2)
    line = np.column_stack([z * 10 / 140, 0 * z, z])
    r = axis_focus(mag.astype(np.complex128), line, 140.0)
    assert r["peak_mm"][2] == 138.0 and r["hottest_mm"][2] == 90.0
    assert np.isclose(r["peak_mm"][0], 138.0 * 10 / 140)


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
