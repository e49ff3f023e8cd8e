"""The paper's loop 2 with a measured safeguard: successive images with the current
correction applied, fitted jointly; a correction is kept only if the scanner shows it better."""

import os

import numpy as np
import pytest

from arfi.analysis.loop import loop2, robust_focal

NOISE = 0.02

# Seeds of the sweeps below: the first by default, 1-5 with ARFI_FULL_SWEEPS=1 (docs/testing.md);
# each seed is a loop of 16-group estimates, two or three of them on several images.
SEEDS = range(1, 6) if os.environ.get("ARFI_FULL_SWEEPS") else range(1, 2)


def run_loop(sim, applied, seed, iterations):
    """Loop 2 on simulated acquisitions of the element phases `applied` with ARFI noise."""
    count = [0]

    def acquire(added):
        count[0] += 1
        return sim.arfi_image(applied + np.asarray(added)[sim.groups], noise_rad=NOISE, seed=100 * seed + count[0])

    first = sim.arfi_image(applied, noise_rad=NOISE, seed=seed)
    return loop2(sim, first, acquire, iterations=iterations, seed=seed)


def test_a_16_group_correction_of_1024_aberrations_never_makes_the_focus_worse(sim, ideal):
    # The loop's acceptance: a correction never makes the focus worse. With the default skull
    # screen the fitted 16-group estimates of these element-level aberrations all leave a weaker
    # focus than no correction (over seeds 1-5 the true focus is 0.13-0.34 of the ideal after
    # correction against 0.25-0.53 aberrated), so the safeguard
    # must see that in the noisy images and keep no correction. The check is on noise-free truth,
    # the same for every seed (no rate): seed 1 by default, 1-5 in the full mode.
    for seed in SEEDS:
        applied = sim.skull_phases(seed)
        r = run_loop(sim, applied, seed, iterations=2)
        aberrated = sim.arfi_image(applied).max()
        corrected = sim.arfi_image(applied - r.correction_rad[sim.groups]).max()
        assert corrected >= aberrated - 1e-12, (
            f"seed {seed}: {corrected / ideal.max():.3f} < {aberrated / ideal.max():.3f}"
        )
        assert len(r.steps) >= 2 and r.steps[0].estimate is None and r.steps[1].estimate is not None


def test_loop2_refocuses_16_group_aberrations_one_image_cannot(sim, ideal):
    # One in-focus image at 0.02 rad recovers about 0.5 of the ideal focus on average (an aberration
    # and its twin phi(u) -> -phi(-u) fit it almost equally well); loop 2 adds the corrected
    # images to the joint fit. With 3 iterations the kept corrections recover about 0.92 of the
    # ideal focus on average over seeds 1-5, every seed at least 0.85 (paper loop 1: 0.83).
    # Required: mean >= 0.85 and never below the aberrated focus. The mean is over the seeds run:
    # in the default run seed 1 alone must reach it (the single-seed form of the claim; seed 1 is
    # among the lowest of the five), over 1-5 in the full mode.
    recovered = []
    for seed in SEEDS:
        applied = sim.condense(sim.skull_phases(seed))[sim.groups]
        r = run_loop(sim, applied, seed, iterations=3)
        corrected = sim.arfi_image(applied - r.correction_rad[sim.groups]).max()
        assert corrected >= sim.arfi_image(applied).max() - 1e-12
        recovered.append(corrected / ideal.max())
    assert np.mean(recovered) >= 0.85, recovered


def test_robust_focal_is_the_mean_around_the_peak():
    image = np.zeros((9, 9))
    image[4, 4] = 9.0
    assert robust_focal(image) == pytest.approx(1.0)
    image[3:6, 3:6] = 2.0
    assert robust_focal(image) == pytest.approx(2.0)
    # Pixels without signal are left out of each mean; a region keeps a brighter place elsewhere out.
    image[4, 4] = np.nan
    assert robust_focal(image) == pytest.approx(2.0)
    image[0, 0] = 50.0
    region = np.zeros((9, 9), dtype=bool)
    region[2:7, 2:7] = True
    assert robust_focal(image, region) == pytest.approx(2.0) and robust_focal(image) > 2.0


def test_loop2_rejects_bad_arguments(sim, ideal):
    with pytest.raises(ValueError, match="iterations"):
        loop2(sim, ideal, lambda a: ideal, iterations=0)
    with pytest.raises(ValueError, match="acquire: must be a callable"):
        loop2(sim, ideal, None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="acquire: returned an image of shape"):
        loop2(sim, sim.arfi_image(np.linspace(-1, 1, 16)), lambda a: np.zeros((3, 3)), iterations=1)
    with pytest.raises(ValueError, match="margin_sigma"):
        loop2(sim, ideal, lambda a: ideal, margin_sigma=float("nan"))


def test_estimate_reports_a_model_it_cannot_fit(sim):
    # A 16-group model fitted to element-level aberrations leaves residuals above the noise
    # (on seed 2 a misfit of about 1.9, against about 0.8 for its 16-group condensation: asserted
    # above 1.5); the flag is a chi-square test at 95 % on the masked pixels.
    elements = sim.skull_phases(2)
    mixed = sim.estimate(sim.arfi_image(elements, noise_rad=NOISE, seed=2), seed=2)
    assert mixed.model_mismatch and mixed.misfit > 1.5
    grouped = sim.estimate(sim.arfi_image(sim.condense(elements), noise_rad=NOISE, seed=2), seed=2)
    assert not grouped.model_mismatch and 0.6 < grouped.misfit < 1.2
