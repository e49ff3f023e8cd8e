//! The per-element cost of paper Eq. 4 on a [`FieldBasis`]: the model images of every
//! measured image from one product `P = B·V`, the linear nuisance solved for each evaluation, and
//! the gradient by the adjoint (see the parent module).

use super::{power_columns, FieldBasis};
use crate::error::{HasError, Result};
use crate::inverse::cost::Objective;
use crate::physics::mr::MrSampler;
use ndarray::Array2;
use num_complex::{Complex32 as C32, Complex64 as C64};
use std::sync::Arc;

/// One image as the per-element cost sees it.
#[derive(Debug, Clone)]
pub struct ElementTerm {
    /// Box indices of the masked pixels.
    pub mask: Vec<usize>,
    /// Measured ARFI phase at the masked pixels (rad).
    pub measured: Vec<f64>,
    /// Known per-element phases added for this image (rad).
    pub offset: Vec<f64>,
}

/// The joint cost of paper Eq. 4 over images, on the per-element basis: the same `J` as
/// [`crate::inverse::cost::HybridCost`] with one phase per element, optionally with nuisance
/// parameters ([`crate::inverse::element::nuisance`]): the model value of pixel `i` of image `k` is
/// `s·d_k,i + b_k·(1, u_i, v_i)` with the scale `s` and the background planes `b_k` solved by
/// least squares for each `phases`, and `d` formed with the cost's view (W, shift).
#[derive(Debug, Clone)]
pub struct ElementCost {
    /// The fields of every element in the MR window.
    pub basis: Arc<FieldBasis>,
    /// One term per measured image.
    pub terms: Vec<ElementTerm>,
    /// Fit one least-squares amplitude scale for all images (see `HybridCost::fit_amplitude`).
    pub fit_amplitude: bool,
    /// Fit a background plane (offset and slopes along u and v) per image.
    pub fit_background: bool,
    /// The MR sampling the images are formed with: the basis' own, or another W and shift.
    sampler: MrSampler,
    /// Pixel-centre coordinates (mm) of the box's rows (u) and columns (v).
    coords: [Vec<f64>; 2],
}

/// The linear nuisance at some phases: the amplitude scale and one background plane per image.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearNuisance {
    /// Scale on the model image (1 unless fitted).
    pub scale: f64,
    /// Per image: offset (rad), slopes along u and v (rad/mm); zero unless fitted.
    pub background: Vec<[f64; 3]>,
}

impl ElementCost {
    /// Checks the terms against the basis.
    pub fn new(basis: Arc<FieldBasis>, terms: Vec<ElementTerm>) -> Result<Self> {
        if terms.is_empty() {
            return Err(HasError::invalid("images", "need at least one image"));
        }
        let (g, n_box) = (basis.n_elements(), basis.sampler.pixels[0].len() * basis.sampler.pixels[1].len());
        for (k, t) in terms.iter().enumerate() {
            if t.offset.len() != g {
                return Err(HasError::invalid(
                    format!("image[{k}]"),
                    format!("known phases have {} values for {g} elements", t.offset.len()),
                ));
            }
            if t.mask.is_empty() || t.mask.len() != t.measured.len() || t.mask.iter().any(|&p| p >= n_box) {
                return Err(HasError::invalid(format!("image[{k}]"), "mask is empty or outside the basis' pixel box"));
            }
        }
        let sampler = basis.sampler.clone();
        let coords = [0, 1].map(|k| sampler.pixels[k].clone().map(|i| sampler.geometry.pixel_center(k, i) * 1e3).collect());
        Ok(ElementCost { basis, terms, fit_amplitude: false, fit_background: false, sampler, coords })
    }

    /// The same cost with the images formed with broadening widths `widths` and shift `shift`
    /// (m, along u and v; see [`MrSampler::with_view`]), on the basis' window.
    pub fn with_view(&self, widths: [f64; 2], shift: [f64; 2]) -> Result<Self> {
        Ok(ElementCost { sampler: self.basis.sampler.with_view(widths, shift)?, ..self.clone() })
    }

    /// The view the images are formed with: W and the shift along u and v (mm).
    pub fn view_mm(&self) -> (f64, [f64; 2]) {
        (self.sampler.broadening.width * 1e3, self.sampler.shift.map(|s| s * 1e3))
    }

    /// The MR sampling the images are formed with (the basis' own, or another view).
    pub fn sampler(&self) -> &MrSampler {
        &self.sampler
    }

    /// The model image on the box (before the linear nuisance) at `phases` with known
    /// per-element phases `offset` added, formed with this cost's view: what an acquisition
    /// with those known phases is expected to show.
    pub fn predicted_image(&self, phases: &[f64], offset: &[f64]) -> Result<Array2<f64>> {
        self.basis.image_with(&self.sampler, phases, offset)
    }

    /// The broadening width of the basis (the model's, m).
    pub fn model_width(&self) -> f64 {
        self.basis.sampler.broadening.width
    }

    /// The window fields of every term at `phases` (real and imaginary parts, samples x terms).
    fn fields_at(&self, phases: &[f64]) -> (Array2<f32>, Array2<f32>) {
        let offsets: Vec<&[f64]> = self.terms.iter().map(|t| t.offset.as_slice()).collect();
        let (vr, vi) = FieldBasis::drives(phases, &offsets);
        self.basis.fields(&vr, &vi)
    }

    /// `|p|²` on the window for every term at `phases` (samples, one vector per term).
    pub fn powers(&self, phases: &[f64]) -> Vec<Vec<f64>> {
        let (pr, pi) = self.fields_at(phases);
        power_columns(&pr, &pi)
    }

    /// The cost for fixed `powers` ([`ElementCost::powers`]) with this cost's view and linear
    /// nuisance.
    pub fn cost_of_powers(&self, powers: &[Vec<f64>]) -> f64 {
        let images: Vec<Array2<f64>> = powers.iter().map(|q| self.image_of(q)).collect();
        let model = self.masked(&images);
        let linear = self.linear_fit(&model);
        self.residuals(&model, &linear).iter().flatten().map(|r| r * r).sum()
    }

    /// The model image on the box (before the linear nuisance) from `|p|²` samples.
    fn image_of(&self, q: &[f64]) -> Array2<f64> {
        self.sampler.apply(q).map(|img| img * self.basis.amplitude).unwrap_or_else(|_| Array2::from_elem((0, 0), f64::NAN))
    }

    /// Model images on the box for every term, and the fields they came from.
    fn evaluate(&self, phases: &[f64]) -> (Vec<Array2<f64>>, Array2<f32>, Array2<f32>) {
        let (pr, pi) = self.fields_at(phases);
        let images = power_columns(&pr, &pi).iter().map(|q| self.image_of(q)).collect();
        (images, pr, pi)
    }

    /// Masked model values per term.
    fn masked(&self, images: &[Array2<f64>]) -> Vec<Vec<f64>> {
        images.iter().zip(&self.terms).map(|(img, t)| t.mask.iter().map(|&p| img.as_slice().map_or(f64::NAN, |s| s[p])).collect()).collect()
    }

    /// Pixel-centre coordinates (mm) of box index `p`.
    fn uv(&self, p: usize) -> (f64, f64) {
        let nv = self.coords[1].len();
        (self.coords[0][p / nv], self.coords[1][p % nv])
    }

    /// The least-squares scale and background planes for masked model values `model`: the
    /// normal equations of `s·d + b_k·(1, u, v) ≈ m` (s fixed at 1 unless fitted). Falls back to
    /// the scale alone when the planes are not determined (e.g. one row of pixels).
    pub fn linear_fit(&self, model: &[Vec<f64>]) -> LinearNuisance {
        let k = self.terms.len();
        let scale_only = || {
            let s = if self.fit_amplitude {
                crate::inverse::cost::least_squares_scale(model.iter().zip(&self.terms).map(|(d, t)| (d.as_slice(), t.measured.as_slice())))
            } else {
                1.0
            };
            LinearNuisance { scale: s, background: vec![[0.0; 3]; k] }
        };
        if !self.fit_background {
            return scale_only();
        }
        let o = usize::from(self.fit_amplitude);
        let m = o + 3 * k;
        let mut a = vec![vec![0.0; m + 1]; m];
        for (c, (d, t)) in model.iter().zip(&self.terms).enumerate() {
            for ((&p, &x), &y) in t.mask.iter().zip(d).zip(&t.measured) {
                let (u, v) = self.uv(p);
                let target = if self.fit_amplitude { y } else { y - x };
                let mut cols = [(0, 0.0); 4];
                let mut n = 0;
                if self.fit_amplitude {
                    cols[0] = (0, x);
                    n = 1;
                }
                for (j, value) in [1.0, u, v].into_iter().enumerate() {
                    cols[n] = (o + 3 * c + j, value);
                    n += 1;
                }
                for &(p, vp) in &cols[..n] {
                    for &(q, vq) in &cols[..n] {
                        a[p][q] += vp * vq;
                    }
                    a[p][m] += vp * target;
                }
            }
        }
        match crate::inverse::linear::solve_augmented(a) {
            Some(x) => LinearNuisance {
                scale: if self.fit_amplitude { x[0] } else { 1.0 },
                background: (0..k).map(|c| [x[o + 3 * c], x[o + 3 * c + 1], x[o + 3 * c + 2]]).collect(),
            },
            None => scale_only(),
        }
    }

    /// Residuals model - measured per term.
    fn residuals(&self, model: &[Vec<f64>], linear: &LinearNuisance) -> Vec<Vec<f64>> {
        model
            .iter()
            .zip(&self.terms)
            .zip(&linear.background)
            .map(|((d, t), b)| {
                t.mask
                    .iter()
                    .zip(d)
                    .zip(&t.measured)
                    .map(|((&p, x), m)| {
                        let (u, v) = self.uv(p);
                        linear.scale * x + b[0] + b[1] * u + b[2] * v - m
                    })
                    .collect()
            })
            .collect()
    }

    /// The linear nuisance at `phases`.
    pub fn linear_at(&self, phases: &[f64]) -> LinearNuisance {
        let (images, _, _) = self.evaluate(phases);
        self.linear_fit(&self.masked(&images))
    }

    /// Number of masked pixels over all images.
    pub fn n_pixels(&self) -> usize {
        self.terms.iter().map(|t| t.mask.len()).sum()
    }
}

impl Objective for ElementCost {
    fn n_phases(&self) -> usize {
        self.basis.n_elements()
    }

    fn cost(&self, phases: &[f64]) -> f64 {
        self.cost_of_powers(&self.powers(phases))
    }

    fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        let (images, pr, pi) = self.evaluate(phases);
        let model = self.masked(&images);
        let linear = self.linear_fit(&model);
        let s = linear.scale;
        let b = &self.basis;
        let (nu, nv) = (self.sampler.pixels[0].len(), self.sampler.pixels[1].len());
        let (n_s, k) = (b.n_samples(), self.terms.len());
        let mut h_all = vec![C32::new(0.0, 0.0); n_s * k];
        let mut total = 0.0;
        for (c, (res, t)) in self.residuals(&model, &linear).iter().zip(&self.terms).enumerate() {
            // The linear nuisance sits at its least-squares optimum: its own change does not
            // enter the gradient (variable projection).
            let mut r = Array2::<f64>::zeros((nu, nv));
            for (&p, &e) in t.mask.iter().zip(res) {
                total += e * e;
                r[[p / nv, p % nv]] = 2.0 * s * e * b.amplitude;
            }
            let Ok(h) = self.sampler.apply_adjoint(&r) else {
                return (f64::NAN, vec![0.0; phases.len()]);
            };
            // H = h ∘ conj(p)
            for (n, hv) in h.iter().enumerate() {
                h_all[n * k + c] = C32::new((hv * f64::from(pr[[n, c]])) as f32, (-hv * f64::from(pi[[n, c]])) as f32);
            }
        }
        let (cr, ci) = b.back_project(&h_all, k);
        let offsets: Vec<&[f64]> = self.terms.iter().map(|t| t.offset.as_slice()).collect();
        let grad = (0..phases.len())
            .map(|e| {
                (0..k)
                    .map(|c| {
                        let v = C64::from_polar(1.0, phases[e] + offsets[c][e]);
                        -2.0 * (v * C64::new(cr[[e, c]], ci[[e, c]])).im
                    })
                    .sum()
            })
            .collect();
        (total, grad)
    }
}
