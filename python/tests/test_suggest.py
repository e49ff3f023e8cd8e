"""The next acquisition of a per-element estimate (``suggest=True`` / ``arfi estimate --suggest``),
on a small array (256 elements) so that each estimate takes seconds. The information
arithmetic itself (Jacobian, expected focus) is checked against finite differences, a closed form
and Monte Carlo in crates/has-core/tests/suite/information.rs."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import arfi
from arfi.cli import main

SMALL = "[transducer]\nelements_per_side = 8\n"


@pytest.fixture(scope="module")
def small() -> arfi.Simulation:
    return arfi.Simulation(arfi.Scenario.from_toml(SMALL))


def test_per_element_estimate_suggests_a_focus_shift(small: arfi.Simulation) -> None:
    el = small.with_groups(small.n_elements)
    truth = small.skull_phases(2)
    prediction = truth + small.skull_phases(1002, correlation_length_mm=15.0, peak_to_peak_rad=3.0, jitter_rad=0.0)
    image = small.arfi_image(truth, noise_rad=0.02, seed=2)
    e = el.estimate(
        [image],
        [None],
        prior=prediction,
        prior_std_rad=0.8,
        prior_correlation_mm=15.0,
        max_evaluations=60,
        suggest=True,
    )
    n = e.next_acquisition
    assert n is not None
    shifts = [c.focus_shift_mm for c in n.candidates]
    values = [c.expected_focus for c in n.candidates]
    # One image: the prediction is kept, so the in-focus image again (a repeat, which would be kept
    # again) is not offered, and the expected focus now is the prior's alone.
    assert e.kept_prediction and len(shifts) == 14 and [0.0, 0.0, 0.0] not in shifts
    assert values == sorted(values, reverse=True) and n.focus_shift_mm == shifts[0]
    # More data never lowers the expected focus; the suggested image's known phases move the focus.
    assert 0.0 < n.expected_focus_now <= n.expected_focus <= 1.0, n
    np.testing.assert_allclose(e.suggested_phases_rad, small.focus_shift_phases(n.focus_shift_mm), atol=1e-12)
    assert json.loads(json.dumps(e.to_dict()))["next_acquisition"]["focus_shift_mm"] == n.focus_shift_mm
    # Not asked: an ambiguous posterior (one image, a loose prior) still comes with the acquisition
    # that would settle it; an unambiguous one (a tight prior) and a group estimate come without.
    loose = el.estimate([image], [None], prior=prediction, prior_std_rad=0.8, max_evaluations=20)
    assert loose.ambiguous and loose.next_acquisition is not None
    np.testing.assert_allclose(
        loose.suggested_phases_rad, small.focus_shift_phases(loose.next_acquisition.focus_shift_mm), atol=1e-12
    )
    tight = el.estimate([image], [None], prior=prediction, prior_std_rad=0.05, max_evaluations=20)
    assert not tight.ambiguous and tight.next_acquisition is None, tight.worst_recovery
    assert small.estimate(image, suggest=True).next_acquisition is None


def test_cli_one_acquisition_keeps_the_prediction_until_a_second(tmp_path, capsys) -> None:
    # Per element with a prior, one image cannot check a correction of the prediction: the CLI keeps
    # it, says so and suggests a second acquisition; with that image added it searches.
    scenario, first, second = tmp_path / "small.toml", tmp_path / "a.nii.gz", tmp_path / "b.nii.gz"
    scenario.write_text(SMALL)
    sim = arfi.Simulation(arfi.Scenario.from_toml(SMALL))
    truth = sim.skull_phases(3)
    np.save(tmp_path / "ab.npy", truth)
    np.save(
        tmp_path / "prior.npy",
        truth + sim.skull_phases(1003, correlation_length_mm=15.0, peak_to_peak_rad=3.0, jitter_rad=0.0),
    )
    common = [
        "--scenario",
        str(scenario),
        "--groups",
        "256",
        "--max-evaluations",
        "30",
        "--prior",
        str(tmp_path / "prior.npy"),
        "--prior-std-rad",
        "0.8",
        "--prior-correlation-mm",
        "15",
    ]
    assert (
        main(
            [
                "simulate",
                "--scenario",
                str(scenario),
                "--phases",
                str(tmp_path / "ab.npy"),
                "--out",
                str(first),
                "--noise-rad",
                "0.02",
                "--seed",
                "3",
            ]
        )
        == 0
    )
    out, nxt = tmp_path / "e.json", tmp_path / "next.npy"
    assert main(["estimate", "--image", str(first), *common, "--suggest", str(nxt), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "KEPT THE PREDICTION" in printed and "next acquisition" in printed, printed
    d = json.loads(out.read_text())
    assert d["kept_prediction"] is True and d["evaluations"] == 0 and d["stop"] == "prediction kept"
    # Not fitted, so no model mismatch is judged; the line gives the misfit the prediction leaves
    # (here a prediction 3 rad off over 15 mm: well above 1), and one image is underdetermined.
    assert d["model_mismatch"] is False and d["underdetermined"] is True and d["misfit"] > 1.2
    assert f"misfit of {d['misfit']:.2f} x the noise expectation on this image (well above 1" in printed, printed
    assert "AMBIGUOUS" not in printed
    np.testing.assert_allclose(
        np.exp(1j * np.array(d["phases_rad"])), np.exp(1j * np.load(tmp_path / "prior.npy")), atol=1e-12
    )
    shift = d["next_acquisition"]["focus_shift_mm"]
    assert (
        main(
            [
                "simulate",
                "--scenario",
                str(scenario),
                "--phases",
                str(tmp_path / "ab.npy"),
                "--focus-shift-mm",
                *map(str, shift),
                "--out",
                str(second),
                "--noise-rad",
                "0.02",
                "--seed",
                "4",
            ]
        )
        == 0
    )
    assert main(["estimate", "--image", str(first), "--image", str(second), *common, "--json", str(out)]) == 0
    assert "KEPT" not in capsys.readouterr().out
    d = json.loads(out.read_text())
    assert d["kept_prediction"] is False and d["evaluations"] > 0


def test_cli_suggest_per_element(tmp_path, capsys) -> None:
    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    image = tmp_path / "a.nii.gz"
    aberration = tmp_path / "ab.npy"
    sim = arfi.Simulation(arfi.Scenario.from_toml(SMALL))
    np.save(aberration, sim.skull_phases(4))
    assert (
        main(
            [
                "simulate",
                "--scenario",
                str(scenario),
                "--phases",
                str(aberration),
                "--out",
                str(image),
                "--noise-rad",
                "0.02",
                "--seed",
                "4",
            ]
        )
        == 0
    )
    out, nxt = tmp_path / "e.json", tmp_path / "next.npy"
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
                "--suggest",
                str(nxt),
                "--json",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "next acquisition: the focus shifted by" in printed, printed
    shift = json.loads(out.read_text())["next_acquisition"]["focus_shift_mm"]
    np.testing.assert_allclose(np.load(nxt), sim.focus_shift_phases(shift), atol=1e-12)
    # The suggested image can be taken with simulate --focus-shift-mm and estimated with the first.
    second = tmp_path / "b.nii.gz"
    assert (
        main(
            [
                "simulate",
                "--scenario",
                str(scenario),
                "--phases",
                str(aberration),
                "--focus-shift-mm",
                *map(str, shift),
                "--out",
                str(second),
                "--noise-rad",
                "0.02",
                "--seed",
                "5",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "estimate",
                "--scenario",
                str(scenario),
                "--image",
                str(image),
                "--image",
                str(second),
                "--groups",
                "256",
                "--max-evaluations",
                "30",
                "--json",
                str(tmp_path / "e2.json"),
            ]
        )
        == 0
    )


def poor_prediction(sim: arfi.Simulation, seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The skull-like truth of ``seed``, a poor prediction of it (a 20 mm screen of 3 rad peak to
    peak plus 0.5 rad independent per element, 0.9 rad RMS in all) and the focal pressure that
    prediction leaves as a fraction of the ideal (``Simulation.element_responses``)."""
    truth = sim.skull_phases(seed)
    prior = truth + sim.skull_phases(1000 + seed, correlation_length_mm=20.0, peak_to_peak_rad=3.0, jitter_rad=0.5)
    return truth, prior, focal_pressure(sim, truth, prior)


def focal_pressure(sim: arfi.Simulation, truth: np.ndarray, applied: np.ndarray) -> float:
    """``|Σ c·exp(i·(truth − applied))| / |Σ c|``, ``c`` each element's steered response at the focus."""
    c = sim.element_responses() * np.exp(1j * sim.steering_phases_rad)
    return float(abs(np.sum(c * np.exp(1j * (truth - applied)))) / abs(np.sum(c)))


def test_a_poor_prediction_is_raised_by_a_defocused_image_with_the_amplitude_fitted(small: arfi.Simulation) -> None:
    # A smooth prior leaves the prediction's element-level error (0.5 rad) in the model, which
    # lowers the modelled images by about exp(-0.5²) = 0.78. With the scale held at 1 the model
    # cannot explain the images (misfit 2.1-6.1 on seeds 21-24 of this array) and the prediction
    # was recommended (0.63-0.70 of the ideal focal pressure); the estimate is searched again with
    # the scale fitted, which explains them (misfit 0.93-1.05, scale 1.23-1.27) and leaves
    # 0.87-0.89 with the in-focus and one 20 mm defocused image (the ceiling of the 0.5 rad
    # element-level error, exp(-0.5²/2) = 0.88, give or take what the prediction's screen has of it).
    # Tolerances: 0.85 is 0.02-0.04 under those; the scale within 10 % of exp(0.5²) = 1.28.
    el = small.with_groups(small.n_elements)
    truth, prior, alone = poor_prediction(small, 22)
    shift = small.focus_shift_phases((0.0, 0.0, -20.0))
    images = [
        small.arfi_image(truth, noise_rad=0.02, seed=22),
        small.arfi_image(truth + shift, noise_rad=0.02, seed=2200),
    ]
    e = el.estimate(images, [None, shift], prior=prior, prior_std_rad=0.9, prior_correlation_mm=20.0, seed=22)
    assert e.recommended == "estimate" and not e.model_mismatch and e.misfit < 1.2, e.misfit
    assert e.nuisance is not None and e.nuisance.fitted == ["amplitude"], e.nuisance
    assert abs(e.nuisance.scale / np.exp(0.25) - 1.0) < 0.1, e.nuisance.scale
    focus = focal_pressure(small, truth, e.recommended_phases_rad)
    assert focus >= 0.85 and focus > alone + 0.1, (focus, alone)


@pytest.mark.skipif(
    not os.environ.get("ARFI_FULL_SWEEPS"), reason="full mode (ARFI_FULL_SWEEPS=1): 1024 elements, four seeds"
)
def test_a_poor_prediction_keeps_rising_along_the_suggested_acquisitions_on_1024_elements() -> None:
    # The whole path of benches/bench_poor_prediction.py: 1024 elements, the poor prediction
    # above, the in-focus image and then each acquisition the estimate suggests, four in all.
    # Measured (BENCHMARKS.md, "A poor prediction and the suggested acquisitions"): seeds 11-14 end
    # at 0.86-0.88 of the ideal focal pressure (mean 0.87; before the amplitude refit the
    # prediction, 0.62-0.73, was recommended at every step, and the estimates themselves stalled
    # at 0.79-0.85). Tolerances: the mean >= 0.85 (0.02 under the measured, a ceiling of 0.88 leaves
    # no more room); no step below the prediction alone - 0.02 (a kept or recommended prediction
    # is the prediction itself; 0.02 is what the issue allows for noise).
    sim = arfi.Simulation()
    el = sim.with_groups(sim.n_elements)
    last = []
    for seed in (11, 12, 13, 14):
        truth, prior, alone = poor_prediction(sim, seed)
        images, known = [sim.arfi_image(truth, noise_rad=0.02, seed=seed)], [None]
        while True:
            e = el.estimate(
                images, known, prior=prior, prior_std_rad=0.9, prior_correlation_mm=20.0, seed=seed, suggest=True
            )
            focus = focal_pressure(sim, truth, e.recommended_phases_rad)
            assert focus >= alone - 0.02, (seed, len(images), focus, alone)
            if len(images) == 4:
                break
            images.append(
                sim.arfi_image(truth + e.suggested_phases_rad, noise_rad=0.02, seed=100 * seed + len(images) - 1)
            )
            known.append(np.asarray(e.suggested_phases_rad))
        last.append(focus)
    assert np.mean(last) >= 0.85, last


def test_cli_images_the_model_cannot_form_about_the_prediction_recommend_it(tmp_path, capsys) -> None:
    # Per element with a prior: the images in focus and defocused +-5 mm, moved by one MR pixel
    # (a focal spot the model cannot form). The search fits them to a misfit near 1 (no MODEL
    # MISMATCH) by moving its phases; the images' chi-squared at the prediction lies far above
    # what truths within the prior's +-0.3 rad give (z 46.9 with seed 1 of this array, 34.2 with
    # seed 3; -1.4 and -1.6 unmoved), so the prediction is recommended: the line says PRIOR
    # CONFLICT, --out-phases holds the prediction and the JSON gives the check. Unmoved, the
    # estimate is what it recommends.
    sim = arfi.Simulation(arfi.Scenario.from_toml(SMALL))
    scenario = tmp_path / "small.toml"
    scenario.write_text(SMALL)
    truth = sim.skull_phases(1)
    prediction = truth + np.random.default_rng(1).normal(0.0, 0.3, sim.n_elements)
    np.save(tmp_path / "prior.npy", prediction)
    known = [None] + [sim.focus_shift_phases((0.0, 0.0, dz)) for dz in (5.0, -5.0)]

    def estimate(moved: bool, *options: str) -> tuple[dict, str]:
        paths = []
        for i, k in enumerate(known):
            image = sim.arfi_image(truth + (0.0 if k is None else k), noise_rad=0.02, seed=10 + i)
            path = tmp_path / f"{'moved' if moved else 'plain'}{i}.nii.gz"
            arfi.write_arfi_image(
                path,
                np.roll(image, 1, axis=0) if moved else image,
                sim.mr_affine_mm,
                sim.mr_volume_shape,
                None if k is None else {"applied_phases_rad": list(k)},
            )
            paths += ["--image", str(path)]
        assert (
            main(
                [
                    "estimate",
                    "--scenario",
                    str(scenario),
                    *paths,
                    "--groups",
                    str(sim.n_elements),
                    "--prior",
                    str(tmp_path / "prior.npy"),
                    "--prior-std-rad",
                    "0.3",
                    "--seed",
                    "1",
                    "--out-phases",
                    str(tmp_path / "out.npy"),
                    "--json",
                    str(tmp_path / "e.json"),
                    *options,
                ]
            )
            == 0
        )
        return json.loads((tmp_path / "e.json").read_text()), capsys.readouterr().out

    result, out = estimate(moved=True)
    check = result["prior_check"]
    assert check["conflict"] and check["z"] > 3.0 and check["draws"] == 40 and check["conflict_z"] == 3.0, check
    assert not result["model_mismatch"] and result["recommended"] == "prediction", result["misfit"]
    assert "PRIOR CONFLICT" in out and "NOT to be applied" in out and "out.npy" in out, out
    assert np.allclose(np.load(tmp_path / "out.npy"), prediction)
    # A user who trusts the images further sets the threshold above the check's z: the same
    # images are then no conflict, and the estimate is what is recommended.
    trusting, out = estimate(True, "--prior-conflict-z", f"{check['z'] + 1.0:.1f}")
    assert trusting["prior_check"]["z"] == check["z"] and not trusting["prior_check"]["conflict"]
    assert trusting["prior_check"]["conflict_z"] == float(f"{check['z'] + 1.0:.1f}")
    assert trusting["recommended"] == "estimate" and "PRIOR CONFLICT" not in out, trusting["recommended"]
    result, out = estimate(moved=False)
    assert not result["prior_check"]["conflict"] and result["recommended"] == "estimate", result["prior_check"]
    assert "PRIOR CONFLICT" not in out
    assert np.allclose(np.load(tmp_path / "out.npy"), result["phases_rad"])
