//! Scenario files (SPEC §4): TOML (or JSON) with the paper's phantom experiment as defaults.
//!
//! Parsing rejects unknown keys. [`Scenario`] holds the file's values in file units (mm, Hz,
//! dB/cm/MHz); [`Scenario::resolve`] turns them into validated SI objects.

use crate::error::{require_non_negative, require_positive, HasError, Result};
use crate::physics::medium::{Material, Medium, Region, Shape};
use crate::physics::mr::{MrGeometry, MrPlane};
use crate::physics::propagation::InterfaceModel;
use crate::physics::transducer::{ElementShape, Transducer};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A scenario as written in a file (units in the key names).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default = "d::name")]
    pub name: String,
    #[serde(default = "d::frequency")]
    pub frequency_hz: f64,
    /// Total acoustic power (W); every element face gets the same pressure amplitude.
    #[serde(default = "d::power")]
    pub acoustic_power_w: f64,
    #[serde(default)]
    pub transducer: TransducerSpec,
    #[serde(default)]
    pub focus: FocusSpec,
    #[serde(default, rename = "material", skip_serializing_if = "Option::is_none")]
    pub materials: Option<Vec<MaterialSpec>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub medium: Option<MediumSpec>,
    #[serde(default, rename = "region", skip_serializing_if = "Option::is_none")]
    pub regions: Option<Vec<RegionSpec>>,
    #[serde(default)]
    pub grid: GridSpec,
    #[serde(default)]
    pub mr: MrSpec,
    #[serde(default)]
    pub arfi: ArfiSpec,
    /// Folder that relative paths (the elements CSV) are resolved against.
    #[serde(skip)]
    pub base_dir: Option<PathBuf>,
}

/// `[transducer]`: `kind` = `"planar-quadrants"` | `"bowl"` | `"elements"`; only the keys of
/// that kind may be given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransducerSpec {
    #[serde(default = "d::kind")]
    pub kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elements_per_side: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub element_size_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quadrant_gap_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_of_curvature_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_diameter_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elements: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// `"square"` (default) or `"disc"`, for `kind = "elements"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub element_shape: Option<String>,
}

impl Default for TransducerSpec {
    fn default() -> Self {
        TransducerSpec {
            kind: d::kind(),
            elements_per_side: Some(16),
            pitch_mm: Some(2.5),
            element_size_mm: Some(2.3),
            quadrant_gap_mm: Some(1.0),
            radius_of_curvature_mm: None,
            aperture_diameter_mm: None,
            elements: None,
            file: None,
            element_shape: None,
        }
    }
}

/// `[focus]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FocusSpec {
    #[serde(default = "d::focus")]
    pub position_mm: [f64; 3],
}

impl Default for FocusSpec {
    fn default() -> Self {
        FocusSpec { position_mm: d::focus() }
    }
}

/// `[[material]]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    pub name: String,
    pub sound_speed_m_s: f64,
    pub density_kg_m3: f64,
    #[serde(default)]
    pub attenuation_db_cm_mhz: f64,
    /// Exponent y of `a0·f^y` (default 1: linear in frequency).
    #[serde(default = "d::one")]
    pub attenuation_power: f64,
}

/// `[medium]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MediumSpec {
    pub background: String,
}

/// `[[region]]`: `shape` = `"cylinder"` | `"slab"`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    pub material: String,
    pub shape: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_mm: Option<f64>,
    pub z_min_mm: f64,
    pub z_max_mm: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center_mm: Option<[f64; 2]>,
}

/// `[grid]`: all optional; chosen from the wavelength, the aperture and the focus when absent.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Lateral spacing (default: a quarter of the shortest wavelength).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spacing_mm: Option<f64>,
    /// Step along z (default: the lateral spacing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_mm: Option<f64>,
    /// Lateral size of the square grid (default: aperture + 2 x 20 mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral_size_mm: Option<f64>,
    /// Last plane (default: 1.5 x the focal depth, and the MR field of view).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub z_max_mm: Option<f64>,
    /// Absorbing layer at the lateral edges (default 10 mm).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sponge_width_mm: Option<f64>,
    /// Add the waves reflected at changes of impedance (a backward pass; default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reflections: Option<bool>,
    /// How changes of medium are crossed: `"angular"` (default: plane-wave coefficients of
    /// every angular-spectrum component, with the reverberation of strongly reflecting layers)
    /// or `"normal-incidence"` (the original HAS coefficient per pixel, one way).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interfaces: Option<String>,
}

impl GridSpec {
    /// The interface model named by `interfaces` (default: angular).
    pub fn interface_model(&self) -> Result<InterfaceModel> {
        match self.interfaces.as_deref() {
            None => Ok(InterfaceModel::default()),
            Some(name) => InterfaceModel::parse(name).ok_or_else(|| {
                HasError::invalid("grid.interfaces", format!("must be \"angular\" or \"normal-incidence\", got \"{name}\""))
            }),
        }
    }
}

/// `[mr]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MrSpec {
    #[serde(default = "d::plane")]
    pub plane: String,
    /// Centre of the slice (default: the focus).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center_mm: Option<[f64; 3]>,
    #[serde(default = "d::fov")]
    pub fov_mm: [f64; 2],
    #[serde(default = "d::matrix")]
    pub matrix: [usize; 2],
    #[serde(default = "d::thickness")]
    pub slice_thickness_mm: f64,
}

impl Default for MrSpec {
    fn default() -> Self {
        MrSpec { plane: d::plane(), center_mm: None, fov_mm: d::fov(), matrix: d::matrix(), slice_thickness_mm: d::thickness() }
    }
}

/// `[arfi]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArfiSpec {
    #[serde(default = "d::width")]
    pub broadening_width_mm: f64,
    #[serde(default = "d::mask")]
    pub mask_fraction: f64,
    #[serde(default = "d::noise")]
    pub noise_rad: f64,
    /// Focal ARFI phase of the ideal (unaberrated) beam; sets the amplitude unless given.
    #[serde(default = "d::focal_phase")]
    pub ideal_focal_phase_rad: f64,
    /// Scale from broadened force density to ARFI phase (rad·m³/N), overriding the above.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplitude_rad_m3_per_n: Option<f64>,
}

impl Default for ArfiSpec {
    fn default() -> Self {
        ArfiSpec {
            broadening_width_mm: d::width(),
            mask_fraction: d::mask(),
            noise_rad: d::noise(),
            ideal_focal_phase_rad: d::focal_phase(),
            amplitude_rad_m3_per_n: None,
        }
    }
}

/// Defaults of SPEC §3.
mod d {
    pub fn name() -> String {
        "vyas2014-phantom".into()
    }
    pub fn frequency() -> f64 {
        550e3
    }
    pub fn power() -> f64 {
        70.0
    }
    pub fn kind() -> String {
        "planar-quadrants".into()
    }
    pub fn focus() -> [f64; 3] {
        [0.0, 0.0, 85.0]
    }
    pub fn one() -> f64 {
        1.0
    }
    pub fn plane() -> String {
        "xy".into()
    }
    pub fn fov() -> [f64; 2] {
        [180.0, 135.0]
    }
    pub fn matrix() -> [usize; 2] {
        [128, 96]
    }
    pub fn thickness() -> f64 {
        3.0
    }
    pub fn width() -> f64 {
        2.7
    }
    pub fn mask() -> f64 {
        0.05
    }
    pub fn noise() -> f64 {
        0.02
    }
    pub fn focal_phase() -> f64 {
        0.6
    }
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            name: d::name(),
            frequency_hz: d::frequency(),
            acoustic_power_w: d::power(),
            transducer: TransducerSpec::default(),
            focus: FocusSpec::default(),
            materials: None,
            medium: None,
            regions: None,
            grid: GridSpec::default(),
            mr: MrSpec::default(),
            arfi: ArfiSpec::default(),
            base_dir: None,
        }
    }
}

/// The default medium: water below z = 40 mm, the CIRS phantom cylinder above (SPEC §3).
fn default_medium() -> (Vec<MaterialSpec>, MediumSpec, Vec<RegionSpec>) {
    let materials = vec![
        MaterialSpec {
            name: "water".into(),
            sound_speed_m_s: 1500.0,
            density_kg_m3: 1000.0,
            attenuation_db_cm_mhz: 0.0,
            attenuation_power: 1.0,
        },
        MaterialSpec {
            name: "phantom".into(),
            sound_speed_m_s: 1533.0,
            density_kg_m3: 1040.0,
            attenuation_db_cm_mhz: 0.46,
            attenuation_power: 1.0,
        },
    ];
    let regions = vec![RegionSpec {
        material: "phantom".into(),
        shape: "cylinder".into(),
        radius_mm: Some(60.0),
        z_min_mm: 40.0,
        z_max_mm: 160.0,
        center_mm: None,
    }];
    (materials, MediumSpec { background: "water".into() }, regions)
}

/// The scenario in SI units, validated.
#[derive(Debug, Clone)]
pub struct Resolved {
    pub name: String,
    pub frequency: f64,
    pub acoustic_power: f64,
    pub transducer: Transducer,
    pub focus: [f64; 3],
    pub medium: Medium,
    pub grid: GridSpec,
    pub mr: MrGeometry,
    pub broadening_width: f64,
    pub mask_fraction: f64,
    pub noise: f64,
    pub ideal_focal_phase: f64,
    pub amplitude: Option<f64>,
}

impl Scenario {
    /// Parses TOML text. `base_dir` resolves relative paths.
    pub fn from_toml(text: &str, base_dir: Option<&Path>) -> Result<Self> {
        let mut s: Scenario = toml::from_str(text).map_err(|e| HasError::invalid("scenario", one_line(&e.to_string())))?;
        s.base_dir = base_dir.map(Path::to_path_buf);
        Ok(s)
    }

    /// Parses JSON text with the same keys.
    pub fn from_json(text: &str, base_dir: Option<&Path>) -> Result<Self> {
        let mut s: Scenario = serde_json::from_str(text).map_err(|e| HasError::invalid("scenario", one_line(&e.to_string())))?;
        s.base_dir = base_dir.map(Path::to_path_buf);
        Ok(s)
    }

    /// Reads a TOML file.
    pub fn load(path: &Path) -> Result<Self> {
        let p = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => HasError::FileNotFound { path: p.clone() },
            _ => HasError::BadFile { path: p.clone(), reason: e.to_string() },
        })?;
        let mut s: Scenario = toml::from_str(&text).map_err(|e| HasError::BadFile { path: p.clone(), reason: one_line(&e.to_string()) })?;
        s.base_dir = path.parent().map(Path::to_path_buf);
        Ok(s)
    }

    /// The scenario with every default written out (the medium included), as TOML.
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(&self.explicit()).map_err(|e| HasError::invalid("scenario", e.to_string()))
    }

    /// The scenario with every default written out, as JSON.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string(&self.explicit()).map_err(|e| HasError::invalid("scenario", e.to_string()))
    }

    fn explicit(&self) -> Scenario {
        let mut s = self.clone();
        if s.materials.is_none() && s.regions.is_none() {
            let (m, b, r) = default_medium();
            s.materials = Some(m);
            s.medium = Some(s.medium.unwrap_or(b));
            s.regions = Some(r);
        }
        if s.mr.center_mm.is_none() {
            s.mr.center_mm = Some(s.focus.position_mm);
        }
        s
    }

    /// Validates every value and converts to SI objects.
    pub fn resolve(&self) -> Result<Resolved> {
        let f = self.frequency_hz;
        require_positive("frequency_hz", f)?;
        require_positive("acoustic_power_w", self.acoustic_power_w)?;
        let focus = mm3(self.focus.position_mm, "focus.position_mm")?;
        let medium = self.medium_si()?;
        let transducer = self.transducer_si()?;
        let mr = MrGeometry {
            plane: MrPlane::parse(&self.mr.plane)?,
            center: mm3(self.mr.center_mm.unwrap_or(self.focus.position_mm), "mr.center_mm")?,
            fov: [self.mr.fov_mm[0] * 1e-3, self.mr.fov_mm[1] * 1e-3],
            matrix: self.mr.matrix,
            slice_thickness: self.mr.slice_thickness_mm * 1e-3,
        };
        mr.validate()?;
        let a = &self.arfi;
        require_non_negative("arfi.broadening_width_mm", a.broadening_width_mm)?;
        require_non_negative("arfi.noise_rad", a.noise_rad)?;
        require_positive("arfi.ideal_focal_phase_rad", a.ideal_focal_phase_rad)?;
        if !(a.mask_fraction.is_finite() && a.mask_fraction > 0.0 && a.mask_fraction < 1.0) {
            return Err(HasError::invalid("arfi.mask_fraction", format!("must lie in (0, 1), got {}", a.mask_fraction)));
        }
        if let Some(v) = a.amplitude_rad_m3_per_n {
            require_positive("arfi.amplitude_rad_m3_per_n", v)?;
        }
        for (name, v) in [
            ("grid.spacing_mm", self.grid.spacing_mm),
            ("grid.step_mm", self.grid.step_mm),
            ("grid.lateral_size_mm", self.grid.lateral_size_mm),
            ("grid.z_max_mm", self.grid.z_max_mm),
        ] {
            if let Some(v) = v {
                require_positive(name, v)?;
            }
        }
        if let Some(v) = self.grid.sponge_width_mm {
            require_non_negative("grid.sponge_width_mm", v)?;
        }
        self.grid.interface_model()?;
        Ok(Resolved {
            name: self.name.clone(),
            frequency: f,
            acoustic_power: self.acoustic_power_w,
            transducer,
            focus,
            medium,
            grid: self.grid.clone(),
            mr,
            broadening_width: a.broadening_width_mm * 1e-3,
            mask_fraction: a.mask_fraction,
            noise: a.noise_rad,
            ideal_focal_phase: a.ideal_focal_phase_rad,
            amplitude: a.amplitude_rad_m3_per_n,
        })
    }

    fn medium_si(&self) -> Result<Medium> {
        let (dm, db, dr) = default_medium();
        let custom = self.materials.is_some() || self.regions.is_some();
        let materials = if custom { self.materials.clone().unwrap_or_default() } else { dm };
        let regions = if custom { self.regions.clone().unwrap_or_default() } else { dr };
        if materials.is_empty() {
            return Err(HasError::invalid("material", "a scenario with [[region]] must also name its [[material]]s"));
        }
        let mut mats = Vec::with_capacity(materials.len());
        for (i, m) in materials.iter().enumerate() {
            if materials[..i].iter().any(|o| o.name == m.name) {
                return Err(HasError::invalid("material.name", format!("'{}' is given twice", m.name)));
            }
            let mut mat = Material {
                name: m.name.clone(),
                sound_speed: m.sound_speed_m_s,
                density: m.density_kg_m3,
                attenuation_db_cm_mhz: m.attenuation_db_cm_mhz,
                attenuation_power: m.attenuation_power,
            };
            mat.validate()?;
            mat.name = m.name.clone();
            mats.push(mat);
        }
        let index = |name: &str, key: &str| {
            mats.iter().position(|m| m.name == name).ok_or_else(|| HasError::invalid(key, format!("names no material: '{name}'")))
        };
        let background = match (&self.medium, custom) {
            (Some(m), _) => index(&m.background, "medium.background")?,
            (None, false) => index(&db.background, "medium.background")?,
            (None, true) => mats.iter().position(|m| m.name == "water").unwrap_or(0),
        };
        let mut regs = Vec::with_capacity(regions.len());
        for (i, r) in regions.iter().enumerate() {
            let key = format!("region[{i}]");
            let material = index(&r.material, &format!("{key}.material"))?;
            let (z_min, z_max) = (r.z_min_mm * 1e-3, r.z_max_mm * 1e-3);
            let shape = match r.shape.as_str() {
                "cylinder" => {
                    let radius = r.radius_mm.ok_or_else(|| HasError::invalid(format!("{key}.radius_mm"), "is required for a cylinder"))?;
                    let c = r.center_mm.unwrap_or([0.0, 0.0]);
                    Shape::Cylinder { radius: radius * 1e-3, z_min, z_max, center: [c[0] * 1e-3, c[1] * 1e-3] }
                }
                "slab" => {
                    if r.radius_mm.is_some() || r.center_mm.is_some() {
                        return Err(HasError::invalid(key, "a slab takes no radius_mm or center_mm"));
                    }
                    Shape::Slab { z_min, z_max }
                }
                s => return Err(HasError::invalid(format!("{key}.shape"), format!("must be \"cylinder\" or \"slab\", got \"{s}\""))),
            };
            regs.push(Region { material, shape });
        }
        let m = Medium { materials: mats, background, regions: regs, voxels: None };
        m.validate()?;
        Ok(m)
    }

    fn transducer_si(&self) -> Result<Transducer> {
        let t = &self.transducer;
        let given = |name: &str, v: bool| (name.to_string(), v);
        let fields = [
            given("elements_per_side", t.elements_per_side.is_some()),
            given("pitch_mm", t.pitch_mm.is_some()),
            given("element_size_mm", t.element_size_mm.is_some()),
            given("quadrant_gap_mm", t.quadrant_gap_mm.is_some()),
            given("radius_of_curvature_mm", t.radius_of_curvature_mm.is_some()),
            given("aperture_diameter_mm", t.aperture_diameter_mm.is_some()),
            given("elements", t.elements.is_some()),
            given("file", t.file.is_some()),
            given("element_shape", t.element_shape.is_some()),
        ];
        let allowed: &[&str] = match t.kind.as_str() {
            "planar-quadrants" => &["elements_per_side", "pitch_mm", "element_size_mm", "quadrant_gap_mm"],
            "bowl" => &["radius_of_curvature_mm", "aperture_diameter_mm", "elements", "element_size_mm"],
            "elements" => &["file", "element_shape"],
            k => {
                return Err(HasError::invalid(
                    "transducer.kind",
                    format!("must be \"planar-quadrants\", \"bowl\" or \"elements\", got \"{k}\""),
                ))
            }
        };
        if let Some((name, _)) = fields.iter().find(|(n, g)| *g && !allowed.contains(&n.as_str())) {
            return Err(HasError::invalid(format!("transducer.{name}"), format!("is not a key of kind \"{}\"", t.kind)));
        }
        match t.kind.as_str() {
            "planar-quadrants" => Transducer::planar_quadrants(
                t.elements_per_side.unwrap_or(16),
                t.pitch_mm.unwrap_or(2.5) * 1e-3,
                t.element_size_mm.unwrap_or(2.3) * 1e-3,
                t.quadrant_gap_mm.unwrap_or(1.0) * 1e-3,
            ),
            "bowl" => {
                let r = t
                    .radius_of_curvature_mm
                    .ok_or_else(|| HasError::invalid("transducer.radius_of_curvature_mm", "is required for a bowl"))?
                    * 1e-3;
                let a =
                    t.aperture_diameter_mm.ok_or_else(|| HasError::invalid("transducer.aperture_diameter_mm", "is required for a bowl"))?
                        * 1e-3;
                match t.elements {
                    None if t.element_size_mm.is_some() => {
                        Err(HasError::invalid("transducer.element_size_mm", "needs transducer.elements"))
                    }
                    None => Transducer::bowl(r, a),
                    Some(n) => {
                        // Default element diameter: 80 % of the centre spacing of equal-area cells.
                        let cap = Transducer::bowl(r, a)?.area();
                        let size = t.element_size_mm.map(|s| s * 1e-3).unwrap_or(0.8 * (cap / n.max(1) as f64).sqrt());
                        Transducer::bowl_elements(r, a, n, size)
                    }
                }
            }
            _ => {
                let file = t.file.as_deref().ok_or_else(|| HasError::invalid("transducer.file", "is required for kind \"elements\""))?;
                let path = match &self.base_dir {
                    Some(b) if Path::new(file).is_relative() => b.join(file),
                    _ => PathBuf::from(file),
                };
                let shape = match t.element_shape.as_deref().unwrap_or("square") {
                    "square" => ElementShape::Square,
                    "disc" => ElementShape::Disc,
                    s => return Err(HasError::invalid("transducer.element_shape", format!("must be \"square\" or \"disc\", got \"{s}\""))),
                };
                let p = path.display().to_string();
                let text = std::fs::read_to_string(&path).map_err(|e| match e.kind() {
                    std::io::ErrorKind::NotFound => HasError::FileNotFound { path: p.clone() },
                    _ => HasError::BadFile { path: p.clone(), reason: e.to_string() },
                })?;
                Transducer::from_csv(&text, &p, shape)
            }
        }
    }
}

fn mm3(v: [f64; 3], name: &str) -> Result<[f64; 3]> {
    if v.iter().all(|x| x.is_finite()) {
        Ok([v[0] * 1e-3, v[1] * 1e-3, v[2] * 1e-3])
    } else {
        Err(HasError::invalid(name, "must be finite"))
    }
}

/// Parser messages span several lines (with a source excerpt); keep one line.
fn one_line(s: &str) -> String {
    let parts: Vec<&str> =
        s.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('|') && !l.chars().all(|c| c == '^' || c == ' ')).collect();
    parts.join(": ").replace("TOML parse error at ", "")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_round_trips_through_toml() {
        let s = Scenario::default();
        let text = s.to_toml().unwrap();
        let back = Scenario::from_toml(&text, None).unwrap();
        assert_eq!(back.to_toml().unwrap(), text);
        let r = back.resolve().unwrap();
        assert_eq!(r.transducer.elements.len(), 1024);
        assert_eq!(r.medium.materials.len(), 2);
        assert!((r.medium.properties_at(0.0, 0.0, 0.085, 550e3).sound_speed - 1533.0).abs() < 1e-12);
    }

    #[test]
    fn unknown_keys_are_errors() {
        let e = Scenario::from_toml("frequency_hz = 5e5\nfrequncy = 3\n", None).unwrap_err();
        assert!(e.to_string().contains("frequncy"), "{e}");
        let e = Scenario::from_toml("[transducer]\nkind = \"bowl\"\npitch_mm = 2\n", None).unwrap().resolve().unwrap_err();
        assert!(e.to_string().contains("pitch_mm"), "{e}");
    }

    #[test]
    fn negative_sound_speed_is_named() {
        let t = "[[material]]\nname = \"w\"\nsound_speed_m_s = -1500\ndensity_kg_m3 = 1000\n";
        let e = Scenario::from_toml(t, None).unwrap().resolve().unwrap_err();
        assert!(e.to_string().contains("sound_speed_m_s"), "{e}");
    }
}
