"""CT volumes in scenarios: the synthetic head phantom, frames and conversions read from files
written by nibabel (an independent NIfTI writer), and bad CT input."""

from __future__ import annotations

import json
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from arfi.cli import main
from arfi.io.phantom import head_phantom, placement
from arfi.scenario import Scenario
from arfi.simulation import Simulation

GRID = "[grid]\nspacing_mm = 0.68\nstep_mm = 0.68\n"
PLATE_HU = 1200.0
WATER = '[[material]]\nname = "water"\nsound_speed_m_s = 1500\ndensity_kg_m3 = 1000\n'


def test_the_head_phantom_is_seeded_and_holds_air_scalp_bone_and_brain():
    a, b, c = head_phantom(3, voxel_mm=2.0), head_phantom(3, voxel_mm=2.0), head_phantom(4, voxel_mm=2.0)
    assert np.array_equal(a.hu, b.hu) and not np.array_equal(a.hu, c.hu)
    centre = a.hu[a.hu.shape[0] // 2, a.hu.shape[1] // 2, :]
    # Up the central column (patient z): brain, then inner table, diploë, outer table, scalp, air.
    top = centre[::-1]
    assert top[0] < -900  # air above the crown
    bone = np.nonzero(top > 500)[0]
    assert (
        2 <= len(bone) <= 5 and top[bone].max() > 1200
    )  # 2 mm voxels across 4-9 mm of bone, a cortical table among them
    assert -100 < np.median(centre[: len(centre) // 2]) < 150  # brain, with 20 HU noise
    assert a.hu.min() >= -1024 and a.hu.max() <= 3071
    lo, hi, _ = a.thickness_mm
    assert 4.0 <= lo <= hi <= 9.0
    with pytest.raises(ValueError, match="voxel_mm"):
        head_phantom(0, voxel_mm=0.01)
    with pytest.raises(ValueError, match="thickness_mm"):
        head_phantom(0, thickness_mm=(9.0, 4.0))


def _plate_ct(path: Path, sim: Simulation, rotate: bool) -> np.ndarray:
    """A CT of the plate of `test_a_plate_...` written by nibabel: one slice per grid step, three
    60 mm voxels across, air elsewhere. With ``rotate``, the volume's axes are a quarter turn about
    z from RAS and the returned transform turns them back: the field must not change."""
    g = sim.grid
    dz = g.dz_mm
    a = int(round((30.0 - g.z0_mm) / dz))
    z_first = g.z0_mm + (a - 5 + 0.5) * dz
    nk = int((95.0 - z_first) / dz)
    z = z_first + dz * np.arange(nk)
    lo, hi = g.z0_mm + a * dz, g.z0_mm + (a + 4) * dz
    column = np.where((z > lo) & (z < hi), PLATE_HU, -1000.0)
    data = np.broadcast_to(column, (3, 3, nk))
    affine = np.array([[-60.0, 0, 0, 60.0], [0, -60.0, 0, 60.0], [0, 0, dz, z_first], [0, 0, 0, 1]])
    transform = np.eye(4)
    if rotate:  # voxel i along RAS y, j along RAS -x; the transform turns LPS back by -90° about z
        quarter = np.array([[0.0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
        affine = quarter @ affine
        lps = np.diag([-1.0, -1, 1, 1])
        transform = lps @ np.linalg.inv(quarter) @ lps
    img = nib.Nifti1Image(data.astype(np.float64), affine)
    img.set_data_dtype(np.uint8)  # nibabel stores 0 and 255 with scl_slope 8.63, scl_inter -1000
    nib.save(img, str(path))
    assert nib.load(str(path)).dataobj.slope != 1.0
    return transform


def test_a_plate_ct_written_by_nibabel_gives_the_field_of_the_plate_as_a_region(tmp_path):
    water = Simulation(Scenario.from_toml(GRID))
    g = water.grid
    p = _plate_properties()
    a = int(round((30.0 - g.z0_mm) / g.dz_mm))
    region = (
        f'{GRID}[[material]]\nname = "water"\nsound_speed_m_s = 1500\ndensity_kg_m3 = 1000\n'
        f'[[material]]\nname = "bone"\nsound_speed_m_s = {p[0]!r}\ndensity_kg_m3 = {p[1]!r}\n'
        f'attenuation_db_cm_mhz = {p[2]!r}\n[[region]]\nmaterial = "bone"\nshape = "slab"\n'
        f"z_min_mm = {g.z0_mm + a * g.dz_mm!r}\nz_max_mm = {g.z0_mm + (a + 4) * g.dz_mm!r}\n"
    )
    reference = Simulation(Scenario.from_toml(region)).field()
    peak = np.abs(reference.pressure).max()
    assert peak < 0.7 * np.abs(water.field().pressure).max()
    for rotate in (False, True):
        t = _plate_ct(tmp_path / f"plate{int(rotate)}.nii.gz", water, rotate)
        rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in t)
        text = f'{GRID}[ct]\nfile = "plate{int(rotate)}.nii.gz"\npatient_to_transducer_mm = [{rows}]\n'
        sim = Simulation(Scenario.from_toml(text, tmp_path))
        f = sim.field()
        # Same cells, same steering rays (see tests/suite/ct.rs); 1e-4 allows the affine's float32.
        assert np.abs(f.pressure - reference.pressure).max() < 1e-4 * peak, rotate
        # The medium where a report draws it: in the plate its HU (stored through a uint8 slope:
        # within one step of 8.63 HU) and the conversion's c and rho by hand; far outside the CT, NaN
        # HU and the scenario's water.
        inside = g.z0_mm + (a + 2) * g.dz_mm
        m = sim.properties_at([[0.0, 0.0, inside], [0.0, 0.0, 1e4]])
        assert abs(m["hu"][0] - PLATE_HU) < 8.7 and np.isnan(m["hu"][1])
        c, rho, _ = _plate_properties()
        assert np.allclose([m["sound_speed_m_s"][0], m["density_kg_m3"][0]], [c, rho], rtol=0.01)
        assert m["sound_speed_m_s"][1] == 1500.0 and m["density_kg_m3"][1] == 1000.0


def _plate_properties() -> tuple[float, float, float]:
    """c, rho, a0 (dB/cm/MHz) of PLATE_HU in the porosity model (Aubry et al. 2003 constants)."""
    psi = 1.0 - PLATE_HU / 2000.0
    return 1500.0 + 1400.0 * (1.0 - psi), psi * 1000.0 + (1.0 - psi) * 2200.0, 2.0 + 78.0 * psi**0.5


def test_cli_phantom_writes_a_ct_and_a_scenario_that_simulates_through_the_skull(tmp_path, capsys):
    ct, toml, js = tmp_path / "head.nii.gz", tmp_path / "head.toml", tmp_path / "p.json"
    assert (
        main(
            [
                "phantom",
                "--out",
                str(ct),
                "--scenario-out",
                str(toml),
                "--voxel-mm",
                "1",
                "--seed",
                "2",
                "--json",
                str(js),
            ]
        )
        == 0
    )
    result = json.loads(js.read_text())
    assert result["seed"] == 2 and np.allclose(result["patient_to_transducer_mm"], placement())
    head = Simulation(Scenario.load(toml))
    water = Simulation(Scenario.from_toml(WATER))
    skull, free = np.abs(head.field().pressure).max(), np.abs(water.field().pressure).max()
    # 5-8 mm of bone at 550 kHz: a large loss, but a beam still arrives.
    assert 0.05 * free < skull < 0.7 * free, (skull, free)
    capsys.readouterr()
    bad = tmp_path / "bad.nii.gz"
    assert main(["phantom", "--out", str(bad), "--voxel-mm", "0.05"]) == 2
    assert "voxel_mm" in capsys.readouterr().err and not bad.exists()


def test_cli_phantom_for_a_hemisphere_focuses_through_the_skull_at_the_centre(tmp_path):
    # --array hemisphere: the 150 mm hemisphere out to 60 degrees, the target at its centre. Run at
    # 220 kHz with 256 elements (2 mm CT voxels) to keep the test short; the defaults (650 kHz, 1024)
    # take about 40 s.
    ct, toml = tmp_path / "head.nii.gz", tmp_path / "head.toml"
    assert (
        main(["phantom", "--out", str(ct), "--scenario-out", str(toml), "--voxel-mm", "2", "--array", "hemisphere"])
        == 0
    )
    text = toml.read_text()
    assert 'kind = "hemisphere"' in text and "position_mm = [0.0, 0.0, 150.0]" in text
    text = text.replace("frequency_hz = 650000.0", "frequency_hz = 220000.0").replace(
        "elements = 1024", "elements = 256"
    )
    head = Simulation(Scenario.from_toml(text, tmp_path))
    water = Simulation(Scenario.from_toml(text.split("[ct]")[0] + WATER))
    skull, free = head.field(), water.field()
    at, ref = skull.focus(), free.focus()
    # The focus stays at the centre (within a pixel, 1.7 mm) and the skull costs pressure.
    assert abs(at.plane_peak_x_mm) < 1.8 and abs(at.plane_peak_y_mm) < 1.8, at
    assert 0.2 * ref.plane_peak_pa < at.plane_peak_pa < 0.9 * ref.plane_peak_pa, (at, ref)


@pytest.mark.parametrize(
    ("volume", "ct_keys", "message"),
    [
        # The voxel as (i, j, k) of the NIfTI (nibabel's data[i, j, k]), not a flat index.
        ("nan", "", "voxel (1, 1, 60) (i, j, k) is NaN"),
        ("hot", "", "voxel (1, 1, 60) (i, j, k) is 5000 HU"),
        ("good", 'conversion = "hounsfield"', "ct.conversion"),
        ("good", "patient_to_transducer_mm = [[1,0,0,0],[0,1,0,0],[0,0,1.5,0],[0,0,0,1]]", "rigid"),
        ("missing", "", 'no such file (the [ct] file of scenario "vyas2014-phantom")'),
    ],
)
def test_cli_refuses_a_bad_ct_in_one_line_and_writes_nothing(tmp_path, capsys, volume, ct_keys, message):
    z = np.arange(120) * 1.0 + 10.0
    column = np.where((z > 30) & (z < 34), 1500.0, -1000.0)
    data = np.broadcast_to(column, (3, 3, 120)).astype(np.float32).copy()
    if volume == "nan":
        data[1, 1, 60] = np.nan
    if volume == "hot":
        data[1, 1, 60] = 5000.0
    affine = np.array([[-60.0, 0, 0, 60.0], [0, -60.0, 0, 60.0], [0, 0, 1.0, 10.0], [0, 0, 0, 1]])
    if volume != "missing":
        nib.save(nib.Nifti1Image(data, affine), str(tmp_path / f"{volume}.nii"))
    (tmp_path / "s.toml").write_text(f'[ct]\nfile = "{volume}.nii"\n{ct_keys}\n')
    out = tmp_path / "f.npz"
    assert main(["field", "--scenario", str(tmp_path / "s.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err, err
    assert volume == "good" or f"{volume}.nii" in err
    assert not out.exists()
