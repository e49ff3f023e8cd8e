//! Hybrid Angular Spectrum propagation (Vyas & Christensen, IEEE TUFFC 59(6), 2012).
//!
//! Each step of length `dz` from plane `n` to plane `n + 1`:
//! 1. at a change of medium, the interface (see [`InterfaceModel`] and [`reflection_coefficient`]): by default the plane-wave
//!    pressure coefficients of every angular-spectrum component (angle-dependent, total
//!    reflection beyond the critical angle), or the normal-incidence `T = 2·Z2 / (Z1 + Z2)` per
//!    pixel ([`InterfaceModel::NormalIncidence`]);
//! 2. an angular-spectrum step in a homogeneous medium of complex wavenumber `k̄ + i·ᾱ`:
//!    `P(kx, ky) ← P · exp(i·kz·dz + ᾱ·dz)`, `kz = sqrt((k̄ + i·ᾱ)² - kx² - ky²)` (`Im kz >= 0`:
//!    evanescent components decay; the `ᾱ·dz` leaves normal incidence to the screen, so only
//!    the extra attenuation of oblique waves, `ᾱ·(1/cos θ - 1)`, is applied here);
//! 3. a space-domain screen for the slab's deviation from `k̄` and its attenuation:
//!    `p ← p · exp(i·(k(x, y) - k̄)·dz - (alpha(x, y) + sigma(x, y))·dz)`,
//!    where `sigma` is an absorbing layer at the lateral edges (it does not count as absorption
//!    for the radiation force).
//!
//! `k̄` and `ᾱ` of each slab are means of `k(x, y)` and `alpha(x, y)` weighted by the magnitude
//! of the marched (flux-normalised) field of a *reference beam* (the steered, unaberrated source), fixed when the plan is
//! built. Fixing them makes every later propagation linear in the source, so group fields add up
//! to the field of the whole array exactly. Screens, interfaces and propagators are built once
//! per distinct slab and shared by every source of a batch. Time convention `exp(-i·omega·t)`: a
//! wave travelling to +z is `exp(+i·k·z)`.
//!
//! Between the first and the last interface whose round trip with the most strongly reflecting
//! one returns at least [`ROUND_TRIP_THRESHOLD`] of the amplitude (normal-incidence
//! `|R_i|·|R_max|`; water/bone/water: 0.3, water/phantom/water: 0.001), the angular model adds
//! the waves reverberating between interfaces (a Bremmer series: alternate backward and forward sweeps through that
//! zone, each fed by the reflections of the previous one). The number of round trips is fixed
//! when the plan is built (until the reference beam's next round trip is below
//! [`REVERBERATION_TOLERANCE`] of its incident amplitude), so marches stay linear. Waves
//! reflected back towards the source are added in front of the zone only when
//! [`RecordSpec::reflections`] asks for them.

mod elastic;
mod faces;
mod interface;
mod march;
mod oblique;
mod oblique_shear;
mod operators;
mod options;
mod point;
mod record;
mod references;
mod risers;
mod single;
mod transpose;
mod walls;

pub(crate) use interface::axial_wavenumber;
pub use interface::{reflection_coefficient, InterfaceModel, MAX_PLAN_PAIRS, MAX_SPECTRAL_PAIRS};
pub use march::{RecordSpec, Recording, Window};
pub use options::{HasOptions, Screen};
pub(crate) use single::single;
pub use single::SinglePlan;

use crate::error::{HasError, Result};
use crate::physics::fft::Fft2;
use crate::physics::grid::Grid;
use crate::physics::medium::{Medium, SliceProperties};
use interface::{Around, Coefficients, Interface};
use num_complex::Complex64 as C64;
use operators::{oblique_toward, propagator, screen, sponge_map, step_screen, Refraction};
use references::References;
use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::Arc;

/// An interface takes part in the reverberation when a round trip between it and the most
/// strongly reflecting interface (normal incidence) returns at least this fraction of the
/// amplitude.
pub const ROUND_TRIP_THRESHOLD: f64 = 0.01;

/// Round trips are added until the next one would carry less than this fraction of the incident
/// amplitude (root-mean-square over the zone's entry plane) of the reference beam.
pub const REVERBERATION_TOLERANCE: f64 = 1e-3;

/// Batches of fields with at least this many samples per plane march one field after another,
/// each step's rows spread over the pool, instead of one field per thread: beyond 2 MiB a field
/// leaves a core's cache, and splitting it over the cores runs faster (the `has_step` bench on
/// 2 cores: a 540² step split takes less than half the time it takes on one core; a 256² step
/// split gains a quarter, which two fields at once still beat).
pub const SEQUENTIAL_BATCH_SAMPLES: usize = 1 << 17;

/// Whether a batch of fields of `samples` per plane marches one field after another
/// ([`SEQUENTIAL_BATCH_SAMPLES`]).
fn in_sequence(samples: usize) -> bool {
    samples >= SEQUENTIAL_BATCH_SAMPLES
}

/// At most this many round trips (a layer with near-total reflection and no loss).
pub const MAX_ROUND_TRIPS: usize = 32;

#[derive(Clone)]
struct Step {
    /// Index into `HasPlan::slabs` of the slab between plane n and n + 1.
    slab: usize,
    /// The change of medium at plane n (from slab n - 1, or the source's medium, into slab n).
    interface: Option<Arc<Interface>>,
    /// exp(i·kz·dz + ᾱ·dz) / (nx·ny), transposed layout (nx, ny).
    propagator: Arc<Vec<C64>>,
    screen: Arc<Vec<C64>>,
    /// The normal of the oblique wall whose first plane this step starts from: the oblique
    /// screen's rays refract through it (`operators::refract`).
    wall_normal: Option<[f64; 3]>,
    mean_wavenumber: f64,
    mean_attenuation: f64,
    /// Where a planar oblique wall crosses the slab, its two reference media (`references.rs`):
    /// `propagator` and `screen` are the first's, this the second's propagator and screen.
    split: Option<Split>,
    /// The SV field's propagator and screen through a slab that holds a solid, in a plan that
    /// carries shear (`elastic.rs`).
    shear: Option<Operators>,
}

/// A propagator and a screen, shared between the steps that use them.
type Operators = (Arc<Vec<C64>>, Arc<Vec<C64>>);

/// The second reference medium of a step through a slab an oblique wall crosses.
#[derive(Clone)]
struct Split {
    references: References,
    propagator: Arc<Vec<C64>>,
    screen: Arc<Vec<C64>>,
}

impl Step {
    /// Its propagator and screen, and those of its second reference medium if it has one.
    fn operators(&self) -> march::StepOperators<'_, f64> {
        (
            (&self.propagator, &self.screen),
            self.split.as_ref().map(|s| (&s.propagator[..], &s.screen[..])),
            self.shear.as_ref().map(|(p, s)| (&p[..], &s[..])),
        )
    }
}

/// The planes bounding the reverberation, and the round trips added.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Zone {
    first: usize,
    last: usize,
    round_trips: usize,
}

/// A propagation plan: grid, FFT plans and per-step operators for one medium and frequency
/// (cloning shares the operators).
#[derive(Clone)]
pub struct HasPlan {
    /// The grid it marches on.
    pub grid: Grid,
    /// Frequency, Hz.
    pub frequency: f64,
    /// The options it was built with.
    pub options: HasOptions,
    fft: Fft2,
    /// The medium half a step before plane 0, which the source radiates from.
    source_medium: Arc<SliceProperties>,
    slabs: Vec<Arc<SliceProperties>>,
    steps: Vec<Step>,
    zone: Option<Zone>,
    /// The reference beam's recording of a window, kept where the build marched it through the
    /// reverberation (see [`HasPlan::propagate`]).
    kept: Option<Arc<Kept>>,
    /// Whether its marches carry the SV field beside `ψ` (a solid meets another medium on a
    /// plane, `elastic.rs`): fields are then `[ψ | s]`, twice a plane long.
    shear: bool,
    /// Whether walls continue the SV wave they transmit into the fluid beside the solid.
    continues: bool,
}

/// A recording of one source, and what it recorded.
struct Kept {
    source: Vec<C64>,
    spec: RecordSpec,
    recording: Recording,
}

impl HasPlan {
    /// Builds the plan, marching `reference` (the steered source on plane 0) through the medium
    /// to fix each slab's mean wavenumber, and returns what `spec` asks of that beam. The medium
    /// half a step before plane 0 is the one the source radiates from.
    pub fn build(
        grid: &Grid,
        medium: &Medium,
        frequency: f64,
        reference: &[C64],
        options: &HasOptions,
        spec: &RecordSpec,
    ) -> Result<(Self, Recording)> {
        let mut out = Err(HasError::invalid("plan", "not built"));
        march::in_pool(|| {
            out = Self::build_here(layout(grid, medium, frequency, options.interfaces), grid, medium, reference, options, spec)
        });
        out
    }

    /// [`HasPlan::build`] with the reference made by `reference` (e.g. the steered source's
    /// Rayleigh projection) while the medium is sampled onto the planes: the two share the pool,
    /// and the sampling's serial parts leave it room. Returns the reference too.
    pub fn build_with_reference(
        grid: &Grid,
        medium: &Medium,
        frequency: f64,
        reference: impl FnOnce() -> Result<Vec<C64>> + Send,
        options: &HasOptions,
        spec: &RecordSpec,
    ) -> Result<(Self, Recording, Vec<C64>)> {
        let mut out = Err(HasError::invalid("plan", "not built"));
        march::in_pool(|| {
            let (layout, reference) = rayon::join(|| layout(grid, medium, frequency, options.interfaces), reference);
            out = reference.and_then(|r| {
                let (plan, rec) = Self::build_here(layout, grid, medium, &r, options, spec)?;
                Ok((plan, rec, r))
            });
        });
        out
    }

    /// The build on the pool, from the medium laid out on the planes.
    fn build_here(
        layout: Layout,
        grid: &Grid,
        medium: &Medium,
        reference: &[C64],
        options: &HasOptions,
        spec: &RecordSpec,
    ) -> Result<(Self, Recording)> {
        let n = grid.lateral_len();
        if reference.len() != n {
            return Err(HasError::invalid("reference", format!("has {} samples, grid has {n}", reference.len())));
        }
        let Layout { frequency, source_medium, slabs, slab_of_step, interfaces } = layout;
        let omega = 2.0 * PI * frequency;
        let fft = Fft2::new(grid.nx, grid.ny);
        let sponge = sponge_map(grid, options);
        let mut propagator_cache: HashMap<[u64; 2], Arc<Vec<C64>>> = HashMap::new();
        let mut screen_cache: HashMap<(usize, u64), Arc<Vec<C64>>> = HashMap::new();
        // k̄ and ᾱ are rounded to 1e-4 of k: far below any medium contrast, so slabs of one
        // material share one propagator and screen (the screen uses the rounded values, so the
        // sum stays exact).
        let quantum = omega / medium.min_sound_speed() * 1e-4;
        let mut plan = HasPlan {
            grid: grid.clone(),
            frequency,
            options: options.clone(),
            fft,
            source_medium,
            slabs,
            steps: Vec::with_capacity(grid.nz - 1),
            zone: None,
            kept: None,
            shear: interfaces.iter().flatten().any(|i| i.converts_shear()),
            continues: false,
        };
        // March the reference one way (single transmission at each interface) to fix the means;
        // without reverberation or reflections that march is the recording asked for.
        let mut recorder = march::Recorder::new(grid, spec, spec.last_plane(grid.nz));
        // Where walls transmit SV waves into a solid, the SV field is continued into the fluid
        // beside the solid (`oblique_shear::CONTINUATION`).
        let continues =
            interfaces.iter().flatten().any(|i| i.walls().is_some_and(|w| w.groups.iter().any(|g| g.ahead.iter().any(|a| !a.is_empty()))));
        plan.continues = continues;
        let continuation = continues.then(|| {
            let reach = |d: f64| (oblique_shear::CONTINUATION / d).round() as usize;
            ([grid.nx, grid.ny], [reach(grid.dx), reach(grid.dy)])
        });
        let mut field = reference.to_vec();
        field.resize(plan.field_len(), C64::new(0.0, 0.0));
        let mut ws = plan.fft.workspace(true);
        let (mut work, mut reflected) = (Vec::new(), Vec::new());
        for (step, (slab, interface)) in slab_of_step.into_iter().zip(interfaces).enumerate() {
            let before = plan.steps.last().map_or(&plan.source_medium, |s| &plan.slabs[s.slab]);
            recorder.add(step, &field, before, &plan.source_medium);
            recorder.power(step, &plan.source_medium, &field);
            if let Some(i) = &interface {
                march::cross(i, &plan.fft, &mut field, 1.0, false, (&mut reflected, &mut work), &mut ws);
            }
            let props = &plan.slabs[slab];
            let wall_normal = interface.as_ref().and_then(|i| i.wall_normal());
            // A slab an oblique wall crosses (the wall's plane, or the same slab again after it)
            // takes two reference media.
            let crossed = wall_normal.is_some()
                || interface.as_ref().is_some_and(|i| i.two_media)
                || (interface.is_none() && plan.steps.last().is_some_and(|s| s.split.is_some()));
            let psi = &field[..n];
            let references = if crossed { References::of(psi, props, omega, quantum) } else { None };
            let (k_mean, a_mean) = match references {
                Some(r) => r.0[0],
                None => mean_wavenumber(psi, props, omega, quantum),
            };
            let shear_mean = props
                .shear
                .as_ref()
                .filter(|_| plan.shear)
                .map(|m| (m, weighted_mean(psi, &m.sound_speed, &m.attenuation, omega, quantum)));
            let mut cached = |(k, a): (f64, f64)| {
                propagator_cache.entry([k.to_bits(), a.to_bits()]).or_insert_with(|| Arc::new(propagator(grid, grid.dz, k, a))).clone()
            };
            let propagator = cached((k_mean, a_mean));
            let split = references.map(|r| Split {
                references: r,
                propagator: cached(r.0[1]),
                screen: Arc::new(r.screen(1, props, &sponge, omega, grid.dz)),
            });
            let bits = [k_mean.to_bits(), a_mean.to_bits()];
            let screen = if let Some(r) = references {
                Arc::new(r.screen(0, props, &sponge, omega, grid.dz))
            } else if oblique_toward(options.screen, props).is_some() {
                let wall = wall_normal.map(|normal| Refraction { normal, source: &plan.source_medium });
                Arc::new(step_screen(grid, props, &sponge, omega, (k_mean, a_mean), options.screen, step, grid.dz, wall))
            } else {
                screen_cache
                    .entry((slab, bits[0]))
                    .or_insert_with(|| Arc::new(screen(props, &sponge, omega, k_mean, a_mean, None, grid.dz)))
                    .clone()
            };
            let shear = shear_mean
                .map(|(maps, (k, a))| (cached((k, a)), Arc::new(elastic::screen(maps, &sponge, omega, (k, a), grid.dz, continuation))));
            let s =
                Step { slab, interface, propagator, screen, wall_normal, mean_wavenumber: k_mean, mean_attenuation: a_mean, split, shear };
            march::step(&plan.fft, &mut field, (&mut ws, &mut work), s.operators(), false);
            plan.steps.push(s);
        }
        let last = grid.nz - 1;
        recorder.add(last, &field, plan.slab_properties(last), &plan.source_medium);
        recorder.power(last, &plan.source_medium, &field);
        plan.zone = plan.reverberation_zone();
        // The march that counts the round trips records what `spec` asks when it reaches the
        // zone (not with reflections: the waves left in the zone when counting stops differ from
        // those of the march with the count, and they are sent back to the source); else the
        // one-way march above is the recording unless the reverberation or the reflections add
        // to it (and a recording of nothing needs no march).
        let mut counted = None;
        if let Some(z) = plan.zone {
            let reaches = !spec.records_nothing() && !spec.reflections && spec.last_plane(grid.nz) >= z.first;
            let to_count = if reaches { spec.clone() } else { RecordSpec { planes: vec![z.last], ..RecordSpec::default() } };
            let (rec, round_trips) = plan.round_trips_needed(reference, &to_count);
            plan.zone = Some(Zone { round_trips, ..z });
            counted = reaches.then_some(rec);
        }
        let rec = match counted {
            Some(rec) => rec,
            None if (plan.zone.is_some() || spec.reflections) && !spec.records_nothing() => plan.propagate_here(reference, spec),
            None => recorder.finish(),
        };
        let window_only = spec.window.is_some() && *spec == RecordSpec { window: spec.window.clone(), ..RecordSpec::default() };
        if plan.zone.is_some() && window_only {
            plan.kept = Some(Arc::new(Kept { source: reference.to_vec(), spec: spec.clone(), recording: rec.clone() }));
        }
        Ok((plan, rec))
    }

    /// The first and last interfaces of the reverberation (see [`ROUND_TRIP_THRESHOLD`]), if there
    /// are two (angular model only).
    fn reverberation_zone(&self) -> Option<Zone> {
        if self.options.interfaces != InterfaceModel::Angular {
            return None;
        }
        let strength = |n: usize| self.steps[n].interface.as_ref().map_or(0.0, |i| i.strength);
        let strongest = (0..self.steps.len()).map(strength).fold(0.0, f64::max);
        let strong: Vec<usize> =
            (0..self.steps.len()).filter(|&n| strength(n) > 0.0 && strength(n) * strongest >= ROUND_TRIP_THRESHOLD).collect();
        match (strong.first(), strong.last()) {
            (Some(&first), Some(&last)) if last > first => Some(Zone { first, last, round_trips: 0 }),
            _ => None,
        }
    }

    /// The mean wavenumber `k̄` (rad/m) used for the slab after each plane (the first reference's
    /// where an oblique wall's slab takes two, see [`HasPlan::split_steps`]).
    pub fn mean_wavenumbers(&self) -> Vec<f64> {
        self.steps.iter().map(|s| s.mean_wavenumber).collect()
    }

    /// The mean attenuation `ᾱ` (Np/m) used for the slab after each plane.
    pub fn mean_attenuations(&self) -> Vec<f64> {
        self.steps.iter().map(|s| s.mean_attenuation).collect()
    }

    /// Round trips of the reverberation added between the first and last strongly reflecting
    /// interfaces, with those planes (`None`: no such pair of interfaces, or normal incidence).
    pub fn reverberation(&self) -> Option<(usize, usize, usize)> {
        self.zone.map(|z| (z.first, z.last, z.round_trips))
    }

    /// Properties of the slab the beam crossed to reach plane `n` (the first slab for plane 0).
    pub fn slab_properties(&self, plane: usize) -> &SliceProperties {
        let s = plane.max(1).min(self.steps.len()) - 1;
        &self.slabs[self.steps[s].slab]
    }

    /// Marches one source from plane 0, keeping what `spec` asks for. Rows of each FFT are spread
    /// over the rayon pool. Where the build marched the reference beam through a reverberating
    /// layer for a window alone, that recording is kept, and the same source with the same `spec`
    /// returns it without marching again (the same values bit for bit: the march's operations do
    /// not depend on when it runs).
    pub fn propagate(&self, source: &[C64], spec: &RecordSpec) -> Result<Recording> {
        self.check(source, spec)?;
        if let Some(rec) = self.kept_recording(source, spec) {
            return Ok(rec);
        }
        let mut rec = Recording::default();
        march::in_pool(|| rec = self.propagate_here(source, spec));
        Ok(rec)
    }

    /// The kept recording (see [`HasPlan::propagate`]) if it is of `source` for `spec`.
    pub(crate) fn kept_recording(&self, source: &[C64], spec: &RecordSpec) -> Option<Recording> {
        self.kept.as_ref().filter(|k| k.spec == *spec && k.source == source).map(|k| k.recording.clone())
    }

    fn propagate_here(&self, source: &[C64], spec: &RecordSpec) -> Recording {
        self.march(source.to_vec(), spec, true, march::RoundTrips::Fixed).0
    }

    /// Marches many sources through the same steps: one source per rayon task on small grids,
    /// one after another over the whole pool on large ones ([`SEQUENTIAL_BATCH_SAMPLES`]). The
    /// result is the same as calling [`HasPlan::propagate`] on each.
    pub fn propagate_batch(&self, sources: &[Vec<C64>], spec: &RecordSpec) -> Result<Vec<Recording>> {
        use rayon::prelude::*;
        for s in sources {
            self.check(s, spec)?;
        }
        if sources.len() == 1 || in_sequence(self.grid.lateral_len()) {
            return sources.iter().map(|s| self.propagate(s, spec)).collect();
        }
        Ok(sources
            .par_iter()
            .map(|s| self.kept_recording(s, spec).unwrap_or_else(|| self.march(s.clone(), spec, false, march::RoundTrips::Fixed).0))
            .collect())
    }

    /// Whether its marches carry shear: the SV wave of a solid whose faces with other media lie
    /// on the planes (material regions, `elastic.rs`) or on planar walls oblique to them (a
    /// tilted CT plate, `oblique_shear.rs`), with mode conversion at those faces. A CT's other
    /// faces (curved, or its treads on the planes) convert nothing.
    pub fn carries_shear(&self) -> bool {
        self.shear
    }

    /// Whether the SV wave its tilted walls transmit into a solid is continued into the fluid
    /// beside the solid (`oblique_shear::CONTINUATION`).
    pub fn continues_shear(&self) -> bool {
        self.continues
    }

    /// How many of the plan's interfaces convert between compressional and shear waves (a
    /// solid meeting another medium on a plane or on a planar oblique wall).
    pub fn elastic_interfaces(&self) -> usize {
        self.steps.iter().filter(|s| s.interface.as_ref().is_some_and(|i| i.converts_shear())).count()
    }

    /// The length of a marched field: a plane, or two (`[ψ | s]`) where it carries shear.
    pub(crate) fn field_len(&self) -> usize {
        self.grid.lateral_len() * if self.shear { 2 } else { 1 }
    }

    /// How many steps propagate two reference media (`references.rs`): the slabs that planar
    /// walls oblique to the planes cross.
    pub fn split_steps(&self) -> usize {
        self.steps.iter().filter(|s| s.split.is_some()).count()
    }

    /// How many of the plan's interfaces give a planar wall oblique to the planes its own
    /// filters (`oblique.rs`).
    pub fn oblique_walls(&self) -> usize {
        self.steps.iter().filter(|s| s.interface.as_ref().is_some_and(|i| i.walls().is_some())).count()
    }

    fn check(&self, source: &[C64], spec: &RecordSpec) -> Result<()> {
        let g = &self.grid;
        if source.len() != g.lateral_len() {
            return Err(HasError::invalid("source", format!("has {} samples, grid has {}", source.len(), g.lateral_len())));
        }
        if source.iter().any(|v| !v.re.is_finite() || !v.im.is_finite()) {
            return Err(HasError::invalid("source", "contains NaN or infinite values"));
        }
        if let Some(&p) = spec.planes.iter().find(|&&p| p >= g.nz) {
            return Err(HasError::invalid("planes", format!("plane {p} is beyond the grid ({} planes)", g.nz)));
        }
        for (name, w) in [("window", &spec.window), ("magnitude", &spec.magnitude)] {
            if w.as_ref().is_some_and(|w| w.planes.end > g.nz || w.rows.end > g.ny || w.cols.end > g.nx) {
                return Err(HasError::invalid(name, "reaches beyond the grid"));
            }
        }
        Ok(())
    }
}

/// The medium along the march: distinct property maps, the slab of each step, and the interface
/// at each step's first plane (the medium half a step before plane 0 is the one the source
/// radiates from).
struct Layout {
    /// The frequency the properties are taken at (Hz).
    frequency: f64,
    source_medium: Arc<SliceProperties>,
    slabs: Vec<Arc<SliceProperties>>,
    slab_of_step: Vec<usize>,
    interfaces: Vec<Option<Arc<Interface>>>,
}

fn layout(grid: &Grid, medium: &Medium, frequency: f64, model: InterfaceModel) -> Layout {
    let omega = 2.0 * PI * frequency;
    let mut slabs: Vec<Arc<SliceProperties>> = Vec::new();
    let mut slab_of_step = Vec::with_capacity(grid.nz - 1);
    // Whether each slab (the source's medium first) is made of regions: planar faces.
    let mut planar = vec![medium.slice_key(grid.z0 - 0.5 * grid.dz).is_some()];
    let mut scratch = Vec::new();
    let source_medium = Arc::new(medium.slice_with(grid, grid.z0 - 0.5 * grid.dz, frequency, &mut scratch));
    let mut prev_key = None;
    for step in 0..grid.nz - 1 {
        let z = grid.z(step) + 0.5 * grid.dz;
        let key = medium.slice_key(z);
        let slab = match slabs.last() {
            Some(_) if key.is_some() && key == prev_key => slabs.len() - 1,
            last => {
                let props = medium.slice_with(grid, z, frequency, &mut scratch);
                if last.is_some_and(|l| **l == props) {
                    slabs.len() - 1
                } else {
                    slabs.push(Arc::new(props));
                    slabs.len() - 1
                }
            }
        };
        planar.push(key.is_some());
        prev_key = key;
        slab_of_step.push(slab);
    }
    // The slab before plane n (n = 0: the source's medium).
    let before = |n: usize| if n == 0 { &source_medium } else { &slabs[slab_of_step[(n - 1).min(slab_of_step.len() - 1)]] };
    // Slabs are only reused for the step just before, so each change of slab happens once: an
    // interface is built where the slab changes (the material pairs' spectral coefficients are
    // shared through `shared`). Faces of regions lie on planes; others get their positions' phases.
    let mut shared = Coefficients::default();
    let interfaces = (0..grid.nz - 1)
        .map(|step| {
            if step > 0 && slab_of_step[step - 1] == slab_of_step[step] {
                return None;
            }
            let (from, to) = (before(step), before(step + 1));
            // The slabs before planes step - K ..= step + 1 + K: the face between the K + 1-th and
            // the K + 2-th.
            let reach = oblique::normal_slabs(grid.dz);
            let around = (!(planar[step] && planar[step + 1])).then(|| Around {
                column: (0..2 * reach + 2).map(|j| &**before((step + j).saturating_sub(reach))).collect(),
                face: reach + 1,
            });
            Interface::new(grid, from, to, omega, model, around.as_ref(), &mut shared).map(Arc::new)
        })
        .collect();
    Layout { frequency, source_medium, slabs, slab_of_step, interfaces }
}

/// `Σ|p|·k / Σ|p|` and `Σ|p|·alpha / Σ|p|` over the slab (see [`weighted_mean`]).
fn mean_wavenumber(field: &[C64], props: &SliceProperties, omega: f64, quantum: f64) -> (f64, f64) {
    weighted_mean(field, &props.sound_speed, &props.attenuation, omega, quantum)
}

/// `Σ|p|·k / Σ|p|` and `Σ|p|·alpha / Σ|p|` (`k = omega/c`) over the pixels whose speed `c` is
/// above 0 (every pixel of a compressional map; a shear map's solids), by the pixels alone where
/// the field is zero on them (sequential sums: identical with any number of threads), rounded to
/// multiples of `quantum` so slabs of equal medium share one propagator; 0 where no pixel counts.
fn weighted_mean(field: &[C64], speed: &[f64], attenuation: &[f64], omega: f64, quantum: f64) -> (f64, f64) {
    let mean = |weight: &dyn Fn(&C64) -> f64| {
        let (mut k_sum, mut a_sum, mut den) = (0.0, 0.0, 0.0);
        for ((p, c), a) in field.iter().zip(speed).zip(attenuation).filter(|((_, &c), _)| c > 0.0) {
            let w = weight(p);
            k_sum += w * omega / c;
            a_sum += w * a;
            den += w;
        }
        (den > 0.0).then(|| (k_sum / den, a_sum / den))
    };
    // |p| without hypot's overflow care: 2x faster here.
    let (k, a) = mean(&|p| p.norm_sqr().sqrt()).or_else(|| mean(&|_| 1.0)).unwrap_or((0.0, 0.0));
    ((k / quantum).round() * quantum, (a / quantum).round() * quantum)
}
