//! The per-element field basis for estimation with many phases (e.g. one per element of a
//! 1024-element array, the paper's clinical case).
//!
//! For G in the thousands the per-pixel G x G kernels of [`crate::inverse::cost::ArfiKernel`] are too
//! large. Instead keep the field of every element on the window samples that the box of pixels
//! depends on, `B` (S samples x G elements), and per image with drives `v_k`:
//! `p = B·v_k`, `d = A·S(|p|²)` (the sampler's linear map `S`, amplitude `A`). The gradient is
//! the adjoint: with `h = A·Sᵀ(∂J/∂d)`, `∂J/∂phi_e = -2·Im(v_e·(Bᵀ(h ∘ conj p))_e)`.
//!
//! Through soft tissue and water `B` is marched on a coarser grid than the simulation's
//! ([`basis_grid`], [`Simulation::on_grid`]): its images are that grid's.
//!
//! `B` is stored in single precision as real and imaginary parts; the products for all images at
//! once run over fixed blocks of samples (deterministic for any number of threads) in loops
//! written for their shape (`products`). The cost itself is [`ElementCost`].
//!
//! Fitted with the phases on this basis: the nuisance parameters of the image ([`nuisance`]) and
//! the MR view, broadening width and registration shift ([`view_fit`]).

mod cost;
pub mod nuisance;
mod products;
pub mod view_fit;

pub use cost::{ElementCost, ElementTerm, LinearNuisance};

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::grouping;
use crate::inverse::cost::{imaged_pixels, masks_and_box, Measurement};
use crate::inverse::element::nuisance::Nuisance;
use crate::memory;
use crate::physics::grid::Grid;
use crate::physics::mr::MrSampler;
use crate::physics::propagation::single;
use crate::simulation::{coarser_grid, Simulation};
use ndarray::Array2;
use num_complex::{Complex32 as C32, Complex64 as C64};
use products::{Column, Split};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::{Arc, Mutex};

/// Pixels around the masks whose background a background plane is fitted on.
pub const BACKGROUND_MARGIN: usize = 4;
/// Samples per block of the matrix products.
const BLOCK: usize = 2048;
/// Element fields marched per batch while building.
const BATCH: usize = 32;

/// The lateral spacing of an element basis's marches at most, in shortest wavelengths (see
/// [`basis_grid`]).
pub const BASIS_SPACING_WAVELENGTHS: f64 = 0.375;

/// The lateral spacing of an element basis's marches at most, in MR pixels (the smaller side; see
/// [`basis_grid`]).
pub const BASIS_SPACING_PIXELS: f64 = 0.75;

/// The grid an element basis of `sim` is marched on, where not the simulation's own: a spacing of
/// at most [`BASIS_SPACING_WAVELENGTHS`] of the shortest wavelength and [`BASIS_SPACING_PIXELS`]
/// of an MR pixel ([`coarser_grid`]: the simulation's lateral period), when that is coarser (by
/// more than 5 %) and no layer reverberates (soft tissue and water, e.g. the model of a head
/// without its bone). Such a grid samples every propagating wave (its Nyquist wavenumber at least
/// 4/3 of the largest) and the force finer than the pixels it is averaged
/// over; the steps to the window cost a third of the λ/4 grid's, and the window holds fewer
/// samples. Its images differ from the simulation's own by about 1 % of their peak at 650 kHz,
/// well below an MR-ARFI image's noise (`tests/suite/element_basis.rs`); where the wavelength alone
/// would allow a spacing near the pixel's (220 kHz: 2.6 mm against 1.4 mm pixels) they differ
/// by 20 %, hence the pixel's bound. Through reverberating bone the simulation's grid is kept.
pub fn basis_grid(sim: &Simulation) -> Result<Option<Grid>> {
    let pixel = sim.mr.pixel_size();
    let spacing =
        (BASIS_SPACING_WAVELENGTHS * sim.medium.min_sound_speed() / sim.frequency).min(BASIS_SPACING_PIXELS * pixel[0].min(pixel[1]));
    if sim.plan.reverberation().is_some() || sim.reflections || spacing <= 1.05 * sim.grid.dx.max(sim.grid.dy) {
        return Ok(None);
    }
    coarser_grid(&sim.grid, sim.focus[2], spacing).map(Some)
}

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
    /// Marches every element's field (steering phase, unit drive) in batches, on
    /// [`basis_grid`]'s grid where it gives one, and keeps the
    /// samples that pixels `u x v` depend on, also with the views `reach` fits: another
    /// broadening width (up to [`crate::inverse::element::nuisance::width_reach`]) and a registration
    /// shift (up to [`crate::inverse::element::nuisance::SHIFT_REACH_MM`]); see
    /// [`Nuisance::window_width`]. `control` reports `(done, total)` elements after each batch and,
    /// once cancelled, ends the build before the next batch ([`HasError::Interrupted`]).
    pub fn build(sim: &Simulation, u: Range<usize>, v: Range<usize>, reach: &Nuisance, control: Control<'_>) -> Result<Self> {
        let coarser = basis_grid(sim)?.map(|g| sim.on_grid(g)).transpose()?;
        let sim = coarser.as_ref().unwrap_or(sim);
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
        // Kept in single precision: marched in it too (the round trips of a reverberating layer
        // included), with the plan's steps to the window in single precision besides the basis.
        let window = &sampler.window;
        let last = window.planes.end - 1;
        let steps_bytes = sim.single_precision_bytes(last);
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
            control.check()?;
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
            control.report(end, n);
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

    /// `B` as split row-major parts.
    fn split(&self) -> Split<'_> {
        // Built in standard layout by `FieldBasis::build` and never sliced.
        fn part(a: &Array2<f32>) -> &[f32] {
            a.as_slice().expect("the basis is stored row-major")
        }
        Split { re: part(&self.re), im: part(&self.im), cols: self.n_elements() }
    }

    /// Fields `P = B·V` for drive columns `V` (elements x images): real and imaginary parts,
    /// samples x images.
    pub(crate) fn fields(&self, vr: &Array2<f32>, vi: &Array2<f32>) -> (Array2<f32>, Array2<f32>) {
        let k = vr.ncols();
        let columns: Vec<Column> = (0..k).map(|c| Column::new(vr.column(c).to_vec(), vi.column(c).to_vec())).collect();
        let b = self.split();
        let blocks = self.map_blocks(|rows| products::fields(b, rows, &columns));
        let mut pr = Array2::zeros((self.n_samples(), k));
        let mut pi = Array2::zeros((self.n_samples(), k));
        for (p, (r, i)) in blocks.iter().flatten().zip(pr.iter_mut().zip(pi.iter_mut())) {
            (*r, *i) = (p.re, p.im);
        }
        (pr, pi)
    }

    /// `C = Bᵀ·H` for sample columns `H` (row-major, samples x `k` images), summed block by block
    /// in order.
    fn back_project(&self, h: &[C32], k: usize) -> (Array2<f64>, Array2<f64>) {
        let b = self.split();
        let blocks = self.map_blocks(|rows| products::back_project(b, rows.clone(), &h[rows.start * k..rows.end * k], k));
        let mut cr = Array2::<f64>::zeros((self.n_elements(), k));
        let mut ci = Array2::<f64>::zeros((self.n_elements(), k));
        for block in blocks {
            for (c, (r, i)) in block.into_iter().enumerate() {
                cr.column_mut(c).zip_mut_with(&ndarray::ArrayView1::from(&r), |a, &b| *a += f64::from(b));
                ci.column_mut(c).zip_mut_with(&ndarray::ArrayView1::from(&i), |a, &b| *a += f64::from(b));
            }
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
    control: Control<'_>,
) -> Result<ElementModel> {
    BasisCache::default().element_model(sim, measurements, mask_fraction, margin, &Nuisance::default(), control)
}

/// Keeps the element basis of the last per-element model built through it, for the next on the
/// same simulation: the basis depends only on the simulation and the pixel box, so another
/// estimate from the same images (another prior, seed or limit) skips the marching (one march
/// per element). Holds at most one basis ([`FieldBasis::bytes`]); a cache must only ever
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
        control: Control<'_>,
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
        let b = Arc::new(FieldBasis::build(sim, u, v, reach, control)?);
        *kept = Some(Arc::clone(&b));
        Ok(b)
    }

    /// [`build_element_model`] on the kept basis when it covers the images' pixel box, set up
    /// to fit `nuisance`: a fitted amplitude or background plane is fitted on every pixel of the
    /// box (its margin at least [`BACKGROUND_MARGIN`] pixels; see [`fits_whole_box`]), and W or
    /// the shift need a wider window ([`Nuisance::window_width`]).
    pub fn element_model(
        &self,
        sim: &Simulation,
        measurements: &[Measurement],
        mask_fraction: f64,
        margin: usize,
        nuisance: &Nuisance,
        control: Control<'_>,
    ) -> Result<ElementModel> {
        let whole_box = fits_whole_box(nuisance);
        let margin = if whole_box { margin.max(BACKGROUND_MARGIN) } else { margin };
        let crate::inverse::cost::MaskedBox { masks, pixels: [u, v], noise } = masks_and_box(sim, measurements, mask_fraction, margin)?;
        let mut terms = Vec::with_capacity(measurements.len());
        for (k, (meas, mask)) in measurements.iter().zip(&masks).enumerate() {
            let offset = image_known_per_element(sim, k, &meas.known)?;
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
        let basis = self.basis(sim, u, v, nuisance, control)?;
        let mut cost = ElementCost::new(basis, terms)?;
        cost.fit_amplitude = nuisance.amplitude;
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
/// (`tests/suite/prior.rs`). A fitted background plane needs the pixels outside the focal zone as well.
/// Pixels without signal (NaN) are left out either way.
pub fn fits_whole_box(nuisance: &Nuisance) -> bool {
    nuisance.amplitude || nuisance.background_phase
}

/// [`known_per_element`] of image `k`'s known phases, an error naming that image's
/// `applied_phases_rad`.
pub fn image_known_per_element(sim: &Simulation, k: usize, known: &[f64]) -> Result<Vec<f64>> {
    known_per_element(sim, known).map_err(|e| e.naming(&format!("image[{k}].applied_phases_rad")))
}

/// Known phases per element from values per element, per group of `sim`, or per default group
/// of the array (16 groups of contiguous element numbers, the paper's; empty = none).
pub fn known_per_element(sim: &Simulation, known: &[f64]) -> Result<Vec<f64>> {
    grouping::known_per_element("phases", known, &sim.groups, sim.n_groups, &sim.transducer.default_groups())
}
