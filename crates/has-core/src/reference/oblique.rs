//! The bowl through a planar plate tilted against its axis: exact for the Rayleigh bowl.
//!
//! The plate's faces are planes of unit normal `n` (the axis `z` turned by `tilt` about `y`), the
//! first through the axis point `(0, 0, z1)`. In the plate's frame (`x'`, `y'` along the face,
//! `z' = n·(r - (0, 0, z1))`) Weyl's expansion of each point of the cap gives the field before
//! the plate as plane waves of wave vector `K' = k·(sin ψ cos φ, sin ψ sin φ, cos ψ)`:
//!
//! `p(r') = (k²/2π) ∫∫ sin ψ dψ dφ · S(K') · exp(i·K'·r')`, `S(K') = Σ_rings w·J0(|K⊥|·ρ)·exp(-i·Kz·(z - z1))`,
//!
//! where `K = (K⊥, Kz)` is the same wave vector in the bowl's frame and each ring (radius `ρ`,
//! depth `z`, weight `w`) is summed over its azimuth in closed form. Each plane wave meets the
//! plate at `sin θ = sin ψ` and leaves the last face (`z' = D`) with the plate's exact
//! plane-wave transmission `t(k·sin ψ)` ([`super::layered::transmission`] for fluid layers,
//! [`super::elastic::plate_response`] for a solid with shear); beyond it
//! `p = (k²/2π) ∫∫ sin ψ dψ dφ · S · t · exp(i·(K'⊥·r'⊥ + kz_exit·(z' - D)))`.
//! Evanescent waves are left out: from the cap they decay before the plate, and any they excite
//! in it decay again in the exit fluid; the field is given from two wavelengths past the last
//! face. Gauss–Legendre in `ψ`, the trapezoidal rule in `φ` (exact for a periodic band-limited
//! integrand once the number of azimuths exceeds the largest `k·|r'⊥|` plus a margin).

use super::elastic::{plate_response, Solid};
use super::layered::{transmission, Layer};
use super::special::{bessel_j0, composite_gauss};
use super::{Bowl, Fluid};
use crate::error::{HasError, Result};
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use std::f64::consts::PI;

/// What the plate is made of.
#[derive(Debug, Clone, PartialEq)]
pub enum Plate {
    /// Fluid layers, first face first.
    Fluid(Vec<Layer>),
    /// One isotropic viscoelastic solid of this thickness (m).
    Solid(Solid, f64),
}

impl Plate {
    /// Total thickness, m.
    pub fn thickness(&self) -> f64 {
        match self {
            Plate::Fluid(layers) => layers.iter().map(|l| l.thickness).sum(),
            Plate::Solid(_, d) => *d,
        }
    }

    /// Pressure at the last face per unit incident pressure at the first, at transverse
    /// wavenumber `kt` (rad/m).
    pub fn transmission(&self, entry: Fluid, exit: Fluid, kt: f64) -> C64 {
        let kt = C64::new(kt, 0.0);
        match self {
            Plate::Fluid(layers) => transmission(entry, layers, exit, kt),
            Plate::Solid(solid, d) => plate_response(entry, *solid, *d, exit, kt).transmission,
        }
    }
}

/// Quadrature sizes, tested by halving against the direct Rayleigh sum and the axisymmetric
/// solution: 24-point Gauss panels over `ψ` in `[0, π/2]`, cap rings of 20 Gauss points per
/// panel, and azimuths for `k·(reach + extent) + 48` (`reach` the largest lateral distance, in
/// the plate's frame, of the points asked for, `extent` the cap's).
const PSI_PANELS: usize = 16;
const CAP_PANELS: usize = 10;

/// The bowl's field beyond a tilted plate, precomputed as the plane waves leaving it.
#[derive(Debug, Clone)]
pub struct ObliqueBowl {
    /// Tilt of the plate's normal from the axis about `y`, rad.
    pub tilt: f64,
    /// Axis point of the first face, m.
    pub z1: f64,
    /// Plate thickness, m.
    pub thickness: f64,
    /// Largest lateral distance from the axis point, in the plate's frame, of a point the
    /// quadrature resolves, m.
    pub reach: f64,
    /// Per plane wave: `K'x`, `K'y` (rad/m), the exit fluid's `kz` and the amplitude times weight.
    nodes: Vec<(f64, f64, C64, C64)>,
}

impl ObliqueBowl {
    /// The bowl in `water` (lossless), the plate's first face through `(0, 0, z1)` with its normal
    /// turned by `tilt` (rad, |tilt| < 60°) about `y`, then `exit`; the field resolved within
    /// `reach` (m) of the axis point in the plate's frame. The whole cap must lie before the
    /// first face.
    pub fn new(bowl: &Bowl, water: Fluid, z1: f64, tilt: f64, plate: &Plate, exit: Fluid, reach: f64) -> Result<Self> {
        if (water.k.re - bowl.k).abs() > 1e-9 * bowl.k || water.k.im != 0.0 {
            return Err(HasError::invalid("water", "must be the lossless fluid of the bowl's wavenumber"));
        }
        if !(tilt.abs() < PI / 3.0) {
            return Err(HasError::invalid("tilt", "must be below 60 degrees"));
        }
        if !(plate.thickness() > 0.0) || !(reach > 0.0) {
            return Err(HasError::invalid("plate", "thickness and reach must be positive"));
        }
        let (s, c) = tilt.sin_cos();
        // The cap's rim, the plate's side of it, must lie before the first face (the rim's
        // point towards +x is the nearest).
        let rim = [bowl.aperture_radius, bowl.depth()];
        if s.abs() * rim[0] + c * (rim[1] - z1) >= -1e-4 {
            return Err(HasError::invalid("z1", "the tilted plate must clear the bowl's rim by at least 0.1 mm"));
        }
        let k = bowl.k;
        let rings = bowl.rings(CAP_PANELS);
        let j0 = J0Table::new(k * bowl.aperture_radius + 1.0);
        // The integrand's bandwidth in φ: the cap's and the points' lateral extents in the
        // plate's frame, times k.
        let extent = rings.iter().map(|&(rho, z, _)| rho * c + (z - z1).abs() * s.abs()).fold(0.0, f64::max);
        let azimuths = 4 * ((k * (reach + extent) + 48.0) / 4.0).ceil() as usize;
        let psis = composite_gauss(PSI_PANELS, 24, 0.0, 0.5 * PI);
        let d = plate.thickness();
        let nodes: Vec<(f64, f64, C64, C64)> = psis
            .par_iter()
            .flat_map_iter(|&(psi, wpsi)| {
                let (sp, cp) = psi.sin_cos();
                let t = plate.transmission(water, exit, k * sp);
                let kz_exit = exit.kz(C64::new(k * sp, 0.0));
                let rings = &rings;
                let j0 = &j0;
                (0..azimuths).map(move |m| {
                    let phi = 2.0 * PI * m as f64 / azimuths as f64;
                    let (kx, ky, kz) = (k * sp * phi.cos(), k * sp * phi.sin(), k * cp);
                    // The same wave vector in the bowl's frame: x' = (cos t, 0, -sin t),
                    // y' = y, n = (sin t, 0, cos t).
                    let (bx, bz) = (kx * c + kz * s, -kx * s + kz * c);
                    let perp = bx.hypot(ky);
                    let sum: C64 = rings.iter().map(|&(rho, z, w)| w * j0.at(perp * rho) * C64::from_polar(1.0, -bz * (z - z1))).sum();
                    let weight = k * k / (2.0 * PI) * sp * wpsi * 2.0 * PI / azimuths as f64;
                    (kx, ky, kz_exit, sum * t * weight)
                })
            })
            .collect();
        Ok(ObliqueBowl { tilt, z1, thickness: d, reach, nodes })
    }

    /// The point `r` (m, bowl frame) in the plate's frame.
    pub fn plate_frame(&self, r: [f64; 3]) -> [f64; 3] {
        let (s, c) = self.tilt.sin_cos();
        let (x, z) = (r[0], r[2] - self.z1);
        [x * c - z * s, r[1], x * s + z * c]
    }

    /// Whether the field is given at `r` (m, bowl frame): at least 3 mm past the last face and
    /// within `reach`.
    pub fn covers(&self, r: [f64; 3]) -> bool {
        let [x, y, z] = self.plate_frame(r);
        z >= self.thickness + 3e-3 && x.hypot(y) <= self.reach
    }

    /// `p/p0` at `r` (m, bowl frame): at least 3 mm past the last face and within `reach`.
    pub fn pressure(&self, r: [f64; 3]) -> Result<C64> {
        let [x, y, z] = self.plate_frame(r);
        if z < self.thickness + 3e-3 {
            return Err(HasError::invalid("r", "must lie at least 3 mm past the plate's last face"));
        }
        if x.hypot(y) > self.reach {
            return Err(HasError::invalid("r", format!("lies beyond the {:.0} mm the spectrum resolves", self.reach * 1e3)));
        }
        let dz = z - self.thickness;
        Ok(self.nodes.iter().map(|&(kx, ky, kz, a)| a * (C64::i() * (kz * dz + C64::new(kx * x + ky * y, 0.0))).exp()).sum())
    }

    /// The peak of `|p/p0|` in the plane `y = 0` (the plane of the tilt, where symmetry puts it)
    /// within `half_x` across and `half_z` along of `centre` (m; points the field is not given at
    /// are passed over): a 0.5 mm search, then a parabola through the neighbours on each axis.
    /// Returns the point and `|p/p0|` there.
    pub fn peak(&self, centre: [f64; 3], half_x: f64, half_z: f64) -> Result<([f64; 3], f64)> {
        let h = 0.5e-3;
        let (nx, nz) = ((half_x / h).round() as i64, (half_z / h).round() as i64);
        let points: Vec<[f64; 3]> =
            (-nz..=nz).flat_map(|kz| (-nx..=nx).map(move |kx| [centre[0] + kx as f64 * h, 0.0, centre[2] + kz as f64 * h])).collect();
        let values: Vec<f64> = points.par_iter().map(|&p| self.pressure(p).map_or(0.0, |v| v.norm())).collect();
        let best = (0..values.len()).max_by(|&a, &b| values[a].total_cmp(&values[b])).unwrap_or(0);
        let mut point = points[best];
        for axis in [0, 2] {
            let at = |d: f64| {
                let mut p = point;
                p[axis] += d;
                self.pressure(p).map(|v| v.norm())
            };
            let (a, b, c) = (at(-h)?, at(0.0)?, at(h)?);
            let den = a - 2.0 * b + c;
            if den < 0.0 {
                point[axis] += (0.5 * h * (a - c) / den).clamp(-h, h);
            }
        }
        let value = self.pressure(point)?.norm();
        Ok((point, value))
    }
}

/// `J0` on a table of step 0.01 with four-point Lagrange interpolation (error below 1e-9): the
/// spectrum needs it some 1e7 times.
struct J0Table {
    values: Vec<f64>,
}

const J0_STEP: f64 = 0.01;

impl J0Table {
    fn new(max: f64) -> Self {
        let n = (max / J0_STEP).ceil() as usize + 4;
        J0Table { values: (0..n).map(|i| bessel_j0(i as f64 * J0_STEP)).collect() }
    }

    fn at(&self, x: f64) -> f64 {
        let u = x.abs() / J0_STEP;
        let i = (u.floor() as usize).clamp(1, self.values.len() - 3);
        let t = u - i as f64;
        let v = &self.values[i - 1..i + 3];
        // Lagrange through the nodes at -1, 0, 1, 2.
        -t * (t - 1.0) * (t - 2.0) / 6.0 * v[0] + (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0 * v[1] - (t + 1.0) * t * (t - 2.0) / 2.0 * v[2]
            + (t + 1.0) * t * (t - 1.0) / 6.0 * v[3]
    }
}

#[cfg(test)]
mod tests {
    use super::super::layered::LayeredBowl;
    use super::super::test_fluid as fluid;
    use super::*;

    fn bowl(water: &Fluid) -> Bowl {
        Bowl::new(64e-3, 32e-3, water.k.re).unwrap()
    }

    /// A plate of water at 25°: the plane waves give back the direct Rayleigh sum beyond it, on
    /// and off the axis, to 1.5e-3 of the focal pressure: the evanescent waves left out (which
    /// a water plate passes, and bone does not) are about 1e-3 here, the quadratures' error
    /// below 1e-4 (see the untilted test).
    #[test]
    fn a_tilted_plate_of_water_gives_the_rayleigh_sum() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let b = bowl(&water);
        let plate = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: water }]);
        let s = ObliqueBowl::new(&b, water, 30e-3, 25f64.to_radians(), &plate, water, 30e-3).unwrap();
        let peak = b.oneil(64e-3);
        for r in [[0.0, 0.0, 50e-3], [0.0, 0.0, 64e-3], [3e-3, -2e-3, 62e-3], [-8e-3, 4e-3, 75e-3]] {
            let a = s.pressure(r).unwrap();
            let e = b.rayleigh(r, 30, 720);
            assert!((a - e).norm() < 1.5e-3 * peak, "{r:?}: {a} vs {e}");
        }
    }

    /// Untilted, a cortical plate's field equals the axisymmetric layered solution (Hankel
    /// transform, an independent quadrature), to 2e-4 of the water focus.
    #[test]
    fn an_untilted_plate_gives_the_layered_solution() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bone = fluid(2800.0, 1850.0, 8.0);
        let b = bowl(&water);
        let layers = vec![Layer { thickness: 6.5e-3, fluid: bone }];
        let s = ObliqueBowl::new(&b, water, 30e-3, 0.0, &Plate::Fluid(layers.clone()), water, 20e-3).unwrap();
        let l = LayeredBowl::new(&b, water, 30e-3, &layers, water).unwrap();
        let peak = b.oneil(64e-3);
        for (rho, z) in [(0.0, 45e-3), (0.0, 58e-3), (2e-3, 60e-3), (5e-3, 70e-3)] {
            let a = s.pressure([rho, 0.0, z]).unwrap();
            let e = l.pressure(rho, z).unwrap();
            assert!((a - e).norm() < 2e-4 * peak, "({rho}, {z}): {a} vs {e}");
        }
    }

    /// Mirror symmetry: the plate turned by -θ gives the field of +θ mirrored in x, to 1e-9 of
    /// the water focus (the same quadrature on mirrored nodes).
    #[test]
    fn opposite_tilts_mirror_the_field() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bone = fluid(2800.0, 1850.0, 8.0);
        let b = bowl(&water);
        let plate = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: bone }]);
        let t = 15f64.to_radians();
        let plus = ObliqueBowl::new(&b, water, 30e-3, t, &plate, water, 20e-3).unwrap();
        let minus = ObliqueBowl::new(&b, water, 30e-3, -t, &plate, water, 20e-3).unwrap();
        let peak = b.oneil(64e-3);
        for r in [[4e-3, 1e-3, 58e-3], [-3e-3, -2e-3, 66e-3]] {
            let (a, m) = (plus.pressure(r).unwrap(), minus.pressure([-r[0], r[1], r[2]]).unwrap());
            assert!((a - m).norm() < 1e-9 * peak, "{r:?}: {a} vs {m}");
        }
    }

    #[test]
    fn a_plate_through_the_bowl_is_refused() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let plate = Plate::Fluid(vec![Layer { thickness: 6.5e-3, fluid: water }]);
        assert!(ObliqueBowl::new(&bowl(&water), water, 12e-3, 30f64.to_radians(), &plate, water, 20e-3).is_err());
    }
}
