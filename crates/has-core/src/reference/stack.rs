//! A plane wave through a stack of planar layers, each a fluid or an isotropic viscoelastic
//! solid, between two fluids: exact, with P-SV conversion at every face and every reverberation.
//!
//! The formulation of [`super::elastic`] extended to many layers (a global matrix, Lowe, IEEE
//! UFFC 42:525, 1995): in layer `j` (faces `z_j`, `z_{j+1}`) the compressional potential is
//! `φ = A⁺·exp(iα(z - z_j)) + A⁻·exp(iα(z_{j+1} - z))` and in a solid the shear potential
//! `ψ = B⁺·exp(iβ(z - z_j)) + B⁻·exp(iβ(z_{j+1} - z))`, each wave referred to the face it leaves
//! (no factor exceeds 1). With `u = ∇φ + ∇×(ψ·ŷ)` in the plane of incidence (x along the faces) at
//! transverse wavenumber `ξ`, a face between two solids keeps `u_x`, `u_z`, `σ_zz` and `σ_xz`
//! continuous; a face between a fluid and a solid `u_z` and `σ_zz`, with no shear stress on the
//! solid; a face between fluids `u_z` and the pressure. Amplitudes are scaled by `ρω²`, so that
//! a fluid's is its pressure. Time dependence `exp(-i·omega·t)`.

use super::elastic::{PlateResponse, Solid};
use super::Fluid;
use num_complex::Complex64 as C64;

/// One layer of a stack: a fluid or a solid, and its thickness (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StackLayer {
    /// A fluid layer.
    Fluid(Fluid, f64),
    /// A solid layer.
    Solid(Solid, f64),
}

impl StackLayer {
    /// Thickness, m.
    pub fn thickness(&self) -> f64 {
        match self {
            StackLayer::Fluid(_, d) | StackLayer::Solid(_, d) => *d,
        }
    }
}

/// A medium's waves at one face: density, the compressional wavenumber and, in a solid, the
/// shear wavenumber.
#[derive(Clone, Copy)]
struct Waves {
    density: f64,
    kp: C64,
    ks: Option<C64>,
}

impl Waves {
    fn of_fluid(f: &Fluid) -> Self {
        Waves { density: f.density, kp: f.k, ks: None }
    }

    /// `(ω²·u_x, ω²·u_z, σ_zz, σ_xz)` at the wave's own reference face per unit scaled amplitude:
    /// P (`shear` false) or SV travelling in direction `dir` (±1 along z).
    fn column(&self, shear: bool, dir: f64, kt: C64) -> [C64; 4] {
        let i = C64::i();
        let rho = self.density;
        match (shear, self.ks) {
            (false, None) => {
                let alpha = super::vertical(self.kp, kt);
                [i * kt / rho, i * dir * alpha / rho, C64::new(-1.0, 0.0), C64::new(0.0, 0.0)]
            }
            (false, Some(ks)) => {
                let (alpha, ks2) = (super::vertical(self.kp, kt), ks * ks);
                [i * kt / rho, i * dir * alpha / rho, -(1.0 - 2.0 * kt * kt / ks2), -2.0 * dir * kt * alpha / ks2]
            }
            (true, Some(ks)) => {
                let (beta, ks2) = (super::vertical(ks, kt), ks * ks);
                [-i * dir * beta / rho, i * kt / rho, -2.0 * dir * kt * beta / ks2, (beta * beta - kt * kt) / ks2]
            }
            (true, None) => [C64::new(0.0, 0.0); 4],
        }
    }

    /// `exp(i·kz·d)` of the P (`shear` false) or SV wave across a layer of thickness `d`.
    fn across(&self, shear: bool, kt: C64, d: f64) -> C64 {
        let k = if shear { self.ks.unwrap_or(self.kp) } else { self.kp };
        (C64::i() * super::vertical(k, kt) * d).exp()
    }
}

/// The response of `layers` (first face first) from `entry` into `exit` at transverse wavenumber
/// `kt` (rad/m): pressure reflected at the first face and transmitted at the last, per unit
/// incident pressure at the first face. A singular system (a lossless guided mode exactly on
/// `kt`) gives NaN.
pub fn stack_response(entry: Fluid, layers: &[StackLayer], exit: Fluid, kt: C64) -> PlateResponse {
    let zero = C64::new(0.0, 0.0);
    let media: Vec<(Waves, f64)> = layers
        .iter()
        .map(|l| match l {
            StackLayer::Fluid(f, d) => (Waves::of_fluid(f), *d),
            StackLayer::Solid(s, d) => (Waves { density: s.density, kp: s.kp, ks: Some(s.ks) }, *d),
        })
        .collect();
    // Unknowns: R, then per layer (A⁺, A⁻[, B⁺, B⁻]), then T.
    let mut first = Vec::with_capacity(media.len());
    let mut n = 1;
    for (w, _) in &media {
        first.push(n);
        n += if w.ks.is_some() { 4 } else { 2 };
    }
    let t_index = n;
    n += 1;
    let mut m = vec![vec![zero; n]; n];
    let mut rhs = vec![zero; n];
    let mut row = 0;
    // The waves on each side of face `f` (0: the entry's, N: the exit's), as (unknown or the
    // incident wave, medium, shear, direction, factor at this face).
    enum Slot {
        Unknown(usize),
        Incident,
    }
    let sides = |f: usize, before: bool| -> (Waves, Vec<(Slot, bool, f64, C64)>) {
        let one = C64::new(1.0, 0.0);
        if before && f == 0 {
            return (Waves::of_fluid(&entry), vec![(Slot::Incident, false, 1.0, one), (Slot::Unknown(0), false, -1.0, one)]);
        }
        if !before && f == media.len() {
            return (Waves::of_fluid(&exit), vec![(Slot::Unknown(t_index), false, 1.0, one)]);
        }
        let j = if before { f - 1 } else { f };
        let (w, d) = media[j];
        let base = first[j];
        let mut waves = Vec::new();
        for (k, shear) in [(0, false), (2, true)] {
            if shear && w.ks.is_none() {
                continue;
            }
            let e = w.across(shear, kt, d);
            // A⁺ leaves the top face (factor e at the bottom one), A⁻ the bottom face.
            let (down, up) = if before { (e, one) } else { (one, e) };
            waves.push((Slot::Unknown(base + k), shear, 1.0, down));
            waves.push((Slot::Unknown(base + k + 1), shear, -1.0, up));
        }
        (w, waves)
    };
    for f in 0..=media.len() {
        let (wa, a) = sides(f, true);
        let (wb, b) = sides(f, false);
        // (state component, which sides: 0 both (a minus b), 1 a's only, 2 b's only).
        let conditions: &[(usize, u8)] = match (wa.ks.is_some(), wb.ks.is_some()) {
            (true, true) => &[(0, 0), (1, 0), (2, 0), (3, 0)],
            (false, true) => &[(1, 0), (2, 0), (3, 2)],
            (true, false) => &[(1, 0), (2, 0), (3, 1)],
            (false, false) => &[(1, 0), (2, 0)],
        };
        for &(component, which) in conditions {
            for (side, (w, waves), sign) in [(1u8, (&wa, &a), 1.0), (2u8, (&wb, &b), -1.0)] {
                if which != 0 && which != side {
                    continue;
                }
                for (slot, shear, dir, factor) in waves {
                    let v = w.column(*shear, *dir, kt)[component] * *factor * sign;
                    match slot {
                        Slot::Unknown(u) => m[row][*u] += v,
                        Slot::Incident => rhs[row] -= v,
                    }
                }
            }
            row += 1;
        }
    }
    debug_assert_eq!(row, n);
    let x = solve(m, rhs);
    PlateResponse { reflection: x[0], transmission: x[t_index] }
}

/// Gaussian elimination with rows scaled to unit largest entry and partial pivoting; NaN where
/// singular.
fn solve(mut m: Vec<Vec<C64>>, mut rhs: Vec<C64>) -> Vec<C64> {
    let n = rhs.len();
    for (row, b) in m.iter_mut().zip(rhs.iter_mut()) {
        let s = row.iter().map(|v| v.norm()).fold(0.0, f64::max);
        if s > 0.0 {
            row.iter_mut().for_each(|v| *v /= s);
            *b /= s;
        }
    }
    for col in 0..n {
        let p = (col..n).max_by(|&a, &b| m[a][col].norm().total_cmp(&m[b][col].norm())).unwrap_or(col);
        m.swap(col, p);
        rhs.swap(col, p);
        let (pivot, b) = (m[col].clone(), rhs[col]);
        for (row, r) in m.iter_mut().zip(rhs.iter_mut()).skip(col + 1) {
            let f = row[col] / pivot[col];
            if f.norm() != 0.0 {
                row.iter_mut().zip(&pivot).skip(col).for_each(|(v, p)| *v -= f * p);
                *r -= f * b;
            }
        }
    }
    let mut x = vec![C64::new(0.0, 0.0); n];
    for r in (0..n).rev() {
        let s: C64 = (r + 1..n).map(|c| m[r][c] * x[c]).sum();
        x[r] = (rhs[r] - s) / m[r][r];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::super::elastic::plate_response;
    use super::super::layered::{transmission, Layer};
    use super::super::test_fluid as fluid;
    use super::*;
    use std::f64::consts::LN_10;

    const F: f64 = 500e3;

    fn solid(cp: f64, cs: f64, rho: f64, db_cm: f64) -> Solid {
        let a = db_cm * 100.0 * LN_10 / 20.0;
        Solid::new(cp, cs, rho, a, a, F).unwrap()
    }

    fn kt_at(water: &Fluid, deg: f64) -> C64 {
        C64::new(water.k.re * deg.to_radians().sin(), 0.0)
    }

    const ANGLES: [f64; 8] = [0.0, 7.0, 19.0, 31.0, 33.0, 47.0, 62.0, 80.0];

    /// One solid layer is [`plate_response`] (itself held against Brekhovskikh's closed form), to
    /// 1e-10 in reflection and transmission: the same system assembled face by face.
    #[test]
    fn one_solid_layer_is_the_plate() {
        let water = fluid(1500.0, 1000.0, 0.0);
        for (cs, loss) in [(1500.0, 4.0), (1300.0, 0.0)] {
            let s = solid(2800.0, cs, 1850.0, loss);
            for deg in ANGLES {
                let kt = kt_at(&water, deg);
                let (a, b) =
                    (stack_response(water, &[StackLayer::Solid(s, 6.5e-3)], water, kt), plate_response(water, s, 6.5e-3, water, kt));
                assert!((a.transmission - b.transmission).norm() < 1e-10, "{deg}°: {a:?} vs {b:?}");
                assert!((a.reflection - b.reflection).norm() < 1e-10, "{deg}°: {a:?} vs {b:?}");
            }
        }
    }

    /// Fluid layers are [`transmission`]'s transfer matrices (another formulation), to 1e-10.
    #[test]
    fn fluid_layers_are_the_transfer_matrices() {
        let (water, brain) = (fluid(1500.0, 1000.0, 0.0), fluid(1560.0, 1040.0, 3.45));
        let layers = [fluid(1610.0, 1090.0, 2.3), fluid(2800.0, 1850.0, 46.1), fluid(2300.0, 1700.0, 92.1)];
        let d = [4e-3, 1.5e-3, 4e-3];
        for deg in ANGLES {
            let kt = kt_at(&water, deg);
            let stack: Vec<StackLayer> = layers.iter().zip(d).map(|(f, d)| StackLayer::Fluid(*f, d)).collect();
            let fl: Vec<Layer> = layers.iter().zip(d).map(|(f, d)| Layer { thickness: d, fluid: *f }).collect();
            let (a, b) = (stack_response(water, &stack, brain, kt).transmission, transmission(water, &fl, brain, kt));
            assert!((a - b).norm() < 1e-10, "{deg}°: {a} vs {b}");
        }
    }

    /// A solid cut into two layers of the same solid is the uncut solid, to 1e-10: the face
    /// between them (every solid-solid condition: both displacements and both stresses) is
    /// transparent.
    #[test]
    fn a_solid_cut_in_two_is_the_same_solid() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let s = solid(2800.0, 1500.0, 1850.0, 4.0);
        for deg in ANGLES {
            let kt = kt_at(&water, deg);
            let cut = stack_response(water, &[StackLayer::Solid(s, 2.5e-3), StackLayer::Solid(s, 4e-3)], water, kt);
            let whole = plate_response(water, s, 6.5e-3, water, kt);
            assert!((cut.transmission - whole.transmission).norm() < 1e-10, "{deg}°");
            assert!((cut.reflection - whole.reflection).norm() < 1e-10, "{deg}°");
        }
    }

    /// Two solid tables about a solid diploë and a fluid layer, asymmetric, each attenuating by
    /// `loss` times its own dB/cm at 500 kHz (0: lossless).
    fn mixed_stack(loss: f64) -> [StackLayer; 4] {
        [
            StackLayer::Solid(solid(2800.0, 1500.0, 1850.0, 4.0 * loss), 1.5e-3),
            StackLayer::Solid(solid(2300.0, 1100.0, 1700.0, 8.0 * loss), 4e-3),
            StackLayer::Fluid(fluid(1610.0, 1090.0, 2.3 * loss), 0.8e-3),
            StackLayer::Solid(solid(2600.0, 1300.0, 1800.0, 2.0 * loss), 1e-3),
        ]
    }

    /// Lossless solids of different moduli in a stack between water conserve energy:
    /// `|R|² + |T|² = 1` at every propagating angle, to 1e-10.
    #[test]
    fn a_lossless_stack_of_solids_conserves_energy() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let layers = mixed_stack(0.0);
        for deg in (0..90).map(|d| d as f64 + 0.41) {
            let r = stack_response(water, &layers, water, kt_at(&water, deg));
            let e = r.reflection.norm_sqr() + r.transmission.norm_sqr();
            assert!((e - 1.0).abs() < 1e-10, "{deg}°: {e}");
        }
    }

    /// Reciprocity: an asymmetric stack (different solids, a fluid layer among them) between the
    /// same fluid transmits the same from either side, to 1e-10, below and beyond the critical
    /// angles: a solid-solid face between different solids with a condition or a column wrong
    /// would break it (energy conservation alone does not test the phase).
    #[test]
    fn an_asymmetric_stack_transmits_alike_both_ways() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let layers = mixed_stack(1.0);
        let reversed: Vec<StackLayer> = layers.iter().rev().copied().collect();
        for deg in ANGLES {
            let kt = kt_at(&water, deg);
            let (a, b) = (stack_response(water, &layers, water, kt).transmission, stack_response(water, &reversed, water, kt).transmission);
            assert!((a - b).norm() < 1e-10 * a.norm().max(1e-6), "{deg}°: {a} vs {b}");
        }
    }

    /// At normal incidence no shear is excited: solid layers act as the fluids of their
    /// compressional wave, to 1e-12.
    #[test]
    fn normal_incidence_sees_fluids() {
        let (water, brain) = (fluid(1500.0, 1000.0, 0.0), fluid(1560.0, 1040.0, 3.45));
        let (c, t) = (solid(2800.0, 1500.0, 1850.0, 4.0), solid(2300.0, 1100.0, 1700.0, 8.0));
        let stack = [StackLayer::Solid(c, 1.5e-3), StackLayer::Solid(t, 4e-3), StackLayer::Solid(c, 1e-3)];
        let fl = [
            Layer { thickness: 1.5e-3, fluid: Fluid { k: c.kp, density: 1850.0 } },
            Layer { thickness: 4e-3, fluid: Fluid { k: t.kp, density: 1700.0 } },
            Layer { thickness: 1e-3, fluid: Fluid { k: c.kp, density: 1850.0 } },
        ];
        let zero = C64::new(0.0, 0.0);
        let (a, b) = (stack_response(water, &stack, brain, zero).transmission, transmission(water, &fl, brain, zero));
        assert!((a - b).norm() < 1e-12, "{a} vs {b}");
    }
}
