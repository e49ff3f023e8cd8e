//! The array moved: its transposed projection onto a moved array, and the projection's rate as
//! the elements move, from weights on the plane alone.
//!
//! The Rayleigh kernel from a point `q` of an element to a pixel `x` of the plane depends on
//! `x - q` only (the plane in a homogeneous coupling medium). So the transposed projection of
//! weights `w` onto the array moved by `b`, `Σ_x w(x)·K(x - q - b)`, is the projection onto the
//! array as it is of the weights moved the other way: laterally `w(x + b)` (an index shift where
//! `b` is whole cells), along z `P(-b_z)·w`, the weights propagated by `-b_z` through the coupling
//! medium (`exp(-i·k_z·b_z)` on their angular spectrum: to an element moved `b_z` towards the
//! plane the plane is `b_z` nearer; the factor is even in the spatial frequencies, so the
//! operator is its own transpose). The projection's rate as each point moves with velocity `v`
//! is `∇u(q)·v`, `u` the weights' Rayleigh integral on the same coarse pixels, the kernel's
//! gradient summed there ([`gradient_at_points`]): the derivative of the same discrete sum that
//! [`SourceModel::transposed`] makes. A moved array then costs a plane's index shift or FFTs,
//! and a rate one more evaluation of the kernel, instead of a projection of its own each.

use super::{Footprint, SourceModel};
use crate::error::{HasError, Result};
use crate::physics::fft::Fft2;
use crate::physics::grid::Grid;
use crate::physics::propagation::axial_wavenumber;
use crate::physics::rayleigh::gradient_at_points;
use crate::physics::transducer::SurfacePoint;
use num_complex::Complex64 as C64;

/// A velocity of the elements' surface points: the velocity (m per unit of the motion's
/// parameter) of the point at the given position (m).
pub type Velocity<'a> = &'a (dyn Fn([f64; 3]) -> [f64; 3] + Sync);

impl SourceModel {
    /// Whether every element is projected onto the plane by the Rayleigh integral over its
    /// quadrature points (curved or tilted elements before the plane), as
    /// [`SourceModel::moved_weights`] and [`SourceModel::transposed_rates`] need: not a
    /// rasterised element in the plane nor a whole cap projected by its symmetry.
    pub fn is_projected(&self) -> bool {
        !self.footprints.is_empty() && self.footprints.iter().all(|fp| matches!(fp, Footprint::Points(_)))
    }

    /// The weights whose [`SourceModel::transposed`] onto this array is that of `weights` (row-major
    /// `(ny, nx)`) onto the array moved by `shift` (m): `weights` moved by `-shift` laterally (whole
    /// cells: refused otherwise; what moves in from beyond the grid's edge is zero) and propagated
    /// by `-shift[2]` through the coupling medium (see the module docs). The moved array must stay
    /// behind the plane (its elements' projections are integrals from before it), which the
    /// caller checks. Refused unless [`SourceModel::is_projected`].
    pub fn moved_weights(&self, weights: &[C64], shift: [f64; 3]) -> Result<Vec<C64>> {
        self.check_projected(weights)?;
        let g = &self.grid;
        crate::error::require_finite("shift", &shift)?;
        let cells = |d: f64, step: f64| -> Result<isize> {
            let n = d / step;
            if (n - n.round()).abs() > 1e-6 {
                return Err(HasError::invalid("shift", format!("{:.4} mm is not a whole number of {:.4} mm cells", d * 1e3, step * 1e3)));
            }
            Ok(n.round() as isize)
        };
        let (mx, my) = (cells(shift[0], g.dx)?, cells(shift[1], g.dy)?);
        let at = |i: usize, m: isize, n: usize| Some(i as isize + m).filter(|&v| v >= 0 && v < n as isize).map(|v| v as usize);
        let mut moved: Vec<C64> = (0..g.lateral_len())
            .map(|p| match (at(p % g.nx, mx, g.nx), at(p / g.nx, my, g.ny)) {
                (Some(i), Some(j)) => weights[j * g.nx + i],
                _ => C64::new(0.0, 0.0),
            })
            .collect();
        if shift[2] != 0.0 {
            self.step_through_coupling(&mut moved, -shift[2]);
        }
        Ok(moved)
    }

    /// The rate of change of [`SourceModel::transposed`] of `weights` (row-major `(ny, nx)`) as
    /// the elements move: for each of `velocities`, each element's
    /// `d/ds Σ_pixels weights · field_s(δ_e)` at `s = 0`, its surface points moving with that
    /// velocity (`out[velocity][element]`): the gradient of the kernel summed on the coarse pixels
    /// at every quadrature point in one evaluation ([`gradient_at_points`]), dotted with each
    /// point's velocity. Refused unless [`SourceModel::is_projected`].
    pub fn transposed_rates(&self, weights: &[C64], velocities: &[Velocity]) -> Result<Vec<Vec<C64>>> {
        self.check_projected(weights)?;
        let (xs, ys) = self.coarse_pixels();
        let coarse = self.coarse_weights(weights);
        let gradient = gradient_at_points(&coarse, &xs, &ys, self.grid.z0, &self.quadrature_points(), self.wavenumber, self.attenuation);
        Ok(velocities
            .iter()
            .map(|v| {
                let rate = |n: usize, q: &SurfacePoint| {
                    let (u, d) = (v(q.position), gradient[n]);
                    d[0] * u[0] + d[1] * u[1] + d[2] * u[2]
                };
                self.over_points(rate).into_iter().map(|r| r * self.face_pressure).collect()
            })
            .collect())
    }

    /// Refuses arrays that are not [`SourceModel::is_projected`] and weights not of the plane.
    fn check_projected(&self, weights: &[C64]) -> Result<()> {
        if !self.is_projected() {
            return Err(HasError::invalid(
                "transducer",
                "moving the array needs every element before the plane, projected by the Rayleigh integral (not an element in the plane or a whole bowl)",
            ));
        }
        if weights.len() != self.grid.lateral_len() {
            return Err(HasError::invalid("weights", format!("has {} samples, grid has {}", weights.len(), self.grid.lateral_len())));
        }
        Ok(())
    }

    /// `weights ← IFFT2(exp(i·k_z·dz) · FFT2(weights))`: the plane's field propagated by `dz` (m)
    /// through the coupling medium, `k_z` the axial wavenumber of its complex wavenumber (the
    /// attenuation its imaginary part; the root with `Im k_z ≥ 0`, evanescent waves decaying for
    /// `dz > 0`), as the Rayleigh kernel `exp((i·k - alpha)·R)/R` propagates.
    fn step_through_coupling(&self, weights: &mut [C64], dz: f64) {
        let g = &self.grid;
        let fft = Fft2::<f64>::new(g.nx, g.ny);
        let k = C64::new(self.wavenumber, self.attenuation);
        let norm = 1.0 / g.lateral_len() as f64;
        // The transposed spectrum layout (nx, ny) of `Fft2`.
        let kernel: Vec<C64> = (0..g.lateral_len())
            .map(|p| {
                let (kx, ky) = (Grid::wavenumber(p / g.ny, g.nx, g.dx), Grid::wavenumber(p % g.ny, g.ny, g.dy));
                (C64::i() * axial_wavenumber(k, kx * kx + ky * ky) * dz).exp() * norm
            })
            .collect();
        fft.filter(weights, &mut fft.workspace(true), None, &kernel, None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::transducer::Transducer;

    /// A small hemisphere-like array of curved elements before a 48 x 48 plane at 1 MHz.
    fn array_and_model() -> (Transducer, Grid, SourceModel) {
        let k = 2.0 * std::f64::consts::PI * 1e6 / 1500.0;
        let t = Transducer::hemisphere(30e-3, 40f64.to_radians(), 16, 5e-3).unwrap();
        let z0 = crate::physics::source::source_plane_z(&t, 1.5e-3, 0.375e-3);
        let g = Grid::new(48, 48, 0.375e-3, 0.375e-3, 2, 0.375e-3, z0).unwrap();
        let model = SourceModel::new(&t, &g, 1.0, k, 20.0).unwrap();
        (t, g, model)
    }

    /// The field a point source at `(1, -2, 30)` mm sends to the plane (what the transposed march
    /// from a target gives in water), falling to zero towards the plane's edges.
    fn weights(g: &Grid, k: f64) -> Vec<C64> {
        (0..g.lateral_len())
            .map(|p| {
                let (x, y) = (g.x(p % g.nx), g.y(p / g.nx));
                let r = ((x - 1e-3).powi(2) + (y + 2e-3).powi(2) + (30e-3 - g.z0).powi(2)).sqrt();
                C64::from_polar(1.0 / r, k * r) * (-(x * x + y * y) / (4e-3f64).powi(2)).exp()
            })
            .collect()
    }

    fn relative(a: &[C64], b: &[C64]) -> f64 {
        let diff: f64 = a.iter().zip(b).map(|(a, b)| (a - b).norm_sqr()).sum();
        (diff / b.iter().map(|v| v.norm_sqr()).sum::<f64>()).sqrt()
    }

    #[test]
    fn moved_weights_project_as_the_moved_array_does() {
        // Reference: the array itself moved (its own quadrature points, the Rayleigh integral at
        // each). The identity is exact for the continuous integral; both sides sample it on the
        // same coarse pixels, at points a cell apart, so they differ by the sums' discretisation:
        // measured 3e-4 laterally and 2e-3 along z (a cell towards the plane raises the evanescent
        // part the coarse pixels carry). Tolerance 1e-2 of the responses' norm.
        let (t, g, model) = array_and_model();
        let w = weights(&g, model.wavenumber);
        let identity = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for shift in [[g.dx, 0.0, 0.0], [0.0, -2.0 * g.dy, 0.0], [0.0, 0.0, -g.dz], [0.0, 0.0, 0.5 * g.dz], [-g.dx, g.dy, g.dz]] {
            let moved =
                SourceModel::new(&t.moved(&identity, [0.0; 3], shift).unwrap(), &g, 1.0, model.wavenumber, model.attenuation).unwrap();
            let direct = moved.transposed(&w).unwrap();
            let fast = model.transposed(&model.moved_weights(&w, shift).unwrap()).unwrap();
            let err = relative(&fast, &direct);
            eprintln!("[moved weights] shift {:?} mm: relative difference {err:.2e} (tol 1e-2)", shift.map(|v| v * 1e3));
            assert!(err < 1e-2, "shift {shift:?}: {err:.2e}");
        }
        assert!(model.moved_weights(&w, [0.3 * g.dx, 0.0, 0.0]).is_err());
    }

    /// `model` with every quadrature point moved rigidly by `motion` (the same points, moved; no
    /// projections kept from the model's).
    fn rigidly_moved(model: &SourceModel, motion: impl Fn([f64; 3]) -> [f64; 3]) -> SourceModel {
        let mut moved = model.clone();
        moved.projections = std::sync::Arc::default();
        for fp in &mut moved.footprints {
            if let Footprint::Points(points) = fp {
                points.iter_mut().for_each(|q| q.position = motion(q.position));
            }
        }
        moved
    }

    #[test]
    fn transposed_rates_are_the_moved_points_central_difference() {
        // Reference: the central difference of the transposed projections from the elements'
        // quadrature points moved rigidly either way (the same sums at the moved points): turned
        // by ±0.02° about an axis through a point 30 mm beyond the array, and shifted ±0.01 mm
        // along y and z. The rates are the derivative of the same discrete sums, so the two differ
        // by the difference's error, of second order in the step ((k·δ)²/6 ≈ 3e-4 at 1 MHz), and
        // single precision. Tolerance 2e-3.
        // (A turned element's own quadrature is laid out anew in its turned frame: the projection
        // onto the turned array itself differs from the rigidly moved points' by that layout.)
        let (_, g, model) = array_and_model();
        let w = weights(&g, model.wavenumber);
        let about = [1e-3, -2e-3, 30e-3];
        let turn_x: Velocity = &|q: [f64; 3]| [0.0, -(q[2] - about[2]), q[1] - about[1]];
        let along_y: Velocity = &|_| [0.0, 1.0, 0.0];
        let along_z: Velocity = &|_| [0.0, 0.0, 1.0];
        let rates = model.transposed_rates(&w, &[turn_x, along_y, along_z]).unwrap();
        let (angle, step) = (0.02f64.to_radians(), 0.01e-3);
        let turned = |a: f64| {
            let (sin, cos) = a.sin_cos();
            let r = [[1.0, 0.0, 0.0], [0.0, cos, -sin], [0.0, sin, cos]];
            rigidly_moved(&model, move |q| std::array::from_fn(|i| about[i] + (0..3).map(|j| r[i][j] * (q[j] - about[j])).sum::<f64>()))
                .transposed(&w)
                .unwrap()
        };
        let shifted = |axis: usize, d: f64| {
            rigidly_moved(&model, move |q| std::array::from_fn(|i| q[i] + if i == axis { d } else { 0.0 })).transposed(&w).unwrap()
        };
        let central =
            |plus: Vec<C64>, minus: Vec<C64>, d: f64| plus.iter().zip(&minus).map(|(p, m)| (p - m) / (2.0 * d)).collect::<Vec<_>>();
        let references = [
            central(turned(angle), turned(-angle), angle),
            central(shifted(1, step), shifted(1, -step), step),
            central(shifted(2, step), shifted(2, -step), step),
        ];
        let errors: Vec<f64> = rates.iter().zip(&references).map(|(r, f)| relative(r, f)).collect();
        eprintln!(
            "[transposed rates] turn about x, along y, along z: relative differences {:.2e} {:.2e} {:.2e} (tol 2e-3)",
            errors[0], errors[1], errors[2]
        );
        assert!(errors.iter().all(|&e| e < 2e-3), "{errors:?}");
    }
}
