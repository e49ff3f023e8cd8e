//! Whether the images agree with the prediction as the prior states it: a prior-predictive
//! check (Box 1980; Evans & Moshonov 2006) of the images' cost at the prediction.
//!
//! With a prior, a per-element search can move far from the prediction for the wrong reason:
//! where the model cannot form the measured images (a shifted or wider focal spot, a missed
//! effect), hundreds of phases absorb the difference and the fit looks good (misfit near 1)
//! while the focus they leave falls below the prediction's. A likelihood-ratio test of the move
//! cannot see this: the images' cost falls by hundreds either way. What does differ is the cost at
//! the prediction itself, against what the images of truths the prior allows would give there:
//! beyond that, either the model cannot form the images or the prediction errs by more than its
//! stated spread, and in both cases the move the images ask for cannot be trusted.

use crate::error::{HasError, Result};
use crate::inverse::element::ElementCost;
use crate::inverse::estimate::MATERIAL_MISFIT;
use crate::inverse::prior::smooth::error_modes;
use crate::inverse::prior::{Prior, MIN_NOISE_RAD};
use crate::phase::wrap;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Draws of the prior in the Monte Carlo null. The null's spread is estimated to about 11 %
/// (`1/sqrt(2·40)`), enough for a threshold of [`CONFLICT_Z`] standard deviations: images of a
/// model that forms them sat within 1.1 of the null's mean on six seeds, images one MR pixel off
/// or 1.5 times as wide at 7.8 or more.
pub const PRIOR_CHECK_DRAWS: usize = 40;

/// Standard deviations of the null above its mean at which the prediction's cost conflicts, by
/// default (`EstimateRequest::prior_conflict_z`).
pub const CONFLICT_Z: f64 = 3.0;

/// The prior-predictive check of a per-element estimate with a prior.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorCheck {
    /// `chi²` of the images at the prediction (the images' cost over `sigma²`, the linear
    /// nuisance refitted there, the amplitude scale always).
    pub chi2_prediction: f64,
    /// Mean and standard deviation of the same `chi²` over images of truths drawn from the
    /// prior (the model's images of `prediction + error`, errors of the prior's std per element,
    /// plus noise `sigma`).
    pub null_mean: f64,
    /// See `null_mean`.
    pub null_std: f64,
    /// `(chi2_prediction - null_mean) / null_std`.
    pub z: f64,
    /// `(chi2_prediction - null_mean) / n_pixels`: how much more than the noise per pixel the
    /// images leave unexplained at the prediction.
    pub excess_per_pixel: f64,
    /// The images conflict with the prediction as the prior states it: `z` above `conflict_z`
    /// and the excess material (above `MATERIAL_MISFIT - 1`, the misfit rule's: smaller
    /// residuals act as a little more noise).
    pub conflict: bool,
    /// The threshold on `z` the conflict was judged by.
    pub conflict_z: f64,
    /// Draws made.
    pub draws: usize,
}

/// The check of the images in `cost` (its view and linear nuisance as fitted) against `prior`
/// with noise `noise` (rad), a conflict beyond `conflict_z` standard deviations of the null
/// ([`CONFLICT_Z`] by default), [`PRIOR_CHECK_DRAWS`] seeded draws of the prior's own errors:
/// independent per element with its std, or for a smooth prior its field over the elements'
/// `positions` (m; `W·a`, `a ~ N(0, 1)`, [`error_modes`]), plus its modes of known shape
/// (`a·g`). Drawn otherwise the null would be wrong, not wider: independent errors weaken the
/// focus, which a fitted scale absorbs, where smooth ones move and reshape it.
pub fn prior_check(
    cost: &ElementCost,
    noise: f64,
    prior: &Prior,
    positions: &[[f64; 3]],
    seed: u64,
    conflict_z: f64,
) -> Result<PriorCheck> {
    let sigma = noise.max(MIN_NOISE_RAD);
    let mean = prior.mean();
    let n = cost.n_pixels();
    if n == 0 {
        return Err(HasError::invalid("images", "no masked pixel to check the prediction on"));
    }
    // The scale refitted on both sides: a prediction that errs by more than its std (or images
    // weaker than the model's) loses focal amplitude, which the search's move rightly restores;
    // what no scale explains is a focal spot of another shape or place.
    let mut checked = cost.clone();
    checked.fit_amplitude = true;
    let cost = &checked;
    // The model's powers at the prediction are the same for every draw: only the data change.
    let at_mean = cost.powers(mean);
    let chi2_prediction = cost.cost_of_powers(&at_mean) / sigma.powi(2);
    let scale = cost.linear_at(mean).scale;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9c0f_11c7);
    let error = Normal::new(0.0, prior.std_rad()).map_err(|e| HasError::invalid("prior_std_rad", e.to_string()))?;
    let unit = Normal::new(0.0, 1.0).map_err(|e| HasError::invalid("prior", e.to_string()))?;
    let noise_draw = Normal::new(0.0, sigma).map_err(|e| HasError::invalid("noise", e.to_string()))?;
    let smooth = match prior.correlation_length() {
        Some(length) => error_modes(positions, prior.std_rad(), length)?,
        None => Vec::new(),
    };
    let mut null = Vec::with_capacity(PRIOR_CHECK_DRAWS);
    let mut drawn = cost.clone();
    for _ in 0..PRIOR_CHECK_DRAWS {
        let mut truth: Vec<f64> = if smooth.is_empty() { mean.iter().map(|m| m + error.sample(&mut rng)).collect() } else { mean.to_vec() };
        for mode in smooth.iter().chain(prior.modes()) {
            let a = unit.sample(&mut rng);
            truth.iter_mut().zip(mode).for_each(|(t, g)| *t += a * g);
        }
        let truth: Vec<f64> = truth.into_iter().map(wrap).collect();
        for term in drawn.terms.iter_mut() {
            let image = cost.predicted_image(&truth, &term.offset)?;
            let flat = image.as_standard_layout();
            let flat = flat.as_slice().ok_or_else(|| HasError::invalid("images", "not contiguous"))?;
            term.measured = term.mask.iter().map(|&i| scale * flat[i] + noise_draw.sample(&mut rng)).collect();
        }
        null.push(drawn.cost_of_powers(&at_mean) / sigma.powi(2));
    }
    let k = null.len() as f64;
    let null_mean = null.iter().sum::<f64>() / k;
    let null_std = (null.iter().map(|c| (c - null_mean).powi(2)).sum::<f64>() / (k - 1.0)).sqrt().max(f64::MIN_POSITIVE);
    let z = (chi2_prediction - null_mean) / null_std;
    let excess_per_pixel = (chi2_prediction - null_mean) / n as f64;
    Ok(PriorCheck {
        chi2_prediction,
        null_mean,
        null_std,
        z,
        excess_per_pixel,
        conflict: z > conflict_z && excess_per_pixel > MATERIAL_MISFIT - 1.0,
        conflict_z,
        draws: PRIOR_CHECK_DRAWS,
    })
}
