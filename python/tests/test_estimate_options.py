"""EstimateOptions: the estimate's options as one typed value, checked once by the core's rules."""

import numpy as np
import pytest

import arfi
from arfi import EstimateOptions


def test_options_read_back_in_the_units_of_their_names():
    modes = np.arange(6.0).reshape(2, 3)
    o = EstimateOptions(
        method="nelder-mead",
        max_evaluations=np.int64(50),
        seed=7,
        noise_rad=0.02,
        prior=[0.1, 0.2, 0.3],
        prior_std_rad=0.3,
        prior_correlation_mm=20,
        prior_modes=modes,
        fit_nuisance="amplitude, background_phase",
    )
    assert (o.method, o.max_evaluations, o.seed, o.noise_rad) == ("nelder-mead", 50, 7, 0.02)
    np.testing.assert_array_equal(o.prior, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(o.prior_modes, modes)
    assert o.prior_correlation_mm == pytest.approx(20.0)  # held in metres by the core
    assert o.fit_nuisance == ["amplitude", "background_phase"]
    # Defaults: the core's.
    d = EstimateOptions()
    assert (d.method, d.seed, d.threshold, d.prior, d.fit_nuisance, d.suggest) == ("lbfgs", 0, 0.9, None, [], False)


def test_numpy_values_are_taken_and_unknown_attributes_are_attribute_errors():
    o = EstimateOptions(fit_amplitude=np.True_, suggest=np.bool_(False), seed=np.uint8(3), threshold=np.float32(0.5))
    assert (o.fit_amplitude, o.suggest, o.seed, o.threshold) == (True, False, 3, 0.5)
    with pytest.raises(AttributeError, match="nope"):
        o.nope  # noqa: B018
    assert not hasattr(o, "nope") and "prior_conflict_z" in dir(o)
    assert "prior_conflict_z (number):" in EstimateOptions.describe()


def test_to_dict_and_replace_make_the_same_options_again():
    # Without a prior: the prior-only options come back unset (they would be refused without one).
    plain = EstimateOptions(seed=3)
    assert EstimateOptions(**plain.to_dict()).to_dict() == plain.to_dict()
    assert plain.replace(seed=1).seed == 1 and plain.to_dict()["prior_conflict_z"] is None
    o = EstimateOptions(prior=[0.5, -0.5], prior_std_rad=0.4, starts=3, fit_amplitude=True)
    again = EstimateOptions(**o.to_dict())
    assert again.to_dict() == o.to_dict()
    r = o.replace(seed=5, prior=[0.0, 1.0])
    assert r.seed == 5 and list(r.prior) == [0.0, 1.0] and r.prior_std_rad == 0.4 and r.starts == 3
    assert o.seed == 0  # the original is unchanged (frozen)
    with pytest.raises(ValueError, match="bogus: is not an estimate option"):
        o.replace(bogus=1)
    with pytest.raises(ValueError, match="prior_std_rad: was given without a prior"):
        o.replace(prior=None)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"method": "simplex"}, "method"),
        ({"max_evaluations": 0}, "max_evaluations: must be > 0"),
        ({"max_evaluations": True}, "max_evaluations: must be an integer"),
        ({"max_evaluations": 2.5}, "max_evaluations: must be an integer"),
        ({"seed": -1}, "seed: must be an integer"),
        ({"starts": 0}, "starts: must be >= 1"),
        ({"starts": 3, "method": "pso"}, "starts: applies to L-BFGS only"),
        ({"time_limit_s": 0}, "time_limit_s: must be a finite number > 0"),
        ({"time_limit_s": "5"}, "time_limit_s: must be a finite number"),
        ({"noise_rad": float("nan")}, "noise_rad: must be a finite number"),
        ({"noise_rad": -0.1}, "noise_rad: must be a finite number > 0"),
        ({"threshold": 1.5}, "threshold: must be a fraction"),
        ({"prior": [0.0, 1.0]}, "prior_std_rad: is required with a prior"),
        ({"prior_std_rad": 0.3}, "prior_std_rad: was given without a prior"),
        ({"prior_modes": [[0.0]]}, "prior_modes: was given without a prior"),
        ({"prior": [1j], "prior_std_rad": 0.3}, "prior: must be real, got complex values"),
        ({"prior": [[0.0, 1.0]], "prior_std_rad": 0.3}, "prior: must be one-dimensional, got shape \\(1, 2\\)"),
        ({"prior": [0.0, np.nan], "prior_std_rad": 0.3}, "prior: contains NaN or infinite values"),
        ({"prior_modes": [[[0.0]]], "prior": [0.0], "prior_std_rad": 0.3}, "prior_modes: must have shape"),
        ({"prior": "abc", "prior_std_rad": 0.3}, "prior: not numeric"),
        ({"prior": [0.0], "prior_std_rad": 0.0}, "prior_std_rad"),
        ({"prior": [0.0], "prior_std_rad": 0.3, "prior_correlation_mm": -1}, "prior_correlation_mm"),
        ({"prior": [0.0], "prior_std_rad": 0.3, "prior_modes": [[0.0], [np.inf]]}, "prior_modes"),
        ({"fit_nuisance": "bogus"}, 'fit_nuisance: unknown nuisance parameter "bogus"'),
        (
            {"prior_conflict_z": 0.0, "prior": [0.0], "prior_std_rad": 0.3},
            "prior_conflict_z: must be a finite number > 0",
        ),
        ({"prior_conflict_z": 4.0}, "prior_conflict_z: was given without a prior"),
        ({"fit_amplitude": 1}, "fit_amplitude: must be True or False, got 1"),
        ({"suggest": "yes"}, "suggest: must be True or False"),
        ({"method": 1}, "method: must be a string, got 1"),
    ],
)
def test_bad_options_are_refused_naming_the_option(options, message):
    with pytest.raises(ValueError, match=message):
        EstimateOptions(**options)


def test_an_estimate_takes_the_options_or_the_same_as_keywords(sim, ideal):
    truth = sim.condense(sim.skull_phases(4))
    image = sim.arfi_image(truth, noise_rad=0.02, seed=2)
    options = EstimateOptions(method="nelder-mead", max_evaluations=300, seed=1)
    a = sim.estimate(image, None, options)
    b = sim.estimate(image, method="nelder-mead", max_evaluations=300, seed=1)
    np.testing.assert_array_equal(a.phases_rad, b.phases_rad)
    assert a.method == "nelder-mead" and a.evaluations <= 300
    with pytest.raises(ValueError, match="options: give EstimateOptions or keyword options"):
        sim.estimate(image, None, options, seed=2)
    with pytest.raises(ValueError, match="options: must be an EstimateOptions"):
        sim.estimate(image, None, {"method": "lbfgs"})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^bogus: is not an estimate option"):
        sim.estimate(image, bogus=1)


def test_the_package_exports_the_options():
    assert arfi.EstimateOptions is EstimateOptions and "EstimateOptions" in arfi.__all__


def test_progress_is_a_callable_or_a_bar_and_a_raising_callable_stops_the_estimate():
    # 64 elements: the element basis is marched in batches, each reported as (done, total).
    small = arfi.Simulation(arfi.Scenario.from_toml("[transducer]\nelements_per_side = 8\n"))
    el = small.with_groups(small.n_elements)
    image = small.arfi_image(noise_rad=0.02, seed=1)
    seen: list[tuple[int, int]] = []
    el.estimate(image, progress=lambda done, total: seen.append((done, total)), max_evaluations=5)
    assert seen and seen[-1] == (el.n_elements, el.n_elements) and [d for d, _ in seen] == sorted(d for d, _ in seen)

    class Stop(Exception):
        pass

    def stop(done: int, total: int) -> None:
        raise Stop(f"{done}/{total}")

    # A fresh simulation (the first kept its basis, which would skip the marching).
    fresh = arfi.Simulation(arfi.Scenario.from_toml("[transducer]\nelements_per_side = 8\n"))
    with pytest.raises(Stop):
        fresh.with_groups(fresh.n_elements).estimate(image, progress=stop, max_evaluations=5)
    # True draws a bar only on a terminal: under pytest (no terminal) nothing, and the estimate runs.
    assert el.estimate(image, progress=True, max_evaluations=5).phases_rad.shape == (el.n_elements,)
