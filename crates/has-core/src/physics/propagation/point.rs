//! The pressure at a point between grid points, as weights on one recorded plane.
//!
//! Across a plane the march's field is band-limited to the grid's spectrum, so its value at
//! `(x, y)` is the trigonometric interpolation `p(x, y) = Σ_ij d_i(x)·d_j(y)·p_ij` with the
//! Dirichlet kernel `d_i(x) = (1/N)·Σ_m exp(i·k_m·(x - x_i))` (the Nyquist term split evenly
//! between `±π/dx`, so that the weights are real). Between planes, the field at `z` is that of the
//! next plane stepped back by `δz = z - z_next < 0` through the slab between them, the inverse of
//! a HAS step: `p(z) = IFFT·H(δz)·FFT·(S(δz)·p_next)` with the step's own propagator `H` and
//! screen `S` (the oblique screen with the step's directions) evaluated for `δz` (evanescent
//! components left out); a step with two reference media (`references.rs`) steps each part back
//! through its own medium and adds them. The next plane's field is recorded before its
//! interface, so no interface lies between. On a grid point the weights are that point's alone.
//! Both act on the marched field `ψ = p·sqrt(Z_s/Z)` (see [`super::interface`]), the
//! band-limited one, so the weights on the recorded pressure carry `c/C_ij`: `C = sqrt(Z/Z_s)` of
//! the slab before the plane, `c` at the point's nearest pixel (1 where the slab's impedance is
//! the source's).

use super::march::{pressure_scale, Operators};
use super::operators::Refraction;
use super::{propagator, sponge_map, step_screen, HasPlan};
use crate::physics::grid::ON_GRID;
use num_complex::Complex64 as C64;
use std::f64::consts::PI;

impl HasPlan {
    /// The plane `n` and weights `w` (row-major `(ny, nx)`) with `Σ w·p_n` the pressure at
    /// `point` (m) for the field `p_n` recorded on plane `n` (see the module doc). `None` outside
    /// the grid: beyond its first or last plane, or more than half a spacing beyond its outermost
    /// columns or rows.
    pub fn point_weights(&self, point: [f64; 3]) -> Option<(usize, Vec<C64>)> {
        let g = &self.grid;
        if !g.holds_point(point) {
            return None;
        }
        let t = (point[2] - g.z0) / g.dz;
        let across = |v: f64, n: usize, d: f64| dirichlet_weights(v / d + (n / 2) as f64, n);
        let (wx, wy) = (across(point[0], g.nx, g.dx), across(point[1], g.ny, g.dy));
        let mut w: Vec<C64> = wy.iter().flat_map(|y| wx.iter().map(move |x| C64::new(x * y, 0.0))).collect();
        let on_plane = (t - t.round()).abs() < ON_GRID;
        if on_plane {
            let n = t.round() as usize;
            self.to_pressure_weights(n, point, &mut w);
            return Some((n, w));
        }
        let next = t.ceil() as usize;
        let dz = point[2] - g.z(next);
        let step = &self.steps[next - 1];
        let omega = 2.0 * PI * self.frequency;
        let (props, sponge) = (&self.slabs[step.slab], sponge_map(g, &self.options));
        let mut ws = self.fft.workspace(true);
        match &step.split {
            // Each reference medium's part stepped back through its own medium.
            Some(split) => {
                let r = split.references;
                let mut second = w.clone();
                let parts = [(0, &mut w), (1, &mut second)];
                for (i, part) in parts {
                    let (k, a) = r.0[i];
                    self.fft.filter(part, &mut ws, None, &propagator(g, dz, k, a), Some(&r.screen(i, props, &sponge, omega, dz)));
                }
                w.iter_mut().zip(&second).for_each(|(w, s)| *w += s);
            }
            None => {
                let back = propagator(g, dz, step.mean_wavenumber, step.mean_attenuation);
                let mean = (step.mean_wavenumber, step.mean_attenuation);
                let wall = step.wall_normal.map(|normal| Refraction { normal, source: &self.source_medium });
                let back_screen = step_screen(g, props, &sponge, omega, mean, self.options.screen, next - 1, dz, wall);
                self.fft.filter(&mut w, &mut ws, None, &back, Some(&back_screen));
            }
        }
        self.to_pressure_weights(next, point, &mut w);
        Some((next, w))
    }

    /// Weights `w` on the marched field of plane `n` made weights on its recorded pressure:
    /// `w_ij·c/C_ij` (see the module doc).
    fn to_pressure_weights(&self, n: usize, point: [f64; 3], w: &mut [C64]) {
        let (before, source) = (self.before(n), self.source_medium());
        if std::ptr::eq(before, source) {
            return;
        }
        let Some([i, j, _]) = self.grid.nearest(point) else { return };
        let at_point = pressure_scale(before, source, j * self.grid.nx + i);
        w.iter_mut().enumerate().for_each(|(p, w)| *w *= at_point / pressure_scale(before, source, p));
    }
}

/// Trigonometric interpolation weights `d_i`, `i < n`, at the fractional sample index `u`:
/// `(1/n)·Σ_m cos(2π·m·(u - i)/n)` over `|m| < n/2`, plus `cos(π·(u - i))/n` for even `n` (the
/// Nyquist term halved between `±n/2`). A whole `u` gives the unit vector.
fn dirichlet_weights(u: f64, n: usize) -> Vec<f64> {
    let nearest = u.round();
    if (u - nearest).abs() < ON_GRID {
        return (0..n).map(|i| if i as f64 == nearest.rem_euclid(n as f64) { 1.0 } else { 0.0 }).collect();
    }
    let half = n.div_ceil(2);
    (0..n)
        .map(|i| {
            let s = u - i as f64;
            let mut sum = 1.0 + (1..half).map(|m| 2.0 * (2.0 * PI * m as f64 * s / n as f64).cos()).sum::<f64>();
            if n % 2 == 0 {
                sum += (PI * s).cos();
            }
            sum / n as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::grid::Grid;
    use crate::physics::medium::{Material, Medium};
    use crate::physics::propagation::{HasOptions, RecordSpec};

    /// A band-limited signal `Σ_m a_m exp(i·k_m·x)` sampled on the grid is interpolated exactly
    /// (to rounding, 1e-12) between samples, for odd and even lengths.
    #[test]
    fn dirichlet_weights_interpolate_band_limited_samples() {
        for n in [15usize, 16] {
            let d = 0.5e-3;
            let modes = [(-5i32, C64::new(0.3, -0.2)), (0, C64::new(1.0, 0.0)), (3, C64::new(-0.1, 0.7)), (6, C64::new(0.2, 0.2))];
            let signal =
                |x: f64| modes.iter().map(|(m, a)| a * C64::from_polar(1.0, 2.0 * PI * *m as f64 * x / (n as f64 * d))).sum::<C64>();
            let samples: Vec<C64> = (0..n).map(|i| signal(i as f64 * d)).collect();
            for u in [0.0, 0.37, 4.5, 7.91, n as f64 - 0.2] {
                let w = dirichlet_weights(u, n);
                let interpolated: C64 = w.iter().zip(&samples).map(|(w, s)| w * s).sum();
                assert!((interpolated - signal(u * d)).norm() < 1e-12, "n {n}, u {u}: {interpolated} vs {}", signal(u * d));
            }
        }
    }

    /// In water the march is exact, so the weights between planes must give the field of a plane
    /// wave travelling obliquely, `exp(i·(kx·x + kz·z))`, at any point (tolerance 1e-9: rounding of
    /// the FFTs). A grid point gives its own unit weight.
    #[test]
    fn point_weights_give_an_oblique_plane_wave_between_grid_points() {
        let g = Grid::new(32, 24, 0.5e-3, 0.5e-3, 12, 0.4e-3, 1e-3).unwrap();
        let frequency = 1e6;
        let water = Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap());
        let k = 2.0 * PI * frequency / 1500.0;
        let (kx, ky) = (Grid::wavenumber(3, g.nx, g.dx), Grid::wavenumber(g.ny - 2, g.ny, g.dy));
        let kz = (k * k - kx * kx - ky * ky).sqrt();
        let wave = |x: f64, y: f64, z: f64| C64::from_polar(1.0, kx * x + ky * y + kz * z);
        let source: Vec<C64> = (0..g.lateral_len()).map(|p| wave(g.x(p % g.nx), g.y(p / g.nx), g.z(0))).collect();
        let options = HasOptions { sponge_width: 0.0, ..HasOptions::default() };
        let (plan, _) = HasPlan::build(&g, &water, frequency, &source, &options, &RecordSpec::default()).unwrap();
        let rec = plan.propagate(&source, &RecordSpec { planes: (0..g.nz).collect(), ..RecordSpec::default() }).unwrap();
        for point in [[0.7e-3, -1.3e-3, 2.9e-3], [g.x(20), g.y(3), g.z(5)], [-2.2e-3, 0.4e-3, g.z(7) + 0.1e-3]] {
            let (n, w) = plan.point_weights(point).unwrap();
            let p: C64 = w.iter().zip(&rec.planes[n]).map(|(w, p)| w * p).sum();
            let exact = wave(point[0], point[1], point[2]);
            assert!((p - exact).norm() < 1e-9, "{point:?}: {p} vs {exact}");
        }
        let (_, on_grid) = plan.point_weights([g.x(20), g.y(3), g.z(5)]).unwrap();
        assert_eq!(on_grid.iter().filter(|w| w.norm() > 0.0).count(), 1);
        assert!(plan.point_weights([0.0, 0.0, g.z(g.nz - 1) + 0.1e-3]).is_none());
        assert!(plan.point_weights([0.0, 0.0, g.z0 - 0.1e-3]).is_none());
    }
}
