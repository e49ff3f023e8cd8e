"""``arfi diagnose`` (the model-discrepancy workflow): the JSON keys and the paper's broadening story
end to end."""

import json

import numpy as np
import pytest

import arfi
from arfi.cli import main
from arfi.io.files import write_arfi_image

# The effects that act on the image alone (no march per evaluation), for tests of the bindings.
IMAGE_SPACE = [
    "amplitude",
    "broadening",
    "broadening_anisotropic",
    "registration_shift",
    "slice_offset",
    "background_phase",
]


def test_cli_diagnose_names_the_missing_broadening(tmp_path, sim):
    # The paper's story: a model without broadening (W = 0, calibration file) meets an image
    # with W = 2.7 mm; the workflow names `broadening` with W within 0.2 mm and stops. The CLI
    # (files, flags, JSON keys, report) with the image-space effects: naming among the whole
    # library is tests/suite/diagnose.rs's `the_papers_story_...`, and the tutorial's `arfi diagnose`
    # (test_docs.py) runs the CLI on the whole library.
    image = tmp_path / "m.nii.gz"
    assert main(["simulate", "--noise-rad", "0.02", "--seed", "5", "--out", str(image)]) == 0
    cal = tmp_path / "cal.json"
    cal.write_text(json.dumps({"broadening_width_mm": 0.0, "amplitude": sim.amplitude}))
    js = tmp_path / "d.json"
    report = tmp_path / "report"
    assert (
        main(
            [
                "diagnose",
                "--image",
                str(image),
                "--calibration",
                str(cal),
                "--effects",
                ",".join(IMAGE_SPACE),
                "--json",
                str(js),
                "--report",
                str(report),
            ]
        )
        == 0
    )
    d = json.loads(js.read_text())
    for key in ("effects", "cost_initial", "cost_final", "noise_floor"):
        assert key in d
    assert [e["name"] for e in d["effects"]] == ["broadening"]
    e = d["effects"][0]
    assert set(e) >= {"name", "params", "cost_before", "cost_after", "evidence"}
    assert e["params"]["broadening_width_mm"] == pytest.approx(2.7, abs=0.2)
    assert d["cost_final"] < d["cost_initial"] and d["residual_rms_final"] < 1.2 * d["noise_floor"]
    # The report: one figure per step (measured, model, residual, candidates), the gap, one page.
    assert sorted(p.name for p in report.iterdir()) == [
        "diagnose_gap.png",
        "diagnose_step0.png",
        "diagnose_step1.png",
        "report.html",
    ]
    page = (report / "report.html").read_text()
    assert "broadening" in page and page.count("data:image/png;base64") == 3


def test_diagnose_on_noise_only_names_nothing_and_rejects_bad_input(sim):
    # Every candidate tried is reported rejected (the whole library on noise alone is
    # tests/suite/diagnose.rs's `noise_only_names_nothing`).
    d = sim.diagnose(sim.arfi_image(noise_rad=0.02, seed=11), effects=IMAGE_SPACE)
    assert d.names == [] and sorted(c.name for c in d.rejected) == sorted(IMAGE_SPACE)
    with pytest.raises(ValueError, match="image"):
        sim.diagnose(sim.arfi_image()[:10])
    assert sim.diagnose(sim.arfi_image()).names == []  # noise-free and the exact model: nothing to add
    with pytest.raises(ValueError, match="threshold"):
        sim.diagnose(sim.arfi_image(noise_rad=0.02), threshold=float("nan"))


def test_cli_diagnose_bad_input_is_one_line_exit_2(tmp_path, capsys):
    assert main(["diagnose", "--image", str(tmp_path / "missing.nii.gz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("arfi: error:")
    assert not list(tmp_path.iterdir())


def test_several_images_at_once_and_effect_images(sim):
    # A calibration image and one with known group phases, both 0.9 mm off in x: the shift is
    # named once for both, within 0.3 mm (the workflow's required accuracy for a shift).
    known = np.linspace(-1.0, 1.0, sim.n_groups)
    images = [
        m + np.random.default_rng(k).normal(0.0, 0.02, m.shape)
        for k, m in enumerate(sim.effect_images({"dx_mm": 0.9}, known=[None, known]))
    ]
    # The image-space effects only: naming among the whole library is tested in Rust
    # (tests/suite/diagnose.rs); here the bindings carry several images and their known phases.
    d = sim.diagnose(images, [None, known], effects=IMAGE_SPACE)
    assert d.names == ["registration_shift"]
    assert d.effects[0].params["dx_mm"] == pytest.approx(0.9, abs=0.3)
    assert len(d.models_final) == 2 and d.n_pixels == 2 * images[0].size
    assert d.residual_rms_final < 1.2 * d.noise_floor
    with pytest.raises(ValueError, match="known"):
        sim.diagnose(images, [None])
    with pytest.raises(ValueError, match="effects"):
        sim.diagnose(images, [None, known], effects=["no_such_effect"])
    with pytest.raises(ValueError, match="unknown parameter"):
        sim.effect_images({"dx": 1.0})
    with pytest.raises(ValueError, match="dead_groups"):
        sim.effect_images({"dead_groups": [99]})
    with pytest.raises(ValueError, match="finite"):
        sim.effect_images({"scale": float("nan")})


def test_cli_diagnose_effects_option(tmp_path, capsys):
    image = tmp_path / "m.nii.gz"
    assert main(["simulate", "--noise-rad", "0.02", "--seed", "3", "--out", str(image)]) == 0
    assert main(["diagnose", "--image", str(image), "--effects", "amplitude,broadening"]) == 0
    assert "no effect missing" in capsys.readouterr().out
    assert main(["diagnose", "--image", str(image), "--effects", "amplitude,warp"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warp" in err[0]


def test_an_effect_that_cannot_be_fitted_is_reported_not_fatal():
    # With one group per element, element_dropout and phase_aberration (at most 128 groups) cannot
    # be fitted: the run goes on with the other effects and reports why they were left out.
    sim = arfi.Simulation(groups=1024)
    d = sim.diagnose(sim.arfi_image(noise_rad=0.02, seed=4))
    failed = {c.name: c.failure for c in d.rejected if c.failure}
    assert set(failed) == {"element_dropout", "phase_aberration"}
    assert all("128 groups" in f for f in failed.values())
    assert d.names == []
    json.dumps(d.to_dict(), allow_nan=False)  # failed candidates carry null, not inf


def test_a_time_limit_returns_the_effects_added_so_far(sim, tmp_path, capsys):
    import time

    image = sim.effect_images({"broadening_width_mm": 3.6, "dx_mm": 1.0})[0] + np.random.default_rng(3).normal(
        0.0, 0.02, sim.arfi_image().shape
    )
    full = sim.diagnose(image, effects=IMAGE_SPACE)
    assert full.stop == "converged" and set(full.names) >= {"broadening", "registration_shift"}
    t = time.perf_counter()
    d = sim.diagnose(image, time_limit_s=0.5, effects=IMAGE_SPACE)
    # Within the limit plus one candidate evaluation and the set-up (one HAS window, ~1 s).
    assert time.perf_counter() - t < 3.0
    assert d.stop == "time limit" and d.names == full.names[: len(d.names)] and len(d.names) < len(full.names)
    with pytest.raises(ValueError, match="time_limit_s"):
        sim.diagnose(image, time_limit_s=0.0)
    path = tmp_path / "m.nii.gz"
    write_arfi_image(path, image, sim.mr_affine_mm, sim.mr_volume_shape)
    assert main(["diagnose", "--image", str(path), "--time-limit-s", "0.5"]) == 0
    assert "stopped at the time limit" in capsys.readouterr().out


@pytest.mark.parametrize(
    "effect, hidden",
    [
        # One effect per kind of value: numbers (the anisotropic widths, a pair effect_images takes by name),
        # group indices and one phase per group. Every effect's round trip is tested in Rust
        # (tests/suite/diagnose.rs); this is the path through the bindings' dict.
        ("broadening_anisotropic", {"broadening_width_u_mm": 2.0, "broadening_width_v_mm": 3.6}),
        ("element_dropout", {"dead_groups": [5]}),
        ("phase_aberration", {"group_phases_rad": list(1.2 * np.sin(0.7 * np.arange(16)))}),
    ],
)
def test_reported_params_fed_to_effect_images_give_the_fitted_images(sim, effect, hidden):
    known = [None, np.linspace(-1.5, 1.5, 16)]
    images = [
        im + 0.02 * np.random.default_rng(k).standard_normal(im.shape)
        for k, im in enumerate(sim.effect_images(hidden, known))
    ]
    d = sim.diagnose(images, known, effects=[effect])
    assert d.names == [effect]
    step = d.effects[0]
    again = sim.effect_images(step.params, known)
    # The same forward model both ways: only the reported form of the values separates them.
    for a, b in zip(again, step.models):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_effect_images_names_the_known_parameters_when_one_is_unknown(sim):
    with pytest.raises(ValueError, match='unknown parameter "width_mm".*broadening_width_u_mm'):
        sim.effect_images({"width_mm": 2.0})
    assert set(arfi.analysis.diagnose.PARAMETERS) >= {
        "broadening_width_u_mm",
        "broadening_width_v_mm",
        "dead_groups",
        "group_phases_rad",
    }
    assert {e for e, _ in arfi.analysis.diagnose.PARAMETERS.values()} == set(arfi.analysis.diagnose.EFFECTS)


def test_effect_images_take_the_old_sound_speed_name_with_a_deprecation(sim) -> None:
    # The parameter was named sound_speed_m_per_s; the scenario's sound_speed_m_s is the one name
    # now, and the old one is accepted for one release with a DeprecationWarning.
    new = sim.effect_images({"sound_speed_m_s": 1600.0})
    with pytest.warns(DeprecationWarning, match="sound_speed_m_per_s' is now 'sound_speed_m_s'"):
        old = sim.effect_images({"sound_speed_m_per_s": 1600.0})
    np.testing.assert_array_equal(new[0], old[0])
    assert "sound_speed_m_s" in arfi.analysis.diagnose.PARAMETERS
