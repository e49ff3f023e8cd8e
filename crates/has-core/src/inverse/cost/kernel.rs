//! Per-pixel Hermitian kernels of the MR-ARFI image over group drives (the quadratic model the
//! hybrid cost evaluates), stored as blocked upper triangles for streaming dot products.

use crate::error::{HasError, Result};
use crate::physics::mr::MrSampler;
use crate::simulation::Simulation;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use std::ops::Range;

/// Per-pixel Hermitian kernels over a box of MR pixels: the image for any group phases.
#[derive(Debug, Clone)]
pub struct ArfiKernel {
    /// Number of groups `G`.
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
        let g_count = crate::grouping::count(groups);
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
    pub(super) fn weighted_sum(&self, which: &[usize], r: &[f64]) -> Vec<f64> {
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
    pub(super) fn hermitian_times(&self, r_mat: &[f64], v: &[C64]) -> Vec<C64> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::cost::{HybridCost, Term};

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
