"""The hottest place of each tissue class over the whole grid (``arfi field``'s ``hottest``, the
safety line of the skull, the scalp and the brain): checked against a slow, obvious reference,
every voxel of the ``--volume`` file read back with nibabel, in decreasing |p|, named by
:func:`describe_tissue` (101 samples of its straight path to the target) until each class is
found; ``Simulation.tissue_classes`` (the core's grid walk) against the same reference."""

from __future__ import annotations

import json
import math

import nibabel as nib
import numpy as np
import pytest

import arfi
from arfi.cli import main


def describe_tissue(tissue_at, point_mm: list[float], target_mm: tuple[float, float, float]) -> str:
    """The reference: the tissue at ``point_mm`` as a user would name it, ``skull`` for bone,
    ``scalp`` for the target's own tissue where 101 samples of its straight path to the target
    cross bone, else the tissue's own name. ``tissue_at`` maps points (n, 3) in mm to names."""
    p, t = np.asarray(point_mm, dtype=np.float64), np.asarray(target_mm, dtype=np.float64)
    names = tissue_at(p[None, :] + np.linspace(0.0, 1.0, 101)[:, None] * (t - p)[None, :])
    if names[0] == "bone":
        return "skull"
    return "scalp" if names[0] == names[-1] and "bone" in names[1:] else names[0]


def reference_hottest(sim: arfi.Simulation, volume: str, target: tuple[float, float, float], classes: set[str]) -> dict:
    """The first voxel of each class in decreasing |p| (ties in file order), until ``classes``
    are all found: {class: (|p| Pa, position mm)}. A voxel whose own tissue is not the target's
    is named by it alone (as ``describe_tissue`` would); the others by ``describe_tissue``."""
    img = nib.load(volume)
    data = np.asarray(img.dataobj)
    flat = data.ravel()
    top = np.argpartition(-flat, 300_000)[:300_000]  # the hottest 300 000 voxels hold every class here
    order = top[np.lexsort((top, -flat[top]))]
    ijk = np.stack(np.unravel_index(order, data.shape), axis=1).astype(np.float64)
    points = ijk @ img.affine[:3, :3].T + img.affine[:3, 3]
    own = sim.tissue_at(points)
    target_tissue = sim.tissue_at(np.array([target]))[0]
    found: dict = {}
    for n, index in enumerate(order):
        tissue = describe_tissue(sim.tissue_at, list(points[n]), target) if own[n] == target_tissue else own[n]
        found.setdefault({"bone": "skull"}.get(tissue, tissue), (float(flat[index]), points[n]))
        if set(found) >= classes:
            return found
    raise AssertionError(f"classes {classes - set(found)} not among the hottest voxels")


def test_through_a_head_the_skull_the_scalp_and_the_brain_each_have_their_hottest_place(tmp_path, capsys):
    # The head phantom (2 mm CT voxels) in front of the planar array at 550 kHz: the field's
    # hottest places lie in the skull and the scalp just behind the head's surface, hotter than
    # the brain's, which is the focal peak's sample.
    ct, toml = tmp_path / "head.nii.gz", tmp_path / "head.toml"
    assert main(["phantom", "--out", str(ct), "--scenario-out", str(toml), "--voxel-mm", "2", "--seed", "2"]) == 0
    vol, js = tmp_path / "v.nii.gz", tmp_path / "f.json"
    assert (
        main(
            [
                "field",
                "--scenario",
                str(toml),
                "--out",
                str(tmp_path / "f.npz"),
                "--volume",
                str(vol),
                "--json",
                str(js),
                "--mi-limit",
                "0.5",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    d = json.loads(js.read_text())
    hottest = d["hottest"]
    assert {"skull", "scalp", "brain"} <= set(hottest), hottest
    pressures = [h["pressure_pa"] for h in hottest.values()]
    assert pressures == sorted(pressures, reverse=True)
    sim = arfi.Simulation(arfi.Scenario.load(toml))
    ref = reference_hottest(sim, str(vol), tuple(d["target_mm"]), set(hottest))
    # The same voxel: |p| the same float32, the position the same to rounding.
    for tissue, h in hottest.items():
        assert h["pressure_pa"] == ref[tissue][0], (tissue, h, ref[tissue])
        assert np.allclose(h["position_mm"], ref[tissue][1], atol=1e-6), (tissue, h, ref[tissue])
    # The brain's hottest sample is the focal peak's (the peak refined between samples, within 3 %).
    assert 0.97 * d["focal_peak_pa"] <= hottest["brain"]["pressure_pa"] <= d["focal_peak_pa"] * (1 + 1e-6)
    # The exposure by hand in the brain (1546 m/s, 1040 kg/m³) at 550 kHz.
    b = hottest["brain"]["pressure_pa"]
    assert math.isclose(hottest["brain"]["mechanical_index"], b / 1e6 / math.sqrt(0.55), rel_tol=1e-12)
    assert math.isclose(hottest["brain"]["isppa_w_cm2"], b * b / (2 * 1040.0 * 1546.0) * 1e-4, rel_tol=1e-12)
    # Printed, hottest first; with the mechanical-index line at 0.5, the skull and the scalp are flagged.
    line = next(ln for ln in out.splitlines() if ln.startswith("field: hottest in each tissue: "))
    assert [part.split()[0] for part in line.split(": ", 2)[2].split("; ")] == list(hottest)
    flagged = {(r["where"], r["tissue"]) for r in d["safety"]["exceeded"]}
    assert {("hottest place", "skull"), ("hottest place", "scalp")} <= flagged
    assert all(hottest[t]["mechanical_index"] > 0.5 for w, t in flagged if w == "hottest place")


def test_without_bone_the_hottest_places_cover_the_whole_grid_and_name_no_skull(tmp_path):
    # The paper's phantom in water: two classes, the phantom's hottest sample the focal peak's,
    # and the hottest of both the hottest voxel of the whole grid's volume.
    sim = arfi.Simulation()
    f = sim.field(volume=True)
    hottest = f.hottest
    assert list(hottest) == ["phantom", "water"]
    peak = f.focal_metrics.focal_peak_pa
    assert 0.97 * peak <= hottest["phantom"].pressure_pa <= peak * (1 + 1e-6)
    whole = sim.pressure_volume(None).pressure_pa
    assert hottest["phantom"].pressure_pa == float(whole.max())
    # The phantom's hottest sample is the focus itself (flagged once, as the focal peak); the water's is not.
    assert hottest["phantom"].is_focus and not hottest["water"].is_focus
    assert hottest["phantom"].tissue == "phantom" and list(f.focus().hottest) == list(hottest)
    assert f.focus().to_dict()["hottest"] == {t: h.to_dict() for t, h in hottest.items()}
    assert list(hottest["water"].to_dict()) == ["pressure_pa", "position_mm", "isppa_w_cm2", "mechanical_index"]


def test_tissue_classes_name_each_place_as_the_slow_reference_does(tmp_path):
    # 4000 random grid samples of the head phantom (2 mm CT): Simulation.tissue_classes (the
    # core's walk from the sample towards the target, one sample a step) names each as the
    # reference does from 101 points of its straight path. Only a sample on a face between two CT
    # voxels may differ (its own tissue changes within 1e-3 mm: the two sides of a tie), and few do.
    ct, toml = tmp_path / "head.nii.gz", tmp_path / "head.toml"
    assert main(["phantom", "--out", str(ct), "--scenario-out", str(toml), "--voxel-mm", "2", "--seed", "2"]) == 0
    sim = arfi.Simulation(arfi.Scenario.load(toml))
    f = sim.field(volume=True)
    grid = f.pressure_volume()  # the grid's shape and affine (mm)
    nz, ny, nx = grid.pressure_pa.shape
    rng = np.random.default_rng(0)
    ijk = np.stack([rng.integers(0, nx, 4000), rng.integers(0, ny, 4000), rng.integers(0, nz, 4000)], axis=1)
    points = ijk @ grid.affine_mm[:3, :3].T + grid.affine_mm[:3, 3]
    target = tuple(f.target_mm)
    core = sim.tissue_classes(points)
    ref = [describe_tissue(sim.tissue_at, list(p), target) for p in points]
    assert {"skull", "scalp", "brain", "water"} <= set(core)
    differ = [k for k in range(len(points)) if core[k] != ref[k]]
    for k in differ:
        near = points[k] + 1e-3 * np.vstack([np.zeros(3), np.eye(3), -np.eye(3)])
        assert len(set(sim.tissue_at(near))) > 1, (points[k], core[k], ref[k])
    assert len(differ) <= 0.005 * len(points), len(differ)
    with pytest.raises(ValueError, match="points_mm: .* lies off the grid"):
        sim.tissue_classes([0.0, 0.0, -50.0])
