//! The simulation grid: lateral samples and the planes the beam is marched through.

use crate::error::{require_positive, HasError, Result};

/// A regular grid in the transducer frame (metres).
///
/// Lateral sample `i` sits at `x_i = (i - nx/2)·dx` (index `nx/2` is on the beam axis), sample
/// `j` at `y_j = (j - ny/2)·dy`; plane `n` at `z_n = z0 + n·dz` for `n = 0..nz`. Lateral arrays are
/// stored row-major with shape `(ny, nx)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Lateral samples along x.
    pub nx: usize,
    /// Lateral samples along y.
    pub ny: usize,
    /// Lateral spacing along x, m.
    pub dx: f64,
    /// Lateral spacing along y, m.
    pub dy: f64,
    /// Number of planes along the beam.
    pub nz: usize,
    /// Step between planes along z, m.
    pub dz: f64,
    /// z of plane 0 (the source plane), m.
    pub z0: f64,
}

/// Offsets within this fraction of a spacing of a grid point (or plane) count as on it.
pub(crate) const ON_GRID: f64 = 1e-9;

impl Grid {
    /// Validates sizes and spacings.
    pub fn new(nx: usize, ny: usize, dx: f64, dy: f64, nz: usize, dz: f64, z0: f64) -> Result<Self> {
        require_positive("grid.dx", dx)?;
        require_positive("grid.dy", dy)?;
        require_positive("grid.dz", dz)?;
        if !z0.is_finite() {
            return Err(HasError::invalid("grid.z0", "must be finite"));
        }
        if nx < 4 || ny < 4 || nz < 2 {
            return Err(HasError::invalid("grid", format!("too few samples ({nx} x {ny} x {nz})")));
        }
        Ok(Grid { nx, ny, dx, dy, nz, dz, z0 })
    }

    /// x of lateral column `i` (m).
    pub fn x(&self, i: usize) -> f64 {
        (i as f64 - (self.nx / 2) as f64) * self.dx
    }
    /// y of lateral row `j` (m).
    pub fn y(&self, j: usize) -> f64 {
        (j as f64 - (self.ny / 2) as f64) * self.dy
    }
    /// z of plane `n` (m).
    pub fn z(&self, n: usize) -> f64 {
        self.z0 + n as f64 * self.dz
    }
    /// Column, row and plane of `p` (m) as fractional indices (grid points at whole numbers).
    pub fn fractional_index(&self, p: [f64; 3]) -> [f64; 3] {
        [p[0] / self.dx + (self.nx / 2) as f64, p[1] / self.dy + (self.ny / 2) as f64, (p[2] - self.z0) / self.dz]
    }
    /// Index of the plane nearest to `z` (clamped to the grid).
    pub fn plane_index(&self, z: f64) -> usize {
        let n = ((z - self.z0) / self.dz).round();
        n.clamp(0.0, (self.nz - 1) as f64) as usize
    }
    /// Whether a field can be read at `p` (m) by interpolation
    /// ([`crate::physics::propagation::HasPlan::point_weights`]): between the first and last
    /// planes (to a billionth of a spacing) and within half a spacing of the outermost columns
    /// and rows.
    pub fn holds_point(&self, p: [f64; 3]) -> bool {
        let t = (p[2] - self.z0) / self.dz;
        self.nearest(p).is_some() && (-ON_GRID..=(self.nz - 1) as f64 + ON_GRID).contains(&t)
    }
    /// Column, row and plane `[i, j, n]` of the grid point nearest `p` (m); `None` if `p` lies
    /// outside the grid (more than half a spacing beyond its outermost points) or is not finite.
    pub fn nearest(&self, p: [f64; 3]) -> Option<[usize; 3]> {
        let index = |v: f64, d: f64, n: usize| {
            let i = (v / d).round() + (n / 2) as f64;
            (i >= 0.0 && i < n as f64).then_some(i as usize)
        };
        let in_z = p[2] >= self.z0 - 0.5 * self.dz && p[2] <= self.z(self.nz - 1) + 0.5 * self.dz;
        Some([index(p[0], self.dx, self.nx)?, index(p[1], self.dy, self.ny)?, in_z.then(|| self.plane_index(p[2]))?])
    }

    /// Number of lateral samples.
    pub fn lateral_len(&self) -> usize {
        self.nx * self.ny
    }
    /// Spatial frequency (rad/m) of FFT bin `i` of `n` samples spaced `d` apart, in FFT order
    /// (0, 1, …, n/2-1, -n/2, …, -1)·2π/(n·d).
    pub fn wavenumber(i: usize, n: usize, d: f64) -> f64 {
        let k = if i < n.div_ceil(2) { i as f64 } else { i as f64 - n as f64 };
        2.0 * std::f64::consts::PI * k / (n as f64 * d)
    }
}

/// The smallest integer `>= n` whose only prime factors are 2, 3 and 5 (fast FFT lengths).
pub fn fft_friendly(n: usize) -> usize {
    let mut m = n.max(1);
    loop {
        let mut r = m;
        for p in [2, 3, 5] {
            while r % p == 0 {
                r /= p;
            }
        }
        if r == 1 {
            return m;
        }
        m += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_sample_is_at_zero_and_wavenumbers_are_in_fft_order() {
        let g = Grid::new(8, 6, 1e-3, 2e-3, 3, 1e-3, 0.0).unwrap();
        assert_eq!(g.x(4), 0.0);
        assert_eq!(g.y(3), 0.0);
        let k: Vec<f64> = (0..4).map(|i| Grid::wavenumber(i, 4, 1.0)).collect();
        let u = std::f64::consts::PI / 2.0;
        assert_eq!(k, vec![0.0, u, -2.0 * u, -u]);
    }

    #[test]
    fn fft_friendly_lengths() {
        assert_eq!(fft_friendly(178), 180);
        assert_eq!(fft_friendly(7), 8);
        assert_eq!(fft_friendly(121), 125);
    }
}
