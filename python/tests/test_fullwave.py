"""``arfi field --engine fdtd``: the full-wave engine (BabelViscoFDTD) fed the march's source plane
and medium, its field read as the march's is.

The engine's own accuracy is checked elsewhere (benches/fullwave: plane waves through plates
against the exact elastic solution). Here: that arfi hands it the right source, medium and
read-out. In water the march is exact (the angular spectrum of its own source plane), so an
engine run in water that agrees with it checks the source's amplitude (the kz/k prefilter and the
2·c·Δt/h scale), the time step and window, and the read-back onto the march's grid.
"""

import importlib.util
import json

import numpy as np
import pytest

import arfi
from arfi.cli import main
from arfi.validation import fdtd

SMALL_BOWL = """
name = "small bowl in water"
frequency_hz = 250000.0
acoustic_power_w = 10.0

[transducer]
kind = "bowl"
radius_of_curvature_mm = 40.0
aperture_diameter_mm = 36.0

[focus]
position_mm = [0.0, 0.0, 40.0]

[[material]]
name = "water"
sound_speed_m_s = 1500.0
density_kg_m3 = 1000.0
attenuation_db_cm_mhz = 0.0

[medium]
background = "water"
"""


def small_sim(tmp_path) -> tuple[arfi.Simulation, str]:
    path = tmp_path / "small.toml"
    path.write_text(SMALL_BOWL)
    return arfi.Simulation(arfi.Scenario.load(str(path))), str(path)


def test_a_marched_volume_read_back_gives_the_same_focus(sim):
    f = sim.field(volume=True)
    back = sim.field_from_volume(f.pressure, f.z_mm, f.axis_pressure, f.pressure_volume().pressure_pa)
    a, b = f.focus().to_dict(), back.focus().to_dict()
    for key in ("focal_peak_pa", "focal_peak_mm", "fwhm_6db_mm", "plane_peak_pa", "axis_peak_z_mm", "isppa_w_cm2"):
        assert a[key] == b[key], key
    assert [h.position_mm for h in f.hottest.values()] == [h.position_mm for h in back.hottest.values()]


def test_a_volume_of_the_wrong_size_is_refused_naming_it(sim):
    f = sim.field(volume=True)
    v = f.pressure_volume().pressure_pa
    with pytest.raises(ValueError, match="^magnitude"):
        sim.field_from_volume(f.pressure, f.z_mm, f.axis_pressure, v[:-1])
    with pytest.raises(ValueError, match="^plane"):
        sim.field_from_volume(f.pressure[:, :-1], f.z_mm, f.axis_pressure, v)
    with pytest.raises(ValueError, match="^axis"):
        sim.field_from_volume(f.pressure, f.z_mm, f.axis_pressure[:3], v)
    bad = v.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="^magnitude"):
        sim.field_from_volume(f.pressure, f.z_mm, f.axis_pressure, bad)


def test_lagrange_weights_are_exact_for_cubics_and_pick_a_node_on_it():
    rng = np.random.default_rng(3)
    t = rng.uniform(2, 20, 200)
    base, w = fdtd._lagrange(t)
    nodes = base[:, None] + np.arange(4)[None, :]
    for coeffs in ([1, 0, 0, 0], [0.3, -2, 0.1, 0.05]):
        poly = np.polynomial.Polynomial(coeffs)
        assert np.allclose((w * poly(nodes)).sum(axis=1), poly(t), rtol=1e-10, atol=1e-9)
    base, w = fdtd._lagrange(np.array([7.0]))
    assert base[0] + np.argmax(w[0]) == 7 and w[0].max() == 1.0


def test_the_plan_resolves_the_shortest_wavelength_and_holds_the_beam(tmp_path):
    sim, _ = small_sim(tmp_path)
    f = sim.field(volume=True)
    for ppw in (6.0, 9.0):
        p = fdtd.plan(sim, f, fdtd.FdtdOptions(points_per_wavelength=ppw))
        assert p.h_m <= 1500.0 / 250e3 / ppw * (1 + 1e-9)
        assert p.dt_s * p.steps_per_period == pytest.approx(4e-6)
        # The focus and the source plane's aperture lie inside the box, away from its layer.
        lo = np.array(p.origin_m) + (p.pml_cells + 2) * p.h_m
        hi = np.array(p.origin_m) + (np.array(p.shape) - p.pml_cells - 3) * p.h_m
        assert (lo[:2] < -0.018).all() and (hi[:2] > 0.018).all() and lo[2] <= f.axis_z_mm[0] * 1e-3 < 0.04 < hi[2]
        assert p.seconds > 0 and p.memory_bytes == p.voxels * fdtd.BYTES_PER_VOXEL
        assert "voxels of" in p.describe() and "about" in p.describe()
    with pytest.raises(ValueError, match="points_per_wavelength"):
        fdtd.FdtdOptions(points_per_wavelength=2.0)


def test_without_the_engine_fdtd_is_one_line_and_nothing_written(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(fdtd, "engine_available", lambda: False)
    out = tmp_path / "f.npz"
    assert main(["field", "--engine", "fdtd", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pip install 'arfi[fullwave]'" in err
    assert not out.exists()


def test_a_grid_beyond_the_memory_is_refused_before_running(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(fdtd, "engine_available", lambda: True)
    monkeypatch.setattr(fdtd, "available_memory_bytes", lambda: 50_000_000)
    _, scenario = small_sim(tmp_path)
    out, js = tmp_path / "f.npz", tmp_path / "f.json"
    assert main(["field", "--engine", "fdtd", "--scenario", scenario, "--out", str(out), "--json", str(js)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "GiB" in err and "points per wavelength" in err
    assert not out.exists() and not js.exists()
    assert (
        main(
            [
                "field",
                "--engine",
                "fdtd",
                "--fdtd-points-per-wavelength",
                "1",
                "--scenario",
                scenario,
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "--fdtd-points-per-wavelength" in capsys.readouterr().err


def test_fdtd_in_water_agrees_with_the_exact_march_and_writes_the_same_outputs(tmp_path, capsys):
    # A test dependency (pyproject's [test]): missing, this fails rather than skips.
    assert importlib.util.find_spec("BabelViscoFDTD") is not None, "pip install '.[test]' installs BabelViscoFDTD"
    sim, scenario = small_sim(tmp_path)
    out, js = tmp_path / "f.npz", tmp_path / "f.json"
    assert (
        main(["field", "--scenario", scenario, "--out", str(tmp_path / "m.npz"), "--json", str(tmp_path / "m.json")])
        == 0
    )
    assert (
        main(
            [
                "field",
                "--engine",
                "fdtd",
                "--fdtd-points-per-wavelength",
                "6",
                "--scenario",
                scenario,
                "--out",
                str(out),
                "--json",
                str(js),
                "--report",
                str(tmp_path / "report"),
            ]
        )
        == 0
    )
    # The report draws the engine's field and names the engine, not the march.
    html = (tmp_path / "report" / "report.html").read_text()
    assert "computed by BabelViscoFDTD" in html and (tmp_path / "report" / "field_sections.png").exists()
    printed = capsys.readouterr().out
    assert "fdtd: BabelViscoFDTD" in printed and "computed by BabelViscoFDTD" in printed
    march, fdtd = json.loads((tmp_path / "m.json").read_text()), json.loads(js.read_text())
    assert set(march) <= set(fdtd) and fdtd["engine"] == "fdtd" and march["engine"] == "has"
    assert fdtd["fdtd"]["steady_change"] < 1e-3
    a, b = np.load(tmp_path / "m.npz"), np.load(out)
    assert set(a.files) == set(b.files)
    # 6 points per wavelength, second order: the engine's waves run about 0.5 % slow, which over
    # the ~8 wavelengths to the focus turns the phase by ~0.2 rad and moves the gain by a few %:
    # 4 % on the axial peak, one march step on its depth, 0.98 on the focal plane's correlation.
    assert b["axis_pressure"].shape == a["axis_pressure"].shape
    pa, pb = abs(a["axis_pressure"]).max(), abs(b["axis_pressure"]).max()
    assert abs(pb / pa - 1) < 0.04, (pa, pb)
    assert abs(fdtd["axis_peak_z_mm"] - march["axis_peak_z_mm"]) <= sim.grid.dz_mm + 1e-9
    # Along the axis over the focal zone (|p| above 0.7 of its peak, -3 dB) point by point, 4 %
    # (the pre-focal interference is more sensitive to the engine's phase error: +4 % at -4 dB).
    near = abs(a["axis_pressure"]) > 0.7 * pa
    assert np.abs(abs(b["axis_pressure"][near]) / abs(a["axis_pressure"][near]) - 1).max() < 0.04
    p, q = a["pressure"], b["pressure"]
    corr = abs((p * q.conj()).sum()) / np.sqrt((abs(p) ** 2).sum() * (abs(q) ** 2).sum())
    assert corr > 0.98, corr


SOLID_PLATE = (
    SMALL_BOWL
    + """
[[material]]
name = "cortical"
sound_speed_m_s = 2800.0
density_kg_m3 = 1850.0
attenuation_db_cm_mhz = 8.0
shear_sound_speed_m_s = {cs}
shear_attenuation_db_cm_mhz = {a}

[[region]]
material = "cortical"
shape = "slab"
z_min_mm = 20.0
z_max_mm = 24.0
"""
)


def test_a_solid_material_gives_its_shear_wave_and_the_march_carries_it_on_its_planes(tmp_path):
    path = tmp_path / "solid.toml"
    path.write_text(SOLID_PLATE.format(cs=1500.0, a=10.0))
    sim = arfi.Simulation(arfi.Scenario.load(str(path)))
    props = sim.properties_at([[0.0, 0.0, 22.0], [0.0, 0.0, 30.0]])
    assert props["shear_sound_speed_m_s"].tolist() == [1500.0, 0.0]
    # 10 dB/cm/MHz at 250 kHz, linear: 2.5 dB/cm = 28.8 Np/m.
    assert props["shear_attenuation_np_m"][0] == pytest.approx(2.5 * 100 * np.log(10) / 20)
    assert sim.has_shear and sim.propagation.shear and "shear waves carried" in sim.propagation_summary()
    water, _ = small_sim(tmp_path)
    assert not water.propagation.shear
    assert not water.has_shear and "shear" not in water.propagation_summary()


@pytest.mark.parametrize(
    ("cs", "a", "name"),
    [
        (2800.0, 0.0, "shear_sound_speed_m_s"),  # at the compressional speed
        (2500.0, 0.0, "shear_sound_speed_m_s"),  # above √3/2 of it: a negative bulk modulus
        (1500.0, -1.0, "shear_attenuation_db_cm_mhz"),
    ],
)
def test_an_impossible_shear_wave_is_one_line_and_exit_2(tmp_path, capsys, cs, a, name):
    path = tmp_path / "solid.toml"
    path.write_text(SOLID_PLATE.format(cs=cs, a=a))
    out = tmp_path / "f.npz"
    assert main(["field", "--scenario", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"material 'cortical'.{name}" in err, err
    assert not out.exists()


def test_ct_bone_shear_follows_the_solid_fraction_and_is_bounded_by_the_dense_bone(tmp_path, capsys):
    from arfi.io.files import write_volume

    # A layer of 1000 HU (porosity 0.5 in the default conversion) from z = 20 to 40 mm in water.
    affine = np.eye(4)
    affine[:3, 3] = [-30.0, -30.0, 10.0]
    hu = np.full((41, 61, 61), -1000.0, np.float32)
    hu[10:31] = 1000.0
    write_volume(tmp_path / "ct.nii", hu, affine, "test layer")

    def scenario(cs: float) -> str:
        path = tmp_path / f"ct_{cs:g}.toml"
        path.write_text(
            SMALL_BOWL + f'\n[ct]\nfile = "ct.nii"\nbone_shear_sound_speed_m_s = {cs}\n'
            "bone_shear_attenuation_db_cm_mhz = 20.0\n"
        )
        return str(path)

    sim = arfi.Simulation(arfi.Scenario.load(scenario(1500.0)))
    props = sim.properties_at([[0.0, 0.0, 30.0], [0.0, 0.0, 50.0]])
    assert props["shear_sound_speed_m_s"][0] == pytest.approx(750.0) and props["shear_sound_speed_m_s"][1] == 0.0
    # A CT's faces between layers convert on the march's planes, and the summary says so.
    summary = sim.propagation_summary()
    assert sim.has_shear and sim.propagation.shear and "a CT's faces between layers" in summary, summary
    # The same layer turned 20° about y: its planar walls convert, and the summary says where.
    z, x = np.meshgrid(10.0 + np.arange(41), -30.0 + np.arange(61), indexing="ij")
    tilted = np.where(np.abs((z - 30.0) * np.cos(np.radians(20)) + x * np.sin(np.radians(20))) <= 5.0, 1000.0, -1000.0)
    write_volume(
        tmp_path / "ct.nii", np.repeat(tilted[:, None, :], 61, axis=1).astype(np.float32), affine, "tilted layer"
    )
    sim = arfi.Simulation(arfi.Scenario.load(scenario(1500.0)))
    summary = sim.propagation_summary()
    assert sim.propagation.shear and "planar walls tilted" in summary and "not carried by the march" in summary, summary
    # The dense bone's 2900 m/s allows up to 2511 m/s.
    assert main(["field", "--scenario", scenario(2600.0), "--out", str(tmp_path / "f.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "ct.bone_shear_sound_speed_m_s" in err and "2511" in err, err
