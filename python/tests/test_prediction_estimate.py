"""arfi.estimate_with_prediction: the library call behind ``arfi estimate --prior ... --prior-transmission``.

The modes' fit on a head is exercised through the command line (test_prior_modes.py,
test_cli.py's bone-speed cases), which calls this function; here: its result against the
simulation it says it used, and its refusals, each before any model is built (no simulation is
made: the build is patched to fail)."""

import numpy as np
import pytest

import arfi
from arfi.analysis.prior_modes import PriorMode


def test_a_transmission_drives_the_model_and_the_result_says_what_it_used(sim, ideal):
    n = sim.n_elements
    rng = np.random.default_rng(7)
    transmission = rng.uniform(0.3, 1.0, n)
    truth = sim.condense(sim.skull_phases(3))
    image = sim.with_element_amplitudes(transmission / transmission.mean()).arfi_image(truth, noise_rad=0.02, seed=4)
    options = arfi.EstimateOptions(method="nelder-mead", seed=2)
    r = arfi.estimate_with_prediction(sim.scenario, image, None, options, transmission=transmission)
    # The same estimate as the simulation it returns, driven at the transmission relative to its mean.
    np.testing.assert_allclose(r.simulation.element_amplitudes, transmission / transmission.mean())
    direct = r.simulation.estimate(image, None, options)
    np.testing.assert_allclose(r.estimate.phases_rad, direct.phases_rad)
    assert r.modes_fit is None and not r.prior_moved
    assert r.to_dict() == r.estimate.to_dict()
    # ... and it is the model that made the image (the same drive, the same plan).
    model = r.simulation.arfi_image(truth)
    np.testing.assert_allclose(model, sim.with_element_amplitudes(transmission / transmission.mean()).arfi_image(truth))
    assert not np.allclose(model, sim.arfi_image(truth), rtol=0.01, atol=0.0)
    # A prediction's JSON gives the same drive, checked at its target.
    same = arfi.estimate_with_prediction(
        sim.scenario,
        image,
        None,
        options,
        prediction={"transmission": transmission.tolist(), "target_mm": list(sim.focus_mm)},
    )
    np.testing.assert_allclose(same.estimate.phases_rad, r.estimate.phases_rad)


def test_bad_requests_name_the_parameter_as_the_caller_knows_it(sim, ideal, monkeypatch):
    n = sim.n_elements

    def no_build(*args, **kwargs):
        raise AssertionError("a model was built before the request was checked")

    monkeypatch.setattr(arfi._core, "CoreSimulation", no_build)
    scenario = sim.scenario
    prior = arfi.EstimateOptions(prior=np.zeros(n), prior_std_rad=0.3)
    ones = np.ones(n)
    mode = PriorMode("thickness", "scale", np.zeros(n), 1.0)
    cases = [
        (dict(transmission=ones[:-1]), "transmission"),
        (dict(transmission=-ones), "transmission: transmissions must be non-negative"),
        (dict(transmission=ones, prediction={"transmission": ones.tolist()}), "transmission: give the prediction"),
        (dict(prediction={"target_mm": [0, 0, 85]}), "prediction: holds no 'transmission'"),
        (
            dict(prediction={"transmission": ones.tolist(), "target_mm": [0.0, 0.0, 80.0]}),
            r"prediction: predicted for the target \(0.0, 0.0, 80.0\) mm",
        ),
        (dict(prediction=[1.0, 2.0]), "prediction: must be an arfi.Prediction or its JSON"),
        (dict(pose_std_mm=1.5), "pose_std_mm: needs options.prior"),
        (dict(options=prior, groups=16, bone_speed_std_percent=20.0), "bone_speed_std_percent: fitted for per-element"),
        (dict(options=prior, groups=n, pose_std_deg=-1.0), "pose_std_deg: must be a finite number >= 0"),
        (dict(options=prior, groups=n, bone_speed_std_percent=20.0), "bone_speed_std_percent: needs prediction"),
        (dict(options=prior, groups=n, modes=[mode]), r"modes: needs a \[ct\] scenario"),
        (dict(options=prior, groups=n, modes=["x"]), "modes: must be arfi.analysis.prior_modes.PriorMode"),
        (dict(options={"method": "lbfgs"}), "options: must be an arfi.EstimateOptions"),
        (dict(calibration={"broadening_width_mm": 2.7}), "calibration: must be an arfi.Calibration"),
        (dict(calibration=arfi.Calibration(2.7, 1e-6, scenario="other")), 'calibration: made for scenario "other"'),
        (dict(groups=0), "groups: must be an integer between 1 and"),
        (dict(images=np.zeros((10, 10))), r"images\[0\]"),
        (dict(known=np.zeros(5)), r"known\[0\]"),
        (dict(options=arfi.EstimateOptions(prior=np.zeros(7), prior_std_rad=0.3)), "options.prior: has 7 values"),
        (
            dict(options=prior, groups=16, prediction={"transmission": None}),
            "prediction: holds no 'transmission'",
        ),
    ]
    for kwargs, match in cases:
        options = kwargs.pop("options", None)
        images = kwargs.pop("images", ideal)
        known = kwargs.pop("known", None)
        with pytest.raises(ValueError, match=match):
            arfi.estimate_with_prediction(scenario, images, known, options, **kwargs)  # type: ignore[arg-type]
    # Renamed for a caller that knows the parameters by other names (arfi estimate's options).
    with pytest.raises(ValueError, match="--prior-pose-std-mm: needs --prior "):
        arfi.estimate_with_prediction(
            scenario, ideal, pose_std_mm=1.5, names={"pose_std_mm": "--prior-pose-std-mm", "prior": "--prior"}
        )
    # A mode left to its default is skipped quietly where it cannot apply (group estimate).
    monkeypatch.undo()
    r = arfi.estimate_with_prediction(
        scenario,
        ideal,
        None,
        arfi.EstimateOptions(method="nelder-mead", max_evaluations=50, prior=np.zeros(16), prior_std_rad=0.3),
        prediction={"transmission": ones.tolist(), "bone_speed_sensitivity_rad_per_percent": ones.tolist()},
    )
    assert r.modes_fit is None
