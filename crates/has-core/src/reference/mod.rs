//! Exact solutions to check the propagation against, written independently of the marching code
//! (they share no grid, FFT or medium sampling with it): O'Neil's bowl in water, the bowl through
//! planar fluid layers ([`layered`], angular spectrum and transfer matrices), and the bowl through
//! a spherical fluid shell ([`shell`], spherical-harmonic expansion) or solid shell
//! ([`solid_shell`]: P-SV conversion at both surfaces); plane waves through a solid plate
//! ([`elastic`]) and a stack of fluid and solid layers ([`stack`]) with P-SV conversion.
//!
//! The source is the one every case shares: a spherical bowl with uniform normal velocity `u0`
//! radiating as the Rayleigh integral `p(r) = -i·omega·rho·u0/(2π) ∫ exp(ik|r - r'|)/|r - r'| dS'`
//! (the baffled bowl, whose on-axis closed form is O'Neil's), apex at the origin, axis +z.
//! Pressures are relative to `p0 = rho·c·u0` of the medium the bowl radiates into. Time
//! dependence `exp(-i·omega·t)`.

pub mod beam;
pub mod elastic;
pub mod layered;
pub mod oblique;
pub mod shell;
pub mod solid_shell;
pub mod special;
pub mod stack;

use crate::error::{require_positive, HasError, Result};
use crate::physics::material::Properties;
use num_complex::Complex64 as C64;
use special::composite_gauss;
use std::f64::consts::PI;

/// A fluid at one frequency: its complex wavenumber `omega/c + i·alpha` and density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fluid {
    /// Complex wavenumber, rad/m (imaginary part: amplitude attenuation, Np/m).
    pub k: C64,
    /// Density, kg/m³.
    pub density: f64,
}

impl Fluid {
    /// The fluid of `properties` at `frequency` (Hz).
    pub fn new(properties: Properties, frequency: f64) -> Result<Self> {
        require_positive("sound_speed", properties.sound_speed)?;
        require_positive("density", properties.density)?;
        if !(properties.attenuation >= 0.0) {
            return Err(HasError::invalid("attenuation", "must be non-negative"));
        }
        Ok(Fluid { k: C64::new(2.0 * PI * frequency / properties.sound_speed, properties.attenuation), density: properties.density })
    }

    /// `kz = sqrt(k² - kt²)` for the transverse wavenumber `kt` (rad/m; the root with `Im >= 0`,
    /// so evanescent waves decay along +z).
    pub fn kz(&self, kt: C64) -> C64 {
        vertical(self.k, kt)
    }
}

/// `sqrt(k² - kt²)`, the root with `Im >= 0` (evanescent waves decay along +z).
pub(crate) fn vertical(k: C64, kt: C64) -> C64 {
    let r = (k * k - kt * kt).sqrt();
    if r.im < 0.0 {
        -r
    } else {
        r
    }
}

/// A spherical bowl (apex at the origin, centre of curvature at `z = radius_of_curvature` on
/// the axis) with uniform normal velocity, in a lossless fluid of wavenumber `k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bowl {
    /// Radius of curvature R, m.
    pub radius_of_curvature: f64,
    /// Aperture radius a (half the diameter), m.
    pub aperture_radius: f64,
    /// Wavenumber in the fluid it radiates into, rad/m (real).
    pub k: f64,
}

impl Bowl {
    /// Validates the geometry (`0 < a <= R`) and the wavenumber.
    pub fn new(radius_of_curvature: f64, aperture_radius: f64, k: f64) -> Result<Self> {
        require_positive("radius_of_curvature", radius_of_curvature)?;
        require_positive("aperture_radius", aperture_radius)?;
        require_positive("k", k)?;
        if aperture_radius > radius_of_curvature {
            return Err(HasError::invalid("aperture_radius", "must not exceed the radius of curvature"));
        }
        Ok(Bowl { radius_of_curvature, aperture_radius, k })
    }

    /// The largest polar angle of the cap seen from the centre of curvature, rad.
    pub fn half_angle(&self) -> f64 {
        (self.aperture_radius / self.radius_of_curvature).asin()
    }

    /// Depth of the cap (z of its rim), m.
    pub fn depth(&self) -> f64 {
        let (r, a) = (self.radius_of_curvature, self.aperture_radius);
        r - (r * r - a * a).sqrt()
    }

    /// The cap as rings: `(rho', z', weight)` with `Σ weight·f(ring)` approximating
    /// `∫ f dS / (2π)` (`dS = R²·sin β dβ dφ`, β the polar angle from the apex about the centre
    /// of curvature), by Gauss–Legendre in β on `panels` panels of 20 points.
    pub(crate) fn rings(&self, panels: usize) -> Vec<(f64, f64, f64)> {
        let r = self.radius_of_curvature;
        composite_gauss(panels, 20, 0.0, self.half_angle())
            .into_iter()
            .map(|(b, w)| (r * b.sin(), r * (1.0 - b.cos()), w * r * r * b.sin()))
            .collect()
    }

    /// O'Neil (JASA 21:516, 1949): `|p/p0|` on the axis at `z` (m from the apex),
    /// `2/|1 - z/R| · |sin(k/2·(sqrt((z - h)² + a²) - z))|`, `k·h` at the centre of curvature.
    pub fn oneil(&self, z: f64) -> f64 {
        let (r, a, h) = (self.radius_of_curvature, self.aperture_radius, self.depth());
        if (z - r).abs() < 1e-9 * r {
            return self.k * h;
        }
        (2.0 / (1.0 - z / r) * (0.5 * self.k * (((z - h).powi(2) + a * a).sqrt() - z)).sin()).abs()
    }

    /// `p/p0` at `(x, y, z)` (m) by the Rayleigh integral summed directly over the cap
    /// (`rings` × `azimuths` points): the slow, obvious reference for the expansions.
    pub fn rayleigh(&self, point: [f64; 3], panels: usize, azimuths: usize) -> C64 {
        let mut sum = C64::new(0.0, 0.0);
        for (rho, z, w) in self.rings(panels) {
            let mut ring = C64::new(0.0, 0.0);
            for m in 0..azimuths {
                let phi = 2.0 * PI * (m as f64 + 0.5) / azimuths as f64;
                let d = ((point[0] - rho * phi.cos()).powi(2) + (point[1] - rho * phi.sin()).powi(2) + (point[2] - z).powi(2)).sqrt();
                ring += C64::from_polar(1.0 / d, self.k * d);
            }
            sum += ring * (w / azimuths as f64);
        }
        // -i·omega·rho·u0/(2π) · 2π·Σ = -i·k·p0·Σ (omega·rho·u0 = k·p0).
        -C64::i() * self.k * sum
    }
}

/// The fluid of sound speed `c` (m/s), density `rho` (kg/m³) and attenuation `a0` (dB/cm/MHz,
/// linear in frequency) at the tests' 500 kHz.
#[cfg(test)]
pub(crate) fn test_fluid(c: f64, rho: f64, a0: f64) -> Fluid {
    use crate::physics::material::attenuation_np_m;
    Fluid::new(
        Properties {
            sound_speed: c,
            density: rho,
            attenuation: attenuation_np_m(a0, 1.0, 500e3),
            shear_sound_speed: 0.0,
            shear_attenuation: 0.0,
        },
        500e3,
    )
    .unwrap()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The direct Rayleigh sum on the axis against O'Neil's closed form (the same integral):
    /// 1e-6 of the focal value from the quadrature.
    #[test]
    fn rayleigh_sum_matches_oneil_on_the_axis() {
        let bowl = Bowl::new(64e-3, 32e-3, 2.0 * PI * 500e3 / 1500.0).unwrap();
        let peak = bowl.oneil(64e-3);
        for z in [20e-3, 50e-3, 64e-3, 90e-3] {
            let p = bowl.rayleigh([0.0, 0.0, z], 30, 4).norm();
            assert!((p - bowl.oneil(z)).abs() < 1e-6 * peak, "z = {z}: {p} vs {}", bowl.oneil(z));
        }
    }
}
