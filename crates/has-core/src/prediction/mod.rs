//! CT-based prediction of the skull's per-element aberration, by reciprocity.
//!
//! For every element `e`, `h_e` is its complex pressure at the target for unit drive
//! ([`Simulation::element_responses`]: one transposed march and one transposed projection for
//! all elements), once through the scenario's head with its CT and once through the same head
//! with the CT's bone read as soft tissue (the *reference*: what the estimation's model, the
//! head without its skull, assumes). The predicted aberration is
//!
//! `phi_e = arg(h_e^skull · conj(h_e^reference)) - c`,
//!
//! the phase the skull adds to element `e` at the target, in the sign of estimated phases (an
//! aberration adds to the steering; subtracting it corrects), with the common phase `c` =
//! `arg Σ_e h_e^skull · conj(h_e^reference)` removed (the images see phase differences only). The
//! transmission is `|h_e^skull| / |h_e^reference|`. Since the march is linear, every focal
//! pressure below is exact in the model: `|Σ_e h_e · exp(i·drive_e)|` for the drive in question.
//! The reference's plan is fixed by the same steered beam as the skull's (its mean wavenumbers
//! are weighted by that beam's pressure; see [`crate::physics::propagation`]).

use crate::control::Control;
use crate::error::{HasError, Result};
use crate::phase::wrap;
use crate::physics::grid::Grid;
use crate::physics::medium::Medium;
use crate::physics::propagation::{HasOptions, HasPlan, RecordSpec};
use crate::physics::source::SourceModel;
use crate::physics::steering::steering_phases;
use crate::physics::transducer::Transducer;
use crate::scenario::Scenario;
use crate::simulation::{outside_grid, reciprocal_field, Simulation, Unbuilt};
use num_complex::Complex64 as C64;
use std::sync::atomic::{AtomicUsize, Ordering};

pub mod pose;
pub use pose::{pose_sensitivity, PoseSensitivity};

/// The prediction for one target, with the focal pressures it implies (Pa, for the
/// scenario's drive amplitude).
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// The point predicted for (m, transducer frame); between grid points, the fields are
    /// interpolated there (see [`crate::physics::propagation::HasPlan::point_weights`]).
    pub target: [f64; 3],
    /// Predicted aberration per element (rad, wrapped to (-π, π]), relative to the reference
    /// steering: driving `reference_steering - phases` corrects it.
    pub phases: Vec<f64>,
    /// Pressure transmission per element at the target: `|h^skull| / |h^reference|`.
    pub transmission: Vec<f64>,
    /// Steering phases (rad) of the reference toward the target (straight-ray times of flight
    /// through the head without bone): at the focus, those of the estimation's model.
    pub reference_steering: Vec<f64>,
    /// Reference steering through the reference head (no skull).
    pub reference_pressure: f64,
    /// The most any phases give through the reference head, `Σ_e |h_e^reference|`:
    /// `reference_pressure` below it is what the straight-ray reference steering misses without
    /// any bone (refraction and oblique paths through the soft tissue), which the predicted phases,
    /// relative to that steering, do not correct either.
    pub reference_optimal_pressure: f64,
    /// Reference steering through the skull: the aberrated focus.
    pub uncorrected_pressure: f64,
    /// The scenario's own steering toward the target through the skull (straight-ray times of
    /// flight through the CT's bone; at the focus, as `Simulation::field` drives it).
    pub ray_steering_pressure: f64,
    /// Reference steering minus the predicted phases, through the skull.
    pub corrected_pressure: f64,
    /// The most any phases can give through the skull at this drive amplitude, `Σ_e |h_e^skull|`
    /// (every element's wave arriving in phase).
    pub optimal_pressure: f64,
    /// The focus the array gives at the target in water (the coupling medium everywhere, no head)
    /// with every element in phase, `Σ_e |h_e^water|` (Pa; each `h_e` a direct Rayleigh sum,
    /// [`crate::physics::source::SourceModel::free_field_responses`]): what a focus through the head is
    /// measured against.
    pub water_pressure: f64,
    /// Each element's complex pressure at the target through the skull for unit drive, Pa.
    pub skull_responses: Vec<C64>,
}

impl Prediction {
    /// The focal pressure (Pa) through this prediction's skull when the array is driven with the
    /// reference steering minus `phases` (one per element), e.g. another prediction's: what a
    /// prediction made with wrong CT constants would give on this skull.
    pub fn pressure_with(&self, phases: &[f64]) -> Result<f64> {
        if phases.len() != self.skull_responses.len() {
            return Err(HasError::invalid("phases", format!("has {} values for {} elements", phases.len(), self.skull_responses.len())));
        }
        crate::error::require_finite("phases", phases)?;
        Ok(focal_pressure(&self.skull_responses, |e| self.reference_steering[e] - phases[e]))
    }
}

/// `|Σ_e h_e · exp(i·drive(e))|`: the focal pressure of element responses `h` (Pa per unit drive)
/// for the drive phases `drive(e)` (rad).
fn focal_pressure(h: &[C64], drive: impl Fn(usize) -> f64) -> f64 {
    h.iter().enumerate().map(|(e, h)| h * C64::from_polar(1.0, drive(e))).sum::<C64>().norm()
}

/// The prediction at `target` (m; `None`: the focus) of a scenario with a `[ct]`:
/// [`predict_scenario_with`] without its options. Its simulations are built without calibrating
/// the ARFI amplitude from the ideal image, which a prediction does not use (through a
/// reverberating head that is one whole march more, with all its round trips).
pub fn predict_scenario(scenario: &Scenario, target: Option<[f64; 3]>) -> Result<Prediction> {
    Ok(predict_scenario_with(scenario, target, PredictionOptions::default())?.prediction)
}

/// What [`predict_scenario_with`] computes beside the prediction.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PredictionOptions {
    /// Also [`bone_speed_sensitivity`]: one more simulation of the skull.
    pub bone_speed_sensitivity: bool,
    /// Also the [`pose_sensitivity`]: six more transposed marches through the skull (side by
    /// side with the target's), projected with the prediction's, and one evaluation of the
    /// Rayleigh kernel's gradient; no plan.
    pub pose_sensitivity: bool,
    /// Return the skull's simulation (ARFI amplitude not calibrated: 1 unless the scenario gives
    /// one), e.g. to march the predicted correction without building its plan again. Without
    /// reflections, its build records the steered beam's x–z section through the target: through
    /// reverberating bone the plan keeps it, and [`Simulation::section`] of the steered beam there
    /// is free.
    pub keep_simulation: bool,
}

/// A prediction and what its [`PredictionOptions`] asked for.
pub struct PredictionRun {
    /// The prediction.
    pub prediction: Prediction,
    /// Per element, rad per percent of bone sound speed (see [`bone_speed_sensitivity`]).
    pub bone_speed_sensitivity: Option<Vec<f64>>,
    /// The modes of the CT's registration (see [`pose_sensitivity`]).
    pub pose_sensitivity: Option<PoseSensitivity>,
    /// The skull's simulation, built from [`with_amplitude`] of the scenario.
    pub simulation: Option<Simulation>,
}

/// [`predict_scenario`] with the bone speed and pose sensitivities and the skull's simulation on
/// request: [`predict_targets_with`] for the one target.
pub fn predict_scenario_with(scenario: &Scenario, target: Option<[f64; 3]>, options: PredictionOptions) -> Result<PredictionRun> {
    let unbuilt = Unbuilt::new(&with_amplitude(scenario.clone()))?;
    let target = target.unwrap_or(unbuilt.focus());
    let TargetsRun { mut runs, simulation } = predict_from(unbuilt, scenario, &[target], options, Control::default())?;
    let TargetRun { prediction, bone_speed_sensitivity, pose_sensitivity } = runs.remove(0);
    Ok(PredictionRun { prediction, bone_speed_sensitivity, pose_sensitivity, simulation })
}

/// What [`predict_targets_with`] gives for one target.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetRun {
    /// The prediction.
    pub prediction: Prediction,
    /// Per element, rad per percent of bone sound speed (see [`bone_speed_sensitivity`]).
    pub bone_speed_sensitivity: Option<Vec<f64>>,
    /// The modes of the CT's registration (see [`pose_sensitivity`]).
    pub pose_sensitivity: Option<PoseSensitivity>,
}

/// The predictions of [`predict_targets_with`], in the order of its targets, and the skull's
/// simulation where asked for.
pub struct TargetsRun {
    /// One per target.
    pub runs: Vec<TargetRun>,
    /// The skull's simulation, built from [`with_amplitude`] of the scenario.
    pub simulation: Option<Simulation>,
}

/// Predictions at many targets (m, transducer frame) from one plan of each head: the reference
/// head's plan is built once and marched from every target, then dropped; then the skull's,
/// likewise (and the faster bone's first, for the bone speed sensitivity). A plan depends on the
/// head, the grid and the scenario's steering, not on the target, so each target beyond the
/// first costs its transposed marches and projection, not a plan. Each target's values equal
/// [`predict_scenario_with`]'s at that target to the last bit. The scenario's grid must hold
/// every target, and a planning target lies in the head: a target outside the grid or outside the
/// CT's box is refused, by its index and position, before anything is built. `control`'s
/// progress counts the transposed marches; cancelling ends the run at the next march.
/// The plans are built one after another, each dropped (and its memory handed back,
/// [`crate::memory::release_freed`]) before the next unless kept: the faster bone's (on the
/// skull's grid and source model, whose element projections it shares, where the faster bone
/// resolves to the same grid), the reference head's, then the skull's; never two at once. The
/// marches from the targets run two side by side, and each target's transposed marches are
/// projected onto the elements in one pass.
pub fn predict_targets_with(scenario: &Scenario, targets: &[[f64; 3]], options: PredictionOptions, control: Control) -> Result<TargetsRun> {
    let unbuilt = Unbuilt::new(&with_amplitude(scenario.clone()))?;
    check_targets(&unbuilt, targets)?;
    predict_from(unbuilt, scenario, targets, options, control)
}

/// Refuses an empty list of targets, or one off the grid or outside the CT's box, by its index.
fn check_targets(unbuilt: &Unbuilt, targets: &[[f64; 3]]) -> Result<()> {
    if targets.is_empty() {
        return Err(HasError::invalid("targets", "none given"));
    }
    let ct = unbuilt.medium().ct.clone().ok_or_else(no_ct)?;
    for (k, &target) in targets.iter().enumerate() {
        let at = || format!("target {k} ({:.1}, {:.1}, {:.1}) mm", target[0] * 1e3, target[1] * 1e3, target[2] * 1e3);
        crate::error::require_finite("targets", &target)?;
        if !unbuilt.grid.holds_point(target) {
            return Err(HasError::invalid("targets", format!("target {k} {}", outside_grid(&unbuilt.grid, target))));
        }
        if ct.hu_at(target).is_none() {
            let [lo, hi] = ct.bounds();
            let span = |a: usize| format!("{:.1} to {:.1}", lo[a] * 1e3, hi[a] * 1e3);
            return Err(HasError::invalid(
                "targets",
                format!("{} lies outside the CT (its box spans x {}, y {}, z {} mm)", at(), span(0), span(1), span(2)),
            ));
        }
    }
    Ok(())
}

/// The tissue class at each of `targets` (m, transducer frame) as the skull's simulation names
/// it ([`Simulation::tissue_classes`]: `skull`, `scalp`, the CT's soft tissue by name, the
/// coupling medium's), from the scenario's grid and head alone: no plan is built, so a planning
/// grid can be kept to the brain before anything is predicted. Targets are refused as by
/// [`predict_targets_with`].
pub fn target_tissues(scenario: &Scenario, targets: &[[f64; 3]]) -> Result<Vec<String>> {
    let unbuilt = Unbuilt::new(&with_amplitude(scenario.clone()))?;
    check_targets(&unbuilt, targets)?;
    crate::simulation::tissue_classes_on(&unbuilt.grid, unbuilt.medium(), unbuilt.focus(), targets)
}

/// Counts a prediction's transposed marches for its [`Control`], and runs them.
struct Marches<'a> {
    control: Control<'a>,
    done: AtomicUsize,
    total: usize,
}

impl Marches<'_> {
    /// `march()`, after the cancel check, then counted.
    fn counted<T>(&self, march: impl FnOnce() -> Result<T>) -> Result<T> {
        self.control.check()?;
        let out = march()?;
        self.control.report(self.done.fetch_add(1, Ordering::Relaxed) + 1, self.total);
        Ok(out)
    }

    /// The transposed march from `target` through `plan` ([`reciprocal_field`]), counted.
    fn one(&self, plan: &HasPlan, target: [f64; 3], reflections: bool) -> Result<Vec<C64>> {
        self.counted(|| reciprocal_field(plan, target, reflections))
    }

    /// [`Marches::one`] from each of `targets`, side by side ([`pose::side_by_side`]).
    fn each(&self, plan: &HasPlan, targets: &[[f64; 3]], reflections: bool) -> Result<Vec<Vec<C64>>> {
        pose::side_by_side(targets, |&t| self.one(plan, t, reflections))
    }
}

/// The predictions at `targets` from the scenario made ready to build ([`predict_targets_with`]).
fn predict_from(
    mut unbuilt: Unbuilt,
    scenario: &Scenario,
    targets: &[[f64; 3]],
    options: PredictionOptions,
    control: Control,
) -> Result<TargetsRun> {
    let n = targets.len();
    let per_skull = if options.pose_sensitivity { 7 } else { 1 };
    let marches = Marches { control, done: AtomicUsize::new(0), total: n * (1 + per_skull + usize::from(options.bone_speed_sensitivity)) };
    // Through the faster bone: marches to be projected with the others, or (another grid) the
    // responses of a simulation of its own.
    let faster = if options.bone_speed_sensitivity {
        let faster = with_amplitude(faster_bone(scenario)?);
        Some(match unbuilt.reciprocal_fields_of(&faster, |plan, reflections| marches.each(plan, targets, reflections))? {
            Some(fields) => Ok(fields),
            None => {
                let sim = Simulation::new(&faster)?;
                let responses = targets.iter().map(|&t| marches.counted(|| sim.element_responses(t))).collect::<Result<Vec<_>>>()?;
                drop(sim);
                crate::memory::release_freed();
                Err(responses)
            }
        })
    } else {
        None
    };
    let reference_medium = without_bone(unbuilt.medium())?;
    let steered_source = unbuilt.steered_source()?.to_vec();
    let reflections = unbuilt.reflections();
    let through_reference =
        through_reference(&unbuilt.grid, &reference_medium, unbuilt.frequency(), &steered_source, &unbuilt.options, |plan| {
            marches.each(plan, targets, reflections)
        })?;
    drop(steered_source);
    let sim = if options.keep_simulation { unbuilt.build_with_section(targets[0][1])? } else { unbuilt.build()? };
    // The skull's marches: with the pose modes, each target's own and its six moved targets'.
    let mut through_skull: Vec<(Vec<C64>, Vec<Vec<C64>>)> = if options.pose_sensitivity {
        targets.iter().map(|&t| pose::skull_marches(&sim, t, &|q| marches.one(&sim.plan, q, sim.reflections))).collect::<Result<_>>()?
    } else {
        marches.each(&sim.plan, targets, sim.reflections)?.into_iter().map(|f| (f, Vec::new())).collect()
    };
    let (mut faster_fields, mut faster_responses) = match faster {
        Some(Ok(fields)) => (fields.into_iter().map(Some).collect(), Vec::new()),
        Some(Err(responses)) => (vec![None; n], responses.into_iter().map(Some).collect()),
        None => (vec![None; n], Vec::new()),
    };
    let mut runs = Vec::with_capacity(n);
    for (k, (&target, reference)) in targets.iter().zip(through_reference).enumerate() {
        let (skull, moved_fields) = std::mem::take(&mut through_skull[k]);
        // The fields projected at once: the skull's, the reference's, the faster bone's and the
        // moved targets' for the pose modes.
        let mut fields = vec![skull, reference];
        fields.extend(faster_fields[k].take());
        let moved_from = fields.len();
        fields.extend(moved_fields);
        let mut responses = sim.source.transposed_many(&fields)?;
        let moved = responses.split_off(moved_from);
        let faster = if responses.len() == 3 { responses.pop() } else { faster_responses.get_mut(k).and_then(Option::take) };
        let reference = responses.remove(1);
        let skull = responses.remove(0);
        let water = water_pressure(&sim.source, target);
        let prediction = from_responses(
            &sim.transducer,
            &reference_medium,
            sim.frequency,
            target,
            [skull, reference],
            sim.steering_toward(target)?,
            water,
        )?;
        let pose_sensitivity = options
            .pose_sensitivity
            .then(|| pose::pose_modes(&sim, target, &fields[0], &prediction.skull_responses, &moved))
            .transpose()?;
        let bone_speed_sensitivity = faster.map(|m| sensitivity(&m, &prediction.skull_responses)).transpose()?;
        runs.push(TargetRun { prediction, bone_speed_sensitivity, pose_sensitivity });
    }
    let simulation = if options.keep_simulation {
        Some(sim)
    } else {
        drop(sim);
        crate::memory::release_freed();
        None
    };
    Ok(TargetsRun { runs, simulation })
}

/// `scenario` with the ARFI amplitude given (1 unless it sets one), so that its simulation is
/// not calibrated from an ideal image: for predictions, which make none. The scenario of the
/// skull's simulation a [`PredictionRun`] keeps.
pub fn with_amplitude(mut scenario: Scenario) -> Scenario {
    scenario.arfi.amplitude_rad_m3_per_n.get_or_insert(1.0);
    scenario
}

/// The head without its skull, or why a prediction cannot be made without a CT.
fn without_bone(medium: &Medium) -> Result<Medium> {
    medium.without_bone().ok_or_else(no_ct)
}

/// Why a prediction cannot be made without a CT.
fn no_ct() -> HasError {
    HasError::invalid("ct", "a prediction needs a CT of the head ([ct]): it predicts what the CT's bone does to each element's wave")
}

/// Predicts the aberration of the scenario's CT bone at `target` (m; `None`: the focus).
/// Costs two transposed marches (through the skull and through the reference head, whose plan is
/// built for the purpose) and one transposed projection, whatever the number of elements. Takes
/// the simulation by value: its plan is dropped once its march is done, so that the two plans
/// are never held at once (a 650 kHz hemisphere's plan through a head holds several GB).
/// Refused without a `[ct]`.
pub fn predict(sim: Simulation, target: Option<[f64; 3]>) -> Result<Prediction> {
    let target = target.unwrap_or(sim.focus);
    let reference_medium = without_bone(&sim.medium)?;
    let through_skull = reciprocal_field(&sim.plan, target, sim.reflections)?;
    let ray_steering = sim.steering_toward(target)?;
    let steered_source = sim.steered_source().to_vec();
    let Simulation { plan, grid, frequency, source, transducer, reflections, .. } = sim;
    let options = plan.options.clone();
    drop(plan);
    crate::memory::release_freed();
    let through_reference = through_reference(&grid, &reference_medium, frequency, &steered_source, &options, |plan| {
        reciprocal_field(plan, target, reflections)
    })?;
    let mut responses = source.transposed_many(&[through_skull, through_reference])?;
    let (reference, skull) = (responses.remove(1), responses.remove(0));
    let water = water_pressure(&source, target);
    from_responses(&transducer, &reference_medium, frequency, target, [skull, reference], ray_steering, water)
}

/// `march(plan)` (the transposed marches from the targets) through the head without bone
/// (`medium`), its plan built with the skull's grid, steered source and options, then dropped and
/// its memory handed back.
fn through_reference<T>(
    grid: &Grid,
    medium: &Medium,
    frequency: f64,
    steered_source: &[C64],
    options: &HasOptions,
    march: impl FnOnce(&HasPlan) -> Result<T>,
) -> Result<T> {
    let out = {
        let (plan, _) = HasPlan::build(grid, medium, frequency, steered_source, options, &RecordSpec::default())?;
        march(&plan)?
    };
    crate::memory::release_freed();
    Ok(out)
}

/// `Σ_e |h_e|` of the array's elements at `target` (m) in water ([`Prediction::water_pressure`]).
fn water_pressure(source: &SourceModel, target: [f64; 3]) -> f64 {
    source.free_field_responses(target).iter().map(|h| h.norm()).sum()
}

/// The prediction at `target` from each element's response through the skull and through the
/// reference head (`[skull, reference]`), the reference steering through `reference_medium`, the
/// scenario's own steering `ray_steering` (rad) and the focus in water `water` (Pa).
fn from_responses(
    transducer: &Transducer,
    reference_medium: &Medium,
    frequency: f64,
    target: [f64; 3],
    [skull, reference]: [Vec<C64>; 2],
    ray_steering: Vec<f64>,
    water: f64,
) -> Result<Prediction> {
    let reference_steering = steering_phases(transducer, reference_medium, frequency, target)?;
    let common = skull.iter().zip(&reference).map(|(s, r)| s * r.conj()).sum::<C64>().arg();
    let phases: Vec<f64> = skull.iter().zip(&reference).map(|(s, r)| wrap((s * r.conj()).arg() - common)).collect();
    let transmission = skull.iter().zip(&reference).map(|(s, r)| if r.norm() > 0.0 { s.norm() / r.norm() } else { 0.0 }).collect();
    Ok(Prediction {
        target,
        reference_pressure: focal_pressure(&reference, |e| reference_steering[e]),
        reference_optimal_pressure: reference.iter().map(|h| h.norm()).sum(),
        uncorrected_pressure: focal_pressure(&skull, |e| reference_steering[e]),
        ray_steering_pressure: focal_pressure(&skull, |e| ray_steering[e]),
        corrected_pressure: focal_pressure(&skull, |e| reference_steering[e] - phases[e]),
        optimal_pressure: skull.iter().map(|h| h.norm()).sum(),
        water_pressure: water,
        phases,
        transmission,
        reference_steering,
        skull_responses: skull,
    })
}

/// The relative step of the bone sound speed over which [`bone_speed_sensitivity`] takes its
/// difference (+10 %).
pub const BONE_SPEED_STEP: f64 = 0.1;

/// How the predicted phases move when the CT conversion's bone sound speed is misjudged: per
/// element, the change of the predicted aberration (rad) per percent of bone sound speed,
/// `g_e = wrap(arg(h'_e · conj(h_e)) - c) / (100·BONE_SPEED_STEP)` with `h'` the responses
/// through the same skull with `bone_sound_speed_m_s` [`BONE_SPEED_STEP`] higher and `c` their
/// weighted common phase (the reference's responses cancel: the head without bone does not
/// change). A finite difference through the wave model, not straight rays: oblique paths
/// through bone move differently from their straight-ray times (on the 650 kHz head phantom the
/// straight-ray change does not correlate with it at all). `s·g` is the prediction's error mode
/// for a conversion off by `s` percent ([`crate::inverse::prior::Prior::with_modes`]). Costs a
/// simulation of the skull (plan, march, projection) beyond `prediction`'s, which must have been
/// made from `scenario`. Refused without the porosity conversion (the constant is its own).
pub fn bone_speed_sensitivity(scenario: &Scenario, prediction: &Prediction) -> Result<Vec<f64>> {
    let moved = Simulation::new(&with_amplitude(faster_bone(scenario)?))?.element_responses(prediction.target)?;
    sensitivity(&moved, &prediction.skull_responses)
}

/// `scenario` with the CT conversion's bone sound speed [`BONE_SPEED_STEP`] higher.
fn faster_bone(scenario: &Scenario) -> Result<Scenario> {
    let base = bone_sound_speed(scenario)?;
    let mut faster = scenario.clone();
    if let Some(c) = faster.ct.as_mut() {
        c.bone_sound_speed_m_s = Some(base * (1.0 + BONE_SPEED_STEP));
    }
    Ok(faster)
}

/// The sensitivity from the responses `moved` through the faster bone and `h` through the skull.
fn sensitivity(moved: &[C64], h: &[C64]) -> Result<Vec<f64>> {
    Ok(phase_change(moved, h)?.into_iter().map(|d| d / (100.0 * BONE_SPEED_STEP)).collect())
}

/// Each element's phase change (rad) from responses `h` to `moved`,
/// `wrap(arg(moved_e · conj(h_e)) − c)`, with the common phase `c = arg Σ_e moved_e · conj(h_e)`
/// removed (weighted by the responses: the images see phase differences only).
pub fn phase_change(moved: &[C64], h: &[C64]) -> Result<Vec<f64>> {
    if moved.len() != h.len() {
        return Err(HasError::invalid("prediction", format!("has {} elements; the scenario has {}", h.len(), moved.len())));
    }
    let change: Vec<C64> = moved.iter().zip(h).map(|(m, h)| m * h.conj()).collect();
    let common = change.iter().sum::<C64>().arg();
    Ok(change.iter().map(|c| wrap(c.arg() - common)).collect())
}

/// The CT conversion's bone sound speed (m/s) in `scenario`, or why it has none for
/// [`bone_speed_sensitivity`] (no `[ct]`, or a conversion other than the porosity model's):
/// checked before a prediction that is to be followed by it.
pub fn bone_sound_speed(scenario: &Scenario) -> Result<f64> {
    let ct = scenario.ct.as_ref().ok_or_else(|| HasError::invalid("ct", "a bone speed sensitivity needs a CT of the head ([ct])"))?;
    if ct.conversion != "aubry2003" {
        return Err(HasError::invalid(
            "ct.conversion",
            format!("'{}' has no bone sound speed: the bone speed sensitivity needs conversion = \"aubry2003\"", ct.conversion),
        ));
    }
    Ok(ct.bone_sound_speed_m_s.unwrap_or(crate::physics::ct::Porosity::default().bone_sound_speed))
}
