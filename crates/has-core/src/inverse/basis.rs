//! The per-element field basis for estimation with many phases (e.g. one per element of a
//! 1024-element array, the paper's clinical case).
//!
//! For G in the thousands the per-pixel G x G kernels of [`crate::inverse::cost::ArfiKernel`] are too
//! large. Instead keep the field of every element on the window samples that the box of pixels
//! depends on, `B` (S samples x G elements), and per image with drives `v_k`:
//! `p = B·v_k`, `d = A·S(|p|²)` (the sampler's linear map `S`, amplitude `A`). The gradient is
//! the adjoint: with `h = A·Sᵀ(∂J/∂d)`, `∂J/∂phi_e = -2·Im(v_e·(Bᵀ(h ∘ conj p))_e)`.
//!
//! `B` is stored in single precision as real and imaginary parts, so the products for all images
//! at once are real matrix products over fixed blocks of samples (deterministic for any number
//! of threads).

use crate::error::{HasError, Result};
use crate::inverse::cost::{imaged_pixels, masks_and_box, Measurement, Objective};
use crate::inverse::nuisance::Nuisance;
use crate::memory;
use crate::physics::mr::MrSampler;
use crate::physics::propagation::single;
use crate::simulation::Simulation;
use ndarray::{s, Array2};
use num_complex::{Complex32 as C32, Complex64 as C64};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Pixels around the masks whose background a background plane is fitted on.
pub const BACKGROUND_MARGIN: usize = 4;
/// Samples per block of the matrix products.
const BLOCK: usize = 2048;
/// Element fields marched per batch while building.
const BATCH: usize = 32;

/// Element fields on the window of a box of MR pixels.
#[derive(Debug, Clone)]
pub struct FieldBasis {
    /// The sampler of the pixel box.
    pub sampler: MrSampler,
    /// Scale from force density to ARFI phase (rad·m³/N).
    pub amplitude: f64,
    /// Real and imaginary parts of `B`, samples x elements (Pa per unit drive).
    pub(crate) re: Array2<f32>,
    pub(crate) im: Array2<f32>,
    /// The views (W, shift) the window reaches for ([`FieldBasis::build`]; [`Nuisance::views`]).
    reach: Nuisance,
}

impl FieldBasis {
    /// Marches every element's field (steering phase, unit drive) in batches and keeps the
    /// samples that pixels `u x v` depend on, also with the views `reach` fits: another
    /// broadening width (up to [`crate::inverse::nuisance::width_reach`]) and a registration
    /// shift (up to [`crate::inverse::nuisance::SHIFT_REACH_MM`]); see
    /// [`Nuisance::window_width`]. `progress(done, total)` is called after each batch; `cancel`,
    /// when set by another thread, ends the build before the next batch
    /// ([`HasError::Interrupted`]).
    pub fn build(
        sim: &Simulation,
        u: Range<usize>,
        v: Range<usize>,
        reach: &Nuisance,
        progress: Option<&(dyn Fn(usize, usize) + Sync)>,
        cancel: Option<&AtomicBool>,
    ) -> Result<Self> {
        let full = sim.sampler()?;
        let reach = reach.views();
        let sampler = if reach.view() {
            let w = full.broadening.width;
            full.with_broadening(reach.window_width(w))?.restrict(u, v)?.with_view([w; 2], [0.0; 2])?
        } else {
            full.restrict(u, v)?
        };
        let n = sim.n_elements();
        let s_len = sampler.window.len();
        // Kept in single precision: marched in it too where the march is one-way, with the
        // plan's steps to the window in single precision besides the basis.
        let window = &sampler.window;
        let last = window.planes.end - 1;
        let steps_bytes = if sim.reflections { None } else { sim.plan.single_precision_bytes(last) };
        memory::check(
            || format!("a field basis of {s_len} samples x {n} elements"),
            (s_len * n) as u64 * 8 + steps_bytes.unwrap_or(0),
            "estimate fewer groups, or give the MR slice a smaller field of view or matrix",
        )?;
        let spec = crate::physics::propagation::RecordSpec {
            window: Some(sampler.window.clone()),
            reflections: sim.reflections,
            ..Default::default()
        };
        let mut re = Array2::<f32>::zeros((s_len, n));
        let mut im = Array2::<f32>::zeros((s_len, n));
        let single_plan = steps_bytes.and_then(|_| sim.plan.single_precision(last));
        for start in (0..n).step_by(BATCH) {
            if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
                return Err(HasError::Interrupted);
            }
            let end = (start + BATCH).min(n);
            let sources = (start..end)
                .map(|e| {
                    let mut drive = vec![C64::new(0.0, 0.0); n];
                    drive[e] = sim.drive(e, 0.0);
                    sim.source.field(&drive)
                })
                .collect::<Result<Vec<_>>>()?;
            let windows: Vec<Vec<C32>> = match &single_plan {
                Some(plan) => plan.window_batch(&sources, window),
                None => sim.plan.propagate_batch(&sources, &spec)?.iter().map(|r| single(&r.window)).collect(),
            };
            for (k, w) in windows.iter().enumerate() {
                for (s, p) in w.iter().enumerate() {
                    re[[s, start + k]] = p.re;
                    im[[s, start + k]] = p.im;
                }
            }
            if let Some(f) = progress {
                f(end, n);
            }
        }
        Ok(FieldBasis { sampler, amplitude: sim.amplitude()?, re, im, reach })
    }

    /// Number of elements (columns of `B`).
    pub fn n_elements(&self) -> usize {
        self.re.ncols()
    }

    /// Number of window samples (rows of `B`).
    pub fn n_samples(&self) -> usize {
        self.re.nrows()
    }

    /// Bytes held by the basis.
    pub fn bytes(&self) -> usize {
        2 * self.re.len() * std::mem::size_of::<f32>()
    }

    /// `f` over the fixed blocks of [`BLOCK`] sample rows, in parallel, results in block order.
    fn map_blocks<T: Send>(&self, f: impl Fn(Range<usize>) -> T + Sync) -> Vec<T> {
        let n = self.n_samples();
        (0..n).step_by(BLOCK).collect::<Vec<_>>().into_par_iter().map(|a| f(a..(a + BLOCK).min(n))).collect()
    }

    /// Fields `P = B·V` for drive columns `V` (elements x images): real and imaginary parts,
    /// samples x images.
    pub(crate) fn fields(&self, vr: &Array2<f32>, vi: &Array2<f32>) -> (Array2<f32>, Array2<f32>) {
        let blocks = self.map_blocks(|rows| {
            let (br, bi) = (self.re.slice(s![rows.clone(), ..]), self.im.slice(s![rows, ..]));
            (br.dot(vr) - bi.dot(vi), br.dot(vi) + bi.dot(vr))
        });
        let k = vr.ncols();
        let mut pr = Array2::zeros((self.n_samples(), k));
        let mut pi = Array2::zeros((self.n_samples(), k));
        for (n, (r, i)) in blocks.into_iter().enumerate() {
            let a = n * BLOCK;
            pr.slice_mut(s![a..a + r.nrows(), ..]).assign(&r);
            pi.slice_mut(s![a..a + i.nrows(), ..]).assign(&i);
        }
        (pr, pi)
    }

    /// `C = Bᵀ·H` for sample columns `H` (samples x images), summed block by block in order.
    fn back_project(&self, hr: &Array2<f32>, hi: &Array2<f32>) -> (Array2<f64>, Array2<f64>) {
        let blocks = self.map_blocks(|rows| {
            let (br, bi) = (self.re.slice(s![rows.clone(), ..]), self.im.slice(s![rows.clone(), ..]));
            let (h_r, h_i) = (hr.slice(s![rows.clone(), ..]), hi.slice(s![rows, ..]));
            (br.t().dot(&h_r) - bi.t().dot(&h_i), br.t().dot(&h_i) + bi.t().dot(&h_r))
        });
        let k = hr.ncols();
        let mut cr = Array2::<f64>::zeros((self.n_elements(), k));
        let mut ci = Array2::<f64>::zeros((self.n_elements(), k));
        for (r, i) in blocks {
            cr += &r.mapv(f64::from);
            ci += &i.mapv(f64::from);
        }
        (cr, ci)
    }

    /// Drive columns `exp(i·(phases + offset_k))` for each offset.
    pub(crate) fn drives(phases: &[f64], offsets: &[&[f64]]) -> (Array2<f32>, Array2<f32>) {
        let (g, k) = (phases.len(), offsets.len());
        let mut vr = Array2::zeros((g, k));
        let mut vi = Array2::zeros((g, k));
        for (c, off) in offsets.iter().enumerate() {
            for e in 0..g {
                let (s, co) = (phases[e] + off[e]).sin_cos();
                vr[[e, c]] = co as f32;
                vi[[e, c]] = s as f32;
            }
        }
        (vr, vi)
    }

    /// The image on the box for per-element phases (rad) added to the steering.
    pub fn image(&self, phases: &[f64]) -> Result<Array2<f64>> {
        self.image_with(&self.sampler, phases, &vec![0.0; self.n_elements()])
    }

    /// The image on the box formed with `sampler` for per-element `phases` with known phases
    /// `offset` added.
    fn image_with(&self, sampler: &MrSampler, phases: &[f64], offset: &[f64]) -> Result<Array2<f64>> {
        for (name, values) in [("phases", phases), ("offset", offset)] {
            if values.len() != self.n_elements() {
                return Err(HasError::invalid(name, format!("has {} values for {} elements", values.len(), self.n_elements())));
            }
        }
        let (vr, vi) = Self::drives(phases, &[offset]);
        let (pr, pi) = self.fields(&vr, &vi);
        Ok(sampler.apply(&power_columns(&pr, &pi)[0])? * self.amplitude)
    }
}

/// `|p|²` of each column of fields `P` (real and imaginary parts, samples x columns).
fn power_columns(pr: &Array2<f32>, pi: &Array2<f32>) -> Vec<Vec<f64>> {
    (0..pr.ncols())
        .map(|k| pr.column(k).iter().zip(pi.column(k).iter()).map(|(a, b)| f64::from(*a).powi(2) + f64::from(*b).powi(2)).collect())
        .collect()
}

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
/// parameters ([`crate::inverse::nuisance`]): the model value of pixel `i` of image `k` is
/// `s·d_k,i + b_k·(1, u_i, v_i)` with the scale `s` and the background planes `b_k` solved by
/// least squares for each `phases`, and `d` formed with the cost's view (W, shift).
#[derive(Debug, Clone)]
pub struct ElementCost {
    /// The fields of every element in the MR window.
    pub basis: Arc<FieldBasis>,
    /// One term per measured image.
    pub terms: Vec<ElementTerm>,
    /// Fit one least-squares amplitude scale for all images (see `HybridCost::fit_scale`).
    pub fit_scale: bool,
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
        Ok(ElementCost { basis, terms, fit_scale: false, fit_background: false, sampler, coords })
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
            let s = if self.fit_scale {
                crate::inverse::cost::least_squares_scale(model.iter().zip(&self.terms).map(|(d, t)| (d.as_slice(), t.measured.as_slice())))
            } else {
                1.0
            };
            LinearNuisance { scale: s, background: vec![[0.0; 3]; k] }
        };
        if !self.fit_background {
            return scale_only();
        }
        let o = usize::from(self.fit_scale);
        let m = o + 3 * k;
        let mut a = vec![vec![0.0; m + 1]; m];
        for (c, (d, t)) in model.iter().zip(&self.terms).enumerate() {
            for ((&p, &x), &y) in t.mask.iter().zip(d).zip(&t.measured) {
                let (u, v) = self.uv(p);
                let target = if self.fit_scale { y } else { y - x };
                let mut cols = [(0, 0.0); 4];
                let mut n = 0;
                if self.fit_scale {
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
                scale: if self.fit_scale { x[0] } else { 1.0 },
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
        let mut hr = Array2::<f32>::zeros((n_s, k));
        let mut hi = Array2::<f32>::zeros((n_s, k));
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
                hr[[n, c]] = (hv * f64::from(pr[[n, c]])) as f32;
                hi[[n, c]] = (-hv * f64::from(pi[[n, c]])) as f32;
            }
        }
        let (cr, ci) = b.back_project(&hr, &hi);
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

/// The per-element cost of `measurements` and the background noise level (rad).
#[derive(Debug, Clone)]
pub struct ElementModel {
    /// The per-element cost of paper Eq. 4.
    pub cost: ElementCost,
    /// Noise standard deviation of the image backgrounds (rad).
    pub noise: f64,
}

/// Builds the per-element cost of `measurements` as [`crate::inverse::cost::build_model`] does for groups
/// (same masks, pixel box and noise level), on one basis: the known phases of each image (per
/// element or per group) only offset its drives, so no image needs a march of its own.
pub fn build_element_model(
    sim: &Simulation,
    measurements: &[Measurement],
    mask_fraction: f64,
    margin: usize,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
    cancel: Option<&AtomicBool>,
) -> Result<ElementModel> {
    BasisCache::default().element_model(sim, measurements, mask_fraction, margin, &Nuisance::default(), progress, cancel)
}

/// Keeps the element basis of the last per-element model built through it, for the next on the
/// same simulation: the basis depends only on the simulation and the pixel box, so another
/// estimate from the same images (another prior, seed or limit) skips the marching (about 15 s
/// for 1024 elements). Holds at most one basis ([`FieldBasis::bytes`]); a cache must only ever
/// see one simulation.
#[derive(Debug, Default)]
pub struct BasisCache(Mutex<Option<Arc<FieldBasis>>>);

impl BasisCache {
    /// The kept basis when it covers pixels `u x v` with the same window (the same views in
    /// `reach`), else a new one (built as [`FieldBasis::build`], then kept in place of the old
    /// one).
    pub fn basis(
        &self,
        sim: &Simulation,
        u: Range<usize>,
        v: Range<usize>,
        reach: &Nuisance,
        progress: Option<&(dyn Fn(usize, usize) + Sync)>,
        cancel: Option<&AtomicBool>,
    ) -> Result<Arc<FieldBasis>> {
        let mut kept = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let fits = |b: &&Arc<FieldBasis>| {
            b.sampler.pixels == [u.clone(), v.clone()] && b.n_elements() == sim.n_elements() && b.reach == reach.views()
        };
        if let Some(b) = kept.as_ref().filter(fits) {
            return Ok(Arc::clone(b));
        }
        // Release the old basis before building the next: at most one in memory.
        *kept = None;
        let b = Arc::new(FieldBasis::build(sim, u, v, reach, progress, cancel)?);
        *kept = Some(Arc::clone(&b));
        Ok(b)
    }

    /// [`build_element_model`] on the kept basis when it covers the images' pixel box, set up
    /// to fit `nuisance`: a fitted amplitude or background plane is fitted on every pixel of the
    /// box (its margin at least [`BACKGROUND_MARGIN`] pixels; see [`fits_whole_box`]), and W or
    /// the shift need a wider window ([`Nuisance::window_width`]).
    #[allow(clippy::too_many_arguments)]
    pub fn element_model(
        &self,
        sim: &Simulation,
        measurements: &[Measurement],
        mask_fraction: f64,
        margin: usize,
        nuisance: &Nuisance,
        progress: Option<&(dyn Fn(usize, usize) + Sync)>,
        cancel: Option<&AtomicBool>,
    ) -> Result<ElementModel> {
        let whole_box = fits_whole_box(nuisance);
        let margin = if whole_box { margin.max(BACKGROUND_MARGIN) } else { margin };
        let crate::inverse::cost::MaskedBox { masks, pixels: [u, v], noise } = masks_and_box(sim, measurements, mask_fraction, margin)?;
        let mut terms = Vec::with_capacity(measurements.len());
        for (k, (meas, mask)) in measurements.iter().zip(&masks).enumerate() {
            let offset = known_per_element(sim, &meas.known)
                .map_err(|e| HasError::invalid(format!("image[{k}].applied_phases_rad"), e.to_string()))?;
            let local = |&(i, j): &(usize, usize)| (i - u.start) * v.len() + (j - v.start);
            let box_pixels;
            let pixels = if whole_box {
                box_pixels = imaged_pixels(&meas.image, u.clone(), v.clone());
                &box_pixels
            } else {
                mask
            };
            terms.push(ElementTerm {
                mask: pixels.iter().map(local).collect(),
                measured: pixels.iter().map(|&ij| meas.image[ij]).collect(),
                offset,
            });
        }
        let basis = self.basis(sim, u, v, nuisance, progress, cancel)?;
        let mut cost = ElementCost::new(basis, terms)?;
        cost.fit_scale = nuisance.amplitude;
        cost.fit_background = nuisance.background_phase;
        Ok(ElementModel { cost, noise })
    }
}

/// Whether the per-element cost of `nuisance` is fitted on every pixel of the box rather than on
/// each image's focal-zone mask.
///
/// The mask keeps the pixels of the measured image above a level connected to its peak, so in its
/// faint outskirts it keeps the pixels whose noise happens to be positive: there the measured
/// values are biased upwards (by about `sigma` where the signal is below the noise). A model
/// image with a known scale pays for that bias at the focus; with a fitted amplitude it does not,
/// and the bias favours model beams that are weaker and broader (phases that defocus the beam,
/// the scale raised to match the peak), which a smooth prior lets the estimate reach cheaply
/// (`tests/prior.rs`). A fitted background plane needs the pixels outside the focal zone as well.
/// Pixels without signal (NaN) are left out either way.
pub fn fits_whole_box(nuisance: &Nuisance) -> bool {
    nuisance.amplitude || nuisance.background_phase
}

/// Known phases per element from values per element, per group of `sim`, or per default group
/// of the array (16 groups of contiguous element numbers, the paper's; empty = none).
pub fn known_per_element(sim: &Simulation, known: &[f64]) -> Result<Vec<f64>> {
    let n = sim.n_elements();
    if known.is_empty() {
        return Ok(vec![0.0; n]);
    }
    let default = sim.transducer.default_groups();
    let n_default = default.iter().max().map_or(0, |m| m + 1);
    if known.len() == n_default && known.len() != sim.n_groups && known.len() != n {
        crate::error::require_finite("phases", known)?;
        return Ok(default.iter().map(|&g| known[g]).collect());
    }
    sim.element_phases(known).map_err(|_| {
        HasError::invalid(
            "phases",
            format!(
                "has {} values; expected {n} (one per element), {} (one per group) or {n_default} (one per default group)",
                known.len(),
                sim.n_groups
            ),
        )
    })
}
