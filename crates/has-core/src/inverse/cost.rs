//! The hybrid cost (paper Eq. 4) on a precomputed quadratic model of the image.
//!
//! The forward model after the pressure field is linear in `|p|²`, and the field is linear in the
//! group drives `v_g = exp(i·phi_g)`. So each pixel of the image is a Hermitian form
//! `d_i(phi) = v^H K_i v` with `K_i[g, h] = A · S_i(conj(W_g)·W_h)`, where `W_g` is the field of
//! group `g` in the MR window and `S_i` the MR sampling of pixel `i` (SPEC §8). An evaluation costs
//! `O(P·G²)` for `P` pixels, and the gradient is analytic:
//! `∂d_i/∂phi_g = 2·Im(conj(v_g)·(K_i v)_g)`.

use crate::error::{HasError, Result};
use crate::physics::mr::MrSampler;
use crate::simulation::Simulation;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use std::ops::Range;

/// What an estimator minimises: a cost over phases (rad), one per group or element, and its
/// gradient. Implemented by [`HybridCost`] and [`crate::inverse::basis::ElementCost`].
pub trait Objective: Sync {
    /// Number of phases.
    fn n_phases(&self) -> usize;
    /// The cost at `phases`.
    fn cost(&self, phases: &[f64]) -> f64;
    /// The cost and its gradient with respect to each phase.
    fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>);
}

/// Per-pixel Hermitian kernels over a box of MR pixels: the image for any group phases.
#[derive(Debug, Clone)]
pub struct ArfiKernel {
    pub n_groups: usize,
    /// The pixel box (ranges along u and v of the full image).
    pub pixels: [Range<usize>; 2],
    /// Real diagonals, `(n_pixels, G)`.
    diag: Vec<f64>,
    /// The strict upper triangles `K[g, h]`, `g < h`, pairs numbered row by row, one row of
    /// [`Blocked`] layout per pixel, `(n_pixels, Blocked::len(G(G-1)/2))`.
    upper: Vec<f64>,
}

/// Complex vectors stored as blocks of [`Blocked::B`] real parts followed by their imaginary
/// parts, zero-padded to whole blocks: one memory stream per vector (like interleaved complex)
/// whose products still vectorise (like split arrays).
struct Blocked;

impl Blocked {
    const B: usize = 8;

    /// Stored length of `n` complex values.
    fn len(n: usize) -> usize {
        2 * n.div_ceil(Self::B) * Self::B
    }

    /// Position of the real part of value `k` (its imaginary part is `B` further).
    fn re(k: usize) -> usize {
        (k / Self::B) * 2 * Self::B + k % Self::B
    }

    fn get(x: &[f64], k: usize) -> C64 {
        C64::new(x[Self::re(k)], x[Self::re(k) + Self::B])
    }

    fn set(x: &mut [f64], k: usize, c: C64) {
        (x[Self::re(k)], x[Self::re(k) + Self::B]) = (c.re, c.im);
    }
}

/// Pixels per task when an image or a weighted kernel sum is split across threads. Fixed, so the
/// summation order (and every bit of the result) does not depend on the number of threads.
const PIXEL_CHUNK: usize = 32;

/// Multiply-adds (pixels × kernel pairs) below which one evaluation stays on the calling thread
/// (rayon's hand-off costs a few µs: the 16-group cost is ~40 000).
const PARALLEL_WORK: usize = 200_000;

impl ArfiKernel {
    /// Marches the `G` group fields (steering plus `known` element phases, rad; empty = none) and
    /// builds the kernels of the pixels in the box `u x v`.
    pub fn build(sim: &Simulation, groups: &[usize], known: &[f64], u: Range<usize>, v: Range<usize>) -> Result<Self> {
        let g_count = groups.iter().max().map_or(0, |m| m + 1);
        if g_count < 2 {
            return Err(HasError::invalid("groups", "need at least two groups"));
        }
        let sampler = sim.sampler()?.restrict(u.clone(), v.clone())?;
        // At the peak of the build the pair maps (re and im per pair) and the kernels coexist.
        let (n_pix, n_pairs) = ((u.len() * v.len()) as u64, (g_count * (g_count + 1) / 2) as u64);
        crate::memory::check(
            || format!("the {g_count}-group kernels of {n_pix} pixels"),
            n_pix * n_pairs * 8 * 2 + n_pix * (g_count as u64 + Blocked::len(g_count * (g_count - 1) / 2) as u64) * 8,
            "estimate fewer groups, or lower the mask fraction's reach (a tighter focus, fewer pixels)",
        )?;
        let sources = sim.group_sources(groups, known)?;
        let recordings = sim.record_window(&sources)?;
        let window = &sim.sampler()?.window;
        let fields: Vec<Vec<C64>> = recordings.iter().map(|r| window.extract(&r.window, &sampler.window)).collect();
        Self::from_fields(&sampler, &fields, sim.amplitude()?, [u, v])
    }

    /// Kernels from group fields already recorded on `sampler.window`.
    pub fn from_fields(sampler: &MrSampler, fields: &[Vec<C64>], amplitude: f64, pixels: [Range<usize>; 2]) -> Result<Self> {
        let g = fields.len();
        let pairs: Vec<(usize, usize)> = (0..g).flat_map(|a| (a..g).map(move |b| (a, b))).collect();
        let maps: Vec<(Array2<f64>, Array2<f64>)> = pairs
            .par_iter()
            .map(|&(a, b)| {
                let q: Vec<C64> = fields[a].iter().zip(&fields[b]).map(|(x, y)| x.conj() * y).collect();
                let re: Vec<f64> = q.iter().map(|c| c.re).collect();
                let im: Vec<f64> = q.iter().map(|c| c.im).collect();
                Ok((sampler.apply(&re)? * amplitude, if a == b { Array2::zeros((0, 0)) } else { sampler.apply(&im)? * amplitude }))
            })
            .collect::<Result<Vec<_>>>()?;
        let n_pix = pixels[0].len() * pixels[1].len();
        let n_up = g * (g - 1) / 2;
        let mut diag = vec![0.0; n_pix * g];
        let row = Blocked::len(n_up);
        let mut upper = vec![0.0; n_pix * row];
        for ((a, b), (re, im)) in pairs.iter().zip(&maps) {
            for (p, (i, j)) in pixel_order(&pixels).enumerate() {
                if a == b {
                    diag[p * g + a] = re[[i, j]];
                } else {
                    Blocked::set(&mut upper[p * row..(p + 1) * row], upper_index(g, *a, *b), C64::new(re[[i, j]], im[[i, j]]));
                }
            }
        }
        Ok(ArfiKernel { n_groups: g, pixels, diag, upper })
    }

    /// Number of group pairs `g < h`, `G(G-1)/2`.
    fn n_pairs(&self) -> usize {
        self.n_groups * (self.n_groups - 1) / 2
    }

    /// Pixel `p`'s upper triangle (blocked).
    fn upper_row(&self, p: usize) -> &[f64] {
        let n = Blocked::len(self.n_pairs());
        &self.upper[p * n..(p + 1) * n]
    }

    /// Number of pixels in the box.
    pub fn n_pixels(&self) -> usize {
        self.pixels[0].len() * self.pixels[1].len()
    }

    /// Index into the box of full-image pixel `(i, j)`, if inside.
    pub fn pixel_index(&self, i: usize, j: usize) -> Option<usize> {
        (self.pixels[0].contains(&i) && self.pixels[1].contains(&j))
            .then(|| (i - self.pixels[0].start) * self.pixels[1].len() + (j - self.pixels[1].start))
    }

    /// The kernels of the box pixels `which`: real diagonals `K_i[g, g]`, shape `(n, G)`, and
    /// strict upper triangles `K_i[g, h]`, `g < h`, row by row (`(0,1), (0,2), …, (G-2,G-1)`),
    /// shape `(n, G(G-1)/2)`. The image is `d_i = Σ_g K_i[g,g] + 2·Re Σ_{g<h} K_i[g,h]·conj(v_g)·v_h`.
    pub fn kernels_at(&self, which: &[usize]) -> Result<(Array2<f64>, Array2<C64>)> {
        let (g, n_up) = (self.n_groups, self.n_pairs());
        if let Some(&p) = which.iter().find(|&&p| p >= self.n_pixels()) {
            return Err(HasError::invalid("pixels", format!("index {p} outside the kernel's {} pixels", self.n_pixels())));
        }
        let diag = which.iter().flat_map(|&p| self.diag[p * g..(p + 1) * g].iter().copied()).collect();
        let upper = which.iter().flat_map(|&p| (0..n_up).map(move |k| Blocked::get(self.upper_row(p), k))).collect();
        let shape_err = |e: ndarray::ShapeError| HasError::invalid("kernel", e.to_string());
        Ok((
            Array2::from_shape_vec((which.len(), g), diag).map_err(shape_err)?,
            Array2::from_shape_vec((which.len(), n_up), upper).map_err(shape_err)?,
        ))
    }

    /// `conj(v_g)·v_h` for `g < h`, the pair weights shared by every pixel (blocked).
    fn pair_weights(&self, v: &[C64]) -> Vec<f64> {
        let g = self.n_groups;
        let mut w = vec![0.0; Blocked::len(self.n_pairs())];
        let mut k = 0;
        for a in 0..g {
            for b in a + 1..g {
                Blocked::set(&mut w, k, v[a].conj() * v[b]);
                k += 1;
            }
        }
        w
    }

    /// Whether work over `n` pixels is worth splitting across threads.
    fn parallel(&self, n: usize) -> bool {
        n * self.n_pairs() >= PARALLEL_WORK
    }

    /// Image values `v^H K_i v` at the box pixels `which` (indices into the box) for drives `v`.
    pub fn image_at(&self, v: &[C64], which: &[usize], out: &mut Vec<f64>) {
        let g = self.n_groups;
        let w = self.pair_weights(v);
        let value = |(&p, o): (&usize, &mut f64)| {
            let d: f64 = self.diag[p * g..(p + 1) * g].iter().sum();
            *o = d + 2.0 * re_dot(self.upper_row(p), &w);
        };
        out.clear();
        out.resize(which.len(), 0.0);
        if self.parallel(which.len()) {
            which.par_iter().zip(out.par_iter_mut()).with_min_len(PIXEL_CHUNK).for_each(value);
        } else {
            which.iter().zip(out.iter_mut()).for_each(value);
        }
    }

    /// The image on the whole box for group phases (rad), shape `(len u, len v)`.
    pub fn image(&self, phases: &[f64]) -> Result<Array2<f64>> {
        if phases.len() != self.n_groups {
            return Err(HasError::invalid("phases", format!("has {} values for {} groups", phases.len(), self.n_groups)));
        }
        let v: Vec<C64> = phases.iter().map(|&p| C64::from_polar(1.0, p)).collect();
        let all: Vec<usize> = (0..self.n_pixels()).collect();
        let mut out = Vec::new();
        self.image_at(&v, &all, &mut out);
        Array2::from_shape_vec((self.pixels[0].len(), self.pixels[1].len()), out).map_err(|e| HasError::invalid("kernel", e.to_string()))
    }

    /// `R = Σ_i r_i · K_i` over the pixels `which`, as `[diagonal (G) | upper (blocked)]`: per
    /// chunk of [`PIXEL_CHUNK`] pixels, then the chunks in order.
    fn weighted_sum(&self, which: &[usize], r: &[f64]) -> Vec<f64> {
        let g = self.n_groups;
        let n = g + Blocked::len(self.n_pairs());
        let chunk_sum = |(ps, rs): (&[usize], &[f64])| {
            let mut acc = vec![0.0; n];
            let (d, upper) = acc.split_at_mut(g);
            for (&p, &ri) in ps.iter().zip(rs) {
                axpy(ri, &self.diag[p * g..(p + 1) * g], d);
                axpy(ri, self.upper_row(p), upper);
            }
            acc
        };
        let parts: Vec<Vec<f64>> = if self.parallel(which.len()) {
            which.par_chunks(PIXEL_CHUNK).zip(r.par_chunks(PIXEL_CHUNK)).map(chunk_sum).collect()
        } else {
            which.chunks(PIXEL_CHUNK).zip(r.chunks(PIXEL_CHUNK)).map(chunk_sum).collect()
        };
        let mut total = vec![0.0; n];
        for part in &parts {
            axpy(1.0, part, &mut total);
        }
        total
    }

    /// `(R v)_a` for the Hermitian `R` of [`Self::weighted_sum`] (stored as its diagonal and
    /// upper triangle).
    fn hermitian_times(&self, r_mat: &[f64], v: &[C64]) -> Vec<C64> {
        let g = self.n_groups;
        let (d, upper) = r_mat.split_at(g);
        let mut rv: Vec<C64> = d.iter().zip(v).map(|(x, y)| y * x).collect();
        let mut k = 0;
        for a in 0..g {
            for b in a + 1..g {
                let r_ab = Blocked::get(upper, k);
                rv[a] += r_ab * v[b];
                rv[b] += r_ab.conj() * v[a];
                k += 1;
            }
        }
        rv
    }
}

/// `y += a·x`.
fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    y.iter_mut().zip(x).for_each(|(y, x)| *y += a * x);
}

/// `Σ_k Re(a_k · b_k)` over two [`Blocked`] vectors: one running sum per lane of a block,
/// independent additions that the compiler turns into vector instructions.
fn re_dot(a: &[f64], b: &[f64]) -> f64 {
    const B: usize = Blocked::B;
    let mut acc = [0.0; B];
    for (x, y) in a.chunks_exact(2 * B).zip(b.chunks_exact(2 * B)) {
        for k in 0..B {
            acc[k] += x[k] * y[k] - x[B + k] * y[B + k];
        }
    }
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// Pixels of a box in row-major (u, v) order.
fn pixel_order(p: &[Range<usize>; 2]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let nv = p[1].len();
    (0..p[0].len() * nv).map(move |k| (k / nv, k % nv))
}

/// Position of pair `(a, b)`, `a < b`, in the row-by-row strict upper triangle of a `g x g` matrix.
fn upper_index(g: usize, a: usize, b: usize) -> usize {
    a * (2 * g - a - 1) / 2 + (b - a - 1)
}

/// One measured image as the cost sees it: a kernel, the measured values on the masked pixels,
/// and the known group phase offsets added for this acquisition.
#[derive(Debug, Clone)]
pub struct Term {
    pub kernel: std::sync::Arc<ArfiKernel>,
    /// Box indices of the masked pixels (measured > mask_fraction · max).
    pub mask: Vec<usize>,
    /// Measured ARFI phase at the masked pixels (rad).
    pub measured: Vec<f64>,
    /// Known per-group phases added to the estimate for this image (rad).
    pub offset: Vec<f64>,
}

/// The joint cost `J(phi) = Σ_k Σ_{i in mask_k} (s·d_k,i(phi + offset_k) - m_k,i)²` over images.
/// `s = 1`, or, with `fit_scale`, the least-squares scale `s = <d, m> / <d, d>` for each `phi`
/// (one for all images): a free amplitude that absorbs a uniform loss of focal intensity the
/// phases cannot explain (e.g. element-level aberration within groups).
#[derive(Debug, Clone)]
pub struct HybridCost {
    pub terms: Vec<Term>,
    pub n_groups: usize,
    pub fit_scale: bool,
}

impl HybridCost {
    /// Checks that every term has the same number of groups.
    pub fn new(terms: Vec<Term>) -> Result<Self> {
        let n_groups = terms.first().map(|t| t.kernel.n_groups).ok_or_else(|| HasError::invalid("images", "need at least one image"))?;
        for (k, t) in terms.iter().enumerate() {
            if t.kernel.n_groups != n_groups || t.offset.len() != n_groups {
                return Err(HasError::invalid(format!("image[{k}]"), "group count differs from the first image"));
            }
            if t.mask.is_empty() || t.mask.len() != t.measured.len() {
                return Err(HasError::invalid(format!("image[{k}]"), "empty mask"));
            }
        }
        Ok(HybridCost { terms, n_groups, fit_scale: false })
    }

    /// Number of masked pixels over all images.
    pub fn n_pixels(&self) -> usize {
        self.terms.iter().map(|t| t.mask.len()).sum()
    }

    /// Model images at the masked pixels of every term.
    fn images(&self, phases: &[f64]) -> Vec<Vec<f64>> {
        self.terms
            .iter()
            .map(|t| {
                let v: Vec<C64> = phases.iter().zip(&t.offset).map(|(p, o)| C64::from_polar(1.0, p + o)).collect();
                let mut img = Vec::new();
                t.kernel.image_at(&v, &t.mask, &mut img);
                img
            })
            .collect()
    }

    /// The scale applied to the model images for these images (1 unless `fit_scale`).
    fn scale_for(&self, images: &[Vec<f64>]) -> f64 {
        if !self.fit_scale {
            return 1.0;
        }
        least_squares_scale(images.iter().zip(&self.terms).map(|(d, t)| (d.as_slice(), t.measured.as_slice())))
    }

    /// The amplitude scale at `phases` (1 unless `fit_scale`).
    pub fn scale(&self, phases: &[f64]) -> f64 {
        self.scale_for(&self.images(phases))
    }

    /// `J` for group phases (rad).
    pub fn cost(&self, phases: &[f64]) -> f64 {
        let images = self.images(phases);
        let s = self.scale_for(&images);
        images.iter().zip(&self.terms).map(|(img, t)| img.iter().zip(&t.measured).map(|(d, m)| (s * d - m).powi(2)).sum::<f64>()).sum()
    }

    /// `J` and `∂J/∂phi_g = 4·s·Σ_k Im(conj(v_g)·(R_k v)_g)`, `R_k = Σ_i r_i·K_i`, `r = s·d - m`
    /// (with a fitted scale the envelope theorem makes `∂s/∂phi` drop out).
    pub fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        let g = self.n_groups;
        let images = self.images(phases);
        let s = self.scale_for(&images);
        let mut grad = vec![0.0; g];
        let mut total = 0.0;
        for (t, img) in self.terms.iter().zip(&images) {
            let v: Vec<C64> = phases.iter().zip(&t.offset).map(|(p, o)| C64::from_polar(1.0, p + o)).collect();
            let r: Vec<f64> = img.iter().zip(&t.measured).map(|(d, m)| s * d - m).collect();
            total += r.iter().map(|x| x * x).sum::<f64>();
            let rv = t.kernel.hermitian_times(&t.kernel.weighted_sum(&t.mask, &r), &v);
            for ((gr, va), rva) in grad.iter_mut().zip(&v).zip(&rv) {
                *gr += 4.0 * s * (va.conj() * rva).im;
            }
        }
        (total, grad)
    }
}

/// The scale `s = <d, m> / <d, d>` minimising `Σ (s·d - m)²` over (model, measured) pairs; 1 when
/// the model is all zero.
pub(crate) fn least_squares_scale<'a>(pairs: impl Iterator<Item = (&'a [f64], &'a [f64])>) -> f64 {
    let (mut dm, mut dd) = (0.0, 0.0);
    for (d, m) in pairs {
        for (x, y) in d.iter().zip(m) {
            dm += x * y;
            dd += x * x;
        }
    }
    if dd > 0.0 {
        dm / dd
    } else {
        1.0
    }
}

impl Objective for HybridCost {
    fn n_phases(&self) -> usize {
        self.n_groups
    }
    fn cost(&self, phases: &[f64]) -> f64 {
        HybridCost::cost(self, phases)
    }
    fn cost_and_gradient(&self, phases: &[f64]) -> (f64, Vec<f64>) {
        HybridCost::cost_and_gradient(self, phases)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_at_rebuild_the_image_by_the_documented_formula() {
        // A 3-group kernel over 2 pixels with arbitrary (fixed) entries; the formula of the doc
        // comment, written out by hand, must give `image_at` to rounding.
        let diag = vec![1.0, 2.0, 3.0, 0.5, 0.25, 0.125];
        let values =
            [C64::new(0.3, -0.2), C64::new(-0.1, 0.4), C64::new(0.05, 0.6), C64::new(1.0, 0.0), C64::new(0.0, 1.0), C64::new(-0.7, -0.7)];
        let mut upper = vec![0.0; 2 * Blocked::len(3)];
        for (k, &c) in values.iter().enumerate() {
            Blocked::set(&mut upper[(k / 3) * Blocked::len(3)..], k % 3, c);
        }
        let k = ArfiKernel { n_groups: 3, pixels: [0..1, 0..2], diag, upper };
        let v: Vec<C64> = [0.4, -1.3, 2.9].iter().map(|&p| C64::from_polar(1.0, p)).collect();
        let (d, u) = k.kernels_at(&[1, 0]).unwrap();
        let mut expected = Vec::new();
        k.image_at(&v, &[1, 0], &mut expected);
        for (row, e) in expected.iter().enumerate() {
            let pairs = [(0, 1), (0, 2), (1, 2)];
            let cross: f64 = pairs.iter().enumerate().map(|(q, &(a, b))| (u[[row, q]] * v[a].conj() * v[b]).re).sum();
            let got = d.row(row).sum() + 2.0 * cross;
            assert!((got - e).abs() < 1e-14, "pixel {row}: {got} vs {e}");
        }
        assert!(k.kernels_at(&[2]).is_err());
    }

    /// Pseudo-random numbers in [-1, 1) (a fixed linear congruential sequence).
    fn numbers(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (x >> 11) as f64 / (1u64 << 52) as f64 - 1.0
            })
            .collect()
    }

    #[test]
    fn cost_and_gradient_match_dense_hermitian_forms_with_any_thread_count() {
        // 40 groups x 300 pixels = 234 000 multiply-adds: above PARALLEL_WORK, so the pixels are
        // split across threads. The reference builds each pixel's dense G x G Hermitian K_i and
        // evaluates d_i = v^H K_i v and ∂J/∂phi = Σ_i 2 r_i · 2 Im(conj(v) ∘ K_i v) directly.
        let (g, n_pix) = (40, 300);
        let n_up = g * (g - 1) / 2;
        let diag = numbers(n_pix * g, 1);
        let (re, im) = (numbers(n_pix * n_up, 2), numbers(n_pix * n_up, 3));
        let row = Blocked::len(n_up);
        let mut upper = vec![0.0; n_pix * row];
        for p in 0..n_pix {
            for k in 0..n_up {
                Blocked::set(&mut upper[p * row..(p + 1) * row], k, C64::new(re[p * n_up + k], im[p * n_up + k]));
            }
        }
        assert!(n_pix * n_up >= PARALLEL_WORK);
        let kernel = std::sync::Arc::new(ArfiKernel { n_groups: g, pixels: [0..15, 0..20], diag: diag.clone(), upper });
        let measured: Vec<f64> = numbers(n_pix, 4).iter().map(|m| 10.0 * m).collect();
        let term = Term { kernel, mask: (0..n_pix).collect(), measured: measured.clone(), offset: numbers(g, 5) };
        let cost = HybridCost::new(vec![term.clone()]).unwrap();
        let phases = numbers(g, 6).iter().map(|p| 3.0 * p).collect::<Vec<_>>();

        let v: Vec<C64> = phases.iter().zip(&term.offset).map(|(p, o)| C64::from_polar(1.0, p + o)).collect();
        let (mut j_ref, mut grad_ref) = (0.0, vec![0.0; g]);
        for p in 0..n_pix {
            let mut k_mat = vec![C64::new(0.0, 0.0); g * g];
            let mut q = 0;
            for a in 0..g {
                k_mat[a * g + a] = C64::new(diag[p * g + a], 0.0);
                for b in a + 1..g {
                    let c = C64::new(re[p * n_up + q], im[p * n_up + q]);
                    (k_mat[a * g + b], k_mat[b * g + a]) = (c, c.conj());
                    q += 1;
                }
            }
            let kv: Vec<C64> = (0..g).map(|a| (0..g).map(|b| k_mat[a * g + b] * v[b]).sum()).collect();
            let d: f64 = (0..g).map(|a| (v[a].conj() * kv[a]).re).sum();
            let r = d - measured[p];
            j_ref += r * r;
            for a in 0..g {
                grad_ref[a] += 2.0 * r * 2.0 * (v[a].conj() * kv[a]).im;
            }
        }

        let run =
            |threads| rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| cost.cost_and_gradient(&phases));
        let (j1, grad1) = run(1);
        let (j2, grad2) = run(2);
        assert_eq!(j1.to_bits(), j2.to_bits());
        assert!(grad1.iter().zip(&grad2).all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(cost.cost(&phases).to_bits(), j1.to_bits());
        // Sums of ~800 terms of size ~1 in another order: agreement to 1e-10 relative.
        assert!((j1 - j_ref).abs() <= 1e-10 * j_ref, "{j1} vs {j_ref}");
        let norm = grad_ref.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(grad1.iter().zip(&grad_ref).all(|(a, b)| (a - b).abs() <= 1e-10 * norm));
    }

    #[test]
    fn upper_index_enumerates_pairs_in_order() {
        let g = 5;
        let mut k = 0;
        for a in 0..g {
            for b in a + 1..g {
                assert_eq!(upper_index(g, a, b), k);
                k += 1;
            }
        }
    }
}

/// One measured MR-ARFI image and the known phases (rad; one per element or per group, empty =
/// none) that were added to the steering for it.
#[derive(Debug, Clone)]
pub struct Measurement {
    pub image: Array2<f64>,
    pub known: Vec<f64>,
}

/// The cost assembled from measurements, with the kernel of the plain steering (for predictions)
/// and the noise level estimated from the images' backgrounds.
#[derive(Debug, Clone)]
pub struct Model {
    pub cost: HybridCost,
    pub base: std::sync::Arc<ArfiKernel>,
    /// Noise standard deviation (rad), RMS over the images.
    pub noise: f64,
}

/// Most groups the per-pixel kernels take: their size and build time grow as G² (256 groups:
/// 32 640 pairs per pixel, about 0.5 MB per pixel).
pub const MAX_KERNEL_GROUPS: usize = 256;

/// Largest |pixel| of a measured image (rad): far beyond any unwrapped MR-ARFI phase, small
/// enough that squared residuals summed over every pixel stay finite.
pub const MAX_PHASE: f64 = 1e6;

/// Checks a measured image against the scenario's MR geometry.
pub fn check_image(sim: &Simulation, image: &Array2<f64>, name: &str) -> Result<()> {
    let m = sim.mr.matrix;
    if image.dim() != (m[0], m[1]) {
        return Err(HasError::invalid(name, format!("has shape {:?}, the scenario's MR matrix is {} x {}", image.dim(), m[0], m[1])));
    }
    if let Some(((i, j), v)) = image.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(HasError::invalid(name, format!("pixel ({i}, {j}) is {v}")));
    }
    if let Some(((i, j), v)) = image.indexed_iter().find(|(_, v)| v.abs() > MAX_PHASE) {
        return Err(HasError::invalid(name, format!("pixel ({i}, {j}) is {v:e} rad, beyond any MR phase (|phase| <= {MAX_PHASE} rad)")));
    }
    if !(image.iter().copied().fold(f64::MIN, f64::max) > 0.0) {
        return Err(HasError::invalid(name, "has no positive pixel (all-zero or inverted image?)"));
    }
    Ok(())
}

/// The focal zone (paper Eq. 4): the pixels above `fraction` of the image maximum that are
/// connected (4-neighbours) to the maximum. Isolated noise spikes elsewhere are left out.
pub fn mask_pixels(image: &Array2<f64>, fraction: f64) -> Vec<(usize, usize)> {
    let (nu, nv) = image.dim();
    let Some((peak, &max)) = image.indexed_iter().max_by(|a, b| a.1.total_cmp(b.1)) else {
        return vec![];
    };
    let level = fraction * max;
    let mut seen = Array2::from_elem((nu, nv), false);
    let mut stack = vec![peak];
    seen[peak] = true;
    let mut out = Vec::new();
    while let Some((i, j)) = stack.pop() {
        out.push((i, j));
        let neighbours = [(i.wrapping_sub(1), j), (i + 1, j), (i, j.wrapping_sub(1)), (i, j + 1)];
        for (a, b) in neighbours {
            if a < nu && b < nv && !seen[[a, b]] && image[[a, b]] > level {
                seen[[a, b]] = true;
                stack.push((a, b));
            }
        }
    }
    out.sort_unstable();
    out
}

/// Builds the joint cost of `measurements` for the simulation's groups: masks at `mask_fraction`
/// of each image's maximum, one pixel box around all masks (plus `margin` pixels), kernels from
/// one batched march per distinct known-phase pattern (patterns constant within groups reuse the
/// plain kernel with a phase offset).
pub fn build_model(sim: &Simulation, measurements: &[Measurement], mask_fraction: f64, margin: usize) -> Result<Model> {
    if measurements.is_empty() {
        return Err(HasError::invalid("images", "need at least one image"));
    }
    let g = sim.n_groups;
    if g > MAX_KERNEL_GROUPS {
        return Err(HasError::invalid("groups", format!("{g} groups: the per-pixel kernels are limited to {MAX_KERNEL_GROUPS} groups")));
    }
    let MaskedBox { masks, pixels: [u, v], noise } = masks_and_box(sim, measurements, mask_fraction, margin)?;
    let base = std::sync::Arc::new(ArfiKernel::build(sim, &sim.groups, &[], u.clone(), v.clone())?);
    let mut terms = Vec::with_capacity(measurements.len());
    for (k, (meas, mask)) in measurements.iter().zip(&masks).enumerate() {
        let (kernel, offset) = if meas.known.is_empty() {
            (base.clone(), vec![0.0; g])
        } else {
            let per_element =
                sim.element_phases(&meas.known).map_err(|e| HasError::invalid(format!("image[{k}].applied_phases_rad"), e.to_string()))?;
            match group_constant(&per_element, &sim.groups, g) {
                Some(offset) => (base.clone(), offset),
                None => (std::sync::Arc::new(ArfiKernel::build(sim, &sim.groups, &per_element, u.clone(), v.clone())?), vec![0.0; g]),
            }
        };
        let idx: Vec<usize> = mask.iter().filter_map(|&(i, j)| kernel.pixel_index(i, j)).collect();
        let measured: Vec<f64> = mask.iter().map(|&ij| meas.image[ij]).collect();
        terms.push(Term { kernel, mask: idx, measured, offset });
    }
    Ok(Model { cost: HybridCost::new(terms)?, base, noise })
}

/// The images' masks, one pixel box around them and their noise level.
#[derive(Debug, Clone)]
pub struct MaskedBox {
    /// Each image's mask ([`mask_pixels`]), full-image pixel indices.
    pub masks: Vec<Vec<(usize, usize)>>,
    /// The box around all masks plus a margin: ranges along u and v.
    pub pixels: [Range<usize>; 2],
    /// RMS over the images of the background noise level (rad).
    pub noise: f64,
}

/// Checks the images; returns their masks, one pixel box around all masks (plus `margin`
/// pixels) and the noise level.
pub fn masks_and_box(sim: &Simulation, measurements: &[Measurement], mask_fraction: f64, margin: usize) -> Result<MaskedBox> {
    if measurements.is_empty() {
        return Err(HasError::invalid("images", "need at least one image"));
    }
    let m = sim.mr.matrix;
    let masks: Vec<Vec<(usize, usize)>> = measurements
        .iter()
        .enumerate()
        .map(|(k, meas)| {
            check_image(sim, &meas.image, &format!("image[{k}]"))?;
            Ok(mask_pixels(&meas.image, mask_fraction))
        })
        .collect::<Result<_>>()?;
    let all = masks.iter().flatten();
    let lo_u = all.clone().map(|p| p.0).min().unwrap_or(0).saturating_sub(margin);
    let hi_u = (all.clone().map(|p| p.0).max().unwrap_or(0) + margin + 1).min(m[0]);
    let lo_v = all.clone().map(|p| p.1).min().unwrap_or(0).saturating_sub(margin);
    let hi_v = (all.map(|p| p.1).max().unwrap_or(0) + margin + 1).min(m[1]);
    let (u, v) = (lo_u..hi_u, lo_v..hi_v);
    let noise2: f64 = measurements.iter().map(|meas| crate::physics::mr::noise_floor(&meas.image, &[u.clone(), v.clone()]).powi(2)).sum();
    Ok(MaskedBox { masks, pixels: [u, v], noise: (noise2 / measurements.len() as f64).sqrt() })
}

/// The per-group value of element phases that are constant within every group, if they are.
fn group_constant(per_element: &[f64], groups: &[usize], g: usize) -> Option<Vec<f64>> {
    let mut value = vec![None; g];
    for (&p, &k) in per_element.iter().zip(groups) {
        match value[k] {
            None => value[k] = Some(p),
            Some(q) if (crate::inverse::phase::wrap(p - q)).abs() < 1e-12 => {}
            Some(_) => return None,
        }
    }
    value.into_iter().collect()
}
