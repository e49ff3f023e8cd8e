import numpy as np
import pytest

import arfi
from arfi.simulation import images_and_known


def test_ideal_image_has_the_scenario_focal_phase_and_shape(sim, ideal):
    # The amplitude is defined so that the ideal focal ARFI phase is 0.6 rad.
    assert ideal.shape == (128, 96)
    assert ideal.max() == pytest.approx(0.6, rel=1e-9)
    assert sim.mr_volume_shape == (128, 96, 1)


def test_ideal_image_is_symmetric_about_the_focus(ideal):
    # The array and the default medium are symmetric under x -> -x and y -> -y; the MR pixel
    # grid is centred on the focus. The simulation grid has one extra sample at its -x/-y edge
    # (inside the absorbing layer), so allow 1e-3 of the peak.
    assert np.max(np.abs(ideal - ideal[::-1, :])) < 1e-3 * ideal.max()
    assert np.max(np.abs(ideal - ideal[:, ::-1])) < 1e-3 * ideal.max()


def test_focal_peak_sits_at_the_focus(sim, ideal):
    i, j = np.unravel_index(np.argmax(ideal), ideal.shape)
    pos = sim.mr_affine_mm @ np.array([i, j, 0, 1.0])
    # Pixels are 1.406 mm; the even matrix puts the focus on a pixel corner.
    assert abs(pos[0]) < 1.41 and abs(pos[1]) < 1.41 and pos[2] == pytest.approx(85.0)


def test_group_phases_equal_their_per_element_expansion(sim):
    rng = np.random.default_rng(3)
    g = rng.uniform(-np.pi, np.pi, sim.n_groups)
    a = sim.arfi_image(g)
    b = sim.arfi_image(g[sim.groups])
    np.testing.assert_array_equal(a, b)


def test_aberration_lowers_the_focus_and_a_common_phase_does_not(sim, ideal):
    rng = np.random.default_rng(0)
    aberrated = sim.arfi_image(rng.uniform(-np.pi, np.pi, sim.n_groups))
    assert aberrated.max() < 0.8 * ideal.max()
    shifted = sim.arfi_image(np.full(sim.n_elements, 1.234))
    np.testing.assert_allclose(shifted, ideal, atol=1e-12 * ideal.max())


def test_noise_is_seeded(sim, ideal):
    a = sim.arfi_image(noise_rad=0.02, seed=5)
    b = sim.arfi_image(noise_rad=0.02, seed=5)
    c = sim.arfi_image(noise_rad=0.02, seed=6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # The noise has the requested standard deviation (12288 pixels: sampling error ~0.6 %).
    assert np.std(a - ideal) == pytest.approx(0.02, rel=0.03)


def test_field_on_the_focal_plane(sim):
    f = sim.field()
    assert f.pressure.shape == (len(f.y_mm), len(f.x_mm))
    assert f.z_mm == pytest.approx(85.0, abs=sim.grid.dz_mm / 2)
    typed = f.focus()
    focus = typed.to_dict()
    # The typed result's attributes are the JSON's keys (the focal metrics under focal_metrics).
    assert isinstance(typed, arfi.FieldFocus) and typed.focal_metrics.to_dict() == {
        k: focus[k] for k in arfi.FocalMetrics._fields
    }
    for key in set(focus) - set(arfi.FocalMetrics._fields):
        value = getattr(typed, key)
        assert (list(value) if isinstance(value, (list, tuple)) else value) == focus[key], key
    assert abs(focus["plane_peak_x_mm"]) <= sim.grid.dx_mm and abs(focus["plane_peak_y_mm"]) <= sim.grid.dy_mm
    # The keys `arfi field` writes to its JSON, in order; no hotter place than the focus in water.
    metrics = [
        "focal_peak_mm",
        "focal_peak_pa",
        "peak_to_target_mm",
        "fwhm_6db_mm",
        "fwhm_6db_across_mm",
        "fwhm_3db_mm",
        "focal_volume_6db_mm3",
        "isppa_w_cm2",
        "mechanical_index",
        "focal_tissue",
    ]
    assert list(focus) == [
        "target_mm",
        *metrics,
        "plane_peak_pa",
        "plane_peak_x_mm",
        "plane_peak_y_mm",
        "plane_peak_to_axis_mm",
        "plane_hottest_pa",
        "plane_hottest_mm",
        "axis_peak_pa",
        "axis_peak_z_mm",
        "axis_peak_mm",
        "axis_hottest_pa",
        "axis_hottest_mm",
        "hottest",
    ]
    # Each metric is also the attribute of the same name of the Field's typed FocalMetrics (one
    # name per quantity); the phantom's focus lies within a few mm of the target (the peak sits
    # short of the geometric focus) and above the samples.
    m = f.focal_metrics
    assert all(focus[k] == getattr(m, k) for k in metrics)
    assert m.focal_tissue == "phantom" and m.peak_to_target_mm < 3.0 and m.focal_peak_pa >= focus["plane_peak_pa"]
    assert m.isppa_w_cm2 == pytest.approx(m.focal_peak_pa**2 / (2 * 1040 * 1533) / 1e4, rel=1e-12)
    assert (
        focus["plane_hottest_pa"] is None
        and focus["axis_hottest_mm"] is None
        and focus["target_mm"] == [0.0, 0.0, 85.0]
    )
    # The peak on the plane is its largest |p| here (a focus in water), at the sample the keys name.
    j, i = np.unravel_index(np.argmax(np.abs(f.pressure)), f.pressure.shape)
    assert focus["plane_peak_pa"] == np.abs(f.pressure).max() and (
        focus["plane_peak_x_mm"],
        focus["plane_peak_y_mm"],
    ) == (f.x_mm[i], f.y_mm[j])
    # An attribute is one array (made once), not a copy per access.
    assert f.pressure is f.pressure and f.axis_z_mm is f.axis_z_mm
    # Focal gain of a 81 mm aperture at 85 mm: between 10 and 25 times the face pressure.
    assert 10 < focus["plane_peak_pa"] / f.surface_pressure_pa < 25


def test_focal_metrics_alone_and_around_another_target(sim):
    # Without a target, the metrics of the field's own march, bit for bit (the box's march stops
    # at the box: the planes up to it are the same operators).
    focus = sim.field().focus().to_dict()
    alone = sim.focal_metrics()
    # A typed result whose to_dict() is the JSON's keys, those of Field.focus().
    d = alone.to_dict()
    assert isinstance(alone, arfi.FocalMetrics) and d == {k: focus[k] for k in d} and len(d) == 11
    assert d == sim.field().focal_metrics.to_dict() and list(d) == alone._fields
    # Steered 5 mm sideways and measured around that target: against a simulation built with its
    # focus there, which steers the same way but fixes its plan's mean wavenumbers on its own
    # beam (a different plan): the peak within 0.1 mm and |p| within 0.1 %.
    target = (5.0, 0.0, 85.0)
    shifted = sim.focal_metrics(sim.focus_shift_phases([5.0, 0.0, 0.0]), target_mm=target)
    there = (
        arfi.Simulation(arfi.Scenario.from_toml("[focus]\nposition_mm = [5.0, 0.0, 85.0]\n")).field().focus().to_dict()
    )
    assert list(shifted.target_mm) == list(target) == there["target_mm"]
    assert np.allclose(shifted.focal_peak_mm, there["focal_peak_mm"], atol=0.1)
    assert shifted.focal_peak_pa == pytest.approx(there["focal_peak_pa"], rel=1e-3)
    for bad in [(0.0, 0.0, 900.0), (np.nan, 0.0, 85.0), (1.0, 2.0)]:
        with pytest.raises(ValueError, match="target_mm"):
            sim.focal_metrics(target_mm=bad)


def test_face_pressure_delivers_the_acoustic_power(sim):
    # P = p_face² · A / (2·rho·c) with A = 1024 · (2.3 mm)², rho·c of water.
    p = sim.field().surface_pressure_pa
    area = 1024 * 2.3e-3**2
    assert p**2 * area / (2 * 1000 * 1500) == pytest.approx(70.0, rel=1e-12)


@pytest.mark.parametrize(
    "phases, match",
    [
        (np.zeros(15), "phases: has 15 values"),
        (np.array([np.nan] * 16), "phases"),
        (np.zeros((4, 4)), "phases: must be one-dimensional"),
        (["a"] * 16, "phases: not numeric"),
    ],
)
def test_bad_phases_raise_value_error(sim, phases, match):
    with pytest.raises(ValueError, match=match):
        sim.arfi_image(phases)


def test_bad_noise_and_plane_raise_value_error(sim):
    with pytest.raises(ValueError, match="noise_rad"):
        sim.arfi_image(noise_rad=-1)
    with pytest.raises(ValueError, match="z_mm"):
        sim.field(z_mm=1e4)


def test_reflections_option_adds_the_backward_wave_before_the_phantom(sim):
    # Water -> phantom: R = (1.594 - 1.5) / (1.594 + 1.5) = 0.0304 in pressure. The reflected wave
    # is the converging beam mirrored in the plane z = 40 mm: it diverges from a virtual focus at
    # z = 2·40 - 85 = -5 mm, so on the axis its amplitude relative to the incident beam is about
    # R·(85 - z)/(z + 5) (geometric optics), and it beats against it with period λ/2. Diffraction
    # near the foci makes this approximate: allow 30 %. Beyond the interface nothing changes.
    d = arfi.Scenario.default().to_dict()
    d["grid"]["reflections"] = True
    refl = arfi.Simulation(arfi.Scenario.from_dict(d))
    a, b = sim.field(), refl.field()
    z = a.axis_z_mm
    inside = z > 5  # the axis sample of plane 0 lies in the gap between quadrants: zero pressure
    ripple = np.where(inside, np.abs(np.abs(b.axis_pressure) / np.where(inside, np.abs(a.axis_pressure), 1.0) - 1), 0.0)
    r = (1.040 * 1533 - 1500) / (1.040 * 1533 + 1500)
    for lo, hi in [(20, 24), (30, 34), (35, 39)]:
        sel = (z > lo) & (z < hi)
        predicted = r * (85 - z[sel].mean()) / (z[sel].mean() + 5)
        assert abs(ripple[sel].max() / predicted - 1) < 0.3, (lo, ripple[sel].max(), predicted)
    np.testing.assert_allclose(b.axis_pressure[z > 41], a.axis_pressure[z > 41], rtol=1e-12)


PLATE = """
frequency_hz = 500000.0
[transducer]
elements_per_side = 4
[focus]
position_mm = [0.0, 0.0, 40.0]
[arfi]
amplitude_rad_m3_per_n = 1.0
[medium]
background = "water"
[[material]]
name = "water"
sound_speed_m_s = 1500.0
density_kg_m3 = 1000.0
[[material]]
name = "cortical"
sound_speed_m_s = 2800.0
density_kg_m3 = 1850.0
attenuation_db_cm_mhz = 4.0
[[region]]
material = "cortical"
shape = "slab"
z_min_mm = 15.0
z_max_mm = 21.5
"""


def test_propagation_says_which_interface_model_ran_and_where_it_reverberates(tmp_path):
    from arfi.cli import main

    sim = arfi.Simulation(arfi.Scenario.from_toml(PLATE))
    p = sim.propagation
    assert p.interfaces == "angular" and p.screen == "oblique" and p.reflections is False
    r = p.reverberation
    assert r is not None
    # Between the plate's faces (the grid puts each on the nearest plane, within one step).
    assert abs(r.first_interface_z_mm - 15.0) <= sim.grid.dz_mm and abs(r.last_interface_z_mm - 21.5) <= sim.grid.dz_mm
    assert r.round_trips >= 1
    # The JSON form (arfi field's "propagation") is the attributes, nested ones as dicts.
    assert p.to_dict() == {
        "interfaces": "angular",
        "screen": "oblique",
        "reflections": False,
        "shear": p.shear,
        "reverberation": {
            "first_interface_z_mm": r.first_interface_z_mm,
            "last_interface_z_mm": r.last_interface_z_mm,
            "round_trips": r.round_trips,
        },
    }
    assert sim.grid.to_dict() == {k: getattr(sim.grid, k) for k in arfi.Grid._fields}
    same = arfi.Simulation(arfi.Scenario.from_toml(PLATE))
    assert sim.grid == same.grid and "dz_mm=" in repr(sim.grid)
    # Frozen values: equal ones hash alike, so they key dicts and sets.
    assert hash(sim.grid) == hash(same.grid) and hash(sim.propagation) == hash(same.propagation)
    assert len({sim.grid, same.grid, arfi.Simulation().grid}) == 2 and p in {same.propagation: 1}
    normal = arfi.Simulation(
        arfi.Scenario.from_toml(PLATE.replace("[medium]", '[grid]\ninterfaces = "normal-incidence"\n[medium]'))
    )
    assert normal.propagation.to_dict() == {
        "interfaces": "normal-incidence",
        "screen": "oblique",
        "reflections": False,
        "shear": False,
        "reverberation": None,
    }
    vertical = arfi.Simulation(
        arfi.Scenario.from_toml(PLATE.replace("[medium]", '[grid]\nscreen = "vertical"\n[medium]'))
    )
    assert vertical.propagation.screen == "vertical"
    with pytest.raises(ValueError, match="grid.screen"):
        arfi.Scenario.from_toml(PLATE.replace("[medium]", '[grid]\nscreen = "slanted"\n[medium]'))
    scenario = tmp_path / "plate.toml"
    scenario.write_text(PLATE)
    assert (
        main(
            ["field", "--scenario", str(scenario), "--out", str(tmp_path / "f.npz"), "--report", str(tmp_path / "rep")]
        )
        == 0
    )
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "angle-dependent interface transmission" in html and "round trips" in html


def test_focus_shift_phases_move_the_focus_where_asked(sim):
    # Steering physics, not the code: with the phases for a 3 mm lateral shift the focal-plane peak
    # moves 3 mm in x (within one grid step, 0.68 mm: it lands about 0.3 mm short); with a +10 mm
    # axial shift the peak on the axis moves deeper by 5-15 mm (about 9.5 mm: the axial peak of a focused
    # beam sits short of its geometric focus). No shift, no phases; bad shifts are refused naming
    # the parameter.
    assert np.allclose(sim.focus_shift_phases((0.0, 0.0, 0.0)), 0.0)
    ideal = sim.field().focus()
    lateral = sim.field(sim.focus_shift_phases((3.0, 0.0, 0.0))).focus()
    step = float(np.diff(sim.field().x_mm[:2])[0])
    assert abs(lateral.plane_peak_x_mm - ideal.plane_peak_x_mm - 3.0) <= step
    axial = sim.field(sim.focus_shift_phases((0.0, 0.0, 10.0))).focus()
    assert 5.0 < axial.axis_peak_z_mm - ideal.axis_peak_z_mm < 15.0
    with pytest.raises(ValueError, match="shift_mm: must be three finite numbers"):
        sim.focus_shift_phases((0.0, 1.0))


def test_section_takes_one_drive_or_several(sim):
    # None, one vector, a list with None entries or a 2-D array: one section per drive, the
    # steering alone wherever None; the focus is the section's peak (85 mm from the array).
    truth = sim.condense(sim.skull_phases(seed=1))
    one, both = sim.section(), sim.section([None, truth])
    assert one.pressure.shape[0] == 1 and both.pressure.shape[0] == 2
    assert np.array_equal(one.pressure[0], both.pressure[0])
    assert np.array_equal(sim.section(truth).pressure[0], both.pressure[1])
    assert sim.section(np.zeros((3, 16))).pressure.shape[0] == 3
    n, i = np.unravel_index(np.argmax(np.abs(one.pressure[0])), one.pressure[0].shape)
    assert abs(one.z_mm[n] - 85.0) < 10.0 and abs(one.x_mm[i]) < 1.0
    assert np.abs(both.pressure[1]).max() < np.abs(both.pressure[0]).max()  # the aberration defocuses
    with pytest.raises(ValueError, match=r"phases\[1\]"):
        sim.section([None, [np.nan] * 16])


def test_element_amplitudes_weight_the_elements_linearly(sim):
    # The march is linear in the drives: the fields of amplitudes a and 1 - a add up to the whole
    # array's (to 1e-9 of the peak: double-precision sums), and amplitudes of 1 change nothing.
    a = np.random.default_rng(3).uniform(0.0, 1.0, sim.n_elements)
    whole = sim.field().pressure
    part, rest = (sim.with_element_amplitudes(v).field().pressure for v in (a, 1.0 - a))
    assert np.abs(part + rest - whole).max() < 1e-9 * np.abs(whole).max()
    assert np.array_equal(sim.with_element_amplitudes(np.ones(sim.n_elements)).field().pressure, whole)
    assert np.array_equal(sim.with_element_amplitudes(a).element_amplitudes, a) and np.all(
        sim.element_amplitudes == 1.0
    )
    for bad in [np.ones(3), -a, np.zeros(sim.n_elements), np.full(sim.n_elements, np.nan)]:
        with pytest.raises(ValueError, match="amplitudes"):
            sim.with_element_amplitudes(bad)


def test_images_and_known_take_one_image_or_several_in_every_form():
    img, p = np.arange(12.0).reshape(3, 4), np.linspace(0.0, 1.0, 5)
    for images, known in [(img, p), (img, [p]), (img.tolist(), p)]:
        arrays, knowns = images_and_known(images, known)
        assert len(arrays) == 1 and np.array_equal(arrays[0], img) and np.array_equal(knowns[0], p)
    for images in ([img, img], (img, img), np.stack([img, img])):
        arrays, knowns = images_and_known(images, [None, p])
        assert len(arrays) == 2 and knowns[0] is None and np.array_equal(knowns[1], p)
        assert images_and_known(images, None)[1] == [None, None]
    with pytest.raises(ValueError, match="^images: need at least one image"):
        images_and_known([], None)
    with pytest.raises(ValueError, match=r"^images\[0\]: must be a 2-D image"):
        images_and_known(np.zeros(5), None)
    with pytest.raises(ValueError, match=r"^known\[1\]: must be one-dimensional"):
        images_and_known([img, img], [p, np.zeros((2, 2))])


def test_a_shared_source_model_gives_the_same_simulation(sim):
    """``Simulation(..., source=other.source_model())`` reuses the array's projection where the
    array, grid, power and coupling medium are the same, and projects anew where they are not:
    the images are the same to the bit either way; anything but a source model is refused."""
    scenario = arfi.Scenario.default()
    phases = np.linspace(-1.0, 1.0, sim.n_elements)
    shared = arfi.Simulation(scenario, source=sim.source_model())
    assert sim.source_model().n_elements == sim.n_elements
    assert np.array_equal(shared.arfi_image(phases), sim.arfi_image(phases))
    small = arfi.Simulation(arfi.Scenario.from_toml("[transducer]\nelements_per_side = 4\n"))
    other = arfi.Simulation(scenario, source=small.source_model())
    assert np.array_equal(other.arfi_image(phases), sim.arfi_image(phases))
    with pytest.raises(ValueError, match="^source: "):
        arfi.Simulation(scenario, source=sim)  # type: ignore[arg-type]
