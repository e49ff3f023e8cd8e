//! The fit of the MR view (broadening width W, registration shift) of a per-element cost with
//! the phases held: Nelder–Mead on fixed `|p|²`, the scale and backgrounds projected out (see
//! [`crate::inverse::element::nuisance`]).

use crate::error::{HasError, Result};
use crate::inverse::element::nuisance::{width_reach, Nuisance, SHIFT_REACH_MM};
use crate::inverse::element::ElementCost;
use argmin::core::{CostFunction, Error as ArgminError, Executor, State};
use argmin::solver::neldermead::NelderMead;

/// Nelder–Mead iterations of one view fit.
const VIEW_ITERATIONS: u64 = 200;

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
