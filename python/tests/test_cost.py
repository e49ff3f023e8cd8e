"""The cost model exposed to Python, checked against a NumPy evaluation of its own kernels and
against finite differences: references that are not the Rust arithmetic being tested."""

import sys
from pathlib import Path

import numpy as np
import pytest

import arfi

# The NumPy cost of the benchmark (benches/numpy_cost.py) is the reference here.
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benches"))
import numpy_cost  # noqa: E402


@pytest.fixture(scope="module")
def aberrated(sim):
    truth = np.random.default_rng(3).uniform(-np.pi, np.pi, sim.n_groups)
    diversity = np.zeros(sim.n_groups)
    diversity[:4] = np.pi / 2
    images = [
        sim.arfi_image(truth, noise_rad=0.002, seed=1),
        sim.arfi_image(truth + diversity, noise_rad=0.002, seed=2),
    ]
    return truth, images, [None, diversity]


@pytest.mark.parametrize("fit_amplitude", [False, True])
def test_cost_matches_numpy_from_the_exposed_kernels(sim, aberrated, fit_amplitude):
    truth, images, known = aberrated
    model = sim.cost_model(images, known, fit_amplitude=fit_amplitude)
    terms = model.terms()
    assert model.n_groups == sim.n_groups == 16
    assert [t.diagonal.shape[1] for t in terms] == [16, 16] and terms[0].upper.shape[1] == 16 * 15 // 2
    assert sum(len(t.measured_rad) for t in terms) == model.n_pixels
    np.testing.assert_array_equal(terms[1].offset_rad, known[1])
    rng = np.random.default_rng(0)
    for phases in [np.zeros(16), truth, rng.uniform(-np.pi, np.pi, 16)]:
        # Same sums in another order: agreement to ~1e-12 of the cost's size.
        j = model.cost(phases)
        assert j == pytest.approx(numpy_cost.cost(terms, phases, fit_amplitude), rel=1e-10, abs=1e-14)
        j2, grad = model.cost_and_gradient(phases)
        assert j2 == pytest.approx(j, rel=1e-12, abs=1e-15)
        ref_j, ref_grad = numpy_cost.cost_and_gradient(terms, phases, fit_amplitude)
        assert ref_j == pytest.approx(j, rel=1e-10, abs=1e-14)
        np.testing.assert_allclose(grad, ref_grad, rtol=0, atol=1e-10 * np.linalg.norm(ref_grad) + 1e-15)


def test_gradient_matches_central_differences(sim, aberrated):
    _, images, known = aberrated
    model = sim.cost_model(images, known, fit_amplitude=True)
    phases = np.random.default_rng(5).uniform(-np.pi, np.pi, 16)
    _, grad = model.cost_and_gradient(phases)
    h = 1e-5
    fd = np.array([(model.cost(phases + h * e) - model.cost(phases - h * e)) / (2 * h) for e in np.eye(16)])
    # Central differences err by O(h²·J''') ~ 1e-10 relative here; 1e-6 of the gradient's norm
    # leaves room for rounding in J (1e-16·J/h).
    assert np.max(np.abs(grad - fd)) < 1e-6 * np.linalg.norm(grad)


def test_cost_is_what_estimate_minimises(sim, aberrated):
    truth, images, known = aberrated
    est = sim.estimate(images, known, seed=0)
    model = sim.cost_model(images, known)
    assert model.cost(est.phases_rad) == pytest.approx(est.cost, rel=1e-9)
    # Near the truth the cost is at the noise floor: n_pixels·σ² within a factor of 3.
    assert model.cost(truth) < 3 * model.n_pixels * 0.002**2
    assert model.cost(np.zeros(16)) > 100 * model.cost(truth)


def test_cost_model_refuses_bad_phases(sim, aberrated):
    _, images, known = aberrated
    model = sim.cost_model(images, known)
    with pytest.raises(ValueError, match="phases: has 3 values for 16 groups"):
        model.cost(np.zeros(3))
    with pytest.raises(ValueError, match="phases"):
        model.cost_and_gradient([0.0] * 15 + [np.nan])
    with pytest.raises(ValueError, match="images"):
        sim.cost_model([])
    with pytest.raises(ValueError, match="groups"):
        sim.with_groups(sim.n_elements).cost_model(images[0])
    assert "n_groups=16" in repr(model) and isinstance(model, arfi.CostModel)
