//! Hybrid estimation of the phase aberration (paper loop 1, and its multi-image extension).
//!
//! Estimators are values configured with validated `with_*` builders and run through argmin on
//! the [`HybridCost`](crate::inverse::cost::HybridCost): Nelder–Mead (the paper's), particle swarm, and multi-start L-BFGS with
//! the analytic gradient, on any [`Objective`] (group kernels or the per-element basis). The common phase is unobservable, so group 0 is held at zero during
//! the search; reported phases have zero circular mean. Every run has an evaluation limit and an
//! optional time limit; a non-finite cost is replaced by a large finite penalty.
//!
//! Around them: whether the data decide ([`Assessment`]: rivals within the noise, misfit), what
//! per-element acquisitions tell and which to take next ([`information`]), and the estimation
//! workflow as one call ([`workflow`]).

mod assess;
pub mod information;
mod problem;
mod solvers;
pub mod workflow;

pub use assess::{chi2_95, misfit, propose_diversity, rival_solutions, Assessment, RivalSolution, MATERIAL_MISFIT};
use problem::Problem;
use solvers::{lbfgs_run, restarted_nelder_mead};

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::inverse::cost::Objective;
pub use crate::phase::{centred, condense, phase_error, point_reflection, twin, wrap};
use argmin::core::Executor;
use argmin::solver::particleswarm::ParticleSwarm;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::time::{Duration, Instant};

/// Cost returned in place of a non-finite one.
pub(crate) const PENALTY: f64 = 1e300;

/// Why a run stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// A convergence test of the method was met.
    Converged,
    /// The evaluation limit was spent.
    EvaluationLimit,
    /// The time limit passed.
    TimeLimit,
    /// Cancelled by another thread (Ctrl-C).
    Interrupted,
    /// No search ran: the prediction of a prior was kept (see
    /// [`crate::inverse::estimate::workflow::one_acquisition`]).
    PredictionKept,
}

impl Stop {
    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Stop::Converged => "converged",
            Stop::EvaluationLimit => "evaluation limit",
            Stop::TimeLimit => "time limit",
            Stop::Interrupted => "interrupted",
            Stop::PredictionKept => "prediction kept",
        }
    }
}

/// The search method and its settings.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    /// Nelder–Mead from `start` (default zero) with an initial simplex of `step` rad along each
    /// axis; stops when the standard deviation of the simplex costs falls below `tolerance`.
    NelderMead {
        /// Initial simplex size along each axis (rad).
        step: f64,
        /// Stop when the standard deviation of the simplex costs falls below this.
        tolerance: f64,
    },
    /// Particle swarm in `[-pi, pi]` per phase with `particles` particles, seeded.
    ParticleSwarm {
        /// Swarm size.
        particles: usize,
    },
    /// L-BFGS with the analytic gradient from zero and `starts - 1` seeded random starts.
    Lbfgs {
        /// Number of starts (the first from `start` or zero).
        starts: usize,
        /// L-BFGS history length.
        memory: usize,
    },
}

/// An estimator: a method, limits and a seed, configured by `with_*` builders that validate,
/// run on any [`Objective`] (the hybrid cost of paper Eq. 4, the per-element cost, ...).
///
/// ```
/// use has_core::inverse::cost::{build_model, Measurement};
/// use has_core::{phase::phase_error, Control, Estimator, Scenario, Simulation};
/// let sim = Simulation::new(&Scenario::default())?;
/// let truth: Vec<f64> = (0..16).map(|g| 0.4 * (g as f64).sin()).collect();
/// let image = sim.arfi_image(&truth)?; // noise-free, one image
/// let model = build_model(&sim, &[Measurement { image, known: vec![] }], 0.05, 3)?;
/// let estimate = Estimator::lbfgs().with_starts(4)?.run(&model.cost, Control::default())?;
/// assert!(phase_error(&estimate.phases, &truth) < 0.05);
/// # Ok::<(), has_core::HasError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Estimator {
    /// The search method and its settings.
    pub method: Method,
    /// Cost evaluations allowed over all runs.
    pub max_evaluations: usize,
    /// Wall-clock limit of the whole estimation.
    pub time_limit: Option<Duration>,
    /// Seed of the random starts and of the swarm.
    pub seed: u64,
    /// Start phases (rad, one per phase of the objective); default zero.
    pub start: Option<Vec<f64>>,
    /// Point-reflection pairing of groups ([`point_reflection`]): L-BFGS also starts from the
    /// twins of its best minima.
    pub twins: Option<Vec<usize>>,
}

impl Estimator {
    /// The paper's settings: Nelder–Mead from zero, at most 8000 evaluations, stop when the cost
    /// changes by less than 1e-8; the initial simplex spans 1 rad per phase (MATLAB's default of
    /// 5 % of a zero start, 0.00025 rad, barely leaves the start).
    pub fn nelder_mead() -> Self {
        Estimator {
            method: Method::NelderMead { step: 1.0, tolerance: 1e-8 },
            max_evaluations: 8000,
            time_limit: None,
            seed: 0,
            start: None,
            twins: None,
        }
    }

    /// Particle swarm: 40 particles, 8000 evaluations.
    pub fn particle_swarm() -> Self {
        Estimator { method: Method::ParticleSwarm { particles: 40 }, max_evaluations: 8000, ..Self::nelder_mead() }
    }

    /// L-BFGS: 20 random starts then 20 from twins and perturbations of the best, memory 10,
    /// 40000 evaluations over all starts.
    pub fn lbfgs() -> Self {
        Estimator { method: Method::Lbfgs { starts: 20, memory: 10 }, max_evaluations: 40000, ..Self::nelder_mead() }
    }

    /// At most this many cost evaluations (> 0).
    pub fn with_max_evaluations(mut self, n: usize) -> Result<Self> {
        if n == 0 {
            return Err(HasError::invalid("max_evaluations", "must be > 0"));
        }
        self.max_evaluations = n;
        Ok(self)
    }

    /// Stop after this many seconds (> 0).
    pub fn with_time_limit(mut self, seconds: f64) -> Result<Self> {
        if !(seconds.is_finite() && seconds > 0.0) {
            return Err(HasError::invalid("time_limit_s", format!("must be a finite number > 0, got {seconds}")));
        }
        self.time_limit = Some(Duration::from_secs_f64(seconds));
        Ok(self)
    }

    /// The same with an optional time limit (none = unlimited).
    pub fn with_time_limit_opt(mut self, limit: Option<Duration>) -> Self {
        self.time_limit = limit;
        self
    }

    /// Seed of the random starts and swarm.
    pub fn with_seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Number of L-BFGS starts (>= 1).
    pub fn with_starts(mut self, starts: usize) -> Result<Self> {
        match &mut self.method {
            Method::Lbfgs { starts: s, .. } if starts >= 1 => *s = starts,
            Method::Lbfgs { .. } => return Err(HasError::invalid("starts", "must be >= 1")),
            _ => return Err(HasError::invalid("starts", "applies to L-BFGS only")),
        }
        Ok(self)
    }

    /// Group pairing for twin starts (see [`point_reflection`]).
    pub fn with_twins(mut self, sigma: Option<Vec<usize>>) -> Self {
        self.twins = sigma;
        self
    }

    /// Start of the search (group phases, rad); default zero.
    pub fn with_start(mut self, start: Vec<f64>) -> Result<Self> {
        crate::error::require_finite("start", &start)?;
        self.start = Some(start);
        Ok(self)
    }

    /// Runs the search on `cost`. `control`'s cancel flag, when set by another thread, stops it
    /// promptly with [`Stop::Interrupted`] and the best point so far (not an error: the search's
    /// own limits end it the same way); its progress is not reported (the number of evaluations
    /// a search takes is not known ahead).
    pub fn run(&self, cost: &dyn Objective, control: Control<'_>) -> Result<Estimate> {
        let cancel = control.cancel();
        let g = cost.n_phases();
        if g < 2 {
            return Err(HasError::invalid("groups", "need at least two phases to estimate"));
        }
        let t0 = Instant::now();
        let deadline = self.time_limit.map(|d| t0 + d);
        let frame = Frame::of(cost);
        let n = frame.dims(g);
        let start = match &self.start {
            Some(s) if s.len() != g => return Err(HasError::invalid("start", format!("has {} values for {g} groups", s.len()))),
            Some(s) => frame.search(s),
            None => vec![0.0; n],
        };
        let runs: Vec<Run> = match &self.method {
            Method::NelderMead { step, tolerance } => {
                let p = Problem::new(cost, start.clone(), self.max_evaluations, deadline, cancel);
                let outcome = restarted_nelder_mead(&p, start.clone(), *step, *tolerance, self.max_evaluations);
                vec![p.finish(outcome)]
            }
            Method::ParticleSwarm { particles } => {
                let p = Problem::new(cost, start.clone(), self.max_evaluations, deadline, cancel);
                let bounds = (vec![-PI; n], vec![PI; n]);
                let solver = ParticleSwarm::new(bounds, *particles).with_rng_generator(ChaCha8Rng::seed_from_u64(self.seed));
                let iters = (self.max_evaluations / particles.max(&1)).max(1) as u64;
                let outcome = Executor::new(&p, solver).configure(|s| s.max_iters(iters)).run().map(|_| ());
                vec![p.finish(outcome)]
            }
            Method::Lbfgs { starts, memory } => {
                // Every start gets at least one evaluation of the budget, a second round two.
                let starts = &(*starts).min(self.max_evaluations).max(1);
                let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
                let mut inits = vec![start.clone()];
                for _ in 1..*starts {
                    inits.push((0..n).map(|_| rng.random_range(-PI..PI)).collect());
                }
                let rounds = if *starts > 1 && self.max_evaluations >= 2 * starts { 2 } else { 1 };
                let per_start = (self.max_evaluations / (rounds * starts)).max(1);
                let run_all = |inits: &[Vec<f64>]| {
                    inits.par_iter().map(|x0| lbfgs_run(cost, x0.clone(), *memory, per_start, deadline, cancel)).collect::<Result<Vec<_>>>()
                };
                let mut runs = run_all(&inits)?;
                // A single start only polishes it; more starts get a second round from the twins
                // of the best distinct minima and perturbations of the best.
                if rounds > 1 {
                    let second = self.second_round(&mut runs, *starts, frame, &mut rng);
                    runs.extend(run_all(&second)?);
                }
                runs
            }
        };
        let evaluations = runs.iter().map(|r| r.evaluations).sum();
        let stop = runs.iter().map(|r| r.stop).find(|s| *s != Stop::Converged).unwrap_or(Stop::Converged);
        // Best over all runs; ties go to the earliest start (deterministic).
        let best = runs.iter().enumerate().min_by(|a, b| a.1.cost.total_cmp(&b.1.cost).then(a.0.cmp(&b.0))).map(|(i, _)| i).unwrap_or(0);
        let minima: Vec<Minimum> = runs.iter().map(|r| Minimum { phases: frame.report(&r.params), cost: r.cost }).collect();
        let b = &runs[best];
        Ok(Estimate {
            phases: frame.report(&b.params),
            cost: b.cost,
            evaluations,
            seconds: t0.elapsed().as_secs_f64(),
            history: b.history.clone(),
            stop,
            minima,
        })
    }

    /// Starts of L-BFGS's second round: twins of the best distinct minima (when a pairing is
    /// set) and seeded perturbations of the best, `starts` in all. Sorts `runs` by cost.
    fn second_round(&self, runs: &mut [Run], starts: usize, frame: Frame, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        runs.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        let mut second: Vec<Vec<f64>> = Vec::new();
        let mut distinct: Vec<Vec<f64>> = Vec::new();
        for r in runs.iter() {
            let p = frame.phases(&r.params);
            if distinct.len() < 4 && distinct.iter().all(|d| phase_error(d, &p) > 0.1) {
                distinct.push(p);
            }
        }
        if let Some(sigma) = &self.twins {
            second.extend(distinct.iter().map(|d| frame.search(&twin(d, sigma))));
        }
        let best = runs[0].params.clone();
        while second.len() < starts {
            second.push(best.iter().map(|b| frame.step(*b, rng.random_range(-1.0..1.0))).collect());
        }
        second
    }
}

/// A local minimum found by one run.
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// Phases at the minimum (rad), zero circular mean.
    pub phases: Vec<f64>,
    /// The cost there.
    pub cost: f64,
}

/// The result of an estimation.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// Group phases (rad) in (-pi, pi], zero circular mean: subtract them to correct.
    pub phases: Vec<f64>,
    /// The best cost.
    pub cost: f64,
    /// Cost evaluations over all runs.
    pub evaluations: usize,
    /// Wall-clock time of the estimation (s).
    pub seconds: f64,
    /// Best cost after each evaluation of the winning run.
    pub history: Vec<f64>,
    /// Why the search stopped (the first limit any run reached, else converged; or that no
    /// search ran because a prediction was kept).
    pub stop: Stop,
    /// The end point of every run (one per start).
    pub minima: Vec<Minimum>,
}

impl Estimate {
    /// The same estimate with its parameters (the best and every run's minimum) mapped to
    /// phases by `f`: for searches over coefficients of a parametrisation of the phases.
    pub fn map_phases(mut self, f: impl Fn(&[f64]) -> Vec<f64>) -> Self {
        self.phases = f(&self.phases);
        for m in &mut self.minima {
            m.phases = f(&m.phases);
        }
        self
    }
}

pub(super) struct Run {
    params: Vec<f64>,
    cost: f64,
    evaluations: usize,
    history: Vec<f64>,
    stop: Stop,
}

/// How a search parametrises the phases.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Frame {
    /// The cost ignores a common phase: phase 0 is held at zero and the others are searched
    /// relative to it; phases are reported with zero circular mean.
    Relative,
    /// The cost sees the common phase (a prior anchors it): every phase is searched, and
    /// reported wrapped to (-pi, pi].
    Absolute,
    /// The parameters are coefficients, not phases: searched and reported as they are.
    Linear,
}

impl Frame {
    /// The frame `cost` needs.
    pub(super) fn of(cost: &dyn Objective) -> Self {
        if !cost.periodic() {
            Frame::Linear
        } else if cost.sees_common_phase() {
            Frame::Absolute
        } else {
            Frame::Relative
        }
    }

    /// Search dimensions for `g` phases.
    pub(super) fn dims(self, g: usize) -> usize {
        match self {
            Frame::Relative => g - 1,
            Frame::Absolute | Frame::Linear => g,
        }
    }

    /// Search parameters of `phases`.
    pub(super) fn search(self, phases: &[f64]) -> Vec<f64> {
        match self {
            Frame::Relative => phases[1..].iter().map(|p| wrap(p - phases[0])).collect(),
            Frame::Absolute | Frame::Linear => phases.to_vec(),
        }
    }

    /// The phases at search parameters `x` (`[0, x...]` when relative).
    pub(super) fn phases(self, x: &[f64]) -> Vec<f64> {
        match self {
            Frame::Relative => std::iter::once(0.0).chain(x.iter().copied()).collect(),
            Frame::Absolute | Frame::Linear => x.to_vec(),
        }
    }

    /// The phases at `x` as reported.
    pub(super) fn report(self, x: &[f64]) -> Vec<f64> {
        match self {
            Frame::Relative => centred(&self.phases(x)),
            Frame::Absolute => x.iter().map(|&p| wrap(p)).collect(),
            Frame::Linear => x.to_vec(),
        }
    }

    /// Parameter `x` moved by `d` (wrapped when it is a phase).
    pub(super) fn step(self, x: f64, d: f64) -> f64 {
        match self {
            Frame::Linear => x + d,
            _ => wrap(x + d),
        }
    }

    /// The gradient over the search parameters from the gradient over the phases.
    pub(super) fn gradient(self, mut g: Vec<f64>) -> Vec<f64> {
        if self == Frame::Relative {
            g.remove(0);
        }
        g
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::cost::test_objectives::Cosines;
    use std::sync::atomic::AtomicBool;

    #[test]
    fn every_method_stops_cleanly_at_any_evaluation_or_time_limit() {
        // Limits that end a run inside Nelder-Mead's initial simplex (n + 1 = 8 evaluations),
        // inside an L-BFGS line search or a swarm's first generation: a stop, never a panic.
        let cost = Cosines(vec![0.0, 0.3, -0.2, 0.5, 1.0, -1.0, 0.1, 0.4]);
        for method in [Estimator::nelder_mead(), Estimator::lbfgs(), Estimator::particle_swarm()] {
            for budget in [1, 2, 7, 8, 9, 30] {
                let e = method.clone().with_max_evaluations(budget).unwrap().run(&cost, Control::default()).unwrap();
                assert!(e.evaluations <= budget && e.cost.is_finite(), "{budget}: {} evaluations", e.evaluations);
            }
            let e = method.clone().with_time_limit(1e-9).unwrap().run(&cost, Control::default()).unwrap();
            assert!(matches!(e.stop, Stop::TimeLimit | Stop::Converged), "{:?}", e.stop);
            let cancel = AtomicBool::new(true);
            assert_eq!(method.run(&cost, Control::default().with_cancel(&cancel)).unwrap().stop, Stop::Interrupted);
        }
    }
}
