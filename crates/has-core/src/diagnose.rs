//! The model-discrepancy workflow (SPEC §7): find where the model and a measured MR-ARFI image
//! disagree, name the missing effect, add it to the model, and repeat until what is left is noise.
//!
//! Each candidate effect is a parametrised extension of the forward model. At each step every
//! candidate not yet in the model is fitted (Nelder–Mead, jointly with the parameters of the
//! effects already added, warm-started from them) on the whole image, and scored with the
//! Bayesian information criterion for Gaussian noise of known `sigma` (estimated from the image
//! background): `evidence = (J_before - J_after) / sigma² - k·ln(n)` for `k` added parameters and
//! `n` pixels. The best candidate is added when its evidence is positive. With noise only, a
//! one-parameter effect passes by chance with probability `P(chi²_1 > ln n)`, 0.2 % for a
//! 128 x 96 image.
//!
//! This module holds the effects that act after the pressure field (the image-space part of the
//! model) and the slice: `amplitude`, `broadening`, `registration_shift`, `background_phase` and
//! `slice_offset`. They share one march of the model's field, recorded on the MR window extended
//! along the slice normal.

use crate::arfi::MrSampler;
use crate::cost::{masks_and_box, Measurement};
use crate::error::{HasError, Result};
use crate::simulation::Simulation;
use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use ndarray::Array2;

/// Cost returned in place of a non-finite one.
const PENALTY: f64 = 1e300;

/// A candidate effect of the SPEC §7 library.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    /// A scale on the force-to-ARFI-phase amplitude.
    Amplitude,
    /// The width W of the Gaussian broadening (paper Eq. 2).
    Broadening,
    /// An in-plane offset of the image against the model.
    RegistrationShift,
    /// A constant plus a linear phase ramp across the image.
    BackgroundPhase,
    /// An offset of the imaged slice from the model's along its normal.
    SliceOffset,
}

impl Effect {
    /// Every effect this module fits, in a fixed order (ties go to the earlier).
    pub const ALL: [Effect; 5] =
        [Effect::Amplitude, Effect::Broadening, Effect::RegistrationShift, Effect::BackgroundPhase, Effect::SliceOffset];

    /// The SPEC §7 name.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::Amplitude => "amplitude",
            Effect::Broadening => "broadening",
            Effect::RegistrationShift => "registration_shift",
            Effect::BackgroundPhase => "background_phase",
            Effect::SliceOffset => "slice_offset",
        }
    }

    /// Indices into [`View::to_vec`] of this effect's parameters.
    fn slots(&self) -> &'static [usize] {
        match self {
            Effect::Amplitude => &[0],
            Effect::Broadening => &[1],
            Effect::RegistrationShift => &[2, 3],
            Effect::BackgroundPhase => &[4, 5, 6],
            Effect::SliceOffset => &[7],
        }
    }
}

/// The image-space parameters of the model, in the units of their names.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Scale on the amplitude (1 = the model's).
    pub scale: f64,
    pub broadening_width_mm: f64,
    pub shift_mm: [f64; 2],
    /// `offset + slope_u·u + slope_v·v` (rad, rad/mm; u, v pixel-centre coordinates in mm).
    pub background_offset_rad: f64,
    pub background_slope_rad_per_mm: [f64; 2],
    /// Offset of the slice along its normal (mm), within ±[`SLICE_REACH_MM`].
    pub slice_offset_mm: f64,
}

/// The largest slice offset fitted (mm): the extra field recorded on each side of the slice.
pub const SLICE_REACH_MM: f64 = 8.0;

/// Parameter names with units, in [`View::to_vec`] order.
const NAMES: [&str; 8] =
    ["scale", "broadening_width_mm", "dx_mm", "dy_mm", "offset_rad", "slope_x_rad_per_mm", "slope_y_rad_per_mm", "dz_mm"];
/// Initial simplex steps, in [`View::to_vec`] order.
const STEPS: [f64; 8] = [0.05, 0.5, 0.5, 0.5, 0.01, 2e-4, 2e-4, 1.0];

impl View {
    fn to_vec(self) -> [f64; 8] {
        let b = self.background_slope_rad_per_mm;
        [
            self.scale,
            self.broadening_width_mm,
            self.shift_mm[0],
            self.shift_mm[1],
            self.background_offset_rad,
            b[0],
            b[1],
            self.slice_offset_mm,
        ]
    }
    fn from_vec(v: &[f64; 8]) -> Self {
        View {
            scale: v[0],
            broadening_width_mm: v[1].abs(),
            shift_mm: [v[2], v[3]],
            background_offset_rad: v[4],
            background_slope_rad_per_mm: [v[5], v[6]],
            slice_offset_mm: v[7],
        }
    }
}

/// The model image for [`View`] parameters: one recorded `|p|²` window, re-sampled.
struct Forward {
    sim: Simulation,
    /// `|p|²` on the MR window extended by [`SLICE_REACH_MM`] (plus a sample) along the normal.
    window: crate::has::Window,
    power: Vec<f64>,
    amplitude: f64,
    /// Pixel-centre coordinates along u and v (mm).
    coords: [Vec<f64>; 2],
    /// The last sampled force image and its (width, shift): scale and background changes reuse it.
    cache: std::sync::Mutex<Option<([f64; 4], Array2<f64>)>>,
}

impl Forward {
    fn new(sim: &Simulation, known: &[f64]) -> Result<Self> {
        let g = &sim.sampler.geometry;
        let window = extended_window(sim);
        let spec = crate::has::RecordSpec { window: Some(window.clone()), reflections: sim.reflections, ..Default::default() };
        let rec = sim.plan.propagate(&sim.source_field(known)?, &spec)?;
        let coords = [0, 1].map(|k| (0..g.matrix[k]).map(|i| g.pixel_center(k, i) * 1e3).collect());
        let power = rec.window.iter().map(|p| p.norm_sqr()).collect();
        Ok(Forward { sim: sim.clone(), window, power, amplitude: sim.amplitude, coords, cache: std::sync::Mutex::new(None) })
    }

    /// The sampler of the slice moved `dz_mm` along its normal, and its `|p|²` samples.
    fn slice(&self, dz_mm: f64) -> Result<(MrSampler, Vec<f64>)> {
        let s = &self.sim;
        if dz_mm == 0.0 {
            return Ok((s.sampler.clone(), self.window.extract(&self.power, &s.sampler.window)));
        }
        if !(dz_mm.abs() <= SLICE_REACH_MM) {
            return Err(HasError::invalid("dz_mm", format!("slice offsets are fitted within ±{SLICE_REACH_MM} mm")));
        }
        let mut geometry = s.sampler.geometry.clone();
        geometry.center[geometry.plane.axes()[2]] += dz_mm * 1e-3;
        let sampler = MrSampler::new(&s.grid, &s.medium, s.frequency, &geometry, s.sampler.broadening)?;
        let w = &sampler.window;
        let inside = |a: &std::ops::Range<usize>, b: &std::ops::Range<usize>| a.start >= b.start && a.end <= b.end;
        if !(inside(&w.planes, &self.window.planes) && inside(&w.rows, &self.window.rows) && inside(&w.cols, &self.window.cols)) {
            return Err(HasError::invalid("dz_mm", "the moved slice leaves the recorded field"));
        }
        let power = self.window.extract(&self.power, w);
        Ok((sampler, power))
    }

    /// The broadened, shifted force image (N/m³) for a width and shift (mm).
    fn force(&self, key: [f64; 4]) -> Result<Array2<f64>> {
        if let Ok(c) = self.cache.lock() {
            if let Some((k, img)) = c.as_ref() {
                if *k == key {
                    return Ok(img.clone());
                }
            }
        }
        let (sampler, power) = self.slice(key[3])?;
        let img = sampler.with_view(key[0] * 1e-3, [key[1] * 1e-3, key[2] * 1e-3])?.apply(&power)?;
        if let Ok(mut c) = self.cache.lock() {
            *c = Some((key, img.clone()));
        }
        Ok(img)
    }

    fn image(&self, v: &View) -> Result<Array2<f64>> {
        let mut img = self.force([v.broadening_width_mm, v.shift_mm[0], v.shift_mm[1], v.slice_offset_mm])? * (self.amplitude * v.scale);
        let b = v.background_slope_rad_per_mm;
        for ((i, j), x) in img.indexed_iter_mut() {
            *x += v.background_offset_rad + b[0] * self.coords[0][i] + b[1] * self.coords[1][j];
        }
        Ok(img)
    }

    fn cost(&self, v: &View, measured: &Array2<f64>) -> f64 {
        match self.image(v) {
            Ok(img) => img.iter().zip(measured).map(|(a, b)| (a - b).powi(2)).sum(),
            Err(_) => f64::INFINITY,
        }
    }
}

/// Settings of the workflow.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseOptions {
    /// Evidence an effect needs to be added (0 = the plain BIC).
    pub threshold: f64,
    /// Nelder–Mead iterations per candidate fit.
    pub max_iterations: usize,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions { threshold: 0.0, max_iterations: 1500 }
    }
}

/// One candidate's fit at one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub effect: Effect,
    pub cost: f64,
    pub evidence: f64,
}

/// One effect added to the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub effect: Effect,
    /// The effect's fitted parameters, named with their units.
    pub params: Vec<(&'static str, f64)>,
    pub cost_before: f64,
    pub cost_after: f64,
    pub evidence: f64,
    /// Every candidate tried at this step.
    pub candidates: Vec<Candidate>,
    /// The whole model after this step.
    pub view: View,
}

/// The outcome of [`diagnose`].
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub steps: Vec<Step>,
    /// Candidates of the last, unsuccessful round (none passed).
    pub rejected: Vec<Candidate>,
    pub cost_initial: f64,
    pub cost_final: f64,
    /// Noise standard deviation from the image background (rad).
    pub noise_floor: f64,
    pub n_pixels: usize,
    pub model_initial: Array2<f64>,
    pub model_final: Array2<f64>,
}

impl Diagnosis {
    /// Residual RMS (rad) before the first and after the last step.
    pub fn residual_rms(&self) -> (f64, f64) {
        let n = self.n_pixels.max(1) as f64;
        ((self.cost_initial / n).sqrt(), (self.cost_final / n).sqrt())
    }
}

/// Runs the workflow on one measured image taken with `known` phases (rad, per element or
/// group; empty = none) added to the steering, starting from the simulation's model.
pub fn diagnose(sim: &Simulation, image: &Array2<f64>, known: &[f64], options: &DiagnoseOptions) -> Result<Diagnosis> {
    let meas = [Measurement { image: image.clone(), known: known.to_vec() }];
    let noise = masks_and_box(sim, &meas, sim.mask_fraction, 3)?.noise;
    if !(noise > 0.0) {
        return Err(HasError::invalid("image", "has no measurable background noise: the evidence needs a noise level"));
    }
    let forward = Forward::new(sim, known)?;
    let n = image.len();
    let penalty = (n as f64).ln();
    let mut view = View {
        scale: 1.0,
        broadening_width_mm: sim.sampler.broadening.width * 1e3,
        shift_mm: [0.0; 2],
        background_offset_rad: 0.0,
        background_slope_rad_per_mm: [0.0; 2],
        slice_offset_mm: 0.0,
    };
    let model_initial = forward.image(&view)?;
    let cost_initial = forward.cost(&view, image);
    let mut cost = cost_initial;
    let mut included: Vec<Effect> = Vec::new();
    let mut steps = Vec::new();
    let rejected = loop {
        let mut fits: Vec<(Candidate, View)> = Vec::new();
        for effect in Effect::ALL.into_iter().filter(|e| !included.contains(e)) {
            let mut free: Vec<usize> = included.iter().flat_map(|e| e.slots().iter().copied()).collect();
            free.extend_from_slice(effect.slots());
            let (c, v) = fit(&forward, image, view, &free, options.max_iterations)?;
            let evidence = (cost - c) / noise.powi(2) - effect.slots().len() as f64 * penalty;
            fits.push((Candidate { effect, cost: c, evidence }, v));
        }
        let best = fits.iter().enumerate().max_by(|a, b| a.1 .0.evidence.total_cmp(&b.1 .0.evidence).then(b.0.cmp(&a.0)));
        match best {
            Some((_, (cand, v))) if cand.evidence > options.threshold => {
                let values = v.to_vec();
                steps.push(Step {
                    effect: cand.effect,
                    params: cand.effect.slots().iter().map(|&s| (NAMES[s], values[s])).collect(),
                    cost_before: cost,
                    cost_after: cand.cost,
                    evidence: cand.evidence,
                    candidates: fits.iter().map(|f| f.0.clone()).collect(),
                    view: *v,
                });
                included.push(cand.effect);
                view = *v;
                cost = cand.cost;
            }
            _ => break fits.into_iter().map(|f| f.0).collect(),
        }
    };
    Ok(Diagnosis {
        steps,
        rejected,
        cost_initial,
        cost_final: cost,
        noise_floor: noise,
        n_pixels: n,
        model_initial,
        model_final: forward.image(&view)?,
    })
}

/// Nelder–Mead over the parameters `free` (indices into [`View::to_vec`]) from `start`, in units
/// of [`STEPS`]; returns the best cost and parameters.
fn fit(forward: &Forward, measured: &Array2<f64>, start: View, free: &[usize], max_iterations: usize) -> Result<(f64, View)> {
    let base = start.to_vec();
    let problem = Fit { forward, measured, base, free };
    let x0 = vec![0.0; free.len()];
    let mut simplex = vec![x0.clone()];
    for i in 0..free.len() {
        let mut y = x0.clone();
        y[i] = 1.0;
        simplex.push(y);
    }
    let solver = NelderMead::new(simplex).with_sd_tolerance(1e-10).map_err(|e| HasError::invalid("diagnose", e.to_string()))?;
    let res = Executor::new(&problem, solver)
        .configure(|s| s.max_iters(max_iterations as u64))
        .run()
        .map_err(|e| HasError::invalid("diagnose", e.to_string()))?;
    let x = res.state().best_param.clone().unwrap_or(x0);
    let view = problem.view(&x);
    Ok((forward.cost(&view, measured), view))
}

struct Fit<'a> {
    forward: &'a Forward,
    measured: &'a Array2<f64>,
    base: [f64; 8],
    free: &'a [usize],
}

impl Fit<'_> {
    fn view(&self, x: &[f64]) -> View {
        let mut v = self.base;
        for (&k, &xi) in self.free.iter().zip(x) {
            v[k] += xi * STEPS[k];
        }
        View::from_vec(&v)
    }
}

impl CostFunction for &Fit<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        let c = self.forward.cost(&self.view(x), self.measured);
        Ok(if c.is_finite() { c } else { PENALTY })
    }
}

/// The MR window extended by [`SLICE_REACH_MM`] plus the slice half-thickness and a sample on each
/// side along the slice normal, within the grid.
fn extended_window(sim: &Simulation) -> crate::has::Window {
    let g = &sim.grid;
    let mut w = sim.sampler.window.clone();
    let (range, step, n) = match sim.sampler.geometry.plane.axes()[2] {
        0 => (&mut w.cols, g.dx, g.nx),
        1 => (&mut w.rows, g.dy, g.ny),
        _ => (&mut w.planes, g.dz, g.nz),
    };
    let extra = ((SLICE_REACH_MM * 1e-3 + sim.sampler.geometry.slice_thickness) / step).ceil() as usize + 1;
    *range = range.start.saturating_sub(extra)..(range.end + extra).min(n);
    w
}
