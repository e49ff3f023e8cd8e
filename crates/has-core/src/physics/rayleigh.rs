//! The Rayleigh integral of a baffled velocity source, summed over quadrature points:
//! `p(r) = -(i·k / 2·pi) · Σ_q w_q · exp((i·k - alpha)·R_q) / R_q` with `w_q` = drive × area
//! (time convention `exp(-i·omega·t)`).
//!
//! [`Sources::row`] is the fast form used for projections: distances, phases and the sum run in
//! single precision over blocks of [`BLOCK`] points (a vectorisable polynomial `sin`/`cos`,
//! loops the compiler turns into SIMD), each block's sum added to a double-precision total.
//! [`row_f64`] is the obvious double-precision sum it is tested against (agreement ~1e-6 of the
//! peak: the phase `k·R` in single precision is good to ~1e-5 rad for paths up to 0.3 m at
//! 1 MHz).
//!
//! The sums are compiled twice: for the baseline x86-64 (4 single-precision lanes) and for AVX2
//! (8 lanes), chosen when the CPU has it. Both do the same IEEE operations pixel by pixel (no
//! fused multiply-add), so they give the same bits (tested), twice as fast with AVX2.

use num_complex::Complex64 as C64;

/// Points summed in single precision before their sum joins the double-precision total.
pub const BLOCK: usize = 64;

/// Quadrature points prepared for the sums onto the plane `z = z0`: x (single precision, m),
/// y and the height `z0 - z` (double precision, combined once per row), and the weights.
pub struct Sources {
    x: Vec<f32>,
    y: Vec<f64>,
    height: Vec<f64>,
    w_re: Vec<f32>,
    w_im: Vec<f32>,
    k: f64,
    alpha: f64,
}

impl Sources {
    /// `points`: position (m) and weight (drive × area); wavenumber `k` (rad/m) and attenuation
    /// `alpha` (Np/m) of the medium; the plane `z0` (m).
    pub fn new(points: &[([f64; 3], C64)], z0: f64, k: f64, alpha: f64) -> Self {
        Sources {
            x: points.iter().map(|(p, _)| p[0] as f32).collect(),
            y: points.iter().map(|(p, _)| p[1]).collect(),
            height: points.iter().map(|(p, _)| z0 - p[2]).collect(),
            w_re: points.iter().map(|(_, w)| w.re as f32).collect(),
            w_im: points.iter().map(|(_, w)| w.im as f32).collect(),
            k,
            alpha,
        }
    }

    /// The integral at `(x, y, z0)` for every `x` in `xs`.
    pub fn row(&self, xs: &[f64], y: f64) -> Vec<C64> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked on the line above).
            return unsafe { self.row_avx2(xs, y) };
        }
        self.row_portable(xs, y)
    }

    /// [`Sources::row`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn row_avx2(&self, xs: &[f64], y: f64) -> Vec<C64> {
        self.row_portable(xs, y)
    }

    #[inline(always)]
    fn row_portable(&self, xs: &[f64], y: f64) -> Vec<C64> {
        let n = xs.len();
        let xs32: Vec<f32> = xs.iter().map(|&x| x as f32).collect();
        let (k, alpha) = (self.k as f32, self.alpha as f32);
        let mut total = vec![C64::new(0.0, 0.0); n];
        let (mut re, mut im) = (vec![0f32; n], vec![0f32; n]);
        for start in (0..self.x.len()).step_by(BLOCK) {
            re.fill(0.0);
            im.fill(0.0);
            for q in start..(start + BLOCK).min(self.x.len()) {
                let dy = y - self.y[q];
                let d2 = (dy * dy + self.height[q] * self.height[q]) as f32;
                let (px, wr, wi) = (self.x[q], self.w_re[q], self.w_im[q]);
                let lanes = re.iter_mut().zip(im.iter_mut()).zip(&xs32);
                if alpha > 0.0 {
                    for ((a, b), &x) in lanes {
                        let dx = x - px;
                        let r = (dx * dx + d2).sqrt();
                        let (s, c) = sin_cos(k * r);
                        let f = (-alpha * r).exp() / r;
                        *a += f * (wr * c - wi * s);
                        *b += f * (wr * s + wi * c);
                    }
                } else {
                    for ((a, b), &x) in lanes {
                        let dx = x - px;
                        let r = (dx * dx + d2).sqrt();
                        let (s, c) = sin_cos(k * r);
                        let f = 1.0 / r;
                        *a += f * (wr * c - wi * s);
                        *b += f * (wr * s + wi * c);
                    }
                }
            }
            total.iter_mut().zip(re.iter().zip(&im)).for_each(|(t, (&a, &b))| *t += C64::new(a as f64, b as f64));
        }
        let pre = C64::new(0.0, -self.k / (2.0 * std::f64::consts::PI));
        total.iter_mut().for_each(|v| *v *= pre);
        total
    }

    /// [`Sources::row`] for several weight sets on the same points at once (`weights[set][point]`,
    /// complex): the kernel `exp((i·k - alpha)·R) / R` of each point and pixel is evaluated once
    /// and summed with every set's weight (`out[set][x]`). The same single-precision blocks.
    pub fn row_many(&self, weights: &[Vec<C64>], xs: &[f64], y: f64) -> Vec<Vec<C64>> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked on the line above).
            return unsafe { self.row_many_avx2(weights, xs, y) };
        }
        self.row_many_portable(weights, xs, y)
    }

    /// [`Sources::row_many`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn row_many_avx2(&self, weights: &[Vec<C64>], xs: &[f64], y: f64) -> Vec<Vec<C64>> {
        self.row_many_portable(weights, xs, y)
    }

    #[inline(always)]
    fn row_many_portable(&self, weights: &[Vec<C64>], xs: &[f64], y: f64) -> Vec<Vec<C64>> {
        let n = xs.len();
        let xs32: Vec<f32> = xs.iter().map(|&x| x as f32).collect();
        let (k, alpha) = (self.k as f32, self.alpha as f32);
        let parts: Vec<(Vec<f32>, Vec<f32>)> =
            weights.iter().map(|w| (w.iter().map(|v| v.re as f32).collect(), w.iter().map(|v| v.im as f32).collect())).collect();
        let mut totals = vec![vec![C64::new(0.0, 0.0); n]; weights.len()];
        let mut sums = vec![(vec![0f32; n], vec![0f32; n]); weights.len()];
        let (mut kc, mut ks) = (vec![0f32; n], vec![0f32; n]);
        for start in (0..self.x.len()).step_by(BLOCK) {
            sums.iter_mut().for_each(|(re, im)| {
                re.fill(0.0);
                im.fill(0.0);
            });
            for q in start..(start + BLOCK).min(self.x.len()) {
                let dy = y - self.y[q];
                let d2 = (dy * dy + self.height[q] * self.height[q]) as f32;
                let px = self.x[q];
                for ((c_out, s_out), &x) in kc.iter_mut().zip(ks.iter_mut()).zip(&xs32) {
                    let dx = x - px;
                    let r = (dx * dx + d2).sqrt();
                    let (s, c) = sin_cos(k * r);
                    let f = if alpha > 0.0 { (-alpha * r).exp() / r } else { 1.0 / r };
                    (*c_out, *s_out) = (f * c, f * s);
                }
                for ((re, im), (w_re, w_im)) in sums.iter_mut().zip(&parts) {
                    let (wr, wi) = (w_re[q], w_im[q]);
                    for (((a, b), &c), &s) in re.iter_mut().zip(im.iter_mut()).zip(&kc).zip(&ks) {
                        *a += wr * c - wi * s;
                        *b += wr * s + wi * c;
                    }
                }
            }
            for (total, (re, im)) in totals.iter_mut().zip(&sums) {
                total.iter_mut().zip(re.iter().zip(im)).for_each(|(t, (&a, &b))| *t += C64::new(a as f64, b as f64));
            }
        }
        let pre = C64::new(0.0, -self.k / (2.0 * std::f64::consts::PI));
        totals.iter_mut().flatten().for_each(|v| *v *= pre);
        totals
    }
}

/// The transposed sum: for each field `v` of `fields` on the pixels `(xs[i], ys[j], z0)` of a
/// plane (row-major `(ys.len(), xs.len())`), `Σ_pixels v · (-(i·k / 2·pi) · exp((i·k - alpha)·R) /
/// R)` at each of `points` (`out[field][point]`), so that `Σ_q w_q · out_q` equals
/// `Σ_pixels v · p` for the field `p` that [`Sources::row`] gives for weights `w_q` at `points`
/// (the kernel depends on the distance only). Each row's kernel is evaluated once in single
/// precision and dotted with every field in [`LANES`] lanes; rows add in double precision; one
/// rayon task per point.
pub fn at_points(fields: &[Vec<C64>], xs: &[f64], ys: &[f64], z0: f64, points: &[[f64; 3]], k: f64, alpha: f64) -> Vec<Vec<C64>> {
    use rayon::prelude::*;
    let plane = Plane::new(fields.iter().map(Vec::as_slice), xs, ys, z0, k, alpha);
    #[cfg(target_arch = "x86_64")]
    let wide = std::arch::is_x86_feature_detected!("avx2");
    let pre = C64::new(0.0, -k / (2.0 * std::f64::consts::PI));
    let per_point: Vec<Vec<C64>> = points
        .par_iter()
        .map_init(
            || (vec![0f32; xs.len()], vec![0f32; xs.len()]),
            |(kr, ki), p| {
                #[cfg(target_arch = "x86_64")]
                if wide {
                    // SAFETY: the CPU has AVX2 (checked once above).
                    return unsafe { plane.sums_avx2(*p, kr, ki) }.iter().map(|t| pre * t).collect();
                }
                plane.sums(*p, kr, ki).iter().map(|t| pre * t).collect()
            },
        )
        .collect();
    (0..fields.len()).map(|f| per_point.iter().map(|v| v[f]).collect()).collect()
}

/// The gradient of [`at_points`]' sum with respect to the point: for `field` on the same pixels,
/// `∇_q Σ_pixels v · (-(i·k / 2·pi) · K(R))` at each of `points`, `K(R) = exp((i·k - alpha)·R) / R`,
/// `R = |x - q|`: the kernel's derivative `K'(R) · ∂R/∂q = -K'(R) · (x - q) / R` summed on the same
/// pixels, so that it is the derivative of the same discrete sum (the rate at which the sum
/// changes as the point moves), not of the continuous integral. Single precision per row, as
/// [`at_points`].
pub fn gradient_at_points(field: &[C64], xs: &[f64], ys: &[f64], z0: f64, points: &[[f64; 3]], k: f64, alpha: f64) -> Vec<[C64; 3]> {
    use rayon::prelude::*;
    let plane = Plane::new(std::iter::once(field), xs, ys, z0, k, alpha);
    #[cfg(target_arch = "x86_64")]
    let wide = std::arch::is_x86_feature_detected!("avx2");
    let pre = C64::new(0.0, -k / (2.0 * std::f64::consts::PI));
    points
        .par_iter()
        .map_init(
            || std::array::from_fn::<Vec<f32>, 4, _>(|_| vec![0f32; xs.len()]),
            |rows, p| {
                #[cfg(target_arch = "x86_64")]
                if wide {
                    // SAFETY: the CPU has AVX2 (checked once above).
                    return unsafe { plane.gradient_avx2(*p, rows) }.map(|t| pre * t);
                }
                plane.gradient(*p, rows).map(|t| pre * t)
            },
        )
        .collect()
}

/// The plane of [`at_points`]: pixel coordinates and the fields in single precision.
struct Plane<'a> {
    xs: Vec<f32>,
    ys: &'a [f64],
    z0: f64,
    parts: Vec<(Vec<f32>, Vec<f32>)>,
    k: f32,
    alpha: f32,
}

impl<'a> Plane<'a> {
    /// The pixels `(xs[i], ys[j], z0)` with `fields` on them, in single precision, and the
    /// kernel's `k` and `alpha`.
    fn new<'f>(fields: impl Iterator<Item = &'f [C64]>, xs: &[f64], ys: &'a [f64], z0: f64, k: f64, alpha: f64) -> Self {
        Plane {
            xs: xs.iter().map(|&x| x as f32).collect(),
            ys,
            z0,
            parts: fields.map(|v| (v.iter().map(|v| v.re as f32).collect(), v.iter().map(|v| v.im as f32).collect())).collect(),
            k: k as f32,
            alpha: alpha as f32,
        }
    }

    /// [`Plane::sums`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sums_avx2(&self, p: [f64; 3], kr: &mut [f32], ki: &mut [f32]) -> Vec<C64> {
        self.sums(p, kr, ki)
    }

    /// [`Plane::gradient`] compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn gradient_avx2(&self, p: [f64; 3], rows: &mut [Vec<f32>; 4]) -> [C64; 3] {
        self.gradient(p, rows)
    }

    /// The first field's sum with the kernel's gradient in `p` (without the prefactor; see
    /// [`gradient_at_points`]): per row, with `G = K'(R)/R`, the sums `S₀ = Σ v·G` and
    /// `S₁ = Σ v·G·(x - p_x)` give `-(S₁, (y - p_y)·S₀, (z0 - p_z)·S₀)`. `rows` hold one row of
    /// `G` and of `G·(x - p_x)` (real and imaginary parts, overwritten).
    #[inline(always)]
    fn gradient(&self, p: [f64; 3], rows: &mut [Vec<f32>; 4]) -> [C64; 3] {
        let nx = self.xs.len();
        let (px, h) = (p[0] as f32, self.z0 - p[2]);
        let (v_re, v_im) = &self.parts[0];
        let mut total = [C64::new(0.0, 0.0); 3];
        let [gr, gi, hr, hi] = rows;
        for (j, &y) in self.ys.iter().enumerate() {
            let dy = y - p[1];
            let d2 = (dy * dy + h * h) as f32;
            for (((a, b), (c, d)), &x) in gr.iter_mut().zip(gi.iter_mut()).zip(hr.iter_mut().zip(hi.iter_mut())).zip(&self.xs) {
                let dx = x - px;
                let r = (dx * dx + d2).sqrt();
                let (s, co) = sin_cos(self.k * r);
                let f = if self.alpha > 0.0 { (-self.alpha * r).exp() / r } else { 1.0 / r } / r;
                // K'(R) = K·(i·k - alpha - 1/R).
                let m = -self.alpha - 1.0 / r;
                let (g_re, g_im) = (f * (co * m - s * self.k), f * (s * m + co * self.k));
                (*a, *b, *c, *d) = (g_re, g_im, g_re * dx, g_im * dx);
            }
            let row = j * nx..(j + 1) * nx;
            let (mut s0, mut s1) = (([0f32; LANES], [0f32; LANES]), ([0f32; LANES], [0f32; LANES]));
            let lanes = gr.chunks(LANES).zip(gi.chunks(LANES)).zip(hr.chunks(LANES).zip(hi.chunks(LANES)));
            for (((g_re, g_im), (h_re, h_im)), (vr, vi)) in lanes.zip(v_re[row.clone()].chunks(LANES).zip(v_im[row].chunks(LANES))) {
                for l in 0..g_re.len() {
                    s0.0[l] += vr[l] * g_re[l] - vi[l] * g_im[l];
                    s0.1[l] += vr[l] * g_im[l] + vi[l] * g_re[l];
                    s1.0[l] += vr[l] * h_re[l] - vi[l] * h_im[l];
                    s1.1[l] += vr[l] * h_im[l] + vi[l] * h_re[l];
                }
            }
            let sum =
                |(re, im): ([f32; LANES], [f32; LANES])| C64::new(re.iter().map(|&a| a as f64).sum(), im.iter().map(|&b| b as f64).sum());
            let (s0, s1) = (sum(s0), sum(s1));
            total[0] -= s1;
            total[1] -= dy * s0;
            total[2] -= h * s0;
        }
        total
    }

    /// Each field's sum with the kernel `exp((i·k - alpha)·R) / R` from the point `p` (without
    /// the prefactor); `kr`, `ki` hold one row of the kernel (overwritten).
    #[inline(always)]
    fn sums(&self, p: [f64; 3], kr: &mut [f32], ki: &mut [f32]) -> Vec<C64> {
        let nx = self.xs.len();
        let (px, h2) = (p[0] as f32, (self.z0 - p[2]) * (self.z0 - p[2]));
        let mut totals = vec![C64::new(0.0, 0.0); self.parts.len()];
        for (j, &y) in self.ys.iter().enumerate() {
            let d2 = ((y - p[1]) * (y - p[1]) + h2) as f32;
            for ((a, b), &x) in kr.iter_mut().zip(ki.iter_mut()).zip(&self.xs) {
                let dx = x - px;
                let r = (dx * dx + d2).sqrt();
                let (s, c) = sin_cos(self.k * r);
                let f = if self.alpha > 0.0 { (-self.alpha * r).exp() / r } else { 1.0 / r };
                (*a, *b) = (f * c, f * s);
            }
            for ((v_re, v_im), total) in self.parts.iter().zip(totals.iter_mut()) {
                let (mut re, mut im) = ([0f32; LANES], [0f32; LANES]);
                let row = j * nx..(j + 1) * nx;
                let lanes = kr.chunks(LANES).zip(ki.chunks(LANES)).zip(v_re[row.clone()].chunks(LANES).zip(v_im[row].chunks(LANES)));
                for ((c, s), (vr, vi)) in lanes {
                    for l in 0..c.len() {
                        re[l] += vr[l] * c[l] - vi[l] * s[l];
                        im[l] += vr[l] * s[l] + vi[l] * c[l];
                    }
                }
                *total += C64::new(re.iter().map(|&a| a as f64).sum(), im.iter().map(|&b| b as f64).sum());
            }
        }
        totals
    }
}

/// Lanes of the single-precision partial sums in [`at_points`].
pub const LANES: usize = 8;

/// The same integral in double precision, point by point (the slow obvious reference).
pub fn row_f64(points: &[([f64; 3], C64)], xs: &[f64], y: f64, z0: f64, k: f64, alpha: f64) -> Vec<C64> {
    let pre = C64::new(0.0, -k / (2.0 * std::f64::consts::PI));
    xs.iter()
        .map(|&x| {
            let sum: C64 = points
                .iter()
                .map(|(p, w)| {
                    let r = ((x - p[0]).powi(2) + (y - p[1]).powi(2) + (z0 - p[2]).powi(2)).sqrt();
                    w * C64::from_polar((-alpha * r).exp() / r, k * r)
                })
                .sum();
            pre * sum
        })
        .collect()
}

/// `(sin x, cos x)` in single precision for `0 <= x < 2^22` (absolute error ~1e-7 plus the
/// rounding of `x`): `x = q·pi/2 + t` with `|t| <= pi/4` (three-part Cody–Waite reduction), the
/// Cephes minimax polynomials on `t`, and the quadrant `q mod 4` chosen with bit operations (no
/// branch, so loops over it vectorise).
#[inline(always)]
fn sin_cos(x: f32) -> (f32, f32) {
    // Adding 1.5·2^23 rounds to the nearest integer, which lands in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let v = x * std::f32::consts::FRAC_2_PI + ROUND;
    let quadrant = v.to_bits() & 3;
    let q = v - ROUND;
    let t = ((x - q * 1.570_312_5) - q * 4.837_513e-4) - q * 7.549_79e-8;
    let t2 = t * t;
    let s = t + t * t2 * (-1.666_665_5e-1 + t2 * (8.332_161e-3 + t2 * -1.951_529_6e-4));
    let c = 1.0 - 0.5 * t2 + t2 * t2 * (4.166_664_6e-2 + t2 * (-1.388_731_6e-3 + t2 * 2.443_315_7e-5));
    // Quadrants 1 and 3 swap sine and cosine; the sine is negative in 2, 3, the cosine in 1, 2.
    let swap = 0u32.wrapping_sub(quadrant & 1);
    let (sb, cb) = (s.to_bits(), c.to_bits());
    let sin = (sb & !swap) | (cb & swap);
    let cos = (cb & !swap) | (sb & swap);
    (f32::from_bits(sin ^ ((quadrant & 2) << 30)), f32::from_bits(cos ^ (((quadrant + 1) & 2) << 30)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_precision_sin_cos_is_accurate_over_long_paths() {
        // Phases up to k·R for 0.3 m at 1 MHz in water (1257 rad); error against f64 sin/cos of
        // the same single-precision argument.
        let mut worst: f64 = 0.0;
        for i in 0..200_000 {
            let x = i as f32 * 0.006_283_1;
            let (s, c) = sin_cos(x);
            let (es, ec) = (x as f64).sin_cos();
            worst = worst.max((s as f64 - es).abs()).max((c as f64 - ec).abs());
        }
        assert!(worst < 2e-6, "worst error {worst:.2e}");
    }

    #[test]
    fn several_weight_sets_at_once_equal_one_row_each() {
        // The shared kernel changes only the order of single-precision operations within a
        // point's term (an ulp, 6e-8 of the term, in sums whose terms exceed their result many
        // times over after cancellation): equal to 5e-6 of the peak (each is within 2e-5 of
        // the double-precision sum, below).
        let points: Vec<([f64; 3], C64)> = (0..500)
            .map(|i| ([(i % 25) as f64 * 1e-3 - 0.012, (i / 25) as f64 * 1e-3 - 0.01, -0.03 - 1e-5 * i as f64], C64::new(1e-7, 0.0)))
            .collect();
        let sets: Vec<Vec<C64>> = (0..3).map(|s| (0..500).map(|i| C64::from_polar(1e-7, 0.37 * (i * (s + 1)) as f64)).collect()).collect();
        let xs: Vec<f64> = (0..200).map(|i| (i as f64 - 100.0) * 0.5e-3).collect();
        let k = 2.0 * std::f64::consts::PI * 650e3 / 1500.0;
        for alpha in [0.0, 3.0] {
            let many = Sources::new(&points, 0.0, k, alpha).row_many(&sets, &xs, 0.004);
            for (set, row) in sets.iter().zip(&many) {
                let weighted: Vec<([f64; 3], C64)> = points.iter().zip(set).map(|((p, _), w)| (*p, *w)).collect();
                let one = Sources::new(&weighted, 0.0, k, alpha).row(&xs, 0.004);
                let peak = one.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let err = row.iter().zip(&one).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak;
                assert!(err < 5e-6, "alpha {alpha}: error {err:.2e} of the peak");
            }
        }
    }

    #[test]
    fn avx2_sums_give_the_same_bits_as_the_baseline() {
        // Same operations in the same order per pixel, only more pixels per instruction.
        let points: Vec<([f64; 3], C64)> = (0..300)
            .map(|i| {
                (
                    [(i % 20) as f64 * 1e-3 - 0.01, (i / 20) as f64 * 1e-3 - 0.007, -0.03 - 1e-5 * i as f64],
                    C64::from_polar(1e-7, 0.1 * i as f64),
                )
            })
            .collect();
        let sets: Vec<Vec<C64>> = (0..2).map(|s| (0..300).map(|i| C64::from_polar(1e-7, 0.37 * (i * (s + 1)) as f64)).collect()).collect();
        let xs: Vec<f64> = (0..99).map(|i| (i as f64 - 50.0) * 0.5e-3).collect();
        let ys = [-0.003, 0.0, 0.004];
        let k = 2.0 * std::f64::consts::PI * 650e3 / 1500.0;
        for alpha in [0.0, 3.0] {
            let sources = Sources::new(&points, 0.0, k, alpha);
            assert_eq!(sources.row(&xs, 0.004), sources.row_portable(&xs, 0.004));
            assert_eq!(sources.row_many(&sets, &xs, 0.004), sources.row_many_portable(&sets, &xs, 0.004));
            let fields: Vec<Vec<C64>> = sets.iter().map(|w| w[..xs.len() * ys.len()].to_vec()).collect();
            let at: Vec<[f64; 3]> = points.iter().take(7).map(|(p, _)| *p).collect();
            let pre = C64::new(0.0, -k / (2.0 * std::f64::consts::PI));
            let plane = Plane {
                xs: xs.iter().map(|&x| x as f32).collect(),
                ys: &ys,
                z0: 0.0,
                parts: fields.iter().map(|v| (v.iter().map(|v| v.re as f32).collect(), v.iter().map(|v| v.im as f32).collect())).collect(),
                k: k as f32,
                alpha: alpha as f32,
            };
            let (mut kr, mut ki) = (vec![0f32; xs.len()], vec![0f32; xs.len()]);
            let baseline: Vec<Vec<C64>> = at.iter().map(|p| plane.sums(*p, &mut kr, &mut ki).iter().map(|t| pre * t).collect()).collect();
            let sums = at_points(&fields, &xs, &ys, 0.0, &at, k, alpha);
            for (f, per_field) in sums.iter().enumerate() {
                assert!(per_field.iter().zip(&baseline).all(|(a, b)| *a == b[f]), "at_points, field {f}");
            }
        }
    }

    #[test]
    fn fast_row_matches_the_double_precision_sum() {
        // 3000 points on a tilted disc 40-80 mm before a plane, attenuating and not; the sum
        // against the obvious one, relative to the largest value (tolerance 2e-5: single
        // precision phases and blocked sums, see the module note).
        let mut s = 3u64;
        let mut rnd = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let points: Vec<([f64; 3], C64)> = (0..3000)
            .map(|_| {
                let (u, v) = (0.06 * rnd(), 0.06 * rnd());
                ([u, v, 0.02 * u - 0.04], C64::new(1e-7 * (1.0 + rnd()), 1e-7 * rnd()))
            })
            .collect();
        let xs: Vec<f64> = (0..300).map(|i| (i as f64 - 150.0) * 0.3e-3).collect();
        let k = 2.0 * std::f64::consts::PI * 1e6 / 1500.0;
        for alpha in [0.0, 5.0] {
            for y in [-0.02, 0.0, 0.013] {
                let fast = Sources::new(&points, 0.01, k, alpha).row(&xs, y);
                let slow = row_f64(&points, &xs, y, 0.01, k, alpha);
                let peak = slow.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let err = fast.iter().zip(&slow).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak;
                assert!(err < 2e-5, "alpha {alpha}, y {y}: error {err:.2e} of the peak");
            }
        }
    }
}
