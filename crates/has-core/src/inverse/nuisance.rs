//! Nuisance parameters of the MR-ARFI image fitted jointly with per-element phases: what an
//! independent measurement differs in besides the aberration (found with the
//! model-discrepancy workflow, [`crate::inverse::diagnose`], whose effect names they share).
//!
//! - `amplitude`: one scale on the force-to-phase amplitude for all images;
//! - `background_phase`: per image, a constant plus a linear ramp `b0 + bu·u + bv·v` (u, v the
//!   pixel centres in mm): each acquisition has its own drift;
//! - `broadening`: the width W of the Gaussian broadening (paper Eq. 2–3);
//! - `registration_shift`: an in-plane offset of the images against the model.
//!
//! The scale and the background enter the image linearly and are solved by least squares inside
//! every cost evaluation (variable projection: the phase gradient at the projected optimum is the
//! gradient with them held fixed). W and the shift change the sampling of the recorded
//! `|p|²`: they are fitted by Nelder–Mead with the phases held, alternating with the phase search
//! ([`fit_view`]); each of their evaluations re-samples fixed `|p|²` (no matrix products over
//! the element basis).

use crate::error::{HasError, Result};
use crate::inverse::basis::ElementCost;
use argmin::core::{CostFunction, Error as ArgminError, Executor, State};
use argmin::solver::neldermead::NelderMead;

/// Largest broadening width fitted, as a multiple of the model's (and at least the model's plus
/// [`WIDTH_REACH_MIN_MM`]): the element basis records the window this reach needs.
pub const WIDTH_REACH_FACTOR: f64 = 1.5;
/// Smallest reach above the model's broadening width (mm).
pub const WIDTH_REACH_MIN_MM: f64 = 1.0;
/// Largest registration shift fitted along each image axis (mm).
pub const SHIFT_REACH_MM: f64 = 2.0;
/// Nelder–Mead iterations of one view fit.
const VIEW_ITERATIONS: u64 = 200;

/// Which nuisance parameters to fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Nuisance {
    /// One amplitude scale for all images.
    pub amplitude: bool,
    /// The broadening width W.
    pub broadening: bool,
    /// An in-plane registration shift (u, v).
    pub registration_shift: bool,
    /// A background plane per image.
    pub background_phase: bool,
}

impl Nuisance {
    /// The names accepted, in the order reported.
    pub const NAMES: [&'static str; 4] = ["amplitude", "broadening", "registration_shift", "background_phase"];

    /// Every nuisance parameter.
    pub fn all() -> Self {
        Nuisance { amplitude: true, broadening: true, registration_shift: true, background_phase: true }
    }

    /// Parses effect names (those of [`Nuisance::NAMES`], or `"all"`); an unknown name is an error
    /// naming `fit_nuisance`.
    pub fn parse<S: AsRef<str>>(names: &[S]) -> Result<Self> {
        let mut n = Nuisance::default();
        for name in names {
            match name.as_ref() {
                "amplitude" => n.amplitude = true,
                "broadening" => n.broadening = true,
                "registration_shift" => n.registration_shift = true,
                "background_phase" => n.background_phase = true,
                "all" => n = Nuisance::all(),
                other => {
                    return Err(HasError::invalid(
                        "fit_nuisance",
                        format!("unknown nuisance parameter \"{other}\"; expected some of {} or \"all\"", Nuisance::NAMES.join(", ")),
                    ))
                }
            }
        }
        Ok(n)
    }

    /// The names of the parameters fitted, in [`Nuisance::NAMES`] order.
    pub fn names(&self) -> Vec<&'static str> {
        let on = [self.amplitude, self.broadening, self.registration_shift, self.background_phase];
        Nuisance::NAMES.iter().zip(on).filter(|(_, o)| *o).map(|(n, _)| *n).collect()
    }

    /// Whether anything is fitted.
    pub fn any(&self) -> bool {
        !self.names().is_empty()
    }

    /// Whether the view (W or the shift) is fitted: the basis then records a wider window.
    pub fn view(&self) -> bool {
        self.broadening || self.registration_shift
    }
}

/// The fitted nuisance values (model values for those not fitted).
#[derive(Debug, Clone, PartialEq)]
pub struct FittedNuisance {
    /// The parameters that were fitted.
    pub fitted: Nuisance,
    /// Scale on the amplitude (1 = the model's).
    pub scale: f64,
    /// Broadening width W (mm).
    pub broadening_width_mm: f64,
    /// Registration shift along u and v (mm): the image content sits this far from the model's.
    pub shift_mm: [f64; 2],
    /// Per image: background offset (rad) and slopes along u and v (rad/mm).
    pub background: Vec<[f64; 3]>,
}

/// The largest broadening width (m) fitted for a model width `width` (m).
pub fn width_reach(width: f64) -> f64 {
    (WIDTH_REACH_FACTOR * width).max(width + WIDTH_REACH_MIN_MM * 1e-3)
}

/// Fits the view parameters that `nuisance` enables (W, shift) to the images with `phases`
/// held, from the view of `cost`, with the scale and background projected out in every
/// evaluation; returns the cost on the fitted view. W stays within `[0, width_reach(W_model)]`
/// and each shift within ±[`SHIFT_REACH_MM`] (the reach of the basis' window); the search stops
/// when its costs agree to 10⁻³ of `noise_rad²`.
pub fn fit_view(cost: &ElementCost, phases: &[f64], nuisance: &Nuisance, noise_rad: f64) -> Result<ElementCost> {
    if !nuisance.view() {
        return Ok(cost.clone());
    }
    let powers = cost.powers(phases);
    let start = cost.view_mm();
    let problem = ViewProblem { cost, powers: &powers, nuisance, start, max_width_mm: width_reach(cost.model_width()) * 1e3 };
    let x0 = vec![0.0; problem.n()];
    let mut simplex = vec![x0.clone()];
    for i in 0..x0.len() {
        let mut y = x0.clone();
        y[i] = VIEW_STEP_MM;
        simplex.push(y);
    }
    // Costs matter to a small fraction of sigma² (a change of 1 sigma² is a chi² unit).
    let tolerance = 1e-3 * noise_rad.max(1e-4).powi(2);
    let solver = NelderMead::new(simplex).with_sd_tolerance(tolerance).map_err(|e| HasError::invalid("fit_nuisance", e.to_string()))?;
    let res = Executor::new(problem.clone(), solver)
        .configure(|s| s.max_iters(VIEW_ITERATIONS))
        .run()
        .map_err(|e| HasError::invalid("fit_nuisance", e.to_string()))?;
    let best = res.state().get_best_param().cloned().unwrap_or(x0);
    let (widths, shift) = problem.view(&best);
    cost.with_view(widths, shift)
}

/// Initial simplex step of W and the shift (mm).
const VIEW_STEP_MM: f64 = 0.3;

/// The view fit: parameters are offsets (mm) from the starting view, W first when fitted.
#[derive(Clone)]
struct ViewProblem<'a> {
    cost: &'a ElementCost,
    powers: &'a [Vec<f64>],
    nuisance: &'a Nuisance,
    /// Starting W and shift (mm).
    start: (f64, [f64; 2]),
    max_width_mm: f64,
}

impl ViewProblem<'_> {
    fn n(&self) -> usize {
        usize::from(self.nuisance.broadening) + 2 * usize::from(self.nuisance.registration_shift)
    }

    /// Widths and shift (m) at parameters `x`.
    fn view(&self, x: &[f64]) -> ([f64; 2], [f64; 2]) {
        let mut it = x.iter();
        let (mut w, mut shift) = self.start;
        if self.nuisance.broadening {
            w += it.next().copied().unwrap_or(0.0);
        }
        if self.nuisance.registration_shift {
            shift[0] += it.next().copied().unwrap_or(0.0);
            shift[1] += it.next().copied().unwrap_or(0.0);
        }
        ([w * 1e-3; 2], shift.map(|s| s * 1e-3))
    }

    fn inside(&self, widths: [f64; 2], shift: [f64; 2]) -> bool {
        let w_mm = widths[0] * 1e3;
        (0.0..=self.max_width_mm).contains(&w_mm) && shift.iter().all(|s| (s * 1e3).abs() <= SHIFT_REACH_MM)
    }
}

/// Returned outside the bounds or where the model cannot be evaluated (Nelder–Mead needs a
/// finite cost).
const PENALTY: f64 = 1e30;

impl CostFunction for ViewProblem<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, ArgminError> {
        let (widths, shift) = self.view(x);
        if !self.inside(widths, shift) {
            return Ok(PENALTY);
        }
        let c = self.cost.with_view(widths, shift).map(|c| c.cost_of_powers(self.powers)).unwrap_or(PENALTY);
        Ok(if c.is_finite() { c } else { PENALTY })
    }
}
