//! `[ct]`: a CT of the head as part of the medium, and its conversion to acoustic properties.

use crate::error::{HasError, Result};
use crate::nifti;
use crate::physics::ct::{BoneModel, BoneShear, CtMedium, HuConversion, Porosity};
use crate::physics::medium::Material;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `[ct]`: the CT volume, where it lies, and how its Hounsfield units become sound speed, density
/// and attenuation (see [`crate::physics::ct`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CtSpec {
    /// NIfTI-1 volume (`.nii` or `.nii.gz`) in Hounsfield units; a relative path is taken from
    /// the scenario file's folder.
    pub file: String,
    /// Rigid 4x4 transform from the patient frame (DICOM LPS, mm: the NIfTI's RAS+ with x and y
    /// negated) to the transducer frame (mm), as `arfi dicom --transform` takes it (default: the
    /// identity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub patient_to_transducer_mm: Option<[[f64; 4]; 4]>,
    /// `"aubry2003"` (porosity; default) or `"schneider-mast"`.
    #[serde(default = "aubry")]
    pub conversion: String,
    /// Below this HU a voxel is the coupling medium: the scenario's own medium applies (default
    /// −500).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coupling_below_hu: Option<f64>,
    /// From this HU on a voxel is bone (default 300).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_from_hu: Option<f64>,
    /// Name of the `[[material]]` for soft tissue between the thresholds (default: brain,
    /// 1546 m/s, 1040 kg/m³, 0.6 dB/cm/MHz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub soft_tissue: Option<String>,
    /// Porosity model: HU of bone without pores (default 2000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hu_max: Option<f64>,
    /// Porosity model: c of dense bone, m/s (default 2900).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_sound_speed_m_s: Option<f64>,
    /// Porosity model: ρ of dense bone, kg/m³ (default 2200).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_density_kg_m3: Option<f64>,
    /// Porosity model: c of the pores' water, m/s (default 1500).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub water_sound_speed_m_s: Option<f64>,
    /// Porosity model: ρ of the pores' water, kg/m³ (default 1000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub water_density_kg_m3: Option<f64>,
    /// Porosity model: attenuation of dense bone, dB/cm/MHz (default 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_attenuation_min_db_cm_mhz: Option<f64>,
    /// Porosity model: attenuation of fully porous bone, dB/cm/MHz (default 80).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_attenuation_max_db_cm_mhz: Option<f64>,
    /// Porosity model: exponent β of the attenuation law (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub porosity_exponent: Option<f64>,
    /// Shear-wave speed of dense bone, m/s (absent or 0: fluid bone, the default); a voxel of
    /// porosity ψ gets `(1 − ψ)` of it. Cortical bone: about 1300-1750 m/s (Pichardo et al.,
    /// Phys Med Biol 62:6938, 2017). Carried by `arfi field --engine fdtd`, not by the march.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_shear_sound_speed_m_s: Option<f64>,
    /// Shear-wave attenuation of bone, dB/cm/MHz (linear in frequency; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bone_shear_attenuation_db_cm_mhz: Option<f64>,
    /// Read the bone as soft tissue (default false): the head without its skull, the model of
    /// an MR-ARFI estimate whose prior comes from `arfi predict` (that prediction's reference).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub without_bone: Option<bool>,
    /// Steer with the straight-ray times of flight of the head without its skull (default
    /// false: through the CT's bone): the reference steering of `arfi predict`, the one the
    /// estimation's model (`without_bone = true`) drives. For a scenario that plays the patient
    /// whose MR-ARFI images an estimate with a CT prior fits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub steer_without_bone: Option<bool>,
}

fn aubry() -> String {
    "aubry2003".into()
}

impl CtSpec {
    /// The conversion: the named one with the constants given here.
    pub fn conversion(&self, materials: &[Material]) -> Result<HuConversion> {
        let mut c = HuConversion::named(&self.conversion)?;
        if let Some(v) = self.coupling_below_hu {
            c.coupling_below_hu = v;
        }
        if let Some(v) = self.bone_from_hu {
            c.bone_from_hu = v;
        }
        if let Some(name) = &self.soft_tissue {
            c.soft_tissue = materials
                .iter()
                .find(|m| &m.name == name)
                .cloned()
                .ok_or_else(|| HasError::invalid("ct.soft_tissue", format!("names no [[material]]: '{name}'")))?;
        }
        let constants = [
            ("hu_max", self.hu_max),
            ("bone_sound_speed_m_s", self.bone_sound_speed_m_s),
            ("bone_density_kg_m3", self.bone_density_kg_m3),
            ("water_sound_speed_m_s", self.water_sound_speed_m_s),
            ("water_density_kg_m3", self.water_density_kg_m3),
            ("bone_attenuation_min_db_cm_mhz", self.bone_attenuation_min_db_cm_mhz),
            ("bone_attenuation_max_db_cm_mhz", self.bone_attenuation_max_db_cm_mhz),
            ("porosity_exponent", self.porosity_exponent),
        ];
        match &mut c.bone {
            BoneModel::Porosity(p) => {
                let d = Porosity::default();
                let pick = |v: Option<f64>, default: f64| v.unwrap_or(default);
                *p = Porosity {
                    hu_max: pick(self.hu_max, d.hu_max),
                    bone_sound_speed: pick(self.bone_sound_speed_m_s, d.bone_sound_speed),
                    bone_density: pick(self.bone_density_kg_m3, d.bone_density),
                    water_sound_speed: pick(self.water_sound_speed_m_s, d.water_sound_speed),
                    water_density: pick(self.water_density_kg_m3, d.water_density),
                    attenuation_min: pick(self.bone_attenuation_min_db_cm_mhz, d.attenuation_min),
                    attenuation_max: pick(self.bone_attenuation_max_db_cm_mhz, d.attenuation_max),
                    exponent: pick(self.porosity_exponent, d.exponent),
                };
            }
            BoneModel::SchneiderMast => {
                if let Some((name, _)) = constants.iter().find(|(_, v)| v.is_some()) {
                    return Err(HasError::invalid(
                        format!("ct.{name}"),
                        "is a constant of the porosity model (conversion = \"aubry2003\")",
                    ));
                }
            }
        }
        c.bone_shear = BoneShear {
            sound_speed: self.bone_shear_sound_speed_m_s.unwrap_or(0.0),
            attenuation_db_cm_mhz: self.bone_shear_attenuation_db_cm_mhz.unwrap_or(0.0),
        };
        c.validate()?;
        Ok(if self.without_bone == Some(true) { c.without_bone() } else { c })
    }

    /// Reads the volume from `path` (the scenario's `file`, resolved) and places it in the
    /// transducer frame.
    pub fn resolve(&self, path: &Path, materials: &[Material]) -> Result<CtMedium> {
        let conversion = self.conversion(materials)?;
        let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
        let volume = nifti::read(path)?;
        CtMedium::new(volume, self.patient_to_transducer_mm.unwrap_or(identity), conversion, &path.display().to_string())
    }
}
