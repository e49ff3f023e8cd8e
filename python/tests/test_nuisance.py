"""Nuisance parameters fitted jointly with per-element phases (``fit_nuisance``): on a small
array (256 elements) so that each estimate takes seconds. The physics claims (data from a
finer-grid simulation, 1024 elements, seeds 1-5) are in crates/has-core/tests/suite/nuisance.rs."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arfi
from arfi.cli import main

SMALL = "[transducer]\nelements_per_side = 8\n"


@pytest.fixture(scope="module")
def small() -> arfi.Simulation:
    return arfi.Simulation(arfi.Scenario.from_toml(SMALL))


def hidden_background(sim: arfi.Simulation, truth: np.ndarray, offsets: list[float], seed: int) -> list[np.ndarray]:
    """Images with `truth` applied, one per offset (rad) of the background, a ramp of 2e-4
    rad/mm along u and an amplitude scale of 0.9, plus 0.02 rad of seeded noise."""
    rng = np.random.default_rng(seed)
    images = []
    for off in offsets:
        (img,) = sim.effect_images({"scale": 0.9, "offset_rad": off, "slope_x_rad_per_mm": 2e-4}, [truth])
        images.append(img + rng.normal(0.0, 0.02, img.shape))
    return images


def test_amplitude_and_backgrounds_are_fitted_with_the_element_phases(small: arfi.Simulation) -> None:
    el = small.with_groups(small.n_elements)
    truth = small.skull_phases(3)
    offsets = [0.03, -0.02]
    known = [None, small.focus_shift_phases([0.0, 0.0, 5.0])]
    images = hidden_background(small, truth, offsets, 3)
    images[1] = hidden_background(small, truth + known[1], offsets[1:], 4)[0]
    plain = el.estimate(images, known, prior=truth, prior_std_rad=0.3, max_evaluations=60)
    fitted = el.estimate(
        images, known, prior=truth, prior_std_rad=0.3, max_evaluations=60, fit_nuisance="amplitude,background_phase"
    )
    assert plain.nuisance is None and plain.model_mismatch
    n = fitted.nuisance
    assert n is not None and n.fitted == ["amplitude", "background_phase"]
    # Hundreds of pixels per image determine the offset far below the 0.02 rad noise per pixel;
    # 0.005 rad leaves room for the phases' trade with the scale.
    assert np.allclose(n.offset_rad, offsets, atol=0.005), n
    assert abs(n.slope_x_rad_per_mm[0] - 2e-4) < 1e-4, n
    assert abs(n.scale - 0.9) < 0.05, n
    # One amplitude scale: the estimate's is the one its nuisance fit applied.
    assert fitted.scale == n.scale and plain.scale == 1.0
    # Not fitted: the model's values.
    assert n.broadening_width_mm == pytest.approx(2.7) and (n.dx_mm, n.dy_mm) == (0.0, 0.0)
    # The residual is the noise: within 10 % of its expectation.
    assert fitted.misfit < 1.1 and not fitted.model_mismatch, fitted.misfit
    assert json.loads(json.dumps(fitted.to_dict()))["nuisance"]["fitted"] == ["amplitude", "background_phase"]


@pytest.mark.parametrize(
    "value, match",
    [
        ("bogus", 'fit_nuisance: unknown nuisance parameter "bogus"'),
        (3, "fit_nuisance: must be names"),
        ([1, 2], "fit_nuisance: must be names"),
    ],
)
def test_bad_nuisance_names_are_refused(small: arfi.Simulation, value, match: str) -> None:
    el = small.with_groups(small.n_elements)
    with pytest.raises(ValueError, match=match):
        el.estimate(small.arfi_image(), fit_nuisance=value)


def test_group_estimates_fit_the_amplitude_only(small: arfi.Simulation) -> None:
    image = small.arfi_image(noise_rad=0.02, seed=1)
    with pytest.raises(ValueError, match="fit_nuisance: fitting broadening needs a per-element estimate"):
        small.estimate(image, fit_nuisance=["broadening"])
    assert small.estimate(image, fit_nuisance="amplitude").nuisance is None


def test_cli_fit_nuisance(tmp_path, capsys) -> None:
    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    image = tmp_path / "a.nii.gz"
    assert (
        main(["simulate", "--scenario", str(scenario), "--out", str(image), "--noise-rad", "0.02", "--seed", "2"]) == 0
    )
    out = tmp_path / "e.json"
    assert (
        main(
            [
                "estimate",
                "--scenario",
                str(scenario),
                "--image",
                str(image),
                "--groups",
                "256",
                "--max-evaluations",
                "30",
                "--fit-nuisance",
                "background_phase",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "fitted background_phase" in printed
    # The amplitude was neither asked for nor fitted: no word of a refit with it.
    assert "the amplitude was not asked for" not in printed, printed
    assert json.loads(out.read_text())["nuisance"]["fitted"] == ["background_phase"]
    bad = tmp_path / "bad.json"
    assert (
        main(
            [
                "estimate",
                "--scenario",
                str(scenario),
                "--image",
                str(image),
                "--fit-nuisance",
                "broadening",
                "--json",
                str(bad),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "fit_nuisance: fitting broadening needs a per-element estimate" in err, err
    assert not bad.exists()


def test_cli_diagnose_with_the_aberration_in_the_model(tmp_path, capsys) -> None:
    # With the image's own aberration in the model, the residual is noise: nothing is named;
    # without it, the model is missing the aberration (here taken as an amplitude loss or more).
    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    sim = arfi.Simulation(arfi.Scenario.from_toml(SMALL))
    aberration = tmp_path / "ab.npy"
    np.save(aberration, sim.skull_phases(2))
    image = tmp_path / "s.nii.gz"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                str(scenario),
                "--phases",
                str(aberration),
                "--noise-rad",
                "0.02",
                "--seed",
                "3",
                "--out",
                str(image),
            ]
        )
        == 0
    )
    base = [
        "diagnose",
        "--scenario",
        str(scenario),
        "--image",
        str(image),
        "--effects",
        "amplitude,broadening,background_phase",
    ]
    capsys.readouterr()
    assert main(base + ["--aberration", str(aberration)]) == 0
    assert "no effect missing" in capsys.readouterr().out
    assert main(base) == 0
    assert "no effect missing" not in capsys.readouterr().out
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros(5))
    assert main(base + ["--aberration", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"arfi: error: --aberration: {bad}: has 5 values"), err
