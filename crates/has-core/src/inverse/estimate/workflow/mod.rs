//! The estimation workflow as one call: choose the method, estimate per group (on the per-pixel
//! group kernels) or per element (on the element field basis, warm-started from the array's
//! default groups), with or without a predicted aberration as prior, apply the limits, and assess
//! the answer (ambiguity, misfit, and the phases to apply). What the CLI, the Python API and Rust
//! users run. The group path is here, the per-element one in `per_element`, the recommendation in
//! `support`, the request's options by name in `options`.

mod options;
mod per_element;
mod prior_check;
mod support;

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::grouping::{self, PriorLayout};
use crate::inverse::cost::{build_model, Measurement, Model, MAX_KERNEL_GROUPS};
use crate::inverse::element::nuisance::{FittedNuisance, Nuisance};
use crate::inverse::element::BasisCache;
use crate::inverse::estimate::information::ShiftSuggestion;
use crate::inverse::estimate::{Assessment, Estimate, Estimator};
use crate::inverse::prior::{Posterior, Prior};
use crate::phase::point_reflection;
use crate::simulation::Simulation;

pub use options::{option_spec, OptionKind, OptionSpec, OptionValue, OPTIONS};
use per_element::estimate_per_element;
pub use per_element::{one_acquisition, REPEAT_TOLERANCE_RAD, VIEW_ROUNDS};
pub use prior_check::{prior_check, PriorCheck, CONFLICT_Z, PRIOR_CHECK_DRAWS};
pub use support::{converged, element_support, Recommendation, Recommended, Support, GROUPS_MARGIN};

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

/// Default evaluation limit of the per-element search. Without a prior (1024 elements, 4 images)
/// the best point's recovered focus changes by at most 0.01 and its cost by under 1 % after 150
/// evaluations (the images do not determine more); with a prior the search converges in 50–160
/// (BENCHMARKS.md, per-element estimation).
pub const ELEMENT_EVALUATIONS: usize = 200;

/// Default evaluation limit of the per-element search when W or the shift is fitted (its
/// [`VIEW_ROUNDS`] rounds share it). With the smooth prior (1024 elements, 4 images, amplitude,
/// W and backgrounds fitted) 120 evaluations end at the same focus and misfit as 200
/// (BENCHMARKS.md, nuisance fitted with the phases), and every evaluation is a cost and gradient
/// over the whole element basis.
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
    pub fit_amplitude: bool,
    /// The images' noise standard deviation (rad) where it is known, e.g. from the difference of
    /// two reference acquisitions (its standard deviation over `√2`). By default each image's
    /// floor is estimated from its background ([`crate::physics::mr::noise_floor`]), which counts
    /// any pixel-scale structure of the background as noise: through a head at 650 kHz it came
    /// out 0.024-0.025 rad for a noise of 0.02, and an estimate that lost focus against its
    /// prediction looked like a fit to the noise (misfit 0.82 instead of 1.27). The misfit, the
    /// mismatch rule, the prior check and the posterior's weights all use it.
    pub noise_rad: Option<f64>,
    /// Nuisance parameters fitted jointly with per-element phases (the amplitude also with
    /// `fit_amplitude`: see [`EstimateRequest::fitted_nuisance`]); group estimates fit the amplitude
    /// only.
    pub nuisance: Nuisance,
    /// A rival solution counts as ambiguous when it would leave less than this fraction of the
    /// ideal focus after the estimate's correction.
    pub threshold: f64,
    /// Predicted aberration (per element, or per group of the simulation; per element also
    /// per default group of the array) and its expected error: the estimate is then the
    /// posterior optimum (see [`crate::inverse::prior`]).
    pub prior: Option<Prior>,
    /// Per element with a searched prior: the prior check flags a conflict when the images'
    /// `chi²` at the prediction lies more than this many standard deviations of its null above
    /// the null's mean ([`CONFLICT_Z`] by default; [`prior_check`]).
    pub prior_conflict_z: f64,
    /// Per element: also suggest the next acquisition, the focus shift whose image is expected
    /// to raise the focus most ([`crate::inverse::estimate::information`]; a posterior covariance over all elements per
    /// candidate shift).
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
            fit_amplitude: false,
            noise_rad: None,
            nuisance: Nuisance::default(),
            threshold: 0.9,
            prior: None,
            prior_conflict_z: CONFLICT_Z,
            suggest: false,
        }
    }
}

impl EstimateRequest {
    /// The noise the costs are weighed with: `noise_rad` when given (checked: finite, > 0),
    /// else `estimated` (the images' background floor).
    pub fn noise(&self, estimated: f64) -> Result<f64> {
        match self.noise_rad {
            Some(n) => crate::error::require_positive("noise_rad", n).map(|_| n),
            None => Ok(estimated),
        }
    }

    /// Checks what the request holds on its own (the method's limits, the threshold, the noise),
    /// before any image is read: each error names its parameter. What depends on the simulation
    /// (the prior's length, modes per element) is checked by the estimate.
    pub fn check(&self) -> Result<()> {
        self.noise(1.0)?;
        if !(self.threshold.is_finite() && (0.0..=1.0).contains(&self.threshold)) {
            return Err(HasError::invalid("threshold", format!("must be a fraction of the ideal focus in [0, 1], got {}", self.threshold)));
        }
        crate::error::require_positive("prior_conflict_z", self.prior_conflict_z)?;
        let est = estimator(self, self.method, None)?;
        if let Some(n) = self.max_evaluations {
            est.with_max_evaluations(n)?;
        }
        Ok(())
    }

    /// The nuisance fitted: `nuisance`, with the amplitude also when `fit_amplitude`.
    pub fn fitted_nuisance(&self) -> Nuisance {
        Nuisance { amplitude: self.fit_amplitude || self.nuisance.amplitude, ..self.nuisance }
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
    /// The amplitude scale at the estimate: the images' amplitude over the model's (1 unless
    /// fitted: `fit_amplitude`, or per element the fitted nuisance's, its `scale`).
    pub scale: f64,
    /// The default-group warm start of a per-element estimate.
    pub group_phases: Option<Vec<f64>>,
    /// Per element, the images cannot determine a phase per element: one acquisition, or
    /// (without a prior) images that determine too few combinations of phases for the
    /// correction to be expected to beat the uncorrected beam or the group fit
    /// ([`Support::determines`]). The assessment is then marked ambiguous, unless the prediction
    /// was kept.
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
    /// Per element without a prior: what the images determine and the focus of the
    /// alternatives ([`element_support`]).
    pub support: Option<Support>,
    /// Per element with a prior (searched, not kept): whether the images agree with the
    /// prediction as the prior states it ([`prior_check`]).
    pub prior_check: Option<PriorCheck>,
    /// The phases to apply: the estimate; with a prior, the prediction when the model does not
    /// explain the images (`assessment.mismatch`) or the images conflict with the prediction as
    /// the prior states it ([`PriorCheck::conflict`]: the search's move would absorb what the model
    /// cannot form); per element without a prior, the uncorrected beam or the group fit when the
    /// images do not support the estimate ([`Support`]).
    pub recommendation: Recommendation,
}

impl EstimateReport {
    /// Whether the search converged (it did not stop at its evaluation or time limit; a kept
    /// prediction needs none).
    pub fn converged(&self) -> bool {
        converged(self.estimate.stop)
    }
}

/// The phases to apply for an estimate `phases` (see [`EstimateReport::recommendation`]): with
/// `prior` (as given) and a model `mismatch` or a `conflict` of the images with it, the
/// prediction; without a prior, per element, the alternative of an unsupported estimate
/// (`support`, with the default-group fit `groups` spread to the elements); else the estimate.
fn recommend(
    phases: &[f64],
    prior: Option<&Prior>,
    (mismatch, conflict): (bool, bool),
    support: Option<&Support>,
    groups: Option<&[f64]>,
) -> Recommendation {
    let estimate = || Recommendation { kind: Recommended::Estimate, phases: phases.to_vec() };
    match (prior, support) {
        (Some(p), _) if mismatch || conflict => Recommendation { kind: Recommended::Prediction, phases: p.mean().to_vec() },
        (None, Some(s)) if !s.supported() => match (s.alternative(), groups) {
            (Recommended::Groups, Some(g)) => Recommendation { kind: Recommended::Groups, phases: g.to_vec() },
            _ => Recommendation { kind: Recommended::Uncorrected, phases: vec![0.0; phases.len()] },
        },
        _ => estimate(),
    }
}

/// Whether the simulation's groups are its elements, one each in order.
fn per_element(sim: &Simulation) -> bool {
    grouping::one_per_element(&sim.groups)
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
/// prediction. `control`, once cancelled, ends the run with [`HasError::Interrupted`]; its
/// progress follows the element fields' marches `(done, total)`.
pub fn estimate_aberration(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    control: Control<'_>,
) -> Result<EstimateReport> {
    estimate_aberration_with(sim, measurements, request, &BasisCache::default(), control)
}

/// [`estimate_aberration`] keeping the element basis of a per-element estimate in `basis` for
/// the next estimate on the same simulation (see [`BasisCache`]).
pub fn estimate_aberration_with(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    basis: &BasisCache,
    control: Control<'_>,
) -> Result<EstimateReport> {
    request.check()?;
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
        let prior = request.prior.as_ref().map(|p| laid_out_prior(sim, p)).transpose()?;
        return estimate_per_element(sim, measurements, request, prior, basis, control);
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
    let prior = request.prior.as_ref().map(|p| laid_out_prior(sim, p)).transpose()?;
    let sigma = point_reflection(&sim.transducer.reference_points(), &sim.groups);
    let mut est = estimator(request, request.method, sigma.clone())?;
    if let Some(n) = request.max_evaluations {
        est = est.with_max_evaluations(n)?;
    }
    let mut model = build_model(sim, measurements, sim.mask_fraction, 3)?;
    model.noise = request.noise(model.noise)?;
    model.cost.fit_amplitude = request.fitted_nuisance().amplitude;
    let (estimate, assessment) = fit_groups(&model, est, prior.as_ref(), sigma.as_deref(), request, control)?;
    let recommendation = recommend(&estimate.phases, request.prior.as_ref(), (assessment.mismatch, false), None, None);
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
        support: None,
        prior_check: None,
        recommendation,
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
    control: Control<'_>,
) -> Result<(Estimate, Assessment)> {
    let Some(prior) = prior else {
        let estimate = est.run(&model.cost, control)?;
        let assessment = estimate.assess(model, sigma, request.threshold, request.seed)?;
        return Ok((estimate, assessment));
    };
    let posterior = Posterior::new(&model.cost, model.noise, prior)?;
    let est = if est.start.is_some() { est } else { est.with_start(prior.mean().to_vec())? };
    let estimate = est.run(&posterior, control)?;
    let assessment = estimate.assess_posterior(&posterior, model, sigma, request.threshold, request.seed)?;
    Ok((estimate, assessment))
}

/// The prior on the estimate's phases ([`grouping::prior_layout`]): per element for a
/// per-element estimate (one given per default group spread over its elements, as known phases
/// are); per group for a group estimate (one given per element condensed to each group's
/// circular mean).
fn laid_out_prior(sim: &Simulation, prior: &Prior) -> Result<Prior> {
    let default = sim.transducer.default_groups();
    match grouping::prior_layout("prior", prior.mean().len(), &sim.groups, sim.n_groups, &default)? {
        PriorLayout::PerDefaultGroup => prior.with_mean(default.iter().map(|&g| prior.mean()[g]).collect()),
        PriorLayout::PerElement if !per_element(sim) => prior.condensed(&sim.groups),
        PriorLayout::PerElement | PriorLayout::PerGroup => Ok(prior.clone()),
    }
}
