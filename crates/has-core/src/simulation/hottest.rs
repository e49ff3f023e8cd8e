//! The hottest place of each tissue class over the whole grid: the safety line of the skull, the
//! scalp and the brain (and of the water in front of a head) beside the focal peak.
//!
//! A grid sample is named as a user names a place: `skull` where the medium is bone, `scalp`
//! where it is the target's own soft tissue but the straight path from it to the target crosses
//! bone (the soft tissue outside the skull), else the medium's name for it (`brain`, `water`, a
//! `[[material]]`'s name). The path test runs on the grid: a sample *sees* the target when it is
//! not bone and either lies within one sample of the target along every axis, or the sample one
//! step nearer along the line to the target sees it (the step: one sample along the axis of the
//! largest index difference, the others rounded). Each sample's answer is kept, so the test costs
//! one step per sample at most.

use super::Simulation;
use crate::error::{HasError, Result};
use crate::focal::{exposure, FocalMetrics};
use crate::physics::grid::Grid;
use crate::physics::medium::Medium;
use rayon::prelude::*;

/// What the medium calls bone (a CT's class, or a `[[material]]` named so).
const BONE: &str = "bone";

/// The class of the medium's tissue named `name` as a user names it: bone is the `skull`.
fn class_name(name: &str) -> &str {
    if name == BONE {
        "skull"
    } else {
        name
    }
}

/// The hottest grid sample of one tissue class, with the exposure there.
#[derive(Debug, Clone, PartialEq)]
pub struct TissueHottest {
    /// The class: `skull`, `scalp`, or the medium's name of the tissue (`brain`, `water` …).
    pub tissue: String,
    /// `|p|` there (Pa).
    pub pressure: f64,
    /// The sample's position (m, transducer frame).
    pub position: [f64; 3],
    /// Spatial-peak pulse-average intensity there, `p² / (2·ρ·c)` (W/m²).
    pub isppa: f64,
    /// Mechanical index there, `p[MPa] / √f[MHz]` (in situ).
    pub mechanical_index: f64,
}

impl TissueHottest {
    /// Whether this place is the focus itself: in the focal peak's tissue and no hotter than the
    /// peak refined between samples (`1e-6`: the sample is a float32 sum, the peak a
    /// double-precision refinement, which may lie a hair below it). A safety check flags the focus
    /// once, at the focal peak, and any other hottest place on its own.
    pub fn is_focus(&self, focal: &FocalMetrics) -> bool {
        self.tissue == focal.tissue && self.pressure <= focal.peak_pressure * (1.0 + 1e-6)
    }
}

/// Per grid sample: the index of its tissue's name in a list of names.
struct TissueMap {
    names: Vec<String>,
    index: Vec<u8>,
}

impl Simulation {
    /// The hottest sample of each tissue class (see the module docs) of `magnitude`, `|p|` (Pa)
    /// on every grid sample (row-major plane, row, column), hottest class first. Classes with no
    /// sample in the grid are left out; the first sample in row-major order wins a tie.
    pub fn hottest_by_tissue(&self, magnitude: &[f32]) -> Vec<TissueHottest> {
        let g = &self.grid;
        assert_eq!(magnitude.len(), g.lateral_len() * g.nz, "one |p| per grid sample");
        let mut out: Vec<TissueHottest> = hottest_samples(g, self.focus, &self.tissue_map(), magnitude)
            .into_iter()
            .map(|(tissue, p, s)| self.exposure(tissue, p as f64, sample_position(g, s)))
            .collect();
        out.sort_by(|a, b| b.pressure.total_cmp(&a.pressure));
        out
    }

    /// The tissue class of each of `points` (m, transducer frame): the class
    /// [`Simulation::hottest_by_tissue`] gives the grid sample nearest it (the module docs' path
    /// test, walked from that sample alone). Refused for a point off the grid.
    pub fn tissue_classes(&self, points: &[[f64; 3]]) -> Result<Vec<String>> {
        tissue_classes_on(&self.grid, &self.medium, self.focus, points)
    }

    /// The tissue class at the point `p` (m): the medium's tissue there by class (bone the
    /// `skull`), or `scalp` where [`Simulation::tissue_classes`] names the grid sample nearest it so.
    pub(crate) fn class_at(&self, p: [f64; 3]) -> String {
        let own = class_name(self.medium.tissue_name_at(p[0], p[1], p[2]));
        match self.tissue_classes(&[p]) {
            Ok(c) if c[0] == "scalp" => c[0].clone(),
            _ => own.to_string(),
        }
    }

    /// The tissue of every grid sample (its centre), by name.
    fn tissue_map(&self) -> TissueMap {
        let g = &self.grid;
        let names = self.medium.tissue_names();
        assert!(names.len() < 256, "fewer than 256 tissue names");
        let mut index = vec![0u8; g.lateral_len() * g.nz];
        index.par_chunks_mut(g.lateral_len()).enumerate().for_each(|(k, plane)| {
            for (s, out) in plane.iter_mut().enumerate() {
                let name = self.medium.tissue_name_at(g.x(s % g.nx), g.y(s / g.nx), g.z(k));
                *out = names.iter().position(|&n| n == name).expect("a name of tissue_names") as u8;
            }
        });
        TissueMap { names: names.into_iter().map(String::from).collect(), index }
    }

    /// [`TissueHottest`] of `tissue` with `|p|` = `pressure` at `position`.
    fn exposure(&self, tissue: String, pressure: f64, position: [f64; 3]) -> TissueHottest {
        let [x, y, z] = position;
        let p = self.medium.properties_at(x, y, z, self.frequency);
        let (isppa, mechanical_index) = exposure(pressure, p.density, p.sound_speed, self.frequency);
        TissueHottest { tissue, pressure, position, isppa, mechanical_index }
    }
}

/// The hottest sample of each class of `map` (see the module docs) for the target `focus` (m):
/// its class, `|p|` and index, in the order of the classes (the map's names, `bone` named
/// `skull`, then `scalp`), one entry per name.
fn hottest_samples(g: &Grid, focus: [f64; 3], map: &TissueMap, magnitude: &[f32]) -> Vec<(String, f32, usize)> {
    let bone = map.names.iter().position(|n| n == BONE);
    let target = g.nearest(focus).map(|[i, j, k]| (k * g.ny + j) * g.nx + i);
    // The target's soft tissue splits into what sees the target and the scalp.
    let split = target.map(|t| map.index[t] as usize).filter(|&t| bone.is_some() && Some(t) != bone);
    let mut names: Vec<String> = map.names.iter().map(|n| class_name(n).to_string()).collect();
    let scalp = names.len();
    names.push("scalp".into());
    let mut best: Vec<Option<(f32, usize)>> = vec![None; names.len()];
    let mut sees = Sees::new(g, focus, &map.index, bone);
    for (s, &p) in magnitude.iter().enumerate() {
        let id = map.index[s] as usize;
        // A sample cooler than the best of every class it may fall in changes nothing.
        let may = |c: usize| best[c].map_or(true, |b| p > b.0);
        if !(may(id) || (Some(id) == split && may(scalp))) {
            continue;
        }
        let c = if Some(id) == split && !sees.sees(s) { scalp } else { id };
        if may(c) {
            best[c] = Some((p, s));
        }
    }
    // A material may bear a class's name ("scalp", "skull"): one entry per name, the hotter.
    let mut out: Vec<(String, f32, usize)> = Vec::new();
    for (tissue, (p, s)) in names.into_iter().zip(best).filter_map(|(t, b)| b.map(|b| (t, b))) {
        match out.iter_mut().find(|o| o.0 == tissue) {
            Some(o) if p > o.1 || (p == o.1 && s < o.2) => (o.1, o.2) = (p, s),
            Some(_) => {}
            None => out.push((tissue, p, s)),
        }
    }
    out
}

/// Position (m) of grid sample `s` (row-major plane, row, column).
fn sample_position(g: &Grid, s: usize) -> [f64; 3] {
    let (k, r) = (s / g.lateral_len(), s % g.lateral_len());
    [g.x(r % g.nx), g.y(r / g.nx), g.z(k)]
}

/// Whether grid samples see the target (see the module docs), each answer kept once found.
struct Sees<'a> {
    shape: [usize; 3],
    /// The target in fractional sample indices (column, row, plane).
    target: [f64; 3],
    tissue: &'a [u8],
    bone: Option<u8>,
    /// 0: not known yet, 1: sees, 2: does not.
    known: Vec<u8>,
}

impl<'a> Sees<'a> {
    fn new(g: &Grid, focus: [f64; 3], tissue: &'a [u8], bone: Option<usize>) -> Self {
        let target = g.fractional_index(focus);
        let known = if bone.is_some() { vec![0; tissue.len()] } else { Vec::new() };
        Sees { shape: [g.nx, g.ny, g.nz], target, tissue, bone: bone.map(|b| b as u8), known }
    }

    /// Whether sample `s` sees the target: follows the steps towards it until a sample with a
    /// known answer, then gives every sample on the way that answer.
    fn sees(&mut self, s: usize) -> bool {
        let Some(bone) = self.bone else { return true };
        let mut path = Vec::new();
        let mut at = s;
        let answer = loop {
            match self.known[at] {
                1 => break true,
                2 => break false,
                _ => {}
            }
            path.push(at);
            if self.tissue[at] == bone {
                break false;
            }
            match nearer(self.shape, self.target, at) {
                Some(next) => at = next,
                None => break true,
            }
        };
        for p in path {
            // A sample beyond bone does not see the target; the bone itself does not either.
            self.known[p] = if answer { 1 } else { 2 };
        }
        answer
    }
}

/// The sample one step nearer the target (fractional indices `target`, column, row, plane) than
/// sample `s` of a grid of `shape` (nx, ny, nz): one sample along the axis of the largest index
/// difference, the others rounded; `None` when `s` lies within one sample of it along every axis.
fn nearer(shape: [usize; 3], target: [f64; 3], s: usize) -> Option<usize> {
    let [nx, ny, nz] = shape;
    let v = [s % nx, s / nx % ny, s / (nx * ny)];
    let d: [f64; 3] = std::array::from_fn(|a| target[a] - v[a] as f64);
    let m = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if m <= 1.0 {
        return None;
    }
    let n = [nx, ny, nz];
    let q: [usize; 3] = std::array::from_fn(|a| (v[a] as f64 + d[a] / m).round().clamp(0.0, (n[a] - 1) as f64) as usize);
    Some((q[2] * ny + q[1]) * nx + q[0])
}

/// [`Simulation::tissue_classes`] of `points` (m) on `grid` through `medium`, the path test
/// walked toward `focus` (m): what a simulation's would be, before its plan is built.
pub fn tissue_classes_on(g: &Grid, medium: &Medium, focus: [f64; 3], points: &[[f64; 3]]) -> Result<Vec<String>> {
    let name = |s: usize| {
        let [x, y, z] = sample_position(g, s);
        medium.tissue_name_at(x, y, z)
    };
    let index = |[i, j, k]: [usize; 3]| (k * g.ny + j) * g.nx + i;
    let target = g.nearest(focus).map(|t| name(index(t)));
    let (shape, towards) = ([g.nx, g.ny, g.nz], g.fractional_index(focus));
    let class = |p: [f64; 3]| -> Result<String> {
        let s = g.nearest(p).map(index).ok_or_else(|| {
            HasError::invalid("points_mm", format!("({:.1}, {:.1}, {:.1}) mm lies off the grid", p[0] * 1e3, p[1] * 1e3, p[2] * 1e3))
        })?;
        let own = name(s);
        if own == BONE || Some(own) != target {
            return Ok(class_name(own).to_string());
        }
        let mut at = s;
        while let Some(next) = nearer(shape, towards, at) {
            if name(next) == BONE {
                return Ok("scalp".to_string());
            }
            at = next;
        }
        Ok(own.to_string())
    };
    points.iter().map(|&p| class(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    /// The focal tissue's hottest sample is the focus when no hotter than the peak (a float32
    /// hair above it included); hotter (a side lobe), or another tissue, it is a place of its own.
    #[test]
    fn the_focal_tissues_hottest_sample_is_the_focus_unless_hotter() {
        let focal = FocalMetrics {
            target: [0.0; 3],
            peak: [0.0; 3],
            peak_pressure: 1.5e6,
            fwhm_6db: [0.0; 2],
            across_6db: [0.0; 2],
            fwhm_3db: [0.0; 2],
            volume_6db: 0.0,
            isppa: 0.0,
            mechanical_index: 0.0,
            tissue: "skull".into(),
        };
        let place = |tissue: &str, pressure: f64| TissueHottest {
            tissue: tissue.into(),
            pressure,
            position: [0.0; 3],
            isppa: 0.0,
            mechanical_index: 0.0,
        };
        assert!(place("skull", 1.5e6 * (1.0 + 1e-7)).is_focus(&focal));
        assert!(place("skull", 1.2e6).is_focus(&focal));
        assert!(!place("skull", 1.5e6 * 1.01).is_focus(&focal));
        assert!(!place("brain", 1.2e6).is_focus(&focal));
    }

    /// A 41³ grid (0.5 mm) around a target at its centre sample: brain within 5 mm of it, a bone
    /// shell to 7 mm (4 samples thick: a step of the path test moves at most √3 samples, so it
    /// cannot pass over it), brain again to 9 mm (the scalp), water beyond. `|p|` is a fixed
    /// pseudo-random value per sample.
    fn shell() -> (Grid, [f64; 3], TissueMap, Vec<f32>, Vec<&'static str>) {
        let g = Grid::new(41, 41, 0.5e-3, 0.5e-3, 41, 0.5e-3, 10e-3).unwrap();
        let focus = [0.0, 0.0, g.z(20)];
        let (mut index, mut truth) = (Vec::new(), Vec::new());
        for s in 0..g.lateral_len() * g.nz {
            let p = sample_position(&g, s);
            let r = (p[0].powi(2) + p[1].powi(2) + (p[2] - focus[2]).powi(2)).sqrt() * 1e3;
            let (id, class) = match r {
                r if r < 5.0 => (1, "brain"),
                r if r < 7.0 => (2, "skull"),
                r if r < 9.0 => (1, "scalp"),
                _ => (0, "water"),
            };
            index.push(id);
            truth.push(class);
        }
        let magnitude = (0..index.len()).map(|s| ((s as f64 * 12.9898).sin() * 43758.5453).fract().abs() as f32).collect();
        let names = ["water", "brain", "bone"].map(String::from).to_vec();
        (g, focus, TissueMap { names, index }, magnitude, truth)
    }

    /// The hottest sample of each class by brute force over `truth` (a class per sample).
    fn brute_force(magnitude: &[f32], truth: &[&str]) -> Vec<(String, f32, usize)> {
        let mut best: Vec<(String, f32, usize)> = Vec::new();
        for (s, (&p, &c)) in magnitude.iter().zip(truth).enumerate() {
            match best.iter_mut().find(|b| b.0 == c) {
                Some(b) if p > b.1 => *b = (c.to_string(), p, s),
                Some(_) => {}
                None => best.push((c.to_string(), p, s)),
            }
        }
        best.sort_by(|a, b| a.0.cmp(&b.0));
        best
    }

    fn sorted(mut v: Vec<(String, f32, usize)>) -> Vec<(String, f32, usize)> {
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    }

    /// Through a closed bone shell, the target's tissue outside it is the scalp and inside it the
    /// brain: the same samples, exactly, as the classes by radius.
    #[test]
    fn a_bone_shell_splits_the_targets_tissue_into_brain_and_scalp() {
        let (g, focus, map, magnitude, truth) = shell();
        assert_eq!(sorted(hottest_samples(&g, focus, &map, &magnitude)), brute_force(&magnitude, &truth));
    }

    /// A material named like a class ("scalp" for the water here) merges with it: one entry, the
    /// hotter of the two.
    #[test]
    fn a_material_named_like_a_class_gives_one_entry() {
        let (g, focus, mut map, magnitude, truth) = shell();
        map.names[0] = "scalp".into();
        let merged: Vec<&str> = truth.iter().map(|&c| if c == "water" { "scalp" } else { c }).collect();
        assert_eq!(sorted(hottest_samples(&g, focus, &map, &magnitude)), brute_force(&magnitude, &merged));
    }

    /// A bowl focused at 50 mm through water, a soft "brain" layer from 20 mm, bone from 30 to
    /// 35 mm and brain beyond: the brain in front of the bone is the scalp, behind it the brain;
    /// bone is the skull; the water stays water; a point off the grid is refused. With the bone
    /// moved onto the focus, the focal peak's tissue is the skull too.
    #[test]
    fn tissue_classes_name_points_as_the_hottest_places_do() {
        let scenario = |bone: (f64, f64)| {
            format!(
                "frequency_hz = 500000.0\n[focus]\nposition_mm = [0.0, 0.0, 50.0]\n[transducer]\nkind = \"bowl\"\n\
                 radius_of_curvature_mm = 50.0\naperture_diameter_mm = 40.0\nelements = 64\n[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\n\
                 density_kg_m3 = 1000.0\n[[material]]\nname = \"brain\"\nsound_speed_m_s = 1540.0\n\
                 density_kg_m3 = 1040.0\n[[material]]\nname = \"bone\"\nsound_speed_m_s = 2800.0\n\
                 density_kg_m3 = 1850.0\nattenuation_db_cm_mhz = 10.0\n[medium]\nbackground = \"water\"\n\
                 [[region]]\nmaterial = \"brain\"\nshape = \"slab\"\nz_min_mm = 20.0\nz_max_mm = 80.0\n\
                 [[region]]\nmaterial = \"bone\"\nshape = \"slab\"\nz_min_mm = {}\nz_max_mm = {}\n[grid]\nspacing_mm = 0.75\n",
                bone.0, bone.1
            )
        };
        let sim = Simulation::new(&Scenario::from_toml(&scenario((30.0, 35.0)), None).unwrap()).unwrap();
        let at = |z_mm: f64| [2e-3, -1e-3, z_mm * 1e-3];
        let classes = sim.tissue_classes(&[at(10.0), at(25.0), at(32.5), at(45.0), at(60.0)]).unwrap();
        assert_eq!(classes, ["water", "scalp", "skull", "brain", "brain"]);
        let off = sim.tissue_classes(&[[0.0, 0.0, -5e-3]]).unwrap_err().to_string();
        assert!(off.starts_with("points_mm: (0.0, 0.0, -5.0) mm lies off the grid"), "{off}");
        let in_bone = Simulation::new(&Scenario::from_toml(&scenario((40.0, 60.0)), None).unwrap()).unwrap();
        let m = in_bone.focal_metrics(&[], in_bone.focus).unwrap().expect("a closed -6 dB region");
        assert_eq!(m.tissue, "skull");
    }

    /// Without bone nothing is the scalp; a target outside the grid splits nothing either.
    #[test]
    fn without_bone_or_target_there_is_no_scalp() {
        let (g, focus, mut map, magnitude, _) = shell();
        fn by_name(map: &TissueMap) -> Vec<&str> {
            map.index.iter().map(|&i| if map.names[i as usize] == BONE { "skull" } else { map.names[i as usize].as_str() }).collect()
        }
        let far = [0.0, 0.0, 1.0];
        assert_eq!(sorted(hottest_samples(&g, far, &map, &magnitude)), brute_force(&magnitude, &by_name(&map)));
        map.index.iter_mut().filter(|i| **i == 2).for_each(|i| *i = 1);
        map.names.pop();
        assert_eq!(sorted(hottest_samples(&g, focus, &map, &magnitude)), brute_force(&magnitude, &by_name(&map)));
    }
}
