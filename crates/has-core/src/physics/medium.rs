//! Acoustic media: materials, regions (cylinder, slab), voxel maps and CT volumes.

use crate::error::{require_positive, HasError, Result};
use crate::physics::ct::CtMedium;
use crate::physics::fft::map_collect;
use crate::physics::grid::Grid;
use rayon::prelude::*;
use std::sync::Arc;

use crate::physics::material::{attenuation_np_m, require_sound_speed};
pub use crate::physics::material::{Material, Properties, NP_PER_DB};
use crate::physics::tissue::MrResponse;

/// The geometry of a region (metres, transducer frame).
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// `(x-cx)² + (y-cy)² <= r²` and `z_min <= z <= z_max`: a cylinder about the beam direction.
    Cylinder {
        /// Radius r, m.
        radius: f64,
        /// Lower bound along z, m.
        z_min: f64,
        /// Upper bound along z, m.
        z_max: f64,
        /// Axis position `(cx, cy)`, m.
        center: [f64; 2],
    },
    /// `z_min <= z <= z_max`, all x, y: a layer perpendicular to the beam.
    Slab {
        /// Lower bound along z, m.
        z_min: f64,
        /// Upper bound along z, m.
        z_max: f64,
    },
}

impl Shape {
    /// Whether the point lies inside.
    pub fn contains(&self, x: f64, y: f64, z: f64) -> bool {
        match *self {
            Shape::Cylinder { radius, z_min, z_max, center } => {
                let (dx, dy) = (x - center[0], y - center[1]);
                z >= z_min && z <= z_max && dx * dx + dy * dy <= radius * radius
            }
            Shape::Slab { z_min, z_max } => z >= z_min && z <= z_max,
        }
    }

    /// Its extent along z, `(z_min, z_max)` (m).
    pub fn z_range(&self) -> (f64, f64) {
        match *self {
            Shape::Cylinder { z_min, z_max, .. } | Shape::Slab { z_min, z_max } => (z_min, z_max),
        }
    }

    /// A point `(x, y)` (m) the shape covers at every z of its range: the cylinder's axis, or the
    /// beam axis for a slab.
    pub fn axis_point(&self) -> [f64; 2] {
        match *self {
            Shape::Cylinder { center, .. } => center,
            Shape::Slab { .. } => [0.0, 0.0],
        }
    }

    fn validate(&self, name: &str) -> Result<()> {
        if let Shape::Cylinder { radius, center, .. } = *self {
            require_positive(&format!("{name}.radius_mm"), radius)?;
            if !center.iter().all(|c| c.is_finite()) {
                return Err(HasError::invalid(format!("{name}.center_mm"), "must be finite"));
            }
        }
        let (z_min, z_max) = self.z_range();
        if !(z_min.is_finite() && z_max.is_finite() && z_max > z_min) {
            return Err(HasError::invalid(
                format!("{name}.z_min_mm/z_max_mm"),
                format!("need finite z_min < z_max, got {z_min} and {z_max}"),
            ));
        }
        Ok(())
    }
}

/// A region of one material; later regions override earlier ones where they overlap.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    /// Index into [`Medium::materials`].
    pub material: usize,
    /// Where the material lies.
    pub shape: Shape,
}

/// Properties given voxel by voxel on a box (nearest-neighbour lookup); outside the box the
/// region/background description applies.
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelMap {
    /// Centre of voxel (0, 0, 0), metres, order (x, y, z).
    pub origin: [f64; 3],
    /// Voxel spacing (m), order (x, y, z).
    pub spacing: [f64; 3],
    /// Shape (nz, ny, nx).
    pub shape: [usize; 3],
    /// Sound speed c per voxel, m/s; row-major (z, y, x).
    pub sound_speed: Vec<f64>,
    /// Density rho per voxel, kg/m³; row-major (z, y, x).
    pub density: Vec<f64>,
    /// Attenuation coefficient a0 per voxel, dB/cm/MHz^y; row-major (z, y, x).
    pub attenuation_db_cm_mhz: Vec<f64>,
    /// Frequency exponent y of the power law `a0·(f / 1 MHz)^y`, shared by every voxel.
    pub attenuation_power: f64,
}

impl VoxelMap {
    /// Validates shapes and values.
    pub fn validate(&self) -> Result<()> {
        let n: usize = self.shape.iter().product();
        if n == 0 {
            return Err(HasError::invalid("voxels.shape", "must not be empty"));
        }
        for (name, v) in [
            ("voxels.sound_speed", &self.sound_speed),
            ("voxels.density", &self.density),
            ("voxels.attenuation", &self.attenuation_db_cm_mhz),
        ] {
            if v.len() != n {
                return Err(HasError::invalid(name, format!("has {} values, shape needs {n}", v.len())));
            }
        }
        for (i, s) in self.spacing.iter().enumerate() {
            require_positive(&format!("voxels.spacing[{i}]"), *s)?;
        }
        for (i, c) in self.sound_speed.iter().enumerate() {
            require_sound_speed(&format!("voxels.sound_speed[{i}]"), *c)?;
        }
        let bad = |v: &[f64], strict: bool| v.iter().position(|x| !x.is_finite() || (strict && *x <= 0.0) || *x < 0.0);
        if let Some(i) = bad(&self.density, true) {
            return Err(HasError::invalid("voxels.density", format!("voxel {i} is {} (need > 0)", self.density[i])));
        }
        if let Some(i) = bad(&self.attenuation_db_cm_mhz, false) {
            return Err(HasError::invalid("voxels.attenuation", format!("voxel {i} is {} (need >= 0)", self.attenuation_db_cm_mhz[i])));
        }
        Ok(())
    }

    /// Whether the box spans height `z`.
    fn covers_z(&self, z: f64) -> bool {
        let k = ((z - self.origin[2]) / self.spacing[2]).round();
        k >= 0.0 && k < self.shape[0] as f64
    }

    fn index(&self, x: f64, y: f64, z: f64) -> Option<usize> {
        let [nz, ny, nx] = self.shape;
        let idx = |v: f64, o: f64, d: f64, n: usize| {
            let i = ((v - o) / d).round();
            (i >= 0.0 && i < n as f64).then_some(i as usize)
        };
        let i = idx(x, self.origin[0], self.spacing[0], nx)?;
        let j = idx(y, self.origin[1], self.spacing[1], ny)?;
        let k = idx(z, self.origin[2], self.spacing[2], nz)?;
        Some((k * ny + j) * nx + i)
    }
}

/// The medium: materials, a background, regions, an optional voxel map and an optional CT.
#[derive(Debug, Clone, PartialEq)]
pub struct Medium {
    /// The materials, referred to by index.
    pub materials: Vec<Material>,
    /// Index of the background material (wherever no region or voxel map applies).
    pub background: usize,
    /// Regions in order; later ones override earlier ones where they overlap.
    pub regions: Vec<Region>,
    /// Voxel-by-voxel properties, overriding the regions and background inside their box.
    pub voxels: Option<VoxelMap>,
    /// A CT of the head, overriding everything else where it holds tissue (its coupling voxels
    /// and the space outside it keep the description above); shared, as it may be large.
    pub ct: Option<Arc<CtMedium>>,
}

impl Medium {
    /// A single homogeneous material.
    pub fn homogeneous(material: Material) -> Self {
        Medium { materials: vec![material], background: 0, regions: vec![], voxels: None, ct: None }
    }

    /// The same medium with the CT's bone read as soft tissue (the head without its skull);
    /// `None` without a CT.
    pub fn without_bone(&self) -> Option<Medium> {
        let ct = self.ct.as_ref()?;
        Some(Medium { ct: Some(Arc::new(ct.without_bone())), ..self.clone() })
    }

    /// Checks materials, indices and shapes.
    pub fn validate(&self) -> Result<()> {
        if self.materials.is_empty() {
            return Err(HasError::invalid("material", "no material given"));
        }
        for m in &self.materials {
            m.validate()?;
        }
        if self.background >= self.materials.len() {
            return Err(HasError::invalid("medium.background", "names no material"));
        }
        for (i, r) in self.regions.iter().enumerate() {
            if r.material >= self.materials.len() {
                return Err(HasError::invalid(format!("region[{i}].material"), "names no material"));
            }
            r.shape.validate(&format!("region[{i}]"))?;
        }
        if let Some(v) = &self.voxels {
            v.validate()?;
        }
        Ok(())
    }

    /// Checks that `grid` resolves every region: each must reach into the grid (a region wholly
    /// beyond it would have no effect) and be at least one step thick along z (the march samples
    /// each slab at its midpoint, so a thinner layer would vanish or count as a whole step; the
    /// default step puts planes on the faces of layers, a step set in `[grid]` may round them).
    pub fn check_on_grid(&self, grid: &Grid) -> Result<()> {
        let (z_lo, z_hi) = (grid.z0, grid.z(grid.nz - 1));
        let (x_half, y_half) = (grid.x(grid.nx - 1).max(-grid.x(0)), grid.y(grid.ny - 1).max(-grid.y(0)));
        for (i, r) in self.regions.iter().enumerate() {
            let name = format!("region[{i}] ({})", self.materials[r.material].name);
            let (z_min, z_max) = r.shape.z_range();
            let lateral_miss = match r.shape {
                Shape::Slab { .. } => false,
                Shape::Cylinder { radius, center, .. } => center[0].abs() - radius > x_half || center[1].abs() - radius > y_half,
            };
            if z_max < z_lo {
                return Err(HasError::invalid(
                    name,
                    format!(
                        "ends at z = {:.2} mm, before the source plane at {:.2} mm (just in front of the transducer), where the march \
                         starts: it would have no effect; move it further from the transducer",
                        z_max * 1e3,
                        z_lo * 1e3
                    ),
                ));
            }
            if z_min > z_hi || lateral_miss {
                return Err(HasError::invalid(
                    name,
                    format!(
                        "lies outside the simulation grid (z {:.2} to {:.2} mm, |x| <= {:.1} mm, |y| <= {:.1} mm): it would have no \
                         effect; move it, or extend grid.z_max_mm / grid.lateral_size_mm",
                        z_lo * 1e3,
                        z_hi * 1e3,
                        x_half * 1e3,
                        y_half * 1e3
                    ),
                ));
            }
            if z_max - z_min < grid.dz {
                return Err(HasError::invalid(
                    name,
                    format!(
                        "is {:.3} mm thick, less than one grid step ({:.3} mm): the march would miss it or make it a whole step; \
                         set grid.step_mm to {:.4} mm (one step across it), or leave it out: the default step puts planes on \
                         the faces of layers",
                        (z_max - z_min) * 1e3,
                        grid.dz * 1e3,
                        (z_max - z_min) * 1e3
                    ),
                ));
            }
        }
        if let Some(ct) = &self.ct {
            let [lo, hi] = ct.bounds();
            if hi[2] < z_lo || lo[2] > z_hi || lo[0] > x_half || hi[0] < -x_half || lo[1] > y_half || hi[1] < -y_half {
                return Err(HasError::BadFile {
                    path: ct.path.clone(),
                    reason: format!(
                        "the CT lies outside the simulation grid (z {:.2} to {:.2} mm, |x| <= {:.1} mm, |y| <= {:.1} mm): check \
                         ct.patient_to_transducer_mm",
                        z_lo * 1e3,
                        z_hi * 1e3,
                        x_half * 1e3,
                        y_half * 1e3
                    ),
                });
            }
        }
        Ok(())
    }

    /// Checks that nothing but the background lies before the source plane `z0` (m) on the straight
    /// paths from `sources` to `focus` (m): the march starts at the source plane, so tissue behind
    /// it would be missed without a word. Paths are sampled every `step` (m).
    pub fn check_before_source_plane(&self, z0: f64, sources: &[[f64; 3]], focus: [f64; 3], step: f64, frequency: f64) -> Result<()> {
        let background = self.materials[self.background].properties(frequency);
        for (e, s) in sources.iter().enumerate() {
            if s[2] >= z0 {
                continue;
            }
            // The part of the path with z < z0 (all of it if the focus lies behind the plane too).
            let t_end = if focus[2] > z0 { (z0 - s[2]) / (focus[2] - s[2]) } else { 1.0 };
            let len = t_end * (0..3).map(|k| (focus[k] - s[k]).powi(2)).sum::<f64>().sqrt();
            let n = (len / step).ceil().max(1.0) as usize;
            for m in 0..n {
                let t = t_end * m as f64 / n as f64;
                let p: [f64; 3] = std::array::from_fn(|k| s[k] + t * (focus[k] - s[k]));
                if self.properties_at(p[0], p[1], p[2], frequency) != background {
                    return Err(HasError::invalid(
                        self.name_at(p),
                        format!(
                            "lies on the path from element {e} to the focus at ({:.1}, {:.1}, {:.1}) mm, before the source plane at \
                             z = {:.1} mm (just in front of the transducer's most forward element): the march along z starts there \
                             and would miss it; move it further from the transducer or use a smaller aperture (for a hemisphere, \
                             transducer.polar_angle_max_deg)",
                            p[0] * 1e3,
                            p[1] * 1e3,
                            p[2] * 1e3,
                            z0 * 1e3
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// What sets the medium at a point, as a scenario names it: the CT, the voxel map or a region.
    fn name_at(&self, p: [f64; 3]) -> String {
        // (Whether the CT holds tissue there does not depend on the frequency.)
        if let Some(ct) = self.ct.as_ref().filter(|ct| ct.properties_at(p, 1e6).is_some()) {
            return format!("ct.file ({})", ct.path);
        }
        if self.voxels.as_ref().is_some_and(|v| v.index(p[0], p[1], p[2]).is_some()) {
            return "the voxel map".into();
        }
        match self.regions.iter().enumerate().rev().find(|(_, r)| r.shape.contains(p[0], p[1], p[2])) {
            Some((i, r)) => format!("region[{i}] ({})", self.materials[r.material].name),
            None => format!("medium.background ({})", self.materials[self.background].name),
        }
    }

    /// Index of the material at a point (last region containing it, else the background).
    pub fn material_at(&self, x: f64, y: f64, z: f64) -> usize {
        self.regions.iter().rev().find(|r| r.shape.contains(x, y, z)).map_or(self.background, |r| r.material)
    }

    /// Properties at a point for `frequency` (Hz).
    pub fn properties_at(&self, x: f64, y: f64, z: f64, frequency: f64) -> Properties {
        if let Some(p) = self.ct.as_ref().and_then(|ct| ct.properties_at([x, y, z], frequency)) {
            return p;
        }
        self.described_at(x, y, z, frequency)
    }

    /// Properties at a point from the voxel map, regions and background (the CT aside).
    fn described_at(&self, x: f64, y: f64, z: f64, frequency: f64) -> Properties {
        if let Some(v) = &self.voxels {
            if let Some(i) = v.index(x, y, z) {
                let a = attenuation_np_m(v.attenuation_db_cm_mhz[i], v.attenuation_power, frequency);
                return Properties {
                    sound_speed: v.sound_speed[i],
                    density: v.density[i],
                    attenuation: a,
                    shear_sound_speed: 0.0,
                    shear_attenuation: 0.0,
                };
            }
        }
        self.materials[self.material_at(x, y, z)].properties(frequency)
    }

    /// How the tissue at a point shows in MR-ARFI images: the CT's class where it holds tissue,
    /// else the material's (a voxel map's voxel by its sound speed,
    /// [`MrResponse::for_sound_speed`]).
    pub fn mr_response_at(&self, x: f64, y: f64, z: f64) -> MrResponse {
        if let Some(r) = self.ct.as_ref().and_then(|ct| ct.mr_response_at([x, y, z])) {
            return r;
        }
        if let Some(v) = &self.voxels {
            if let Some(i) = v.index(x, y, z) {
                return MrResponse::for_sound_speed(v.sound_speed[i]);
            }
        }
        self.materials[self.material_at(x, y, z)].mr
    }

    /// The name of the tissue at a point: the CT's class where it holds tissue (`"bone"` or its
    /// soft tissue's material name), `"voxel map"` inside a voxel map, else the material's name.
    pub fn tissue_at(&self, x: f64, y: f64, z: f64) -> String {
        self.tissue_name_at(x, y, z).to_string()
    }

    /// Every name [`Medium::tissue_at`] may give, each once: the materials', then `"voxel map"`
    /// with a voxel map, then a CT's soft tissue and `"bone"`.
    pub fn tissue_names(&self) -> Vec<&str> {
        let mut names: Vec<&str> = self.materials.iter().map(|m| m.name.as_str()).collect();
        names.extend(self.voxels.as_ref().map(|_| "voxel map"));
        if let Some(ct) = &self.ct {
            names.extend([ct.conversion.soft_tissue.name.as_str(), "bone"]);
        }
        let mut unique = Vec::with_capacity(names.len());
        for n in names {
            if !unique.contains(&n) {
                unique.push(n);
            }
        }
        unique
    }

    /// [`Medium::tissue_at`] without a copy of the name.
    pub fn tissue_name_at(&self, x: f64, y: f64, z: f64) -> &str {
        if let Some(name) = self.ct.as_ref().and_then(|ct| ct.conversion.tissue_name(ct.hu_at([x, y, z])?)) {
            return name;
        }
        if self.voxels.as_ref().is_some_and(|v| v.index(x, y, z).is_some()) {
            return "voxel map";
        }
        &self.materials[self.material_at(x, y, z)].name
    }

    /// Lowest sound speed anywhere in the medium (sets the shortest wavelength).
    pub fn min_sound_speed(&self) -> f64 {
        let m = self.materials.iter().map(|m| m.sound_speed).fold(f64::INFINITY, f64::min);
        let m = self.ct.as_ref().map_or(m, |ct| m.min(ct.min_sound_speed()));
        match &self.voxels {
            Some(v) => v.sound_speed.iter().copied().fold(m, f64::min),
            None => m,
        }
    }

    /// Properties on the lateral grid at height `z`: row-major `(ny, nx)`. Where a CT reaches,
    /// each pixel holds its cell's average (see [`crate::physics::ct`]).
    pub fn slice(&self, grid: &Grid, z: f64, frequency: f64) -> SliceProperties {
        self.slice_with(grid, z, frequency, &mut Vec::new())
    }

    /// [`Medium::slice`] built in `scratch` (reused from slice to slice, its memory touched once:
    /// a plan's layout reads hundreds of slices).
    pub fn slice_with(&self, grid: &Grid, z: f64, frequency: f64, scratch: &mut Vec<Properties>) -> SliceProperties {
        let per_material: Vec<Properties> = self.materials.iter().map(|m| m.properties(frequency)).collect();
        let voxels_here = self.voxels.as_ref().is_some_and(|v| v.covers_z(z));
        let props = scratch;
        props.resize(grid.lateral_len(), per_material[self.background]);
        props.par_chunks_mut(grid.nx).enumerate().for_each(|(j, row)| {
            for (i, p) in row.iter_mut().enumerate() {
                let (x, y) = (grid.x(i), grid.y(j));
                *p = if voxels_here { self.described_at(x, y, z, frequency) } else { per_material[self.material_at(x, y, z)] };
            }
        });
        if let Some(ct) = self.ct.as_ref().filter(|ct| ct.covers_z(z)) {
            ct.fill_slice(grid, z, frequency, props);
        }
        let field = |f: fn(&Properties) -> f64| map_collect(true, props, f);
        let shear = props
            .iter()
            .any(|p| p.shear_sound_speed > 0.0)
            .then(|| ShearMaps { sound_speed: field(|p| p.shear_sound_speed), attenuation: field(|p| p.shear_attenuation) });
        SliceProperties {
            sound_speed: field(|p| p.sound_speed),
            density: field(|p| p.density),
            attenuation: field(|p| p.attenuation),
            shear,
        }
    }

    /// Which regions' z-ranges contain `z`; two heights with equal keys have identical slices.
    /// `None` where a voxel map covers `z` (every slice may differ there).
    pub fn slice_key(&self, z: f64) -> Option<Vec<bool>> {
        if self.voxels.as_ref().is_some_and(|v| v.covers_z(z)) || self.ct.as_ref().is_some_and(|ct| ct.covers_z(z)) {
            return None;
        }
        Some(
            self.regions
                .iter()
                .map(|r| {
                    let (z_min, z_max) = r.shape.z_range();
                    z >= z_min && z <= z_max
                })
                .collect(),
        )
    }
}

/// Property maps of one lateral slice, row-major `(ny, nx)`.
#[derive(Debug, Clone, PartialEq)]
pub struct SliceProperties {
    /// Sound speed c, m/s.
    pub sound_speed: Vec<f64>,
    /// Density rho, kg/m³.
    pub density: Vec<f64>,
    /// Amplitude attenuation coefficient alpha at the slice's frequency, Np/m.
    pub attenuation: Vec<f64>,
    /// The shear wave's maps where any pixel is a solid (`None`: every pixel a fluid).
    pub shear: Option<ShearMaps>,
}

/// Shear-wave maps of one lateral slice, row-major `(ny, nx)`: 0 m/s at a fluid's pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct ShearMaps {
    /// Shear-wave speed c_s, m/s.
    pub sound_speed: Vec<f64>,
    /// Shear-wave amplitude attenuation at the slice's frequency, Np/m.
    pub attenuation: Vec<f64>,
}

impl SliceProperties {
    /// A slice of fluids (no shear maps).
    pub fn fluid(sound_speed: Vec<f64>, density: Vec<f64>, attenuation: Vec<f64>) -> Self {
        SliceProperties { sound_speed, density, attenuation, shear: None }
    }

    /// The shear speed (m/s) at pixel `i`: 0 in a fluid.
    pub fn shear_speed(&self, i: usize) -> f64 {
        self.shear.as_ref().map_or(0.0, |s| s.sound_speed[i])
    }

    /// Whether sound speed and attenuation are the same at every pixel.
    pub fn is_uniform(&self) -> bool {
        let same = |v: &[f64]| v.iter().all(|x| *x == v[0]);
        same(&self.sound_speed) && same(&self.attenuation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn attenuation_converts_db_cm_mhz_to_np_m() {
        // 0.46 dB/cm/MHz at 0.55 MHz: 0.253 dB/cm = 25.3 dB/m = 2.9128 Np/m.
        let m = Material::new("phantom", 1533.0, 1040.0, 0.46).unwrap();
        assert!((m.attenuation_np_m(550e3) - 25.3 / 8.685_889_638).abs() < 1e-9);
    }

    #[test]
    fn later_regions_override_earlier_ones() {
        let water = Material::new("water", 1500.0, 1000.0, 0.0).unwrap();
        let a = Material::new("a", 1600.0, 1000.0, 0.0).unwrap();
        let b = Material::new("b", 1700.0, 1000.0, 0.0).unwrap();
        let mut m = Medium::homogeneous(water);
        m.materials.extend([a, b]);
        m.regions.push(Region { material: 1, shape: Shape::Slab { z_min: 0.01, z_max: 0.05 } });
        m.regions.push(Region { material: 2, shape: Shape::Cylinder { radius: 0.01, z_min: 0.02, z_max: 0.03, center: [0.0, 0.0] } });
        assert_eq!(m.properties_at(0.0, 0.0, 0.005, 1e6).sound_speed, 1500.0);
        assert_eq!(m.properties_at(0.02, 0.0, 0.025, 1e6).sound_speed, 1600.0);
        assert_eq!(m.properties_at(0.0, 0.0, 0.025, 1e6).sound_speed, 1700.0);
    }

    #[test]
    fn negative_sound_speed_is_rejected_by_name() {
        let e = Material::new("skull", -1.0, 1900.0, 0.0).unwrap_err();
        assert!(e.to_string().contains("skull"), "{e}");
    }

    #[test]
    fn sound_speeds_outside_gases_to_diamond_are_rejected() {
        for c in [1e-300, 5e-324, 99.0, 20_001.0, 1e300] {
            let e = Material::new("brain", c, 1000.0, 0.5).unwrap_err();
            assert!(e.to_string().contains("sound_speed_m_s"), "{c}: {e}");
        }
        for c in [100.0, 343.0, 1500.0, 12_000.0, 20_000.0] {
            assert!(Material::new("m", c, 1000.0, 0.5).is_ok(), "{c}");
        }
    }
}
