//! A scenario made ready to simulate: grid, steered source, HAS plan and MR sampler.
//!
//! Fields need no MR model: where the MR slice cannot be sampled (outside the grid) or the ideal
//! beam exerts no radiation force there (lossless water), the simulation still gives fields and
//! only the ARFI images, fits and diagnoses report why they cannot be made.

use crate::error::{HasError, Result};
use crate::focal::FocalMetrics;
use crate::grouping;
use crate::memory;
use crate::phase::wrap;
use crate::physics::grid::Grid;
use crate::physics::medium::{Material, Medium};
use crate::physics::mr::{add_noise, focal_peak, MrGeometry, MrSampler};
use crate::physics::propagation::{HasPlan, RecordSpec, Recording, Window};
use crate::physics::source::SourceModel;
use crate::physics::steering::steering_phases;
use crate::physics::transducer::Transducer;
use crate::scenario::Scenario;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use std::sync::Arc;

mod build;
mod external;
mod focus;
mod grid;
mod hottest;
mod regrid;
mod volume;
pub(crate) use build::Unbuilt;
pub use external::ExternalField;
pub use grid::{choose_grid, coarser_grid, with_chosen_grid};
pub use hottest::{tissue_classes_on, TissueHottest};
pub use volume::{
    check_ct_volume, crop_volume, intensity_in_ct, intensity_on_window, resample_into_ct, window_affine, window_of_box, CtPressureVolume,
    PressureVolume,
};

/// Everything needed to simulate fields and MR-ARFI images of one scenario (cloning shares the
/// HAS operators).
#[derive(Clone)]
pub struct Simulation {
    /// The scenario's name.
    pub name: String,
    /// Driving frequency f, Hz.
    pub frequency: f64,
    /// The grid the beam is marched on.
    pub grid: Grid,
    /// The acoustic medium: materials, background, regions and any voxel map.
    pub medium: Medium,
    /// The medium that steers where it is not `medium` (see [`Simulation::steering_medium`]).
    steering_medium: Option<Medium>,
    /// The array (element number = index).
    pub transducer: Transducer,
    /// The steering target in the transducer frame, m.
    pub focus: [f64; 3],
    /// Steering phases per element (rad): a phase `phi` delays that element's emission by
    /// `phi / (2·pi·f)`.
    pub steering: Vec<f64>,
    /// Drive amplitude of each element relative to the scenario's (see
    /// [`Simulation::with_element_amplitudes`]; 1 for all by default).
    element_amplitudes: Arc<Vec<f64>>,
    /// Element → group (default: 16 groups of contiguous elements).
    pub groups: Vec<usize>,
    /// Number of groups G (groups are numbered 0 to G-1).
    pub n_groups: usize,
    /// The map from element drives to the pressure on the source plane (plane 0).
    pub source: SourceModel,
    /// The source plane of the steered array (no added phases), kept: projecting curved
    /// elements is the costly part of a field.
    steered_source: Arc<Vec<C64>>,
    /// The HAS plan through the medium, built with the steered beam as reference.
    pub plan: HasPlan,
    /// The MR image geometry of the scenario.
    pub mr: MrGeometry,
    /// The MR sampler, or why there is none (see [`Simulation::sampler`]).
    pub(crate) sampler: Result<MrSampler>,
    /// Scale from broadened force density (N/m³) to ARFI phase (rad), or why there is none.
    pub(crate) amplitude: Result<f64>,
    /// Focal-zone level (paper Eq. 4): fits use the pixels above this fraction of each image's
    /// maximum that are connected to it.
    pub mask_fraction: f64,
    /// Radius (m, in the image plane) around the target within which an image's focal maximum is
    /// sought (see [`Simulation::focal_region`]).
    pub focal_search_radius: f64,
    /// Standard deviation of the Gaussian noise the scenario assumes on ARFI phase images
    /// (`[arfi] noise_rad`), rad.
    pub noise: f64,
    /// Whether marches add the reflected waves (scenario `[grid] reflections`).
    pub reflections: bool,
}

/// How the simulation crosses changes of medium: the model, and the reverberation zone if any.
#[derive(Debug, Clone, PartialEq)]
pub struct Propagation {
    /// `"angular"` or `"normal-incidence"` (see [`crate::physics::propagation::InterfaceModel`]).
    pub interfaces: &'static str,
    /// `"oblique"` or `"vertical"` (see [`crate::physics::propagation::Screen`]).
    pub screen: &'static str,
    /// z (m) of the first and last interface between which reverberation is added, and the round
    /// trips added; `None` where no two interfaces reflect strongly enough.
    pub reverberation: Option<(f64, f64, usize)>,
    /// Whether waves reflected back towards the source are added.
    pub reflections: bool,
    /// Whether the march carries shear waves (a solid's faces with other media on the planes,
    /// see [`HasPlan::carries_shear`]).
    pub shear: bool,
}

/// A pressure field on one plane and along the beam axis.
#[derive(Debug, Clone)]
pub struct Field {
    /// Complex pressure amplitude (Pa), `(ny, nx)`.
    pub pressure: Array2<C64>,
    /// x of each column of `pressure`, m.
    pub x: Vec<f64>,
    /// y of each row of `pressure`, m.
    pub y: Vec<f64>,
    /// z of the plane (m).
    pub z: f64,
    /// Complex pressure amplitude (Pa) on the beam's axis, one per grid plane: the line from the
    /// array's centre (the origin) through the focus (x = y = 0 for a focus on the z axis).
    pub axis_pressure: Vec<C64>,
    /// z of each sample of `axis_pressure`, m.
    pub axis_z: Vec<f64>,
    /// x and y of each sample of `axis_pressure`, m.
    pub axis_xy: Vec<[f64; 2]>,
    /// Pressure amplitude on every element face (Pa).
    pub surface_pressure: f64,
    /// The focal region's metrics in 3-D ([`FocalMetrics`]); `None` when the target lies outside
    /// the grid or the -6 dB region around it reaches the grid's edge.
    pub metrics: Option<FocalMetrics>,
    /// `|p|` in 3-D and the hottest places, kept by [`Simulation::field_with_volume`].
    pub volume: Option<FieldVolume>,
}

/// What a field made with [`Simulation::field_with_volume`] keeps of the whole grid.
#[derive(Debug, Clone)]
pub struct FieldVolume {
    /// `|p|` (Pa) on every grid sample, row-major (plane, row, column), single precision: the
    /// volume `arfi field --volume` writes ([`window_affine`] places a box of it,
    /// [`resample_into_ct`] lays it on a CT).
    pub magnitude: Vec<f32>,
    /// The hottest place of each tissue class over the whole grid, hottest first
    /// ([`Simulation::hottest_by_tissue`]).
    pub hottest: Vec<TissueHottest>,
}

impl Simulation {
    /// Resolves the scenario, chooses the grid, steers to the focus and builds the HAS plan (one
    /// march of the steered beam) and the MR sampler.
    ///
    /// ```
    /// use has_core::{Scenario, Simulation};
    /// let sim = Simulation::new(&Scenario::default())?; // the paper's phantom experiment
    /// assert_eq!((sim.n_elements(), sim.n_groups), (1024, 16));
    /// # Ok::<(), has_core::HasError>(())
    /// ```
    pub fn new(scenario: &Scenario) -> Result<Self> {
        Unbuilt::new(scenario)?.build()
    }

    /// [`Simulation::new`] reusing the source model `kept` (another simulation's
    /// [`Simulation::source`]) where this scenario's array, grid, acoustic power and coupling
    /// medium are the same ([`SourceModel::new_reusing`]): its elements' projections are then
    /// shared, not made again. The same simulation either way.
    pub fn new_reusing(scenario: &Scenario, kept: &SourceModel) -> Result<Self> {
        Unbuilt::new_reusing(scenario, Some(kept))?.build()
    }

    /// The medium whose straight-ray times of flight give the steering: `medium`, or the head
    /// without its skull with `[ct] steer_without_bone`
    /// ([`crate::scenario::Resolved::steering_medium`]).
    pub fn steering_medium(&self) -> &Medium {
        self.steering_medium.as_ref().unwrap_or(&self.medium)
    }

    /// The steered source plane (no added phases), Pa.
    pub fn steered_source(&self) -> &[C64] {
        &self.steered_source
    }

    /// The same simulation with another broadening width W (m) and amplitude (rad·m³/N), e.g.
    /// from a calibration; the HAS plan is shared.
    pub fn with_calibration(&self, broadening_width: f64, amplitude: f64) -> Result<Self> {
        crate::error::require_positive("amplitude", amplitude)?;
        let mut s = self.clone();
        s.sampler = Ok(self.sampler()?.with_broadening(broadening_width)?);
        s.amplitude = Ok(amplitude);
        Ok(s)
    }

    /// The same simulation with each element driven at `amplitudes` (one per element, ≥ 0, not
    /// all zero) times the scenario's amplitude: e.g. a CT prediction's per-element transmission,
    /// so that a model of the head without its skull loses at each element what the skull loses
    /// there (its focus then as weak as the skull's, and its elements weighted as through it).
    /// The HAS plan, the ARFI amplitude and the MR sampler are kept; the steered source plane is
    /// projected again.
    pub fn with_element_amplitudes(&self, amplitudes: &[f64]) -> Result<Self> {
        if amplitudes.len() != self.n_elements() {
            return Err(HasError::invalid("amplitudes", format!("has {} values for {} elements", amplitudes.len(), self.n_elements())));
        }
        if amplitudes.iter().any(|a| !a.is_finite() || *a < 0.0) || amplitudes.iter().all(|&a| a == 0.0) {
            return Err(HasError::invalid("amplitudes", "must be finite and non-negative, and not all zero"));
        }
        let mut s = self.clone();
        s.element_amplitudes = Arc::new(amplitudes.to_vec());
        s.steered_source = Arc::new(s.source.field(&s.steered_drives())?);
        Ok(s)
    }

    /// Each element's drive amplitude relative to the scenario's (see
    /// [`Simulation::with_element_amplitudes`]).
    pub fn element_amplitudes(&self) -> &[f64] {
        &self.element_amplitudes
    }

    /// The complex drive of element `e` with `added` phase (rad) on top of its steering:
    /// `a_e·exp(i·(steering_e + added))`.
    pub fn drive(&self, e: usize, added: f64) -> C64 {
        C64::from_polar(self.element_amplitudes[e], self.steering[e] + added)
    }

    /// Each element's drive with no added phase: `a_e·exp(i·steering_e)` ([`Simulation::drive`]).
    fn steered_drives(&self) -> Vec<C64> {
        (0..self.n_elements()).map(|e| self.drive(e, 0.0)).collect()
    }

    /// This simulation's MR sampler (geometry, broadening, shift) made anew on `grid` through
    /// `medium`.
    fn sampler_on(&self, grid: &Grid, medium: &Medium) -> Result<MrSampler> {
        let old = self.sampler()?;
        MrSampler::new(grid, medium, self.frequency, &old.geometry, old.broadening)?.with_view([old.broadening.width; 2], old.shift)
    }

    /// The MR sampler (the map from `|p|²` on the MR window to the image without its amplitude),
    /// or why this scenario has none (the MR slice lies outside the simulation grid).
    pub fn sampler(&self) -> Result<&MrSampler> {
        self.sampler.as_ref().map_err(Clone::clone)
    }

    /// The scale (rad·m³/N) from broadened force density to ARFI phase, or why this scenario has
    /// none (no radiation force in the MR slice, e.g. lossless water, and none given).
    pub fn amplitude(&self) -> Result<f64> {
        self.amplitude.clone()
    }

    /// The same simulation (steering, groups, amplitude and sampler window kept: the device is
    /// driven as before) in a medium whose material `material` has another sound speed (m/s)
    /// and attenuation (dB/cm/MHz); rebuilds the HAS plan and the force coefficients.
    pub fn with_material(&self, material: usize, sound_speed: f64, attenuation_db_cm_mhz: f64) -> Result<Self> {
        let spec = RecordSpec { reflections: self.reflections, ..RecordSpec::default() };
        self.with_material_recording(material, sound_speed, attenuation_db_cm_mhz, &spec).map(|(sim, _)| sim)
    }

    /// [`Simulation::with_material`], and the new plan's recording `spec` of the steered beam
    /// ([`Simulation::steered_source`]): the build marches that beam to fix the plan's mean
    /// wavenumbers, so the recording costs no second march and equals the new plan's
    /// `propagate` of the steered source.
    pub fn with_material_recording(
        &self,
        material: usize,
        sound_speed: f64,
        attenuation_db_cm_mhz: f64,
        spec: &RecordSpec,
    ) -> Result<(Self, Recording)> {
        let (sim, recording) = self.with_material_plan(material, sound_speed, attenuation_db_cm_mhz, spec)?;
        let sampler = sim.sampler_on(&sim.grid, &sim.medium)?;
        Ok((Simulation { sampler: Ok(sampler), ..sim }, recording))
    }

    /// [`Simulation::with_material_recording`] with the HAS plan alone rebuilt: the sampler stays
    /// this simulation's (the force coefficients of the old medium), for a caller that maps the
    /// recorded `|p|²` itself (the discrepancy workflow scales it by the coefficients' ratio), and
    /// spares the sampler's build (its slab map over the MR window).
    pub(crate) fn with_material_plan(
        &self,
        material: usize,
        sound_speed: f64,
        attenuation_db_cm_mhz: f64,
        spec: &RecordSpec,
    ) -> Result<(Self, Recording)> {
        let Some(m) = self.medium.materials.get(material) else {
            return Err(HasError::invalid("material", format!("index {material} names no material")));
        };
        let mut medium = self.medium.clone();
        let changed = Material { sound_speed, attenuation_db_cm_mhz, ..m.clone() };
        changed.validate()?;
        medium.materials[material] = changed;
        let (plan, recording) = HasPlan::build(&self.grid, &medium, self.frequency, &self.steered_source, &self.plan.options, spec)?;
        Ok((Simulation { medium, plan, ..self.clone() }, recording))
    }

    /// Replaces the element → group map (every group from 0 to G-1 must have an element).
    pub fn set_groups(&mut self, groups: Vec<usize>) -> Result<()> {
        self.n_groups = grouping::check_groups(&groups, self.n_elements())?;
        self.groups = groups;
        Ok(())
    }

    /// The interface model, screen and reverberation this simulation uses.
    pub fn propagation(&self) -> Propagation {
        Propagation {
            interfaces: self.plan.options.interfaces.name(),
            screen: self.plan.options.screen.name(),
            reverberation: self.plan.reverberation().map(|(a, b, n)| (self.grid.z(a), self.grid.z(b), n)),
            reflections: self.reflections,
            shear: self.plan.carries_shear(),
        }
    }

    /// Number of elements.
    pub fn n_elements(&self) -> usize {
        self.steering.len()
    }

    /// Known phases (rad, one per element) that move the focus by `shift` (m, transducer frame):
    /// the steering phases for `focus + shift` minus the current ones. Added to an
    /// acquisition they give a displaced or, along the axis, defocused diversity image: the
    /// classic phase-diversity choice (Gonsalves, Opt. Eng. 21, 829, 1982). A defocused image
    /// spreads the beam over more pixels while keeping it bright, and it tells an aberration
    /// from its twin, so it carries more information per image than random group phases.
    pub fn focus_shift_phases(&self, shift: [f64; 3]) -> Result<Vec<f64>> {
        crate::error::require_finite("shift", &shift)?;
        let target = [self.focus[0] + shift[0], self.focus[1] + shift[1], self.focus[2] + shift[2]];
        let moved = self.steering_toward(target)?;
        Ok(moved.iter().zip(&self.steering).map(|(m, s)| wrap(m - s)).collect())
    }

    /// The scenario's steering phases (rad, one per element) toward `target` (m): straight-ray
    /// times of flight through the steering medium, as for the focus (whose are kept).
    pub fn steering_toward(&self, target: [f64; 3]) -> Result<Vec<f64>> {
        if target == self.focus {
            return Ok(self.steering.clone());
        }
        steering_phases(&self.transducer, self.steering_medium(), self.frequency, target)
    }

    /// Expands added phases (rad), one per element or one per group, to one per element
    /// ([`grouping::per_element`]).
    pub fn element_phases(&self, phases: &[f64]) -> Result<Vec<f64>> {
        grouping::per_element("phases", phases, &self.groups, self.n_groups)
    }

    /// Source plane for the steering plus `added` phases (per element or per group; empty or all
    /// zero = none, the kept steered plane).
    pub fn source_field(&self, added: &[f64]) -> Result<Vec<C64>> {
        match self.added_drive(added)? {
            None => Ok(self.steered_source.to_vec()),
            Some(drive) => self.source.field(&drive),
        }
    }

    /// [`Simulation::source_field`] of several drives, the projection's kernel evaluated once for
    /// all of those that add phases ([`SourceModel::fields`]).
    pub fn source_fields(&self, added: &[Vec<f64>]) -> Result<Vec<Vec<C64>>> {
        let drives = added.iter().map(|a| self.added_drive(a)).collect::<Result<Vec<_>>>()?;
        let (with_phases, phasors): (Vec<usize>, Vec<Vec<C64>>) =
            drives.into_iter().enumerate().filter_map(|(i, d)| d.map(|d| (i, d))).unzip();
        let mut out = vec![self.steered_source.to_vec(); added.len()];
        for (i, field) in with_phases.into_iter().zip(self.source.fields(&phasors)?) {
            out[i] = field;
        }
        Ok(out)
    }

    /// The element drives (steering plus `added`, per element or per group) when `added` holds
    /// any phase, `None` for none (the steered source serves); `added` is checked either way.
    fn added_drive(&self, added: &[f64]) -> Result<Option<Vec<C64>>> {
        crate::error::require_finite("phases", added)?;
        if added.is_empty() {
            return Ok(None);
        }
        let extra = self.element_phases(added)?;
        Ok(added.iter().any(|&a| a != 0.0).then(|| extra.iter().enumerate().map(|(e, a)| self.drive(e, *a)).collect()))
    }

    /// One source plane per group: steering plus `known` element phases (rad; empty = none) on
    /// that group's elements, nothing elsewhere. They add up to the whole array's source.
    pub fn group_sources(&self, groups: &[usize], known: &[f64]) -> Result<Vec<Vec<C64>>> {
        let n = self.n_elements();
        if groups.len() != n {
            return Err(HasError::invalid("groups", format!("has {} entries for {n} elements", groups.len())));
        }
        let known = if known.is_empty() { vec![0.0; n] } else { self.element_phases(known)? };
        let g_count = grouping::count(groups);
        (0..g_count)
            .map(|g| {
                let drive: Vec<C64> = (0..n).map(|e| if groups[e] == g { self.drive(e, known[e]) } else { C64::new(0.0, 0.0) }).collect();
                self.source.field(&drive)
            })
            .collect()
    }

    /// The field on the plane nearest `z` (default: the focus) and along the axis, for
    /// `added` phases (per element or per group; empty: none), with the focal metrics in 3-D from
    /// a box around the target recorded in the same march ([`FocalMetrics`]). Needs no MR model:
    /// works in lossless water.
    ///
    /// ```
    /// use has_core::{Scenario, Simulation};
    /// let water = "[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 40.0\naperture_diameter_mm = 30.0\n\
    ///              [focus]\nposition_mm = [0.0, 0.0, 40.0]\n[medium]\nbackground = \"water\"\n\
    ///              [[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n";
    /// let sim = Simulation::new(&Scenario::from_toml(water, None)?)?;
    /// let field = sim.field(&[], None)?; // the focal plane (z = 40 mm) and the axis
    /// let peak = field.axis_pressure.iter().map(|p| p.norm()).fold(0.0, f64::max);
    /// assert!(peak > 5.0 * field.surface_pressure); // a bowl focuses
    /// assert!(sim.arfi_image(&[]).is_err()); // no radiation force in lossless water
    /// # Ok::<(), has_core::HasError>(())
    /// ```
    pub fn field(&self, added: &[f64], z: Option<f64>) -> Result<Field> {
        self.field_with(added, z, false)
    }

    /// [`Simulation::field`] with `|p|` kept on every grid sample in the same march, and the
    /// hottest place of each tissue class found in it ([`FieldVolume`]): what `arfi field`
    /// reports and writes. Refused before the march when the volume would not fit in memory.
    pub fn field_with_volume(&self, added: &[f64], z: Option<f64>) -> Result<Field> {
        self.field_with(added, z, true)
    }

    fn field_with(&self, added: &[f64], z: Option<f64>, keep_volume: bool) -> Result<Field> {
        let g = &self.grid;
        let z = z.unwrap_or(self.focus[2]);
        if !z.is_finite() || z < g.z0 || z > g.z(g.nz - 1) {
            return Err(HasError::invalid("z_mm", format!("must lie within the grid, {:.1} to {:.1} mm", g.z0 * 1e3, g.z(g.nz - 1) * 1e3)));
        }
        let plane = g.plane_index(z);
        let slope = self.axis_slope();
        let whole = Window::whole(g);
        if keep_volume {
            memory::check(
                || format!("|p| on the whole {} x {} x {} grid (the hottest place of each tissue, the volume)", g.nx, g.ny, g.nz),
                whole.len() as u64 * volume::BYTES_PER_VOXEL,
                "use a coarser grid ([grid] spacing_mm)",
            )?;
        }
        let spec = RecordSpec {
            planes: vec![plane],
            axis: true,
            axis_slope: slope,
            magnitude: keep_volume.then_some(whole),
            reflections: self.reflections,
            ..RecordSpec::default()
        };
        let (mut rec, metrics) = self.record_with_focus(&self.source_field(added)?, spec)?;
        let volume = keep_volume.then(|| {
            let magnitude = std::mem::take(&mut rec.magnitude);
            FieldVolume { hottest: self.hottest_by_tissue(&magnitude), magnitude }
        });
        let pressure = Array2::from_shape_vec((g.ny, g.nx), rec.planes.remove(0)).map_err(|e| HasError::invalid("field", e.to_string()))?;
        Ok(self.assemble_field(pressure, plane, rec.axis, metrics, volume))
    }

    /// The [`Field`] of `pressure` on grid plane `plane` and `axis` (one per plane from plane 0,
    /// on the beam's axis), with its metrics and kept volume: the grid's coordinates filled in
    /// whichever engine computed the pressure.
    fn assemble_field(
        &self,
        pressure: Array2<C64>,
        plane: usize,
        axis: Vec<C64>,
        metrics: Option<FocalMetrics>,
        volume: Option<FieldVolume>,
    ) -> Field {
        let g = &self.grid;
        let slope = self.axis_slope();
        Field {
            pressure,
            x: (0..g.nx).map(|i| g.x(i)).collect(),
            y: (0..g.ny).map(|j| g.y(j)).collect(),
            z: g.z(plane),
            axis_z: (0..axis.len()).map(|n| g.z(n)).collect(),
            axis_xy: (0..axis.len()).map(|n| [slope[0] * g.z(n), slope[1] * g.z(n)]).collect(),
            axis_pressure: axis,
            surface_pressure: self.source.face_pressure,
            metrics,
            volume,
        }
    }

    /// Lateral offset per unit depth of the beam's axis, the line from the array's centre (the
    /// origin of the transducer frame) through the focus (zero for a focus on the z axis).
    pub fn axis_slope(&self) -> [f64; 2] {
        if self.focus[2] > 0.0 {
            [self.focus[0] / self.focus[2], self.focus[1] / self.focus[2]]
        } else {
            [0.0, 0.0]
        }
    }

    /// Each element's complex pressure (Pa) at `target` (m, transducer frame; between grid points,
    /// the march's field interpolated there, see [`HasPlan::point_weights`]) when it alone is
    /// driven with a unit phasor (no steering): `p = Σ_e h_e · d_e` for
    /// drives `d`. By reciprocity, one transposed march from that point back to the source plane
    /// ([`HasPlan::transposed`]) and one transposed projection onto the elements
    /// ([`SourceModel::transposed`]) give all of them, instead of one march per element; they
    /// equal what one march per element gives, to the rounding of the single-precision Rayleigh
    /// sums (`tests/suite/reciprocity.rs`).
    pub fn element_responses(&self, target: [f64; 3]) -> Result<Vec<C64>> {
        self.source.transposed(&reciprocal_field(&self.plan, target, self.reflections)?)
    }

    /// The noise-free MR-ARFI phase image (rad), `(n_u, n_v)`, for added phases (per element
    /// or per group).
    ///
    /// ```
    /// use has_core::{Scenario, Simulation};
    /// let sim = Simulation::new(&Scenario::default())?;
    /// let ideal = sim.arfi_image(&[])?;
    /// let peak = ideal.iter().copied().fold(0.0, f64::max);
    /// assert!((peak - 0.6).abs() < 1e-9); // the scenario sets the ideal focal ARFI phase
    /// let aberrated = sim.arfi_image(&[1.0, -1.0, 0.5, 2.0, 0.0, 0.3, -0.7, 1.1, 0.9, -1.4, 0.2, 0.0, 1.6, -0.2, 0.4, -0.9])?;
    /// assert!(aberrated.iter().copied().fold(0.0, f64::max) < peak);
    /// # Ok::<(), has_core::HasError>(())
    /// ```
    pub fn arfi_image(&self, added: &[f64]) -> Result<Array2<f64>> {
        let rec = self.record_window(&[self.source_field(added)?])?.remove(0);
        self.sampler()?.arfi_image(&rec.window, self.amplitude()?)
    }

    /// An MR-ARFI image with seeded Gaussian noise of `noise` rad added (NaN stays NaN).
    pub fn noisy_arfi_image(&self, added: &[f64], noise: f64, seed: u64) -> Result<Array2<f64>> {
        let mut img = self.arfi_image(added)?;
        add_noise(&mut img, noise, seed)?;
        Ok(img)
    }

    /// The pixels within [`Simulation::focal_search_radius`] of the focus in the image plane,
    /// `(n_u, n_v)`: where an image's focal maximum is sought.
    pub fn focal_region(&self) -> Array2<bool> {
        self.mr.pixels_near(self.focus, self.focal_search_radius)
    }

    /// The focal ARFI of an image (paper's metric): its largest imaged pixel within the focal
    /// region ([`Simulation::focal_region`]), with that pixel's index; an error naming `name` when
    /// no imaged pixel lies there.
    pub fn focal_arfi(&self, image: &Array2<f64>, name: &str) -> Result<((usize, usize), f64)> {
        focal_peak(image, &self.focal_region()).ok_or_else(|| {
            HasError::invalid(
                name,
                format!(
                    "has no imaged pixel (all NaN: no MR signal) within {:.1} mm of the target ({:.1}, {:.1}, {:.1}) mm in its \
                     plane (arfi.focal_search_radius_mm)",
                    self.focal_search_radius * 1e3,
                    self.focus[0] * 1e3,
                    self.focus[1] * 1e3,
                    self.focus[2] * 1e3
                ),
            )
        })
    }

    /// Marches several sources in one batch, keeping the MR window.
    pub fn record_window(&self, sources: &[Vec<C64>]) -> Result<Vec<Recording>> {
        self.record_in(&self.sampler()?.window, sources)
    }

    /// The bytes of the plan's steps to plane `last` in single precision
    /// ([`HasPlan::single_precision_bytes`]), or `None` where this simulation marches reflections
    /// back, which no single-precision plan does, or `last` is beyond the grid: where
    /// [`HasPlan::single_precision`] may serve its marches to a window ending at `last`.
    pub fn single_precision_bytes(&self, last: usize) -> Option<u64> {
        if self.reflections {
            None
        } else {
            self.plan.single_precision_bytes(last)
        }
    }

    /// Marches several sources in one batch, keeping `window` (e.g. a restricted sampler's),
    /// with reflections as the simulation marches.
    pub fn record_in(&self, window: &Window, sources: &[Vec<C64>]) -> Result<Vec<Recording>> {
        let spec = RecordSpec { window: Some(window.clone()), reflections: self.reflections, ..RecordSpec::default() };
        self.plan.propagate_batch(sources, &spec)
    }
}

/// Where `p` (m) lies against the grid's span, mm.
pub(crate) fn outside_grid(g: &Grid, p: [f64; 3]) -> String {
    format!(
        "({:.1}, {:.1}, {:.1}) mm lies outside the grid (x, y within ±{:.1} mm, z {:.1} to {:.1} mm)",
        p[0] * 1e3,
        p[1] * 1e3,
        p[2] * 1e3,
        0.5 * g.nx as f64 * g.dx * 1e3,
        g.z0 * 1e3,
        g.z(g.nz - 1) * 1e3
    )
}

/// The transposed march through `plan` from `target` (m; between grid points, the band-limited
/// interpolation of [`HasPlan::point_weights`]): the source-plane field whose dot product with a
/// source plane is that source's pressure there (`reflections` as the simulation marches).
pub(crate) fn reciprocal_field(plan: &HasPlan, target: [f64; 3], reflections: bool) -> Result<Vec<C64>> {
    crate::error::require_finite("target", &target)?;
    let Some((plane, weights)) = plan.point_weights(target) else {
        return Err(HasError::invalid("target", outside_grid(&plan.grid, target)));
    };
    plan.transposed(plane, &weights, reflections)
}

/// The grid row nearest y = `y` (m) and the spec that records the x–z section there: every
/// plane, that row, all columns (`reflections` as the simulation marches).
pub(crate) fn section_spec(g: &Grid, y: f64, reflections: bool) -> Result<(usize, RecordSpec)> {
    let Some([_, row, _]) = g.nearest([0.0, y, g.z0]) else {
        return Err(HasError::invalid("y_mm", format!("must lie within the grid, ±{:.1} mm", 0.5 * g.ny as f64 * g.dy * 1e3)));
    };
    let window = Window { planes: 0..g.nz, rows: row..row + 1, cols: 0..g.nx };
    Ok((row, RecordSpec { window: Some(window), reflections, ..RecordSpec::default() }))
}
