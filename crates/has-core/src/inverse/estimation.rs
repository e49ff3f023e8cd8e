//! The estimation workflow as one call: choose the method, estimate per group (on the per-pixel
//! group kernels) or per element (on the element field basis, warm-started from the array's
//! default groups), apply the limits, and assess the answer (ambiguity, misfit). What the CLI,
//! the Python API and Rust users run.

use crate::error::{HasError, Result};
use crate::inverse::basis::estimate_elements;
use crate::inverse::cost::{build_model, Measurement, Model, MAX_KERNEL_GROUPS};
use crate::inverse::estimate::{Assessment, Estimate, Estimator};
use crate::inverse::phase::point_reflection;
use crate::simulation::Simulation;
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
    /// Parses `"nelder-mead"`, `"pso"` or `"lbfgs"`.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "nelder-mead" => Ok(Method::NelderMead),
            "pso" => Ok(Method::ParticleSwarm),
            "lbfgs" => Ok(Method::Lbfgs),
            m => Err(HasError::invalid("method", format!("must be 'nelder-mead', 'pso' or 'lbfgs', got '{m}'"))),
        }
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

/// What to estimate with: the method and its limits (each `None`: the method's default).
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateRequest {
    /// The search method and its settings.
    pub method: Method,
    /// Evaluation limit (defaults: Nelder–Mead and particle swarm 8000, L-BFGS 40 000 over all
    /// starts, per element 500 on the element basis).
    pub max_evaluations: Option<usize>,
    /// Wall-clock limit per stage (s).
    pub time_limit_s: Option<f64>,
    /// Seed of the random starts, the swarm and the ambiguity assessment.
    pub seed: u64,
    /// L-BFGS starts (default 20).
    pub starts: Option<usize>,
    /// Fit a free amplitude scale too.
    pub fit_scale: bool,
    /// A rival solution counts as ambiguous when it would leave less than this fraction of the
    /// ideal focus after the estimate's correction.
    pub threshold: f64,
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
            threshold: 0.9,
        }
    }
}

/// An estimate with what it rests on.
#[derive(Debug, Clone)]
pub struct EstimateReport {
    /// One phase per group of the simulation (per element when its groups are its elements).
    pub estimate: Estimate,
    /// Ambiguity and misfit, judged on the group model (for per-element estimates, on the
    /// warm start's default groups).
    pub assessment: Assessment,
    /// The group model the assessment used (masks, noise, kernels).
    pub model: Model,
    /// Pixels the estimate was fitted on.
    pub n_pixels: usize,
    /// The fitted amplitude scale (1 unless `fit_scale`; per element: 1).
    pub scale: f64,
    /// The default-group warm start of a per-element estimate.
    pub group_phases: Option<Vec<f64>>,
    /// Fewer masked pixels than phases (one image, per element): the data cannot determine it,
    /// and the assessment is marked ambiguous.
    pub underdetermined: bool,
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
/// the default groups. `cancel`, when set by another thread, ends the run with
/// [`HasError::Interrupted`]; `progress(done, total)` follows the element fields' marches.
pub fn estimate_aberration(
    sim: &Simulation,
    measurements: &[Measurement],
    request: &EstimateRequest,
    cancel: Option<&AtomicBool>,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<EstimateReport> {
    let positions: Vec<[f64; 3]> = sim.transducer.elements.iter().map(|e| e.reference_point()).collect();
    if per_element(sim) {
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
        let sigma = point_reflection(&positions, &sim.transducer.default_groups());
        let warm = estimator(request, Method::Lbfgs, sigma.clone())?;
        let r = estimate_elements(sim, measurements, &warm, request.max_evaluations.unwrap_or(500), request.fit_scale, cancel, progress)?;
        let mut assessment = r.group.assess(&r.group_model, sigma.as_deref(), request.threshold, request.seed)?;
        let n_pixels = r.model.cost.n_pixels();
        // One image's masked pixels cannot determine more phases than they number.
        let underdetermined = n_pixels < sim.n_elements();
        assessment.ambiguous |= underdetermined;
        return Ok(EstimateReport {
            estimate: r.elements,
            assessment,
            model: r.group_model,
            n_pixels,
            scale: 1.0,
            group_phases: Some(r.group.phases),
            underdetermined,
        });
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
    let sigma = point_reflection(&positions, &sim.groups);
    let mut est = estimator(request, request.method, sigma.clone())?;
    if let Some(n) = request.max_evaluations {
        est = est.with_max_evaluations(n)?;
    }
    let mut model = build_model(sim, measurements, sim.mask_fraction, 3)?;
    model.cost.fit_scale = request.fit_scale;
    let estimate = est.run(&model.cost, cancel)?;
    let assessment = estimate.assess(&model, sigma.as_deref(), request.threshold, request.seed)?;
    Ok(EstimateReport {
        n_pixels: model.cost.n_pixels(),
        scale: model.cost.scale(&estimate.phases),
        estimate,
        assessment,
        model,
        group_phases: None,
        underdetermined: false,
    })
}
