//! The model-discrepancy workflow (SPEC §7): find where the model and the measured MR-ARFI
//! image(s) disagree, name the missing effect, add it to the model, and repeat until what is
//! left is noise.
//!
//! Each candidate effect is a parametrised extension of the forward model ([`Effects`]). At each
//! step every candidate not yet in the model is fitted, warm-started from the current model and
//! jointly with the image-space parameters already added, on every pixel of every image, and
//! scored with the Bayesian information criterion for Gaussian noise of known `sigma` (from the
//! image backgrounds): `evidence = (J_before - J_after) / sigma² - k·ln(n)` for `k` added
//! parameters and `n` pixels (plus `ln G` for the choice of a dead group). The best candidate is
//! added when its evidence exceeds the threshold (default 0). With noise only, a one-parameter
//! effect passes by chance with probability `P(chi²_1 > ln n)`, 0.2 % for a 128 x 96 image.
//! Candidates whose evidence lies within [`EQUIVALENCE`] of the best are reported as equally
//! good explanations: the data cannot tell them apart (e.g. `attenuation` and `amplitude`).
//!
//! Image-space effects (`amplitude`, `broadening`, `broadening_anisotropic`, `registration_shift`,
//! `background_phase`, `slice_offset`) re-sample one recorded `|p|²` window, extended along the
//! slice normal; field effects (`phase_aberration`, `element_dropout`, `sound_speed`,
//! `attenuation` of the material at the focus) march the field again.

use crate::error::{HasError, Result};
use crate::inverse::cost::{build_model, masks_and_box, Measurement};
use crate::inverse::estimate::{point_reflection, Estimator, Stop, PENALTY};
use crate::physics::mr::MrSampler;
use crate::physics::propagation::{RecordSpec, Window};
use crate::simulation::Simulation;
use crate::Complex64 as C64;
use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use ndarray::Array2;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod effects;

use effects::{focal_material, params_of, STEPS};
pub use effects::{Effect, Effects, FieldState, Parameter, Value, ValueKind, View, PARAMETERS, SLICE_REACH_MM};

/// Evidence difference below which two candidates explain the data equally well (BIC units:
/// "not worth more than a bare mention", Kass & Raftery 1995).
pub const EQUIVALENCE: f64 = 2.0;

/// The model images (rad) of images taken with `knowns` (per element or group; empty = none)
/// under `effects`: the forward model with every effect of the library applied. Values so extreme
/// that an image overflows are refused (an error naming `effects`), never returned as inf or NaN.
pub fn effect_images(sim: &Simulation, knowns: &[Vec<f64>], effects: &Effects) -> Result<Vec<Array2<f64>>> {
    let images = Forward::new(sim, knowns)?.images(effects)?;
    if images.iter().any(|m| m.iter().any(|v| !v.is_finite())) {
        return Err(HasError::invalid("effects", "the model image overflows for these values (not finite); use realistic strengths"));
    }
    Ok(images)
}

/// The sampler of a moved slice (its window is `sampler.window`).
type Slice = Arc<MrSampler>;

/// `|p|²` of each image on the extended window, for one field state.
type Power = Arc<Vec<Vec<f64>>>;

/// The extended forward model for a set of images.
struct Forward<'a> {
    sim: &'a Simulation,
    /// Known element phases per image.
    knowns: Vec<Vec<f64>>,
    material: usize,
    /// The MR window extended by [`SLICE_REACH_MM`] (plus the slab and a sample) along the normal.
    window: Window,
    /// Whether each window sample lies in the focal material.
    in_material: Vec<bool>,
    /// Pixel-centre coordinates along u and v (mm).
    coords: [Vec<f64>; 2],
    /// Recent field states and their powers.
    powers: Recent<FieldState, Power>,
    /// Samplers of moved slices, by offset bits.
    samplers: Recent<u64, Slice>,
}

/// A small cache of the last [`CACHED`] values computed (pure functions of their keys, so a
/// hit returns what a recomputation would).
struct Recent<K, V>(Mutex<Vec<(K, V)>>);

impl<K: PartialEq + Clone, V: Clone> Recent<K, V> {
    fn new() -> Self {
        Recent(Mutex::new(vec![]))
    }

    /// The value for `key`, computed by `make` when it is not held.
    fn get_or_try(&self, key: &K, make: impl FnOnce() -> Result<V>) -> Result<V> {
        if let Some(v) = self.0.lock().ok().and_then(|c| c.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone())) {
            return Ok(v);
        }
        let v = make()?;
        if let Ok(mut c) = self.0.lock() {
            if c.len() >= CACHED {
                c.remove(0);
            }
            c.push((key.clone(), v.clone()));
        }
        Ok(v)
    }
}

/// The most groups `element_dropout` and `phase_aberration` are fitted for (one march per
/// group; the group kernels' limit).
const MAX_GROUPS: usize = 128;

/// How many field states and samplers the caches keep.
const CACHED: usize = 6;

impl<'a> Forward<'a> {
    fn new(sim: &'a Simulation, knowns: &[Vec<f64>]) -> Result<Self> {
        let sampler = sim.sampler()?;
        let g = &sampler.geometry;
        let window = extended_window(sim, sampler);
        let material = focal_material(sim);
        let grid = &sim.grid;
        let mut in_material = Vec::with_capacity(window.len());
        for n in window.planes.clone() {
            for j in window.rows.clone() {
                for i in window.cols.clone() {
                    in_material.push(sim.medium.material_at(grid.x(i), grid.y(j), grid.z(n)) == material);
                }
            }
        }
        let knowns = knowns
            .iter()
            .map(|k| if k.is_empty() { Ok(vec![0.0; sim.n_elements()]) } else { sim.element_phases(k) })
            .collect::<Result<_>>()?;
        let coords = [0, 1].map(|k| (0..g.matrix[k]).map(|i| g.pixel_center(k, i) * 1e3).collect());
        Ok(Forward { sim, knowns, material, window, in_material, coords, powers: Recent::new(), samplers: Recent::new() })
    }

    /// `|p|²` (times the force coefficient relative to the model's) on the extended window for
    /// every image of a field state.
    fn powers(&self, state: &FieldState) -> Result<Power> {
        self.powers.get_or_try(state, || self.march(state))
    }

    /// [`Forward::powers`], computed.
    fn march(&self, state: &FieldState) -> Result<Power> {
        let (sim, ratio) = self.in_medium(state)?;
        let sim = sim.as_ref();
        let s = self.sim;
        if let Some(&d) = state.dead_groups.iter().find(|&&d| d >= s.n_groups) {
            return Err(HasError::invalid("dead_groups", format!("group {d} does not exist ({} groups)", s.n_groups)));
        }
        if !state.group_phases.is_empty() && state.group_phases.len() != s.n_groups {
            return Err(HasError::invalid("group_phases", format!("has {} values for {} groups", state.group_phases.len(), s.n_groups)));
        }
        let sources = self
            .knowns
            .iter()
            .map(|known| {
                let drive: Vec<C64> = (0..s.n_elements())
                    .map(|e| {
                        let g = s.groups[e];
                        if state.dead_groups.contains(&g) {
                            return C64::new(0.0, 0.0);
                        }
                        let extra = state.group_phases.get(g).copied().unwrap_or(0.0);
                        C64::from_polar(1.0, s.steering[e] + known[e] + extra)
                    })
                    .collect();
                s.source.field(&drive)
            })
            .collect::<Result<Vec<_>>>()?;
        let spec = RecordSpec { window: Some(self.window.clone()), reflections: s.reflections, ..Default::default() };
        let power: Vec<Vec<f64>> = sim
            .plan
            .propagate_batch(&sources, &spec)?
            .into_iter()
            .map(|rec| rec.window.iter().zip(&self.in_material).map(|(p, &m)| p.norm_sqr() * if m { ratio } else { 1.0 }).collect())
            .collect();
        Ok(Arc::new(power))
    }

    /// The simulation in the medium of `state`, and the ratio of its force coefficient
    /// `alpha/(rho·c²)` in the focal material to the model's (the samplers keep the model's).
    fn in_medium(&self, state: &FieldState) -> Result<(std::borrow::Cow<'a, Simulation>, f64)> {
        let model = &self.sim.medium.materials[self.material];
        if state.sound_speed == model.sound_speed && state.attenuation_db_cm_mhz == model.attenuation_db_cm_mhz {
            return Ok((std::borrow::Cow::Borrowed(self.sim), 1.0));
        }
        let sim = self.sim.with_material(self.material, state.sound_speed, state.attenuation_db_cm_mhz)?;
        let coef = |m: &crate::physics::medium::Material| m.properties(self.sim.frequency).force_coefficient();
        let ratio = coef(&sim.medium.materials[self.material]) / coef(model);
        Ok((std::borrow::Cow::Owned(sim), ratio))
    }

    /// The sampler of the slice moved `dz_mm` along its normal, and its window.
    fn slice(&self, dz_mm: f64) -> Result<Slice> {
        self.samplers.get_or_try(&dz_mm.to_bits(), || self.moved_slice(dz_mm))
    }

    /// [`Forward::slice`], computed.
    fn moved_slice(&self, dz_mm: f64) -> Result<Slice> {
        let s = &self.sim;
        if !(dz_mm.abs() <= SLICE_REACH_MM) {
            return Err(HasError::invalid("dz_mm", format!("slice offsets are fitted within ±{SLICE_REACH_MM} mm")));
        }
        let mut geometry = s.sampler()?.geometry.clone();
        geometry.center[geometry.plane.axes()[2]] += dz_mm * 1e-3;
        let sampler = MrSampler::new(&s.grid, &s.medium, s.frequency, &geometry, s.sampler()?.broadening)?;
        let w = &sampler.window;
        let inside = |a: &std::ops::Range<usize>, b: &std::ops::Range<usize>| a.start >= b.start && a.end <= b.end;
        if !(inside(&w.planes, &self.window.planes) && inside(&w.rows, &self.window.rows) && inside(&w.cols, &self.window.cols)) {
            return Err(HasError::invalid("dz_mm", "the moved slice leaves the recorded field"));
        }
        Ok(Arc::new(sampler))
    }

    /// The force images times the model's amplitude (rad, before the scale and background).
    fn force_images(&self, e: &Effects) -> Result<Vec<Array2<f64>>> {
        let power = self.powers(&e.field)?;
        let v = &e.view;
        let slice = self.slice(v.slice_offset_mm)?;
        let sampler = slice.with_view(v.widths_mm().map(|w| w * 1e-3), v.shift_mm.map(|s| s * 1e-3))?;
        power.iter().map(|p| Ok(sampler.apply(&self.window.extract(p, &slice.window))? * self.sim.amplitude()?)).collect()
    }

    /// The model image of every image.
    fn images(&self, e: &Effects) -> Result<Vec<Array2<f64>>> {
        Ok(self.force_images(e)?.into_iter().map(|f| self.compose(f, &e.view)).collect())
    }

    /// `scale · force + offset + slope_u·u + slope_v·v`.
    fn compose(&self, force: Array2<f64>, v: &View) -> Array2<f64> {
        let mut img = force * v.scale;
        let b = v.background_slope_rad_per_mm;
        for ((i, j), x) in img.indexed_iter_mut() {
            *x += v.background_offset_rad + b[0] * self.coords[0][i] + b[1] * self.coords[1][j];
        }
        img
    }

    /// Sum of squared differences over every pixel of every image (infinite when the model
    /// cannot be evaluated).
    fn cost(&self, e: &Effects, measured: &[Array2<f64>]) -> f64 {
        match self.images(e) {
            Ok(imgs) => sum_squares(&imgs, measured),
            Err(_) => f64::INFINITY,
        }
    }

    /// The view with its linear parameters `linear` (slots 0 = scale, 5–7 = background) set to
    /// their least-squares values for the given force images (variable projection: the image is
    /// linear in them), and the cost. Falls back to `view` when the system is singular.
    fn project(&self, force: Vec<Array2<f64>>, view: View, linear: &[usize], measured: &[Array2<f64>]) -> (View, f64) {
        let mut v = view.to_vec();
        for &k in linear {
            v[k] = 0.0;
        }
        let base = View::from_vec(&v);
        let column = |k: usize, img: usize, i: usize, j: usize| match k {
            0 => force[img][[i, j]],
            5 => 1.0,
            6 => self.coords[0][i],
            _ => self.coords[1][j],
        };
        let m = linear.len();
        let mut a = vec![vec![0.0; m + 1]; m];
        for (img, (f, d)) in force.iter().zip(measured).enumerate() {
            let fixed = self.compose(f.clone(), &base);
            for ((i, j), y) in d.indexed_iter() {
                let r = y - fixed[[i, j]];
                let mut cols = [0.0; 4];
                for (c, &k) in cols.iter_mut().zip(linear) {
                    *c = column(k, img, i, j);
                }
                for p in 0..m {
                    for q in 0..m {
                        a[p][q] += cols[p] * cols[q];
                    }
                    a[p][m] += cols[p] * r;
                }
            }
        }
        let solved = match solve(a) {
            Some(x) => {
                for (&k, xk) in linear.iter().zip(x) {
                    v[k] = xk;
                }
                View::from_vec(&v)
            }
            None => view,
        };
        let images: Vec<Array2<f64>> = force.into_iter().map(|f| self.compose(f, &solved)).collect();
        (solved, sum_squares(&images, measured))
    }
}

fn sum_squares(model: &[Array2<f64>], measured: &[Array2<f64>]) -> f64 {
    model.iter().zip(measured).map(|(m, d)| m.iter().zip(d).map(|(a, b)| (a - b).powi(2)).sum::<f64>()).sum()
}

/// Solves the augmented system `[A | b]` by Gaussian elimination with partial pivoting; None
/// when it is (numerically) singular.
#[allow(clippy::needless_range_loop)] // index loops read as the textbook algorithm
fn solve(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    let scale = (0..m).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for c in 0..m {
        let p = (c..m).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        if !(a[p][c].abs() > 1e-12 * scale) {
            return None;
        }
        a.swap(c, p);
        for r in c + 1..m {
            let f = a[r][c] / a[c][c];
            for k in c..=m {
                a[r][k] -= f * a[c][k];
            }
        }
    }
    let mut x = vec![0.0; m];
    for c in (0..m).rev() {
        x[c] = (a[c][m] - (c + 1..m).map(|k| a[c][k] * x[k]).sum::<f64>()) / a[c][c];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Settings of the workflow.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseOptions {
    /// Evidence an effect needs to be added (0 = the plain BIC).
    pub threshold: f64,
    /// Nelder–Mead iterations per candidate fit.
    pub max_iterations: usize,
    /// The effects to try (default: all of [`Effect::ALL`]).
    pub effects: Vec<Effect>,
    /// Wall-clock limit: when it passes, the round under way is dropped and the effects added
    /// so far are reported, with [`Diagnosis::stop`] = [`Stop::TimeLimit`].
    pub time_limit: Option<Duration>,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions { threshold: 0.0, max_iterations: 1500, effects: Effect::ALL.to_vec(), time_limit: None }
    }
}

impl DiagnoseOptions {
    /// Validated options: a finite `threshold`, `max_iterations > 0`, effects by name (`None`:
    /// the whole library), a time limit in seconds (> 0).
    pub fn new(threshold: f64, max_iterations: usize, effects: Option<&[String]>, time_limit_s: Option<f64>) -> Result<Self> {
        if !threshold.is_finite() {
            return Err(HasError::invalid("threshold", "must be finite"));
        }
        if max_iterations == 0 {
            return Err(HasError::invalid("max_iterations", "must be > 0"));
        }
        let effects = match effects {
            None => Effect::ALL.to_vec(),
            Some(names) => names.iter().map(|n| Effect::named(n)).collect::<Result<_>>()?,
        };
        if let Some(t) = time_limit_s {
            crate::error::require_positive("time_limit_s", t)?;
        }
        Ok(DiagnoseOptions { threshold, max_iterations, effects, time_limit: time_limit_s.map(Duration::from_secs_f64) })
    }
}

/// One candidate's fit at one step.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    pub effect: Effect,
    pub cost: f64,
    pub evidence: f64,
    /// Why the fit failed (then `cost` is infinite and `evidence` -infinity).
    pub failure: Option<String>,
}

/// One effect added to the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    pub effect: Effect,
    /// The effect's fitted parameters, named with their units.
    pub params: Vec<(&'static str, Value)>,
    pub cost_before: f64,
    pub cost_after: f64,
    pub evidence: f64,
    /// Every candidate tried at this step.
    pub candidates: Vec<Candidate>,
    /// Other candidates within [`EQUIVALENCE`] of this one's evidence (and above the threshold):
    /// the data explain equally well with them.
    pub equivalent: Vec<Effect>,
    /// The whole model after this step, and its image of each measurement.
    pub effects: Effects,
    pub models: Vec<Array2<f64>>,
}

/// The outcome of [`diagnose`].
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub steps: Vec<Step>,
    /// Candidates of the last, unsuccessful round (none passed).
    pub rejected: Vec<Candidate>,
    pub cost_initial: f64,
    pub cost_final: f64,
    /// Noise standard deviation from the image backgrounds (rad, RMS over the images).
    pub noise_floor: f64,
    /// Pixels over all images.
    pub n_pixels: usize,
    /// The model's image of each measurement before the first step and after the last.
    pub models_initial: Vec<Array2<f64>>,
    pub models_final: Vec<Array2<f64>>,
    pub effects: Effects,
    /// `(J_initial - J_final) / sigma² - K·ln n` over the steps (the sum of their evidence).
    pub total_evidence: f64,
    /// The other path tried (when the phase aberration competes with simpler effects).
    pub alternative: Option<Alternative>,
    /// `Converged` (no candidate passes the threshold) or `TimeLimit`.
    pub stop: Stop,
}

/// Another set of effects that was fitted in full: the data may not decide between it and the
/// one reported when their total evidence differs by little (below 10 is less than "very
/// strong" on the BIC scale, Kass & Raftery 1995).
#[derive(Debug, Clone, PartialEq)]
pub struct Alternative {
    pub effects: Vec<Effect>,
    pub total_evidence: f64,
    pub cost: f64,
}

impl Diagnosis {
    /// Residual RMS (rad) before the first step and after the last.
    pub fn residual_rms(&self) -> (f64, f64) {
        let n = self.n_pixels.max(1) as f64;
        ((self.cost_initial / n).sqrt(), (self.cost_final / n).sqrt())
    }
}

/// A fitted candidate: its score and the model it leads to.
struct Fitted {
    candidate: Candidate,
    effects: Effects,
}

/// Runs the workflow on measured images (each with the known phases added for it), starting
/// from the simulation's model. `cancel`, when set by another thread, ends the run promptly
/// with [`HasError::Interrupted`].
///
/// The paper's story: a model without broadening meets an image broadened with W = 2.7 mm.
///
/// ```
/// use has_core::physics::mr::add_noise;
/// use has_core::inverse::cost::Measurement;
/// use has_core::inverse::diagnose::{diagnose, DiagnoseOptions, Effect};
/// use has_core::{Scenario, Simulation};
/// let sim = Simulation::new(&Scenario::default())?; // W = 2.7 mm
/// let mut image = sim.arfi_image(&[])?;
/// add_noise(&mut image, 0.02, 1)?;
/// let unbroadened = sim.with_calibration(0.0, sim.amplitude()?)?;
/// let d = diagnose(&unbroadened, &[Measurement { image, known: vec![] }], &DiagnoseOptions::default(), None)?;
/// assert_eq!(d.steps[0].effect, Effect::Broadening);
/// # Ok::<(), has_core::HasError>(())
/// ```
pub fn diagnose(
    sim: &Simulation,
    measurements: &[Measurement],
    options: &DiagnoseOptions,
    cancel: Option<&AtomicBool>,
) -> Result<Diagnosis> {
    let never = AtomicBool::new(false);
    let cancel = cancel.unwrap_or(&never);
    let deadline = options.time_limit.map(|t| Instant::now() + t);
    let noise = masks_and_box(sim, measurements, sim.mask_fraction, 3)?.noise;
    if !(noise > 0.0) {
        return Err(HasError::invalid("image", "has no measurable background noise: the evidence needs a noise level"));
    }
    if options.max_iterations == 0 {
        return Err(HasError::invalid("max_iterations", "must be at least 1"));
    }
    let knowns: Vec<Vec<f64>> = measurements.iter().map(|m| m.known.clone()).collect();
    let measured: Vec<Array2<f64>> = measurements.iter().map(|m| m.image.clone()).collect();
    let forward = Forward::new(sim, &knowns)?;
    let n: usize = measured.iter().map(|m| m.len()).sum();
    let initial = Effects::none(sim);
    let models_initial = forward.images(&initial)?;
    let cost_initial = forward.cost(&initial, &measured);
    let ctx = Context {
        sim,
        forward: &forward,
        measured: &measured,
        max_iterations: options.max_iterations,
        noise,
        penalty: (n as f64).ln(),
        memory: Mutex::new(vec![]),
        cancel,
        deadline,
        timed_out: AtomicBool::new(false),
    };
    let start = Path { steps: vec![], effects: initial, cost: cost_initial, rejected: vec![] };
    // The 15-parameter phase aberration and the simpler effects can mimic each other (a tilt
    // is a shift, a defocus a slice offset, a blur a broadening), so greedy selection would let
    // whichever comes first swallow the rest. Two paths are built: the simpler effects first
    // (then the aberration, and the simpler ones again), and the aberration first (then the
    // simpler ones); the path with the larger total evidence is kept, the other reported.
    let simple: Vec<Effect> = options.effects.iter().copied().filter(|e| *e != Effect::PhaseAberration).collect();
    let simple_path = ctx.extend(start.clone(), &simple, options.threshold)?;
    let (path, alternative) = if options.effects.contains(&Effect::PhaseAberration) {
        let with = ctx.extend(simple_path.clone(), &[Effect::PhaseAberration], options.threshold)?;
        let a = if with.included().contains(&Effect::PhaseAberration) {
            ctx.extend(with, &simple, options.threshold)?
        } else {
            Path { rejected: [simple_path.rejected.clone(), with.rejected].concat(), ..simple_path.clone() }
        };
        // When the simpler effects added nothing, the aberration-first path is the same one.
        let first =
            if simple_path.steps.is_empty() { None } else { Some(ctx.extend(start, &[Effect::PhaseAberration], options.threshold)?) };
        match first.filter(|f| !f.steps.is_empty()) {
            None => (a, None),
            Some(first) => {
                let b = ctx.extend(first, &simple, options.threshold)?;
                if b.total_evidence() > a.total_evidence() {
                    (b, Some(a))
                } else {
                    (a, Some(b))
                }
            }
        }
    } else {
        (simple_path, None)
    };
    let alternative = alternative.filter(|p| p.included() != path.included()).map(|p| Alternative {
        effects: p.included(),
        total_evidence: p.total_evidence(),
        cost: p.cost,
    });
    let total_evidence = path.total_evidence();
    Ok(Diagnosis {
        models_final: path.steps.last().map_or_else(|| models_initial.clone(), |s| s.models.clone()),
        steps: path.steps,
        rejected: path.rejected,
        cost_initial,
        cost_final: path.cost,
        noise_floor: noise,
        n_pixels: n,
        models_initial,
        total_evidence,
        effects: path.effects,
        alternative,
        stop: if ctx.timed_out.load(Ordering::Relaxed) { Stop::TimeLimit } else { Stop::Converged },
    })
}

/// A sequence of effects added to the model.
#[derive(Clone)]
struct Path {
    steps: Vec<Step>,
    effects: Effects,
    cost: f64,
    /// Candidates of the last round, none of which passed.
    rejected: Vec<Candidate>,
}

impl Path {
    /// The effects added, in order.
    fn included(&self) -> Vec<Effect> {
        self.steps.iter().map(|s| s.effect).collect()
    }

    /// `(J_0 - J) / sigma² - K·ln n` over the whole path.
    fn total_evidence(&self) -> f64 {
        self.steps.iter().map(|s| s.evidence).sum()
    }
}

/// Whether `effect` adds parameters to a model whose free image-space slots are `free`.
fn adds_parameters(effect: Effect, free: &[usize]) -> bool {
    effect.slots().is_empty() || effect.slots().iter().any(|s| !free.contains(s))
}

/// The number of parameters `effect` adds (BIC's k).
fn parameters(effect: Effect, free: &[usize], groups: usize) -> f64 {
    match effect {
        Effect::PhaseAberration => groups.saturating_sub(1) as f64,
        Effect::ElementDropout | Effect::SoundSpeed | Effect::Attenuation => 1.0,
        e => e.slots().iter().filter(|s| !free.contains(s)).count() as f64,
    }
}

/// Extra penalty for a discrete choice among `groups` (which group is dead): `ln G`.
fn choice_penalty(effect: Effect, groups: usize) -> f64 {
    if effect == Effect::ElementDropout {
        (groups.max(1) as f64).ln()
    } else {
        0.0
    }
}

/// What every candidate fit needs.
struct Context<'a> {
    sim: &'a Simulation,
    forward: &'a Forward<'a>,
    measured: &'a [Array2<f64>],
    max_iterations: usize,
    noise: f64,
    /// BIC penalty per parameter, `ln n`.
    penalty: f64,
    /// The last optimum of each searched field parameter.
    memory: Mutex<Vec<(Effect, f64)>>,
    /// Set by another thread to stop: evaluations then return at once and the run ends.
    cancel: &'a AtomicBool,
    /// When passed, evaluations return at once and each path keeps the steps it has.
    deadline: Option<Instant>,
    timed_out: AtomicBool,
}

/// Why evaluations stop early: a signal inside the search, never an error for the caller (a
/// cancel becomes [`HasError::Interrupted`]; a time limit ends the search with the steps so far).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Halt {
    Cancelled,
    TimeUp,
}

impl Context<'_> {
    /// Whether the time limit has passed; `Err(Interrupted)` when cancelled.
    fn out_of_time(&self) -> Result<bool> {
        match self.halted() {
            Some(Halt::Cancelled) => Err(HasError::Interrupted),
            Some(Halt::TimeUp) => Ok(true),
            None => Ok(false),
        }
    }

    /// Whether evaluations should stop: cancelled, or past the deadline.
    fn halted(&self) -> Option<Halt> {
        if self.cancel.load(Ordering::Relaxed) {
            return Some(Halt::Cancelled);
        }
        if self.deadline.is_some_and(|d| Instant::now() > d) {
            self.timed_out.store(true, Ordering::Relaxed);
            return Some(Halt::TimeUp);
        }
        None
    }

    /// Adds effects from `allowed` to `path` one at a time, the candidate with the largest
    /// evidence each round, while it exceeds `threshold`.
    fn extend(&self, mut path: Path, allowed: &[Effect], threshold: f64) -> Result<Path> {
        loop {
            if self.out_of_time()? {
                return Ok(path);
            }
            let included = path.included();
            let free: Vec<usize> = included.iter().flat_map(|e| e.slots().iter().copied()).collect();
            let todo: Vec<Effect> = allowed.iter().copied().filter(|e| !included.contains(e) && adds_parameters(*e, &free)).collect();
            let g = self.sim.n_groups;
            let fits: Vec<Fitted> = todo
                .par_iter()
                .map(|&effect| match self.fit(effect, &path.effects, &free) {
                    Ok((c, e)) => {
                        let k = parameters(effect, &free, g);
                        let evidence = (path.cost - c) / self.noise.powi(2) - k * self.penalty - choice_penalty(effect, g);
                        Fitted { candidate: Candidate { effect, cost: c, evidence, failure: None }, effects: e }
                    }
                    Err(err) => Fitted {
                        candidate: Candidate { effect, cost: f64::INFINITY, evidence: f64::NEG_INFINITY, failure: Some(err.to_string()) },
                        effects: path.effects.clone(),
                    },
                })
                .collect();
            if self.out_of_time()? {
                return Ok(path); // this round's fits are incomplete
            }
            let best = fits.iter().enumerate().max_by(|a, b| a.1.candidate.evidence.total_cmp(&b.1.candidate.evidence).then(b.0.cmp(&a.0)));
            let Some((i, f)) = best.filter(|(_, f)| f.candidate.evidence > threshold) else {
                path.rejected = fits.into_iter().map(|f| f.candidate).collect();
                return Ok(path);
            };
            let top = f.candidate.evidence;
            let equivalent = fits
                .iter()
                .enumerate()
                .filter(|(j, g)| *j != i && g.candidate.evidence > threshold && g.candidate.evidence >= top - EQUIVALENCE)
                .map(|(_, g)| g.candidate.effect)
                .collect();
            let effect = f.candidate.effect;
            path.steps.push(Step {
                effect,
                params: params_of(effect, &f.effects, &path.effects),
                cost_before: path.cost,
                cost_after: f.candidate.cost,
                evidence: top,
                candidates: fits.iter().map(|f| f.candidate.clone()).collect(),
                equivalent,
                effects: f.effects.clone(),
                models: self.forward.images(&f.effects)?,
            });
            path.effects = f.effects.clone();
            path.cost = f.candidate.cost;
            path.rejected = vec![];
        }
    }

    /// Fits `effect` on top of `current` (image-space slots `free` refitted with it).
    fn fit(&self, effect: Effect, current: &Effects, free: &[usize]) -> Result<(f64, Effects)> {
        if matches!(effect, Effect::ElementDropout | Effect::PhaseAberration) && self.sim.n_groups > MAX_GROUPS {
            return Err(HasError::invalid(
                "groups",
                format!(
                    "{} groups: {} is fitted for at most {MAX_GROUPS} groups (use the default grouping)",
                    self.sim.n_groups,
                    effect.name()
                ),
            ));
        }
        let field = |f: FieldState| Effects { view: current.view, field: f };
        let start = match effect {
            Effect::SoundSpeed => self.search(
                effect,
                current.field.sound_speed,
                100.0,
                4.0,
                |c| FieldState { sound_speed: c, ..current.field.clone() },
                current,
            ),
            Effect::Attenuation => {
                let a0 = current.field.attenuation_db_cm_mhz;
                let state = |a: f64| FieldState { attenuation_db_cm_mhz: a.max(0.0), ..current.field.clone() };
                self.search(effect, a0, 1.5 * a0 + 0.25, 0.02, state, current)
            }
            Effect::ElementDropout => {
                let options: Vec<Effects> = (0..self.sim.n_groups)
                    .filter(|g| !current.field.dead_groups.contains(g))
                    .map(|g| {
                        let mut dead = current.field.dead_groups.clone();
                        dead.push(g);
                        dead.sort_unstable();
                        field(FieldState { dead_groups: dead, ..current.field.clone() })
                    })
                    .collect();
                let costs: Vec<f64> = options.iter().map(|e| self.cost(e)).collect();
                let best = (0..options.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
                best.map(|b| options[b].clone()).ok_or_else(|| HasError::invalid("element_dropout", "every group is already dead"))?
            }
            Effect::PhaseAberration => field(FieldState { group_phases: self.group_phases(current)?, ..current.field.clone() }),
            Effect::SliceOffset => {
                // The image changes nearly alike on both sides of the focus, so Nelder–Mead from
                // zero may settle on the wrong side: start from the best of a 2 mm scan.
                let at = |dz: f64| Effects { view: View { slice_offset_mm: dz, ..current.view }, field: current.field.clone() };
                let scan = (-3..=3).map(|k| 2.0 * k as f64 + 1.0 * (k as f64).signum()).chain([current.view.slice_offset_mm]);
                let best = scan.map(|dz| (self.cost(&at(dz)), dz)).min_by(|a, b| a.0.total_cmp(&b.0)).map_or(0.0, |b| b.1);
                at(best)
            }
            _ => current.clone(),
        };
        let mut slots = free.to_vec();
        slots.extend(effect.slots().iter().filter(|s| !free.contains(s)));
        if slots.is_empty() {
            return Ok((self.cost(&start), start));
        }
        self.fit_view(&start, &slots)
    }

    fn cost(&self, e: &Effects) -> f64 {
        if self.halted().is_some() {
            return f64::INFINITY;
        }
        self.forward.cost(e, self.measured)
    }

    /// Brent search of one field parameter within `reach` of `centre` to `tol`, the view of
    /// `current` held; returns the model at the optimum. Later rounds search within a fifth of
    /// the reach around this effect's last optimum, and widen again when the optimum lands near
    /// an end. Each evaluation marches.
    fn search(&self, effect: Effect, centre: f64, reach: f64, tol: f64, state: impl Fn(f64) -> FieldState, current: &Effects) -> Effects {
        let model = |x: f64| Effects { view: current.view, field: state(x) };
        let cost = |x: f64| self.cost(&model(x));
        let last = self.memory.lock().ok().and_then(|m| m.iter().find(|(e, _)| *e == effect).map(|(_, x)| *x));
        let narrowed =
            last.map(|x0| (x0, brent(cost, x0 - 0.2 * reach, x0 + 0.2 * reach, tol).0)).filter(|(x0, x)| (x - x0).abs() < 0.16 * reach);
        let x = narrowed.map_or_else(|| brent(cost, centre - reach, centre + reach, tol).0, |(_, x)| x);
        if let Ok(mut m) = self.memory.lock() {
            m.retain(|(e, _)| *e != effect);
            m.push((effect, x));
        }
        model(x)
    }

    /// Group phases fitted by multi-start L-BFGS on the group kernels of the current model
    /// (its view and medium; dead groups are not modelled here), added to the current ones.
    fn group_phases(&self, current: &Effects) -> Result<Vec<f64>> {
        let s = self.sim;
        let f = &current.field;
        // The window lies in the focal material (water around it absorbs nothing), so the
        // force-coefficient ratio is a scale.
        let (sim, ratio) = self.forward.in_medium(f)?;
        let mut sim = sim.into_owned();
        let v = &current.view;
        let slice = self.forward.slice(v.slice_offset_mm)?;
        sim.sampler = Ok(slice.with_view(v.widths_mm().map(|w| w * 1e-3), v.shift_mm.map(|x| x * 1e-3))?);
        sim.amplitude = Ok(s.amplitude()? * v.scale * ratio);
        let background = self.forward.images(&Effects { view: View { scale: 0.0, ..*v }, field: f.clone() })?;
        let measurements = self
            .measured
            .iter()
            .zip(&background)
            .zip(&self.forward.knowns)
            .map(|((m, b), k)| {
                let known = k.iter().zip(&s.groups).map(|(x, &g)| x + f.group_phases.get(g).copied().unwrap_or(0.0)).collect();
                Measurement { image: m - b, known }
            })
            .collect::<Vec<_>>();
        let hybrid = build_model(&sim, &measurements, s.mask_fraction, 3)?;
        let positions: Vec<[f64; 3]> = s.transducer.elements.iter().map(|e| e.reference_point()).collect();
        let estimate = Estimator::lbfgs()
            .with_twins(point_reflection(&positions, &s.groups))
            .with_time_limit_opt(self.deadline.map(|d| d.saturating_duration_since(Instant::now()).max(Duration::from_millis(1))))
            .run(&hybrid.cost, Some(self.cancel))?;
        Ok(estimate.phases.iter().enumerate().map(|(g, p)| p + f.group_phases.get(g).copied().unwrap_or(0.0)).collect())
    }

    /// Fits the image-space `slots` (indices into [`View::to_vec`]) from `start`: the scale and
    /// the background by linear least squares inside every evaluation, the others by
    /// Nelder–Mead in units of [`STEPS`]; returns the best cost and model.
    fn fit_view(&self, start: &Effects, slots: &[usize]) -> Result<(f64, Effects)> {
        let linear: Vec<usize> = slots.iter().copied().filter(|k| matches!(k, 0 | 5..=7)).collect();
        let nonlinear: Vec<usize> = slots.iter().copied().filter(|k| !linear.contains(k)).collect();
        let problem = ViewFit { ctx: self, base: start.view.to_vec(), field: &start.field, slots: &nonlinear, linear: &linear };
        let x = if nonlinear.is_empty() {
            vec![]
        } else {
            let x0 = vec![0.0; nonlinear.len()];
            let mut simplex = vec![x0.clone()];
            for i in 0..nonlinear.len() {
                let mut y = x0.clone();
                y[i] = 1.0;
                simplex.push(y);
            }
            // Costs matter to a small fraction of sigma² (the evidence unit).
            let tolerance = 1e-4 * self.noise.powi(2);
            let solver = NelderMead::new(simplex).with_sd_tolerance(tolerance).map_err(|e| HasError::invalid("diagnose", e.to_string()))?;
            let res = Executor::new(&problem, solver)
                .configure(|s| s.max_iters(self.max_iterations as u64))
                .run()
                .map_err(|e| HasError::invalid("diagnose", e.to_string()))?;
            res.state().best_param.clone().unwrap_or(x0)
        };
        if self.out_of_time()? {
            // The round this fit belongs to is dropped: no model to report.
            return Ok((f64::INFINITY, start.clone()));
        }
        let (c, view) = problem.evaluate(&x)?;
        if !c.is_finite() {
            return Err(HasError::invalid("diagnose", "the fitted model cannot be evaluated"));
        }
        Ok((c, Effects { view, field: start.field.clone() }))
    }
}

/// The fit of image-space parameters: Nelder–Mead over `slots`, `linear` projected out.
struct ViewFit<'a> {
    ctx: &'a Context<'a>,
    base: [f64; 9],
    field: &'a FieldState,
    slots: &'a [usize],
    linear: &'a [usize],
}

impl ViewFit<'_> {
    /// The view at `x` (with its linear parameters solved) and its cost.
    fn evaluate(&self, x: &[f64]) -> Result<(f64, View)> {
        match self.ctx.halted() {
            Some(Halt::Cancelled) => return Err(HasError::Interrupted),
            Some(Halt::TimeUp) => return Ok((f64::INFINITY, View::from_vec(&self.base))),
            None => {}
        }
        let mut v = self.base;
        for (&k, &xi) in self.slots.iter().zip(x) {
            v[k] += xi * STEPS[k];
        }
        let e = Effects { view: View::from_vec(&v), field: self.field.clone() };
        let force = self.ctx.forward.force_images(&e)?;
        let (view, c) = self.ctx.forward.project(force, e.view, self.linear, self.ctx.measured);
        Ok((c, view))
    }
}

impl CostFunction for &ViewFit<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        let c = self.evaluate(x).map_or(f64::INFINITY, |r| r.0);
        Ok(if c.is_finite() { c } else { PENALTY })
    }
}

/// Brent's minimisation of `f` on `[lo, hi]` to within `tol` (golden sections safeguarding
/// parabolic steps; Brent 1973, ch. 5): a smooth minimum takes 6–10 evaluations. Returns the
/// best point evaluated and its value.
fn brent(f: impl Fn(f64) -> f64, lo: f64, hi: f64, tol: f64) -> (f64, f64) {
    let c = 0.5 * (3.0 - 5f64.sqrt());
    let (mut a, mut b) = (lo, hi);
    let mut x = a + c * (b - a);
    let (mut w, mut v) = (x, x);
    let mut fx = f(x);
    let (mut fw, mut fv) = (fx, fx);
    let (mut d, mut e) = (0.0f64, 0.0f64);
    for _ in 0..100 {
        let m = 0.5 * (a + b);
        let tol1 = 0.5 * tol;
        if (x - m).abs() <= 2.0 * tol1 - 0.5 * (b - a) {
            break;
        }
        let mut golden_step = true;
        if e.abs() > tol1 {
            // Parabola through x, w, v.
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            let mut q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            if p.abs() < (0.5 * q * e).abs() && p > q * (a - x) && p < q * (b - x) {
                e = d;
                d = p / q;
                let u = x + d;
                if u - a < 2.0 * tol1 || b - u < 2.0 * tol1 {
                    d = if x < m { tol1 } else { -tol1 };
                }
                golden_step = false;
            }
        }
        if golden_step {
            e = if x < m { b - x } else { a - x };
            d = c * e;
        }
        let u = if d.abs() >= tol1 { x + d } else { x + tol1.copysign(d) };
        let fu = f(u);
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, fx)
}

/// The MR window extended by [`SLICE_REACH_MM`] plus the slice half-thickness and a sample on each
/// side along the slice normal, within the grid.
fn extended_window(sim: &Simulation, sampler: &MrSampler) -> Window {
    let g = &sim.grid;
    let mut w = sampler.window.clone();
    let (range, step, n) = match sampler.geometry.plane.axes()[2] {
        0 => (&mut w.cols, g.dx, g.nx),
        1 => (&mut w.rows, g.dy, g.ny),
        _ => (&mut w.planes, g.dz, g.nz),
    };
    let extra = ((SLICE_REACH_MM * 1e-3 + sampler.geometry.slice_thickness) / step).ceil() as usize + 1;
    *range = range.start.saturating_sub(extra)..(range.end + extra).min(n);
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brent_finds_smooth_and_edge_minima() {
        let calls = std::cell::Cell::new(0);
        let (x, fx) = brent(
            |x| {
                calls.set(calls.get() + 1);
                (x - 1.3).powi(2) + 2.0 + 0.1 * (x - 1.3).powi(3)
            },
            -5.0,
            5.0,
            1e-4,
        );
        assert!((x - 1.3).abs() < 1e-4 && (fx - 2.0).abs() < 1e-8, "{x} {fx}");
        assert!(calls.get() < 20, "{} evaluations", calls.get());
        // A minimum at the end of the interval: approached to within the tolerance.
        let (x, _) = brent(|x| x, 0.0, 1.0, 1e-3);
        assert!(x < 2e-3, "{x}");
        // Non-finite values are treated as worse.
        let (x, _) = brent(|x| if x > 0.5 { f64::NAN } else { (x - 0.3).powi(2) }, 0.0, 1.0, 1e-4);
        assert!((x - 0.3).abs() < 1e-3, "{x}");
    }
}
