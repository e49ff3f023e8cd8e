//! The estimation workflow as one call: choose the method, estimate per group (on the per-pixel
//! group kernels) or per element (on the element field basis, warm-started from the array's
//! default groups), with or without a predicted aberration as prior, apply the limits, and assess
//! the answer (ambiguity, misfit). What the CLI, the Python API and Rust users run.

use crate::error::{HasError, Result};
use crate::inverse::basis::{known_per_element, BasisCache, ElementCost, ElementTerm};
use crate::inverse::cost::{build_model, Measurement, Model, Objective, MAX_KERNEL_GROUPS};
use crate::inverse::estimate::{chi2_95, misfit, rival_solutions, Assessment, Estimate, Estimator, Minimum, Stop};
use crate::inverse::information::{
    error_covariance, expected_focus, focal_fields, suggest_focus_shift, ShiftSuggestion, Spread, CANDIDATE_SHIFTS_MM,
};
use crate::inverse::nuisance::{FittedNuisance, Nuisance};
use crate::inverse::phase::{phase_error, point_reflection, wrap};
use crate::inverse::prior::{Posterior, Prior, MIN_NOISE_RAD};
use crate::inverse::smooth_prior::SmoothErrors;
use crate::inverse::view_fit::fit_view;
use crate::simulation::Simulation;
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::sync::atomic::AtomicBool;

/// The optimiser.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The paper's: Nelder–Mead from zero phases.
    NelderMead,
    /// Particle swarm.
    ParticleSwarm,
    /// L-BFGS with the analytic gradient from seeded starts (and the twins of its minima).
    Lbfgs,
}

impl Method {
    /// Every optimiser, in the order the names are listed to users.
    pub const ALL: [Method; 3] = [Method::NelderMead, Method::ParticleSwarm, Method::Lbfgs];

    /// Parses a name of [`Method::name`] (`"nelder-mead"`, `"pso"` or `"lbfgs"`).
    pub fn parse(name: &str) -> Result<Self> {
        Method::ALL.into_iter().find(|m| m.name() == name).ok_or_else(|| {
            let names: Vec<String> = Method::ALL.iter().map(|m| format!("'{}'", m.name())).collect();
            HasError::invalid("method", format!("must be one of {}, got '{name}'", names.join(", ")))
        })
    }

    /// The name [`Method::parse`] reads.
    pub fn name(&self) -> &'static str {
        match self {
            Method::NelderMead => "nelder-mead",
            Method::ParticleSwarm => "pso",
            Method::Lbfgs => "lbfgs",
        }
    }
}

/// Default evaluation limit of the per-element search. Measured 2026-11-24 without a prior (1024
/// elements, 4 images, seeds 0–2): after 150 evaluations the best point's recovered focus
/// changed by at most 0.01 and its cost by under 1 % (the images do not determine more); with a
/// prior the search converges in 50–160.
pub const ELEMENT_EVALUATIONS: usize = 200;

/// Default evaluation limit of the per-element search when W or the shift is fitted (its
/// [`VIEW_ROUNDS`] rounds share it). Measured 2026-11-25 with the smooth prior (1024 elements, 4
/// images, amplitude, W and backgrounds fitted, seeds 1–2): 120 evaluations end at the same
/// focus (0.881, 0.879) and misfit (1.002, 1.004) as 200, in 51–54 s against 67–74 s.
pub const VIEW_ELEMENT_EVALUATIONS: usize = 120;

/// What to estimate with: the method and its limits (each `None`: the method's default).
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateRequest {
    /// The search method and its settings.
    pub method: Method,
    /// Evaluation limit (defaults: Nelder–Mead and particle swarm 8000, L-BFGS 40 000 over all
    /// starts, per element [`ELEMENT_EVALUATIONS`] on the element basis, or
    /// [`VIEW_ELEMENT_EVALUATIONS`] when W or the shift is fitted).
    pub max_evaluations: Option<usize>,
    /// Wall-clock limit per stage (s).
    pub time_limit_s: Option<f64>,
    /// Seed of the random starts, the swarm and the ambiguity assessment.
    pub seed: u64,
    /// L-BFGS starts (default 20).
    pub starts: Option<usize>,
    /// Fit a free amplitude scale too.
    pub fit_scale: bool,
    /// Nuisance parameters fitted jointly with per-element phases (the amplitude also with
    /// `fit_scale`: see [`EstimateRequest::fitted_nuisance`]); group estimates fit the amplitude
    /// only.
    pub nuisance: Nuisance,
    /// A rival solution counts as ambiguous when it would leave less than this fraction of the
    /// ideal focus after the estimate's correction.
    pub threshold: f64,
    /// Predicted aberration (per element, or per group of the simulation; per element also
    /// per default group of the array) and its expected error: the estimate is then the
    /// posterior optimum (see [`crate::inverse::prior`]).
    pub prior: Option<Prior>,
    /// Per element: also suggest the next acquisition, the focus shift whose image is expected
    /// to raise the focus most ([`crate::inverse::information`]; about 10 s for 1024 elements).
    pub suggest: bool,
}

impl Default for EstimateRequest {
    fn default() -> Self {
        EstimateRequest {
            method: Method::Lbfgs,
            max_evaluations: None,
            time_limit_s: None,
            seed: 0,
            starts: None,
            fit_scale: false,
            nuisance: Nuisance::default(),
            threshold: 0.9,
            prior: None,
            suggest: false,
        }
    }
}

impl EstimateRequest {
    /// The nuisance fitted: `nuisance`, with the amplitude also when `fit_scale`.
    pub fn fitted_nuisance(&self) -> Nuisance {
        Nuisance { amplitude: self.fit_scale || self.nuisance.amplitude, ..self.nuisance }
    }
}

/// An estimate with what it rests on.
#[derive(Debug, Clone)]
pub struct EstimateReport {
    /// One phase per group of the simulation (per element when its groups are its elements).
    pub estimate: Estimate,
    /// Ambiguity and misfit, judged on the group model (per element: ambiguity on the warm
    /// start's default groups, or with a prior on the element posterior; misfit on the elements).
    pub assessment: Assessment,
    /// Noise standard deviation of the image backgrounds (rad): the noise floor of the costs.
    pub noise: f64,
    /// Pixels the estimate was fitted on.
    pub n_pixels: usize,
    /// The fitted amplitude scale (1 unless `fit_scale`; per element: 1).
    pub scale: f64,
    /// The default-group warm start of a per-element estimate.
    pub group_phases: Option<Vec<f64>>,
    /// Per element, the images cannot determine a phase per element: one acquisition, or
    /// (without a prior) fewer masked pixels than phases. The assessment is then marked
    /// ambiguous, unless the prediction was kept.
    pub underdetermined: bool,
    /// Per element with a prior from one acquisition: the estimate is the prediction itself,
    /// unsearched (see [`one_acquisition`]); `misfit` then measures the prediction against the
    /// image, and the mismatch is not judged.
    pub kept_prediction: bool,
    /// Whether a prior entered the estimate (then the assessment is judged on the posterior).
    pub prior_used: bool,
    /// The images' cost of paper Eq. 4 at the estimate (rad²): `estimate.cost` without a prior;
    /// with one, `estimate.cost` is the negative log posterior.
    pub image_cost: f64,
    /// The fitted nuisance values of a per-element estimate that fitted any.
    pub nuisance: Option<FittedNuisance>,
    /// The next acquisition of a per-element estimate made with `suggest`.
    pub suggestion: Option<ShiftSuggestion>,
}

/// Whether the simulation's groups are its elements, one each in order.
fn per_element(sim: &Simulation) -> bool {
    sim.n_groups == sim.n_elements() && sim.groups.iter().enumerate().all(|(e, &g)| e == g)
}

/// The estimator of `request` for groups paired by the point reflection `sigma`.
fn estimator(request: &EstimateRequest, method: Method, sigma: Option<Vec<usize>>) -> Result<Estimator> {
    let mut est = match method {
        Method::NelderMead => Estimator::nelder_mead(),
        Method::ParticleSwarm => Estimator::particle_swarm(),
        Method::Lbfgs => Estimator::lbfgs().with_twins(sigma),
    }
    .with_seed(request.seed);
    if let Some(t) = request.time_limit_s {
        est = est.with_time_limit(t)?;
    }
    if let Some(n) = request.starts {
        est = est.with_starts(n)?;
    }
    Ok(est)
}

/// Estimates the aberration of `sim`'s groups from `measurements` (each image with its known
/// added phases): per group on the group kernels (at most [`MAX_KERNEL_GROUPS`] groups), or, when
/// the groups are the elements, per element with L-BFGS on the element basis warm-started from
/// the default groups. With a prior, every stage minimises the posterior and starts from the
/// prediction. `cancel`, when set by another thread, ends the run with
/// [`HasError::Interrupted`]; `progress(done, total)` follows the element fields' marches.
pub fn estimate_aberration(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    cancel: Option<&AtomicBool>,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<EstimateReport> {
    estimate_aberration_with(sim, measurements, request, &BasisCache::default(), cancel, progress)
}

/// [`estimate_aberration`] keeping the element basis of a per-element estimate in `basis` for
/// the next estimate on the same simulation (see [`BasisCache`]).
pub fn estimate_aberration_with(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    basis: &BasisCache,
    cancel: Option<&AtomicBool>,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<EstimateReport> {
    if let Some(p) = request.prior.as_ref().filter(|p| !p.modes().is_empty()) {
        if !per_element(sim) {
            return Err(HasError::invalid(
                "prior_modes",
                format!("are fitted by per-element estimates only (one group per element, {})", sim.n_elements()),
            ));
        }
        if p.correlation_length().is_none() {
            return Err(HasError::invalid(
                "prior_modes",
                "need a correlation length (prior_correlation_mm): the modes are fitted with the prior's smooth corrections",
            ));
        }
        if let Some(g) = p.modes().iter().find(|g| g.len() != sim.n_elements()) {
            return Err(HasError::invalid(
                "prior_modes",
                format!("have {} values each; expected {} (one per element)", g.len(), sim.n_elements()),
            ));
        }
    }
    if per_element(sim) {
        let prior = request.prior.as_ref().map(|p| element_prior(sim, p)).transpose()?;
        return estimate_per_element(sim, measurements, request, prior, basis, cancel, progress);
    }
    if sim.n_groups > MAX_KERNEL_GROUPS {
        return Err(HasError::invalid(
            "groups",
            format!(
                "{} groups; the group kernels take at most {MAX_KERNEL_GROUPS}, or one group per element ({}) for per-element estimation",
                sim.n_groups,
                sim.n_elements()
            ),
        ));
    }
    let view = Nuisance { amplitude: false, ..request.nuisance };
    if view.any() {
        return Err(HasError::invalid(
            "fit_nuisance",
            format!(
                "fitting {} needs a per-element estimate (one group per element, {}); a group estimate fits the amplitude only",
                view.names().join(", "),
                sim.n_elements()
            ),
        ));
    }
    let prior = request.prior.as_ref().map(|p| group_prior(sim, p)).transpose()?;
    let sigma = point_reflection(&sim.transducer.reference_points(), &sim.groups);
    let mut est = estimator(request, request.method, sigma.clone())?;
    if let Some(n) = request.max_evaluations {
        est = est.with_max_evaluations(n)?;
    }
    let mut model = build_model(sim, measurements, sim.mask_fraction, 3)?;
    model.cost.fit_scale = request.fitted_nuisance().amplitude;
    let (estimate, assessment) = fit_groups(&model, est, prior.as_ref(), sigma.as_deref(), request, cancel)?;
    Ok(EstimateReport {
        n_pixels: model.cost.n_pixels(),
        scale: model.cost.scale(&estimate.phases),
        image_cost: model.cost.cost(&estimate.phases),
        estimate,
        assessment,
        noise: model.noise,
        group_phases: None,
        underdetermined: false,
        kept_prediction: false,
        prior_used: prior.is_some(),
        nuisance: None,
        suggestion: None,
    })
}

/// Runs `est` on the group cost of `model` (on its posterior with `prior`, from the prediction)
/// and assesses the estimate on the same objective.
fn fit_groups(
    model: &Model,
    est: Estimator,
    prior: Option<&Prior>,
    sigma: Option<&[usize]>,
    request: &EstimateRequest,
    cancel: Option<&AtomicBool>,
) -> Result<(Estimate, Assessment)> {
    let Some(prior) = prior else {
        let estimate = est.run(&model.cost, cancel)?;
        let assessment = estimate.assess(model, sigma, request.threshold, request.seed)?;
        return Ok((estimate, assessment));
    };
    let posterior = Posterior::new(&model.cost, model.noise, prior)?;
    let est = if est.start.is_some() { est } else { est.with_start(prior.mean().to_vec())? };
    let estimate = est.run(&posterior, cancel)?;
    let assessment = estimate.assess_posterior(&posterior, model, sigma, request.threshold, request.seed)?;
    Ok((estimate, assessment))
}

/// The prior on `sim`'s groups: as given (one per group), or each group's circular mean of a
/// per-element prior.
fn group_prior(sim: &Simulation, prior: &Prior) -> Result<Prior> {
    match prior.mean().len() {
        n if n == sim.n_groups => Ok(prior.clone()),
        n if n == sim.n_elements() => prior.condensed(&sim.groups),
        n => Err(HasError::invalid(
            "prior",
            format!("has {n} values; expected {} (one per element) or {} (one per group)", sim.n_elements(), sim.n_groups),
        )),
    }
}

/// The prior per element: as given, or spread from the groups (or the array's default groups)
/// as known phases are ([`known_per_element`]).
fn element_prior(sim: &Simulation, prior: &Prior) -> Result<Prior> {
    let mean = known_per_element(sim, prior.mean()).map_err(|e| match e {
        HasError::InvalidParameter { reason, .. } => HasError::invalid("prior", reason),
        e => e,
    })?;
    prior.with_mean(mean)
}

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
/// of a prediction. Measured 2026-11-25 (1024 elements, the smooth prior 0.8 rad over 15 mm,
/// 0.02 rad, seeds 1–6): the posterior optimum left 0.53, 0.85, 0.83, 0.82, 0.86, 0.85 of the
/// ideal focus against the prediction's 0.72, 0.72, 0.74, 0.70, 0.83, 0.83 (mean 0.79 against
/// 0.76). Seed 1's optimum is the only one from six random starts, fits the image better than
/// the truth does, and predicts a held-out defocused image better than the prediction does:
/// nothing in the data flags it. Keeping the prediction gives up that small mean gain so as
/// never to end below it; with a second, defocused acquisition (5 or 20 mm) all six seeds gained
/// (0.83–0.91). A single defocused image, or one with random known phases, is kept as well: not
/// measured.
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
    cancel: Option<&AtomicBool>,
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
            (Some(s), _) => search.run(&s.posterior(&cost, noise)?, cancel)?,
            (None, Some(p)) => search.run(&Posterior::new(&cost, noise, p)?, cancel)?,
            (None, None) => search.run(&cost, cancel)?,
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
/// acquisition ([`suggest_focus_shift`]). `prior`: one predicted phase per element.
fn estimate_per_element(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    prior: Option<Prior>,
    basis: &BasisCache,
    cancel: Option<&AtomicBool>,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<EstimateReport> {
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
    // default-group fit to element-level data pulls the group phases away from it (measured
    // seed 1 of a 1024-element skull screen: the group posterior's spread 0.27 of the ideal
    // focus against the prediction's 0.84), and the assessment is the element posterior's.
    let warm_start = match &prior {
        Some(p) => WarmStart::Prediction(p),
        None => {
            let mut grouped = sim.clone();
            grouped.set_groups(sim.transducer.default_groups())?;
            let sigma = point_reflection(&positions, &grouped.groups);
            let est = estimator(request, Method::Lbfgs, sigma.clone())?;
            let mut group_model = build_model(&grouped, measurements, sim.mask_fraction, 3)?;
            group_model.cost.fit_scale = request.fit_scale;
            let (group, assessment) = fit_groups(&group_model, est, None, sigma.as_deref(), request, cancel)?;
            WarmStart::Groups { elements: grouped.element_phases(&group.phases)?, groups: group.phases, assessment }
        }
    };
    let start = match &warm_start {
        WarmStart::Prediction(p) => p.mean().to_vec(),
        WarmStart::Groups { elements, .. } => elements.clone(),
    };
    let nuisance = request.fitted_nuisance();
    let model = basis.element_model(sim, measurements, sim.mask_fraction, 0, &nuisance, progress, cancel)?;
    let search = Estimator::lbfgs().with_starts(1)?.with_time_limit_opt(time_limit);
    let default_budget = if nuisance.view() { VIEW_ELEMENT_EVALUATIONS } else { ELEMENT_EVALUATIONS };
    let budget = request.max_evaluations.unwrap_or(default_budget);
    let single_acquisition = one_acquisition(&model.cost.terms);
    let kept_prediction = prior.is_some() && single_acquisition;
    let (elements, cost) = match &prior {
        Some(p) if kept_prediction => keep_prediction(model.cost, model.noise, p, &nuisance, &positions)?,
        _ => search_elements(model.cost, model.noise, prior.as_ref(), start, &nuisance, &search, budget, &positions, cancel)?,
    };
    let fitted = nuisance.any().then(|| {
        let linear = cost.linear_at(&elements.phases);
        let (w, shift) = cost.view_mm();
        FittedNuisance { fitted: nuisance, scale: linear.scale, broadening_width_mm: w, shift_mm: shift, background: linear.background }
    });
    let n_pixels = cost.n_pixels();
    let (group_phases, mut assessment) = match warm_start {
        WarmStart::Groups { groups, assessment, .. } => (Some(groups), assessment),
        WarmStart::Prediction(p) => {
            (None, element_posterior_assessment(&cost, model.noise, p, &elements, budget, request.threshold, request.seed, cancel)?)
        }
    };
    // One acquisition cannot determine a phase per element (a kept prediction says so on its
    // own), nor, without a prior, can fewer masked pixels than phases.
    let underdetermined = single_acquisition || (prior.is_none() && n_pixels < sim.n_elements());
    assessment.ambiguous |= underdetermined && !kept_prediction;
    // Misfit of the element fit itself (the group stage's cannot reach the noise on
    // element-level data).
    let image_cost = cost.cost(&elements.phases);
    let fitted_phases = if prior.is_some() { 0 } else { sim.n_elements() - 1 };
    (assessment.misfit, assessment.mismatch) = misfit(image_cost, n_pixels, fitted_phases, model.noise);
    assessment.mismatch &= !kept_prediction;
    // An ambiguous posterior comes with the acquisition that would settle it.
    let suggestion = if request.suggest || (prior.is_some() && assessment.ambiguous) {
        let spread = Spread::for_prior(prior.as_ref(), &positions)?;
        let mut shifts = Vec::new();
        for shift in CANDIDATE_SHIFTS_MM.map(|s| s.map(|v| v * 1e-3)) {
            // After a kept prediction, a repeat of the acquisition would be kept again.
            if !(kept_prediction && repeats(&sim.focus_shift_phases(shift)?, &cost.terms[0].offset)) {
                shifts.push(shift);
            }
        }
        let mut next = suggest_focus_shift(sim, &cost, &elements.phases, model.noise.max(MIN_NOISE_RAD), &spread, &shifts)?;
        if kept_prediction {
            // The kept phases use the prior alone: so does the expected focus now.
            let none = Array2::zeros((sim.n_elements(), sim.n_elements()));
            next.expected_focus_now = expected_focus(&error_covariance(&none, &spread)?, &focal_fields(&cost.basis))?;
        }
        Some(next)
    } else {
        None
    };
    Ok(EstimateReport {
        image_cost,
        nuisance: fitted,
        estimate: elements,
        assessment,
        noise: model.noise,
        n_pixels,
        scale: 1.0,
        group_phases,
        underdetermined,
        kept_prediction,
        prior_used: prior.is_some(),
        suggestion,
    })
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
    cancel: Option<&AtomicBool>,
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
        ends.push(search.clone().with_start(start)?.run(&posterior, cancel)?.phases);
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
