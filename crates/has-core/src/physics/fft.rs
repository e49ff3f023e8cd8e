//! 2-D FFTs of lateral slices: row FFTs, a blocked transpose, row FFTs again.
//!
//! Planned once ([`Fft2::new`]); every transform takes a caller-owned [`FftWorkspace`], so the
//! propagation loop does not allocate. No normalisation is applied: a forward then an inverse
//! transform multiplies by `nx·ny`. Frequencies are in FFT order (see [`crate::physics::grid::Grid::wavenumber`]).
//! Double precision by default; `Fft2<f32>` serves marches kept in single precision.

use num_complex::Complex;
use rayon::prelude::*;
use rustfft::{Fft, FftNum, FftPlanner};
use std::sync::Arc;

/// Row-major `(ny, nx)` 2-D FFT plans; the spectrum is left transposed, `(nx, ny)`.
#[derive(Clone)]
pub struct Fft2<T: FftNum = f64> {
    /// Samples along x (row length).
    pub nx: usize,
    /// Samples along y (number of rows).
    pub ny: usize,
    fwd_x: Arc<dyn Fft<T>>,
    inv_x: Arc<dyn Fft<T>>,
    fwd_y: Arc<dyn Fft<T>>,
    inv_y: Arc<dyn Fft<T>>,
    scratch_len: usize,
}

/// Buffers for one field's transforms: the transposed spectrum and per-chunk FFT scratch.
pub struct FftWorkspace<T: FftNum = f64> {
    /// The spectrum in transposed layout `(nx, ny)` after [`Fft2::forward`].
    pub spectrum: Vec<Complex<T>>,
    scratch: Vec<Vec<Complex<T>>>,
    parallel: bool,
}

impl<T: FftNum> FftWorkspace<T> {
    /// Whether its transforms spread rows over the pool (see [`Fft2::workspace`]).
    pub fn is_parallel(&self) -> bool {
        self.parallel
    }
}

impl<T: FftNum> Fft2<T> {
    /// Plans the four 1-D transforms.
    pub fn new(nx: usize, ny: usize) -> Self {
        let mut planner = FftPlanner::new();
        let fwd_x = planner.plan_fft_forward(nx);
        let inv_x = planner.plan_fft_inverse(nx);
        let fwd_y = planner.plan_fft_forward(ny);
        let inv_y = planner.plan_fft_inverse(ny);
        let scratch_len = [&fwd_x, &inv_x, &fwd_y, &inv_y].iter().map(|f| f.get_inplace_scratch_len()).max().unwrap_or(0);
        Fft2 { nx, ny, fwd_x, inv_x, fwd_y, inv_y, scratch_len }
    }

    /// A workspace; `parallel` spreads rows over the rayon pool (use for a single field, not inside
    /// an already parallel batch).
    pub fn workspace(&self, parallel: bool) -> FftWorkspace<T> {
        let chunks = if parallel { (2 * rayon::current_num_threads()).clamp(1, self.nx.min(self.ny)) } else { 1 };
        let zero = Complex::new(T::zero(), T::zero());
        FftWorkspace { spectrum: vec![zero; self.nx * self.ny], scratch: vec![vec![zero; self.scratch_len]; chunks], parallel }
    }

    /// `field` (ny, nx) → `ws.spectrum` (nx, ny), unnormalised. `field` is overwritten.
    pub fn forward(&self, field: &mut [Complex<T>], ws: &mut FftWorkspace<T>) {
        rows(&*self.fwd_x, field, self.nx, &mut ws.scratch, ws.parallel);
        transpose(field, &mut ws.spectrum, self.ny, self.nx, ws.parallel);
        rows(&*self.fwd_y, &mut ws.spectrum, self.ny, &mut ws.scratch, ws.parallel);
    }

    /// `ws.spectrum` (nx, ny) → `field` (ny, nx), unnormalised. The spectrum is overwritten.
    pub fn inverse(&self, ws: &mut FftWorkspace<T>, field: &mut [Complex<T>]) {
        rows(&*self.inv_y, &mut ws.spectrum, self.ny, &mut ws.scratch, ws.parallel);
        transpose(&ws.spectrum, field, self.nx, self.ny, ws.parallel);
        rows(&*self.inv_x, field, self.nx, &mut ws.scratch, ws.parallel);
    }

    /// `field ← post · IFFT2(kernel · FFT2(pre · field))` (one HAS step with `post` its screen;
    /// the transposed step with `pre` the screen), unnormalised like [`Fft2::forward`] then
    /// [`Fft2::inverse`], with `kernel` in the transposed layout `(nx, ny)`; `None`: no factor.
    /// The multiplies are fused into the row passes (the same operations in the same order, so the
    /// result is bit-identical to the separate calls): 3 passes over the data instead of 6–7.
    pub fn filter(
        &self,
        field: &mut [Complex<T>],
        ws: &mut FftWorkspace<T>,
        pre: Option<&[Complex<T>]>,
        kernel: &[Complex<T>],
        post: Option<&[Complex<T>]>,
    ) {
        let FftWorkspace { spectrum, scratch, parallel } = ws;
        let (fwd_x, inv_x, fwd_y, inv_y) = (&*self.fwd_x, &*self.inv_x, &*self.fwd_y, &*self.inv_y);
        row_chunks(field, self.nx, scratch, *parallel, |row, at, s| {
            if let Some(pre) = pre {
                row.iter_mut().zip(&pre[at..]).for_each(|(x, t)| *x = *x * *t);
            }
            fwd_x.process_with_scratch(row, s);
        });
        transpose(field, spectrum, self.ny, self.nx, *parallel);
        row_chunks(spectrum, self.ny, scratch, *parallel, |row, at, s| {
            fwd_y.process_with_scratch(row, s);
            row.iter_mut().zip(&kernel[at..]).for_each(|(x, k)| *x = *x * *k);
            inv_y.process_with_scratch(row, s);
        });
        transpose(spectrum, field, self.nx, self.ny, *parallel);
        row_chunks(field, self.nx, scratch, *parallel, |row, at, s| {
            inv_x.process_with_scratch(row, s);
            if let Some(post) = post {
                row.iter_mut().zip(&post[at..]).for_each(|(x, p)| *x = *x * *p);
            }
        });
    }
}

/// In-place FFT of every length-`len` row of `data`.
fn rows<T: FftNum>(fft: &dyn Fft<T>, data: &mut [Complex<T>], len: usize, scratch: &mut [Vec<Complex<T>>], parallel: bool) {
    row_chunks(data, len, scratch, parallel, |row, _, s| fft.process_with_scratch(row, s));
}

/// Calls `f(row, start, scratch)` on every length-`len` row of `data` (`start`: the row's first
/// sample in `data`), the rows spread over the pool in one chunk per scratch buffer when `parallel`.
fn row_chunks<T: FftNum>(
    data: &mut [Complex<T>],
    len: usize,
    scratch: &mut [Vec<Complex<T>>],
    parallel: bool,
    f: impl Fn(&mut [Complex<T>], usize, &mut [Complex<T>]) + Sync,
) {
    let chunk = |(d, s, first): (&mut [Complex<T>], &mut Vec<Complex<T>>, usize)| {
        for (i, row) in d.chunks_exact_mut(len).enumerate() {
            f(row, first + i * len, s);
        }
    };
    if parallel && scratch.len() > 1 {
        let per = (data.len() / len).div_ceil(scratch.len()) * len;
        data.par_chunks_mut(per).zip(scratch.par_iter_mut()).enumerate().for_each(|(i, (d, s))| chunk((d, s, i * per)));
    } else {
        chunk((data, &mut scratch[0], 0));
    }
}

/// `dst[c·rows + r] = src[r·cols + c]`, in 32 x 32 blocks.
pub fn transpose<V: Copy + Send + Sync>(src: &[V], dst: &mut [V], rows: usize, cols: usize, parallel: bool) {
    const B: usize = 32;
    let block = |(cb, out): (usize, &mut [V])| {
        let c0 = cb * B;
        let nc = out.len() / rows;
        for r0 in (0..rows).step_by(B) {
            for r in r0..(r0 + B).min(rows) {
                let s = &src[r * cols + c0..r * cols + c0 + nc];
                for (c, v) in s.iter().enumerate() {
                    out[c * rows + r] = *v;
                }
            }
        }
    };
    if parallel {
        dst.par_chunks_mut(B * rows).enumerate().for_each(block);
    } else {
        dst.chunks_mut(B * rows).enumerate().for_each(block);
    }
}

/// Samples per task of the element-wise loops spread over the pool.
pub(crate) const CHUNK: usize = 1 << 14;

/// `f(a, b)` for each pair of samples, spread over the pool when `parallel` (each sample alone:
/// the same result with any number of threads).
pub fn each_pair<A: Send, B: Sync>(parallel: bool, a: &mut [A], b: &[B], f: impl Fn(&mut A, &B) + Sync) {
    if parallel {
        a.par_chunks_mut(CHUNK).zip(b.par_chunks(CHUNK)).for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(a, b)| f(a, b)));
    } else {
        a.iter_mut().zip(b).for_each(|(a, b)| f(a, b));
    }
}

/// `f` of each sample, collected; spread over the pool when `parallel` (a new buffer is written,
/// and its pages first touched, by every thread at once).
pub fn map_collect<A: Sync, B: Send>(parallel: bool, a: &[A], f: impl Fn(&A) -> B + Sync + Send) -> Vec<B> {
    if parallel {
        a.par_iter().with_min_len(CHUNK).map(f).collect()
    } else {
        a.iter().map(f).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64 as C64;

    /// Direct O(N²) DFT, the slow obvious reference.
    fn dft2(x: &[C64], nx: usize, ny: usize) -> Vec<C64> {
        let mut out = vec![C64::new(0.0, 0.0); nx * ny];
        for ky in 0..ny {
            for kx in 0..nx {
                let mut acc = C64::new(0.0, 0.0);
                for j in 0..ny {
                    for i in 0..nx {
                        let ph = -2.0 * std::f64::consts::PI * ((kx * i) as f64 / nx as f64 + (ky * j) as f64 / ny as f64);
                        acc += x[j * nx + i] * C64::from_polar(1.0, ph);
                    }
                }
                out[kx * ny + ky] = acc; // transposed layout
            }
        }
        out
    }

    #[test]
    fn matches_direct_dft_and_round_trips() {
        let (nx, ny) = (12, 10);
        // Fixed pseudo-random input (LCG) so the test is deterministic.
        let mut s = 12345u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let x: Vec<C64> = (0..nx * ny).map(|_| C64::new(rnd(), rnd())).collect();
        let reference = dft2(&x, nx, ny);
        for parallel in [false, true] {
            let f = Fft2::new(nx, ny);
            let mut ws = f.workspace(parallel);
            let mut field = x.clone();
            f.forward(&mut field, &mut ws);
            let err = ws.spectrum.iter().zip(&reference).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
            assert!(err < 1e-11, "forward error {err}");
            f.inverse(&mut ws, &mut field);
            let err = field.iter().zip(&x).map(|(a, b)| (a / (nx * ny) as f64 - b).norm()).fold(0.0, f64::max);
            assert!(err < 1e-14, "round trip error {err}");
        }
    }

    #[test]
    fn fused_filter_is_bit_identical_to_the_separate_steps() {
        // 40 x 36: rows and columns spread over several parallel chunks.
        for (nx, ny) in [(12, 10), (40, 36)] {
            fused_filter_matches_separate_steps(nx, ny);
        }
    }

    fn fused_filter_matches_separate_steps(nx: usize, ny: usize) {
        let wave = |k: usize, a: f64| C64::new((a * k as f64).sin(), (0.3 * a * k as f64).cos());
        let x: Vec<C64> = (0..nx * ny).map(|k| wave(k, 0.7)).collect();
        let pre: Vec<C64> = (0..nx * ny).map(|k| wave(k, 0.4)).collect();
        let kernel: Vec<C64> = (0..nx * ny).map(|k| wave(k, 1.3)).collect();
        let post: Vec<C64> = (0..nx * ny).map(|k| wave(k, 0.2)).collect();
        for parallel in [false, true] {
            let f = Fft2::new(nx, ny);
            let mut ws = f.workspace(parallel);
            let mut separate = x.clone();
            each_pair(parallel, &mut separate, &pre, |x, y| *x *= y);
            f.forward(&mut separate, &mut ws);
            each_pair(parallel, &mut ws.spectrum, &kernel, |x, y| *x *= y);
            f.inverse(&mut ws, &mut separate);
            each_pair(parallel, &mut separate, &post, |x, y| *x *= y);
            let mut fused = x.clone();
            f.filter(&mut fused, &mut ws, Some(&pre), &kernel, Some(&post));
            assert_eq!(fused, separate, "parallel = {parallel}");
        }
    }
}
