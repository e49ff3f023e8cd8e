//! The bowl through planar fluid layers normal to its axis: exact for the Rayleigh bowl.
//!
//! Weyl's expansion of each point source, averaged over the cap's rings, gives the field in the
//! bowl's fluid as an axisymmetric angular spectrum (Hankel transform):
//!
//! `p(ρ, z)/p0 = k·R² ∫ (kt dkt / kz) · J0(kt·ρ) · B(kt) · exp(i·kz·(z - z1))`,
//! `B(kt) = ∫_0^{β_max} sin β · J0(kt·R·sin β) · exp(i·kz·(z1 - z'(β))) dβ`,
//!
//! for `z` beyond the cap's rim (`z'(β) = R·(1 - cos β)`), with `kz = sqrt(k² - kt²)`; the
//! propagating part (`kt = k·sin ψ`, `kt dkt/kz = k·sin ψ dψ`) and the evanescent part
//! (`kz = i·κ`, `kt dkt/kz = -i dκ`) are integrated by Gauss–Legendre. Beyond the last face each
//! plane wave carries the stack's pressure transmission `t(kt)` from 2x2 transfer matrices of
//! pressure and normal particle velocity (every reflection inside the layers, total reflection
//! beyond the critical angle, evanescent waves, attenuation as a complex wavenumber; Brekhovskikh,
//! *Waves in Layered Media*, 1980), and then the exit fluid's `exp(i·kz_exit·(z - z_N))`.

use super::special::{bessel_j0, composite_gauss};
use super::{Bowl, Fluid};
use crate::error::{HasError, Result};
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use std::f64::consts::PI;

/// One planar layer: its thickness (m) and fluid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer {
    /// Thickness, m.
    pub thickness: f64,
    /// The fluid filling it.
    pub fluid: Fluid,
}

/// The bowl's field beyond a stack of layers whose first face is at `z1` (m), precomputed as
/// the spectrum leaving the last face.
#[derive(Debug, Clone)]
pub struct LayeredBowl {
    /// z of the last face (m): the field is given at and beyond it.
    pub exit_face: f64,
    exit: Fluid,
    /// Per spectral node: `kt`, the node's weight times `k·(kt dkt/kz)·R²·B(kt)·t(kt)`.
    nodes: Vec<(f64, C64)>,
}

/// Quadrature sizes: panels of 24 Gauss points over the propagating angles (the spectrum
/// oscillates about `k·a/(2π)` times over them, and the phase `k·z` ~30 times), 16 over the
/// evanescent range, 30 panels of 20 points over the cap. Tested by halving against the
/// direct Rayleigh sum.
const PROPAGATING_PANELS: usize = 48;
const EVANESCENT_PANELS: usize = 12;
const CAP_PANELS: usize = 30;

impl LayeredBowl {
    /// The bowl in `water` (lossless: the bowl's own fluid), the stack `layers` from `z1` on,
    /// then `exit` (equal to `water` with no layers). `z1` must lie beyond the cap's rim.
    pub fn new(bowl: &Bowl, water: Fluid, z1: f64, layers: &[Layer], exit: Fluid) -> Result<Self> {
        let rim = bowl.depth();
        if !(z1 > rim) {
            return Err(HasError::invalid("z1", format!("the first face must lie beyond the bowl's rim at {:.2} mm", rim * 1e3)));
        }
        if (water.k.re - bowl.k).abs() > 1e-9 * bowl.k || water.k.im != 0.0 {
            return Err(HasError::invalid("water", "must be the lossless fluid of the bowl's wavenumber"));
        }
        if let Some(l) = layers.iter().find(|l| !(l.thickness > 0.0)) {
            return Err(HasError::invalid("layers", format!("thickness {} m is not positive", l.thickness)));
        }
        let k = bowl.k;
        let rings = bowl.rings(CAP_PANELS);
        // The evanescent waves decay at least as exp(-κ·(z1 - rim)) before the first face.
        let kappa_max = 46.0 / (z1 - rim);
        let mut measure: Vec<(f64, C64)> = composite_gauss(PROPAGATING_PANELS, 24, 0.0, 0.5 * PI)
            .into_iter()
            .map(|(psi, w)| (k * psi.sin(), C64::new(w * k * psi.sin(), 0.0)))
            .collect();
        measure.extend(
            composite_gauss(EVANESCENT_PANELS, 16, 0.0, kappa_max)
                .into_iter()
                .map(|(kappa, w)| ((k * k + kappa * kappa).sqrt(), C64::new(0.0, -w))),
        );
        let nodes = measure
            .into_par_iter()
            .map(|(kt, dm)| {
                let ktc = C64::new(kt, 0.0);
                let kz = water.kz(ktc);
                let b: C64 = rings.iter().map(|&(rho, z, w)| w * bessel_j0(kt * rho) * (C64::i() * kz * (z1 - z)).exp()).sum();
                let t = transmission(water, layers, exit, ktc);
                (kt, dm * k * b * t)
            })
            .collect();
        let exit_face = z1 + layers.iter().map(|l| l.thickness).sum::<f64>();
        Ok(LayeredBowl { exit_face, exit, nodes })
    }

    /// `p/p0` at radius `rho` from the axis and depth `z` (m, at or beyond the exit face).
    pub fn pressure(&self, rho: f64, z: f64) -> Result<C64> {
        if z < self.exit_face - 1e-12 {
            return Err(HasError::invalid(
                "z",
                format!("{:.3} mm lies before the stack's exit face at {:.3} mm", z * 1e3, self.exit_face * 1e3),
            ));
        }
        let d = z - self.exit_face;
        Ok(self.nodes.iter().map(|&(kt, a)| a * bessel_j0(kt * rho) * (C64::i() * self.exit.kz(C64::new(kt, 0.0)) * d).exp()).sum())
    }
}

/// Pressure transmission `t` of a plane wave of transverse wavenumber `kt` from `entry` through
/// `layers` into `exit` (pressure at the exit face per unit incident pressure at the first):
/// with `M = Π [[cos qd, i·sin qd / Y], [i·Y·sin qd, cos qd]]`, `Y = kz/(omega·rho)`, incident
/// 1 and reflected r, `(t, Y_e·t) = M·(1 + r, Y_w·(1 - r))`. Only ratios of admittances enter
/// `t`, so `Y = kz/rho` is used (omega cancels).
pub fn transmission(entry: Fluid, layers: &[Layer], exit: Fluid, kt: C64) -> C64 {
    let admittance = |f: &Fluid| f.kz(kt) / f.density;
    let one = C64::new(1.0, 0.0);
    let zero = C64::new(0.0, 0.0);
    let mut m = [[one, zero], [zero, one]];
    for l in layers {
        let q = l.fluid.kz(kt);
        let y = admittance(&l.fluid);
        let (c, s) = ((q * l.thickness).cos(), (q * l.thickness).sin());
        let step = [[c, C64::i() * s / y], [C64::i() * y * s, c]];
        m = [
            [step[0][0] * m[0][0] + step[0][1] * m[1][0], step[0][0] * m[0][1] + step[0][1] * m[1][1]],
            [step[1][0] * m[0][0] + step[1][1] * m[1][0], step[1][0] * m[0][1] + step[1][1] * m[1][1]],
        ];
    }
    let (yw, ye) = (admittance(&entry), admittance(&exit));
    let (a, b) = (m[0][0] + m[0][1] * yw, m[0][0] - m[0][1] * yw);
    let (c, d) = (m[1][0] + m[1][1] * yw, m[1][0] - m[1][1] * yw);
    let den = ye * b - d;
    if den.norm() == 0.0 {
        // Water to water through nothing at grazing incidence (kz = 0): everything passes.
        return one;
    }
    let r = (c - ye * a) / den;
    a + b * r
}

#[cfg(test)]
mod tests {
    use super::super::test_fluid as fluid;
    use super::*;

    /// In water alone the spectrum gives back the direct Rayleigh sum, on and off the axis:
    /// 1e-4 of the focal pressure (the quadratures' accuracy, checked by the direct sum's own).
    #[test]
    fn water_spectrum_matches_the_rayleigh_sum() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bowl = Bowl::new(64e-3, 32e-3, water.k.re).unwrap();
        let s = LayeredBowl::new(&bowl, water, 26e-3, &[], water).unwrap();
        let peak = bowl.oneil(64e-3);
        for (rho, z) in [(0.0, 30e-3), (0.0, 62e-3), (2e-3, 64e-3), (6e-3, 70e-3), (0.0, 90e-3)] {
            let a = s.pressure(rho, z).unwrap();
            let b = bowl.rayleigh([rho, 0.0, z], 30, 720);
            assert!((a - b).norm() < 1e-4 * peak, "({rho}, {z}): {a} vs {b}");
        }
    }

    /// The stack at normal incidence against the closed form of one lossless layer,
    /// `t = 1 / (cos qd - i/2·(Z_l/Z_w + Z_w/Z_l)·sin qd)` (water on both sides), and a layer of
    /// water passes everything with its phase.
    #[test]
    fn transmission_of_one_layer_matches_its_closed_form() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bone = fluid(2800.0, 1850.0, 0.0);
        let d = 6.5e-3;
        let t = transmission(water, &[Layer { thickness: d, fluid: bone }], water, C64::new(0.0, 0.0));
        let ratio = 2800.0 * 1850.0 / 1.5e6;
        let qd = bone.k.re * d;
        let closed = 1.0 / C64::new(qd.cos(), -0.5 * (ratio + 1.0 / ratio) * qd.sin());
        assert!((t - closed).norm() < 1e-12, "{t} vs {closed}");
        let t = transmission(water, &[Layer { thickness: d, fluid: water }], water, C64::new(1000.0, 0.0));
        assert!((t - (C64::i() * water.kz(C64::new(1000.0, 0.0)) * d).exp()).norm() < 1e-12);
    }
}
