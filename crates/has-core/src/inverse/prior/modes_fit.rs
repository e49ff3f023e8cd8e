//! The coefficients of several error modes of a prediction fitted jointly to MR-ARFI images:
//! the model and cost of [`super::mode_fit`] with a vector of coefficients `c` (each mode in
//! units of its prior standard deviation: `c ~ N(0, I)` a priori), e.g. the CT registration's six
//! pose modes ([`crate::prediction::pose_sensitivity`]) with the bone-speed mode. Image `k` is
//! simulated through the CT's bone with the added phases `Σ_m c_m·g_m + known_k` and
//!
//! `J(c) = min_a Σ_k Σ_pixels (a·model_k(c) − measured_k)² / σ² + |c|²`
//!
//! (minus twice the log posterior), minimised by Gauss–Newton in `(a, c)` with the prior's
//! curvature added (Levenberg–Marquardt damping when a step does not lower `J`). The image's
//! derivative along a mode is exact and costs one march: the march is linear in the source, so
//! `∂p/∂c_m` is the field of the drives `i·g_m,e·v_e` (`v_e` the drive at `c`), and
//! `∂model/∂c_m = A·S(2·Re(conj(p)·∂p/∂c_m))` with `S` the sampler's linear map of `|p|²`. An
//! iteration marches `(1 + M)·K` fields in one batch for `M` modes and `K` images.
//!
//! The posterior covariance of `c` is the inverse of the Gauss–Newton curvature at the end,
//! with the scale `a` marginalised: what the images (and the prior) say of each coefficient,
//! and how the coefficients trade against each other (a shift along the beam against the bone
//! speed, for instance).
//!
//! Whether the images support moving the prediction at all is a likelihood-ratio test: the
//! image cost `χ²` must fall by more than the 95 % point of `χ²(M)` from the prediction as it is
//! (`c = 0`) to the fit, the fall divided by the misfit where that exceeds 1. Below it, what the fit explains is what `M` free coefficients explain in
//! noise alone, or in a model that differs from the patient in ways no mode holds (a CT resampled
//! at another sub-voxel offset, anisoplanatism over the focal zone): on a 220 kHz head phantom a
//! 2 mm shift changes the images by a few units of `χ²`, as much as such differences, and an
//! unchecked fit moved the prediction the wrong way.

use super::mode_fit::Setting;
use crate::control::Control;
use crate::error::{HasError, Result};
use crate::inverse::cost::Measurement;
use crate::inverse::linear::spd_inverse;
use crate::numeric::chi2_95;
use crate::simulation::Simulation;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use std::sync::atomic::AtomicBool;

/// Gauss–Newton iterations at most (each marches every image and its derivatives once).
const ITERATIONS: usize = 6;
/// A step whose every coefficient moves by less than this fraction of its posterior standard
/// deviation ends the fit: the coefficients are then known to well within their uncertainty.
const STEP_OF_SPREAD: f64 = 0.25;
/// An undamped short step whose predicted fall of `J` is below this (units of `χ²`) ends the fit
/// before it is taken: no batch of marches confirms it. Far below any evidence threshold (the
/// 95 % point of `χ²(1)` is 3.84), so the evidence the fit reports loses nothing that counts;
/// a short step of correlated coefficients can lower `J` by more, and is marched.
const SKIPPED_FALL: f64 = 0.1;
/// The longest step (prior standard deviations, Euclidean) one iteration takes: the phases are
/// linear in `c`, the images are not.
const MAX_STEP: f64 = 1.5;
/// How far out a coefficient may go (prior standard deviations).
pub const REACH: f64 = 4.0;

/// Modes' coefficients fitted to images ([`fit_modes`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ModesFit {
    /// The fitted coefficients (each mode's units: one prior standard deviation).
    pub coefficients: Vec<f64>,
    /// Their posterior covariance (row-major, `M x M`).
    pub covariance: Vec<Vec<f64>>,
    /// The fitted amplitude scale (the images' amplitude over the model's).
    pub scale: f64,
    /// `χ²` per pixel at the fitted coefficients: about 1 when the model explains the images.
    pub misfit: f64,
    /// `χ²` per pixel with every coefficient zero (the prediction as it is).
    pub misfit_at_zero: f64,
    /// Pixels fitted (over all images).
    pub n_pixels: usize,
    /// The noise level σ (rad) the cost is normalised by.
    pub noise: f64,
    /// Gauss–Newton iterations made (each one batch of marches).
    pub iterations: usize,
    /// Whether the last step was short against the posterior's spread (else the iterations ran
    /// out).
    pub converged: bool,
    /// The fall of the image cost `χ²` from the prediction as it is (`c = 0`) to the fit, divided
    /// by the misfit where it exceeds 1.
    pub evidence: f64,
    /// The 95 % point of `χ²(M)` that `evidence` must exceed.
    pub threshold: f64,
    /// Whether `evidence` exceeds `threshold`: the images support moving the prediction along the
    /// modes (see the module docs).
    pub supported: bool,
    /// Per coefficient, whether it ended at the fit's bound ([`REACH`] prior standard deviations):
    /// the images put it at least that far out, or the linearised modes do not hold there.
    pub at_bound: Vec<bool>,
}

impl ModesFit {
    /// The posterior standard deviation of each coefficient.
    pub fn std(&self) -> Vec<f64> {
        (0..self.coefficients.len()).map(|m| self.covariance[m][m].max(0.0).sqrt()).collect()
    }
}

/// The model images and their derivatives at one `c`, with `J` there.
struct Linearised {
    c: Vec<f64>,
    /// Per pixel: the model value, its derivatives along each mode, the measured value.
    rows: Vec<(f64, Vec<f64>, f64)>,
    scale: f64,
    chi2: f64,
    j: f64,
}

/// Fits the coefficients of `modes` (each rad per element for a coefficient of 1: the mode
/// times its prior standard deviation) to `measurements` on `sim`, the model through the CT's
/// bone driven with the reference steering (see the module docs); pixels as
/// [`super::mode_fit::fit_mode`] takes them. `control`'s cancel flag, when set by another thread,
/// ends the fit before the next batch of marches ([`HasError::Interrupted`]).
pub fn fit_modes(sim: &Simulation, modes: &[Vec<f64>], measurements: &[Measurement], control: &Control) -> Result<ModesFit> {
    fit_modes_with_noise(sim, modes, measurements, None, control)
}

/// [`fit_modes`] with the images' noise `noise_rad` (rad) where it is known, instead of the
/// background floor of the box (see `EstimateRequest::noise_rad`: a floor that counts a
/// background's structure as noise lowers every fall of chi-squared the evidence test weighs).
pub fn fit_modes_with_noise(
    sim: &Simulation,
    modes: &[Vec<f64>],
    measurements: &[Measurement],
    noise_rad: Option<f64>,
    control: &Control,
) -> Result<ModesFit> {
    let cancel = control.cancel();
    let n = sim.n_elements();
    if modes.is_empty() {
        return Err(HasError::invalid("modes", "none given"));
    }
    for (m, g) in modes.iter().enumerate() {
        if g.len() != n {
            return Err(HasError::invalid("modes", format!("mode {m} has {} values for {n} elements", g.len())));
        }
        crate::error::require_finite("modes", g)?;
    }
    let setting = Setting::new(sim, measurements)?.with_noise(noise_rad)?;
    let start = linearise(&setting, modes, &vec![0.0; modes.len()], cancel)?;
    let (misfit_at_zero, chi2_at_zero) = (start.chi2 / start.rows.len().max(1) as f64, start.chi2);
    let mut at = start;
    // The undamped curvature and the gradient at `at`: the damped steps, the spread that judges
    // a step short and, at the end, the covariance all come from them.
    let (mut curvature, mut gradient) = normal_equations(&at, setting.noise);
    let mut damping = 0.0;
    let (mut iterations, mut converged) = (0, false);
    while iterations < ITERATIONS {
        let mut h = curvature.clone();
        h.diag_mut().iter_mut().for_each(|d| *d *= 1.0 + damping);
        let Some(step) = solve(&h, &gradient) else { break };
        let mut dc: Vec<f64> = step[1..].iter().map(|v| -v).collect();
        let length = dc.iter().map(|v| v * v).sum::<f64>().sqrt();
        if length > MAX_STEP {
            dc.iter_mut().for_each(|v| *v *= MAX_STEP / length);
        }
        let next_c: Vec<f64> = at.c.iter().zip(&dc).map(|(c, d)| (c + d).clamp(-REACH, REACH)).collect();
        // The step actually taken (the bound may stop it), against the undamped posterior's spread.
        let taken: Vec<f64> = next_c.iter().zip(&at.c).map(|(n, c)| n - c).collect();
        if taken.iter().all(|d| *d == 0.0) {
            converged = true;
            break;
        }
        let spread = spd_inverse(&curvature).map(|cov| (0..taken.len()).map(|m| cov[[m + 1, m + 1]].max(0.0).sqrt()).collect::<Vec<_>>());
        let short = spread.is_some_and(|s| taken.iter().zip(&s).all(|(d, s)| d.abs() < STEP_OF_SPREAD * s.max(1e-6)));
        // Gauss–Newton's predicted fall of `J` along the undamped step: `gᵀ·h⁻¹·g` (`g` and `h`
        // half the gradient and curvature of `J`).
        let fall: f64 = step.iter().zip(&gradient).map(|(s, g)| s * g).sum();
        if short && damping == 0.0 && fall < SKIPPED_FALL {
            // `at` is the minimum to within a fraction of the spread and of a unit of `χ²`: a
            // batch of marches to confirm the step would change neither.
            converged = true;
            break;
        }
        let next = linearise(&setting, modes, &next_c, cancel)?;
        iterations += 1;
        if next.j < at.j {
            at = next;
            (curvature, gradient) = normal_equations(&at, setting.noise);
            damping = 0.0;
            if short {
                converged = true;
                break;
            }
        } else if short {
            // A short step that does not lower `J`: the fit is at its minimum to within the spread.
            converged = damping == 0.0;
            break;
        } else {
            // Levenberg–Marquardt: a shorter, steeper step next time.
            damping = if damping == 0.0 { 1.0 } else { 10.0 * damping };
        }
    }
    let m = modes.len();
    let covariance = match spd_inverse(&curvature) {
        Some(cov) => (0..m).map(|i| (0..m).map(|j| cov[[i + 1, j + 1]]).collect()).collect(),
        None => (0..m).map(|i| (0..m).map(|j| if i == j { 1.0 } else { 0.0 }).collect()).collect(),
    };
    // Normalised by the misfit where the model leaves more than the noise: a residual the modes
    // do not hold inflates every fall of chi-squared alike (an F-type test).
    let misfit = at.chi2 / at.rows.len().max(1) as f64;
    let evidence = (chi2_at_zero - at.chi2) / misfit.max(1.0);
    Ok(ModesFit {
        evidence,
        threshold: chi2_95(m),
        supported: evidence > chi2_95(m),
        at_bound: at.c.iter().map(|c| c.abs() >= REACH).collect(),
        coefficients: at.c.clone(),
        covariance,
        scale: at.scale,
        misfit,
        misfit_at_zero,
        n_pixels: at.rows.len(),
        noise: setting.noise,
        iterations,
        converged,
    })
}

/// The model images and their derivatives along each mode at `c`: the base drives and, per
/// mode, the drives `i·g_m,e·v_e`, all in one batch march.
fn linearise(s: &Setting, modes: &[Vec<f64>], c: &[f64], cancel: Option<&AtomicBool>) -> Result<Linearised> {
    Setting::cancelled(cancel)?;
    let sim = s.sim;
    let n = sim.n_elements();
    let mut drives: Vec<Vec<C64>> = Vec::with_capacity(s.known.len() * (1 + modes.len()));
    for known in &s.known {
        let base: Vec<C64> = (0..n).map(|e| sim.drive(e, known[e] + modes.iter().zip(c).map(|(g, c)| c * g[e]).sum::<f64>())).collect();
        for g in modes {
            drives.push(base.iter().zip(g).map(|(v, g)| v * C64::new(0.0, *g)).collect());
        }
        drives.push(base);
    }
    let windows = s.window_fields(&sim.source.fields(&drives)?)?;
    let amplitude = sim.amplitude()?;
    let per_image = 1 + modes.len();
    let mut models = Vec::with_capacity(s.known.len());
    let mut derivatives: Vec<Vec<Array2<f64>>> = vec![Vec::new(); modes.len()];
    for chunk in windows.chunks(per_image) {
        let p = &chunk[modes.len()];
        models.push(s.sampler.arfi_image(p, amplitude)?);
        for (m, q) in chunk[..modes.len()].iter().enumerate() {
            let cross: Vec<f64> = p.iter().zip(q).map(|(p, q)| 2.0 * (p.conj() * q).re).collect();
            derivatives[m].push(s.sampler.apply(&cross)? * amplitude);
        }
    }
    let base = s.pairs(&models.iter().collect::<Vec<_>>());
    let along: Vec<Vec<(f64, f64)>> = derivatives.iter().map(|d| s.pairs(&d.iter().collect::<Vec<_>>())).collect();
    let rows: Vec<(f64, Vec<f64>, f64)> = base
        .iter()
        .enumerate()
        .filter(|(_, (m, _))| m.is_finite())
        .map(|(i, &(m, d))| (m, along.iter().map(|a| a[i].0).collect(), d))
        .collect();
    let (md, mm) = rows.iter().fold((0.0, 0.0), |(md, mm), (m, _, d)| (md + m * d, mm + m * m));
    if !(mm > 0.0) {
        return Err(HasError::invalid("images", "have no pixel imaged in both them and the model where the model gives force"));
    }
    let scale = (md / mm).max(0.0);
    let chi2 = rows.iter().map(|(m, _, d)| (scale * m - d).powi(2)).sum::<f64>() / s.noise.powi(2);
    let j = chi2 + c.iter().map(|v| v * v).sum::<f64>();
    Ok(Linearised { c: c.to_vec(), rows, scale, chi2, j })
}

/// The Gauss–Newton curvature and gradient of `J` in `(a, c)` at `at` (the prior's identity on
/// `c`, none on `a`).
fn normal_equations(at: &Linearised, noise: f64) -> (Array2<f64>, Vec<f64>) {
    let m = at.c.len();
    let w = 1.0 / noise.powi(2);
    let mut h = Array2::<f64>::zeros((m + 1, m + 1));
    let mut gradient = vec![0.0; m + 1];
    let mut row = vec![0.0; m + 1];
    for (model, along, measured) in &at.rows {
        row[0] = *model;
        for (r, d) in row[1..].iter_mut().zip(along) {
            *r = at.scale * d;
        }
        let residual = at.scale * model - measured;
        for i in 0..=m {
            gradient[i] += w * row[i] * residual;
            for j in 0..=m {
                h[[i, j]] += w * row[i] * row[j];
            }
        }
    }
    for i in 1..=m {
        h[[i, i]] += 1.0;
        gradient[i] += at.c[i - 1];
    }
    (h, gradient)
}

/// `h⁻¹·g` for the symmetric positive definite `h`, or `None` when it is not.
fn solve(h: &Array2<f64>, g: &[f64]) -> Option<Vec<f64>> {
    let inverse = spd_inverse(h)?;
    Some((0..g.len()).map(|i| (0..g.len()).map(|j| inverse[[i, j]] * g[j]).sum()).collect())
}
