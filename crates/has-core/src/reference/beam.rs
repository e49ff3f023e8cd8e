//! A beam uniform in `y` through a planar plate tilted about `y`: exact, one plane wave at a time.
//!
//! The beam is a pressure profile `g(x)` on the plane `z = 0` in a lossless fluid, periodic with
//! the window `L` it is given on (as on a march's lateral grid without absorbing layers): the
//! Fourier series `g(x) = Σ_m A_m·exp(i·kx_m·x)`, `kx_m = 2π·m/L`. Each propagating term is the
//! plane wave `K = (kx, 0, kz)`, `kz = sqrt(k² - kx²)`. The plate's faces have the unit normal
//! `n = (sin t, 0, cos t)` (the axis turned by `t` about `y`), the first through `(0, 0, z1)`;
//! the wave meets them at `cos θ = K·n / k` and crosses with the plate's exact plane-wave
//! transmission `t(k·sin θ)` ([`super::oblique::Plate`]: fluid layers or the elastic plate with
//! P-SV conversion, every reverberation), which relates the pressure on the last face to the
//! incident pressure on the first at the same point along the face. With water on both sides
//! the wave beyond the plate is the free wave times `t(k·sin θ)·exp(-i·k·cos θ·D)` (the free
//! wave's own phase over the thickness `D` along the normal taken out), so
//!
//! `p(x, z) = Σ_m A_m·t_m·exp(-i·k·cos θ_m·D)·exp(i·(kx_m·x + kz_m·z))`
//!
//! at points beyond the last face. Evanescent terms are left out: they decay long before a plate
//! some wavelengths from the source.

use super::oblique::Plate;
use super::Fluid;
use crate::error::{HasError, Result};
use num_complex::Complex64 as C64;
use std::f64::consts::PI;

/// The plane waves of a beam beyond a tilted plate.
#[derive(Debug, Clone)]
pub struct PlateBeam {
    /// Unit normal of the plate's faces `(sin t, cos t)` in `(x, z)`.
    normal: [f64; 2],
    /// Axis point of the first face, m.
    z1: f64,
    /// Thickness along the normal, m.
    thickness: f64,
    /// Per propagating term: `kx`, `kz` (rad/m) and the amplitude leaving the plate.
    terms: Vec<(f64, f64, C64)>,
}

impl PlateBeam {
    /// The profile `profile[j]` at `x = x0 + j·dx` (m) on `z = 0`, periodic over its window, in
    /// the lossless `water` on both sides of `plate`, whose first face passes through
    /// `(0, 0, z1)` with its normal turned by `tilt` (rad, below 60°) about `y`.
    pub fn new(profile: &[C64], x0: f64, dx: f64, water: Fluid, plate: &Plate, z1: f64, tilt: f64) -> Result<Self> {
        if profile.is_empty() || !(dx > 0.0) {
            return Err(HasError::invalid("profile", "needs samples and a positive spacing"));
        }
        if water.k.im != 0.0 || !(water.k.re > 0.0) {
            return Err(HasError::invalid("water", "must be lossless"));
        }
        if !(tilt.abs() < PI / 3.0) {
            return Err(HasError::invalid("tilt", "must be below 60 degrees"));
        }
        let thickness = plate.thickness();
        if !(thickness > 0.0) || !(z1 > 0.0) {
            return Err(HasError::invalid("plate", "thickness and z1 must be positive"));
        }
        let (n, k) = (profile.len(), water.k.re);
        let window = n as f64 * dx;
        let (s, c) = tilt.sin_cos();
        let m_max = (k * window / (2.0 * PI)).floor() as i64;
        let terms = (-m_max..=m_max)
            .filter_map(|m| {
                let kx = 2.0 * PI * m as f64 / window;
                let kz2 = k * k - kx * kx;
                if kz2 <= 0.0 {
                    return None;
                }
                let kz = kz2.sqrt();
                let a: C64 =
                    profile.iter().enumerate().map(|(j, &g)| g * C64::new(0.0, -kx * (x0 + j as f64 * dx)).exp()).sum::<C64>() / n as f64;
                let cos = (kx * s + kz * c) / k;
                if cos <= 0.0 {
                    // Travelling away from the plate: it never crosses.
                    return None;
                }
                let kt = k * (1.0 - cos * cos).max(0.0).sqrt();
                let t = plate.transmission(water, water, kt) * C64::new(0.0, -k * cos * thickness).exp();
                Some((kx, kz, a * t))
            })
            .collect();
        Ok(PlateBeam { normal: [s, c], z1, thickness, terms })
    }

    /// Pressure at `(x, z)` (m), which must lie beyond the plate's last face.
    pub fn pressure(&self, x: f64, z: f64) -> Result<C64> {
        let depth = self.normal[0] * x + self.normal[1] * (z - self.z1);
        if !(depth > self.thickness) {
            return Err(HasError::invalid("point", format!("({:.2}, {:.2}) mm is not beyond the plate", x * 1e3, z * 1e3)));
        }
        Ok(self.terms.iter().map(|&(kx, kz, a)| a * C64::new(0.0, kx * x + kz * z).exp()).sum())
    }
}

#[cfg(test)]
mod tests {
    use super::super::layered::Layer;
    use super::super::test_fluid as fluid;
    use super::*;

    /// A Gaussian beam of waist `w` (m) steered by `steer` (rad), on 512 samples 0.25 mm apart.
    fn beam(w: f64, steer: f64, k: f64) -> (Vec<C64>, f64, f64) {
        let (n, dx) = (512, 0.25e-3);
        let x0 = -0.5 * n as f64 * dx;
        let profile = (0..n)
            .map(|j| {
                let x = x0 + j as f64 * dx;
                C64::new(-(x / w).powi(2), k * steer.sin() * x).exp()
            })
            .collect();
        (profile, x0, dx)
    }

    /// A plate of the water itself is no plate: the beam beyond it is the free beam, whatever the
    /// tilt (the transmission's phase over the thickness and the one taken out cancel to 1e-12).
    #[test]
    fn a_plate_of_water_leaves_the_free_beam() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let plate = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: water }]);
        let (profile, x0, dx) = beam(8e-3, 0.2, water.k.re);
        for tilt in [0.0f64, 0.35, -0.5] {
            let through = PlateBeam::new(&profile, x0, dx, water, &plate, 30e-3, tilt).unwrap();
            let free = PlateBeam::new(&profile, x0, dx, water, &plate, 30e-3, 0.0).unwrap();
            let z = 50e-3;
            let far = |b: &PlateBeam, x: f64| b.terms.iter().map(|&(kx, kz, a)| a * C64::new(0.0, kx * x + kz * z).exp()).sum::<C64>();
            for x in [-10e-3, 0.0, 7e-3, 15e-3] {
                let (a, b) = (far(&through, x), far(&free, x));
                assert!((a - b).norm() < 1e-12, "tilt {tilt}, x {x}: {a} vs {b}");
            }
        }
    }

    /// A wide beam along a tilted plate's normal (30°, 1.4° of angular spread) crosses it as the
    /// plane wave at normal incidence: its peak is `|t(0)|` of the free beam's within 1 % (the
    /// spread's change of `t`), and turned the other way it meets the plate at 60°, past the
    /// critical angle, where nothing crosses (below 1 %).
    #[test]
    fn a_wide_beam_along_the_normal_crosses_as_at_normal_incidence() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bone = fluid(2800.0, 1850.0, 4.0);
        let plate = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: bone }]);
        let tilt = 30f64.to_radians();
        let (profile, x0, dx) = beam(20e-3, tilt, water.k.re);
        let none = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: water }]);
        let t0 = plate.transmission(water, water, 0.0).norm();
        // Along the beam, beyond the plate.
        let along = |b: &PlateBeam| b.pressure(70e-3 * tilt.tan(), 70e-3).unwrap().norm();
        let free = along(&PlateBeam::new(&profile, x0, dx, water, &none, 30e-3, tilt).unwrap());
        let through = along(&PlateBeam::new(&profile, x0, dx, water, &plate, 30e-3, tilt).unwrap());
        assert!((through / free / t0 - 1.0).abs() < 0.01, "{through} / {free} against |t(0)| {t0}");
        let against = along(&PlateBeam::new(&profile, x0, dx, water, &plate, 30e-3, -tilt).unwrap());
        assert!(against < 0.01 * free, "{against} of {free}");
    }

    /// Points not beyond the plate are refused.
    #[test]
    fn points_before_the_last_face_are_refused() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let plate = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: fluid(2800.0, 1850.0, 4.0) }]);
        let (profile, x0, dx) = beam(8e-3, 0.0, water.k.re);
        let b = PlateBeam::new(&profile, x0, dx, water, &plate, 30e-3, 0.3).unwrap();
        assert!(b.pressure(0.0, 33e-3).is_err());
        assert!(b.pressure(0.0, 45e-3).is_ok());
    }
}
