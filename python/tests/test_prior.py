"""Estimation with a predicted aberration as prior (``--prior`` / ``prior=``): the posterior
optimum, reported with ``prior_used``; bad priors refused naming the parameter."""

import json

import numpy as np
import pytest

import arfi
from arfi.cli import main
from arfi.estimation import phase_error


@pytest.fixture(scope="module")
def case(sim):
    """Seed 3's skull-like group aberration, one image at the paper's 0.02 rad noise, and a
    prediction of it with 0.6 rad error per group (seeded)."""
    truth = sim.condense(sim.skull_phases(3))
    image = sim.arfi_image(truth, noise_rad=0.02, seed=3)
    prediction = np.angle(np.exp(1j * (truth + np.random.default_rng(3).normal(0.0, 0.6, truth.size))))
    return truth, image, prediction


def recovered(sim, truth, estimate):
    return sim.arfi_image(truth - estimate).max() / sim.arfi_image().max()


def test_the_prior_makes_one_image_better_than_either_alone(sim, case):
    # The images alone land near the twin here (0.44 of the ideal focus, flagged ambiguous); the
    # prediction alone gives 0.63 (phase error 0.81 rad); the posterior 0.91 (0.37 rad, not
    # ambiguous). Asserted: better than either by at least 0.02.
    truth, image, prediction = case
    alone = sim.estimate(image)
    post = sim.estimate(image, prior=prediction, prior_std_rad=0.6)
    assert post.prior_used and not alone.prior_used and alone.posterior_cost is None
    assert post.posterior_cost is not None and post.posterior_cost > 0
    assert post.cost == pytest.approx(sim.cost_model(image).cost(post.phases_rad), rel=1e-9)
    r_prior, r_alone, r_post = (recovered(sim, truth, p) for p in (prediction, alone.phases_rad, post.phases_rad))
    assert r_post > max(r_prior, r_alone) + 0.02, (r_prior, r_alone, r_post)
    assert phase_error(post.phases_rad, truth) < phase_error(prediction, truth)
    assert post.to_dict()["prior_used"] is True


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (
            {"prior": np.zeros(7), "prior_std_rad": 0.5},
            "prior: has 7 values; expected 1024 (one per element) or 16 (one per group)",
        ),
        ({"prior": np.array([np.nan] * 16), "prior_std_rad": 0.5}, "prior: contains NaN"),
        ({"prior": np.zeros((4, 4)), "prior_std_rad": 0.5}, "prior: must be one-dimensional"),
        ({"prior": np.zeros(16), "prior_std_rad": 0.0}, "prior_std_rad: must be a finite number > 0"),
        ({"prior": np.zeros(16), "prior_std_rad": float("inf")}, "prior_std_rad: must be a finite number"),
        ({"prior": np.zeros(16)}, "prior_std_rad: is required with a prior"),
        ({"prior_std_rad": 0.5}, "prior_std_rad: was given without a prior"),
        ({"prior_conflict_z": 4.0}, "prior_conflict_z: was given without a prior"),
        ({"prior": np.zeros(16), "prior_std_rad": 0.5, "prior_correlation_mm": 0.0}, "prior_correlation_mm: must be"),
        (
            {"prior": np.zeros(16), "prior_std_rad": 0.5, "prior_correlation_mm": float("nan")},
            "prior_correlation_mm: must be",
        ),
        ({"prior_correlation_mm": 15.0}, "prior_correlation_mm: was given without a prior"),
    ],
)
def test_bad_priors_are_refused_naming_the_parameter(sim, ideal, kwargs, match):
    with pytest.raises(ValueError, match=match.replace("(", "\\(").replace(")", "\\)")):
        sim.estimate(ideal, **kwargs)


@pytest.fixture(scope="module")
def files(tmp_path_factory, sim, case):
    d = tmp_path_factory.mktemp("prior")
    truth, image, prediction = case
    arfi.write_arfi_image(d / "m.nii.gz", image, sim.mr_affine_mm, sim.mr_volume_shape)
    np.save(d / "prior.npy", prediction)
    np.save(d / "short.npy", prediction[:5])
    np.savetxt(d / "nan.txt", np.r_[prediction[:-1], np.nan])
    return d


def test_cli_estimate_with_a_prior_writes_prior_used(tmp_path, files, capsys):
    out = tmp_path / "e.json"
    assert (
        main(
            [
                "estimate",
                "--image",
                str(files / "m.nii.gz"),
                "--prior",
                str(files / "prior.npy"),
                "--prior-std-rad",
                "0.6",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    assert "with the prior" in capsys.readouterr().out
    d = json.loads(out.read_text())
    assert d["prior_used"] is True and len(d["phases_rad"]) == 16 and d["posterior_cost"] > 0
    assert d["prior_std_rad"] == 0.6 and d["prior_correlation_mm"] is None


@pytest.mark.parametrize(
    "args, match",
    [
        (["--prior", "{f}/short.npy", "--prior-std-rad", "0.5"], "--prior: {f}/short.npy: has 5 values"),
        (["--prior", "{f}/nan.txt", "--prior-std-rad", "0.5"], "NaN"),
        (["--prior", "{f}/prior.npy", "--prior-std-rad", "-1"], "--prior-std-rad: must be a finite number > 0"),
        (["--prior", "{f}/prior.npy", "--prior-std-rad", "nan"], "--prior-std-rad: must be a finite number"),
        (["--prior", "{f}/prior.npy"], "--prior-std-rad: is required with a prior"),
        (["--prior-std-rad", "0.5"], "--prior-std-rad: was given without a prior"),
        (
            ["--prior", "{f}/prior.npy", "--prior-std-rad", "0.5", "--prior-correlation-mm", "-3"],
            "--prior-correlation-mm: must be",
        ),
        (["--prior", "{f}/missing.npy", "--prior-std-rad", "0.5"], "missing.npy"),
    ],
)
def test_cli_bad_priors_are_one_line_exit_2_and_nothing_written(tmp_path, files, capsys, args, match):
    args = [
        "estimate",
        "--image",
        str(files / "m.nii.gz"),
        *[a.format(f=files) for a in args],
        "--json",
        str(tmp_path / "e.json"),
        "--out-phases",
        str(tmp_path / "p.npy"),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("arfi: error:") and match.format(f=files) in err, err
    assert list(tmp_path.iterdir()) == []


def test_per_element_prior_on_a_small_array_from_elements_or_default_groups():
    # A small array, one phase per element: a prior per element or per default group (16) is
    # spread to the elements as known phases are; another length is refused naming the prior.
    sim = arfi.Simulation(arfi.Scenario.from_toml("[transducer]\nelements_per_side = 8\n"))
    el = sim.with_groups(sim.n_elements)
    truth = sim.skull_phases(2)
    images = [sim.arfi_image(truth, noise_rad=0.02, seed=2)]
    for s, prior in ((0.3, truth), (0.5, sim.condense(truth))):
        e = el.estimate(images, prior=prior, prior_std_rad=s, max_evaluations=50)
        assert e.prior_used and len(e.phases_rad) == sim.n_elements
        # One acquisition cannot check a per-element correction: the prediction is kept as it is,
        # and the estimate is flagged underdetermined.
        assert e.kept_prediction and e.evaluations == 0 and e.underdetermined
        np.testing.assert_allclose(np.exp(1j * e.phases_rad), np.exp(1j * sim.element_phases(prior)), atol=1e-12)
    # A repeat with the same known phases (up to a common phase) is the same acquisition: kept too.
    repeat = sim.arfi_image(sim.element_phases(truth) + 0.7, noise_rad=0.02, seed=3)
    assert el.estimate(
        images + [repeat], [None, np.full(sim.n_elements, 0.7)], prior=truth, prior_std_rad=0.3, max_evaluations=50
    ).kept_prediction
    # Errors as a smooth field (15 mm), with a defocused second image: the estimate corrects the
    # prediction by smooth fields; a prediction that is the truth stays within its stated error
    # (0.3 rad) of it.
    shift = sim.focus_shift_phases((0.0, 0.0, 10.0))
    defocused = sim.arfi_image(sim.element_phases(truth) + shift, noise_rad=0.02, seed=4)
    e = el.estimate(
        images + [defocused],
        [None, shift],
        prior=truth,
        prior_std_rad=0.3,
        prior_correlation_mm=15.0,
        max_evaluations=50,
    )
    assert e.prior_used and len(e.phases_rad) == sim.n_elements and not e.kept_prediction and e.evaluations > 0
    assert phase_error(e.phases_rad, truth) < 0.3
    with pytest.raises(ValueError, match="prior_correlation_mm: 0.010 mm is too short for 256 phases"):
        el.estimate(images, prior=truth, prior_std_rad=0.3, prior_correlation_mm=0.01)
    with pytest.raises(ValueError, match="prior: has 5 values"):
        el.estimate(images, prior=np.zeros(5), prior_std_rad=0.5)
