//! A CT wall tilted against the march planes crosses them as a staircase: *treads* (faces
//! between planes, where a pointwise interface's coefficient acts) and *risers* (changes of
//! medium across a plane, which the angular spectrum carries without loss: it keeps `Σ|ψ|²`).
//!
//! A wave crossing a wall of unit normal `n` along `n` (normal incidence, which the pointwise
//! coefficient assumes) sends the fraction `f = n_z²` of its flux through the treads: the
//! staircase's faces normal to axis `j` have the area `|n_j|` per unit wall area and pass the
//! flux `|n_j|` per unit area. For the wall to transmit the flux `T = 1 - R²` of its
//! normal-incidence coefficient `R`, as a face on a plane does, the treads must transmit
//! `T_t = (T - (1 - f)) / f` and reflect `R_t = sign(R)·sqrt(1 - T_t)` (flux kept:
//! `R_t² + T_t = 1`). Without it a wall tilted by θ to the planes passes `sin²θ` of the flux
//! unattenuated, whatever the step.
//!
//! `n` is the direction of the gradient of the slowness across the face (the CT's cells average
//! slowness, which makes the staircase's slowness smooth), and the correction is made only on a
//! wall between two layers (`interface::is_wall`): inside graded or textured bone the gradient
//! is the texture's, not a wall's. The incident wave's own direction (its phase gradient) would
//! not do: next to the wall the bone's faster phase tilts it towards the wall.

use crate::numeric::unit;
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;

/// The treads transmit at least this fraction of the wall's `T`: beyond, the wall is so steep
/// against the planes that its risers alone pass more than `T` (a wave along the normal of a wall
/// tilted by more than `asin(sqrt(T))`), which no tread can make up for.
const MIN_TREAD_TRANSMISSION: f64 = 0.25;

/// The coefficient `R_t` of the tread at pixel `i` of the face from slab `from` into `to`, for
/// its normal-incidence coefficient `r` (see the module doc).
pub(super) fn tread_coefficient(r: f64, grid: &Grid, (from, to): (&SliceProperties, &SliceProperties), i: usize) -> f64 {
    let n = wall_normal(grid, from, to, i);
    with_tread_fraction(r, n[2] * n[2])
}

/// `R_t` for the fraction `f` of the flux crossing through treads (see the module doc).
fn with_tread_fraction(r: f64, f: f64) -> f64 {
    let t = 1.0 - r * r;
    // At most `t` (which it is but for rounding: `r ≈ 0` must not give `1 - tread < 0`).
    let tread = if f > 0.0 { (t - (1.0 - f)) / f } else { 0.0 };
    let tread = tread.clamp(MIN_TREAD_TRANSMISSION * t, t);
    r.signum() * (1.0 - tread).sqrt()
}

/// Unit normal of the wall at pixel `i` of the face between slabs `from` and `to`: the direction
/// of the slowness gradient (along z across the face, across the plane from the two slabs'
/// mean, central differences; zero at the grid's edge).
fn wall_normal(g: &Grid, from: &SliceProperties, to: &SliceProperties, i: usize) -> [f64; 3] {
    let slowness = |k: usize| 0.5 * (1.0 / from.sound_speed[k] + 1.0 / to.sound_speed[k]);
    let across = |stride: usize, at: usize, len: usize, spacing: f64| {
        if at > 0 && at + 1 < len {
            (slowness(i + stride) - slowness(i - stride)) / (2.0 * spacing)
        } else {
            0.0
        }
    };
    let gradient =
        [across(1, i % g.nx, g.nx, g.dx), across(g.nx, i / g.nx, g.ny, g.dy), (1.0 / to.sound_speed[i] - 1.0 / from.sound_speed[i]) / g.dz];
    unit(gradient)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Treads and risers together pass the wall's `T = 1 - R²` (to rounding), and all of it
    /// crosses the treads of a wall along the planes; a steep wall's treads keep a quarter of `T`.
    #[test]
    fn treads_make_up_for_the_risers() {
        for r in [-0.55, -0.1, 0.05, 0.55] {
            let t = 1.0 - r * r;
            assert!((with_tread_fraction(r, 1.0) - r).abs() < 1e-12);
            for f in [0.6, 0.75, 0.9] {
                let rt = with_tread_fraction(r, f);
                assert!((f * (1.0 - rt * rt) + (1.0 - f) - t).abs() < 1e-12, "r {r}, f {f}");
                assert_eq!(rt.signum(), r.signum());
            }
            let steep = with_tread_fraction(r, 0.001);
            assert!((1.0 - steep * steep - MIN_TREAD_TRANSMISSION * t).abs() < 1e-12);
        }
    }

    /// The normal of a slowness ramp tilted by 30° about x and 20° about y (linear, so the
    /// differences are exact to rounding): `n_z² = cos²θ` of its tilt θ to z to 1e-9.
    #[test]
    fn the_wall_normal_is_the_slowness_gradients_direction() {
        let g = Grid::new(16, 16, 0.5e-3, 0.5e-3, 8, 0.5e-3, 0.0).unwrap();
        let (ax, ay) = (30f64.to_radians(), 20f64.to_radians());
        let direction = [ax.sin() * ay.cos(), ay.sin(), ax.cos() * ay.cos()];
        let slab = |z: f64| {
            let c = (0..g.lateral_len())
                .map(|p| {
                    let (x, y) = (g.x(p % g.nx), g.y(p / g.nx));
                    1.0 / (1.0 / 1500.0 + 0.1 * (direction[0] * x + direction[1] * y + direction[2] * z))
                })
                .collect::<Vec<f64>>();
            SliceProperties { density: vec![1000.0; c.len()], attenuation: vec![0.0; c.len()], sound_speed: c, shear: None }
        };
        let (from, to) = (slab(1.25e-3), slab(1.75e-3));
        for p in [g.nx + 1, 7 * g.nx + 9, 14 * g.nx + 14] {
            let n = wall_normal(&g, &from, &to, p);
            for k in 0..3 {
                assert!((n[k] - direction[k]).abs() < 1e-9, "pixel {p}: {n:?} against {direction:?}");
            }
        }
        // At the grid's edge the lateral difference is left out.
        assert!((wall_normal(&g, &from, &to, 0)[2] - 1.0).abs() < 1e-12);
    }
}
