//! The bowl through a spherical fluid shell centred on its axis: exact for the Rayleigh bowl.
//!
//! About the shell's centre `C` (on the axis at `z = centre`), each point source of the cap
//! expands as `exp(ik|r - r'|)/|r - r'| = i·k·Σ_n (2n+1)·j_n(k·r)·h_n(k·r')·P_n(cos γ)` for
//! `r < r'` (`h_n = j_n + i·y_n`, outgoing); averaged over a ring of the cap,
//! `P_n(cos γ) → P_n(cos θ)·P_n(cos θ')`. Inside the sphere through the nearest point of the cap
//! the incident field is therefore
//!
//! `p_inc/p0 = Σ_n c_n·j_n(k·r)·P_n(cos θ)`, `c_n = k²·R²·(2n+1) ∫ sin β · h_n(k·r'(β))·P_n(cos θ'(β)) dβ`.
//!
//! A shell `a < r < b` of fluid 1 between the water outside and fluid 2 inside scales each order
//! inside: `p/p0 = Σ_n T_n·c_n·j_n(k_2·r)·P_n(cos θ)` for `r < a`, from continuity of pressure
//! and radial velocity `v = (1/(i·omega·rho))·∂p/∂r` at both surfaces:
//!
//! - [`Passes::One`]: the converging wave crosses the near wall once (every reverberation inside
//!   the wall, none across the cavity): inside, the incoming part `h_n^(2)` of the incident
//!   `j_n = (h_n^(1) + h_n^(2))/2` is transmitted and continues through the centre as the
//!   regular `j_n`; the field of a cap of the shell around the focus, where the beam meets no far
//!   wall;
//! - [`Passes::Closed`]: the closed shell with its cavity (every reflection from the far wall).

use super::solid_shell::{self, kinds, SolidShell};
use super::special::{derivatives, legendre, spherical_functions, spherical_hankels, spherical_j};
use super::{Bowl, Fluid};
use crate::error::{require_positive, HasError, Result};
use num_complex::Complex64 as C64;
use rayon::prelude::*;

/// Which waves inside the shell the solution keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Passes {
    /// The near wall crossed once, with its own reverberation (a cap around the beam's path).
    One,
    /// The closed shell: the cavity's reflections too.
    Closed,
}

/// A spherical shell about `(0, 0, centre)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shell {
    /// z of the centre, m.
    pub centre: f64,
    /// Inner radius a, m.
    pub inner_radius: f64,
    /// Outer radius b, m.
    pub outer_radius: f64,
    /// The wall's fluid.
    pub wall: Fluid,
    /// The fluid inside.
    pub interior: Fluid,
}

/// The bowl's field inside a shell, as the coefficients `T_n·c_n` of its expansion.
#[derive(Debug, Clone)]
pub struct ShellBowl {
    /// z of the shell's centre, m.
    centre: f64,
    /// The interior's wavenumber, rad/m.
    interior_k: C64,
    /// `T_n·c_n`, n = 0..=N.
    coefficients: Vec<C64>,
    /// The largest distance from the centre the expansion is kept accurate for, m.
    pub reach: f64,
}

impl ShellBowl {
    /// The expansion for points within `reach` (m) of the shell's centre; `reach` must lie inside
    /// the inner radius and inside every point of the cap.
    pub fn new(bowl: &Bowl, water: Fluid, shell: Shell, passes: Passes, reach: f64) -> Result<Self> {
        let geometry = (shell.centre, shell.inner_radius, shell.outer_radius);
        Self::expanded(bowl, water, geometry, shell.interior, reach, |n_max| transmissions(water, &shell, passes, n_max))
    }

    /// The same through a solid wall, P and SV converted at both surfaces
    /// ([`super::solid_shell`]).
    pub fn solid(bowl: &Bowl, water: Fluid, shell: SolidShell, passes: Passes, reach: f64) -> Result<Self> {
        let geometry = (shell.centre, shell.inner_radius, shell.outer_radius);
        Self::expanded(bowl, water, geometry, shell.interior, reach, |n_max| solid_shell::transmissions(water, &shell, passes, n_max))
    }

    /// The incident expansion about the centre of the shell `(centre, a, b)`, each order scaled
    /// by `transmissions(n_max)`.
    fn expanded(
        bowl: &Bowl,
        water: Fluid,
        (centre, inner_radius, outer_radius): (f64, f64, f64),
        interior: Fluid,
        reach: f64,
        transmissions: impl FnOnce(usize) -> Vec<C64>,
    ) -> Result<Self> {
        require_positive("inner_radius", inner_radius)?;
        if !(outer_radius > inner_radius) {
            return Err(HasError::invalid("outer_radius", "must exceed the inner radius"));
        }
        if !(reach > 0.0 && reach < inner_radius) {
            return Err(HasError::invalid("reach", "must lie between 0 and the inner radius"));
        }
        let rings = bowl.rings(40);
        let nearest = rings.iter().map(|&(rho, z, _)| rho.hypot(z - centre)).fold(f64::INFINITY, f64::min);
        if !(nearest > outer_radius) {
            return Err(HasError::invalid("outer_radius", "the bowl must lie outside the shell"));
        }
        // Orders: j_n(k·r) is negligible beyond n = k·reach + a margin of its turning region.
        let kr = water.k.re.max(interior.k.re) * reach;
        let n_max = (kr + 8.0 * kr.cbrt() + 30.0).ceil() as usize;
        let k = bowl.k;
        let incident = rings
            .par_iter()
            .map(|&(rho, z, w)| {
                let r = rho.hypot(z - centre);
                let (h, _) = spherical_hankels(n_max, C64::new(k * r, 0.0));
                let p = legendre(n_max, (z - centre) / r);
                (0..=n_max).map(|n| w * h[n] * p[n]).collect::<Vec<C64>>()
            })
            .reduce(|| vec![C64::new(0.0, 0.0); n_max + 1], |a, b| a.iter().zip(&b).map(|(x, y)| x + y).collect());
        let t = transmissions(n_max);
        let coefficients = (0..=n_max).map(|n| k * k * (2 * n + 1) as f64 * incident[n] * t[n]).collect();
        Ok(ShellBowl { centre, interior_k: interior.k, coefficients, reach })
    }

    /// `p/p0` at radius `rho` from the axis and depth `z` (m), within `reach` of the centre.
    pub fn pressure(&self, rho: f64, z: f64) -> Result<C64> {
        let r = rho.hypot(z - self.centre);
        if r > self.reach * (1.0 + 1e-12) {
            return Err(HasError::invalid(
                "point",
                format!("lies {:.2} mm from the centre, beyond the {:.2} mm reach", r * 1e3, self.reach * 1e3),
            ));
        }
        let n_max = self.coefficients.len() - 1;
        if r == 0.0 {
            return Ok(self.coefficients[0]);
        }
        let j = spherical_j(n_max, self.interior_k * r);
        let p = legendre(n_max, (z - self.centre) / r);
        Ok((0..=n_max).map(|n| self.coefficients[n] * j[n] * p[n]).sum())
    }
}

/// `T_n`, n = 0..=n_max: with `W(r) = [[f_n(k1 r), g_n(k1 r)], [Y1·f_n'(k1 r), Y1·g_n'(k1 r)]]`
/// (`Y = k/(i·omega·rho)`, scaled by a common omega; `f, g` the wall's pair of
/// [`super::solid_shell`]'s `kinds`: `h^(1), h^(2)` where the order propagates through the wall,
/// `j, y` where it tunnels) carrying `(p, v)` across the wall,
/// `q = W(b)·W(a)⁻¹·u` for the inside wave `u` (`h^(2)` for one pass, `j` closed), and outside
/// `τ·q = e_in + s·e_1` with `e_1 = (h^(1), Y0·h^(1)')` at `k0·b`: `τ = det[e_in, e_1] / det[q, e_1]`.
/// For one pass `e_in` is the incoming `(h^(2), Y0·h^(2)')` and `T_n = τ` times the ratio that
/// completes the regular interior field (1, since `j = (h^(1) + h^(2))/2` both sides); closed, `e_in`
/// is `(j, Y0·j')` itself.
pub(super) fn transmissions(water: Fluid, shell: &Shell, passes: Passes, n_max: usize) -> Vec<C64> {
    let (a, b) = (shell.inner_radius, shell.outer_radius);
    let admittance = |f: &Fluid| f.k / (C64::i() * f.density);
    let (y0, y1, y2) = (admittance(&water), admittance(&shell.wall), admittance(&shell.interior));
    // `[j, y, h^(1), h^(2)]` and their derivatives, each one order beyond n_max for them.
    let seq = |z: C64| {
        spherical_functions(n_max + 1, z).map(|f| {
            let d = derivatives(&f, z);
            (f, d)
        })
    };
    let (outside, wall_b, wall_a, interior) = (seq(water.k * b), seq(shell.wall.k * b), seq(shell.wall.k * a), seq(shell.interior.k * a));
    // `(value, admittance × derivative)` of kind `which` (0: j, 1: y, 2: h^(1), 3: h^(2)).
    let state = |s: &[(Vec<C64>, Vec<C64>); 4], which: usize, adm: C64, n: usize| [s[which].0[n], adm * s[which].1[n]];
    let det = |u: [C64; 2], v: [C64; 2]| u[0] * v[1] - u[1] * v[0];
    (0..=n_max)
        .map(|n| {
            let inside = match passes {
                Passes::One => state(&interior, 3, y2, n),
                Passes::Closed => state(&interior, 0, y2, n),
            };
            // The wall's pair (`solid_shell::kinds`): travelling waves where the order
            // propagates through the wall, j and y where it tunnels.
            let [f, g] = kinds(shell.wall.k, a, n);
            let (fa, ga) = (state(&wall_a, f, y1, n), state(&wall_a, g, y1, n));
            // W(a)⁻¹ = [[Y1·g', -g], [-Y1·f', f]] / (Y1·(f·g' - f'·g)).
            let w_det = det(fa, ga);
            let alpha = (ga[1] * inside[0] - ga[0] * inside[1]) / w_det;
            let beta = (-fa[1] * inside[0] + fa[0] * inside[1]) / w_det;
            let (fb, gb) = (state(&wall_b, f, y1, n), state(&wall_b, g, y1, n));
            let q = [alpha * fb[0] + beta * gb[0], alpha * fb[1] + beta * gb[1]];
            let e1 = state(&outside, 2, y0, n);
            let e_in = match passes {
                Passes::One => state(&outside, 3, y0, n),
                Passes::Closed => state(&outside, 0, y0, n),
            };
            let t = det(e_in, e1) / det(q, e1);
            // Where y_n overflows (orders well beyond k·r in the wall: waves past the critical
            // angle, tunnelling through it as exp(-κ·d) with κ > k_wall) the order carries
            // nothing through.
            if t.is_finite() {
                t
            } else {
                C64::new(0.0, 0.0)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::layered::{transmission, Layer, LayeredBowl};
    use super::super::test_fluid as fluid;
    use super::*;

    /// A shell of water changes nothing, and the expansion gives back the direct Rayleigh sum
    /// about a centre on the focus and one 41 mm beyond it: 1e-4 of the focal pressure.
    #[test]
    fn a_water_shell_gives_the_rayleigh_sum() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bowl = Bowl::new(64e-3, 32e-3, water.k.re).unwrap();
        let peak = bowl.oneil(64e-3);
        for (centre, inner, points) in [
            (64e-3, 30e-3, vec![(0.0, 64e-3), (3e-3, 60e-3), (0.0, 54e-3), (8e-3, 72e-3)]),
            (105e-3, 68.5e-3, vec![(0.0, 64e-3), (2e-3, 54e-3), (0.0, 74e-3), (6e-3, 66e-3)]),
        ] {
            let shell = Shell { centre, inner_radius: inner, outer_radius: inner + 6.5e-3, wall: water, interior: water };
            for passes in [Passes::One, Passes::Closed] {
                let s = ShellBowl::new(&bowl, water, shell, passes, inner - 1e-3).unwrap();
                for &(rho, z) in &points {
                    let a = s.pressure(rho, z).unwrap();
                    let b = bowl.rayleigh([rho, 0.0, z], 30, 720);
                    assert!((a - b).norm() < 1e-4 * peak, "centre {centre}, ({rho}, {z}): {a} vs {b}");
                }
            }
        }
    }

    /// A thin lossless shell of large radius transmits the lowest orders as a plate at normal
    /// incidence does (the wave crosses it radially): within 1 % once `k·a` is large (the
    /// spherical wave's curvature over the wall, O(1/(k·a)), is what remains).
    #[test]
    fn a_large_shell_transmits_low_orders_as_a_plate() {
        let water = fluid(1500.0, 1000.0, 0.0);
        let bone = fluid(2800.0, 1850.0, 0.0);
        let (a, d) = (0.5, 6.5e-3);
        let shell = Shell { centre: 0.0, inner_radius: a, outer_radius: a + d, wall: bone, interior: water };
        let t = transmissions(water, &shell, Passes::One, 3);
        let plate = transmission(water, &[Layer { thickness: d, fluid: bone }], water, C64::new(0.0, 0.0));
        for tn in &t[..3] {
            assert!((tn.norm() - plate.norm()).abs() < 0.01 * plate.norm(), "|T| {} vs plate {}", tn.norm(), plate.norm());
        }
    }

    /// A shell of 3 m radius whose near wall lies where a plate lies gives the plate's field:
    /// the spherical and the planar solutions, written independently, agree on the axis about
    /// the focus within 2 % (what remains is the wall's curvature: a sagitta of 0.05 mm over the
    /// beam's 17 mm radius, a weak lens that moves the focus by a fraction of a millimetre).
    #[test]
    fn a_huge_shell_gives_the_plates_field() {
        let (water, bone) = (fluid(1500.0, 1000.0, 0.0), fluid(2800.0, 1850.0, 8.0));
        let bowl = Bowl::new(64e-3, 32e-3, water.k.re).unwrap();
        let outer = 3.0;
        let shell = Shell { centre: 30e-3 + outer, inner_radius: outer - 6.5e-3, outer_radius: outer, wall: bone, interior: water };
        let s = ShellBowl::new(&bowl, water, shell, Passes::One, outer - 20e-3).unwrap();
        let plate = LayeredBowl::new(&bowl, water, 30e-3, &[Layer { thickness: 6.5e-3, fluid: bone }], water).unwrap();
        for z in [55e-3, 60e-3, 64e-3] {
            let (a, b) = (s.pressure(0.0, z).unwrap().norm(), plate.pressure(0.0, z).unwrap().norm());
            assert!((a / b - 1.0).abs() < 0.02, "z {:.0} mm: shell {a:.4}, plate {b:.4}", z * 1e3);
        }
    }
}
