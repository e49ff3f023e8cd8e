//! Hybrid estimation of the phase aberration (paper loop 1, and its multi-image extension).
//!
//! Estimators are values configured with validated `with_*` builders and run through argmin on
//! the [`HybridCost`](crate::inverse::cost::HybridCost): Nelder–Mead (the paper's), particle swarm, and multi-start L-BFGS with
//! the analytic gradient, on any [`Objective`] (group kernels or the per-element basis). The common phase is unobservable, so group 0 is held at zero during
//! the search; reported phases have zero circular mean. Every run has an evaluation limit and an
//! optional time limit; a non-finite cost is replaced by a large finite penalty.

use crate::error::{HasError, Result};
use crate::inverse::cost::Objective;
pub use crate::inverse::phase::{centred, condense, phase_error, point_reflection, twin, wrap};
use argmin::core::{CostFunction, Executor, Gradient};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use argmin::solver::quasinewton::LBFGS;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Cost returned in place of a non-finite one.
pub(crate) const PENALTY: f64 = 1e300;

/// Why a run stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    Converged,
    EvaluationLimit,
    TimeLimit,
    Interrupted,
}

impl Stop {
    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            Stop::Converged => "converged",
            Stop::EvaluationLimit => "evaluation limit",
            Stop::TimeLimit => "time limit",
            Stop::Interrupted => "interrupted",
        }
    }
}

/// The search method and its settings.
#[derive(Debug, Clone, PartialEq)]
pub enum Method {
    /// Nelder–Mead from `start` (default zero) with an initial simplex of `step` rad along each
    /// axis; stops when the standard deviation of the simplex costs falls below `tolerance`.
    NelderMead { step: f64, tolerance: f64 },
    /// Particle swarm in `[-pi, pi]` per phase with `particles` particles, seeded.
    ParticleSwarm { particles: usize },
    /// L-BFGS with the analytic gradient from zero and `starts - 1` seeded random starts.
    Lbfgs { starts: usize, memory: usize },
}

/// An estimator: a method, limits and a seed, configured by `with_*` builders that validate,
/// run on any [`Objective`] (the hybrid cost of paper Eq. 4, the per-element cost, ...).
///
/// ```
/// use has_core::inverse::cost::{build_model, Measurement};
/// use has_core::{inverse::phase::phase_error, Estimator, Scenario, Simulation};
/// let sim = Simulation::new(&Scenario::default())?;
/// let truth: Vec<f64> = (0..16).map(|g| 0.4 * (g as f64).sin()).collect();
/// let image = sim.arfi_image(&truth)?; // noise-free, one image
/// let model = build_model(&sim, &[Measurement { image, known: vec![] }], 0.05, 3)?;
/// let estimate = Estimator::lbfgs().with_starts(4)?.run(&model.cost, None)?;
/// assert!(phase_error(&estimate.phases, &truth) < 0.05);
/// # Ok::<(), has_core::HasError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Estimator {
    pub method: Method,
    pub max_evaluations: usize,
    pub time_limit: Option<Duration>,
    pub seed: u64,
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

    /// Runs the search on `cost`. `cancel`, when set by another thread, stops it promptly.
    pub fn run(&self, cost: &dyn Objective, cancel: Option<&AtomicBool>) -> Result<Estimate> {
        let g = cost.n_phases();
        if g < 2 {
            return Err(HasError::invalid("groups", "need at least two phases to estimate"));
        }
        let t0 = Instant::now();
        let deadline = self.time_limit.map(|d| t0 + d);
        let start = match &self.start {
            Some(s) if s.len() != g => return Err(HasError::invalid("start", format!("has {} values for {g} groups", s.len()))),
            Some(s) => reduced(s),
            None => vec![0.0; g - 1],
        };
        let runs: Vec<Run> = match &self.method {
            Method::NelderMead { step, tolerance } => {
                let p = Problem::new(cost, start.clone(), self.max_evaluations, deadline, cancel);
                let outcome = restarted_nelder_mead(&p, start.clone(), *step, *tolerance, self.max_evaluations);
                vec![p.finish(outcome)]
            }
            Method::ParticleSwarm { particles } => {
                let p = Problem::new(cost, start.clone(), self.max_evaluations, deadline, cancel);
                let bounds = (vec![-PI; g - 1], vec![PI; g - 1]);
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
                    inits.push((0..g - 1).map(|_| rng.random_range(-PI..PI)).collect());
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
                    let second = self.second_round(&mut runs, *starts, &mut rng);
                    runs.extend(run_all(&second)?);
                }
                runs
            }
        };
        let evaluations = runs.iter().map(|r| r.evaluations).sum();
        let stop = runs.iter().map(|r| r.stop).find(|s| *s != Stop::Converged).unwrap_or(Stop::Converged);
        // Best over all runs; ties go to the earliest start (deterministic).
        let best = runs.iter().enumerate().min_by(|a, b| a.1.cost.total_cmp(&b.1.cost).then(a.0.cmp(&b.0))).map(|(i, _)| i).unwrap_or(0);
        let minima: Vec<Minimum> = runs.iter().map(|r| Minimum { phases: centred(&full(&r.params)), cost: r.cost }).collect();
        let b = &runs[best];
        Ok(Estimate {
            phases: centred(&full(&b.params)),
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
    fn second_round(&self, runs: &mut [Run], starts: usize, rng: &mut ChaCha8Rng) -> Vec<Vec<f64>> {
        runs.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        let mut second: Vec<Vec<f64>> = Vec::new();
        let mut distinct: Vec<Vec<f64>> = Vec::new();
        for r in runs.iter() {
            let p = full(&r.params);
            if distinct.len() < 4 && distinct.iter().all(|d| phase_error(d, &p) > 0.1) {
                distinct.push(p);
            }
        }
        if let Some(sigma) = &self.twins {
            second.extend(distinct.iter().map(|d| reduced(&twin(d, sigma))));
        }
        let best = runs[0].params.clone();
        while second.len() < starts {
            second.push(best.iter().map(|b| wrap(b + rng.random_range(-1.0..1.0))).collect());
        }
        second
    }
}

/// A local minimum found by one run.
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    pub phases: Vec<f64>,
    pub cost: f64,
}

/// The result of an estimation.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// Group phases (rad) in (-pi, pi], zero circular mean: subtract them to correct.
    pub phases: Vec<f64>,
    pub cost: f64,
    pub evaluations: usize,
    pub seconds: f64,
    /// Best cost after each evaluation of the winning run.
    pub history: Vec<f64>,
    pub stop: Stop,
    /// The end point of every run (one per start).
    pub minima: Vec<Minimum>,
}

struct Run {
    params: Vec<f64>,
    cost: f64,
    evaluations: usize,
    history: Vec<f64>,
    stop: Stop,
}

/// The argmin problem: counts evaluations, keeps the best point, enforces the limits.
struct Problem<'a> {
    cost: &'a dyn Objective,
    budget: usize,
    deadline: Option<Instant>,
    cancel: Option<&'a AtomicBool>,
    evaluations: AtomicUsize,
    /// Evaluations still to answer with a penalty instead of a stop: argmin's Nelder–Mead
    /// unwraps the costs of its initial simplex, so a limit reached there must not be an error.
    lenient: AtomicUsize,
    /// The first limit reached (it ends the run even when a lenient answer hid it from argmin).
    stopped: Mutex<Option<Stop>>,
    best: Mutex<(f64, Vec<f64>, Vec<f64>)>,
}

/// Raised inside the cost to end a run early.
#[derive(Debug)]
struct EarlyStop(Stop);

impl std::fmt::Display for EarlyStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.0.name())
    }
}

impl std::error::Error for EarlyStop {}

impl<'a> Problem<'a> {
    /// `start` is reported when the run ends before its first evaluation (a limit already hit).
    fn new(cost: &'a dyn Objective, start: Vec<f64>, budget: usize, deadline: Option<Instant>, cancel: Option<&'a AtomicBool>) -> Self {
        let best = Mutex::new((f64::INFINITY, start, vec![]));
        Problem {
            cost,
            budget,
            deadline,
            cancel,
            evaluations: AtomicUsize::new(0),
            lenient: AtomicUsize::new(0),
            stopped: Mutex::new(None),
            best,
        }
    }

    fn check(&self) -> std::result::Result<(), EarlyStop> {
        let stop = if self.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            Stop::Interrupted
        } else if self.deadline.is_some_and(|d| Instant::now() > d) {
            Stop::TimeLimit
        } else if self.evaluations.fetch_add(1, Ordering::Relaxed) >= self.budget {
            Stop::EvaluationLimit
        } else {
            return Ok(());
        };
        if let Ok(mut s) = self.stopped.lock() {
            s.get_or_insert(stop);
        }
        Err(EarlyStop(stop))
    }

    fn record(&self, x: &[f64], c: f64) {
        if let Ok(mut b) = self.best.lock() {
            if c < b.0 {
                b.0 = c;
                b.1 = x.to_vec();
            }
            let best = b.0;
            b.2.push(best);
        }
    }

    /// The best cost and point so far.
    fn best(&self) -> (f64, Vec<f64>) {
        self.best.lock().map(|b| (b.0, b.1.clone())).unwrap_or((f64::INFINITY, vec![]))
    }

    fn finish(self, outcome: std::result::Result<(), argmin::core::Error>) -> Run {
        let evaluations = self.evaluations.load(Ordering::Relaxed).min(self.budget);
        let stopped = self.stopped.lock().ok().and_then(|s| *s);
        let stop = match outcome {
            Ok(()) if stopped.is_some() => stopped.unwrap_or(Stop::Converged),
            // argmin's iteration cap (set to the budget) ends a run that used it all.
            Ok(()) if evaluations >= self.budget => Stop::EvaluationLimit,
            Ok(()) => Stop::Converged,
            Err(e) => e.downcast_ref::<EarlyStop>().map_or(Stop::Converged, |s| s.0),
        };
        let (cost, params, history) = self.best.into_inner().unwrap_or_else(|p| p.into_inner());
        Run { params, cost, evaluations, history, stop }
    }
}

impl CostFunction for &Problem<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        let lenient = self.lenient.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1)).is_ok();
        match self.check() {
            Err(_) if lenient => return Ok(PENALTY),
            r => r?,
        }
        let c = self.cost.cost(&full(x));
        let c = if c.is_finite() { c } else { PENALTY };
        self.record(x, c);
        Ok(c)
    }
}

impl Gradient for &Problem<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    fn gradient(&self, x: &Vec<f64>) -> std::result::Result<Vec<f64>, argmin::core::Error> {
        self.check()?;
        let (c, g) = self.cost.cost_and_gradient(&full(x));
        self.record(x, if c.is_finite() { c } else { PENALTY });
        Ok(g[1..].iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect())
    }
}

/// Nelder–Mead with restarts. The first simplex spans `step` rad along each axis. Nelder–Mead
/// is affine-invariant except for its simplex, and in the long curved valleys of this cost an
/// axis-aligned simplex collapses before the valley floor is reached; so each restart (after
/// a run converges, or after `40·n` iterations) shapes the new simplex by the local curvature:
/// along each eigenvector `v_i` of the Hessian (central differences of the analytic gradient,
/// absolute eigenvalues) a vertex at `x + s_i·v_i`, `s_i = sqrt(2·J(x)/|λ_i|)` clamped to
/// [1e-4, π/2] rad, the distance at which the quadratic model would have used up the cost.
/// Stops when a restart lowers the best cost by less than 0.1 % (or less than `tolerance`) or
/// the budget is spent.
fn restarted_nelder_mead(
    p: &Problem,
    start: Vec<f64>,
    step: f64,
    tolerance: f64,
    budget: usize,
) -> std::result::Result<(), argmin::core::Error> {
    let n = start.len();
    let mut simplex: Vec<Vec<f64>> = std::iter::once(start.clone())
        .chain((0..n).map(|i| {
            let mut y = start.clone();
            y[i] += step;
            y
        }))
        .collect();
    let mut last = f64::INFINITY;
    loop {
        // Dimension-adaptive coefficients (Gao & Han, Comput Optim Appl 51, 2012): the classic
        // ones stall in 15+ dimensions (argmin caps the contraction at 0.5).
        let nf = n as f64;
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(tolerance)?
            .with_alpha(1.0)?
            .with_gamma(1.0 + 2.0 / nf)?
            .with_rho(0.5)?
            .with_sigma(1.0 - 1.0 / nf)?;
        let iterations = (40 * n).min(budget) as u64;
        p.lenient.store(n + 1, Ordering::Relaxed);
        Executor::new(p, solver).configure(|s| s.max_iters(iterations)).run()?;
        let (best, x) = p.best();
        if !(best < last * (1.0 - 1e-3) && last - best > tolerance) {
            return Ok(());
        }
        last = best;
        simplex = curvature_simplex(p, &x, best)?;
    }
}

/// The simplex of [`restarted_nelder_mead`]'s restarts around `x` (cost `cost`).
#[allow(clippy::needless_range_loop)] // index loops read as the matrix algebra
fn curvature_simplex(p: &Problem, x: &[f64], cost: f64) -> std::result::Result<Vec<Vec<f64>>, argmin::core::Error> {
    let n = x.len();
    let h = 1e-4;
    let mut hessian = vec![vec![0.0; n]; n];
    for i in 0..n {
        let mut a = x.to_vec();
        let mut b = x.to_vec();
        a[i] += h;
        b[i] -= h;
        let (ga, gb) = (p.gradient(&a)?, p.gradient(&b)?);
        for j in 0..n {
            hessian[j][i] = (ga[j] - gb[j]) / (2.0 * h);
        }
    }
    for i in 0..n {
        for j in 0..i {
            let m = 0.5 * (hessian[i][j] + hessian[j][i]);
            hessian[i][j] = m;
            hessian[j][i] = m;
        }
    }
    let (values, vectors) = symmetric_eigen(hessian);
    let mut simplex = vec![x.to_vec()];
    for (l, v) in values.iter().zip(&vectors) {
        let s = if l.abs() > 0.0 { (2.0 * cost / l.abs()).sqrt() } else { PI / 2.0 };
        let s = if s.is_finite() { s.clamp(1e-4, PI / 2.0) } else { PI / 2.0 };
        simplex.push(x.iter().zip(v).map(|(xi, vi)| xi + s * vi).collect());
    }
    Ok(simplex)
}

/// Eigenvalues and unit eigenvectors of a symmetric matrix (cyclic Jacobi rotations, Golub &
/// Van Loan §8.5); the vectors are returned as rows.
#[allow(clippy::needless_range_loop)] // index loops read as the textbook algorithm
fn symmetric_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = a.len();
    let mut v: Vec<Vec<f64>> = (0..n).map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect()).collect();
    for _sweep in 0..60 {
        let off: f64 = (0..n).flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j))).map(|(i, j)| a[i][j] * a[i][j]).sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let values = (0..n).map(|i| a[i][i]).collect();
    let vectors = (0..n).map(|j| (0..n).map(|i| v[i][j]).collect()).collect();
    (values, vectors)
}

fn lbfgs_run(
    cost: &dyn Objective,
    x0: Vec<f64>,
    memory: usize,
    budget: usize,
    deadline: Option<Instant>,
    cancel: Option<&AtomicBool>,
) -> Result<Run> {
    let p = Problem::new(cost, x0.clone(), budget, deadline, cancel);
    let solver = LBFGS::new(MoreThuenteLineSearch::new(), memory)
        .with_tolerance_grad(1e-12)
        .and_then(|s| s.with_tolerance_cost(1e-14))
        .map_err(argmin_error)?;
    let outcome = Executor::new(&p, solver).configure(|s| s.param(x0).max_iters(budget as u64)).run().map(|_| ());
    Ok(p.finish(outcome))
}

fn argmin_error(e: argmin::core::Error) -> HasError {
    HasError::invalid("estimator", e.to_string())
}

/// `[0, x...]`: group 0 carries the (fixed) common phase.
fn full(x: &[f64]) -> Vec<f64> {
    std::iter::once(0.0).chain(x.iter().copied()).collect()
}

/// Phases relative to group 0.
fn reduced(phases: &[f64]) -> Vec<f64> {
    phases[1..].iter().map(|p| wrap(p - phases[0])).collect()
}

/// A solution that fits the data about as well as the best one (a rival of the estimate, e.g.
/// its twin).
#[derive(Debug, Clone, PartialEq)]
pub struct RivalSolution {
    pub phases: Vec<f64>,
    pub cost: f64,
    /// Focal ARFI of the beam corrected with the best estimate if this candidate were the truth,
    /// relative to the ideal focus (the model's prediction).
    pub predicted_recovery: f64,
}

/// Whether the data decide between clearly different solutions.
#[derive(Debug, Clone)]
pub struct Assessment {
    /// True when some solution within the noise margin would leave less than `threshold` of
    /// the ideal focus after the best estimate's correction.
    pub ambiguous: bool,
    /// Cost margin: `sigma² · chi²_0.95(G - 1)`.
    pub margin: f64,
    pub candidates: Vec<RivalSolution>,
    pub worst_recovery: f64,
    /// Known group phases (rad) to add for one more acquisition that best separates the
    /// candidates, and that separation (squared image difference in units of sigma²).
    pub suggested_phases: Vec<f64>,
    pub suggested_separation: f64,
    /// The best cost over its expectation under the model, `J / (n_pixels·sigma²)` (about 1
    /// when the model explains the data down to the noise; `sigma` at least 1e-4 rad).
    pub misfit: f64,
    /// The best cost lies above the 95 % point of `sigma²·chi²(n_pixels - G + 1)`: the model
    /// cannot explain the images (e.g. element-level aberrations fitted with group phases), and
    /// a correction from it may make the focus worse.
    pub mismatch: bool,
}

/// Upper 95 % point of chi² with `k` degrees of freedom (Wilson–Hilferty, within 1 % for k ≥ 3).
pub fn chi2_95(k: usize) -> f64 {
    let k = k.max(1) as f64;
    let z = 1.644_853_626_951_472_2;
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

impl Estimate {
    /// Looks for clearly different solutions that fit within the noise: the end points of every
    /// start, a 24-start L-BFGS exploration of its own (from the estimate, random points and
    /// twins) and the refined twin of the estimate; each within the chi² margin of the best cost
    /// is a candidate, scored by the focus its truth would leave after the estimate's correction.
    pub fn assess(&self, model: &crate::inverse::cost::Model, sigma: Option<&[usize]>, threshold: f64, seed: u64) -> Result<Assessment> {
        let g = model.cost.n_groups;
        let margin = model.noise.powi(2) * chi2_95(g - 1);
        let mut points: Vec<Minimum> = self.minima.clone();
        points.push(Minimum { phases: self.phases.clone(), cost: self.cost });
        // An exploration of its own, whatever method produced the estimate: L-BFGS from the
        // estimate, its twin and seeded random starts.
        let explore = Estimator::lbfgs()
            .with_starts(12)?
            .with_twins(sigma.map(<[usize]>::to_vec))
            .with_seed(seed)
            .with_start(self.phases.clone())?
            .run(&model.cost, None)?;
        points.extend(explore.minima);
        if let Some(sig) = sigma {
            let t = twin(&self.phases, sig);
            let run = lbfgs_run(&model.cost, reduced(&t), 10, 3000, None, None)?;
            points.push(Minimum { phases: centred(&full(&run.params)), cost: run.cost });
        }
        let best = points.iter().map(|p| p.cost).fold(f64::INFINITY, f64::min);
        let ideal = focal(&model.base, &vec![0.0; g])?;
        let mut candidates: Vec<RivalSolution> = Vec::new();
        for p in points.iter().filter(|p| p.cost <= best + margin) {
            if candidates.iter().any(|c| phase_error(&c.phases, &p.phases) < 0.05) {
                continue;
            }
            let residual: Vec<f64> = p.phases.iter().zip(&self.phases).map(|(t, e)| t - e).collect();
            let predicted_recovery = focal(&model.base, &residual)? / ideal;
            candidates.push(RivalSolution { phases: p.phases.clone(), cost: p.cost, predicted_recovery });
        }
        let worst_recovery = candidates.iter().map(|c| c.predicted_recovery).fold(1.0, f64::min);
        let (suggested_phases, suggested_separation) = propose_diversity(model, &candidates, 64, seed)?;
        let n = model.cost.n_pixels();
        let sigma2 = model.noise.max(1e-4).powi(2);
        let misfit = best / (n as f64 * sigma2);
        let mismatch = best > sigma2 * chi2_95(n.saturating_sub(g - 1).max(1));
        Ok(Assessment {
            ambiguous: worst_recovery < threshold,
            margin,
            candidates,
            worst_recovery,
            suggested_phases,
            suggested_separation,
            misfit,
            mismatch,
        })
    }
}

/// The largest value of the kernel's image (the focal ARFI) for group phases.
fn focal(kernel: &crate::inverse::cost::ArfiKernel, phases: &[f64]) -> Result<f64> {
    Ok(kernel.image(phases)?.iter().copied().fold(f64::MIN, f64::max))
}

/// Among `tries` seeded random group-phase patterns (and a quadratic defocus-like pattern when
/// there is one candidate), the one whose added image best separates the candidates: it
/// maximises the smallest `Σ (d_a - d_b)² / sigma²` over candidate pairs.
pub fn propose_diversity(
    model: &crate::inverse::cost::Model,
    candidates: &[RivalSolution],
    tries: usize,
    seed: u64,
) -> Result<(Vec<f64>, f64)> {
    let g = model.cost.n_groups;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_d17e);
    let sigma2 = model.noise.powi(2).max(1e-30);
    let mut best = (vec![0.0; g], f64::NEG_INFINITY);
    for _ in 0..tries.max(1) {
        let d: Vec<f64> = (0..g).map(|_| rng.random_range(-PI..PI)).collect();
        let images = candidates
            .iter()
            .map(|c| model.base.image(&c.phases.iter().zip(&d).map(|(p, q)| p + q).collect::<Vec<_>>()))
            .collect::<Result<Vec<_>>>()?;
        let mut sep = f64::INFINITY;
        for a in 0..images.len() {
            for b in a + 1..images.len() {
                sep = sep.min((&images[a] - &images[b]).iter().map(|x| x * x).sum::<f64>() / sigma2);
            }
        }
        if images.len() < 2 {
            sep = 0.0;
        }
        if sep > best.1 {
            best = (d, sep);
        }
    }
    Ok((centred(&best.0), best.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn symmetric_eigen_reconstructs_the_matrix() {
        // A random symmetric 15×15 matrix (seeded): A·v = λ·v and orthonormal vectors to
        // 1e-10 of the largest entry (Jacobi converges to rounding).
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = 15;
        let mut a = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in 0..=i {
                let x: f64 = rng.random_range(-1.0..1.0);
                a[i][j] = x;
                a[j][i] = x;
            }
        }
        let (values, vectors) = symmetric_eigen(a.clone());
        for (l, v) in values.iter().zip(&vectors) {
            for i in 0..n {
                let av: f64 = (0..n).map(|j| a[i][j] * v[j]).sum();
                assert!((av - l * v[i]).abs() < 1e-10, "A·v - λ·v = {}", av - l * v[i]);
            }
        }
        for (i, u) in vectors.iter().enumerate() {
            for (j, w) in vectors.iter().enumerate() {
                let d: f64 = u.iter().zip(w).map(|(x, y)| x * y).sum();
                assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-10);
            }
        }
    }

    /// `Σ (1 - cos(φ_i - φ_0 - t_i))`: minimum at the phases `t` (up to a common phase).
    struct Cosines(Vec<f64>);

    impl Objective for Cosines {
        fn n_phases(&self) -> usize {
            self.0.len()
        }
        fn cost(&self, p: &[f64]) -> f64 {
            self.cost_and_gradient(p).0
        }
        fn cost_and_gradient(&self, p: &[f64]) -> (f64, Vec<f64>) {
            let d: Vec<f64> = p.iter().zip(&self.0).map(|(x, t)| x - p[0] - t).collect();
            let mut g: Vec<f64> = d.iter().map(|v| v.sin()).collect();
            g[0] = -g[1..].iter().sum::<f64>();
            (d.iter().map(|v| 1.0 - v.cos()).sum(), g)
        }
    }

    #[test]
    fn every_method_stops_cleanly_at_any_evaluation_or_time_limit() {
        // Limits that end a run inside Nelder-Mead's initial simplex (n + 1 = 8 evaluations),
        // inside an L-BFGS line search or a swarm's first generation: a stop, never a panic.
        let cost = Cosines(vec![0.0, 0.3, -0.2, 0.5, 1.0, -1.0, 0.1, 0.4]);
        for method in [Estimator::nelder_mead(), Estimator::lbfgs(), Estimator::particle_swarm()] {
            for budget in [1, 2, 7, 8, 9, 30] {
                let e = method.clone().with_max_evaluations(budget).unwrap().run(&cost, None).unwrap();
                assert!(e.evaluations <= budget && e.cost.is_finite(), "{budget}: {} evaluations", e.evaluations);
            }
            let e = method.clone().with_time_limit(1e-9).unwrap().run(&cost, None).unwrap();
            assert!(matches!(e.stop, Stop::TimeLimit | Stop::Converged), "{:?}", e.stop);
            let cancel = AtomicBool::new(true);
            assert_eq!(method.run(&cost, Some(&cancel)).unwrap().stop, Stop::Interrupted);
        }
    }

    #[test]
    fn wrap_and_phase_error() {
        assert!((wrap(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap(-0.5) + 0.5).abs() < 1e-12);
        let a = [0.1, 0.2, 3.1];
        let b: Vec<f64> = a.iter().map(|x| x + 1.0).collect();
        assert!(phase_error(&a, &b) < 1e-12);
        assert!((phase_error(&[0.0, 0.0], &[0.5, -0.5]) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn condense_takes_the_circular_mean() {
        let c = condense(&[PI - 0.1, -PI + 0.1, 0.0, 0.2], &[0, 0, 1, 1]).unwrap();
        assert!((c[0].abs() - PI).abs() < 1e-12);
        assert!((c[1] - 0.1).abs() < 1e-12);
    }
}
