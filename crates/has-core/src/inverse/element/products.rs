//! The element basis's two products on one block of sample rows: the fields `P = B·V` and the
//! back projection `C = Bᵀ·H`, for `B` (rows x elements, complex, split into real and
//! imaginary parts, row-major, single precision) and a few columns `V` or `H` (one per image).
//!
//! A general matrix product packs `B` on every call, which at a few columns costs more than the
//! multiplications (packing would take more than half of a per-element estimate's time,
//! BENCHMARKS.md, the element basis's products); these loops
//! read each row of `B` once per call instead. Sums run in [`LANES`] single-precision partial
//! sums, in a fixed order: on one CPU the same bits for any number of threads. Compiled for AVX2
//! with fused multiply-adds too, chosen at run time (the crate builds for baseline x86-64); the
//! fused and plain variants round differently.

use num_complex::Complex32 as C32;
use std::ops::Range;

/// Lanes of the single-precision partial sums.
const LANES: usize = 8;

/// A row-major complex matrix in split parts: `re[r·cols + e]`, `im[r·cols + e]`.
#[derive(Clone, Copy)]
pub(super) struct Split<'a> {
    pub re: &'a [f32],
    pub im: &'a [f32],
    pub cols: usize,
}

impl<'a> Split<'a> {
    fn row(&self, r: usize) -> (&'a [f32], &'a [f32]) {
        let span = r * self.cols..(r + 1) * self.cols;
        (&self.re[span.clone()], &self.im[span])
    }
}

/// Multiply-add as the CPU allows: fused where it has FMA.
trait MulAdd {
    /// `a·b + c`.
    fn madd(a: f32, b: f32, c: f32) -> f32;
}

/// `a·b + c` rounded twice (any CPU).
struct Plain;

/// `a·b + c` rounded once (FMA instructions).
#[cfg(target_arch = "x86_64")]
struct Fused;

impl MulAdd for Plain {
    #[inline(always)]
    fn madd(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }
}

#[cfg(target_arch = "x86_64")]
impl MulAdd for Fused {
    #[inline(always)]
    fn madd(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
}

/// Whether the CPU runs the AVX2 and FMA variants.
#[cfg(target_arch = "x86_64")]
fn wide() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

/// Columns handled in one pass over a row of `B`.
const PASS: usize = 4;

/// One column of `V` as [`fields`] reads it: the real part, the imaginary part and its negation
/// (one value per element each), so that each complex product is four multiply-adds.
pub(super) struct Column([Vec<f32>; 3]);

impl Column {
    pub(super) fn new(re: Vec<f32>, im: Vec<f32>) -> Self {
        let negated = im.iter().map(|x| -x).collect();
        Column([re, im, negated])
    }
}

/// `P[r, c] = Σ_e B[r, e]·V_c[e]` for rows `rows` of `b` and columns `v`; row-major,
/// `rows.len()` x `v.len()`.
pub(super) fn fields(b: Split, rows: Range<usize>, v: &[Column]) -> Vec<C32> {
    #[cfg(target_arch = "x86_64")]
    if wide() {
        // SAFETY: the CPU has AVX2 and FMA (checked on the line above).
        return unsafe { fields_wide(b, rows, v) };
    }
    fields_with::<Plain>(b, rows, v)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fields_wide(b: Split, rows: Range<usize>, v: &[Column]) -> Vec<C32> {
    fields_with::<Fused>(b, rows, v)
}

#[inline(always)]
fn fields_with<M: MulAdd>(b: Split, rows: Range<usize>, v: &[Column]) -> Vec<C32> {
    let mut out = Vec::with_capacity(rows.len() * v.len());
    for r in rows {
        let row = b.row(r);
        for pass in v.chunks(PASS) {
            match pass {
                [a, b, c, d] => out.extend(row_dots::<M, 4>(row, [a, b, c, d])),
                [a, b, c] => out.extend(row_dots::<M, 3>(row, [a, b, c])),
                [a, b] => out.extend(row_dots::<M, 2>(row, [a, b])),
                [a] => out.extend(row_dots::<M, 1>(row, [a])),
                _ => unreachable!("chunks of at most PASS columns"),
            }
        }
    }
    out
}

/// One row of `B` times `C` columns, in [`LANES`] partial sums per column.
#[inline(always)]
fn row_dots<M: MulAdd, const C: usize>((br, bi): (&[f32], &[f32]), v: [&Column; C]) -> [C32; C] {
    let n = br.len();
    let body = n - n % LANES;
    let (mut re, mut im) = ([[0f32; LANES]; C], [[0f32; LANES]; C]);
    for start in (0..body).step_by(LANES) {
        let span = start..start + LANES;
        let (a, c) = (&br[span.clone()], &bi[span.clone()]);
        for k in 0..C {
            let [x, y, ny] = v[k].0.each_ref().map(|part| &part[span.clone()]);
            for l in 0..LANES {
                re[k][l] = M::madd(c[l], ny[l], M::madd(a[l], x[l], re[k][l]));
                im[k][l] = M::madd(c[l], x[l], M::madd(a[l], y[l], im[k][l]));
            }
        }
    }
    std::array::from_fn(|k| {
        let [x, y, _] = &v[k].0;
        for e in body..n {
            re[k][0] += br[e] * x[e] - bi[e] * y[e];
            im[k][0] += br[e] * y[e] + bi[e] * x[e];
        }
        C32::new(lane_sum(&re[k]), lane_sum(&im[k]))
    })
}

/// `C_c[e] = Σ_r B[r, e]·H[r, c]` over rows `rows` of `b`, with `h` row-major (`rows.len()` x
/// columns); one pair of real and imaginary parts per column, one value per element. Rows
/// where `H` is zero are skipped (they add exactly nothing).
pub(super) fn back_project(b: Split, rows: Range<usize>, h: &[C32], columns: usize) -> Vec<(Vec<f32>, Vec<f32>)> {
    #[cfg(target_arch = "x86_64")]
    if wide() {
        // SAFETY: the CPU has AVX2 and FMA (checked on the line above).
        return unsafe { back_project_wide(b, rows, h, columns) };
    }
    back_project_with::<Plain>(b, rows, h, columns)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn back_project_wide(b: Split, rows: Range<usize>, h: &[C32], columns: usize) -> Vec<(Vec<f32>, Vec<f32>)> {
    back_project_with::<Fused>(b, rows, h, columns)
}

#[inline(always)]
fn back_project_with<M: MulAdd>(b: Split, rows: Range<usize>, h: &[C32], columns: usize) -> Vec<(Vec<f32>, Vec<f32>)> {
    let n = b.cols;
    let body = n - n % LANES;
    let mut out = vec![(vec![0f32; n], vec![0f32; n]); columns];
    for (r, hs) in rows.zip(h.chunks_exact(columns)) {
        let (br, bi) = b.row(r);
        for (&hv, (cr, ci)) in hs.iter().zip(out.iter_mut()) {
            if hv == C32::new(0.0, 0.0) {
                continue;
            }
            let (x, y, ny) = (hv.re, hv.im, -hv.im);
            let lanes = br[..body].chunks_exact(LANES).zip(bi[..body].chunks_exact(LANES));
            for ((a, c), (sr, si)) in lanes.zip(cr[..body].chunks_exact_mut(LANES).zip(ci[..body].chunks_exact_mut(LANES))) {
                for l in 0..LANES {
                    sr[l] = M::madd(c[l], ny, M::madd(a[l], x, sr[l]));
                    si[l] = M::madd(c[l], x, M::madd(a[l], y, si[l]));
                }
            }
            for e in body..n {
                cr[e] += br[e] * x - bi[e] * y;
                ci[e] += br[e] * y + bi[e] * x;
            }
        }
    }
    out
}

/// The partial sums' total, added in double precision.
fn lane_sum(lanes: &[f32; LANES]) -> f32 {
    lanes.iter().map(|&v| f64::from(v)).sum::<f64>() as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64 as C64;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
        (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    /// Both products, in the variant this CPU runs and in the plain one, against plain
    /// double-precision sums, with an element count that leaves a remainder after the lanes, five
    /// columns (a pass of four and one), a zero row of `H` and rows from the middle of `B`.
    /// Tolerance: 1e-5 of the sum of the terms' magnitudes (single-precision rounding over 101
    /// terms in 8 lanes is below 1e-6 of it; a wrong index or sign is of order 1).
    #[test]
    fn the_products_match_double_precision_sums() {
        type Fields = fn(Split, Range<usize>, &[Column]) -> Vec<C32>;
        type BackProject = fn(Split, Range<usize>, &[C32], usize) -> Vec<(Vec<f32>, Vec<f32>)>;
        let variants: [(&str, Fields, BackProject); 2] =
            [("chosen", fields, back_project), ("plain", fields_with::<Plain>, back_project_with::<Plain>)];
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (n_rows, n, k) = (23, 101, 5);
        let (re, im) = (random(&mut rng, n_rows * n), random(&mut rng, n_rows * n));
        let b = Split { re: &re, im: &im, cols: n };
        let bz = |r: usize, e: usize| C64::new(f64::from(re[r * n + e]), f64::from(im[r * n + e]));
        let v: Vec<(Vec<f32>, Vec<f32>)> = (0..k).map(|_| (random(&mut rng, n), random(&mut rng, n))).collect();
        let columns: Vec<Column> = v.iter().map(|(re, im)| Column::new(re.clone(), im.clone())).collect();
        let rows = 5..19;
        let mut h: Vec<C32> = (0..rows.len() * k).map(|_| C32::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))).collect();
        h[3 * k..4 * k].fill(C32::new(0.0, 0.0));
        for (name, fields, back_project) in variants {
            let p = fields(b, rows.clone(), &columns);
            for (i, r) in rows.clone().enumerate() {
                for (c, (vr, vi)) in v.iter().enumerate() {
                    let terms: Vec<C64> = (0..n).map(|e| bz(r, e) * C64::new(f64::from(vr[e]), f64::from(vi[e]))).collect();
                    let scale: f64 = terms.iter().map(|t| t.norm()).sum();
                    let exact: C64 = terms.iter().sum();
                    let got = C64::new(f64::from(p[i * k + c].re), f64::from(p[i * k + c].im));
                    assert!((got - exact).norm() < 1e-5 * scale, "{name}: P[{r}, {c}] = {got} against {exact}");
                }
            }
            let c = back_project(b, rows.clone(), &h, k);
            for (col, (cr, ci)) in c.iter().enumerate() {
                for e in 0..n {
                    let terms: Vec<C64> = rows
                        .clone()
                        .enumerate()
                        .map(|(i, r)| bz(r, e) * C64::new(f64::from(h[i * k + col].re), f64::from(h[i * k + col].im)))
                        .collect();
                    let scale: f64 = terms.iter().map(|t| t.norm()).sum();
                    let exact: C64 = terms.iter().sum();
                    let got = C64::new(f64::from(cr[e]), f64::from(ci[e]));
                    assert!((got - exact).norm() < 1e-5 * scale, "{name}: C_{col}[{e}] = {got} against {exact}");
                }
            }
        }
    }
}
