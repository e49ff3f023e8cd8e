//! The model-discrepancy workflow: find where the model and the measured MR-ARFI
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

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::inverse::cost::{masks_and_box, Measurement};
use crate::inverse::estimate::Stop;
use crate::simulation::Simulation;
use ndarray::Array2;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

mod brent;
mod effects;
mod forward;
mod search;

pub use effects::{Effect, Effects, FieldState, Parameter, Value, ValueKind, View, PARAMETERS, SLICE_REACH_MM};
use forward::Forward;
use search::{Context, Path};

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
    /// The candidate effect.
    pub effect: Effect,
    /// Best cost `J` (rad², summed over every pixel of every image) with the effect fitted.
    pub cost: f64,
    /// `(J_before - J) / sigma² - k·ln n` (minus `ln G` for a dead-group choice).
    pub evidence: f64,
    /// Why the fit failed (then `cost` is infinite and `evidence` -infinity).
    pub failure: Option<String>,
}

/// One effect added to the model.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// The effect added.
    pub effect: Effect,
    /// The effect's fitted parameters, named with their units.
    pub params: Vec<(&'static str, Value)>,
    /// Cost before this step (rad²).
    pub cost_before: f64,
    /// Cost after this step (rad²).
    pub cost_after: f64,
    /// The step's evidence (BIC units; see [`Candidate::evidence`]).
    pub evidence: f64,
    /// Every candidate tried at this step.
    pub candidates: Vec<Candidate>,
    /// Other candidates within [`EQUIVALENCE`] of this one's evidence (and above the threshold):
    /// the data explain equally well with them.
    pub equivalent: Vec<Effect>,
    /// The whole model after this step.
    pub effects: Effects,
    /// The model's image of each measurement after this step (rad).
    pub models: Vec<Array2<f64>>,
}

/// The outcome of [`diagnose`].
#[derive(Debug, Clone)]
pub struct Diagnosis {
    /// The effects added, in order.
    pub steps: Vec<Step>,
    /// Candidates of the last, unsuccessful round (none passed).
    pub rejected: Vec<Candidate>,
    /// Cost of the starting model (rad², every pixel of every image).
    pub cost_initial: f64,
    /// Cost of the final model (rad²).
    pub cost_final: f64,
    /// Noise standard deviation from the image backgrounds (rad, RMS over the images).
    pub noise_floor: f64,
    /// Imaged pixels (with MR signal) over all images.
    pub n_pixels: usize,
    /// The model's image of each measurement before the first step (rad).
    pub models_initial: Vec<Array2<f64>>,
    /// The final model's image of each measurement (rad).
    pub models_final: Vec<Array2<f64>>,
    /// Every parameter of the final model.
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
    /// The effects of the other path, in order.
    pub effects: Vec<Effect>,
    /// Its total evidence (BIC units).
    pub total_evidence: f64,
    /// Its final cost (rad²).
    pub cost: f64,
}

impl Diagnosis {
    /// Residual RMS (rad) before the first step and after the last.
    pub fn residual_rms(&self) -> (f64, f64) {
        let n = self.n_pixels.max(1) as f64;
        ((self.cost_initial / n).sqrt(), (self.cost_final / n).sqrt())
    }
}

/// Runs the workflow on measured images (each with the known phases added for it), starting
/// from the simulation's model. `control`'s cancel flag, when set by another thread, ends the
/// run promptly with [`HasError::Interrupted`].
///
/// The paper's story: a model without broadening meets an image broadened with W = 2.7 mm
/// (compiled, not run here: `tests/suite/diagnose.rs` runs this diagnosis and checks it).
///
/// ```no_run
/// use has_core::physics::mr::add_noise;
/// use has_core::inverse::cost::Measurement;
/// use has_core::inverse::diagnose::{diagnose, DiagnoseOptions, Effect};
/// use has_core::{Control, Scenario, Simulation};
/// let sim = Simulation::new(&Scenario::default())?; // W = 2.7 mm
/// let mut image = sim.arfi_image(&[])?;
/// add_noise(&mut image, 0.02, 1)?;
/// let unbroadened = sim.with_calibration(0.0, sim.amplitude()?)?;
/// let d = diagnose(&unbroadened, &[Measurement { image, known: vec![] }], &DiagnoseOptions::default(), &Control::default())?;
/// assert_eq!(d.steps[0].effect, Effect::Broadening);
/// # Ok::<(), has_core::HasError>(())
/// ```
pub fn diagnose(sim: &Simulation, measurements: &[Measurement], options: &DiagnoseOptions, control: &Control) -> Result<Diagnosis> {
    let never = AtomicBool::new(false);
    let cancel = control.cancel().unwrap_or(&never);
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
    let n: usize = measured.iter().map(|m| m.iter().filter(|v| v.is_finite()).count()).sum();
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
