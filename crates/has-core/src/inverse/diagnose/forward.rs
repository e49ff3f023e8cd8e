//! The extended forward model of the discrepancy workflow: every library effect applied to the
//! HAS field and the MR-ARFI image, with small caches of recent field states and moved slices.

use super::effects::{focal_material, FieldState, View, SLICE_REACH_MM};
use super::Effects;
use crate::error::{HasError, Result};
use crate::inverse::linear::solve_augmented;
use crate::physics::grid::Grid;
use crate::physics::mr::MrSampler;
use crate::physics::propagation::{RecordSpec, Recording, Window};
use crate::simulation::Simulation;
use crate::Complex64 as C64;
use ndarray::Array2;
use std::borrow::Cow;
use std::sync::{Arc, Mutex, OnceLock};

/// The sampler of a moved slice (its window is `sampler.window`).
type Slice = Arc<MrSampler>;

/// `|p|²` of each image on the extended window, for one field state.
type Power = Arc<Vec<Vec<f64>>>;

/// The extended forward model for a set of images.
pub(super) struct Forward<'a> {
    sim: &'a Simulation,
    /// Known element phases per image.
    pub(super) knowns: Vec<Vec<f64>>,
    material: usize,
    /// The MR window extended by [`SLICE_REACH_MM`] (plus the slab and a sample) along the normal.
    window: Window,
    /// Whether each window sample lies in the focal material.
    in_material: Vec<bool>,
    /// Pixel-centre coordinates along u and v (mm).
    coords: [Vec<f64>; 2],
    /// Recent field states and their powers.
    powers: Recent<FieldState, Power>,
    /// Samplers of moved slices, by offset bits.
    samplers: Recent<u64, Slice>,
    /// The model on its grid cut after the window, made at the first rebuild (see
    /// [`Forward::cut`]).
    cut: OnceLock<Option<Simulation>>,
}

/// A small cache of the [`CACHED`] values used last (pure functions of their keys, so a hit
/// returns what a recomputation would). The least recently used is dropped: the current model's
/// field state, read by every image-space fit, stays while the field candidates fitted beside it
/// (16 dropped groups, a Brent search) pass through (dropping the oldest inserted re-marched it
/// after every six of theirs).
struct Recent<K, V>(Mutex<Vec<(K, V)>>);

impl<K: PartialEq + Clone, V: Clone> Recent<K, V> {
    fn new() -> Self {
        Recent(Mutex::new(vec![]))
    }

    /// The value for `key`, computed by `make` when it is not held.
    fn get_or_try(&self, key: &K, make: impl FnOnce() -> Result<V>) -> Result<V> {
        let hit = self.0.lock().ok().and_then(|mut c| {
            let i = c.iter().position(|(k, _)| k == key)?;
            let entry = c.remove(i);
            let v = entry.1.clone();
            c.push(entry);
            Some(v)
        });
        if let Some(v) = hit {
            return Ok(v);
        }
        let v = make()?;
        if let Ok(mut c) = self.0.lock() {
            if c.len() >= CACHED {
                c.remove(0);
            }
            c.push((key.clone(), v.clone()));
        }
        Ok(v)
    }
}

/// The most groups `element_dropout` and `phase_aberration` are fitted for (one march per
/// group; the group kernels' limit).
pub(super) const MAX_GROUPS: usize = 128;

/// How many field states and samplers the caches keep.
const CACHED: usize = 6;

impl<'a> Forward<'a> {
    pub(super) fn new(sim: &'a Simulation, knowns: &[Vec<f64>]) -> Result<Self> {
        let sampler = sim.sampler()?;
        let g = &sampler.geometry;
        let window = extended_window(sim, sampler);
        let material = focal_material(sim);
        let grid = &sim.grid;
        let mut in_material = Vec::with_capacity(window.len());
        for n in window.planes.clone() {
            for j in window.rows.clone() {
                for i in window.cols.clone() {
                    in_material.push(sim.medium.material_at(grid.x(i), grid.y(j), grid.z(n)) == material);
                }
            }
        }
        let knowns = knowns
            .iter()
            .map(|k| if k.is_empty() { Ok(vec![0.0; sim.n_elements()]) } else { sim.element_phases(k) })
            .collect::<Result<_>>()?;
        let coords = [0, 1].map(|k| (0..g.matrix[k]).map(|i| g.pixel_center(k, i) * 1e3).collect());
        let (powers, samplers, cut) = (Recent::new(), Recent::new(), OnceLock::new());
        Ok(Forward { sim, knowns, material, window, in_material, coords, powers, samplers, cut })
    }

    /// `|p|²` (times the force coefficient relative to the model's) on the extended window for
    /// every image of a field state.
    fn powers(&self, state: &FieldState) -> Result<Power> {
        self.powers.get_or_try(state, || self.march(state))
    }

    /// [`Forward::powers`], computed.
    fn march(&self, state: &FieldState) -> Result<Power> {
        let s = self.sim;
        let spec = RecordSpec { window: Some(self.window.clone()), reflections: s.reflections, ..Default::default() };
        let (sim, ratio, steered) = self.rebuilt(state, Some(&spec))?;
        let sim = sim.as_ref();
        if let Some(&d) = state.dead_groups.iter().find(|&&d| d >= s.n_groups) {
            return Err(HasError::invalid("dead_groups", format!("group {d} does not exist ({} groups)", s.n_groups)));
        }
        if !state.group_phases.is_empty() && state.group_phases.len() != s.n_groups {
            return Err(HasError::invalid("group_phases", format!("has {} values for {} groups", state.group_phases.len(), s.n_groups)));
        }
        let sources = self
            .knowns
            .iter()
            .map(|known| {
                let drive: Vec<C64> = (0..s.n_elements())
                    .map(|e| {
                        let g = s.groups[e];
                        if state.dead_groups.contains(&g) {
                            return C64::new(0.0, 0.0);
                        }
                        let extra = state.group_phases.get(g).copied().unwrap_or(0.0);
                        s.drive(e, known[e] + extra)
                    })
                    .collect();
                s.source.field(&drive)
            })
            .collect::<Result<Vec<_>>>()?;
        // An image of the steered beam itself (no phases added, no group dead) takes the
        // recording the rebuild marched; the others are marched together.
        let is_steered = |source: &Vec<C64>| steered.is_some() && source.as_slice() == sim.steered_source();
        let to_march: Vec<Vec<C64>> = sources.iter().filter(|source| !is_steered(source)).cloned().collect();
        let mut marched = sim.plan.propagate_batch(&to_march, &spec)?.into_iter();
        let recordings = sources.iter().map(|source| if is_steered(source) { steered.clone() } else { marched.next() });
        let power: Vec<Vec<f64>> = recordings
            .map(|rec| rec.expect("one recording per source"))
            .map(|rec| rec.window.iter().zip(&self.in_material).map(|(p, &m)| p.norm_sqr() * if m { ratio } else { 1.0 }).collect())
            .collect();
        Ok(Arc::new(power))
    }

    /// The simulation in the medium of `state`, and the ratio of its force coefficient
    /// `alpha/(rho·c²)` in the focal material to the model's (the samplers keep the model's).
    pub(super) fn in_medium(&self, state: &FieldState) -> Result<(Cow<'_, Simulation>, f64)> {
        self.rebuilt(state, None).map(|(sim, ratio, _)| (sim, ratio))
    }

    /// [`Forward::in_medium`], and when the medium is rebuilt with `spec` given, the new plan's
    /// recording `spec` of the steered beam (the build's own march).
    /// The rebuilt simulation lies on [`Forward::cut`]'s grid.
    fn rebuilt(&self, state: &FieldState, spec: Option<&RecordSpec>) -> Result<(Cow<'_, Simulation>, f64, Option<Recording>)> {
        let model = &self.sim.medium.materials[self.material];
        if state.sound_speed == model.sound_speed && state.attenuation_db_cm_mhz == model.attenuation_db_cm_mhz {
            return Ok((Cow::Borrowed(self.sim), 1.0, None));
        }
        let (c, a) = (state.sound_speed, state.attenuation_db_cm_mhz);
        let base = self.cut();
        // The plan alone: the samplers are the model's, the ratio below scales their coefficient.
        let nothing = RecordSpec { reflections: base.reflections, ..RecordSpec::default() };
        let (sim, recording) = base.with_material_plan(self.material, c, a, spec.unwrap_or(&nothing))?;
        let steered = spec.is_some().then_some(recording);
        let coef = |m: &crate::physics::medium::Material| m.properties(self.sim.frequency).force_coefficient();
        let ratio = coef(&sim.medium.materials[self.material]) / coef(model);
        Ok((Cow::Owned(sim), ratio, steered))
    }

    /// The model on its grid cut after the last plane of the extended window, where that drops
    /// planes and nothing beyond them reaches the window (no reflections sent back, no
    /// reverberation between interfaces): the planes up to the cut are the model's, marched by
    /// the same operators, so a rebuild there records the window bit for bit as one on the whole
    /// grid, without the screens and steps beyond it. Else (or if the cut grid cannot be built)
    /// the model itself.
    fn cut(&self) -> &Simulation {
        let s = self.sim;
        let planes = self.window.planes.end.max(2);
        let cut = || {
            if s.reflections || s.plan.reverberation().is_some() || planes >= s.grid.nz {
                return None;
            }
            s.on_grid(Grid { nz: planes, ..s.grid.clone() }).ok()
        };
        self.cut.get_or_init(cut).as_ref().unwrap_or(s)
    }

    /// The sampler of the slice moved `dz_mm` along its normal, and its window.
    pub(super) fn slice(&self, dz_mm: f64) -> Result<Slice> {
        self.samplers.get_or_try(&dz_mm.to_bits(), || self.moved_slice(dz_mm))
    }

    /// [`Forward::slice`], computed.
    fn moved_slice(&self, dz_mm: f64) -> Result<Slice> {
        let s = &self.sim;
        if !(dz_mm.abs() <= SLICE_REACH_MM) {
            return Err(HasError::invalid("dz_mm", format!("slice offsets are fitted within ±{SLICE_REACH_MM} mm")));
        }
        let mut geometry = s.sampler()?.geometry.clone();
        geometry.center[geometry.plane.axes()[2]] += dz_mm * 1e-3;
        let sampler = MrSampler::new(&s.grid, &s.medium, s.frequency, &geometry, s.sampler()?.broadening)?;
        let w = &sampler.window;
        let inside = |a: &std::ops::Range<usize>, b: &std::ops::Range<usize>| a.start >= b.start && a.end <= b.end;
        if !(inside(&w.planes, &self.window.planes) && inside(&w.rows, &self.window.rows) && inside(&w.cols, &self.window.cols)) {
            return Err(HasError::invalid("dz_mm", "the moved slice leaves the recorded field"));
        }
        Ok(Arc::new(sampler))
    }

    /// The force images times the model's amplitude (rad, before the scale and background).
    pub(super) fn force_images(&self, e: &Effects) -> Result<Vec<Array2<f64>>> {
        let power = self.powers(&e.field)?;
        let v = &e.view;
        let slice = self.slice(v.slice_offset_mm)?;
        let sampler = slice.with_view(v.widths_mm().map(|w| w * 1e-3), v.shift_mm.map(|s| s * 1e-3))?;
        power.iter().map(|p| Ok(sampler.apply(&self.window.extract(p, &slice.window))? * self.sim.amplitude()?)).collect()
    }

    /// The model image of every image.
    pub(super) fn images(&self, e: &Effects) -> Result<Vec<Array2<f64>>> {
        Ok(self.force_images(e)?.into_iter().map(|f| self.compose(f, &e.view)).collect())
    }

    /// `scale · force + offset + slope_u·u + slope_v·v`.
    fn compose(&self, force: Array2<f64>, v: &View) -> Array2<f64> {
        let mut img = force * v.scale;
        let b = v.background_slope_rad_per_mm;
        for ((i, j), x) in img.indexed_iter_mut() {
            *x += v.background_offset_rad + b[0] * self.coords[0][i] + b[1] * self.coords[1][j];
        }
        img
    }

    /// Sum of squared differences over every imaged pixel of every image (infinite when the
    /// model cannot be evaluated).
    pub(super) fn cost(&self, e: &Effects, measured: &[Array2<f64>]) -> f64 {
        match self.images(e) {
            Ok(imgs) => sum_squares(&imgs, measured),
            Err(_) => f64::INFINITY,
        }
    }

    /// The view with its linear parameters `linear` (slots 0 = scale, 5–7 = background) set to
    /// their least-squares values for the given force images (variable projection: the image is
    /// linear in them), and the cost. Falls back to `view` when the system is singular.
    pub(super) fn project(&self, force: Vec<Array2<f64>>, view: View, linear: &[usize], measured: &[Array2<f64>]) -> (View, f64) {
        let mut v = view.to_vec();
        for &k in linear {
            v[k] = 0.0;
        }
        let base = View::from_vec(&v);
        let column = |k: usize, img: usize, i: usize, j: usize| match k {
            0 => force[img][[i, j]],
            5 => 1.0,
            6 => self.coords[0][i],
            _ => self.coords[1][j],
        };
        let m = linear.len();
        let mut a = vec![vec![0.0; m + 1]; m];
        for (img, (f, d)) in force.iter().zip(measured).enumerate() {
            let fixed = self.compose(f.clone(), &base);
            for ((i, j), y) in d.indexed_iter().filter(|(_, y)| y.is_finite()) {
                let r = y - fixed[[i, j]];
                let mut cols = [0.0; 4];
                for (c, &k) in cols.iter_mut().zip(linear) {
                    *c = column(k, img, i, j);
                }
                for p in 0..m {
                    for q in 0..m {
                        a[p][q] += cols[p] * cols[q];
                    }
                    a[p][m] += cols[p] * r;
                }
            }
        }
        let solved = match solve_augmented(a) {
            Some(x) => {
                for (&k, xk) in linear.iter().zip(x) {
                    v[k] = xk;
                }
                View::from_vec(&v)
            }
            None => view,
        };
        let images: Vec<Array2<f64>> = force.into_iter().map(|f| self.compose(f, &solved)).collect();
        (solved, sum_squares(&images, measured))
    }
}

/// `Σ (model - measured)²` over the imaged pixels (measured pixels without signal, NaN, are left
/// out).
fn sum_squares(model: &[Array2<f64>], measured: &[Array2<f64>]) -> f64 {
    model.iter().zip(measured).map(|(m, d)| m.iter().zip(d).filter(|(_, b)| b.is_finite()).map(|(a, b)| (a - b).powi(2)).sum::<f64>()).sum()
}

/// The MR window extended by [`SLICE_REACH_MM`] plus the slice half-thickness and a sample on each
/// side along the slice normal, within the grid.
fn extended_window(sim: &Simulation, sampler: &MrSampler) -> Window {
    let g = &sim.grid;
    let mut w = sampler.window.clone();
    let (range, step, n) = match sampler.geometry.plane.axes()[2] {
        0 => (&mut w.cols, g.dx, g.nx),
        1 => (&mut w.rows, g.dy, g.ny),
        _ => (&mut w.planes, g.dz, g.nz),
    };
    let extra = ((SLICE_REACH_MM * 1e-3 + sampler.geometry.slice_thickness) / step).ceil() as usize + 1;
    *range = range.start.saturating_sub(extra)..(range.end + extra).min(n);
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    /// A rebuild for another focal medium on the grid cut after the window records the window
    /// bit for bit as the rebuild on the whole grid (the planes up to the cut are marched by the
    /// same operators), and the cut drops planes on the default scenario (its MR slice lies well
    /// before the grid's end).
    #[test]
    fn a_rebuild_on_the_cut_grid_records_the_window_as_on_the_whole_grid() {
        let sim = Simulation::new(&Scenario::default()).unwrap();
        let forward = Forward::new(&sim, &[vec![]]).unwrap();
        assert!(forward.cut().grid.nz < sim.grid.nz, "{} planes of {}", forward.cut().grid.nz, sim.grid.nz);
        let spec = RecordSpec { window: Some(forward.window.clone()), reflections: sim.reflections, ..Default::default() };
        let material = focal_material(&sim);
        let (_, whole) = sim.with_material_recording(material, 1560.0, 0.6, &spec).unwrap();
        let state = FieldState { group_phases: vec![], dead_groups: vec![], sound_speed: 1560.0, attenuation_db_cm_mhz: 0.6 };
        let (_, _, cut) = forward.rebuilt(&state, Some(&spec)).unwrap();
        assert!(whole.window == cut.unwrap().window);
    }
}
