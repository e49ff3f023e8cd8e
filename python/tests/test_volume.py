"""The 3-D pressure amplitude as a NIfTI volume (``arfi field --volume``,
``Simulation.pressure_volume``): read back with nibabel as a viewer reads it, its hottest voxel is
the focal peak ``arfi field`` reports, a crop box holds the same voxels, and bad input writes
nothing."""

from __future__ import annotations

import json

import nibabel as nib
import numpy as np
import pytest

import arfi
from arfi.cli import main


@pytest.fixture(scope="module")
def sim():
    return arfi.Simulation()


def test_arfi_field_volume_opens_with_its_focus_where_the_json_puts_it(tmp_path, capsys):
    out, vol, js = tmp_path / "f.npz", tmp_path / "v.nii.gz", tmp_path / "f.json"
    assert main(["field", "--out", str(out), "--volume", str(vol), "--json", str(js)]) == 0
    d = json.loads(js.read_text())
    img = nib.load(str(vol))
    data = np.asarray(img.dataobj)
    assert data.shape == (180, 180, 189) and data.dtype == np.float32  # x, y, z: the default grid
    assert img.header.get_xyzt_units()[0] == "mm"
    # The hottest voxel lies within one voxel (0.68 mm) of the interpolated 3-D peak, and is at
    # most the peak and within 3 % of it (the peak is refined between samples).
    ijk = np.unravel_index(np.argmax(data), data.shape)
    at = (img.affine @ np.array([*ijk, 1.0]))[:3]
    assert np.all(np.abs(at - np.array(d["focal_peak_mm"])) <= 0.69), (at, d["focal_peak_mm"])
    assert 0.97 * d["focal_peak_pa"] <= data.max() <= d["focal_peak_pa"] * (1 + 1e-6)
    assert d["volume"]["shape_xyz"] == [180, 180, 189] and d["volume"]["path"] == str(vol)
    assert any(line.startswith("field: |p| in 3-D (Pa) on 180 x 180 x 189 voxels") for line in capsys.readouterr().out.splitlines())


def test_a_crop_box_holds_the_same_voxels_as_the_whole_grid(sim):
    whole = sim.pressure_volume()
    box = sim.pressure_volume(box_mm=[-5, 5, -4, 4, 75, 95])
    # The box's first voxel is the whole grid's voxel at that position; the values equal (the same
    # march, recorded on a smaller box).
    first = np.linalg.solve(whole.affine_mm, np.append(box.position_mm((0, 0, 0)), 1.0))[:3]
    i, j, k = (int(round(v)) for v in first)
    nz, ny, nx = box.pressure_pa.shape
    assert np.array_equal(box.pressure_pa, whole.pressure_pa[k:k + nz, j:j + ny, i:i + nx])
    assert np.allclose(box.position_mm((0, 0, 0)), [-5.0, -4.0, 75.0], atol=0.69)
    assert np.allclose(box.position_mm((nz - 1, ny - 1, nx - 1)), [5.0, 4.0, 95.0], atol=0.69)


def test_python_bad_boxes_name_box_mm(sim):
    with pytest.raises(ValueError, match="box_mm"):
        sim.pressure_volume(box_mm=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="box_mm"):
        sim.pressure_volume(box_mm=[5, -5, -4, 4, 75, 95])  # x0 > x1
    with pytest.raises(ValueError, match="holds no sample of the grid"):
        sim.pressure_volume(box_mm=[500, 600, -4, 4, 75, 95])


def test_a_volume_too_large_for_memory_is_refused_before_the_march(sim, monkeypatch):
    monkeypatch.setenv("ARFI_MEMORY_LIMIT_GIB", "0.01")  # 10 MiB: the whole grid needs 122 MB
    with pytest.raises(ValueError, match="volume-box-mm"):
        sim.pressure_volume()


@pytest.mark.parametrize("args, says", [
    (["--volume", "{tmp}/no/such/folder/v.nii.gz"], "does not exist"),
    (["--volume", "{tmp}/v.npz"], ".nii or .nii.gz"),
    (["--volume", "{tmp}/v.nii.gz", "--volume-box-mm", "500", "600", "0", "1", "80", "90"], "holds no sample of the grid"),
    (["--volume-box-mm", "-5", "5", "-5", "5", "80", "90"], "--volume-box-mm"),
])
def test_cli_bad_volume_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, args, says):
    argv = ["field", "--out", str(tmp_path / "f.npz"), *[a.format(tmp=tmp_path) for a in args]]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("arfi: error:") and says in err[0], err
    assert list(tmp_path.iterdir()) == []
