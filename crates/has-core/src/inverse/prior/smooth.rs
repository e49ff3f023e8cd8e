//! A prediction whose errors form a smooth field over the aperture, and the posterior of a
//! per-element estimate under it.
//!
//! A CT-based skull simulation errs where skull thickness or sound speed is misjudged, and those
//! vary over centimetres: the errors of neighbouring elements' predicted phases are alike. Model
//! the error as a Gaussian random field `e(x)` over the lateral element positions with the
//! squared-exponential covariance `k(x, x') = S²·exp(-|x - x'|²/(2·ℓ²))` (S the expected error
//! per phase, ℓ the correlation length), in the reduced-rank Hilbert-space form of Solin &
//! Särkkä (Stat. Comput. 30, 419–446, 2020): on a rectangle `[-L_u, L_u] x [-L_v, L_v]` around
//! the aperture (margin 2ℓ), with the Dirichlet Laplacian's eigenfunctions
//! `phi_jk = sin(pi·j·(u + L_u)/(2·L_u))·sin(pi·k·(v + L_v)/(2·L_v))/sqrt(L_u·L_v)` and
//! eigenvalues `w²_jk = (pi·j/(2·L_u))² + (pi·k/(2·L_v))²`,
//!
//! `e = W·a`, `W_jk = sqrt(s(w_jk))·phi_jk`, `s(w) = S²·2·pi·ℓ²·exp(-ℓ²·w²/2)`, `a ~ N(0, I)`.
//!
//! Modes whose spectral weight `s(w)/s(0)` is below [`MODE_CUTOFF`] are dropped. The estimate is
//! the posterior optimum over the coefficients `a`,
//!
//! `U(a) = J(mu + W·a)/(2·sigma²) + |a|²/2`,
//!
//! so it corrects the prediction only by smooth fields: element-scale detail that the images
//! cannot resolve stays as predicted instead of being fitted to noise.

use crate::error::{HasError, Result};
use crate::inverse::cost::Objective;
use crate::inverse::prior::{likelihood_weight, Prior};
use crate::physics::aberration::lateral_bounds;
use std::f64::consts::PI;

/// Relative spectral weight below which a mode is dropped (its share of the field's variance is
/// below 1e-4 of the largest mode's).
pub const MODE_CUTOFF: f64 = 1e-4;

/// The modes `W` (one vector over the positions per mode) of a smooth error field of expected
/// error `std_rad` per phase and correlation length `length` (m) at lateral positions
/// `positions` (x, y used; m). Refused when it needs more modes than there are positions (the
/// field is then no smoother than independent errors).
pub fn error_modes(positions: &[[f64; 3]], std_rad: f64, length: f64) -> Result<Vec<Vec<f64>>> {
    let (lo, hi) = lateral_bounds(positions);
    let half = [0.5 * (hi[0] - lo[0]) + 2.0 * length, 0.5 * (hi[1] - lo[1]) + 2.0 * length];
    let centre = [0.5 * (hi[0] + lo[0]), 0.5 * (hi[1] + lo[1])];
    // s(w)/s(0) >= MODE_CUTOFF  <=>  ℓ·w <= sqrt(-2 ln MODE_CUTOFF).
    let w_max = (-2.0 * MODE_CUTOFF.ln()).sqrt() / length;
    let count = |k: usize| (w_max * 2.0 * half[k] / PI).floor() as usize;
    let (nj, nk) = (count(0), count(1));
    let density = |w2: f64| std_rad * std_rad * 2.0 * PI * length * length * (-0.5 * length * length * w2).exp();
    let mut modes = Vec::new();
    for j in 1..=nj {
        for k in 1..=nk {
            let (wu, wv) = (PI * j as f64 / (2.0 * half[0]), PI * k as f64 / (2.0 * half[1]));
            let w2 = wu * wu + wv * wv;
            if w2 > w_max * w_max {
                continue;
            }
            if modes.len() >= positions.len() {
                return Err(HasError::invalid(
                    "prior_correlation_mm",
                    format!("{:.3} mm is too short for {} phases: use a longer correlation length or none", length * 1e3, positions.len()),
                ));
            }
            let a = density(w2).sqrt() / (half[0] * half[1]).sqrt();
            modes.push(
                positions
                    .iter()
                    .map(|p| a * (wu * (p[0] - centre[0] + half[0])).sin() * (wv * (p[1] - centre[1] + half[1])).sin())
                    .collect(),
            );
        }
    }
    Ok(modes)
}

/// A prediction and the smooth modes of its error: the phases `mu + W·a` of coefficients `a`
/// (one phase per element position).
#[derive(Debug, Clone)]
pub struct SmoothErrors {
    mean: Vec<f64>,
    modes: Vec<Vec<f64>>,
}

impl SmoothErrors {
    /// The error modes of `prior`, which must have a correlation length, at `positions` (one per
    /// predicted phase): the smooth field's, then the prior's modes of known shape
    /// ([`Prior::with_modes`]).
    pub fn new(prior: &Prior, positions: &[[f64; 3]]) -> Result<Self> {
        if prior.mean().len() != positions.len() {
            return Err(HasError::invalid(
                "prior",
                format!("has {} values; the estimate has {} phases", prior.mean().len(), positions.len()),
            ));
        }
        let length =
            prior.correlation_length().ok_or_else(|| HasError::invalid("prior_correlation_mm", "is required for a smooth prior"))?;
        if let Some(g) = prior.modes().iter().find(|g| g.len() != positions.len()) {
            return Err(HasError::invalid("prior_modes", format!("have {} values each; expected {}", g.len(), positions.len())));
        }
        let mut modes = error_modes(positions, prior.std_rad(), length)?;
        modes.extend(prior.modes().iter().cloned());
        Ok(SmoothErrors { mean: prior.mean().to_vec(), modes })
    }

    /// The modes `W` (one vector over the phases per mode).
    pub fn into_modes(self) -> Vec<Vec<f64>> {
        self.modes
    }

    /// Number of smooth modes.
    pub fn n_modes(&self) -> usize {
        self.modes.len()
    }

    /// The phases `mu + W·a` (rad, not wrapped).
    pub fn phases(&self, a: &[f64]) -> Vec<f64> {
        let mut p = self.mean.clone();
        for (w, c) in self.modes.iter().zip(a) {
            for (y, v) in p.iter_mut().zip(w) {
                *y += c * v;
            }
        }
        p
    }

    /// The posterior over the coefficients for image cost `likelihood` (noise floor
    /// `noise_rad`, at least [`crate::inverse::prior::MIN_NOISE_RAD`]), which must have one
    /// phase per predicted phase.
    pub fn posterior<'a>(&'a self, likelihood: &'a dyn Objective, noise_rad: f64) -> Result<SmoothPosterior<'a>> {
        let n = likelihood.n_phases();
        if self.mean.len() != n {
            return Err(HasError::invalid("prior", format!("has {} values; the estimate has {n} phases", self.mean.len())));
        }
        Ok(SmoothPosterior { likelihood, errors: self, weight: likelihood_weight(noise_rad) })
    }
}

/// The negative log posterior `U(a) = J(mu + W·a)/(2·sigma²) + |a|²/2` over the coefficients `a`
/// of the smooth error modes (see the module docs).
pub struct SmoothPosterior<'a> {
    likelihood: &'a dyn Objective,
    errors: &'a SmoothErrors,
    /// `1 / (2·sigma²)`.
    weight: f64,
}

impl Objective for SmoothPosterior<'_> {
    fn n_phases(&self) -> usize {
        self.errors.n_modes()
    }

    fn cost(&self, a: &[f64]) -> f64 {
        self.weight * self.likelihood.cost(&self.errors.phases(a)) + 0.5 * a.iter().map(|x| x * x).sum::<f64>()
    }

    fn cost_and_gradient(&self, a: &[f64]) -> (f64, Vec<f64>) {
        let (j, g) = self.likelihood.cost_and_gradient(&self.errors.phases(a));
        let grad =
            self.errors.modes.iter().zip(a).map(|(w, x)| self.weight * w.iter().zip(&g).map(|(u, v)| u * v).sum::<f64>() + x).collect();
        (self.weight * j + 0.5 * a.iter().map(|x| x * x).sum::<f64>(), grad)
    }

    fn sees_common_phase(&self) -> bool {
        true
    }

    fn periodic(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::cost::test_objectives::Cosines;

    fn grid(n: usize, pitch: f64) -> Vec<[f64; 3]> {
        (0..n * n)
            .map(|i| [(i / n) as f64 * pitch - 0.5 * (n - 1) as f64 * pitch, (i % n) as f64 * pitch - 0.5 * (n - 1) as f64 * pitch, 0.0])
            .collect()
    }

    #[test]
    fn the_modes_reproduce_the_squared_exponential_covariance() {
        // Reference: k(x, x') = S²·exp(-d²/(2ℓ²)), not the code. Over a 32 x 32 grid of 2.5 mm
        // pitch (the default array) with ℓ = 15 mm, sum_m W_m(x)·W_m(x') at the centre and at
        // points 0, 10, 20, 30 mm away. Tolerance 3 % of S²: the Hilbert-space approximation on
        // a box with a 2ℓ margin is accurate to about 1 % inside the aperture (Solin & Särkkä
        // 2020, Fig. 2), and the dropped modes hold below 1e-4 of the spectrum each.
        let (s, l) = (0.8, 15e-3);
        let pos = grid(32, 2.5e-3);
        let modes = error_modes(&pos, s, l).unwrap();
        let centre = 16 * 32 + 16;
        for (d, e) in [(0.0, centre), (10e-3, centre + 4), (20e-3, centre + 8), (30e-3, centre + 12)] {
            let c: f64 = modes.iter().map(|w| w[centre] * w[e]).sum();
            let expected = s * s * (-(d * d) / (2.0 * l * l)).exp();
            assert!((c - expected).abs() < 0.03 * s * s, "{d}: {c} vs {expected}");
        }
        assert!(modes.len() < pos.len());
        assert!(error_modes(&pos, s, 0.5e-3).unwrap_err().to_string().starts_with("prior_correlation_mm"));
    }

    #[test]
    fn the_gradient_matches_central_differences() {
        // Analytic gradient against (U(a + h) - U(a - h)) / 2h, h = 1e-6: agreement to 1e-6
        // relative (the O(h²) truncation error of derivatives of order one).
        let pos = grid(8, 5e-3);
        // With a mode of known shape too: its coefficient is one more parameter of U.
        let mode: Vec<f64> = (0..64).map(|i| 0.02 * i as f64 - 0.6).collect();
        let prior = Prior::new((0..64).map(|i| 0.1 * i as f64).collect(), 0.5)
            .unwrap()
            .with_correlation_length(20e-3)
            .unwrap()
            .with_modes(vec![mode])
            .unwrap();
        let like = Cosines((0..64).map(|i| (i as f64).sin()).collect());
        let errors = SmoothErrors::new(&prior, &pos).unwrap();
        let post = errors.posterior(&like, 0.3).unwrap();
        let a: Vec<f64> = (0..errors.n_modes()).map(|i| 0.3 * (i as f64 + 1.0).cos()).collect();
        let (_, g) = post.cost_and_gradient(&a);
        for i in 0..a.len() {
            let (mut p, mut m) = (a.clone(), a.clone());
            p[i] += 1e-6;
            m[i] -= 1e-6;
            let fd = (post.cost(&p) - post.cost(&m)) / 2e-6;
            assert!((fd - g[i]).abs() < 1e-6 * (1.0 + g[i].abs()), "{i}: {fd} vs {}", g[i]);
        }
        assert!(SmoothErrors::new(&Prior::new(vec![0.0; 64], 0.5).unwrap(), &pos).is_err());
        assert!(SmoothErrors::new(&prior, &pos[..63]).is_err());
    }

    #[test]
    fn a_mode_of_known_shape_adds_its_vector_after_the_smooth_modes() {
        // Coefficient 1 on the last mode and 0 elsewhere must give the prediction plus that
        // mode exactly (it enters as given, not rescaled), and the smooth modes are those of the
        // prior without it. Modes of the wrong length or with NaN are refused by name.
        let pos = grid(8, 5e-3);
        let mean: Vec<f64> = (0..64).map(|i| 0.05 * i as f64).collect();
        let mode: Vec<f64> = (0..64).map(|i| (0.3 * i as f64).cos()).collect();
        let plain = Prior::new(mean.clone(), 0.5).unwrap().with_correlation_length(20e-3).unwrap();
        let with = plain.clone().with_modes(vec![mode.clone()]).unwrap();
        let (e0, e1) = (SmoothErrors::new(&plain, &pos).unwrap(), SmoothErrors::new(&with, &pos).unwrap());
        assert_eq!(e1.n_modes(), e0.n_modes() + 1);
        let mut a = vec![0.0; e1.n_modes()];
        a[e0.n_modes()] = 1.0;
        for ((p, m), g) in e1.phases(&a).iter().zip(&mean).zip(&mode) {
            assert!((p - m - g).abs() < 1e-12);
        }
        assert_eq!(with.with_mean(mean.clone()).unwrap().modes(), &[mode][..]);
        let short = plain.clone().with_modes(vec![vec![0.0; 63]]).unwrap();
        assert!(SmoothErrors::new(&short, &pos).unwrap_err().to_string().starts_with("prior_modes"));
        assert!(plain.clone().with_modes(vec![vec![0.0; 64], vec![0.0; 63]]).unwrap_err().to_string().starts_with("prior_modes"));
        assert!(plain.with_modes(vec![vec![f64::NAN; 64]]).unwrap_err().to_string().starts_with("prior_modes"));
    }
}
