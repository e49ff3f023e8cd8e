//! A plane wave through an isotropic viscoelastic plate between fluids: exact, with P-SV mode
//! conversion and every reverberation inside the plate.
//!
//! In the plane of incidence (x along the faces, z across, the plate `0 <= z <= d`) a wave of
//! transverse wavenumber `ξ` meets the first face. In the solid the displacement is
//! `u = ∇φ + ∇×(ψ·ŷ)` with the compressional potential
//! `φ = A⁺·exp(iαz) + A⁻·exp(iα(d - z))` and the shear potential
//! `ψ = B⁺·exp(iβz) + B⁻·exp(iβ(d - z))`, `α = sqrt(kp² - ξ²)`, `β = sqrt(ks² - ξ²)`
//! (`Im >= 0`); each wave is referred to the face it leaves, so no factor exceeds 1 and the
//! system stays well conditioned for thick or evanescent layers (a global matrix, as in
//! Lowe, IEEE UFFC 42:525, 1995, rather than a transfer-matrix product). The moduli are those
//! of the complex wavenumbers, `λ + 2μ = ρω²/kp²`, `μ = ρω²/ks²` (a loss per wavelength that
//! is the same at every angle). At each face the normal displacement and normal stress are
//! continuous and the shear stress vanishes (an inviscid fluid): six equations for the
//! reflection `R`, the four amplitudes and the transmission `T`. Time dependence
//! `exp(-i·omega·t)`, as in the rest of [`crate::reference`].

use super::Fluid;
use crate::error::{require_positive, HasError, Result};
use num_complex::Complex64 as C64;
use std::f64::consts::PI;

/// An isotropic viscoelastic solid at one frequency.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solid {
    /// Compressional wavenumber, rad/m (imaginary part: amplitude attenuation, Np/m).
    pub kp: C64,
    /// Shear wavenumber, rad/m.
    pub ks: C64,
    /// Density, kg/m³.
    pub density: f64,
}

impl Solid {
    /// A solid of compressional and shear speeds (m/s), density (kg/m³) and amplitude
    /// attenuations (Np/m) at `frequency` (Hz). The shear speed must be below the compressional
    /// one (`λ > -2μ/3` needs more, but any real bone is far inside).
    pub fn new(
        sound_speed: f64,
        shear_sound_speed: f64,
        density: f64,
        attenuation: f64,
        shear_attenuation: f64,
        frequency: f64,
    ) -> Result<Self> {
        require_positive("sound_speed", sound_speed)?;
        require_positive("shear_sound_speed", shear_sound_speed)?;
        require_positive("density", density)?;
        require_positive("frequency", frequency)?;
        if shear_sound_speed >= sound_speed {
            return Err(HasError::invalid("shear_sound_speed", "must be below the compressional sound speed"));
        }
        if !(attenuation >= 0.0) || !(shear_attenuation >= 0.0) {
            return Err(HasError::invalid("attenuation", "must be non-negative"));
        }
        let w = 2.0 * PI * frequency;
        Ok(Solid { kp: C64::new(w / sound_speed, attenuation), ks: C64::new(w / shear_sound_speed, shear_attenuation), density })
    }

    /// `sqrt(k² - kt²)` with `Im >= 0` for `k` either wavenumber ([`super::vertical`]).
    fn vertical(k: C64, kt: C64) -> C64 {
        super::vertical(k, kt)
    }
}

/// A plane wave's response to a plate: pressure reflection at the first face and pressure
/// transmission at the last face, per unit incident pressure at the first face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateResponse {
    /// Reflected pressure at the first face.
    pub reflection: C64,
    /// Transmitted pressure at the last face.
    pub transmission: C64,
}

/// The response of a solid plate of `thickness` (m) from `entry` into `exit` at transverse
/// wavenumber `kt` (rad/m).
pub fn plate_response(entry: Fluid, plate: Solid, thickness: f64, exit: Fluid, kt: C64) -> PlateResponse {
    let (ks2, rho) = (plate.ks * plate.ks, plate.density);
    let alpha = Solid::vertical(plate.kp, kt);
    let beta = Solid::vertical(plate.ks, kt);
    let (ea, eb) = ((C64::i() * alpha * thickness).exp(), (C64::i() * beta * thickness).exp());
    let (kz1, kz3) = (entry.kz(kt), exit.kz(kt));
    let i = C64::i();
    let zero = C64::new(0.0, 0.0);
    // Per unit potential (scaled by ρω²): normal displacement times ω², normal and shear stress.
    let c_p = -(ks2 - 2.0 * kt * kt) / ks2;
    let s_a = 2.0 * kt * alpha / ks2;
    let s_b = 2.0 * kt * beta / ks2;
    let c_s = (beta * beta - kt * kt) / ks2;
    let (v_a, v_b) = (i * alpha / rho, i * kt / rho);
    let (y1, y3) = (i * kz1 / entry.density, i * kz3 / exit.density);
    // Unknowns: R, A⁺, A⁻, B⁺, B⁻, T.
    let mut m = [
        // z = 0: normal displacement, normal stress, shear stress.
        [y1, v_a, -v_a * ea, v_b, v_b * eb, zero],
        [C64::new(1.0, 0.0), c_p, c_p * ea, -s_b, s_b * eb, zero],
        [zero, -s_a, s_a * ea, c_s, c_s * eb, zero],
        // z = d.
        [zero, v_a * ea, -v_a, v_b * eb, v_b, -y3],
        [zero, c_p * ea, c_p, -s_b * eb, s_b, C64::new(1.0, 0.0)],
        [zero, -s_a * ea, s_a, c_s * eb, c_s, zero],
    ];
    let mut rhs = [y1, C64::new(-1.0, 0.0), zero, zero, zero, zero];
    let x = solve6(&mut m, &mut rhs);
    PlateResponse { reflection: x[0], transmission: x[5] }
}

/// Gaussian elimination with rows scaled to unit largest entry and partial pivoting (the system
/// mixes displacements and stresses); a singular system gives NaN.
pub(super) fn solve6(m: &mut [[C64; 6]; 6], rhs: &mut [C64; 6]) -> [C64; 6] {
    for (row, b) in m.iter_mut().zip(rhs.iter_mut()) {
        let s = row.iter().map(|v| v.norm()).fold(0.0, f64::max);
        if s > 0.0 {
            row.iter_mut().for_each(|v| *v /= s);
            *b /= s;
        }
    }
    for col in 0..6 {
        let p = (col..6).max_by(|&a, &b| m[a][col].norm().total_cmp(&m[b][col].norm())).unwrap_or(col);
        m.swap(col, p);
        rhs.swap(col, p);
        let d = m[col][col];
        for r in col + 1..6 {
            let f = m[r][col] / d;
            if f.norm() != 0.0 {
                let pivot = m[col];
                for (v, p) in m[r].iter_mut().zip(pivot).skip(col) {
                    *v -= f * p;
                }
                let v = rhs[col];
                rhs[r] -= f * v;
            }
        }
    }
    let mut x = [C64::new(0.0, 0.0); 6];
    for r in (0..6).rev() {
        let s: C64 = (r + 1..6).map(|c| m[r][c] * x[c]).sum();
        x[r] = (rhs[r] - s) / m[r][r];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::super::layered::{transmission, Layer};
    use super::super::test_fluid as fluid;
    use super::*;

    const F: f64 = 500e3;

    fn bone(cs: f64, loss: bool) -> Solid {
        // Cortical bone of the ITRUSST benchmark: 4 dB/cm at 500 kHz for both waves (or none).
        let a = if loss { 4.0 * 100.0 / (20.0 / std::f64::consts::LN_10) } else { 0.0 };
        Solid::new(2800.0, cs, 1850.0, a, a, F).unwrap()
    }

    /// The textbook terms of a fluid on the bone solid (density 1850) at tangential `kt`: the
    /// vertical wavenumbers α, β in the solid, the impedances `Z1 = ρ1/kz1`, `Zp = ρ/α`,
    /// `Zs = ρ/β` and `cos 2θs`, `sin 2θs`.
    struct Textbook {
        z1: C64,
        zp: C64,
        zs: C64,
        cos2: C64,
        sin2: C64,
        alpha: C64,
        beta: C64,
    }

    fn textbook(water: &Fluid, solid: &Solid, kt: C64) -> Textbook {
        let (alpha, beta) = (Solid::vertical(solid.kp, kt), Solid::vertical(solid.ks, kt));
        let ks2 = solid.ks * solid.ks;
        Textbook {
            z1: water.density / water.kz(kt),
            zp: 1850.0 / alpha,
            zs: 1850.0 / beta,
            cos2: 1.0 - 2.0 * kt * kt / ks2,
            sin2: 2.0 * kt * beta / ks2,
            alpha,
            beta,
        }
    }

    fn kt_at(water: &Fluid, deg: f64) -> C64 {
        C64::new(water.k.re * deg.to_radians().sin(), 0.0)
    }

    /// Lossless, water on both sides: `|R|² + |T|² = 1` at every propagating angle, to 1e-12
    /// (rounding; the system is solved in double precision with pivoting).
    #[test]
    fn a_lossless_plate_conserves_energy() {
        let water = fluid(1500.0, 1000.0, 0.0);
        for cs in [1300.0, 1500.0, 1700.0] {
            for deg in (0..90).map(|d| d as f64 + 0.37) {
                let r = plate_response(water, bone(cs, false), 6.5e-3, water, kt_at(&water, deg));
                let e = r.reflection.norm_sqr() + r.transmission.norm_sqr();
                assert!((e - 1.0).abs() < 1e-12, "cs {cs}, {deg}°: {e}");
            }
        }
    }

    /// As the shear speed goes to zero the plate becomes the fluid layer of
    /// [`super::super::layered::transmission`]: at 0.5 m/s the shear wave's coupling is of order
    /// `(cs/cp)²` ≈ 3e-8, so 1e-6 at every angle, lossy and not.
    #[test]
    fn a_vanishing_shear_speed_gives_the_fluid_plate() {
        let water = fluid(1500.0, 1000.0, 0.0);
        for loss in [false, true] {
            let solid = bone(0.5, loss);
            let layer = Layer { thickness: 6.5e-3, fluid: Fluid { k: solid.kp, density: 1850.0 } };
            for deg in [0.0, 10.0, 25.0, 31.0, 33.0, 50.0, 80.0] {
                let kt = kt_at(&water, deg);
                let t = plate_response(water, solid, 6.5e-3, water, kt).transmission;
                let f = transmission(water, &[layer], water, kt);
                assert!((t - f).norm() < 1e-6, "{deg}°, loss {loss}: {t} vs {f}");
            }
        }
    }

    /// A plate thick and lossy enough that nothing returns from its second face reflects as the
    /// fluid-solid half-space (Brekhovskikh, *Waves in Layered Media*, 1980:
    /// `R = (Zp·cos²2θs + Zs·sin²2θs - Z1)/(Zp·cos²2θs + Zs·sin²2θs + Z1)`, `Z = ρω/kz`), to
    /// 1e-9 (what returns from the back face: `exp(-2·Im α·d)` ≈ 1e-20 here).
    #[test]
    fn a_thick_plate_reflects_as_the_half_space() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let solid = bone(1500.0, true);
        let d = 0.6;
        for deg in [0.0, 12.0, 28.0, 31.5, 40.0, 65.0] {
            let kt = kt_at(&water, deg);
            let r = plate_response(water, solid, d, water, kt).reflection;
            let Textbook { z1, zp, zs, cos2, sin2, .. } = textbook(&water, &solid, kt);
            let zin = zp * cos2 * cos2 + zs * sin2 * sin2;
            let half = (zin - z1) / (zin + z1);
            assert!((r - half).norm() < 1e-9, "{deg}°: {r} vs {half}");
        }
    }

    /// Water on both sides: Brekhovskikh's closed form of a solid plate (*Waves in Layered Media*, written for
    /// `exp(-i·omega·t)`), `W = -2iN / (M² - N² - 2iM - 1)` with
    /// `M = (Zp/Z1)·cos²2θs·cot P + (Zs/Z1)·sin²2θs·cot Q`,
    /// `N = (Zp/Z1)·cos²2θs / sin P + (Zs/Z1)·sin²2θs / sin Q`, `P = αd`, `Q = βd`: an
    /// independent derivation (symmetric and antisymmetric motions of the plate) of the same
    /// transmission, to 1e-9 lossy and not, below and beyond both critical angles.
    #[test]
    fn a_plate_in_water_matches_brekhovskikh() {
        let water = fluid(1500.0, 1000.0, 0.0);
        for (cs, loss) in [(1500.0, false), (1300.0, true), (1700.0, true)] {
            let solid = bone(cs, loss);
            let d = 6.5e-3;
            for deg in [0.0, 5.0, 17.0, 29.0, 33.0, 45.0, 62.0, 80.0] {
                let kt = kt_at(&water, deg);
                let t = plate_response(water, solid, d, water, kt).transmission;
                let Textbook { z1, zp, zs, cos2, sin2, alpha, beta } = textbook(&water, &solid, kt);
                let (p, q) = (alpha * d, beta * d);
                let (a, b) = (zp / z1 * cos2 * cos2, zs / z1 * sin2 * sin2);
                let m = a * p.cos() / p.sin() + b * q.cos() / q.sin();
                let n = a / p.sin() + b / q.sin();
                let w = -2.0 * C64::i() * n / (m * m - n * n - 2.0 * C64::i() * m - 1.0);
                assert!((t - w).norm() < 1e-9, "cs {cs}, {deg}°: {t} vs {w}");
            }
        }
    }

    /// At normal incidence no shear is excited: the solid plate is the fluid plate exactly.
    #[test]
    fn normal_incidence_excites_no_shear() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let solid = bone(1500.0, true);
        let layer = Layer { thickness: 6.5e-3, fluid: Fluid { k: solid.kp, density: 1850.0 } };
        let kt = C64::new(0.0, 0.0);
        let t = plate_response(water, solid, 6.5e-3, water, kt).transmission;
        assert!((t - transmission(water, &[layer], water, kt)).norm() < 1e-13);
    }
}
