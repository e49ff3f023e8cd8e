//! Scenario files: TOML (or JSON) with the paper's phantom experiment as defaults.
//!
//! Every key is optional; parsing rejects unknown keys. [`Scenario`] holds the file's values in
//! file units (mm, Hz, dB/cm/MHz: the unit is in each key's name) and reads and writes them; a
//! file that names any `[[material]]` or `[[region]]` replaces the default medium whole.
//! [`Scenario::resolve`] validates them and turns them into SI objects ([`Resolved`]).

mod ct;
mod outline;
mod resolve;

pub use ct::CtSpec;
pub use outline::Outline;
pub use resolve::Resolved;

use crate::error::{HasError, Result};
use crate::physics::propagation::{InterfaceModel, Screen};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A scenario as written in a file (units in the key names).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name of the scenario (default `"vyas2014-phantom"`).
    #[serde(default = "d::name")]
    pub name: String,
    /// Driving frequency, Hz (default 550 kHz).
    #[serde(default = "d::frequency")]
    pub frequency_hz: f64,
    /// Total acoustic power (W); every element face gets the same pressure amplitude.
    #[serde(default = "d::power")]
    pub acoustic_power_w: f64,
    /// `[transducer]`: the array (default: the paper's planar quadrant array).
    #[serde(default)]
    pub transducer: TransducerSpec,
    /// `[focus]`: the steering target.
    #[serde(default)]
    pub focus: FocusSpec,
    /// `[[material]]`: the materials of a custom medium. Naming any material or region replaces
    /// the default medium (water, then the phantom cylinder from z = 40 mm) whole.
    #[serde(default, rename = "material", skip_serializing_if = "Option::is_none")]
    pub materials: Option<Vec<MaterialSpec>>,
    /// `[medium]`: which material fills the space outside every region.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub medium: Option<MediumSpec>,
    /// `[[region]]`: where the materials lie; later regions override earlier ones.
    #[serde(default, rename = "region", skip_serializing_if = "Option::is_none")]
    pub regions: Option<Vec<RegionSpec>>,
    /// `[ct]`: a CT of the head in the medium. Without `[[material]]`s the rest of the medium is
    /// water (not the paper's phantom).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ct: Option<CtSpec>,
    /// `[grid]`: sampling and propagation options.
    #[serde(default)]
    pub grid: GridSpec,
    /// `[mr]`: the MR-ARFI image geometry.
    #[serde(default)]
    pub mr: MrSpec,
    /// `[arfi]`: broadening, focal-zone mask, noise and amplitude of the ARFI phase image.
    #[serde(default)]
    pub arfi: ArfiSpec,
    /// Folder that relative paths (the elements CSV) are resolved against.
    #[serde(skip)]
    pub base_dir: Option<PathBuf>,
}

/// `[transducer]`: `kind` = `"planar-quadrants"` | `"bowl"` | `"hemisphere"` | `"elements"`;
/// only the keys of that kind may be given.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransducerSpec {
    /// `"planar-quadrants"` (default), `"bowl"`, `"hemisphere"` or `"elements"`.
    #[serde(default = "d::kind")]
    pub kind: String,
    /// Planar quadrants: elements per side of each square quadrant (default 16).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elements_per_side: Option<usize>,
    /// Planar quadrants: centre-to-centre element spacing, mm (default 2.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pitch_mm: Option<f64>,
    /// Side of a square planar element, mm (default 2.3); or diameter of a bowl's or hemisphere's
    /// disc elements, mm (default: 80 % of the centre spacing of equal-area cells on the cap).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub element_size_mm: Option<f64>,
    /// Planar quadrants: extra spacing between adjacent quadrants, mm (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quadrant_gap_mm: Option<f64>,
    /// Bowl (required) or hemisphere (default 150): radius of curvature R, mm; apex at the
    /// origin, centre at (0, 0, R).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_of_curvature_mm: Option<f64>,
    /// Bowl: diameter of the cap's rim, mm (required).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aperture_diameter_mm: Option<f64>,
    /// Hemisphere: elements from the apex out to this polar angle, degrees (0 to 90; default 60,
    /// the part of a 150 mm hemisphere a march along z reaches in front of a head).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polar_angle_max_deg: Option<f64>,
    /// Bowl: number of flat disc elements on the cap (absent: one continuous cap); hemisphere:
    /// number of elements (default 1024).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elements: Option<usize>,
    /// Elements: CSV with header `x_mm,y_mm,z_mm,nx,ny,nz,size_mm`, one row per element in
    /// element order; a relative path is taken from the scenario file's folder.
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
            polar_angle_max_deg: None,
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
    /// Steering target in the transducer frame, mm (default (0, 0, 85)); the array is steered
    /// geometrically (straight-line time of flight).
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
    /// Name that `[medium] background` and `[[region]] material` refer to.
    pub name: String,
    /// Sound speed c, m/s.
    pub sound_speed_m_s: f64,
    /// Density rho, kg/m³.
    pub density_kg_m3: f64,
    /// Attenuation a0 in `a0·(f / 1 MHz)^y` dB/cm, all taken as absorption (default 0).
    #[serde(default)]
    pub attenuation_db_cm_mhz: f64,
    /// Exponent y of `a0·f^y` (default 1: linear in frequency).
    #[serde(default = "d::one")]
    pub attenuation_power: f64,
    /// A solid's shear-wave speed c_s, m/s (absent or 0: a fluid); below √3/2 of
    /// `sound_speed_m_s`. The march carries the shear wave where the solid's faces lie on its
    /// planes (material regions) and compressional waves alone through a CT's faces (it says so);
    /// `arfi field --engine fdtd` carries both everywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shear_sound_speed_m_s: Option<f64>,
    /// The shear wave's attenuation a0_s in `a0_s·(f / 1 MHz)^y` dB/cm (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shear_attenuation_db_cm_mhz: Option<f64>,
    /// Whether the material gives MR signal (default: false for bone-like materials, sound speed
    /// from 1800 m/s on; true otherwise). Pixels without signal are absent (NaN) from MR-ARFI images.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mr_signal: Option<bool>,
    /// Displacement per unit radiation force relative to soft tissue (default: 0 for bone-like
    /// materials, 1 otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub displacement_scale: Option<f64>,
}

/// `[medium]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MediumSpec {
    /// Material outside every region (absent: `"water"` if named, else the first material).
    pub background: String,
}

/// `[[region]]`: `shape` = `"cylinder"` | `"slab"`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    /// Name of the material filling the region.
    pub material: String,
    /// `"cylinder"` (about an axis parallel to z) or `"slab"` (all x, y).
    pub shape: String,
    /// Cylinder: radius, mm (required).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_mm: Option<f64>,
    /// Lower bound along z, mm.
    pub z_min_mm: f64,
    /// Upper bound along z, mm.
    pub z_max_mm: f64,
    /// Cylinder: axis position (x, y), mm (default (0, 0), the beam axis).
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
    /// The direction the phase screen gives the waves in each slab: `"oblique"` (default: along
    /// the line to the focus, so that a wave crossing soft tissue or bone at an angle gets the
    /// phase and absorption of its path) or `"vertical"` (the original HAS screen, exact along z
    /// only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub screen: Option<String>,
}

impl GridSpec {
    /// The screen named by `screen` (default: oblique), its rays converging on `focus` (m).
    pub fn screen_model(&self, focus: [f64; 3]) -> Result<Screen> {
        match self.screen.as_deref() {
            None | Some("oblique") => Ok(Screen::Oblique { toward: focus }),
            Some("vertical") => Ok(Screen::Vertical),
            Some(name) => Err(HasError::invalid("grid.screen", format!("must be \"oblique\" or \"vertical\", got \"{name}\""))),
        }
    }

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
    /// Slice orientation: `"xy"` (default, perpendicular to the beam), `"xz"` or `"yz"`
    /// (containing the beam axis).
    #[serde(default = "d::plane")]
    pub plane: String,
    /// Centre of the slice (default: the focus).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center_mm: Option<[f64; 3]>,
    /// Field of view along the image axes, mm (default 180 x 135).
    #[serde(default = "d::fov")]
    pub fov_mm: [f64; 2],
    /// Pixels along the image axes (default 128 x 96).
    #[serde(default = "d::matrix")]
    pub matrix: [usize; 2],
    /// Slice thickness, mm (default 3); the force is averaged over it.
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
    /// Width W of the Gaussian broadening filter `exp(-(x²+y²)/(2W²))` applied to the force map
    /// (paper Eq. 2), mm (default 2.7).
    #[serde(default = "d::width")]
    pub broadening_width_mm: f64,
    /// Focal-zone level (paper Eq. 4): fits use the pixels above this fraction of each image's
    /// maximum that are connected to it (default 0.05).
    #[serde(default = "d::mask")]
    pub mask_fraction: f64,
    /// Radius (mm, in the image plane) around the target within which an image's focal maximum
    /// is sought: the focal ARFI, the seed of the focal zone and the ideal amplitude (default 20).
    /// Keeps the skull, scalp or a far side lobe from standing in for the focus.
    #[serde(default = "d::focal_search")]
    pub focal_search_radius_mm: f64,
    /// Standard deviation of the Gaussian noise on the ARFI phase image, rad (default 0.02).
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
            focal_search_radius_mm: d::focal_search(),
            noise_rad: d::noise(),
            ideal_focal_phase_rad: d::focal_phase(),
            amplitude_rad_m3_per_n: None,
        }
    }
}

/// Defaults: the paper's phantom experiment (550 kHz, 70 W, focus at 85 mm; MR slice
/// perpendicular to the beam through the focus, 180 x 135 mm, 128 x 96 pixels, 3 mm thick;
/// broadening W = 2.7 mm scaled to an ideal focal phase of 0.6 rad; noise 0.02 rad).
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
    pub fn focal_search() -> f64 {
        20.0
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
            ct: None,
            grid: GridSpec::default(),
            mr: MrSpec::default(),
            arfi: ArfiSpec::default(),
            base_dir: None,
        }
    }
}

/// Water: 1500 m/s, 1000 kg/m³, no attenuation.
fn water() -> MaterialSpec {
    MaterialSpec {
        name: "water".into(),
        sound_speed_m_s: 1500.0,
        density_kg_m3: 1000.0,
        attenuation_db_cm_mhz: 0.0,
        attenuation_power: 1.0,
        shear_sound_speed_m_s: None,
        shear_attenuation_db_cm_mhz: None,
        mr_signal: None,
        displacement_scale: None,
    }
}

/// The default medium, the paper's phantom experiment: water below z = 40 mm, and above it the
/// CIRS phantom (1533 m/s, 1040 kg/m³, 0.46 dB/cm/MHz) as a cylinder of radius 60 mm about the
/// beam axis up to z = 160 mm.
fn phantom_medium() -> (Vec<MaterialSpec>, MediumSpec, Vec<RegionSpec>) {
    let materials = vec![
        water(),
        MaterialSpec {
            name: "phantom".into(),
            sound_speed_m_s: 1533.0,
            density_kg_m3: 1040.0,
            attenuation_db_cm_mhz: 0.46,
            attenuation_power: 1.0,
            shear_sound_speed_m_s: None,
            shear_attenuation_db_cm_mhz: None,
            mr_signal: None,
            displacement_scale: None,
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

impl Scenario {
    /// The head of this `[ct]` scenario with the CT's bone (`without_bone = false`) driven with
    /// the reference steering (`steer_without_bone = true`): the skull a CT-based prediction
    /// marches, steered as the estimation's model (`without_bone = true`) is. An error for a
    /// scenario without `[ct]`.
    pub fn with_ct_bone(&self) -> Result<Scenario> {
        let Some(ct) = &self.ct else {
            return Err(HasError::invalid(
                format!("scenario {:?}", self.name),
                "has no [ct]: a model with the CT's bone needs a CT of the head",
            ));
        };
        let ct = CtSpec { without_bone: Some(false), steer_without_bone: Some(true), ..ct.clone() };
        Ok(Scenario { ct: Some(ct), ..self.clone() })
    }

    /// The medium when the file names no material or region: the paper's phantom experiment, or
    /// water around a CT.
    fn default_medium(&self) -> (Vec<MaterialSpec>, MediumSpec, Vec<RegionSpec>) {
        match self.ct {
            Some(_) => (vec![water()], MediumSpec { background: "water".into() }, vec![]),
            None => phantom_medium(),
        }
    }

    /// A file named in the scenario: relative paths are taken from the scenario file's folder.
    fn file_path(&self, file: &str) -> PathBuf {
        match &self.base_dir {
            Some(b) if Path::new(file).is_relative() => b.join(file),
            _ => PathBuf::from(file),
        }
    }

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
        let text = std::fs::read_to_string(path).map_err(|e| HasError::reading(&p, &e))?;
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
            let (m, b, r) = s.default_medium();
            s.materials = Some(m);
            s.medium = Some(s.medium.unwrap_or(b));
            s.regions = Some(r);
        }
        if s.mr.center_mm.is_none() {
            s.mr.center_mm = Some(s.focus.position_mm);
        }
        s
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
}
