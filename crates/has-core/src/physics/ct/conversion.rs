//! Hounsfield units to acoustic properties: the published skull conversions.
//!
//! A CT voxel is one of three classes by its value H (HU):
//! - `H < coupling_below_hu` (default −500: air around the head in the scanner) is the coupling
//!   medium of the treatment, so the scenario's own medium (its regions and background, e.g.
//!   water) applies there;
//! - `coupling_below_hu ≤ H < bone_from_hu` (default 300) is soft tissue (scalp, brain): one
//!   material;
//! - `H ≥ bone_from_hu` is bone, converted by the chosen [`BoneModel`].
//!
//! As in the planning tools that use these relations, the conversion acts on bone only; soft tissue
//! and coupling are given materials. In MR-ARFI images bone is dark and still, soft tissue has its
//! material's response, and coupling voxels the scenario's ([`HuConversion::mr_response`]).

use crate::error::{require_in_range, require_non_negative, require_positive, HasError, Result};
use crate::physics::material::{attenuation_np_m, require_shear, Material, Properties};
use crate::physics::tissue::MrResponse;

/// Hounsfield units a CT may hold: below −1100 or above 4000 a value is not a calibrated HU of
/// tissue (air is −1000, the densest cortical bone about 3000); metal implants are out of scope.
pub const HU_RANGE: (f64, f64) = (-1100.0, 4000.0);

/// How bone voxels' HU become sound speed, density and attenuation.
#[derive(Debug, Clone, PartialEq)]
pub enum BoneModel {
    /// Aubry et al., "Experimental demonstration of noninvasive transskull adaptive focusing based
    /// on prior computed tomography scans", J Acoust Soc Am 113(1):84–93 (2003): the porosity
    /// `ψ = 1 − clamp(H / hu_max, 0, 1)` mixes water and dense bone,
    /// `ρ = ψ·ρ_w + (1 − ψ)·ρ_b`, `c = c_w + (c_b − c_w)·(1 − ψ)`, and the attenuation grows with
    /// the porosity (scattering in the diploë): `a = a_min + (a_max − a_min)·ψ^β`.
    Porosity(Porosity),
    /// Density from Schneider, Bortfeld & Schlegel, Phys Med Biol 41:111–124 (1996), by the
    /// piecewise-linear fit k-Wave's `hounsfield2density` uses, and sound speed from Mast's
    /// empirical relation, Acoust Res Lett Online 1(2):37–42 (2000), `c = 1.33·ρ + 167` m/s (as in
    /// k-Wave–based planning pipelines); both are floored at water (1000 kg/m³, 1500 m/s).
    /// These relations give no attenuation: it follows the porosity law of [`Porosity`]'s
    /// defaults.
    SchneiderMast,
}

/// The constants of the porosity model (see [`BoneModel::Porosity`]); the defaults are the values
/// published with it.
#[derive(Debug, Clone, PartialEq)]
pub struct Porosity {
    /// HU of bone with no porosity (ψ = 0): Aubry et al. normalised by their scan's maximum; the
    /// default, 2000 HU, is dense cortical bone on a clinical scanner.
    pub hu_max: f64,
    /// c_w, m/s (1500).
    pub water_sound_speed: f64,
    /// ρ_w, kg/m³ (1000).
    pub water_density: f64,
    /// c_b, m/s (2900).
    pub bone_sound_speed: f64,
    /// ρ_b, kg/m³ (2200).
    pub bone_density: f64,
    /// a_min (dense bone), dB/cm/MHz (0.2 dB/mm/MHz = 2).
    pub attenuation_min: f64,
    /// a_max (porous bone), dB/cm/MHz (8 dB/mm/MHz = 80).
    pub attenuation_max: f64,
    /// β (0.5).
    pub exponent: f64,
}

impl Default for Porosity {
    fn default() -> Self {
        Porosity {
            hu_max: 2000.0,
            water_sound_speed: 1500.0,
            water_density: 1000.0,
            bone_sound_speed: 2900.0,
            bone_density: 2200.0,
            attenuation_min: 2.0,
            attenuation_max: 80.0,
            exponent: 0.5,
        }
    }
}

impl Porosity {
    /// ψ for a bone voxel of `hu`.
    fn porosity(&self, hu: f64) -> f64 {
        1.0 - (hu / self.hu_max).clamp(0.0, 1.0)
    }

    /// The attenuation a0 (dB/cm/MHz) at porosity ψ.
    fn attenuation(&self, psi: f64) -> f64 {
        self.attenuation_min + (self.attenuation_max - self.attenuation_min) * psi.powf(self.exponent)
    }

    fn validate(&self) -> Result<()> {
        let k = |n: &str| format!("ct.{n}");
        require_positive(&k("hu_max"), self.hu_max)?;
        for (n, v) in [
            ("water_sound_speed_m_s", self.water_sound_speed),
            ("water_density_kg_m3", self.water_density),
            ("bone_sound_speed_m_s", self.bone_sound_speed),
            ("bone_density_kg_m3", self.bone_density),
            ("porosity_exponent", self.exponent),
        ] {
            require_positive(&k(n), v)?;
        }
        require_non_negative(&k("bone_attenuation_min_db_cm_mhz"), self.attenuation_min)?;
        require_non_negative(&k("bone_attenuation_max_db_cm_mhz"), self.attenuation_max)?;
        Ok(())
    }
}

/// Bone density (kg/m³) of Schneider et al. 1996 by k-Wave's piecewise-linear fit, in terms of
/// `H + 1000`.
fn schneider_density(hu: f64) -> f64 {
    let h = hu + 1000.0;
    let rho = if h < 930.0 {
        1.025_793_065_681_423 * h - 5.680_404_011_488_714
    } else if h <= 1098.0 {
        0.908_270_969_126_4 * h + 103.615_145_784_713_9
    } else if h < 1260.0 {
        0.510_836_931_659_9 * h + 539.997_718_922_870_4
    } else {
        0.662_537_091_245_1 * h + 348.855_517_845_529_4
    };
    rho.max(1000.0)
}

/// The three classes of CT voxel (see the module docs).
enum HuClass {
    Coupling,
    Soft,
    Bone,
}

/// A conversion from HU to acoustic properties (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct HuConversion {
    /// Name as selected in scenario files (`"aubry2003"` or `"schneider-mast"`).
    pub name: String,
    /// The bone model.
    pub bone: BoneModel,
    /// Below this HU a voxel is the coupling medium (default −500).
    pub coupling_below_hu: f64,
    /// From this HU on a voxel is bone (default 300).
    pub bone_from_hu: f64,
    /// Whether bone voxels take the soft tissue's acoustic properties (the head without its
    /// skull, [`HuConversion::without_bone`]); they stay bone in MR images either way.
    pub bone_as_soft_tissue: bool,
    /// Soft tissue between the two thresholds (default: brain, 1546 m/s, 1040 kg/m³, 0.6
    /// dB/cm/MHz; Duck, Physical Properties of Tissue, 1990).
    pub soft_tissue: Material,
    /// Attenuation law for bone where the model gives none (Schneider–Mast).
    porosity_attenuation: Porosity,
    /// Shear in bone: the dense bone's shear speed c_s (m/s; 0: fluid bone, the default) and
    /// shear attenuation (dB/cm/MHz, linear in frequency). A voxel of porosity ψ gets
    /// `c_s·(1 − ψ)`: the shear modulus is carried by the solid frame, which pores filled with
    /// water (ψ = 1) do not have.
    pub bone_shear: BoneShear,
}

/// The dense bone's shear wave (see [`HuConversion::bone_shear`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BoneShear {
    /// c_s of dense bone, m/s (0: fluid bone).
    pub sound_speed: f64,
    /// a0_s, dB/cm/MHz.
    pub attenuation_db_cm_mhz: f64,
}

impl HuConversion {
    /// The conversions that can be selected by name: `"aubry2003"` (porosity) and
    /// `"schneider-mast"`.
    pub const NAMES: [&'static str; 2] = ["aubry2003", "schneider-mast"];

    /// The named conversion with its published constants and the default thresholds and soft
    /// tissue.
    pub fn named(name: &str) -> Result<Self> {
        let bone = match name {
            "aubry2003" => BoneModel::Porosity(Porosity::default()),
            "schneider-mast" => BoneModel::SchneiderMast,
            _ => {
                return Err(HasError::invalid(
                    "ct.conversion",
                    format!("must be one of {}, got \"{name}\"", Self::NAMES.map(|n| format!("\"{n}\"")).join(", ")),
                ))
            }
        };
        Ok(HuConversion {
            name: name.to_string(),
            bone,
            coupling_below_hu: -500.0,
            bone_from_hu: 300.0,
            bone_as_soft_tissue: false,
            soft_tissue: Material::new("brain", 1546.0, 1040.0, 0.6)?,
            porosity_attenuation: Porosity::default(),
            bone_shear: BoneShear::default(),
        })
    }

    /// Checks the thresholds (`bone_from_hu` may be infinite: no bone), the soft tissue and the
    /// bone constants.
    pub fn validate(&self) -> Result<()> {
        let (lo, hi) = HU_RANGE;
        require_in_range("ct.coupling_below_hu", self.coupling_below_hu, lo, hi, "calibrated HU")?;
        if self.bone_from_hu != f64::INFINITY {
            // (infinite: a CT read without bone)
            require_in_range("ct.bone_from_hu", self.bone_from_hu, lo, hi, "calibrated HU")?;
        }
        if self.bone_from_hu <= self.coupling_below_hu {
            return Err(HasError::invalid(
                "ct.bone_from_hu",
                format!("must lie above ct.coupling_below_hu ({}), got {}", self.coupling_below_hu, self.bone_from_hu),
            ));
        }
        self.soft_tissue.validate()?;
        if let BoneModel::Porosity(p) = &self.bone {
            p.validate()?;
        }
        // Against the dense bone's compressional speed, where c_s / c_p is largest.
        require_shear("ct.bone_shear_sound_speed_m_s", self.bone_shear.sound_speed, self.dense_bone_sound_speed())?;
        require_non_negative("ct.bone_shear_attenuation_db_cm_mhz", self.bone_shear.attenuation_db_cm_mhz)?;
        Ok(())
    }

    /// The properties of a voxel of `hu` at `frequency` (Hz); `None` for the coupling medium
    /// (the scenario's regions and background apply there). Bone attenuation is linear in
    /// frequency, as the published laws are; soft tissue follows its material's power law.
    pub fn properties(&self, hu: f64, frequency: f64) -> Option<Properties> {
        match self.class(hu) {
            HuClass::Coupling => return None,
            HuClass::Soft => return Some(self.soft_tissue.properties(frequency)),
            HuClass::Bone if self.bone_as_soft_tissue => return Some(self.soft_tissue.properties(frequency)),
            HuClass::Bone => {}
        }
        let (sound_speed, density, a0, psi) = match &self.bone {
            BoneModel::Porosity(p) => {
                let psi = p.porosity(hu);
                (
                    p.water_sound_speed + (p.bone_sound_speed - p.water_sound_speed) * (1.0 - psi),
                    psi * p.water_density + (1.0 - psi) * p.bone_density,
                    p.attenuation(psi),
                    psi,
                )
            }
            BoneModel::SchneiderMast => {
                let rho = schneider_density(hu);
                let law = &self.porosity_attenuation;
                let psi = law.porosity(hu);
                ((1.33 * rho + 167.0).max(1500.0), rho, law.attenuation(psi), psi)
            }
        };
        let shear = &self.bone_shear;
        let solid = shear.sound_speed > 0.0;
        Some(Properties {
            sound_speed,
            density,
            attenuation: attenuation_np_m(a0, 1.0, frequency),
            shear_sound_speed: if solid { shear.sound_speed * (1.0 - psi) } else { 0.0 },
            shear_attenuation: if solid { attenuation_np_m(shear.attenuation_db_cm_mhz, 1.0, frequency) } else { 0.0 },
        })
    }

    /// The compressional speed (m/s) of the densest bone the conversion distinguishes (no
    /// porosity), where the ratio of shear to compressional speed is largest.
    fn dense_bone_sound_speed(&self) -> f64 {
        match &self.bone {
            BoneModel::Porosity(p) => p.bone_sound_speed,
            BoneModel::SchneiderMast => (1.33 * schneider_density(self.porosity_attenuation.hu_max) + 167.0).max(1500.0),
        }
    }

    /// The same conversion with bone read as soft tissue: the head without its skull, the
    /// reference of a CT-based prediction.
    pub fn without_bone(&self) -> Self {
        HuConversion { bone_as_soft_tissue: true, ..self.clone() }
    }

    /// How a voxel of `hu` shows in MR-ARFI images; `None` for the coupling medium (the
    /// scenario's materials apply there). Bone is bone here also in [`HuConversion::without_bone`]:
    /// the model of the head without its skull images what a scanner images.
    pub fn mr_response(&self, hu: f64) -> Option<MrResponse> {
        match self.class(hu) {
            HuClass::Coupling => None,
            HuClass::Soft => Some(self.soft_tissue.mr),
            HuClass::Bone => Some(MrResponse::BONE),
        }
    }

    /// The name of the tissue a voxel of `hu` is: `"bone"`, the soft tissue's material name, or
    /// `None` for the coupling medium.
    pub fn tissue_name(&self, hu: f64) -> Option<&str> {
        match self.class(hu) {
            HuClass::Coupling => None,
            HuClass::Soft => Some(&self.soft_tissue.name),
            HuClass::Bone => Some("bone"),
        }
    }

    /// The class of a voxel of `hu` by the thresholds (see the module docs).
    fn class(&self, hu: f64) -> HuClass {
        if hu < self.coupling_below_hu {
            HuClass::Coupling
        } else if hu < self.bone_from_hu {
            HuClass::Soft
        } else {
            HuClass::Bone
        }
    }

    /// The lowest sound speed a voxel can get (sets the shortest wavelength).
    pub fn min_sound_speed(&self) -> f64 {
        let bone = if self.bone_from_hu.is_finite() && !self.bone_as_soft_tissue {
            self.properties(self.bone_from_hu, 1e6).map_or(f64::INFINITY, |p| p.sound_speed)
        } else {
            f64::INFINITY
        };
        bone.min(self.soft_tissue.sound_speed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::material::NP_PER_DB;

    /// c (m/s), ρ (kg/m³) and a0 (dB/cm/MHz) of a tissue voxel, read at 1 MHz.
    fn tissue(c: &HuConversion, hu: f64) -> (f64, f64, f64) {
        let p = c.properties(hu, 1e6).expect("tissue");
        (p.sound_speed, p.density, p.attenuation / (100.0 * NP_PER_DB))
    }

    fn close(a: (f64, f64, f64), b: (f64, f64, f64)) -> bool {
        (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9 && (a.2 - b.2).abs() < 1e-9
    }

    #[test]
    fn porosity_model_matches_hand_values() {
        let c = HuConversion::named("aubry2003").unwrap();
        // H = 1000: ψ = 0.5; c = 1500 + 1400·0.5 = 2200; ρ = 0.5·1000 + 0.5·2200 = 1600;
        // a = 2 + 78·sqrt(0.5).
        assert!(close(tissue(&c, 1000.0), (2200.0, 1600.0, 2.0 + 78.0 * 0.5f64.sqrt())), "{:?}", tissue(&c, 1000.0));
        // Denser than hu_max: no porosity, the dense-bone values.
        assert!(close(tissue(&c, 3000.0), (2900.0, 2200.0, 2.0)));
        assert_eq!(c.properties(-900.0, 1e6), None);
        assert!(close(tissue(&c, 40.0), (1546.0, 1040.0, 0.6)));
        // Linear in frequency: half the Np/m at 500 kHz.
        let (a1, a05) = (c.properties(1000.0, 1e6).unwrap().attenuation, c.properties(1000.0, 5e5).unwrap().attenuation);
        assert!((a05 / a1 - 0.5).abs() < 1e-12);
    }

    #[test]
    fn shear_is_carried_by_the_solid_fraction_and_bounded_by_the_bulk_modulus() {
        let mut c = HuConversion::named("aubry2003").unwrap();
        assert_eq!(c.properties(1000.0, 1e6).unwrap().shear_sound_speed, 0.0); // fluid bone by default
        c.bone_shear = BoneShear { sound_speed: 1500.0, attenuation_db_cm_mhz: 10.0 };
        c.validate().unwrap();
        // ψ = 0.5 at 1000 HU: half the dense bone's shear speed; none in soft tissue.
        let p = c.properties(1000.0, 5e5).unwrap();
        assert!((p.shear_sound_speed - 750.0).abs() < 1e-9 && (p.shear_attenuation - 5.0 * 100.0 * NP_PER_DB).abs() < 1e-9);
        assert!((c.properties(3000.0, 5e5).unwrap().shear_sound_speed - 1500.0).abs() < 1e-9);
        assert_eq!(c.properties(40.0, 5e5).unwrap().shear_sound_speed, 0.0);
        // Dense bone at 2900 m/s: c_s must stay below 2900·√3/2 = 2511 m/s.
        for (cs, a, name) in [
            (2520.0, 0.0, "ct.bone_shear_sound_speed_m_s"),
            (2900.0, 0.0, "ct.bone_shear_sound_speed_m_s"),
            (-1.0, 0.0, "ct.bone_shear_sound_speed_m_s"),
            (1500.0, -1.0, "ct.bone_shear_attenuation_db_cm_mhz"),
        ] {
            c.bone_shear = BoneShear { sound_speed: cs, attenuation_db_cm_mhz: a };
            match c.validate() {
                Err(HasError::InvalidParameter { name: n, .. }) => assert_eq!(n, name),
                other => panic!("{cs} {a}: {other:?}"),
            }
        }
    }

    #[test]
    fn bone_stays_dark_and_still_in_mr_images_when_read_as_soft_tissue() {
        // The head without its skull has the soft tissue's acoustics in the bone voxels, but a
        // scanner still images bone there: the model of an estimate with a CT prior must leave
        // the same pixels out as the patient's images do.
        let c = HuConversion::named("aubry2003").unwrap();
        let soft = c.without_bone();
        assert!(close(tissue(&soft, 1000.0), (1546.0, 1040.0, 0.6)));
        for conversion in [&c, &soft] {
            assert_eq!(conversion.mr_response(1000.0), Some(MrResponse::BONE));
            assert_eq!(conversion.mr_response(40.0), Some(MrResponse::SOFT));
            assert_eq!(conversion.mr_response(-900.0), None);
        }
        assert_eq!(soft.min_sound_speed(), 1546.0);
    }

    #[test]
    fn schneider_mast_matches_hand_values() {
        let c = HuConversion::named("schneider-mast").unwrap();
        // H = 1000: h = 2000 → ρ = 0.6625370912451·2000 + 348.8555178455294 = 1673.9297;
        // c = 1.33·ρ + 167.
        let (s, r, _) = tissue(&c, 1000.0);
        assert!((r - 1_673.929_700_335_73).abs() < 1e-6, "{r}");
        assert!((s - (1.33 * r + 167.0)).abs() < 1e-9, "{s}");
        // The fit's pieces meet within 1.2 kg/m³ (at h = 1260).
        let (below, above) = (schneider_density(259.999), schneider_density(260.0));
        assert!((below - above).abs() < 1.2, "{below} {above}");
    }

    #[test]
    fn unknown_names_and_crossed_thresholds_are_refused() {
        let e = HuConversion::named("hounsfield").unwrap_err().to_string();
        assert!(e.contains("ct.conversion") && e.contains("aubry2003") && e.contains("schneider-mast"), "{e}");
        let mut c = HuConversion::named("aubry2003").unwrap();
        c.bone_from_hu = -600.0;
        assert!(c.validate().unwrap_err().to_string().contains("ct.bone_from_hu"));
    }
}
