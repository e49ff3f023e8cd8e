//! A predicted aberration as prior knowledge, and the posterior an estimator minimises with it.
//!
//! Clinically a CT-based skull simulation predicts the aberration before any MR-ARFI image; its
//! error is what MR-ARFI must fix. With predicted phases `mu` (rad, the sign of the estimate:
//! subtracting them corrects) and an expected error `S` (rad) per predicted phase, each phase
//! gets a von Mises prior `p(phi) ∝ exp(kappa·cos(phi - mu))`, `kappa = 1/S²` (the wrap-aware
//! Gaussian: `kappa·(1 - cos d) ≈ d²/(2·S²)` for small errors `d`). The images' cost `J` of paper
//! Eq. 4 is a Gaussian likelihood with the measured noise floor `sigma`, so the negative log
//! posterior is
//!
//! `U(phi) = J(phi) / (2·sigma²) + kappa·Σ_e (1 - cos(phi_e - mu_e))`.
//!
//! The prior anchors the common phase (the images see only phase differences), removes the
//! twin that one in-focus image cannot tell apart, and makes per-element estimation from a few
//! images well posed.
//!
//! Errors correlated over the aperture are [`smooth`]; the coefficient of a prediction's error
//! mode fitted to images is [`mode_fit`].

pub mod mode_fit;
pub mod modes_fit;
pub mod smooth;

use crate::error::{HasError, Result};
use crate::inverse::cost::Objective;
use crate::phase::condense;

/// The smallest noise floor (rad) the likelihood uses: noise-free images would otherwise give
/// the prior no weight at all.
pub const MIN_NOISE_RAD: f64 = 1e-4;

/// Predicted phases and the expected error of each.
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    mean: Vec<f64>,
    std_rad: f64,
    /// Length over which the errors are correlated (m); none: independent per phase.
    correlation_length: Option<f64>,
    /// Error modes of known shape ([`Prior::with_modes`]), one value per predicted phase each.
    modes: Vec<Vec<f64>>,
}

impl Prior {
    /// A prior with predicted phases `mean` (rad, finite) and expected error `std_rad` (rad,
    /// finite, > 0) of each.
    pub fn new(mean: Vec<f64>, std_rad: f64) -> Result<Self> {
        if mean.is_empty() {
            return Err(HasError::invalid("prior", "is empty"));
        }
        if let Some(i) = mean.iter().position(|v| !v.is_finite()) {
            return Err(HasError::invalid("prior", format!("value {i} is not finite ({})", mean[i])));
        }
        if !(std_rad.is_finite() && std_rad > 0.0) {
            return Err(HasError::invalid("prior_std_rad", format!("must be a finite number > 0, got {std_rad}")));
        }
        Ok(Prior { mean, std_rad, correlation_length: None, modes: Vec::new() })
    }

    /// The same prior with errors that form a smooth field over the aperture, correlated over
    /// `length_m` (m, finite, > 0): per-element estimates then search the smooth corrections of
    /// the prediction (see [`crate::inverse::prior::smooth`]); group estimates keep the
    /// independent prior of the group means.
    pub fn with_correlation_length(mut self, length_m: f64) -> Result<Self> {
        if !(length_m.is_finite() && length_m > 0.0) {
            return Err(HasError::invalid("prior_correlation_mm", format!("must be a finite number > 0, got {}", length_m * 1e3)));
        }
        self.correlation_length = Some(length_m);
        Ok(self)
    }

    /// The same prior with error modes of known shape added to the smooth field: each mode `g`
    /// (rad, one value per predicted phase: the change of the predicted phases when one of the
    /// prediction's inputs is off by one standard deviation, e.g. the CT conversion's bone sound
    /// speed) adds `a·g` with `a ~ N(0, 1)` to the error `W·a` of the smooth prior (see
    /// [`crate::inverse::prior::smooth`]). A per-element estimate then fits each mode's
    /// coefficient with the smooth corrections: an error spread over the whole aperture by one
    /// misjudged constant is one number for the images to find, not hundreds. Modes hold one
    /// value per element (checked by the estimate, also when the predicted phases are given per
    /// group and spread to the elements); they need a correlation length, and group estimates
    /// refuse them. The ambiguity check's draws of the prior do not explore them.
    pub fn with_modes(mut self, modes: Vec<Vec<f64>>) -> Result<Self> {
        for (m, g) in modes.iter().enumerate() {
            if g.len() != modes[0].len() {
                return Err(HasError::invalid("prior_modes", format!("mode {m} has {} values, mode 0 {}", g.len(), modes[0].len())));
            }
            if g.iter().any(|v| !v.is_finite()) {
                return Err(HasError::invalid("prior_modes", format!("mode {m} holds a value that is not finite")));
            }
        }
        self.modes = modes;
        Ok(self)
    }

    /// The error modes of known shape ([`Prior::with_modes`]).
    pub fn modes(&self) -> &[Vec<f64>] {
        &self.modes
    }

    /// The same prior (expected error, correlation, modes) on other predicted phases `mean`,
    /// checked as [`Prior::new`] checks them.
    pub fn with_mean(&self, mean: Vec<f64>) -> Result<Self> {
        Ok(Prior { correlation_length: self.correlation_length, modes: self.modes.clone(), ..Prior::new(mean, self.std_rad)? })
    }

    /// The length over which the errors are correlated (m), if they are.
    pub fn correlation_length(&self) -> Option<f64> {
        self.correlation_length
    }

    /// The prior of optional parts as a caller gives them: none without `mean`; a `mean` needs
    /// its `std_rad`; a `std_rad`, a correlation length (m) or modes without a mean are refused
    /// (they would silently do nothing). See [`Prior::with_correlation_length`] and
    /// [`Prior::with_modes`].
    pub fn from_parts(
        mean: Option<Vec<f64>>,
        std_rad: Option<f64>,
        correlation_length_m: Option<f64>,
        modes: Option<Vec<Vec<f64>>>,
    ) -> Result<Option<Self>> {
        let prior = match (mean, std_rad) {
            (Some(m), Some(s)) => Prior::new(m, s)?,
            (Some(_), None) => {
                return Err(HasError::invalid(
                    "prior_std_rad",
                    "is required with a prior: the expected error of each predicted phase (rad)",
                ))
            }
            (None, std) => {
                let given = [
                    ("prior_std_rad", std.is_some()),
                    ("prior_correlation_mm", correlation_length_m.is_some()),
                    ("prior_modes", modes.is_some()),
                ];
                return match given.iter().find(|(_, g)| *g) {
                    Some((name, _)) => Err(HasError::invalid(*name, "was given without a prior")),
                    None => Ok(None),
                };
            }
        };
        let prior = match correlation_length_m {
            Some(l) => prior.with_correlation_length(l)?,
            None => prior,
        };
        match modes {
            Some(m) => prior.with_modes(m).map(Some),
            None => Ok(Some(prior)),
        }
    }

    /// The predicted phases (rad).
    pub fn mean(&self) -> &[f64] {
        &self.mean
    }

    /// The expected error of each predicted phase (rad).
    pub fn std_rad(&self) -> f64 {
        self.std_rad
    }

    /// The von Mises concentration `kappa = 1/S²`.
    pub fn kappa(&self) -> f64 {
        self.std_rad.powi(-2)
    }

    /// The prior on groups `groups[e]` of a per-element prior: each group's circular mean of
    /// its elements' predictions, with the same expected error.
    pub fn condensed(&self, groups: &[usize]) -> Result<Prior> {
        if groups.len() != self.mean.len() {
            return Err(HasError::invalid("prior", format!("has {} values for {} elements", self.mean.len(), groups.len())));
        }
        Prior::new(condense(&self.mean, groups)?, self.std_rad)
    }

    /// `kappa·Σ (1 - cos(phi - mu))` and its gradient.
    fn energy(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        let k = self.kappa();
        let d: Vec<f64> = phases.iter().zip(&self.mean).map(|(p, m)| p - m).collect();
        (k * d.iter().map(|x| 1.0 - x.cos()).sum::<f64>(), d.iter().map(|x| k * x.sin()).collect())
    }
}

/// The weight `1/(2·sigma²)` of an image cost `J` as a Gaussian log likelihood at noise floor
/// `noise_rad` (at least [`MIN_NOISE_RAD`]; a non-finite floor counts as that minimum).
pub(crate) fn likelihood_weight(noise_rad: f64) -> f64 {
    let sigma = if noise_rad.is_finite() { noise_rad.max(MIN_NOISE_RAD) } else { MIN_NOISE_RAD };
    0.5 / (sigma * sigma)
}

/// The negative log posterior `U = J/(2·sigma²) + kappa·Σ(1 - cos(phi - mu))` of an image cost
/// `J` (see the module docs). Its minimum is the estimate with the prior.
pub struct Posterior<'a> {
    likelihood: &'a dyn Objective,
    prior: &'a Prior,
    /// `1 / (2·sigma²)`.
    weight: f64,
}

impl<'a> Posterior<'a> {
    /// The posterior of image cost `likelihood` (noise floor `noise_rad`, at least
    /// [`MIN_NOISE_RAD`]) under `prior`, one prior phase per phase of the cost.
    pub fn new(likelihood: &'a dyn Objective, noise_rad: f64, prior: &'a Prior) -> Result<Self> {
        let n = likelihood.n_phases();
        if prior.mean.len() != n {
            return Err(HasError::invalid("prior", format!("has {} values; the estimate has {n} phases", prior.mean.len())));
        }
        Ok(Posterior { likelihood, prior, weight: likelihood_weight(noise_rad) })
    }

    /// The image cost `J` at `phases` (rad²).
    pub fn likelihood_cost(&self, phases: &[f64]) -> f64 {
        self.likelihood.cost(phases)
    }
}

impl Objective for Posterior<'_> {
    fn n_phases(&self) -> usize {
        self.likelihood.n_phases()
    }

    fn cost(&self, phases: &[f64]) -> f64 {
        self.weight * self.likelihood.cost(phases) + self.prior.energy(phases).0
    }

    fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        let (j, gj) = self.likelihood.cost_and_gradient(phases);
        let (e, ge) = self.prior.energy(phases);
        (self.weight * j + e, gj.iter().zip(ge).map(|(a, b)| self.weight * a + b).collect())
    }

    fn sees_common_phase(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::cost::test_objectives::Cosines;

    #[test]
    fn the_gradient_matches_central_differences() {
        // Analytic gradient against (U(x + h) - U(x - h)) / 2h, h = 1e-6: agreement to 1e-6
        // relative (the truncation error is O(h²) of the third derivative, here of order 1).
        let like = Cosines(vec![0.0, 0.4, -1.1, 2.0]);
        let prior = Prior::new(vec![0.3, 0.9, -2.5, 3.0], 0.7).unwrap();
        let post = Posterior::new(&like, 0.5, &prior).unwrap();
        let x = [0.2, -0.3, 1.7, -2.9];
        let (_, g) = post.cost_and_gradient(&x);
        for i in 0..4 {
            let (mut a, mut b) = (x.to_vec(), x.to_vec());
            a[i] += 1e-6;
            b[i] -= 1e-6;
            let fd = (post.cost(&a) - post.cost(&b)) / 2e-6;
            assert!((fd - g[i]).abs() < 1e-6 * (1.0 + g[i].abs()), "{i}: {fd} vs {}", g[i]);
        }
    }

    #[test]
    fn the_posterior_is_the_precision_weighted_mean_for_one_phase_difference() {
        // Two phases, J = 1 - cos(d - t) ≈ (d - t)²/2 in the difference d = phi_1 - phi_0: a
        // Gaussian likelihood of precision 1/(2·sigma²) on d. The prior, for small angles (kappa/2)·Σ(phi_i - m_i)², with
        // the common phase at its optimum is (kappa/4)·(d - (m_1 - m_0))²: precision kappa/2. So
        // the optimum is the precision-weighted mean of t and m_1 - m_0. Checked by a fine scan of
        // U along d (tolerance 1e-3 rad: the scan step is 1e-4, the small-angle error at
        // |d| < 0.1 rad is below 1e-5).
        let (t, m, sigma, s) = (0.08, [0.0, 0.02], 0.1, 0.05);
        let like = Cosines(vec![0.0, t]);
        let prior = Prior::new(m.to_vec(), s).unwrap();
        let post = Posterior::new(&like, sigma, &prior).unwrap();
        let (kappa, lp) = (prior.kappa(), 0.5 / (sigma * sigma));
        let expected = (lp * t + kappa / 2.0 * (m[1] - m[0])) / (lp + kappa / 2.0);
        let best = (-1000..=1000)
            .map(|i| i as f64 * 1e-4)
            .map(|d| {
                let c = (m[0] + m[1] - d) / 2.0; // the common phase centred on the prior's
                (post.cost(&[c, c + d]), d)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap()
            .1;
        assert!((best - expected).abs() < 1e-3, "{best} vs {expected}");
        assert!(post.sees_common_phase() && !like.sees_common_phase());
    }

    #[test]
    fn bad_priors_are_refused_naming_the_parameter() {
        let err = |m, s, l, g| Prior::from_parts(m, s, l, g).unwrap_err().to_string();
        assert_eq!(Prior::from_parts(None, None, None, None).unwrap(), None);
        assert!(err(Some(vec![0.0, 1.0]), None, None, None).starts_with("prior_std_rad"));
        assert!(err(None, Some(0.5), None, None).starts_with("prior_std_rad"));
        assert!(err(None, None, Some(0.02), None).starts_with("prior_correlation_mm"));
        assert!(err(None, None, None, Some(vec![vec![0.0, 1.0]])).starts_with("prior_modes"));
        assert!(err(Some(vec![0.0, 1.0]), Some(0.5), Some(-1.0), None).starts_with("prior_correlation_mm"));
        assert!(err(Some(vec![0.0, 1.0]), Some(0.5), None, Some(vec![vec![0.0], vec![f64::NAN]])).starts_with("prior_modes"));
        let full = Prior::from_parts(Some(vec![0.0, 1.0]), Some(0.5), Some(0.02), Some(vec![vec![0.1, 0.2]])).unwrap().unwrap();
        assert_eq!((full.correlation_length(), full.modes().len()), (Some(0.02), 1));
        assert!(Prior::new(vec![], 0.5).unwrap_err().to_string().contains("prior"));
        assert!(Prior::new(vec![0.0, f64::NAN], 0.5).unwrap_err().to_string().contains("prior"));
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Prior::new(vec![0.0, 1.0], s).unwrap_err().to_string().contains("prior_std_rad"), "{s}");
        }
        let like = Cosines(vec![0.0, 1.0, 2.0]);
        let prior = Prior::new(vec![0.0, 1.0], 0.5).unwrap();
        assert!(Posterior::new(&like, 0.1, &prior).is_err());
        assert!(prior.condensed(&[0, 0, 1]).is_err());
        let c = Prior::new(vec![0.1, 0.3, -1.0, -1.0], 0.5).unwrap().condensed(&[0, 0, 1, 1]).unwrap();
        assert!((c.mean()[0] - 0.2).abs() < 1e-12 && (c.mean()[1] + 1.0).abs() < 1e-12);
    }
}
