//! The coefficient of a prediction's error mode from MR-ARFI images, fitted on a model that
//! holds what the mode linearises: the bone-speed mode of a CT prediction
//! ([`crate::prediction::bone_speed_sensitivity`]) on the head with the CT's bone.
//!
//! The estimation's model of a head reads its bone as soft tissue: its focal spot is not shaped
//! by a skull, and a per-element fit that may move along the mode reshapes the spot with it
//! (on a good prediction it moved twice the true bone-speed error). Here the phases stay the
//! prediction's and only the mode's coefficient `c` and one amplitude scale `a` are fitted, on the
//! model through the CT's bone driven with the reference steering (the prediction is what that
//! model already holds): image `k` is simulated with the added phases `c·m + known_k` and
//!
//! `J(c) = min_a Σ_k Σ_pixels (a·model_k(c) − measured_k)² / σ² + c²`
//!
//! over the imaged pixels of the estimation's pixel box (σ the images' background noise; `c`
//! standard normal a priori, so `J` is minus twice the log posterior). `J` is evaluated at
//! coefficients one apart (one march per image each, all in one batch) until a minimum lies
//! inside, then at the vertices of successive parabolas through the best and its neighbours,
//! until a step is short against the posterior's spread.

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::inverse::cost::{imaged_pixels, masks_and_box, Measurement};
use crate::inverse::element::{image_known_per_element, BACKGROUND_MARGIN};
use crate::memory;
use crate::numeric;
use crate::physics::mr::MrSampler;
use crate::physics::propagation::{SinglePlan, Window};
use crate::simulation::Simulation;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, Ordering};

/// The coefficients a fit starts from (the mode's units: one standard deviation each).
const START: [f64; 3] = [-1.0, 0.0, 1.0];
/// How far out the search for an inner minimum goes (standard deviations of the prior).
const REACH: f64 = 3.0;
/// Parabolic steps at most once an inner minimum is bracketed.
const REFINEMENTS: usize = 4;
/// A parabolic step shorter than this fraction of the posterior's standard deviation ends the
/// search: the coefficient is then known to well within its own uncertainty.
const STEP_OF_SPREAD: f64 = 0.25;
/// The smallest noise level (rad) the cost divides by: noise-free images leave the prior
/// negligible rather than the cost undefined.
const MIN_NOISE: f64 = 1e-6;

/// A mode's coefficient fitted to images ([`fit_mode`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ModeFit {
    /// The fitted coefficient `c` (the mode's units; standard normal a priori).
    pub coefficient: f64,
    /// Its posterior standard deviation, from the parabola's curvature (`J` is minus twice the
    /// log posterior: `J ≈ J(ĉ) + (c − ĉ)²/std²`).
    pub std: f64,
    /// The fitted amplitude scale (the images' amplitude over the model's) at `c`.
    pub scale: f64,
    /// `χ²` per pixel at `c`: about 1 when the model explains the images to their noise.
    pub misfit: f64,
    /// Pixels fitted (over all images).
    pub n_pixels: usize,
    /// The noise level σ (rad) the cost is normalised by.
    pub noise: f64,
    /// Each coefficient tried with its `J`, in increasing coefficient.
    pub tried: Vec<[f64; 2]>,
    /// Whether the smallest `J` lies between two coefficients tried: false when it is at the
    /// search's end (the images put the coefficient beyond ±3, three prior standard deviations),
    /// where `coefficient` is that end and `std` the prior's.
    pub bracketed: bool,
}

/// One evaluation of `J`.
#[derive(Debug, Clone, Copy)]
struct Point {
    c: f64,
    j: f64,
    scale: f64,
    chi2: f64,
    pixels: usize,
}

/// Fits the coefficient of `mode` (rad per element for a coefficient of 1) to `measurements`
/// on `sim`, the model through the CT's bone driven with the reference steering (see the module
/// docs). The pixel box is the estimation's ([`masks_and_box`] at the scenario's mask fraction,
/// [`BACKGROUND_MARGIN`] pixels around the masks); every pixel imaged in both the measured and
/// the model image counts. `control`'s cancel flag, when set by another thread, ends the fit
/// before the next coefficient ([`HasError::Interrupted`]). An error when no pixel is imaged in both, or the model
/// gives no force there.
pub fn fit_mode(sim: &Simulation, mode: &[f64], measurements: &[Measurement], control: &Control) -> Result<ModeFit> {
    let cancel = control.cancel();
    let n = sim.n_elements();
    if mode.len() != n {
        return Err(HasError::invalid("mode", format!("has {} values for {n} elements", mode.len())));
    }
    crate::error::require_finite("mode", mode)?;
    let fit = Fit { setting: Setting::new(sim, measurements)?, mode, cancel };
    fit.run()
}

/// What a fit of modes to images holds throughout: the model, the images with their known
/// per-element phases, the sampler on the pixel box and the noise the cost divides by.
pub(super) struct Setting<'a> {
    pub(super) sim: &'a Simulation,
    pub(super) measurements: &'a [Measurement],
    pub(super) known: Vec<Vec<f64>>,
    pub(super) sampler: MrSampler,
    box_pixels: [Range<usize>; 2],
    pub(super) noise: f64,
    /// The plan's steps to the window in single precision, where it marches them
    /// ([`Setting::window_fields`]).
    single: Option<SinglePlan>,
}

impl<'a> Setting<'a> {
    /// The estimation's pixel box ([`masks_and_box`] at the scenario's mask fraction,
    /// [`BACKGROUND_MARGIN`] pixels around the masks) and the images' noise there.
    pub(super) fn new(sim: &'a Simulation, measurements: &'a [Measurement]) -> Result<Self> {
        let boxed = masks_and_box(sim, measurements, sim.mask_fraction, BACKGROUND_MARGIN)?;
        let [u, v] = boxed.pixels.clone();
        let known = measurements.iter().enumerate().map(|(k, m)| image_known_per_element(sim, k, &m.known)).collect::<Result<Vec<_>>>()?;
        let sampler = sim.sampler()?.restrict(u.clone(), v.clone())?;
        let single = single_plan(sim, &sampler.window)?;
        Ok(Setting { sim, measurements, known, sampler, box_pixels: [u, v], noise: boxed.noise.max(MIN_NOISE), single })
    }

    /// The fields of `sources` (source planes) on the sampler's window: marched in single
    /// precision where the plan allows it (see [`single_plan`]), else in double.
    pub(super) fn window_fields(&self, sources: &[Vec<C64>]) -> Result<Vec<Vec<C64>>> {
        let window = &self.sampler.window;
        Ok(match &self.single {
            Some(plan) => plan
                .window_batch(sources, window)
                .into_iter()
                .map(|w| w.into_iter().map(|v| C64::new(v.re.into(), v.im.into())).collect())
                .collect(),
            None => self.sim.record_in(window, sources)?.into_iter().map(|r| r.window).collect(),
        })
    }

    /// The same with the images' noise `noise_rad` where it is known (finite, > 0) instead of
    /// the box's background floor.
    pub(super) fn with_noise(mut self, noise_rad: Option<f64>) -> Result<Self> {
        if let Some(n) = noise_rad {
            crate::error::require_positive("noise_rad", n)?;
            self.noise = n;
        }
        Ok(self)
    }

    /// The values of `images` (one per measurement, on the box: model images or their
    /// derivatives) at every pixel imaged in the measurement, image after image, with the
    /// measured value: `(model, measured)`, NaN model values included.
    pub(super) fn pairs(&self, images: &[&Array2<f64>]) -> Vec<(f64, f64)> {
        let [u, v] = &self.box_pixels;
        self.measurements
            .iter()
            .zip(images)
            .flat_map(|(meas, model)| {
                imaged_pixels(&meas.image, u.clone(), v.clone())
                    .into_iter()
                    .map(move |(i, j)| (model[[i - u.start, j - v.start]], meas.image[[i, j]]))
            })
            .collect()
    }

    /// An error when another thread asked the fit to end ([`HasError::Interrupted`]).
    pub(super) fn cancelled(cancel: Option<&AtomicBool>) -> Result<()> {
        if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return Err(HasError::Interrupted);
        }
        Ok(())
    }
}

/// `sim`'s plan to the last plane of `window` in single precision, or `None` where the
/// simulation marches reflections back (not in a single-precision plan); an error where the
/// memory for it is lacking (as for an element basis: the precision does not depend on the
/// memory free). A fit's model images come from a few marches through the skull (reverberation
/// included) for every coefficient tried: single precision halves their time, and rounds each
/// field to a few 1e-6 of its peak ([`SinglePlan`]), far below an MR-ARFI image's noise (about
/// 3 % of the focal phase).
fn single_plan(sim: &Simulation, window: &Window) -> Result<Option<SinglePlan>> {
    let Some(last) = window.planes.end.checked_sub(1) else { return Ok(None) };
    let Some(bytes) = sim.single_precision_bytes(last) else { return Ok(None) };
    memory::check(
        || format!("the HAS plan's steps to plane {last} in single precision"),
        bytes,
        "give the MR slice a smaller field of view, or the scenario a coarser grid",
    )?;
    Ok(sim.plan.single_precision(last))
}

/// What one fit holds while it searches.
struct Fit<'a> {
    setting: Setting<'a>,
    mode: &'a [f64],
    cancel: Option<&'a AtomicBool>,
}

impl Fit<'_> {
    fn run(&self) -> Result<ModeFit> {
        let mut tried = self.evaluate(&START)?;
        loop {
            let best = argmin(&tried);
            let next = if best == 0 && tried[0].c > -REACH {
                tried[0].c - 1.0
            } else if best == tried.len() - 1 && tried[best].c < REACH {
                tried[best].c + 1.0
            } else {
                break;
            };
            tried.extend(self.evaluate(&[next])?);
            tried.sort_by(|a, b| a.c.total_cmp(&b.c));
        }
        // Successive parabolic steps within the bracket, until a step is small against the
        // posterior's spread.
        for _ in 0..REFINEMENTS {
            let best = argmin(&tried);
            let (Some(vertex), Some(a)) = parabola(&tried, best) else { break };
            if (vertex - tried[best].c).abs() < (STEP_OF_SPREAD / a.sqrt()).max(1e-3) {
                break;
            }
            tried.extend(self.evaluate(&[vertex])?);
            tried.sort_by(|a, b| a.c.total_cmp(&b.c));
        }
        let best = argmin(&tried);
        let chosen = tried[best];
        let bracketed = best > 0 && best + 1 < tried.len();
        Ok(ModeFit {
            coefficient: chosen.c,
            std: parabola(&tried, best).1.map_or(1.0, |a| 1.0 / a.sqrt()),
            bracketed,
            scale: chosen.scale,
            misfit: chosen.chi2 / chosen.pixels.max(1) as f64,
            n_pixels: chosen.pixels,
            noise: self.setting.noise,
            tried: tried.iter().map(|p| [p.c, p.j]).collect(),
        })
    }

    /// `J` at each coefficient in `cs`: every image of every coefficient marched in one batch.
    fn evaluate(&self, cs: &[f64]) -> Result<Vec<Point>> {
        Setting::cancelled(self.cancel)?;
        let s = &self.setting;
        let added: Vec<Vec<f64>> =
            cs.iter().flat_map(|&c| s.known.iter().map(move |k| k.iter().zip(self.mode).map(|(k, m)| k + c * m).collect())).collect();
        let windows = s.window_fields(&s.sim.source_fields(&added)?)?;
        let amplitude = s.sim.amplitude()?;
        let images = windows.iter().map(|w| s.sampler.arfi_image(w, amplitude)).collect::<Result<Vec<_>>>()?;
        cs.iter().zip(images.chunks(s.measurements.len())).map(|(&c, models)| self.point(c, models)).collect()
    }

    /// `J` at `c` from its model images (one per measurement, on the box).
    fn point(&self, c: f64, models: &[Array2<f64>]) -> Result<Point> {
        let pairs: Vec<(f64, f64)> =
            self.setting.pairs(&models.iter().collect::<Vec<_>>()).into_iter().filter(|(m, _)| m.is_finite()).collect();
        let (md, mm) = pairs.iter().fold((0.0, 0.0), |(md, mm), (m, d)| (md + m * d, mm + m * m));
        if !(mm > 0.0) {
            return Err(HasError::invalid(
                "images",
                format!("have no pixel imaged in both them and the model (with the mode at {c}) where the model gives force"),
            ));
        }
        let scale = (md / mm).max(0.0);
        let chi2 = pairs.iter().map(|(m, d)| (scale * m - d).powi(2)).sum::<f64>() / self.setting.noise.powi(2);
        Ok(Point { c, j: chi2 + c * c, scale, chi2, pixels: pairs.len() })
    }
}

/// The index of the smallest `J`.
fn argmin(points: &[Point]) -> usize {
    (0..points.len()).min_by(|&a, &b| points[a].j.total_cmp(&points[b].j)).unwrap_or(0)
}

/// The vertex of the parabola through point `i` and its neighbours (sorted by `c`), kept within
/// them, and the parabola's curvature `a` (`J ≈ a·(c − vertex)² + …`), when it opens upwards.
fn parabola(points: &[Point], i: usize) -> (Option<f64>, Option<f64>) {
    if i == 0 || i + 1 >= points.len() {
        return (None, None);
    }
    let [p0, p1, p2] = [points[i - 1], points[i], points[i + 1]];
    match numeric::parabola([(p0.c, p0.j), (p1.c, p1.j), (p2.c, p2.j)]) {
        Some(p) if p.curvature > 0.0 => (Some(p.vertex.clamp(p0.c, p2.c)), Some(p.curvature)),
        _ => (None, None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(c: f64, j: f64) -> Point {
        Point { c, j, scale: 1.0, chi2: j, pixels: 1 }
    }

    #[test]
    fn the_parabolas_vertex_and_curvature_are_exact_for_a_parabola() {
        // J = 4·(c − 0.3)² + 7 sampled at −1, 0, 1.5: vertex 0.3, curvature 4 (std 0.5).
        let j = |c: f64| 4.0 * (c - 0.3f64).powi(2) + 7.0;
        let pts = [point(-1.0, j(-1.0)), point(0.0, j(0.0)), point(1.5, j(1.5))];
        let (vertex, a) = parabola(&pts, 1);
        assert!((vertex.unwrap() - 0.3).abs() < 1e-12);
        assert!((a.unwrap() - 4.0).abs() < 1e-12);
        // Opening downwards or at the edge: no vertex.
        assert_eq!(parabola(&[point(-1.0, 0.0), point(0.0, 1.0), point(1.0, 0.0)], 1), (None, None));
        assert_eq!(parabola(&pts, 0), (None, None));
    }
}
