//! Band-limited (Fourier) interpolation between a periodic field sampled on a coarse lattice and a
//! finer one of the same period, and its transpose (the source plane's Rayleigh sums run on
//! coarse pixels).

use crate::physics::fft::Fft2;
use num_complex::Complex64 as C64;

/// Band-limited (Fourier) interpolation of a `(cy, cx)` field onto the `(ny, nx)` lattice of the
/// same period and origin (`nx ≥ cx`, `ny ≥ cy`; coarse sample `m` at `m·nx/cx` fine samples): the
/// coarse spectrum, zero-padded (the Nyquist bin of an even length split evenly between `±`),
/// transformed back. Exact for periodic fields without spatial frequencies beyond the coarse
/// lattice's Nyquist frequency; with `nx = r·cx` coarse sample `m` lands on pixel `r·m`.
/// `coarse` is overwritten.
pub fn fourier_resample(coarse: &mut [C64], cx: usize, cy: usize, nx: usize, ny: usize) -> Vec<C64> {
    assert!(nx >= cx && ny >= cy, "a Fourier resampling onto a finer lattice");
    let small = Fft2::new(cx, cy);
    let mut ws = small.workspace(true);
    small.forward(coarse, &mut ws);
    let big = Fft2::new(nx, ny);
    let mut wb = big.workspace(true);
    let scale = 1.0 / (cx * cy) as f64;
    for a in 0..cx {
        let ta = upsample_targets(a, cx, nx);
        for b in 0..cy {
            let v = ws.spectrum[a * cy + b] * scale;
            for &(ia, wa) in &ta {
                for (ib, wb_) in upsample_targets(b, cy, ny) {
                    wb.spectrum[ia * ny + ib] += v * (wa * wb_);
                }
            }
        }
    }
    let mut fine = vec![C64::new(0.0, 0.0); nx * ny];
    big.inverse(&mut wb, &mut fine);
    fine
}

/// The transpose of [`fourier_resample`]: for `fine` on the `(ny, nx)` lattice, the coarse
/// `(cy, cx)` vector `c̄` with `Σ c̄ · c = Σ fine · fourier_resample(c)` for every `c` (the
/// unnormalised inverse transform of `fine`, the coarse frequencies gathered with the same
/// weights, the forward transform of those).
pub fn fourier_resample_transposed(fine: &[C64], cx: usize, cy: usize, nx: usize, ny: usize) -> Vec<C64> {
    assert!(nx >= cx && ny >= cy, "a Fourier resampling onto a finer lattice");
    let big = Fft2::new(nx, ny);
    let mut wb = big.workspace(true);
    // The unnormalised inverse DFT is symmetric: applied to `fine` as if it were a spectrum.
    crate::physics::fft::transpose(fine, &mut wb.spectrum, ny, nx, true);
    let mut spectrum = vec![C64::new(0.0, 0.0); nx * ny];
    big.inverse(&mut wb, &mut spectrum);
    let small = Fft2::new(cx, cy);
    let mut ws = small.workspace(true);
    let scale = 1.0 / (cx * cy) as f64;
    // `spectrum[b·nx + a]` holds frequency (a, b); the coarse values in (cy, cx) layout.
    let mut coarse = vec![C64::new(0.0, 0.0); cx * cy];
    for b in 0..cy {
        for a in 0..cx {
            let mut v = C64::new(0.0, 0.0);
            for &(ia, wa) in &upsample_targets(a, cx, nx) {
                for &(ib, wb_) in &upsample_targets(b, cy, ny) {
                    v += spectrum[ib * nx + ia] * (wa * wb_);
                }
            }
            coarse[b * cx + a] = v * scale;
        }
    }
    small.forward(&mut coarse, &mut ws);
    let mut out = vec![C64::new(0.0, 0.0); cx * cy];
    crate::physics::fft::transpose(&ws.spectrum, &mut out, cx, cy, true);
    out
}

/// Where coarse frequency index `k` of a length-`c` transform goes in a length-`n` one (the
/// Nyquist bin of an even length split evenly between `±`).
fn upsample_targets(k: usize, c: usize, n: usize) -> Vec<(usize, f64)> {
    if 2 * k < c {
        vec![(k, 1.0)]
    } else if 2 * k > c {
        vec![(n - (c - k), 1.0)]
    } else {
        vec![(k, 0.5), (n - k, 0.5)]
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    #[test]
    fn fourier_upsampling_reproduces_a_band_limited_field() {
        // A sum of plane waves strictly below the coarse Nyquist frequency (periodic on the grid), sampled
        // on every 2nd and 3rd pixel, against its exact values at every pixel: only rounding.
        for (nx, ny, r) in [(24, 18, 2), (30, 24, 3), (20, 30, 2)] {
            let waves = [(1.0, 2.0, C64::new(1.0, 0.3)), (-3.0, 1.0, C64::new(-0.4, 0.8)), (2.0, -3.0, C64::new(0.2, -0.1))];
            let at = |i: usize, j: usize| -> C64 {
                waves
                    .iter()
                    .map(|&(fx, fy, a)| {
                        a * C64::from_polar(1.0, 2.0 * std::f64::consts::PI * (fx * i as f64 / nx as f64 + fy * j as f64 / ny as f64))
                    })
                    .sum()
            };
            let (cx, cy) = (nx / r, ny / r);
            let mut coarse: Vec<C64> = (0..cy).flat_map(|j| (0..cx).map(move |i| (i, j))).map(|(i, j)| at(r * i, r * j)).collect();
            let fine = fourier_resample(&mut coarse, cx, cy, nx, ny);
            let err =
                (0..ny).flat_map(|j| (0..nx).map(move |i| (i, j))).map(|(i, j)| (fine[j * nx + i] - at(i, j)).norm()).fold(0.0, f64::max);
            assert!(err < 1e-12, "{nx} x {ny} by {r}: error {err:.2e}");
        }
    }

    #[test]
    fn fourier_resampling_reproduces_a_band_limited_field_on_a_lattice_of_another_ratio() {
        // The same plane waves on a coarse lattice and on one of the same period 3/2 or 5/3
        // times finer (samples that do not fall on coarse ones): only rounding.
        for (cx, cy, nx, ny) in [(24, 18, 36, 27), (30, 24, 50, 40), (20, 30, 30, 30)] {
            let waves = [(1.0, 2.0, C64::new(1.0, 0.3)), (-3.0, 1.0, C64::new(-0.4, 0.8)), (2.0, -3.0, C64::new(0.2, -0.1))];
            let at = |x: f64, y: f64| -> C64 {
                waves.iter().map(|&(fx, fy, a)| a * C64::from_polar(1.0, 2.0 * std::f64::consts::PI * (fx * x + fy * y))).sum()
            };
            let mut coarse: Vec<C64> =
                (0..cy).flat_map(|j| (0..cx).map(move |i| (i, j))).map(|(i, j)| at(i as f64 / cx as f64, j as f64 / cy as f64)).collect();
            let fine = fourier_resample(&mut coarse, cx, cy, nx, ny);
            let err = (0..ny)
                .flat_map(|j| (0..nx).map(move |i| (i, j)))
                .map(|(i, j)| (fine[j * nx + i] - at(i as f64 / nx as f64, j as f64 / ny as f64)).norm())
                .fold(0.0, f64::max);
            assert!(err < 1e-12, "{cx} x {cy} onto {nx} x {ny}: error {err:.2e}");
            let (c, f) = (random(cx * cy, 3), random(nx * ny, 4));
            let lhs: C64 = f.iter().zip(&fourier_resample(&mut c.clone(), cx, cy, nx, ny)).map(|(a, b)| a * b).sum();
            let rhs: C64 = fourier_resample_transposed(&f, cx, cy, nx, ny).iter().zip(&c).map(|(a, b)| a * b).sum();
            assert!((lhs - rhs).norm() < 1e-12 * lhs.norm().max(1.0), "{cx} x {cy} onto {nx} x {ny}: {lhs} vs {rhs}");
        }
    }

    /// Deterministic complex pseudo-random values with parts in [-0.5, 0.5).
    pub(crate) fn random(n: usize, seed: u64) -> Vec<C64> {
        let mut s = seed;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..n).map(|_| C64::new(rnd(), rnd())).collect()
    }

    #[test]
    fn transposed_upsampling_passes_the_dot_product_test() {
        // Σ c̄·c = Σ fine·U(c) for random c and fine: only rounding.
        for (nx, ny, r) in [(24, 18, 2), (30, 24, 3), (20, 30, 2)] {
            let (cx, cy) = (nx / r, ny / r);
            let (c, fine) = (random(cx * cy, 1), random(nx * ny, 2));
            let up = fourier_resample(&mut c.clone(), cx, cy, nx, ny);
            let lhs: C64 = fine.iter().zip(&up).map(|(a, b)| a * b).sum();
            let rhs: C64 = fourier_resample_transposed(&fine, cx, cy, nx, ny).iter().zip(&c).map(|(a, b)| a * b).sum();
            assert!((lhs - rhs).norm() < 1e-12 * lhs.norm().max(1.0), "{nx} x {ny} by {r}: {lhs} vs {rhs}");
        }
    }
}
