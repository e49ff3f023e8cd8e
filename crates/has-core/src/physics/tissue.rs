//! How a tissue shows in an MR-ARFI image: whether it gives MR signal, and how far it moves
//! under a given radiation force.
//!
//! MR-ARFI measures displacement where the tissue gives signal. Cortical bone gives none (T2* far
//! below a millisecond) and barely moves (shear modulus of GPa against about a kPa in brain), so
//! the force it absorbs never appears as displacement; soft tissue (brain, the phantom's gel)
//! gives signal and moves; coupling water gives signal and, absorbing next to nothing, feels no
//! force. The image model is `displacement ∝ displacement_scale · F` in the tissue, broadened and
//! sampled onto the pixels, and a pixel is imaged where at least half of it (over the slice) is
//! tissue with signal.

use crate::error::{require_non_negative, Result};

/// Sound speed (m/s) from which a material counts as bone-like by default: soft tissues lie
/// between about 1400 and 1650 m/s, trabecular bone from about 2000 and cortical bone near 3000.
pub const BONE_LIKE_FROM_M_S: f64 = 1800.0;

/// Least fraction of a pixel (area over the slice) in tissue with MR signal for the pixel to be
/// imaged.
pub const IMAGED_FRACTION: f64 = 0.5;

/// The MR-ARFI response of a tissue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MrResponse {
    /// Whether the tissue gives MR signal (pixels without it are absent from images).
    pub signal: bool,
    /// Displacement per unit radiation force relative to soft tissue (brain, gel: 1; bone: 0).
    pub displacement_scale: f64,
}

impl MrResponse {
    /// Soft tissue and water: signal, displacement as the force says.
    pub const SOFT: MrResponse = MrResponse { signal: true, displacement_scale: 1.0 };
    /// Bone: no signal, no displacement.
    pub const BONE: MrResponse = MrResponse { signal: false, displacement_scale: 0.0 };

    /// The default for a material of sound speed `c` (m/s): bone from [`BONE_LIKE_FROM_M_S`] on,
    /// else soft.
    pub fn for_sound_speed(c: f64) -> Self {
        if c >= BONE_LIKE_FROM_M_S {
            Self::BONE
        } else {
            Self::SOFT
        }
    }

    /// Checks the displacement scale (finite, ≥ 0), naming `owner` in the error.
    pub fn validate(&self, owner: &str) -> Result<()> {
        require_non_negative(&format!("{owner}.displacement_scale"), self.displacement_scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bone_like_materials_are_dark_and_still_by_default() {
        assert_eq!(MrResponse::for_sound_speed(1546.0), MrResponse::SOFT);
        assert_eq!(MrResponse::for_sound_speed(1610.0), MrResponse::SOFT); // skin
        assert_eq!(MrResponse::for_sound_speed(2300.0), MrResponse::BONE); // trabecular
        assert_eq!(MrResponse::for_sound_speed(2800.0), MrResponse::BONE); // cortical
        assert!(MrResponse { signal: true, displacement_scale: -1.0 }.validate("material 'x'").is_err());
        assert!(MrResponse { signal: true, displacement_scale: f64::NAN }.validate("material 'x'").is_err());
    }
}
