//! The per-element path of the workflow: the element search on the field basis (warm-started
//! from the array's default groups, or from the prediction of a prior), the prediction kept when
//! one acquisition cannot check it, and the assessment on the element posterior.

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::inverse::cost::{build_model, Measurement, Objective};
use crate::inverse::element::nuisance::{FittedNuisance, Nuisance};
use crate::inverse::element::view_fit::fit_view;
use crate::inverse::element::{BasisCache, ElementCost, ElementTerm};
use crate::inverse::estimate::information::{
    error_covariance, expected_focus, focal_fields, suggest_focus_shift, ShiftSuggestion, Spread, CANDIDATE_SHIFTS_MM,
};
use crate::inverse::estimate::{chi2_95, misfit, rival_solutions, Assessment, Estimate, Estimator, Minimum, Stop};
use crate::inverse::prior::smooth::SmoothErrors;
use crate::inverse::prior::{Posterior, Prior, MIN_NOISE_RAD};
use crate::phase::{phase_error, point_reflection, wrap};
use crate::simulation::Simulation;
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::prior_check::prior_check;
use super::support::element_support;
use super::{estimator, fit_groups, recommend, EstimateReport, EstimateRequest, Method, ELEMENT_EVALUATIONS, VIEW_ELEMENT_EVALUATIONS};

/// Known per-element phases closer than this (rad, RMS after the common phase,
/// [`phase_error`]) make the same acquisition. To first order a phase change of RMS `d` changes
/// the intensity anywhere by at most `2·d` of the focal value: at 1e-3 rad, 0.2 % (0.0012 rad of
/// the default scenario's 0.6 rad focal ARFI phase, a sixteenth of the paper's 0.02 rad noise).
pub const REPEAT_TOLERANCE_RAD: f64 = 1e-3;

/// Whether known per-element phases `a` and `b` make the same acquisition
/// ([`REPEAT_TOLERANCE_RAD`]).
fn repeats(a: &[f64], b: &[f64]) -> bool {
    phase_error(a, b) < REPEAT_TOLERANCE_RAD
}

/// Whether images `terms` are one acquisition: a single image, or images whose known
/// per-element phases differ only by a common phase (repeats differ only by noise).
pub fn one_acquisition(terms: &[ElementTerm]) -> bool {
    terms.windows(2).all(|w| repeats(&w[0].offset, &w[1].offset))
}

/// The estimate that keeps the prediction of `prior` (wrapped), unsearched, with its posterior
/// cost on `cost` (on the view fitted at the prediction when `nuisance` fits W or the shift).
/// A smooth prior is checked against the element `positions` as a search would check it.
///
/// Used per element for [`one_acquisition`]: one in-focus acquisition cannot check a correction
/// of a prediction. With 1024 elements, the smooth prior (0.8 rad over 15 mm) and 0.02 rad noise,
/// the posterior optimum of one in-focus image gains a little focus over the prediction on
/// average, but on some aberrations ends well below it: that optimum, the only one random starts
/// find, fits the image better than the truth does and predicts a held-out defocused image better
/// than the prediction does, so nothing in the data flags it. Keeping the prediction gives up
/// that small mean gain so as never to end below it; with a second, defocused acquisition (5 or
/// 20 mm) the search gains over the prediction. A single defocused image, or one with random
/// known phases, is kept as well, untested.
fn keep_prediction(
    cost: ElementCost,
    noise: f64,
    prior: &Prior,
    nuisance: &Nuisance,
    positions: &[[f64; 3]],
) -> Result<(Estimate, ElementCost)> {
    if prior.correlation_length().is_some() {
        SmoothErrors::new(prior, positions)?;
    }
    let cost = if nuisance.view() { fit_view(&cost, prior.mean(), nuisance, noise)? } else { cost };
    let u = Posterior::new(&cost, noise, prior)?.cost(prior.mean());
    let phases: Vec<f64> = prior.mean().iter().copied().map(wrap).collect();
    let estimate = Estimate {
        minima: vec![Minimum { phases: phases.clone(), cost: u }],
        phases,
        cost: u,
        evaluations: 0,
        seconds: 0.0,
        history: vec![u],
        stop: Stop::PredictionKept,
    };
    Ok((estimate, cost))
}

/// Rounds of the element search when W or the shift is fitted: each fits the view with the
/// phases held, then searches the phases on the fitted view with its share of the evaluations.
pub const VIEW_ROUNDS: usize = 3;

/// The element search on `cost` (on the posterior with `prior`) from `start` (phases), at most
/// `budget` evaluations; with the view in `nuisance`, [`VIEW_ROUNDS`] rounds of view fit and
/// phase search, and a last view fit at the final phases. Returns the estimate (phases) and the
/// cost on the last fitted view.
#[allow(clippy::too_many_arguments)]
fn search_elements(
    mut cost: ElementCost,
    noise: f64,
    prior: Option<&Prior>,
    start: Vec<f64>,
    nuisance: &Nuisance,
    search: &Estimator,
    budget: usize,
    positions: &[[f64; 3]],
    control: Control<'_>,
) -> Result<(Estimate, ElementCost)> {
    let smooth = prior.filter(|p| p.correlation_length().is_some()).map(|p| SmoothErrors::new(p, positions)).transpose()?;
    let to_phases = |params: &[f64]| -> Vec<f64> {
        match &smooth {
            Some(s) => s.phases(params).into_iter().map(wrap).collect(),
            None => params.to_vec(),
        }
    };
    let rounds = if nuisance.view() { VIEW_ROUNDS } else { 1 };
    let mut params = match &smooth {
        Some(s) => vec![0.0; s.n_modes()],
        None => start,
    };
    let mut done: Option<Estimate> = None;
    for round in 0..rounds {
        if nuisance.view() {
            cost = fit_view(&cost, &to_phases(&params), nuisance, noise)?;
        }
        let share = (budget * (round + 1) / rounds - budget * round / rounds).max(1);
        let search = search.clone().with_max_evaluations(share)?.with_start(params)?;
        let e = match (&smooth, prior) {
            (Some(s), _) => search.run(&s.posterior(&cost, noise)?, control)?,
            (None, Some(p)) => search.run(&Posterior::new(&cost, noise, p)?, control)?,
            (None, None) => search.run(&cost, control)?,
        };
        params = e.phases.clone();
        done = Some(match done {
            None => e,
            Some(d) => merged(d, e),
        });
    }
    if nuisance.view() {
        cost = fit_view(&cost, &to_phases(&params), nuisance, noise)?;
    }
    let estimate = done.ok_or_else(|| HasError::invalid("max_evaluations", "no element search ran"))?;
    let estimate = if smooth.is_some() { estimate.map_phases(to_phases) } else { estimate };
    Ok((estimate, cost))
}

/// Two searches one after the other as one: the later's result, both's evaluations, time and
/// histories (each on its own view: the cost may step between them).
fn merged(first: Estimate, later: Estimate) -> Estimate {
    let mut history = first.history;
    history.extend(&later.history);
    Estimate { evaluations: first.evaluations + later.evaluations, seconds: first.seconds + later.seconds, history, ..later }
}

/// Per-element estimation: the array's default groups are fitted first (the same method, and
/// the prior's group means); the group estimate spread to the elements (with a prior, the
/// prediction itself) starts L-BFGS on the element basis, at most `max_evaluations` (default
/// [`ELEMENT_EVALUATIONS`], or [`VIEW_ELEMENT_EVALUATIONS`] when W or the shift is fitted). With a prior whose errors are correlated ([`Prior::with_correlation_length`]) the
/// element stage searches only smooth corrections of the prediction
/// ([`SmoothPosterior`]). With a prior and [`one_acquisition`] the prediction is kept,
/// unsearched. The assessment is that of the group stage, or with a prior the element
/// posterior's ([`element_posterior_assessment`]), which an ambiguous one completes with the next
/// acquisition ([`suggest_focus_shift`]). Without a prior the images' support of the estimate
/// against the uncorrected beam and the group fit decides what to apply ([`element_support`]).
/// `prior`: one predicted phase per element.
///
/// With a smooth prior and the amplitude scale not fitted, an estimate whose images the model
/// cannot explain (`assessment.mismatch`) is searched again with the scale fitted
/// ([`coherence_refit`]), and that search is kept when it explains them.
pub(super) fn estimate_per_element(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    prior: Option<Prior>,
    basis: &BasisCache,
    control: Control<'_>,
) -> Result<EstimateReport> {
    let (mut report, mut cost) = search_and_assess(sim, measurements, request, prior.clone(), basis, control)?;
    if coherence_refit(&report, prior.as_ref(), request) {
        let scaled = EstimateRequest { fit_amplitude: true, ..request.clone() };
        let (refit, refit_cost) = search_and_assess(sim, measurements, &scaled, prior.clone(), basis, control)?;
        if !refit.assessment.mismatch {
            (report, cost) = (refit, refit_cost);
        }
    }
    // An ambiguous posterior comes with the acquisition that would settle it.
    if request.suggest || (prior.is_some() && report.assessment.ambiguous) {
        report.suggestion = Some(suggest_next(sim, &cost, &report, prior.as_ref())?);
    }
    Ok(report)
}

/// Whether a per-element estimate with `prior` is searched again with the amplitude scale
/// fitted: a smooth prior's searched estimate, the scale not fitted, that the model cannot
/// explain.
///
/// A smooth prior corrects the prediction by smooth fields only, so the prediction's
/// element-level error stays in the model. Independent errors of std `s` keep only the
/// coherent part of every element sum, `E[exp(i·e)] = exp(-s²/2)` in pressure: the model's
/// images are those of the corrected beam times about `exp(-s²)` (0.78 at 0.5 rad; measured on
/// the default scenario 0.78–0.82 for the in-focus and defocused images), the scattered rest
/// lying below the coherent part by the element count. With the scale fixed at 1 the smooth
/// correction bends to make up the lost height instead (1024 elements, a 20 mm screen and
/// 0.5 rad per element: the estimate stalls near 0.80 of the ideal focal pressure with a misfit
/// of 1.2–1.8 and the prediction is recommended); with the scale fitted, the images explain it
/// (misfit near 1) and the smooth correction goes to what they see.
fn coherence_refit(report: &EstimateReport, prior: Option<&Prior>, request: &EstimateRequest) -> bool {
    prior.is_some_and(|p| p.correlation_length().is_some())
        && !request.fitted_nuisance().amplitude
        && !report.kept_prediction
        && report.assessment.mismatch
}

/// The next acquisition for the per-element estimate `report` made on `cost`: the focus shift
/// whose image is expected to raise the focus most ([`suggest_focus_shift`]).
fn suggest_next(sim: &Simulation, cost: &ElementCost, report: &EstimateReport, prior: Option<&Prior>) -> Result<ShiftSuggestion> {
    let positions = sim.transducer.reference_points();
    let spread = Spread::for_prior(prior, &positions)?;
    let mut shifts = Vec::new();
    for shift in CANDIDATE_SHIFTS_MM.map(|s| s.map(|v| v * 1e-3)) {
        // After a kept prediction, a repeat of the acquisition would be kept again.
        if !(report.kept_prediction && repeats(&sim.focus_shift_phases(shift)?, &cost.terms[0].offset)) {
            shifts.push(shift);
        }
    }
    let mut next = suggest_focus_shift(sim, cost, &report.estimate.phases, report.noise.max(MIN_NOISE_RAD), &spread, &shifts)?;
    if report.kept_prediction {
        // The kept phases use the prior alone: so does the expected focus now.
        let none = Array2::zeros((sim.n_elements(), sim.n_elements()));
        next.expected_focus_now = expected_focus(&error_covariance(&none, &spread)?, &focal_fields(&cost.basis))?;
    }
    Ok(next)
}

/// The per-element search and its assessment (see [`estimate_per_element`]), without the next
/// acquisition; with the cost the estimate was made on.
fn search_and_assess(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    prior: Option<Prior>,
    basis: &BasisCache,
    control: Control<'_>,
) -> Result<(EstimateReport, ElementCost)> {
    if request.method != Method::Lbfgs {
        return Err(HasError::invalid(
            "method",
            format!(
                "per-element estimation ({} phases) runs on the gradient: use 'lbfgs', not '{}'",
                sim.n_elements(),
                request.method.name()
            ),
        ));
    }
    let positions = sim.transducer.reference_points();
    let time_limit = estimator(request, Method::Lbfgs, None)?.time_limit;
    // Without a prior the element search starts from a fit of the array's default groups (and
    // that fit's assessment is the estimate's). With one it starts from the prediction: a
    // default-group fit to element-level data pulls the group phases away from it (on a
    // 1024-element skull screen, to a start that leaves far less focus than the prediction),
    // and the assessment is the element posterior's.
    let warm_start = match &prior {
        Some(p) => WarmStart::Prediction(p),
        None => {
            let mut grouped = sim.clone();
            grouped.set_groups(sim.transducer.default_groups())?;
            let sigma = point_reflection(&positions, &grouped.groups);
            let est = estimator(request, Method::Lbfgs, sigma.clone())?;
            let mut group_model = build_model(&grouped, measurements, sim.mask_fraction, 3)?;
            group_model.noise = request.noise(group_model.noise)?;
            group_model.cost.fit_amplitude = request.fit_amplitude;
            let (group, assessment) = fit_groups(&group_model, est, None, sigma.as_deref(), request, control)?;
            WarmStart::Groups { elements: grouped.element_phases(&group.phases)?, groups: group.phases, assessment }
        }
    };
    let start = match &warm_start {
        WarmStart::Prediction(p) => p.mean().to_vec(),
        WarmStart::Groups { elements, .. } => elements.clone(),
    };
    let nuisance = request.fitted_nuisance();
    let mut model = basis.element_model(sim, measurements, sim.mask_fraction, 0, &nuisance, control)?;
    model.noise = request.noise(model.noise)?;
    let search = Estimator::lbfgs().with_starts(1)?.with_time_limit_opt(time_limit);
    let default_budget = if nuisance.view() { VIEW_ELEMENT_EVALUATIONS } else { ELEMENT_EVALUATIONS };
    let budget = request.max_evaluations.unwrap_or(default_budget);
    let single_acquisition = one_acquisition(&model.cost.terms);
    let kept_prediction = prior.is_some() && single_acquisition;
    let (elements, cost) = match &prior {
        Some(p) if kept_prediction => keep_prediction(model.cost, model.noise, p, &nuisance, &positions)?,
        _ => search_elements(model.cost, model.noise, prior.as_ref(), start, &nuisance, &search, budget, &positions, control)?,
    };
    let fitted = nuisance.any().then(|| {
        let linear = cost.linear_at(&elements.phases);
        let (w, shift) = cost.view_mm();
        FittedNuisance { fitted: nuisance, scale: linear.scale, broadening_width_mm: w, shift_mm: shift, background: linear.background }
    });
    let n_pixels = cost.n_pixels();
    // Without a prior: what the images determine, against the uncorrected beam and the group fit.
    let group_elements = match &warm_start {
        WarmStart::Groups { elements: g, .. } => Some(g.clone()),
        WarmStart::Prediction(_) => None,
    };
    let support = match &group_elements {
        Some(g) => Some(element_support(&cost, model.noise, &elements.phases, g, elements.stop)?),
        None => None,
    };
    let (group_phases, mut assessment) = match warm_start {
        WarmStart::Groups { groups, assessment, .. } => (Some(groups), assessment),
        WarmStart::Prediction(p) => {
            (None, element_posterior_assessment(&cost, model.noise, p, &elements, budget, request.threshold, request.seed, control)?)
        }
    };
    // One acquisition cannot determine a phase per element (a kept prediction says so on its
    // own), nor, without a prior, can images that determine too few combinations of phases for
    // the correction to beat the alternatives (`Support`).
    let underdetermined = single_acquisition || support.as_ref().is_some_and(|s| !s.determines());
    assessment.ambiguous |= underdetermined && !kept_prediction;
    // Misfit of the element fit itself (the group stage's cannot reach the noise on
    // element-level data).
    let image_cost = cost.cost(&elements.phases);
    let fitted_phases = if prior.is_some() { 0 } else { sim.n_elements() - 1 };
    (assessment.misfit, assessment.mismatch) = misfit(image_cost, n_pixels, fitted_phases, model.noise);
    assessment.mismatch &= !kept_prediction;
    // With a prior: do the images agree with the prediction as the prior states it? Where they
    // do not, the search's move absorbs what the model cannot form.
    let check = match &prior {
        Some(p) if !kept_prediction => Some(prior_check(&cost, model.noise, p, &positions, request.seed, request.prior_conflict_z)?),
        _ => None,
    };
    let conflict = check.as_ref().is_some_and(|c| c.conflict);
    let recommendation =
        recommend(&elements.phases, request.prior.as_ref(), (assessment.mismatch, conflict), support.as_ref(), group_elements.as_deref());
    let scale = fitted.as_ref().map_or(1.0, |n| n.scale);
    let report = EstimateReport {
        image_cost,
        nuisance: fitted,
        estimate: elements,
        assessment,
        noise: model.noise,
        n_pixels,
        scale,
        group_phases,
        underdetermined,
        kept_prediction,
        prior_used: prior.is_some(),
        suggestion: None,
        support,
        prior_check: check,
        recommendation,
    };
    Ok((report, cost))
}

/// Where a per-element search starts, and what judges its ambiguity.
enum WarmStart<'a> {
    /// The default-group estimate spread to the elements (no prior): its assessment.
    Groups { elements: Vec<f64>, groups: Vec<f64>, assessment: Assessment },
    /// The prediction of the prior: judged on the element posterior.
    Prediction(&'a Prior),
}

/// Starts of the exploration of a per-element posterior ([`element_posterior_assessment`]).
const POSTERIOR_STARTS: usize = 4;

/// Evaluations of each exploring search (at most the estimate's own budget).
const POSTERIOR_START_EVALUATIONS: usize = 60;

/// The assessment of a per-element estimate with a prior: [`POSTERIOR_STARTS`] L-BFGS searches
/// of the element posterior (independent errors of the prior's std about its mean) from seeded
/// draws of that prior; every end point whose image cost lies within `sigma²·chi²_0.95(G - 1)`
/// of the best (the margin of an estimate without a prior) is a solution the images cannot tell
/// from the estimate, and is scored, as for groups, by the focus the estimate's correction would
/// leave were it the truth (the element basis's image of their difference, peak over peak).
/// The draws sample what the prior allows; a smooth prior's starts are drawn independently per
/// element (wider than it allows: a conservative search). Misfit and mismatch are the caller's.
/// (A Gaussian approximation at the estimate does not serve: near a corrected focus the
/// focal intensity is stationary in the phases, so what its height tells of them is of second
/// order and the Fisher information misses it.)
#[allow(clippy::too_many_arguments)]
fn element_posterior_assessment(
    cost: &ElementCost,
    noise: f64,
    prior: &Prior,
    estimate: &Estimate,
    budget: usize,
    threshold: f64,
    seed: u64,
    control: Control<'_>,
) -> Result<Assessment> {
    let g = estimate.phases.len();
    let independent = Prior::new(prior.mean().to_vec(), prior.std_rad())?;
    let posterior = Posterior::new(cost, noise, &independent)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9057_e410);
    let normal = Normal::new(0.0, prior.std_rad()).map_err(|e| HasError::invalid("prior_std_rad", e.to_string()))?;
    let search = Estimator::lbfgs().with_starts(1)?.with_max_evaluations(budget.clamp(1, POSTERIOR_START_EVALUATIONS))?;
    let mut ends = vec![estimate.phases.clone()];
    for _ in 0..POSTERIOR_STARTS {
        let start: Vec<f64> = prior.mean().iter().map(|m| wrap(m + normal.sample(&mut rng))).collect();
        ends.push(search.clone().with_start(start)?.run(&posterior, control)?.phases);
    }
    // Rivals are judged on the images' cost, as without a prior.
    let points: Vec<Minimum> = ends.into_iter().map(|phases| Minimum { cost: cost.cost(&phases), phases }).collect();
    let margin = noise.max(MIN_NOISE_RAD).powi(2) * chi2_95(g.saturating_sub(1).max(1));
    let focal = |phases: &[f64]| -> Result<f64> {
        Ok(cost.basis.image(phases)?.iter().copied().filter(|v| v.is_finite()).fold(f64::MIN, f64::max))
    };
    let (candidates, worst_recovery) = rival_solutions(&points, margin, &estimate.phases, focal)?;
    Ok(Assessment {
        ambiguous: worst_recovery < threshold,
        margin,
        candidates,
        worst_recovery,
        suggested_phases: vec![0.0; g],
        suggested_separation: 0.0,
        misfit: f64::NAN,
        mismatch: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repeats_with_a_common_phase_added_are_one_acquisition() {
        let term = |offset: Vec<f64>| ElementTerm { mask: vec![0], measured: vec![0.0], offset };
        let focus = vec![0.0, 0.0, 0.0];
        let shifted = vec![0.4, 0.4, 0.4 - 2.0 * std::f64::consts::PI];
        let defocus = vec![0.0, 0.3, 1.2];
        assert!(one_acquisition(&[term(focus.clone())]));
        assert!(one_acquisition(&[term(focus.clone()), term(shifted), term(focus.clone())]));
        assert!(!one_acquisition(&[term(focus.clone()), term(defocus.clone())]));
        assert!(!one_acquisition(&[term(defocus), term(focus.clone()), term(focus)]));
    }
}
