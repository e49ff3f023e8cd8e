//! The hybrid cost (paper Eq. 4) on a precomputed quadratic model of the image.
//!
//! The forward model after the pressure field is linear in `|p|²`, and the field is linear in the
//! group drives `v_g = exp(i·phi_g)`. So each pixel of the image is a Hermitian form
//! `d_i(phi) = v^H K_i v` with `K_i[g, h] = A · S_i(conj(W_g)·W_h)`, where `W_g` is the field of
//! group `g` in the MR window and `S_i` the MR sampling of pixel `i` (the slice-
//! thickness average and the Gaussian broadening of the MR-ARFI forward model). An evaluation costs
//! `O(P·G²)` for `P` pixels, and the gradient is analytic:
//! `∂d_i/∂phi_g = 2·Im(conj(v_g)·(K_i v)_g)`.

mod kernel;
mod model;

pub use kernel::ArfiKernel;
pub use model::{
    build_model, check_image, imaged_pixels, mask_pixels, masks_and_box, MaskedBox, Measurement, Model, MAX_KERNEL_GROUPS, MAX_PHASE,
};

use crate::error::{HasError, Result};
use num_complex::Complex64 as C64;

/// What an estimator minimises: a cost over phases (rad), one per group or element, and its
/// gradient. Implemented by [`HybridCost`] and [`crate::inverse::element::ElementCost`].
pub trait Objective: Sync {
    /// Number of phases.
    fn n_phases(&self) -> usize;
    /// The cost at `phases`.
    fn cost(&self, phases: &[f64]) -> f64;
    /// The cost and its gradient with respect to each phase.
    fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>);
    /// Whether the cost depends on a phase common to all (false for images, which see only
    /// phase differences; true once a prior anchors the phases). When false, estimators hold
    /// phase 0 at zero and report phases with zero circular mean.
    fn sees_common_phase(&self) -> bool {
        false
    }
    /// Whether the parameters are phases (rad, periodic; reported wrapped to (-pi, pi]). False
    /// for coefficients of a linear parametrisation, which are searched and reported as they are.
    fn periodic(&self) -> bool {
        true
    }
}

/// One measured image as the cost sees it: a kernel, the measured values on the masked pixels,
/// and the known group phase offsets added for this acquisition.
#[derive(Debug, Clone)]
pub struct Term {
    /// The image's Hermitian kernels over the group drives.
    pub kernel: std::sync::Arc<ArfiKernel>,
    /// Box indices of the masked pixels (measured > mask_fraction · max).
    pub mask: Vec<usize>,
    /// Measured ARFI phase at the masked pixels (rad).
    pub measured: Vec<f64>,
    /// Known per-group phases added to the estimate for this image (rad).
    pub offset: Vec<f64>,
}

/// The joint cost `J(phi) = Σ_k Σ_{i in mask_k} (s·d_k,i(phi + offset_k) - m_k,i)²` over images.
/// `s = 1`, or, with `fit_amplitude`, the least-squares scale `s = <d, m> / <d, d>` for each `phi`
/// (one for all images): a free amplitude that absorbs a uniform loss of focal intensity the
/// phases cannot explain (e.g. element-level aberration within groups).
#[derive(Debug, Clone)]
pub struct HybridCost {
    /// One term per measured image.
    pub terms: Vec<Term>,
    /// Number of group phases `G`.
    pub n_groups: usize,
    /// Fit the least-squares scale `s` (otherwise `s = 1`).
    pub fit_amplitude: bool,
}

impl HybridCost {
    /// Checks that every term has the same number of groups.
    pub fn new(terms: Vec<Term>) -> Result<Self> {
        let n_groups = terms.first().map(|t| t.kernel.n_groups).ok_or_else(|| HasError::invalid("images", "need at least one image"))?;
        for (k, t) in terms.iter().enumerate() {
            if t.kernel.n_groups != n_groups || t.offset.len() != n_groups {
                return Err(HasError::invalid(format!("image[{k}]"), "group count differs from the first image"));
            }
            if t.mask.is_empty() || t.mask.len() != t.measured.len() {
                return Err(HasError::invalid(format!("image[{k}]"), "empty mask"));
            }
        }
        Ok(HybridCost { terms, n_groups, fit_amplitude: false })
    }

    /// Number of masked pixels over all images.
    pub fn n_pixels(&self) -> usize {
        self.terms.iter().map(|t| t.mask.len()).sum()
    }

    /// Model images at the masked pixels of every term.
    fn images(&self, phases: &[f64]) -> Vec<Vec<f64>> {
        self.terms
            .iter()
            .map(|t| {
                let v: Vec<C64> = phases.iter().zip(&t.offset).map(|(p, o)| C64::from_polar(1.0, p + o)).collect();
                let mut img = Vec::new();
                t.kernel.image_at(&v, &t.mask, &mut img);
                img
            })
            .collect()
    }

    /// The scale applied to the model images for these images (1 unless `fit_amplitude`).
    fn scale_for(&self, images: &[Vec<f64>]) -> f64 {
        if !self.fit_amplitude {
            return 1.0;
        }
        least_squares_scale(images.iter().zip(&self.terms).map(|(d, t)| (d.as_slice(), t.measured.as_slice())))
    }

    /// The amplitude scale at `phases` (1 unless `fit_amplitude`).
    pub fn scale(&self, phases: &[f64]) -> f64 {
        self.scale_for(&self.images(phases))
    }

    /// `J` for group phases (rad).
    pub fn cost(&self, phases: &[f64]) -> f64 {
        let images = self.images(phases);
        let s = self.scale_for(&images);
        images.iter().zip(&self.terms).map(|(img, t)| img.iter().zip(&t.measured).map(|(d, m)| (s * d - m).powi(2)).sum::<f64>()).sum()
    }

    /// `J` and `∂J/∂phi_g = 4·s·Σ_k Im(conj(v_g)·(R_k v)_g)`, `R_k = Σ_i r_i·K_i`, `r = s·d - m`
    /// (with a fitted scale the envelope theorem makes `∂s/∂phi` drop out).
    pub fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        let g = self.n_groups;
        let images = self.images(phases);
        let s = self.scale_for(&images);
        let mut grad = vec![0.0; g];
        let mut total = 0.0;
        for (t, img) in self.terms.iter().zip(&images) {
            let v: Vec<C64> = phases.iter().zip(&t.offset).map(|(p, o)| C64::from_polar(1.0, p + o)).collect();
            let r: Vec<f64> = img.iter().zip(&t.measured).map(|(d, m)| s * d - m).collect();
            total += r.iter().map(|x| x * x).sum::<f64>();
            let rv = t.kernel.hermitian_times(&t.kernel.weighted_sum(&t.mask, &r), &v);
            for ((gr, va), rva) in grad.iter_mut().zip(&v).zip(&rv) {
                *gr += 4.0 * s * (va.conj() * rva).im;
            }
        }
        (total, grad)
    }
}

/// The scale `s = <d, m> / <d, d>` minimising `Σ (s·d - m)²` over (model, measured) pairs; 1 when
/// the model is all zero.
pub(crate) fn least_squares_scale<'a>(pairs: impl Iterator<Item = (&'a [f64], &'a [f64])>) -> f64 {
    let (mut dm, mut dd) = (0.0, 0.0);
    for (d, m) in pairs {
        for (x, y) in d.iter().zip(m) {
            dm += x * y;
            dd += x * x;
        }
    }
    if dd > 0.0 {
        dm / dd
    } else {
        1.0
    }
}

impl Objective for HybridCost {
    fn n_phases(&self) -> usize {
        self.n_groups
    }
    fn cost(&self, phases: &[f64]) -> f64 {
        HybridCost::cost(self, phases)
    }
    fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        HybridCost::cost_and_gradient(self, phases)
    }
}

/// Objectives with known minima for the estimators' and the prior's unit tests.
#[cfg(test)]
pub(crate) mod test_objectives {
    use super::Objective;

    /// `Σ (1 - cos(φ_i - φ_0 - t_i))`: minimum at the phases `t` (up to a common phase), which
    /// it does not see.
    pub(crate) struct Cosines(pub(crate) Vec<f64>);

    impl Objective for Cosines {
        fn n_phases(&self) -> usize {
            self.0.len()
        }
        fn cost(&self, p: &[f64]) -> f64 {
            self.cost_and_gradient(p).0
        }
        fn cost_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
            let d: Vec<f64> = p.iter().zip(&self.0).map(|(x, t)| x - p[0] - t).collect();
            let mut g: Vec<f64> = d.iter().map(|v| v.sin()).collect();
            g[0] = -g[1..].iter().sum::<f64>();
            (d.iter().map(|v| 1.0 - v.cos()).sum(), g)
        }
    }
}
