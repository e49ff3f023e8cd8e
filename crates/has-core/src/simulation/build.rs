//! A simulation up to its HAS plan: the resolved scenario, the grid, the steering and the
//! steered source, from which [`Unbuilt::build`] builds the plan (the costly part: one march of
//! the steered beam, more through reverberating layers). Kept apart so that a caller can build
//! another plan from the same pieces first (the prediction's head without bone) and never hold
//! two plans at once.

use super::{choose_grid, section_spec, Simulation};
use crate::error::{HasError, Result};
use crate::physics::grid::Grid;
use crate::physics::medium::Medium;
use crate::physics::mr::{focal_peak, Broadening, MrSampler};
use crate::physics::propagation::{HasOptions, HasPlan, RecordSpec};
use crate::physics::source::SourceModel;
use crate::physics::steering::steering_phases;
use crate::scenario::{Resolved, Scenario};
use num_complex::Complex64 as C64;
use std::sync::Arc;

/// Everything of a [`Simulation`] but its HAS plan and ARFI amplitude.
pub(crate) struct Unbuilt {
    r: Resolved,
    pub(crate) grid: Grid,
    steering: Vec<f64>,
    pub(crate) source: SourceModel,
    pub(crate) options: HasOptions,
    sampler: Result<MrSampler>,
    /// The source plane of the steered array (the plan's reference beam), once made.
    steered_source: Option<Vec<C64>>,
}

impl Unbuilt {
    /// Resolves the scenario, chooses the grid, steers to the focus and projects the steered
    /// source; checks the medium before the source plane and on the grid.
    pub(crate) fn new(scenario: &Scenario) -> Result<Self> {
        Unbuilt::new_reusing(scenario, None)
    }

    /// [`Unbuilt::new`] with the source model `kept` reused where it is the one this scenario
    /// needs ([`SourceModel::new_reusing`]).
    pub(crate) fn new_reusing(scenario: &Scenario, kept: Option<&SourceModel>) -> Result<Self> {
        let r = scenario.resolve()?;
        let grid = choose_grid(&r)?;
        check_medium(&r, &grid)?;
        let steering = steering_of(&r)?;
        let at_source = at_source(&r, &grid);
        let k0 = 2.0 * std::f64::consts::PI * r.frequency / at_source.sound_speed;
        // Plane-wave power: P = p_face² · A / (2·Z) for the whole radiating area A.
        let face_pressure = (2.0 * at_source.impedance() * r.acoustic_power / r.transducer.area()).sqrt();
        let source = SourceModel::new_reusing(&r.transducer, &grid, face_pressure, k0, at_source.attenuation, kept)?;
        let options = options_of(&r)?;
        let sampler = MrSampler::new(&grid, &r.medium, r.frequency, &r.mr, Broadening { width: r.broadening_width });
        Ok(Unbuilt { r, grid, steering, source, options, sampler, steered_source: None })
    }

    /// `march(plan, reflections)` (e.g. transposed marches from the targets) through the head of
    /// `other`, a scenario that differs from this one's in its medium only (e.g. the CT's bone
    /// faster): its plan built as
    /// [`Simulation::new`] builds it (its own steering's beam as reference) but on this
    /// simulation's grid and source model (their projections shared), then dropped and its memory
    /// handed back. `None` when `other` resolves to another grid, options, array, frequency,
    /// acoustic power, reflections or source-plane medium, whose simulation must be built on its
    /// own. Its medium is checked as [`Unbuilt::new`] checks one.
    pub(crate) fn reciprocal_fields_of<T>(&self, other: &Scenario, march: impl FnOnce(&HasPlan, bool) -> Result<T>) -> Result<Option<T>> {
        let r = other.resolve()?;
        let same = choose_grid(&r)? == self.grid
            && options_of(&r)? == self.options
            && r.transducer == self.r.transducer
            && r.frequency == self.r.frequency
            && r.acoustic_power == self.r.acoustic_power
            && r.grid.reflections == self.r.grid.reflections
            && at_source(&r, &self.grid) == at_source(&self.r, &self.grid);
        if !same {
            return Ok(None);
        }
        check_medium(&r, &self.grid)?;
        let steering = steering_of(&r)?;
        let field = {
            let steered = steered_field(&self.source, &steering)?;
            let (plan, _) = HasPlan::build(&self.grid, &r.medium, r.frequency, &steered, &self.options, &RecordSpec::default())?;
            march(&plan, self.reflections())?
        };
        crate::memory::release_freed();
        Ok(Some(field))
    }

    /// The steered array's field on plane 0 (made by the first call, unless the build makes it
    /// while it samples the medium).
    pub(crate) fn steered_source(&mut self) -> Result<&[C64]> {
        let field = match self.steered_source.take() {
            Some(field) => field,
            None => steered_field(&self.source, &self.steering)?,
        };
        Ok(self.steered_source.insert(field))
    }

    /// The scenario's medium.
    pub(crate) fn medium(&self) -> &Medium {
        &self.r.medium
    }

    /// The steering target (m, transducer frame).
    pub(crate) fn focus(&self) -> [f64; 3] {
        self.r.focus
    }

    /// Driving frequency (Hz).
    pub(crate) fn frequency(&self) -> f64 {
        self.r.frequency
    }

    /// Whether marches add the reflected waves.
    pub(crate) fn reflections(&self) -> bool {
        self.r.grid.reflections.unwrap_or(false)
    }

    /// Builds the HAS plan with the steered beam as reference and, unless the scenario gives the
    /// ARFI amplitude, calibrates it from the ideal image (the plan's own march of that beam:
    /// free without reverberation, one more march with it).
    pub(crate) fn build(self) -> Result<Simulation> {
        let window = self.sampler.as_ref().ok().filter(|_| self.r.amplitude.is_none()).map(|s| s.window.clone());
        self.build_recording(RecordSpec { window, ..RecordSpec::default() })
    }

    /// [`Unbuilt::build`] whose march of the steered beam records the x–z section nearest y =
    /// `y` (m) when the scenario gives the ARFI amplitude (else the ideal image, to calibrate it)
    /// and adds no reflections (a reflecting section would cost the build a march it does not
    /// keep): through reverberating layers the plan keeps that recording, so that
    /// [`Simulation::section`] of the steered beam there needs no march of its own.
    pub(crate) fn build_with_section(self, y: f64) -> Result<Simulation> {
        if self.r.amplitude.is_none() || self.reflections() {
            return self.build();
        }
        let (_, spec) = section_spec(&self.grid, y, self.reflections())?;
        self.build_recording(spec)
    }

    /// The build, its march of the steered beam recording `spec` (the MR window when the
    /// amplitude is to be calibrated).
    fn build_recording(self, spec: RecordSpec) -> Result<Simulation> {
        let Unbuilt { r, grid, steering, source, options, sampler, steered_source } = self;
        let (plan, ideal, steered_source) = match steered_source {
            Some(s) => HasPlan::build(&grid, &r.medium, r.frequency, &s, &options, &spec).map(|(p, i)| (p, i, s))?,
            None => HasPlan::build_with_reference(&grid, &r.medium, r.frequency, || steered_field(&source, &steering), &options, &spec)?,
        };
        let amplitude = match (r.amplitude, &sampler) {
            (Some(a), _) => Ok(a),
            (None, Err(e)) => Err(e.clone()),
            (None, Ok(sampler)) => {
                let mut force = sampler.force_image(&ideal.window)?;
                sampler.blank_unimaged(&mut force);
                match focal_peak(&force, &r.mr.pixels_near(r.focus, r.focal_search_radius)) {
                    Some((_, peak)) if peak > 0.0 => Ok(r.ideal_focal_phase / peak),
                    _ => Err(HasError::invalid(
                        "mr",
                        format!(
                            "the ideal beam exerts no radiation force in the MR slice on imaged tissue within \
                             arfi.focal_search_radius_mm = {:.1} of the focus (no attenuating soft tissue there?): fields can be \
                             simulated, MR-ARFI images cannot",
                            r.focal_search_radius * 1e3
                        ),
                    )),
                }
            }
        };
        let groups = r.transducer.default_groups();
        let n_groups = crate::grouping::count(&groups);
        Ok(Simulation {
            name: r.name,
            frequency: r.frequency,
            grid,
            medium: r.medium,
            steering_medium: r.steering_medium,
            transducer: r.transducer,
            focus: r.focus,
            element_amplitudes: Arc::new(vec![1.0; steering.len()]),
            steering,
            groups,
            n_groups,
            source,
            steered_source: Arc::new(steered_source),
            plan,
            mr: r.mr,
            sampler,
            amplitude,
            mask_fraction: r.mask_fraction,
            focal_search_radius: r.focal_search_radius,
            noise: r.noise,
            reflections: r.grid.reflections.unwrap_or(false),
        })
    }
}

/// The field on plane 0 of the array steered by `steering` (rad per element).
fn steered_field(source: &SourceModel, steering: &[f64]) -> Result<Vec<C64>> {
    source.field(&steering.iter().map(|&p| C64::from_polar(1.0, p)).collect::<Vec<_>>())
}

/// Checks the medium before the source plane (along each element's path to the focus) and on
/// `grid`.
fn check_medium(r: &Resolved, grid: &Grid) -> Result<()> {
    r.medium.check_before_source_plane(grid.z0, &r.transducer.reference_points(), r.focus, grid.dz.min(0.5e-3), r.frequency)?;
    r.medium.check_on_grid(grid)
}

/// Each element's steering phase (rad) to the focus through the steering medium.
fn steering_of(r: &Resolved) -> Result<Vec<f64>> {
    steering_phases(&r.transducer, r.steering_medium.as_ref().unwrap_or(&r.medium), r.frequency, r.focus)
}

/// The medium the elements radiate into: half a step before `grid`'s first plane, on the axis.
fn at_source(r: &Resolved, grid: &Grid) -> crate::physics::medium::Properties {
    r.medium.properties_at(0.0, 0.0, grid.z0 - 0.5 * grid.dz, r.frequency)
}

/// The march's options that the scenario's `[grid]` sets.
fn options_of(r: &Resolved) -> Result<HasOptions> {
    Ok(HasOptions {
        sponge_width: r.grid.sponge_width_mm.map_or(HasOptions::default().sponge_width, |w| w * 1e-3),
        interfaces: r.grid.interface_model()?,
        screen: r.grid.screen_model(r.focus)?,
        ..HasOptions::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bowl through a bone plate (which reverberates), the amplitude given: the build with a
    /// section keeps the steered beam's section through y = 1 mm, so that `Simulation::section`
    /// of the steering is not marched again; with reflections (which a build's counting march
    /// does not record) or an amplitude to calibrate, it builds as `build` does and keeps none.
    #[test]
    fn a_build_with_a_section_keeps_the_steered_beams_section() {
        let text = |grid: &str, arfi: &str| {
            format!(
                "frequency_hz = 500000.0\n[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 40.0\naperture_diameter_mm = 30.0\n\
                 [focus]\nposition_mm = [0.0, 0.0, 40.0]\n[grid]\nspacing_mm = 0.5\nz_max_mm = 50.0\n{grid}[arfi]\n{arfi}\
                 [medium]\nbackground = \"water\"\n[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
                 [[material]]\nname = \"bone\"\nsound_speed_m_s = 2800.0\ndensity_kg_m3 = 1850.0\nattenuation_db_cm_mhz = 4.0\n\
                 [[region]]\nmaterial = \"bone\"\nshape = \"slab\"\nz_min_mm = 20.0\nz_max_mm = 26.0\n"
            )
        };
        let given = "amplitude_rad_m3_per_n = 1.0\n";
        for (grid, arfi, keeps) in [("", given, true), ("reflections = true\n", given, false), ("", "", false)] {
            let scenario = Scenario::from_toml(&text(grid, arfi), None).unwrap();
            let sim = Unbuilt::new(&scenario).unwrap().build_with_section(1e-3).unwrap();
            assert!(sim.plan.reverberation().is_some_and(|z| z.2 > 0), "the plate does not reverberate");
            let (_, spec) = section_spec(&sim.grid, 1e-3, sim.reflections).unwrap();
            assert_eq!(sim.plan.kept_recording(&sim.steered_source, &spec).is_some(), keeps, "{grid}{arfi}");
        }
    }
}
