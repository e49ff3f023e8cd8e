"""The 3-D pressure amplitude and intensity as NIfTI volumes (``arfi field --volume``,
``--intensity-volume``, ``Simulation.pressure_volume``, ``Field.intensity_volume``): read back with
nibabel as a viewer reads them, the hottest voxel is the focal peak ``arfi field`` reports, the
intensity is p²/(2ρc) of each voxel's medium, a crop box holds the same voxels, and bad input
writes nothing."""

from __future__ import annotations

import json

import nibabel as nib
import numpy as np
import pytest
import tomllib

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
    assert d["volume"]["shape_ijk"] == [180, 180, 189] and d["volume"]["path"] == str(vol)
    assert any(
        line.startswith("field: |p| in 3-D (Pa) on 180 x 180 x 189 voxels")
        for line in capsys.readouterr().out.splitlines()
    )


def test_arfi_field_intensity_volume_is_p_squared_over_twice_each_voxels_impedance(tmp_path, capsys, sim):
    # I = p²/(2ρc) by hand from the |p| volume and the medium's ρ and c at each voxel of a box
    # through the focus and the gel's front face (Simulation.properties_at, not the code that
    # made the volume), to float32 (1e-6 relative). Its hottest voxel holds the focal I_SPPA the
    # JSON reports to within 6 % (the peak's |p| to 3 %, refined between samples, squared).
    out, vol, iv, js = tmp_path / "f.npz", tmp_path / "p.nii", tmp_path / "i.nii.gz", tmp_path / "f.json"
    box = ["-4", "4", "-3", "3", "20", "95"]
    assert (
        main(
            [
                "field",
                "--out",
                str(out),
                "--volume",
                str(vol),
                "--intensity-volume",
                str(iv),
                "--volume-box-mm",
                *box,
                "--json",
                str(js),
            ]
        )
        == 0
    )
    d = json.loads(js.read_text())
    p_img, i_img = nib.load(str(vol)), nib.load(str(iv))
    p, intensity = np.asarray(p_img.dataobj, dtype=np.float64), np.asarray(i_img.dataobj)
    assert intensity.shape == p.shape and intensity.dtype == np.float32 and np.allclose(i_img.affine, p_img.affine)
    assert i_img.header["descrip"].tobytes().startswith(b"arfi: I = p^2/(2 rho c) (W/cm2)")
    ijk = np.indices(p.shape).reshape(3, -1)
    points = (p_img.affine @ np.vstack([ijk, np.ones(ijk.shape[1])]))[:3].T
    m = sim.properties_at(points)
    rho_c = (m["density_kg_m3"] * m["sound_speed_m_s"]).reshape(p.shape)
    assert len(np.unique(rho_c)) >= 2  # water in front of the gel, the gel behind its face
    expected = p**2 / (2 * rho_c) * 1e-4
    assert np.abs(intensity - expected).max() <= 1e-6 * expected.max()
    assert 0.94 * d["isppa_w_cm2"] <= intensity.max() <= d["isppa_w_cm2"] * (1 + 1e-5)
    v = d["intensity_volume"]
    assert v["path"] == str(iv) and v["shape_ijk"] == list(p.shape) and v["box_mm"] == [float(b) for b in box]
    assert v["max_w_cm2"] == pytest.approx(float(intensity.max()), rel=1e-6)
    assert any(
        line.startswith(f"field: intensity in 3-D (W/cm²) on {p.shape[0]} x {p.shape[1]} x {p.shape[2]} voxels")
        for line in capsys.readouterr().out.splitlines()
    )


def test_arfi_field_volume_ct_lies_on_the_ct_as_an_independent_resampling_puts_it(tmp_path):
    # The head phantom (2 mm voxels): the volume on the CT's grid carries the CT's shape and
    # affine, and each voxel holds the transducer-frame volume at that voxel's place, found here
    # by another route: the CT affine to RAS, RAS to DICOM LPS (x and y negated), the scenario's
    # rigid transform to the transducer frame, and scipy's trilinear interpolation (order 1, zero
    # outside the grid). Float32 values on both sides: within 1e-5 of the peak.
    from scipy.ndimage import map_coordinates

    ct, toml = tmp_path / "head.nii.gz", tmp_path / "head.toml"
    assert main(["phantom", "--out", str(ct), "--scenario-out", str(toml), "--voxel-mm", "2", "--seed", "2"]) == 0
    vol, on_ct, js = tmp_path / "v.nii.gz", tmp_path / "v_ct.nii.gz", tmp_path / "f.json"
    intensity_ct = tmp_path / "i_ct.nii.gz"
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
                "--volume-ct",
                str(on_ct),
                "--intensity-volume-ct",
                str(intensity_ct),
                "--json",
                str(js),
            ]
        )
        == 0
    )
    d = json.loads(js.read_text())
    head, grid, img = nib.load(str(ct)), nib.load(str(vol)), nib.load(str(on_ct))
    assert img.shape == head.shape and np.allclose(img.affine, head.affine)
    assert d["volume_ct"]["shape_ijk"] == list(head.shape)
    data = np.asarray(img.dataobj)
    transform = np.array(tomllib.loads(toml.read_text())["ct"]["patient_to_transducer_mm"], dtype=np.float64)
    ijk = np.indices(head.shape).reshape(3, -1)
    ras = head.affine @ np.vstack([ijk, np.ones(ijk.shape[1])])
    frame = transform @ (np.diag([-1.0, -1.0, 1.0, 1.0]) @ ras)
    at = np.linalg.solve(grid.affine, frame)[:3]
    expected = map_coordinates(np.asarray(grid.dataobj), at, order=1, mode="constant", cval=0.0).reshape(head.shape)
    peak = d["focal_peak_pa"]
    assert np.abs(data - expected).max() < 1e-5 * peak
    # Around the focal peak (within 5 mm; through the head the hottest voxels are at the scalp),
    # the hottest voxel lies within a voxel's diagonal (3.5 mm) of it, in the brain (soft tissue
    # of the CT, not bone), at 70-100 % of the peak: the 2 mm voxels' centres lie up to 1.4 mm off
    # the beam's axis, on a lobe 4.5 mm wide at -6 dB (a Gaussian of that width keeps 0.76 there).
    near = np.linalg.norm(frame[:3] - np.array(d["focal_peak_mm"])[:, None], axis=0) < 5.0
    best = np.flatnonzero(near)[np.argmax(data.ravel()[near])]
    assert np.linalg.norm(frame[:3, best] - np.array(d["focal_peak_mm"])) < 3.5
    assert 0.7 * peak < data.ravel()[best] <= peak and np.asarray(head.dataobj).ravel()[best] < 300.0
    assert d["focal_tissue"] == "brain"
    # The intensity on the CT's voxels is p²/(2ρc) of the |p| laid on the CT and the medium at each
    # voxel's place (its own HU's conversion): bone voxels take bone's impedance, not the brain's.
    intensity = np.asarray(nib.load(str(intensity_ct)).dataobj, dtype=np.float64).ravel()
    hot = np.flatnonzero(data.ravel() > 0)
    m = arfi.Simulation(arfi.Scenario.load(toml)).properties_at(frame[:3, hot].T)
    rho_c = m["density_kg_m3"] * m["sound_speed_m_s"]
    expected = data.ravel()[hot].astype(np.float64) ** 2 / (2 * rho_c) * 1e-4
    assert np.abs(intensity[hot] - expected).max() <= 1e-6 * expected.max() and np.all(
        intensity[data.ravel() == 0] == 0
    )
    hu = np.asarray(head.dataobj).ravel()[hot]
    bone, soft = hu > 1000.0, hu < 100.0
    assert bone.any() and rho_c[bone].min() > 1.5 * rho_c[soft].max()
    assert d["intensity_volume_ct"]["shape_ijk"] == list(head.shape)


def test_volume_ct_without_a_ct_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, sim):
    assert main(["field", "--out", str(tmp_path / "f.npz"), "--volume-ct", str(tmp_path / "v.nii.gz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--volume-ct" in err[0] and "[ct]" in err[0], err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="volume_ct"):
        sim.pressure_volume(in_ct=True)
    with pytest.raises(ValueError, match="box_mm"):
        sim.pressure_volume(box_mm=[-5, 5, -5, 5, 80, 90], in_ct=True)


def test_a_crop_box_holds_the_same_voxels_as_the_whole_grid(sim):
    whole = sim.pressure_volume()
    box = sim.pressure_volume(box_mm=[-5, 5, -4, 4, 75, 95])
    # The box's first voxel is the whole grid's voxel at that position; the values equal (the same
    # march, recorded on a smaller box).
    first = np.linalg.solve(whole.affine_mm, np.append(box.position_mm((0, 0, 0)), 1.0))[:3]
    i, j, k = (int(round(v)) for v in first)
    nz, ny, nx = box.pressure_pa.shape
    assert np.array_equal(box.pressure_pa, whole.pressure_pa[k : k + nz, j : j + ny, i : i + nx])
    assert np.allclose(box.position_mm((0, 0, 0)), [-5.0, -4.0, 75.0], atol=0.69)
    assert np.allclose(box.position_mm((nz - 1, ny - 1, nx - 1)), [5.0, 4.0, 95.0], atol=0.69)


def test_a_fields_volume_is_the_volume_of_its_own_march(sim, tmp_path):
    # Field.pressure_volume takes no march: the field's march kept |p| on every sample, summed as
    # a volume's march sums it (float32 pairs), so the two are equal to the bit; its crop is the
    # whole grid's box, and to_nifti writes what it returns.
    phases = sim.condense(sim.skull_phases(seed=3))
    f = sim.field(phases, volume=True)
    whole, own = sim.pressure_volume(phases), f.pressure_volume()
    assert np.array_equal(own.pressure_pa, whole.pressure_pa) and np.array_equal(own.affine_mm, whole.affine_mm)
    assert own.frame == "transducer"
    # The whole grid's volume is the field's own memory, not a second copy of the grid: each call
    # gives a read-only view of the same buffer, which keeps the field alive.
    again = f.pressure_volume()
    assert np.shares_memory(own.pressure_pa, again.pressure_pa) and not own.pressure_pa.flags.writeable
    assert own.pressure_pa.base is f
    with pytest.raises(ValueError, match="read-only"):
        own.pressure_pa[0, 0, 0] = 1.0
    f.to_nifti(tmp_path / "whole.nii")
    assert np.array_equal(
        np.asarray(nib.load(str(tmp_path / "whole.nii")).dataobj).transpose(2, 1, 0), whole.pressure_pa
    )
    box = f.pressure_volume([-5, 5, -4, 4, 75, 95])
    assert np.array_equal(box.pressure_pa, sim.pressure_volume(phases, box_mm=[-5, 5, -4, 4, 75, 95]).pressure_pa)
    f.to_nifti(tmp_path / "f.nii.gz", box_mm=[-5, 5, -4, 4, 75, 95])
    img = nib.load(str(tmp_path / "f.nii.gz"))
    assert np.array_equal(np.asarray(img.dataobj).transpose(2, 1, 0), box.pressure_pa)
    assert np.allclose(img.affine, box.affine_mm)
    with pytest.raises(ValueError, match="in_ct"):
        f.pressure_volume(in_ct=True)  # no [ct] here
    with pytest.raises(ValueError, match="box_mm"):
        f.pressure_volume([500, 600, -4, 4, 75, 95])
    with pytest.raises(ValueError, match="box_mm: must be six numbers"):
        f.pressure_volume([1.0, 2.0, 3.0])
    # A field made without volume=True keeps none (the default: a lean march) and says how.
    lean = sim.field(phases)
    assert lean.hottest is None and lean.focus().hottest is None and lean.focus().to_dict()["hottest"] is None
    with pytest.raises(ValueError, match="volume=True"):
        lean.to_nifti(tmp_path / "g.nii.gz")
    assert not (tmp_path / "g.nii.gz").exists()


def test_python_bad_boxes_name_box_mm(sim):
    with pytest.raises(ValueError, match="box_mm"):
        sim.pressure_volume(box_mm=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="box_mm"):
        sim.pressure_volume(box_mm=[5, -5, -4, 4, 75, 95])  # x0 > x1
    with pytest.raises(ValueError, match="holds no sample of the grid"):
        sim.pressure_volume(box_mm=[500, 600, -4, 4, 75, 95])


def test_a_volume_too_large_for_memory_is_refused_before_the_march(sim, monkeypatch):
    f = sim.field(volume=True)
    monkeypatch.setenv("ARFI_MEMORY_LIMIT_GIB", "0.01")  # 10 MiB: the whole grid needs 49 MB
    with pytest.raises(arfi.MemoryLimitError, match="volume-box-mm"):
        sim.pressure_volume()
    # The intensity of the whole grid (4 bytes a voxel beside the field's |p|: 24 MB) likewise;
    # of a box around the focus it fits.
    with pytest.raises(arfi.MemoryLimitError, match="an intensity volume of 180 x 180 x 189 voxels"):
        f.intensity_volume()
    assert f.intensity_volume([-5, 5, -5, 5, 80, 90]).intensity_w_cm2.max() > 0


@pytest.mark.parametrize(
    "args, says",
    [
        (["--volume", "{tmp}/no/such/folder/v.nii.gz"], "does not exist"),
        (["--volume", "{tmp}/v.npz"], ".nii or .nii.gz"),
        (
            ["--volume", "{tmp}/v.nii.gz", "--volume-box-mm", "500", "600", "0", "1", "80", "90"],
            "holds no sample of the grid",
        ),
        (["--volume-box-mm", "-5", "5", "-5", "5", "80", "90"], "--volume-box-mm"),
        (["--volume-ct", "{tmp}/v.nii.gz", "--volume-box-mm", "-5", "5", "-5", "5", "80", "90"], "--volume-box-mm"),
        (["--intensity-volume", "{tmp}/no/such/folder/i.nii.gz"], "does not exist"),
        (["--intensity-volume-ct", "{tmp}/i.nii.gz"], "--intensity-volume-ct: needs a scenario with a [ct] section"),
        (
            ["--intensity-volume", "{tmp}/i.nii", "--volume-box-mm", "500", "600", "0", "1", "80", "90"],
            "holds no sample of the grid",
        ),
    ],
)
def test_cli_bad_volume_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, args, says):
    argv = ["field", "--out", str(tmp_path / "f.npz"), *[a.format(tmp=tmp_path) for a in args]]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("arfi: error:") and says in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_a_gzipped_volume_is_written_in_parallel_members_that_every_reader_reads_whole(tmp_path, monkeypatch):
    # Blocks of 1000 bytes: a 20 x 30 x 40 float32 volume (96 kB) becomes ~97 gzip members,
    # compressed on threads and written in order; gzip (the reference reader, RFC 1952's
    # multi-member files) and nibabel read back every value.
    import gzip

    from arfi.io.files import ParallelGzip, save_nifti

    monkeypatch.setattr(ParallelGzip, "BLOCK", 1000)
    data = np.random.default_rng(0).random((20, 30, 40), dtype=np.float32)
    affine = np.diag([0.5, 0.6, 0.7, 1.0])
    path = tmp_path / "v.nii.gz"
    save_nifti(path, data, affine, "test")
    raw = path.read_bytes()
    assert raw.count(b"\x1f\x8b\x08") >= 90  # one gzip header per member
    img = nib.load(str(path))
    assert np.array_equal(np.asarray(img.dataobj), data) and np.allclose(img.affine, affine)
    plain = tmp_path / "v.nii"
    save_nifti(plain, data, affine, "test")
    assert gzip.decompress(raw) == plain.read_bytes()


def test_a_field_whose_volume_does_not_fit_is_refused_and_arfi_field_goes_on_without_it(
    sim, tmp_path, capsys, monkeypatch
):
    # The whole grid's |p| (8 bytes a voxel while marching: 49 MB here) against a 10 MiB budget:
    # sim.field(volume=True) is refused before the march, naming what and how to shrink it; the
    # lean field is not. arfi field, asked for no volume and no report, prints why the hottest
    # places are missing and writes its field.
    monkeypatch.setenv("ARFI_MEMORY_LIMIT_GIB", "0.01")
    with pytest.raises(arfi.MemoryLimitError, match=r"^\|p\| on the whole 180 x 180 x 189 grid .* spacing_mm"):
        sim.field(volume=True)
    f = sim.field()
    with pytest.raises(ValueError, match="volume=True"):
        f.intensity_volume()
    assert sim.field().hottest is None
    monkeypatch.delenv("ARFI_MEMORY_LIMIT_GIB")
    original = arfi.Simulation.field

    def refused(self, phases=None, z_mm=None, volume=False):
        if volume:
            raise arfi.MemoryLimitError(
                "|p| on the whole 180 x 180 x 189 grid needs 9.9 GiB, more than the 0.1 GiB this machine has"
            )
        return original(self, phases, z_mm)

    monkeypatch.setattr(arfi.Simulation, "field", refused)
    js = tmp_path / "f.json"
    assert main(["field", "--out", str(tmp_path / "f.npz"), "--json", str(js)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert (
        out[2].startswith("field: no hottest place per tissue: |p| on the whole")
        and json.loads(js.read_text())["hottest"] is None
    )
    # Asked for a volume, the refusal is the answer: one line, exit 2, nothing written.
    assert main(["field", "--out", str(tmp_path / "g.npz"), "--volume", str(tmp_path / "g.nii.gz")]) == 2
    assert "|p| on the whole" in capsys.readouterr().err and not (tmp_path / "g.npz").exists()


def test_a_failed_gzip_leaves_no_file(tmp_path, monkeypatch):
    import arfi.io.files

    def broken(block: bytes) -> bytes:
        raise OSError("disk full")

    monkeypatch.setattr(arfi.io.files, "gzip_member", broken)
    with pytest.raises(OSError, match="disk full"):
        arfi.io.files.save_nifti(tmp_path / "v.nii.gz", np.zeros((4, 5, 6), dtype=np.float32), np.eye(4), "test")
    assert list(tmp_path.iterdir()) == []
