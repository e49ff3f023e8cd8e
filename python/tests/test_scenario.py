import pytest

import arfi


def test_default_round_trips_through_toml_and_dict(tmp_path):
    s = arfi.Scenario.default()
    d = s.to_dict()
    assert d["frequency_hz"] == 550e3
    assert d["transducer"]["kind"] == "planar-quadrants"
    assert d["mr"]["matrix"] == [128, 96]
    assert d["arfi"]["broadening_width_mm"] == 2.7
    assert arfi.Scenario.from_dict(d) == s
    path = tmp_path / "s.toml"
    s.save(path)
    assert arfi.Scenario.load(path) == s


def test_a_partial_file_keeps_the_other_defaults():
    s = arfi.Scenario.from_toml("[focus]\nposition_mm = [0.0, 5.0, 80.0]\n")
    d = s.to_dict()
    assert d["focus"]["position_mm"] == [0.0, 5.0, 80.0]
    assert d["region"][0]["radius_mm"] == 60.0
    assert d["mr"]["center_mm"] == [0.0, 5.0, 80.0]


@pytest.mark.parametrize(
    "text, names",
    [
        ("frequncy_hz = 5e5\n", "frequncy_hz"),
        ("[grid]\nspacing = 0.5\n", "spacing"),
        ("[[material]]\nname = 'w'\nsound_speed_m_s = -1500\ndensity_kg_m3 = 1000\n", "sound_speed_m_s"),
        ("[[material]]\nname = 'w'\nsound_speed_m_s = 1500\ndensity_kg_m3 = 0\n", "density_kg_m3"),
        ("[[material]]\nname = 'w'\nsound_speed_m_s = nan\ndensity_kg_m3 = 1000\n", "sound_speed_m_s"),
        ("frequency_hz = -1\n", "frequency_hz"),
        ("[transducer]\nkind = 'bowl'\npitch_mm = 2\n", "pitch_mm"),
        ("[transducer]\nkind = 'ring'\n", "transducer.kind"),
        ("[mr]\nplane = 'ab'\n", "mr.plane"),
        ("[arfi]\nmask_fraction = 1.5\n", "mask_fraction"),
        ("[[region]]\nmaterial = 'bone'\nshape = 'slab'\nz_min_mm = 1\nz_max_mm = 2\n", "material"),
        ("this is not toml", "scenario"),
    ],
)
def test_bad_scenarios_raise_value_error_naming_the_key(text, names):
    with pytest.raises(ValueError, match=names):
        arfi.Scenario.from_toml(text)


def test_missing_file_raises_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        arfi.Scenario.load(tmp_path / "absent.toml")


def test_coarse_spacing_is_refused_with_a_suggestion():
    s = arfi.Scenario.from_toml("[grid]\nspacing_mm = 2.0\n")
    with pytest.raises(ValueError, match=r"grid.spacing_mm.*too coarse.*0\.682 mm \(λ/4\)"):
        arfi.Simulation(s)


def test_a_grid_beyond_the_memory_budget_is_refused_before_allocating(monkeypatch):
    # 20 m across at λ/4: a 29 000² grid (~100 GiB), more than this machine has.
    s = arfi.Scenario.from_toml("[grid]\nlateral_size_mm = 20000.0\n")
    with pytest.raises(ValueError, match=r"grid needs [0-9.]+ GiB, more than .* coarser grid.spacing_mm"):
        arfi.Simulation(s)
    # The budget can be lowered for a shared machine.
    monkeypatch.setenv("ARFI_MEMORY_LIMIT_GIB", "0.001")
    with pytest.raises(ValueError, match=r"more than the 0.0 GiB"):
        arfi.Simulation()


def test_elements_csv_is_read_relative_to_the_scenario(tmp_path):
    rows = ["x_mm,y_mm,z_mm,nx,ny,nz,size_mm"]
    for i in range(8):
        rows.append(f"{(i - 3.5) * 5.0},0,0,0,0,1,4.5")
    (tmp_path / "els.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "s.toml").write_text(
        "[transducer]\nkind = 'elements'\nfile = 'els.csv'\n[focus]\nposition_mm = [0, 0, 60]\n[grid]\nz_max_mm = "
        "70\n[mr]\nfov_mm = [40, 40]\nmatrix = [32, 32]\n"
    )
    sim = arfi.Simulation(arfi.Scenario.load(tmp_path / "s.toml"))
    assert sim.n_elements == 8
    assert sim.element_positions_mm[0, 0] == pytest.approx(-17.5)


def test_bowl_of_elements_focuses_near_its_centre_of_curvature():
    # 32 disc elements on a 50 mm bowl (aperture 40 mm) in water, projected onto the first plane
    # with the Rayleigh integral. Fresnel number a²/(λR) ≈ 2.9: the intensity maximum sits a few
    # mm before the centre of curvature (O'Neil), and on the axis.
    text = """
[transducer]
kind = "bowl"
radius_of_curvature_mm = 50.0
aperture_diameter_mm = 40.0
elements = 32
[focus]
position_mm = [0.0, 0.0, 50.0]
[[material]]
name = "water"
sound_speed_m_s = 1500.0
density_kg_m3 = 1000.0
[grid]
lateral_size_mm = 64.0
z_max_mm = 70.0
[mr]
fov_mm = [30.0, 30.0]
matrix = [20, 20]
[arfi]
amplitude_rad_m3_per_n = 1.0
"""
    sim = arfi.Simulation(arfi.Scenario.from_toml(text))
    assert sim.n_elements == 32 and sim.grid.z0_mm > 4.0
    f = sim.field()
    focus = f.focus()
    assert 43.0 < focus.axis_peak_z_mm < 50.0
    assert abs(focus.plane_peak_x_mm) <= 1.0 and abs(focus.plane_peak_y_mm) <= 1.0
