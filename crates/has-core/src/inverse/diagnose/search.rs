//! The search of the discrepancy workflow: paths of effects added one at a time by evidence,
//! each candidate fitted (field parameters by Brent or L-BFGS on group kernels, image-space
//! parameters by Nelder–Mead with the linear ones projected out).

use super::brent::brent;
use super::effects::{params_of, FieldState, View, STEPS};
use super::forward::{Forward, MAX_GROUPS};
use super::{Candidate, Effect, Effects, Step, EQUIVALENCE};
use crate::control::Control;
use crate::error::{HasError, Result};
use crate::inverse::cost::{build_model, Measurement};
use crate::inverse::estimate::{point_reflection, Estimator, PENALTY};
use crate::simulation::Simulation;
use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use ndarray::Array2;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// A fitted candidate: its score and the model it leads to.
pub(super) struct Fitted {
    candidate: Candidate,
    effects: Effects,
}

/// A sequence of effects added to the model.
#[derive(Clone)]
pub(super) struct Path {
    pub(super) steps: Vec<Step>,
    pub(super) effects: Effects,
    pub(super) cost: f64,
    /// Candidates of the last round, none of which passed.
    pub(super) rejected: Vec<Candidate>,
}

impl Path {
    /// The effects added, in order.
    pub(super) fn included(&self) -> Vec<Effect> {
        self.steps.iter().map(|s| s.effect).collect()
    }

    /// `(J_0 - J) / sigma² - K·ln n` over the whole path.
    pub(super) fn total_evidence(&self) -> f64 {
        self.steps.iter().map(|s| s.evidence).sum()
    }
}

/// Whether `effect` adds parameters to a model whose free image-space slots are `free`.
fn adds_parameters(effect: Effect, free: &[usize]) -> bool {
    effect.slots().is_empty() || effect.slots().iter().any(|s| !free.contains(s))
}

/// The number of parameters `effect` adds (BIC's k).
fn parameters(effect: Effect, free: &[usize], groups: usize) -> f64 {
    match effect {
        Effect::PhaseAberration => groups.saturating_sub(1) as f64,
        Effect::ElementDropout | Effect::SoundSpeed | Effect::Attenuation => 1.0,
        e => e.slots().iter().filter(|s| !free.contains(s)).count() as f64,
    }
}

/// Extra penalty for a discrete choice among `groups` (which group is dead): `ln G`.
fn choice_penalty(effect: Effect, groups: usize) -> f64 {
    if effect == Effect::ElementDropout {
        (groups.max(1) as f64).ln()
    } else {
        0.0
    }
}

/// What every candidate fit needs.
pub(super) struct Context<'a> {
    pub(super) sim: &'a Simulation,
    pub(super) forward: &'a Forward<'a>,
    pub(super) measured: &'a [Array2<f64>],
    pub(super) max_iterations: usize,
    pub(super) noise: f64,
    /// BIC penalty per parameter, `ln n`.
    pub(super) penalty: f64,
    /// The last optimum of each searched field parameter.
    pub(super) memory: Mutex<Vec<(Effect, f64)>>,
    /// Set by another thread to stop: evaluations then return at once and the run ends.
    pub(super) cancel: &'a AtomicBool,
    /// When passed, evaluations return at once and each path keeps the steps it has.
    pub(super) deadline: Option<Instant>,
    pub(super) timed_out: AtomicBool,
}

/// Why evaluations stop early: a signal inside the search, never an error for the caller (a
/// cancel becomes [`HasError::Interrupted`]; a time limit ends the search with the steps so far).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Halt {
    Cancelled,
    TimeUp,
}

impl Context<'_> {
    /// Whether the time limit has passed; `Err(Interrupted)` when cancelled.
    fn out_of_time(&self) -> Result<bool> {
        match self.halted() {
            Some(Halt::Cancelled) => Err(HasError::Interrupted),
            Some(Halt::TimeUp) => Ok(true),
            None => Ok(false),
        }
    }

    /// Whether evaluations should stop: cancelled, or past the deadline.
    fn halted(&self) -> Option<Halt> {
        if self.cancel.load(Ordering::Relaxed) {
            return Some(Halt::Cancelled);
        }
        if self.deadline.is_some_and(|d| Instant::now() > d) {
            self.timed_out.store(true, Ordering::Relaxed);
            return Some(Halt::TimeUp);
        }
        None
    }

    /// Adds effects from `allowed` to `path` one at a time, the candidate with the largest
    /// evidence each round, while it exceeds `threshold`.
    pub(super) fn extend(&self, mut path: Path, allowed: &[Effect], threshold: f64) -> Result<Path> {
        loop {
            if self.out_of_time()? {
                return Ok(path);
            }
            let included = path.included();
            let free: Vec<usize> = included.iter().flat_map(|e| e.slots().iter().copied()).collect();
            let todo: Vec<Effect> = allowed.iter().copied().filter(|e| !included.contains(e) && adds_parameters(*e, &free)).collect();
            let g = self.sim.n_groups;
            let fits: Vec<Fitted> = todo
                .par_iter()
                .map(|&effect| match self.fit(effect, &path.effects, &free) {
                    Ok((c, e)) => {
                        let k = parameters(effect, &free, g);
                        let evidence = (path.cost - c) / self.noise.powi(2) - k * self.penalty - choice_penalty(effect, g);
                        Fitted { candidate: Candidate { effect, cost: c, evidence, failure: None }, effects: e }
                    }
                    Err(err) => Fitted {
                        candidate: Candidate { effect, cost: f64::INFINITY, evidence: f64::NEG_INFINITY, failure: Some(err.to_string()) },
                        effects: path.effects.clone(),
                    },
                })
                .collect();
            if self.out_of_time()? {
                return Ok(path); // this round's fits are incomplete
            }
            let best = fits.iter().enumerate().max_by(|a, b| a.1.candidate.evidence.total_cmp(&b.1.candidate.evidence).then(b.0.cmp(&a.0)));
            let Some((i, f)) = best.filter(|(_, f)| f.candidate.evidence > threshold) else {
                path.rejected = fits.into_iter().map(|f| f.candidate).collect();
                return Ok(path);
            };
            let top = f.candidate.evidence;
            let equivalent = fits
                .iter()
                .enumerate()
                .filter(|(j, g)| *j != i && g.candidate.evidence > threshold && g.candidate.evidence >= top - EQUIVALENCE)
                .map(|(_, g)| g.candidate.effect)
                .collect();
            let effect = f.candidate.effect;
            path.steps.push(Step {
                effect,
                params: params_of(effect, &f.effects, &path.effects),
                cost_before: path.cost,
                cost_after: f.candidate.cost,
                evidence: top,
                candidates: fits.iter().map(|f| f.candidate.clone()).collect(),
                equivalent,
                effects: f.effects.clone(),
                models: self.forward.images(&f.effects)?,
            });
            path.effects = f.effects.clone();
            path.cost = f.candidate.cost;
            path.rejected = vec![];
        }
    }

    /// Fits `effect` on top of `current` (image-space slots `free` refitted with it).
    fn fit(&self, effect: Effect, current: &Effects, free: &[usize]) -> Result<(f64, Effects)> {
        if matches!(effect, Effect::ElementDropout | Effect::PhaseAberration) && self.sim.n_groups > MAX_GROUPS {
            return Err(HasError::invalid(
                "groups",
                format!(
                    "{} groups: {} is fitted for at most {MAX_GROUPS} groups (use the default grouping)",
                    self.sim.n_groups,
                    effect.name()
                ),
            ));
        }
        let field = |f: FieldState| Effects { view: current.view, field: f };
        let start = match effect {
            Effect::SoundSpeed => self.search(
                effect,
                current.field.sound_speed,
                100.0,
                4.0,
                |c| FieldState { sound_speed: c, ..current.field.clone() },
                current,
            ),
            Effect::Attenuation => {
                let a0 = current.field.attenuation_db_cm_mhz;
                let state = |a: f64| FieldState { attenuation_db_cm_mhz: a.max(0.0), ..current.field.clone() };
                self.search(effect, a0, 1.5 * a0 + 0.25, 0.02, state, current)
            }
            Effect::ElementDropout => {
                let options: Vec<Effects> = (0..self.sim.n_groups)
                    .filter(|g| !current.field.dead_groups.contains(g))
                    .map(|g| {
                        let mut dead = current.field.dead_groups.clone();
                        dead.push(g);
                        dead.sort_unstable();
                        field(FieldState { dead_groups: dead, ..current.field.clone() })
                    })
                    .collect();
                let costs: Vec<f64> = options.iter().map(|e| self.cost(e)).collect();
                let best = (0..options.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
                best.map(|b| options[b].clone()).ok_or_else(|| HasError::invalid("element_dropout", "every group is already dead"))?
            }
            Effect::PhaseAberration => field(FieldState { group_phases: self.group_phases(current)?, ..current.field.clone() }),
            Effect::SliceOffset => {
                // The image changes nearly alike on both sides of the focus, so Nelder–Mead from
                // zero may settle on the wrong side: start from the best of a 2 mm scan.
                let at = |dz: f64| Effects { view: View { slice_offset_mm: dz, ..current.view }, field: current.field.clone() };
                let scan = (-3..=3).map(|k| 2.0 * k as f64 + 1.0 * (k as f64).signum()).chain([current.view.slice_offset_mm]);
                let best = scan.map(|dz| (self.cost(&at(dz)), dz)).min_by(|a, b| a.0.total_cmp(&b.0)).map_or(0.0, |b| b.1);
                at(best)
            }
            _ => current.clone(),
        };
        let mut slots = free.to_vec();
        slots.extend(effect.slots().iter().filter(|s| !free.contains(s)));
        if slots.is_empty() {
            return Ok((self.cost(&start), start));
        }
        self.fit_view(&start, &slots)
    }

    fn cost(&self, e: &Effects) -> f64 {
        if self.halted().is_some() {
            return f64::INFINITY;
        }
        self.forward.cost(e, self.measured)
    }

    /// Brent search of one field parameter within `reach` of `centre` to `tol`, the view of
    /// `current` held; returns the model at the optimum. Later rounds search within a fifth of
    /// the reach around this effect's last optimum, and widen again when the optimum lands near
    /// an end. Each evaluation marches.
    fn search(&self, effect: Effect, centre: f64, reach: f64, tol: f64, state: impl Fn(f64) -> FieldState, current: &Effects) -> Effects {
        let model = |x: f64| Effects { view: current.view, field: state(x) };
        let cost = |x: f64| self.cost(&model(x));
        let last = self.memory.lock().ok().and_then(|m| m.iter().find(|(e, _)| *e == effect).map(|(_, x)| *x));
        let narrowed =
            last.map(|x0| (x0, brent(cost, x0 - 0.2 * reach, x0 + 0.2 * reach, tol).0)).filter(|(x0, x)| (x - x0).abs() < 0.16 * reach);
        let x = narrowed.map_or_else(|| brent(cost, centre - reach, centre + reach, tol).0, |(_, x)| x);
        if let Ok(mut m) = self.memory.lock() {
            m.retain(|(e, _)| *e != effect);
            m.push((effect, x));
        }
        model(x)
    }

    /// Group phases fitted by multi-start L-BFGS on the group kernels of the current model
    /// (its view and medium; dead groups are not modelled here), added to the current ones.
    fn group_phases(&self, current: &Effects) -> Result<Vec<f64>> {
        let s = self.sim;
        let f = &current.field;
        // The window lies in the focal material (water around it absorbs nothing), so the
        // force-coefficient ratio is a scale.
        let (sim, ratio) = self.forward.in_medium(f)?;
        let mut sim = sim.into_owned();
        let v = &current.view;
        let slice = self.forward.slice(v.slice_offset_mm)?;
        sim.sampler = Ok(slice.with_view(v.widths_mm().map(|w| w * 1e-3), v.shift_mm.map(|x| x * 1e-3))?);
        sim.amplitude = Ok(s.amplitude()? * v.scale * ratio);
        let background = self.forward.images(&Effects { view: View { scale: 0.0, ..*v }, field: f.clone() })?;
        let measurements = self
            .measured
            .iter()
            .zip(&background)
            .zip(&self.forward.knowns)
            .map(|((m, b), k)| {
                let known = k.iter().zip(&s.groups).map(|(x, &g)| x + f.group_phases.get(g).copied().unwrap_or(0.0)).collect();
                Measurement { image: m - b, known }
            })
            .collect::<Vec<_>>();
        let hybrid = build_model(&sim, &measurements, s.mask_fraction, 3)?;
        let positions = s.transducer.reference_points();
        let estimate = Estimator::lbfgs()
            .with_twins(point_reflection(&positions, &s.groups))
            .with_time_limit_opt(self.deadline.map(|d| d.saturating_duration_since(Instant::now()).max(Duration::from_millis(1))))
            .run(&hybrid.cost, Control::default().with_cancel(self.cancel))?;
        Ok(estimate.phases.iter().enumerate().map(|(g, p)| p + f.group_phases.get(g).copied().unwrap_or(0.0)).collect())
    }

    /// Fits the image-space `slots` (indices into [`View::to_vec`]) from `start`: the scale and
    /// the background by linear least squares inside every evaluation, the others by
    /// Nelder–Mead in units of [`STEPS`]; returns the best cost and model.
    fn fit_view(&self, start: &Effects, slots: &[usize]) -> Result<(f64, Effects)> {
        let linear: Vec<usize> = slots.iter().copied().filter(|k| matches!(k, 0 | 5..=7)).collect();
        let nonlinear: Vec<usize> = slots.iter().copied().filter(|k| !linear.contains(k)).collect();
        let problem = ViewFit { ctx: self, base: start.view.to_vec(), field: &start.field, slots: &nonlinear, linear: &linear };
        let x = if nonlinear.is_empty() {
            vec![]
        } else {
            let x0 = vec![0.0; nonlinear.len()];
            let mut simplex = vec![x0.clone()];
            for i in 0..nonlinear.len() {
                let mut y = x0.clone();
                y[i] = 1.0;
                simplex.push(y);
            }
            // Costs matter to a small fraction of sigma² (the evidence unit).
            let tolerance = 1e-4 * self.noise.powi(2);
            let solver = NelderMead::new(simplex).with_sd_tolerance(tolerance).map_err(|e| HasError::invalid("diagnose", e.to_string()))?;
            let res = Executor::new(&problem, solver)
                .configure(|s| s.max_iters(self.max_iterations as u64))
                .run()
                .map_err(|e| HasError::invalid("diagnose", e.to_string()))?;
            res.state().best_param.clone().unwrap_or(x0)
        };
        if self.out_of_time()? {
            // The round this fit belongs to is dropped: no model to report.
            return Ok((f64::INFINITY, start.clone()));
        }
        let (c, view) = problem.evaluate(&x)?;
        if !c.is_finite() {
            return Err(HasError::invalid("diagnose", "the fitted model cannot be evaluated"));
        }
        Ok((c, Effects { view, field: start.field.clone() }))
    }
}

/// The fit of image-space parameters: Nelder–Mead over `slots`, `linear` projected out.
struct ViewFit<'a> {
    ctx: &'a Context<'a>,
    base: [f64; 9],
    field: &'a FieldState,
    slots: &'a [usize],
    linear: &'a [usize],
}

impl ViewFit<'_> {
    /// The view at `x` (with its linear parameters solved) and its cost.
    fn evaluate(&self, x: &[f64]) -> Result<(f64, View)> {
        match self.ctx.halted() {
            Some(Halt::Cancelled) => return Err(HasError::Interrupted),
            Some(Halt::TimeUp) => return Ok((f64::INFINITY, View::from_vec(&self.base))),
            None => {}
        }
        let mut v = self.base;
        for (&k, &xi) in self.slots.iter().zip(x) {
            v[k] += xi * STEPS[k];
        }
        let e = Effects { view: View::from_vec(&v), field: self.field.clone() };
        let force = self.ctx.forward.force_images(&e)?;
        let (view, c) = self.ctx.forward.project(force, e.view, self.linear, self.ctx.measured);
        Ok((c, view))
    }
}

impl CostFunction for &ViewFit<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        let c = self.evaluate(x).map_or(f64::INFINITY, |r| r.0);
        Ok(if c.is_finite() { c } else { PENALTY })
    }
}
