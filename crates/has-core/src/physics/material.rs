//! Homogeneous materials and the acoustic properties at a point.

use crate::error::{require_in_range, require_non_negative, require_positive, HasError, Result};
use crate::physics::tissue::MrResponse;

/// Nepers per decibel: 1 dB = ln(10)/20 Np.
pub const NP_PER_DB: f64 = std::f64::consts::LN_10 / 20.0;

/// Sound speeds (m/s) the propagation accepts: from below air's 343 m/s to above diamond's
/// 12 000 m/s. Outside it a value is a unit mistake, and near zero the wavenumber `omega/c`
/// overflows.
pub const SOUND_SPEED_RANGE_M_S: (f64, f64) = (100.0, 20_000.0);

/// Amplitude attenuation coefficient alpha (Np/m) at `frequency` (Hz) of the power law
/// `a(f) = a0 · (f / 1 MHz)^y` dB/cm with `a0` in dB/cm/MHz^y.
pub fn attenuation_np_m(a0_db_cm_mhz: f64, power: f64, frequency: f64) -> f64 {
    a0_db_cm_mhz * (frequency / 1e6).powf(power) * 100.0 * NP_PER_DB
}

/// Checks a sound speed against [`SOUND_SPEED_RANGE_M_S`].
pub(crate) fn require_sound_speed(name: &str, c: f64) -> Result<()> {
    let (lo, hi) = SOUND_SPEED_RANGE_M_S;
    require_in_range(name, c, lo, hi, "m/s, from gases to diamond")
}

/// A homogeneous material. Attenuation follows `a(f) = a0 · (f / 1 MHz)^y` in dB/cm and is taken to
/// be all absorption (it drives the radiation force).
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Name that regions and scenario files refer to it by.
    pub name: String,
    /// Sound speed c (m/s).
    pub sound_speed: f64,
    /// Density rho (kg/m³).
    pub density: f64,
    /// a0 (dB/cm/MHz^y).
    pub attenuation_db_cm_mhz: f64,
    /// Frequency exponent y of the power law (1 = linear).
    pub attenuation_power: f64,
    /// Shear-wave speed c_s (m/s) of a solid; 0 for a fluid. The march carries the shear wave
    /// where the solid's faces lie on its planes (`propagation/elastic.rs`); a full-wave engine
    /// given the medium uses it everywhere.
    pub shear_sound_speed: f64,
    /// Shear-wave attenuation a0_s (dB/cm/MHz^y, the same power law as the compressional wave).
    pub shear_attenuation_db_cm_mhz: f64,
    /// How the material shows in MR-ARFI images (default: by its sound speed,
    /// [`MrResponse::for_sound_speed`]).
    pub mr: MrResponse,
}

impl Material {
    /// Validates the acoustic parameters.
    pub fn new(name: &str, sound_speed: f64, density: f64, attenuation_db_cm_mhz: f64) -> Result<Self> {
        let mr = MrResponse::for_sound_speed(sound_speed);
        let m = Material {
            name: name.to_string(),
            sound_speed,
            density,
            attenuation_db_cm_mhz,
            attenuation_power: 1.0,
            shear_sound_speed: 0.0,
            shear_attenuation_db_cm_mhz: 0.0,
            mr,
        };
        m.validate()?;
        Ok(m)
    }

    /// Checks every field, naming the material in the error.
    pub fn validate(&self) -> Result<()> {
        let p = |k: &str| format!("material '{}'.{k}", self.name);
        require_sound_speed(&p("sound_speed_m_s"), self.sound_speed)?;
        require_positive(&p("density_kg_m3"), self.density)?;
        require_non_negative(&p("attenuation_db_cm_mhz"), self.attenuation_db_cm_mhz)?;
        require_non_negative(&p("attenuation_power"), self.attenuation_power)?;
        require_shear(&p("shear_sound_speed_m_s"), self.shear_sound_speed, self.sound_speed)?;
        require_non_negative(&p("shear_attenuation_db_cm_mhz"), self.shear_attenuation_db_cm_mhz)?;
        self.mr.validate(&format!("material '{}'", self.name))
    }

    /// Amplitude attenuation coefficient alpha (Np/m) at `frequency` (Hz).
    pub fn attenuation_np_m(&self, frequency: f64) -> f64 {
        attenuation_np_m(self.attenuation_db_cm_mhz, self.attenuation_power, frequency)
    }

    /// Local properties at `frequency`.
    pub fn properties(&self, frequency: f64) -> Properties {
        Properties {
            sound_speed: self.sound_speed,
            density: self.density,
            attenuation: self.attenuation_np_m(frequency),
            shear_sound_speed: self.shear_sound_speed,
            shear_attenuation: attenuation_np_m(self.shear_attenuation_db_cm_mhz, self.attenuation_power, frequency),
        }
    }
}

/// Checks a shear speed `cs` (m/s) against the compressional speed `cp` of the same solid: 0 (a
/// fluid) or positive and below `cp·√3/2`, where the bulk modulus `ρ·(cp² − 4/3·cs²)` stays
/// positive (so also below `cp`).
pub(crate) fn require_shear(name: &str, cs: f64, cp: f64) -> Result<()> {
    require_non_negative(name, cs)?;
    let limit = cp * 3f64.sqrt() / 2.0;
    if cs >= limit {
        return Err(HasError::invalid(
            name,
            format!("must lie below √3/2 of the compressional speed ({limit:.0} m/s for {cp:.0} m/s: a positive bulk modulus), got {cs}"),
        ));
    }
    Ok(())
}

/// Acoustic properties at a point, SI: c (m/s), rho (kg/m³), alpha (Np/m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Properties {
    /// Sound speed c, m/s.
    pub sound_speed: f64,
    /// Density rho, kg/m³.
    pub density: f64,
    /// Amplitude attenuation coefficient alpha at the frequency asked for, Np/m.
    pub attenuation: f64,
    /// Shear-wave speed c_s, m/s (0: a fluid).
    pub shear_sound_speed: f64,
    /// Shear-wave amplitude attenuation at the frequency asked for, Np/m.
    pub shear_attenuation: f64,
}

impl Properties {
    /// Characteristic impedance Z = rho·c (Rayl).
    pub fn impedance(&self) -> f64 {
        self.density * self.sound_speed
    }

    /// The radiation-force coefficient `alpha / (rho·c²)` (m·s/kg): force density per unit
    /// `|p|²` (`F = 2·alpha·I/c` with `I = |p|²/(2·rho·c)`).
    pub fn force_coefficient(&self) -> f64 {
        self.attenuation / (self.density * self.sound_speed * self.sound_speed)
    }
}
