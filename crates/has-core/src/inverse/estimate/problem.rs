//! The argmin problem every estimator runs: it counts evaluations, keeps the best point, ends a
//! run at its evaluation or time limit or on cancel, and answers a non-finite cost with
//! [`PENALTY`]. For gradient searches it evaluates cost and gradient together and answers the
//! gradient at the point it last costed from that evaluation (argmin's line search asks for
//! both at every trial point), so one evaluation is one `cost_and_gradient`; and it ends the
//! search as converged once [`STALL_EVALUATIONS`] evaluations in a row have not lowered the best
//! cost by a relative [`STALL_TOLERANCE`] (on the plateau of a minimum argmin's absolute tests
//! would otherwise spend the whole budget on rounding-level changes).

use super::{Frame, Run, Stop, PENALTY};
use crate::inverse::cost::Objective;
use argmin::core::{CostFunction, Gradient};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// Evaluations without progress after which a gradient search counts as converged.
pub(super) const STALL_EVALUATIONS: usize = 30;
/// Relative lowering of the best cost that counts as progress.
pub(super) const STALL_TOLERANCE: f64 = 1e-9;

/// The argmin problem: counts evaluations, keeps the best point, enforces the limits.
pub(super) struct Problem<'a> {
    cost: &'a dyn Objective,
    frame: Frame,
    budget: usize,
    deadline: Option<Instant>,
    cancel: Option<&'a AtomicBool>,
    evaluations: AtomicUsize,
    /// Evaluations still to answer with a penalty instead of a stop: argmin's Nelder–Mead
    /// unwraps the costs of its initial simplex, so a limit reached there must not be an error.
    pub(super) lenient: AtomicUsize,
    /// The first limit reached (it ends the run even when a lenient answer hid it from argmin).
    stopped: Mutex<Option<Stop>>,
    best: Mutex<(f64, Vec<f64>, Vec<f64>)>,
    /// Whether `cost` evaluates the gradient too (gradient searches).
    with_gradient: bool,
    /// The last point evaluated with its gradient, and that gradient.
    last: Mutex<Option<(Vec<f64>, Vec<f64>)>>,
    /// Evaluations since the best cost last made progress (gradient searches).
    stalled: AtomicUsize,
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
    pub(super) fn new(
        cost: &'a dyn Objective,
        start: Vec<f64>,
        budget: usize,
        deadline: Option<Instant>,
        cancel: Option<&'a AtomicBool>,
    ) -> Self {
        let best = Mutex::new((f64::INFINITY, start, vec![]));
        Problem {
            cost,
            frame: Frame::of(cost),
            budget,
            deadline,
            cancel,
            evaluations: AtomicUsize::new(0),
            lenient: AtomicUsize::new(0),
            stopped: Mutex::new(None),
            best,
            with_gradient: false,
            last: Mutex::new(None),
            stalled: AtomicUsize::new(0),
        }
    }

    /// The same problem for a gradient search: each cost evaluation also evaluates the gradient
    /// and keeps it for the gradient call at the same point.
    pub(super) fn with_gradient(mut self) -> Self {
        self.with_gradient = true;
        self
    }

    /// Cost and search-space gradient at `x` (counted, recorded, the gradient kept).
    fn evaluate(&self, x: &[f64]) -> (f64, Vec<f64>) {
        let (c, g) = self.cost.cost_and_gradient(&self.frame.phases(x));
        let c = if c.is_finite() { c } else { PENALTY };
        self.record(x, c);
        let g: Vec<f64> = self.frame.gradient(g).into_iter().map(|v| if v.is_finite() { v } else { 0.0 }).collect();
        if let Ok(mut last) = self.last.lock() {
            *last = Some((x.to_vec(), g.clone()));
        }
        (c, g)
    }

    /// The kept gradient, if `x` is the point it was evaluated at.
    fn kept_gradient(&self, x: &[f64]) -> Option<Vec<f64>> {
        let last = self.last.lock().ok()?;
        last.as_ref().filter(|(p, _)| p.as_slice() == x).map(|(_, g)| g.clone())
    }

    fn check(&self) -> std::result::Result<(), EarlyStop> {
        let stop = if self.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            Stop::Interrupted
        } else if self.deadline.is_some_and(|d| Instant::now() > d) {
            Stop::TimeLimit
        } else if self.evaluations.fetch_add(1, Ordering::Relaxed) >= self.budget {
            Stop::EvaluationLimit
        } else if self.with_gradient && self.stalled.load(Ordering::Relaxed) >= STALL_EVALUATIONS {
            Stop::Converged
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
            let progress = c < b.0 - STALL_TOLERANCE * b.0.abs();
            if c < b.0 {
                b.0 = c;
                b.1 = x.to_vec();
            }
            if progress {
                self.stalled.store(0, Ordering::Relaxed);
            } else {
                self.stalled.fetch_add(1, Ordering::Relaxed);
            }
            let best = b.0;
            b.2.push(best);
        }
    }

    /// The best cost and point so far.
    pub(super) fn best(&self) -> (f64, Vec<f64>) {
        self.best.lock().map(|b| (b.0, b.1.clone())).unwrap_or((f64::INFINITY, vec![]))
    }

    pub(super) fn finish(self, outcome: std::result::Result<(), argmin::core::Error>) -> Run {
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
        if self.with_gradient {
            return Ok(self.evaluate(x).0);
        }
        let c = self.cost.cost(&self.frame.phases(x));
        let c = if c.is_finite() { c } else { PENALTY };
        self.record(x, c);
        Ok(c)
    }
}

impl Gradient for &Problem<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;

    fn gradient(&self, x: &Vec<f64>) -> std::result::Result<Vec<f64>, argmin::core::Error> {
        if let Some(g) = self.kept_gradient(x) {
            return Ok(g);
        }
        self.check()?;
        Ok(self.evaluate(x).1)
    }
}
