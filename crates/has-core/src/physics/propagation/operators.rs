//! The operators of one HAS step: the angular-spectrum propagator of the slab's mean medium, the
//! space-domain screen of its deviation from that mean (vertical or oblique), and the absorbing
//! layer at the lateral edges.

use super::interface::axial_wavenumber;
use super::{HasOptions, Screen};
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::Complex64 as C64;

/// `exp(i·kz·dz + ᾱ·dz) / (nx·ny)` with `kz = sqrt((k̄ + i·ᾱ)² - kt²)` on the transposed spectrum
/// layout `(nx, ny)`; with `ᾱ = 0` the plain `exp(i·kz·dz)`. A step back (`dz < 0`, the inverse
/// of a step) leaves out the evanescent components (`kt > k̄`), which it would amplify.
pub(super) fn propagator(g: &Grid, dz: f64, k: f64, alpha: f64) -> Vec<C64> {
    use rayon::prelude::*;
    let norm = 1.0 / (g.nx * g.ny) as f64;
    let value = |kt2: f64| {
        let kz2 = k * k - kt2;
        if dz < 0.0 && kz2 < 0.0 {
            C64::new(0.0, 0.0)
        } else if alpha == 0.0 {
            if kz2 >= 0.0 {
                C64::from_polar(norm, kz2.sqrt() * dz)
            } else {
                C64::new(norm * (-(-kz2).sqrt() * dz).exp(), 0.0)
            }
        } else {
            let kz = axial_wavenumber(C64::new(k, alpha), kt2);
            (C64::i() * kz * dz + alpha * dz).exp() * norm
        }
    };
    // kx² and ky² repeat under i -> n - i (the wavenumbers change sign exactly): each distinct
    // pair is computed once, a quarter of the samples, and copied.
    let (ux, uy) = (g.nx / 2 + 1, g.ny / 2 + 1);
    let unique: Vec<C64> = (0..ux * uy)
        .into_par_iter()
        .map(|p| {
            let (kx, ky) = (Grid::wavenumber(p / uy, g.nx, g.dx), Grid::wavenumber(p % uy, g.ny, g.dy));
            value(kx * kx + ky * ky)
        })
        .collect();
    let canonical = |i: usize, n: usize| i.min(n - i);
    let mut h = vec![C64::new(0.0, 0.0); g.lateral_len()];
    h.par_chunks_mut(g.ny).enumerate().for_each(|(i, row)| {
        let from = &unique[canonical(i, g.nx) * uy..];
        row.iter_mut().enumerate().for_each(|(j, v)| *v = from[canonical(j, g.ny)]);
    });
    h
}

/// The screen per pixel, `exp(i·φ·dz - (β + sigma)·dz)`. With the angle θ of the waves crossing
/// the pixel (`sin2`: `sin² θ` per pixel, [`Screen::Oblique`]) and their transverse wavenumber
/// `kt = k·sin θ` in the pixel's medium, `φ = kz(k) - kz(k̄)` and
/// `β = alpha/cos θ - ᾱ·(1/cos θ̄ - 1)`, where `kz(k) = sqrt(k² - kt²)`, `cos θ = kz(k)/k` and
/// `cos θ̄ = kz(k̄)/k̄`: the propagator gives such a wave `kz(k̄)·dz` and the oblique part of the
/// mean absorption, the screen adds what its own medium gives it along its path. Without
/// (`None`, [`Screen::Vertical`]), the plain HAS screen `φ = k - k̄`, `β = alpha`.
/// Computed in parallel over pixels (each pixel alone, so the result does not depend on the
/// threads): the oblique screen is built anew for every step of a plan.
pub(super) fn screen(
    props: &SliceProperties,
    sponge: &[f64],
    omega: f64,
    k_mean: f64,
    a_mean: f64,
    sin2: Option<&[f64]>,
    dz: f64,
) -> Vec<C64> {
    use rayon::prelude::*;
    props
        .sound_speed
        .par_iter()
        .zip(&props.attenuation)
        .zip(sponge)
        .enumerate()
        .map(|(p, ((c, a), s))| {
            let k = omega / c;
            let (phase, absorption) = match sin2 {
                None => (k - k_mean, *a),
                Some(sin2) => {
                    let kt2 = (k * k * sin2[p]).min(MAX_OBLIQUITY_SIN2 * k.min(k_mean).powi(2));
                    let (kz, kz_mean) = ((k * k - kt2).sqrt(), (k_mean * k_mean - kt2).sqrt());
                    (kz - kz_mean, a * k / kz - a_mean * (k_mean / kz_mean - 1.0))
                }
            };
            C64::from_polar((-(absorption + s) * dz).exp(), phase * dz)
        })
        .collect()
}

/// The screen of the step from plane `step` to the next through `props`, for a distance `dz` (m;
/// `grid.dz` for the whole step, less or negative for part of it): with [`Screen::Oblique`] its
/// directions are those at the step's mid-height, whatever `dz`, so that part of a step is the
/// same operator over a shorter distance.
#[allow(clippy::too_many_arguments)]
pub(super) fn step_screen(
    g: &Grid,
    props: &SliceProperties,
    sponge: &[f64],
    omega: f64,
    mean: (f64, f64),
    model: Screen,
    step: usize,
    dz: f64,
    wall: Option<Refraction>,
) -> Vec<C64> {
    let z = g.z(step) + 0.5 * g.dz;
    let sin2 = oblique_toward(model, props).map(|toward| {
        let mut sin2 = obliquity(g, z, toward);
        if let Some(wall) = wall {
            refract(g, z, toward, props, omega, wall, &mut sin2);
        }
        sin2
    });
    screen(props, sponge, omega, mean.0, mean.1, sin2.as_deref(), dz)
}

/// An oblique wall through a slab (`interface`, `oblique.rs`): its unit normal and the medium
/// the screen's rays arrive through (the source's).
#[derive(Clone, Copy)]
pub(super) struct Refraction<'a> {
    pub normal: [f64; 3],
    pub source: &'a SliceProperties,
}

/// A pixel whose wavenumber differs from the source medium's by more than this fraction lies in
/// the wall ([`refract`]).
const WALL_CONTRAST: f64 = 0.1;

/// `sin² θ` of the screen's ray in each pixel of the wall: the ray towards `toward`, carried by
/// the source's medium at `K = k_s·d` (`d` the unit vector to `toward`), refracted into the
/// pixel's medium (wavenumber `k`) by the wall of unit normal `n`, which keeps the component
/// along the wall: `K_t = K - (K·n)·n`, `K' = K_t ± sqrt(k² - |K_t|²)·n` (Snell's law), and
/// `sin² θ = |K'_⊥|²/k²`; beyond the critical angle (`|K_t| ≥ k`) the screen's cap. The straight
/// ray through a wall tilted against it bends: through a plate tilted 20° the oblique screen
/// would otherwise take a ray into bone 10-20° off the refracted one, the error in `kz` growing
/// towards the critical angle, which weakens the plate's focusing and moves the focus
/// millimetres (`docs/validation.md`). A wall normal to the rays (a cap about the focus) leaves
/// them unbent: `K_t = 0`.
fn refract(g: &Grid, z: f64, toward: [f64; 3], props: &SliceProperties, omega: f64, wall: Refraction, sin2: &mut [f64]) {
    use rayon::prelude::*;
    let n = wall.normal;
    sin2.par_iter_mut().enumerate().for_each(|(p, s)| {
        let (k, ks) = (omega / props.sound_speed[p], omega / wall.source.sound_speed[p]);
        if (k - ks).abs() <= WALL_CONTRAST * ks {
            return;
        }
        let d = [toward[0] - g.x(p % g.nx), toward[1] - g.y(p / g.nx), toward[2] - z];
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len == 0.0 {
            return;
        }
        let big_k = d.map(|v| ks * v / len);
        let along = big_k[0] * n[0] + big_k[1] * n[1] + big_k[2] * n[2];
        let kt = [big_k[0] - along * n[0], big_k[1] - along * n[1], big_k[2] - along * n[2]];
        let kt2 = kt[0] * kt[0] + kt[1] * kt[1] + kt[2] * kt[2];
        if kt2 >= k * k {
            *s = 1.0;
            return;
        }
        let normal = (k * k - kt2).sqrt().copysign(along);
        let (px, py) = (kt[0] + normal * n[0], kt[1] + normal * n[1]);
        *s = (px * px + py * py) / (k * k);
    });
}

/// The point the screen's rays converge on where a slab's screen depends on the step: an
/// oblique screen through a slab that is not uniform (in a uniform slab, where `k = k̄` up to
/// `k̄`'s rounding, the oblique screen is the vertical one, so one screen serves all its steps).
pub(super) fn oblique_toward(model: Screen, props: &SliceProperties) -> Option<[f64; 3]> {
    match model {
        Screen::Oblique { toward } if !props.is_uniform() => Some(toward),
        _ => None,
    }
}

/// The screen's angle is capped at 80° (`sin² θ ≤ 0.97`, in the slower of the pixel's medium and
/// the mean): by the focal plane the line to the focus lies across the plane, where the ray
/// picture fails and `kz` would vanish.
const MAX_OBLIQUITY_SIN2: f64 = 0.97;

/// `sin² θ` per pixel, row-major `(ny, nx)`, with `θ` the angle against z of the line from the
/// pixel at height `z` to the point `toward` (m): for a beam focused at that point, the direction
/// of its rays through the pixel (near the point the field holds every direction; there the beam
/// is in one medium, where the screen's correction is small). Zero on the line through the point.
fn obliquity(g: &Grid, z: f64, toward: [f64; 3]) -> Vec<f64> {
    use rayon::prelude::*;
    let dz2 = (z - toward[2]).powi(2);
    (0..g.lateral_len())
        .into_par_iter()
        .map(|p| {
            let rho2 = (g.x(p % g.nx) - toward[0]).powi(2) + (g.y(p / g.nx) - toward[1]).powi(2);
            if rho2 > 0.0 {
                rho2 / (rho2 + dz2)
            } else {
                0.0
            }
        })
        .collect()
}

/// The absorbing layer sigma(x, y) (Np/m): quadratic in the depth into the layer.
pub(super) fn sponge_map(g: &Grid, o: &HasOptions) -> Vec<f64> {
    let w = o.sponge_width;
    let mut s = vec![0.0; g.lateral_len()];
    if w <= 0.0 {
        return s;
    }
    let depth = |i: usize, n: usize, d: f64| {
        let from_edge = (i.min(n - 1 - i) as f64) * d;
        ((w - from_edge) / w).max(0.0)
    };
    let peak = 3.0 * o.sponge_strength / w;
    for j in 0..g.ny {
        for i in 0..g.nx {
            let e = depth(i, g.nx, g.dx).max(depth(j, g.ny, g.dy));
            s[j * g.nx + i] = peak * e * e;
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Each sample computed on its own, as the definition reads.
    fn propagator_directly(g: &Grid, dz: f64, k: f64, alpha: f64) -> Vec<C64> {
        let norm = 1.0 / (g.nx * g.ny) as f64;
        let mut h = Vec::new();
        for i in 0..g.nx {
            for j in 0..g.ny {
                let (kx, ky) = (Grid::wavenumber(i, g.nx, g.dx), Grid::wavenumber(j, g.ny, g.dy));
                let kz = axial_wavenumber(C64::new(k, alpha), kx * kx + ky * ky);
                let evanescent_back = dz < 0.0 && k * k < kx * kx + ky * ky;
                h.push(if evanescent_back { C64::new(0.0, 0.0) } else { (C64::i() * kz * dz + alpha * dz).exp() * norm });
            }
        }
        h
    }

    /// The propagator, built from a quarter of the spectrum and mirrored, against every sample
    /// computed on its own: odd and even sizes (the Nyquist row and column are their own mirror),
    /// lossless and absorbing, a step forward and back. Within 1e-12 of the largest sample: the
    /// two take the exponential by different formulas (real and complex), which round apart.
    #[test]
    fn propagator_equals_its_definition_sample_by_sample() {
        for (nx, ny) in [(12, 9), (15, 16)] {
            let g = Grid::new(nx, ny, 0.4e-3, 0.3e-3, 4, 0.2e-3, 0.0).unwrap();
            let k = 2.0 * PI * 1e6 / 1500.0;
            for (dz, alpha) in [(0.2e-3, 0.0), (0.2e-3, 30.0), (-0.1e-3, 0.0), (-0.1e-3, 30.0)] {
                let (fast, slow) = (propagator(&g, dz, k, alpha), propagator_directly(&g, dz, k, alpha));
                let peak = slow.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let worst = fast.iter().zip(&slow).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
                assert!(worst <= 1e-12 * peak, "{nx}x{ny}, dz {dz}, alpha {alpha}: {worst:e} of {peak:e}");
                assert!(slow.iter().any(|v| v.norm() < 0.5 * peak), "{nx}x{ny}: no evanescent samples tested");
            }
        }
    }
}
