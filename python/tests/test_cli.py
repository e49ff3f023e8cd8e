import json
import re
import subprocess
import sys

import numpy as np
import pytest

import arfi
from arfi.cli import main


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "arfi", *args], capture_output=True, text=True, timeout=300)


def test_scenario_default_prints_complete_toml_with_the_grid_it_uses():
    r = run("scenario", "--default")
    assert r.returncode == 0
    printed = arfi.Scenario.from_toml(r.stdout)
    grid = printed.to_dict()["grid"]
    assert set(grid) == {
        "spacing_mm",
        "step_mm",
        "lateral_size_mm",
        "z_max_mm",
        "sponge_width_mm",
        "reflections",
        "interfaces",
        "screen",
    }
    assert grid["interfaces"] == "angular" and grid["screen"] == "oblique" and grid["reflections"] is False
    # The written grid is the one the default resolves to, and nothing else differs.
    assert arfi.Simulation(printed).grid == arfi.Simulation().grid
    d = printed.to_dict()
    d["grid"] = {}
    assert arfi.Scenario.from_dict(d) == arfi.Scenario.default()


WATER_BOWL = """
frequency_hz = 550000.0
[transducer]
kind = "bowl"
radius_of_curvature_mm = 85.0
aperture_diameter_mm = 80.0
[medium]
background = "water"
[[material]]
name = "water"
sound_speed_m_s = 1500.0
density_kg_m3 = 1000.0
attenuation_db_cm_mhz = 0.0
"""


def test_field_in_lossless_water_needs_no_mr_model(tmp_path):
    # A hydrophone-tank scenario: no attenuation anywhere, so no radiation force in the MR slice.
    scenario = tmp_path / "water.toml"
    scenario.write_text(WATER_BOWL)
    out, js = tmp_path / "f.npz", tmp_path / "f.json"
    r = run("field", "--scenario", str(scenario), "--out", str(out), "--json", str(js))
    assert r.returncode == 0, r.stderr
    assert "angle-dependent interface transmission" in r.stdout
    result = json.loads(js.read_text())
    assert result["propagation"] == {
        "interfaces": "angular",
        "screen": "oblique",
        "reflections": False,
        "shear": False,
        "reverberation": None,
    }
    # The bowl focuses near its centre of curvature (O'Neil: the peak lies ~2 mm before it).
    assert 80.0 < result["axis_peak_z_mm"] < 85.5
    # Only the verbs that need MR-ARFI images refuse it, with the reason and exit 2.
    r = run("simulate", "--scenario", str(scenario), "--out", str(tmp_path / "m.nii.gz"))
    assert r.returncode == 2
    assert "no radiation force in the MR slice" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "m.nii.gz").exists()
    sim = arfi.Simulation(arfi.Scenario.from_toml(WATER_BOWL))
    with pytest.raises(ValueError, match="no radiation force"):
        _ = sim.amplitude
    with pytest.raises(ValueError, match="no radiation force"):
        sim.arfi_image()


def test_simulate_writes_nifti_with_affine_and_sidecar(tmp_path, sim):
    known = tmp_path / "known.txt"
    known.write_text("\n".join(str(v) for v in np.linspace(-1, 1, 16)))
    out = tmp_path / "m.nii.gz"
    js = tmp_path / "r.json"
    assert (
        main(["simulate", "--known-phases", str(known), "--noise-rad", "0", "--out", str(out), "--json", str(js)]) == 0
    )
    image, affine, side = arfi.read_arfi_image(out)
    assert image.shape == (128, 96)
    np.testing.assert_allclose(affine[:3, :3], np.diag([1.40625, 1.40625, 3.0]))
    np.testing.assert_allclose(affine[:3, 3], [-89.296875, -66.796875, 85.0])
    np.testing.assert_allclose(side["applied_phases_rad"], np.linspace(-1, 1, 16))
    result = json.loads(js.read_text())
    assert result["focal_arfi_rad"] == pytest.approx(image.max(), rel=1e-6)
    np.testing.assert_allclose(image, sim.arfi_image(np.linspace(-1, 1, 16)), atol=1e-6)


def test_simulate_focus_shift_records_per_element_known_phases(tmp_path, sim):
    # A defocused diversity image: the focus-shift phases plus any --known-phases, per element, in
    # the sidecar; the image is the one the Python API gives for the same phases.
    known = tmp_path / "known.txt"
    known.write_text("\n".join(str(v) for v in np.linspace(-1, 1, 16)))
    out = tmp_path / "d.nii.gz"
    assert (
        main(
            [
                "simulate",
                "--focus-shift-mm",
                "0",
                "0",
                "5",
                "--known-phases",
                str(known),
                "--noise-rad",
                "0",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    image, _, side = arfi.read_arfi_image(out)
    expected = sim.element_phases(np.linspace(-1, 1, 16)) + sim.focus_shift_phases((0.0, 0.0, 5.0))
    np.testing.assert_allclose(side["applied_phases_rad"], expected)
    np.testing.assert_allclose(image, sim.arfi_image(expected), atol=1e-6)


def test_field_writes_the_documented_npz_keys(tmp_path):
    out = tmp_path / "f.npz"
    assert main(["field", "--z-mm", "60", "--out", str(out)]) == 0
    with np.load(out) as z:
        for key in ("pressure", "x_mm", "y_mm", "z_mm", "axis_pressure", "axis_z_mm", "surface_pressure_pa"):
            assert key in z.files
        assert z["pressure"].dtype == np.complex128
        assert z["pressure"].shape == (len(z["y_mm"]), len(z["x_mm"]))
        assert float(z["z_mm"]) == pytest.approx(60.0, abs=0.4)


@pytest.mark.parametrize(
    "make, args, match",
    [
        (None, ["simulate", "--out", "{d}/x.nii.gz", "--scenario", "{d}/missing.toml"], "missing.toml"),
        ("frequncy = 1\n", ["simulate", "--out", "{d}/x.nii.gz", "--scenario", "{d}/s.toml"], "frequncy"),
        ("[grid]\nspacing_mm = 3.0\n", ["field", "--out", "{d}/x.npz", "--scenario", "{d}/s.toml"], "too coarse"),
        (
            "[[material]]\nname='w'\nsound_speed_m_s=-5\ndensity_kg_m3=1\n",
            ["simulate", "--out", "{d}/x.nii.gz", "--scenario", "{d}/s.toml"],
            "sound_speed",
        ),
        (
            "1\n2\n3\n",
            ["simulate", "--phases", "{d}/s.toml", "--out", "{d}/x.nii.gz"],
            "--phases: {d}/s.toml: has 3 values",
        ),
        ("nan\n" * 16, ["simulate", "--phases", "{d}/s.toml", "--out", "{d}/x.nii.gz"], "NaN"),
        (None, ["simulate", "--noise-rad", "-1", "--out", "{d}/x.nii.gz"], "noise_rad: must be a finite number >= 0"),
        (None, ["simulate", "--out", "{d}/x.png"], ".nii"),
        (
            None,
            ["simulate", "--focus-shift-mm", "0", "0", "nan", "--out", "{d}/x.nii.gz"],
            "--focus-shift-mm: must be three finite numbers",
        ),
        (None, ["field", "--z-mm", "900", "--out", "{d}/x.npz"], "z_mm"),
        (None, ["estimat"], "invalid choice"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, make, args, match):
    if make is not None:
        (tmp_path / "s.toml").write_text(make)
    args = [a.format(d=tmp_path) for a in args]
    r = run(*args)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("arfi: error:"), r.stderr
    assert match.format(d=tmp_path) in lines[0]
    assert "Traceback" not in r.stderr and "panicked" not in r.stderr
    assert not any(p.name.startswith("x") or p.name.startswith(".x") for p in tmp_path.iterdir())


@pytest.fixture(scope="module")
def measured(tmp_path_factory, sim, ideal):
    """A noise-free MR-ARFI image of the default scenario."""
    path = tmp_path_factory.mktemp("measured") / "m.nii.gz"
    arfi.write_arfi_image(path, ideal, sim.mr_affine_mm, sim.mr_volume_shape)
    return path


@pytest.mark.parametrize(
    "args, match",
    [
        (["simulate", "--seed", "-1", "--out", "{d}/x.nii.gz"], "seed: must be an integer"),
        (["simulate", "--seed", "18446744073709551616", "--out", "{d}/x.nii.gz"], "seed: must be an integer"),
        (["simulate", "--noise-rad", "nan", "--out", "{d}/x.nii.gz"], "noise_rad: must be a finite number"),
        (
            ["calibrate", "--image", "{m}", "--max-width-mm", "0", "--report", "{d}/x"],
            "max_width_mm: must be a finite number > 0",
        ),
        (["calibrate", "--image", "{m}", "--max-width-mm", "inf"], "max_width_mm: must be a finite number"),
        (["estimate", "--image", "{m}", "--seed", "-1", "--out-phases", "{d}/x.npy"], "--seed: must be an integer"),
        (
            ["estimate", "--image", "{m}", "--max-evaluations", "0", "--suggest", "{d}/x.npy"],
            "--max-evaluations: must be > 0",
        ),
        (["estimate", "--image", "{m}", "--starts", "0", "--report", "{d}/x"], "--starts: must be >= 1"),
        (["estimate", "--image", "{m}", "--time-limit-s", "0"], "--time-limit-s: must be a finite number > 0"),
        (
            ["estimate", "--image", "{m}", "--noise-rad", "0", "--out-phases", "{d}/x.npy"],
            "--noise-rad: must be a finite number > 0",
        ),
        (
            ["estimate", "--image", "{m}", "--noise-rad", "nan", "--json", "{d}/x.json"],
            "--noise-rad: must be a finite number, got nan",
        ),
        (
            ["estimate", "--image", "{m}", "--out-phases", "{d}/x.npy", "--suggest", "{d}/x.txt"],
            "--suggest: {d}/x.txt: phase vectors are written as .npy",
        ),
        (
            ["diagnose", "--image", "{m}", "--time-limit-s", "nan", "--report", "{d}/x"],
            "time_limit_s: must be a finite number",
        ),
        (["reproduce", "--repeats", "0", "--out", "{d}/x"], "repeats: must be an integer in [1, 100], got 0"),
        (["reproduce", "--repeats", "101", "--out", "{d}/x"], "repeats: must be an integer in [1, 100], got 101"),
        (["reproduce", "--diversity", "33", "--out", "{d}/x"], "diversity: must be an integer in [0, 32]"),
        (["reproduce", "--loop2", "21", "--out", "{d}/x"], "loop2_iterations: must be an integer in [0, 20]"),
        (["reproduce", "--noise-rad", "-0.1", "--out", "{d}/x"], "noise_rad: must be a finite number >= 0"),
        (["reproduce", "--seed", "-1", "--out", "{d}/x"], "seed: must be an integer"),
        (["sweep", "--seed", "-1", "--out", "{d}/x"], "first_seed: must be an integer"),
    ],
)
def test_bad_options_are_refused_by_the_library_before_anything_is_written(tmp_path, capsys, measured, args, match):
    # The CLI does not check these options itself: the library function each verb calls refuses
    # the value (ValueError naming the parameter), which the CLI reports as one line, exit 2.
    args = [a.format(d=tmp_path, m=measured) for a in args] + ["--json", str(tmp_path / "x.json")]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("arfi: error:") and match.format(d=tmp_path) in err, err
    assert list(tmp_path.iterdir()) == []


SMALL_ARRAY = "[transducer]\nelements_per_side = 8\n"


def test_estimate_per_element_on_a_small_array(tmp_path):
    """`--groups` = number of elements (256 here, 1024 on the default array) gives one phase per
    element; one image has fewer masked pixels than phases, so it is flagged."""
    scen = tmp_path / "small.toml"
    scen.write_text(SMALL_ARRAY)
    sim = arfi.Simulation(arfi.Scenario.load(scen))
    np.save(tmp_path / "truth.npy", sim.skull_phases(1))
    image = tmp_path / "ab.nii.gz"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                str(scen),
                "--phases",
                str(tmp_path / "truth.npy"),
                "--noise-rad",
                "0",
                "--out",
                str(image),
            ]
        )
        == 0
    )
    js = tmp_path / "e.json"
    r = run(
        "estimate",
        "--scenario",
        str(scen),
        "--image",
        str(image),
        "--groups",
        "256",
        "--max-evaluations",
        "40",
        "--json",
        str(js),
        "--out-phases",
        str(tmp_path / "out.npy"),
    )
    assert r.returncode == 0, r.stderr
    d = json.loads(js.read_text())
    assert len(d["phases_rad"]) == 256 and len(d["group_phases_rad"]) == 16
    assert d["evaluations"] <= 40 and d["stop"] == "evaluation limit" and d["converged"] is False
    assert d["n_pixels"] < 256 and d["underdetermined"] and d["ambiguous"]
    assert "underdetermined" in r.stdout and "NOT CONVERGED" in r.stdout
    # Without a prior, an estimate the images do not support (and one whose search did not
    # converge) is not recommended: the safer phases are named, printed and written.
    s = d["support"]
    assert set(s) == {
        "determined_phases",
        "expected_focus",
        "uncorrected_focus",
        "groups_focus",
        "determined",
        "converged",
    }
    assert 0 < s["determined_phases"] < 256 and not s["determined"] and s["expected_focus"] < s["uncorrected_focus"]
    assert d["recommended"] in ("uncorrected", "groups") and d["supported"] is False
    assert f"recommended: {d['recommended']}" in r.stdout and "NOT SUPPORTED" in r.stdout
    expected = np.zeros(256) if d["recommended"] == "uncorrected" else np.asarray(d["group_phases_rad"])[sim.groups]
    assert np.allclose(d["recommended_phases_rad"], expected) and np.allclose(np.load(tmp_path / "out.npy"), expected)
    r = run("estimate", "--scenario", str(scen), "--image", str(image), "--groups", "256", "--method", "nelder-mead")
    assert r.returncode == 2 and "method: per-element" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    # More groups than the kernels take (256), but not one per element: refused before any work.
    default = tmp_path / "default.nii.gz"
    assert main(["simulate", "--noise-rad", "0", "--out", str(default)]) == 0
    r = run("estimate", "--image", str(default), "--groups", "512")
    assert r.returncode == 2 and "groups: 512 groups" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_every_verb_has_help_with_an_example(capsys):
    from arfi.cli import build_parser

    verbs = list(build_parser()._subparsers._group_actions[0].choices)  # type: ignore[union-attr]
    assert {"scenario", "field", "dicom", "simulate", "calibrate", "estimate", "diagnose", "reproduce"} <= set(verbs)
    for verb in verbs:
        with pytest.raises(SystemExit) as e:
            main([verb, "--help"])
        text = capsys.readouterr().out
        assert e.value.code == 0 and f"example: arfi {verb} " in text and "--json" in text, verb


def test_every_option_of_every_verb_says_what_it_does():
    import argparse

    from arfi.cli import build_parser

    undocumented = []
    for verb, parser in build_parser()._subparsers._group_actions[0].choices.items():  # type: ignore[union-attr]
        for action in parser._actions:
            if (
                action.option_strings
                and not isinstance(action, argparse._HelpAction)
                and not (action.help or "").strip()
            ):
                undocumented.append(f"{verb} {action.option_strings[0]}")
    assert not undocumented, undocumented


def test_reports_of_field_simulate_calibrate_and_estimate(tmp_path, capsys):
    phases = tmp_path / "ab.npy"
    np.save(phases, np.random.default_rng(3).uniform(-2, 2, 16))
    image = tmp_path / "a.nii.gz"
    assert main(["simulate", "--phases", str(phases), "--out", str(image), "--report", str(tmp_path / "sim")]) == 0
    assert main(["calibrate", "--image", str(image), "--report", str(tmp_path / "cal")]) == 0
    assert main(["estimate", "--image", str(image), "--method", "lbfgs", "--report", str(tmp_path / "est")]) == 0
    assert (
        main(["field", "--phases", str(phases), "--out", str(tmp_path / "f.npz"), "--report", str(tmp_path / "field")])
        == 0
    )
    # Each verb says where its report went, as validate and diagnose do.
    said = [line for line in capsys.readouterr().out.splitlines() if " report -> " in line]
    assert said == [
        f"{verb}: report -> {tmp_path / folder / 'report.html'}"
        for verb, folder in (("simulate", "sim"), ("calibrate", "cal"), ("estimate", "est"), ("field", "field"))
    ]
    expected = {
        "sim": ["simulate.png"],
        "cal": ["calibrate_images.png"],
        "est": ["estimate_images.png", "estimate_elements.png"],
        "field": ["field.png", "field_sections.png"],
    }
    for folder, pngs in expected.items():
        page = (tmp_path / folder / "report.html").read_text()
        # Self-contained: every figure embedded, none linked.
        assert page.count("data:image/png;base64,") == len(pngs) and "src='" + pngs[0] not in page
        # Values written for people: no Python reprs, no None, numbers to 4 significant digits.
        text = re.sub(r"<img[^>]*>", "", page)
        assert "None" not in text and "{'" not in text and "[" not in text, folder
        long = [n for n in re.findall(r"\d+\.\d+", text) if len(n.replace(".", "").lstrip("0")) > 5]
        assert not long, (folder, long[:3])
        for png in pngs:
            assert (tmp_path / folder / png).read_bytes()[:4] == b"\x89PNG"


def test_fit_figures_crop_to_the_focal_spot_and_carry_a_warning(tmp_path):
    # The default image (180 x 135 mm field of view, a ~5 mm spot, noise 0.02 rad): the figures'
    # box holds the spot and is far smaller than the field of view; a flagged estimate's warning
    # heads its page.
    import arfi
    from arfi.reports.figures import focal_box_mm, image_extent_mm
    from arfi.reports.html import fit_report

    sim = arfi.Simulation()
    image = sim.arfi_image(noise_rad=0.02, seed=1)
    u0, u1, v0, v1 = focal_box_mm(sim, [image])
    full = image_extent_mm(sim, image)
    assert 20.0 <= u1 - u0 <= 40.0 and 20.0 <= v1 - v0 <= 40.0 and (full[1] - full[0]) > 150.0
    peak = np.unravel_index(np.argmax(image), image.shape)
    du, dv = (full[1] - full[0]) / image.shape[0], (full[3] - full[2]) / image.shape[1]
    assert u0 < full[0] + (peak[0] + 0.5) * du < u1 and v0 < full[2] + (peak[1] + 0.5) * dv < v1
    fit_report(
        tmp_path, sim, "estimate", image, image, {"misfit": 4.8}, np.zeros(16), warning="AMBIGUOUS: see the summary"
    )
    page = (tmp_path / "report.html").read_text()
    assert "<p style='color:red'><b>AMBIGUOUS: see the summary</b></p>" in page


def test_the_reports_noise_and_lobe_come_from_the_core():
    # The focal crop's noise: white noise of 0.02 rad on a phase ramp (a background the MAD of raw
    # values would take for noise), with a hole of NaN pixels: the core's 3 x 3 second-difference
    # mask gives 0.02 within 5 % (about 17 000 windows: the median's spread is under 1.5 %).
    from arfi._core import connected_region, image_noise_rad

    rng = np.random.default_rng(4)
    u = np.arange(180)[:, None] * np.ones((1, 100))
    image = 0.02 * rng.standard_normal((180, 100)) + 0.01 * u
    image[50:60, 20:40] = np.nan
    assert image_noise_rad(image) == pytest.approx(0.02, rel=0.05)
    # The -6 dB lobe of the sections: what touches the start through faces, not corners.
    values = np.zeros((5, 5))
    values[:2, :2] = values[2, 2] = values[3, 2] = 1.0
    region = connected_region(values, [1, 1], 0.5)
    assert region.dtype == bool and region.sum() == 4 and not region[2, 2]
    for bad in ([-1, 0], [5, 0], [1]):
        with pytest.raises(ValueError, match="start"):
            connected_region(values, bad, 0.5)


def test_image_axes_follow_the_mr_plane():
    from types import SimpleNamespace

    from arfi.reports.figures import axis_labels, image_extent_mm

    a = np.eye(4)
    a[0, 0], a[2, 2], a[0, 3], a[2, 3] = 2.0, 0.5, -10.0, 80.0  # xz image: u along x, v along z
    sim = SimpleNamespace(mr_plane="xz", mr_affine_mm=a)
    assert axis_labels(sim) == {"xlabel": "x (mm)", "ylabel": "z (mm)"}
    # Pixel edges: first centre minus half a pixel, last centre plus half a pixel.
    assert image_extent_mm(sim, np.zeros((11, 41))) == [-11.0, 11.0, 79.75, 100.25]


def test_estimate_weighs_the_elements_by_a_predicted_transmission(tmp_path, capsys, sim):
    # Images of an array whose elements reach the focus unevenly (as through a skull): the model
    # weighted by that transmission (relative to its mean) explains them; the unweighted one
    # cannot (noise-free, so the weighted fit's cost is near 0).
    element = np.arange(sim.n_elements)
    t = 0.2 + 0.8 * (element % 64) / 63.0 * (element // 512 + 1) / 2.0
    truth = sim.condense(sim.skull_phases(seed=2))
    image = tmp_path / "m.nii.gz"
    arfi.write_arfi_image(
        image, sim.with_element_amplitudes(t / t.mean()).arfi_image(truth), sim.mr_affine_mm, sim.mr_volume_shape
    )
    (tmp_path / "prediction.json").write_text(json.dumps({"transmission": list(t), "target_mm": list(sim.focus_mm)}))
    costs = {}
    for name, extra in [("plain", []), ("weighted", ["--prior-transmission", str(tmp_path / "prediction.json")])]:
        assert main(["estimate", "--image", str(image), "--json", str(tmp_path / f"{name}.json"), *extra]) == 0
        costs[name] = json.loads((tmp_path / f"{name}.json").read_text())["cost"]
    assert costs["weighted"] < 0.01 * costs["plain"], costs
    assert json.loads((tmp_path / "weighted.json").read_text())["prior_transmission"] == str(
        tmp_path / "prediction.json"
    )
    capsys.readouterr()
    np.save(tmp_path / "short.npy", t[:10])
    np.save(tmp_path / "negative.npy", -t)
    (tmp_path / "other.json").write_text(json.dumps({"phases_rad": [0.0]}))
    # Predicted for a target 2 mm from the scenario's focus: each element's wave crosses other bone.
    elsewhere = (np.asarray(sim.focus_mm) + [2.0, 0.0, 0.0]).tolist()
    (tmp_path / "elsewhere.json").write_text(json.dumps({"transmission": list(t), "target_mm": elsewhere}))
    for bad in ["short.npy", "negative.npy", "other.json", "missing.json", "elsewhere.json"]:
        assert (
            main(
                [
                    "estimate",
                    "--image",
                    str(image),
                    "--prior-transmission",
                    str(tmp_path / bad),
                    "--out-phases",
                    str(tmp_path / "x.npy"),
                ]
            )
            == 2
        )
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "--prior-transmission" in err and bad in err, err
    assert not (tmp_path / "x.npy").exists()


def test_estimate_refuses_a_bone_speed_prior_it_cannot_fit(tmp_path, capsys, sim):
    # --prior-bone-speed-std-percent needs the prediction (--prior) and its sensitivity (the JSON
    # of arfi predict), one phase per element, a [ct] scenario (the mode is fitted on the head
    # with the CT's bone) and a std >= 0: one line each, exit 2, nothing written.
    image = tmp_path / "m.nii.gz"
    arfi.write_arfi_image(image, sim.arfi_image(None), sim.mr_affine_mm, sim.mr_volume_shape)
    n = sim.n_elements
    np.save(tmp_path / "prior.npy", np.zeros(n))
    plain = {"transmission": [1.0] * n, "target_mm": list(sim.focus_mm)}
    (tmp_path / "plain.json").write_text(json.dumps(plain))
    (tmp_path / "short.json").write_text(json.dumps({**plain, "bone_speed_sensitivity_rad_per_percent": [0.01] * 3}))
    (tmp_path / "full.json").write_text(json.dumps({**plain, "bone_speed_sensitivity_rad_per_percent": [0.01] * n}))
    prior = ["--prior", str(tmp_path / "prior.npy"), "--prior-std-rad", "0.3"]
    cases = [
        (["--groups", str(n)], "--prior-transmission"),
        (["--groups", str(n), "--prior-transmission", str(tmp_path / "plain.json")], "bone_speed_sensitivity"),
        (["--groups", str(n), "--prior-transmission", str(tmp_path / "short.json")], f"{n} finite numbers"),
        (["--prior-transmission", str(tmp_path / "full.json")], "per-element estimates only"),
        (["--groups", str(n), "--prior-transmission", str(tmp_path / "full.json")], "[ct]"),
    ]
    for extra, says in cases:
        assert (
            main(
                [
                    "estimate",
                    "--image",
                    str(image),
                    *prior,
                    *extra,
                    "--prior-bone-speed-std-percent",
                    "20",
                    "--out-phases",
                    str(tmp_path / "x.npy"),
                ]
            )
            == 2
        )
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "--prior-bone-speed-std-percent" in err and says in err, err
    assert (
        main(
            [
                "estimate",
                "--image",
                str(image),
                "--groups",
                str(n),
                "--prior-transmission",
                str(tmp_path / "full.json"),
                "--prior-bone-speed-std-percent",
                "20",
                "--out-phases",
                str(tmp_path / "x.npy"),
            ]
        )
        == 2
    )
    assert "needs --prior" in capsys.readouterr().err
    assert (
        main(
            [
                "estimate",
                "--image",
                str(image),
                *prior,
                "--groups",
                str(n),
                "--prior-transmission",
                str(tmp_path / "full.json"),
                "--prior-bone-speed-std-percent",
                "-5",
                "--out-phases",
                str(tmp_path / "x.npy"),
            ]
        )
        == 2
    )
    assert "must be a finite number >= 0" in capsys.readouterr().err
    assert not (tmp_path / "x.npy").exists()
    # The Python API names the parameter.
    with pytest.raises(ValueError, match="prior_modes"):
        sim.with_groups(n).estimate(
            sim.arfi_image(None),
            prior=np.zeros(n),
            prior_std_rad=0.3,
            prior_correlation_mm=30,
            prior_modes=np.zeros((1, 5)),
        )
    with pytest.raises(ValueError, match="prior_modes"):
        sim.with_groups(n).estimate(sim.arfi_image(None), prior=np.zeros(n), prior_std_rad=0.3, prior_modes=np.zeros(n))


def test_an_estimate_with_a_prior_that_the_images_contradict_recommends_the_prediction(tmp_path, capsys):
    # Images broadened far more than the model (W = 6 mm against 2.7): no phases explain them
    # (MODEL MISMATCH). With a prior, the estimate is then not the correction to apply: the line
    # says so, --out-phases holds the prediction and the JSON names it.
    blurred = arfi.Scenario.default().to_dict()
    blurred["arfi"]["broadening_width_mm"] = 6.0
    sim = arfi.Simulation(arfi.Scenario.from_dict(blurred))
    truth = sim.condense(sim.skull_phases(seed=4))
    image = tmp_path / "m.nii.gz"
    arfi.write_arfi_image(image, sim.arfi_image(truth, 0.02, 1), sim.mr_affine_mm, sim.mr_volume_shape)
    prior = truth + 0.2 * np.cos(np.arange(16))
    np.save(tmp_path / "prior.npy", prior)
    assert (
        main(
            [
                "estimate",
                "--image",
                str(image),
                "--prior",
                str(tmp_path / "prior.npy"),
                "--prior-std-rad",
                "0.3",
                "--out-phases",
                str(tmp_path / "out.npy"),
                "--json",
                str(tmp_path / "e.json"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    result = json.loads((tmp_path / "e.json").read_text())
    assert result["model_mismatch"] and result["prior_used"] and result["recommended"] == "prediction", result["misfit"]
    assert "NOT to be applied" in out and "prediction" in out and "out.npy" in out, out
    assert np.allclose(np.load(tmp_path / "out.npy"), prior) and np.allclose(result["recommended_phases_rad"], prior)
    # Without the contradiction the estimate is what it recommends.
    good = tmp_path / "good.nii.gz"
    plain = arfi.Simulation()
    arfi.write_arfi_image(good, plain.arfi_image(truth, 0.02, 1), plain.mr_affine_mm, plain.mr_volume_shape)
    assert (
        main(
            [
                "estimate",
                "--image",
                str(good),
                "--prior",
                str(tmp_path / "prior.npy"),
                "--prior-std-rad",
                "0.3",
                "--out-phases",
                str(tmp_path / "out.npy"),
                "--json",
                str(tmp_path / "e.json"),
            ]
        )
        == 0
    )
    result = json.loads((tmp_path / "e.json").read_text())
    assert not result["model_mismatch"] and result["recommended"] == "estimate"
    assert np.allclose(np.load(tmp_path / "out.npy"), result["phases_rad"])


def test_images_with_pixels_without_signal_are_read_and_fitted(tmp_path, sim, ideal):
    # NaN marks a pixel without MR signal (bone, a masked-out pixel): read as NaN, fitted without
    # it; infinity is refused naming the file.
    image = ideal.copy()
    image[:, :10] = np.nan
    path = tmp_path / "m.nii.gz"
    arfi.write_arfi_image(path, image, sim.mr_affine_mm, sim.mr_volume_shape)
    read, _, _ = arfi.read_arfi_image(path)
    assert np.array_equal(np.isnan(read), np.isnan(image))
    assert main(["calibrate", "--image", str(path), "--json", str(tmp_path / "c.json")]) == 0
    assert json.loads((tmp_path / "c.json").read_text())["broadening_width_mm"] == pytest.approx(2.7, abs=0.05)
    image[0, 0] = np.inf
    arfi.write_arfi_image(path, image, sim.mr_affine_mm, sim.mr_volume_shape)
    with pytest.raises(ValueError, match="infinite"):
        arfi.read_arfi_image(path)


def test_sweep_without_dask_names_the_extra_to_install(tmp_path, capsys, monkeypatch):
    # Python refuses to import a module whose sys.modules entry is None: as if dask were absent.
    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    assert main(["sweep", "--seeds", "1", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'pip install "arfi[cluster]"' in err, err
    assert not (tmp_path / "o").exists()


def test_a_known_noise_weighs_the_estimate_instead_of_the_background_floor(tmp_path, capsys, sim, measured):
    # The images' noise where it is known (--noise-rad) replaces the floor estimated from their
    # backgrounds: the misfit scales with it, the printed line says it was given. (Through a head
    # at 650 kHz the floor is 0.024-0.025 rad for a noise of 0.02 and hides a model mismatch:
    # docs/estimation.md.)
    assert main(["estimate", "--image", str(measured), "--json", str(tmp_path / "a.json")]) == 0
    floor = json.loads((tmp_path / "a.json").read_text())
    assert "noise floor" in capsys.readouterr().out
    given = 2.0 * max(floor["noise_floor"], 1e-3)
    assert (
        main(["estimate", "--image", str(measured), "--noise-rad", str(given), "--json", str(tmp_path / "b.json")]) == 0
    )
    result = json.loads((tmp_path / "b.json").read_text())
    assert "noise given" in capsys.readouterr().out
    assert result["noise_floor"] == pytest.approx(given)
    # The same fit (the noise weighs every pixel alike), its misfit over the given noise's square.
    assert result["cost"] == pytest.approx(floor["cost"], rel=1e-6)
    assert result["misfit"] == pytest.approx(floor["misfit"] * (max(floor["noise_floor"], 1e-4) / given) ** 2, rel=1e-6)
    with pytest.raises(ValueError, match="noise_rad: must be a finite number > 0"):
        sim.estimate([sim.arfi_image()], [None], noise_rad=-0.01)
