//! Faces where a solid meets a fluid or another solid: the compressional (P) and shear-vertical
//! (SV) plane waves of each angular-spectrum component reflected and transmitted with mode
//! conversion, and the SV wave's step through a solid slab.
//!
//! Where a slab holds a solid (its properties have shear maps) and a face between material
//! regions lies on a plane (a spectral interface), the march carries a second field beside `ψ`:
//! the SV wave's, flux-normalised like `ψ` but with the shear impedance. With `u = ∇Φ + ∇×(Ψ·ŷ)`,
//! `ψ = P·sqrt(Z_s/(ρ·c))` and `s = S·sqrt(Z_s/(ρ·c_s))` for the scaled amplitudes `P = ρω²·Φ`
//! (a fluid's pressure) and `S = ρω²·Ψ`. Each component's SV amplitude is taken in its own plane of
//! incidence (x along its transverse wavenumber), so every coefficient depends on `ξ = |kt|` alone.
//!
//! Per unit scaled amplitude, a wave travelling in direction `s = ±1` along z has the state
//! `(ω²·u_x, ω²·u_z, σ_zz, σ_xz)`:
//! - P: `(iξ/ρ, i·s·α/ρ, -(1 - 2ξ²/ks²), -2·s·ξ·α/ks²)`,
//! - SV: `(-i·s·β/ρ, iξ/ρ, -2·s·ξ·β/ks², (β² - ξ²)/ks²)`,
//!
//! with `α = sqrt(kp² - ξ²)`, `β = sqrt(ks² - ξ²)` (`Im >= 0`); a fluid (`ks → ∞`) has P alone and
//! `σ_zz = -p`. Between two solids the displacement and both stresses are continuous; between a
//! fluid and a solid `u_z` and `σ_zz` are, and the solid's shear stress vanishes (the boundary
//! conditions of [`crate::reference::elastic`]). Solving them per `ξ` gives the waves leaving the
//! face from those arriving at it (e.g. Brekhovskikh, *Waves in Layered Media*, 1980, §4).
//! Components evanescent in every wave of both media are crossed as between fluids: they carry no
//! power, and among them lie the face's surface-wave poles (Scholte, Stoneley), which would
//! amplify them.
//!
//! The SV field is stepped through a solid slab as `ψ` is (propagator of the slab's mean shear
//! wavenumber, screen of its deviation and of the shear attenuation) and is zero in a fluid's
//! pixels, except within `oblique_shear::CONTINUATION` of a solid in plans whose tilted walls
//! continue it (`screen`). Planar walls tilted against the planes convert at their own incidence
//! (`oblique_shear.rs`); a CT's other faces and a voxel map's convert nothing: they cross `ψ` as
//! before and leave the SV field to the next slab's screen.

use super::faces::segment_phase;
use super::march::{zero, Real, Wave};
use crate::physics::fft::{Fft2, FftWorkspace};
use crate::physics::grid::Grid;
use crate::physics::medium::{ShearMaps, SliceProperties};
use num_complex::{Complex, Complex32 as C32, Complex64 as C64};
use rayon::prelude::*;
use rustfft::FftNum;
use std::sync::Arc;

/// One side of a face: density (kg/m³), the compressional and shear wavenumbers (rad/m, the
/// imaginary part the amplitude attenuation in Np/m; no shear in a fluid) and the impedances
/// `ρ·c` of its P and SV waves (Rayl) that the fields are normalised by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Side {
    pub density: f64,
    pub kp: C64,
    pub ks: Option<C64>,
    pub impedance: [f64; 2],
}

impl Side {
    /// Pixel `i` of slab `s` at angular frequency `omega`.
    pub fn of(s: &SliceProperties, i: usize, omega: f64) -> Side {
        let (rho, c, a) = (s.density[i], s.sound_speed[i], s.attenuation[i]);
        let shear = s.shear.as_ref().map(|m| (m.sound_speed[i], m.attenuation[i])).filter(|&(cs, _)| cs > 0.0);
        Side {
            density: rho,
            kp: C64::new(omega / c, a),
            ks: shear.map(|(cs, a)| C64::new(omega / cs, a)),
            impedance: [rho * c, shear.map_or(0.0, |(cs, _)| rho * cs)],
        }
    }

    /// Whether it carries shear.
    pub fn is_solid(&self) -> bool {
        self.ks.is_some()
    }

    /// The state `(ω²·u_x, ω²·u_z, σ_zz, σ_xz)` of its wave `wave` (0: P, 1: SV) travelling in
    /// direction `dir` (±1) at transverse wavenumber `xi`, per unit scaled amplitude; `None`: SV
    /// in a fluid.
    fn state(&self, wave: usize, dir: f64, xi: f64) -> Option<[C64; 4]> {
        let i = C64::i();
        let rho = self.density;
        let vertical = |k: C64| super::interface::axial_wavenumber(k, xi * xi);
        match (wave, self.ks) {
            (0, None) => Some([i * xi / rho, i * dir * vertical(self.kp) / rho, C64::new(-1.0, 0.0), C64::new(0.0, 0.0)]),
            (0, Some(ks)) => {
                let (alpha, ks2) = (vertical(self.kp), ks * ks);
                Some([i * xi / rho, i * dir * alpha / rho, -(1.0 - 2.0 * xi * xi / ks2), -2.0 * dir * xi * alpha / ks2])
            }
            (_, Some(ks)) => {
                let (beta, ks2) = (vertical(ks), ks * ks);
                Some([-i * dir * beta / rho, i * xi / rho, -2.0 * dir * xi * beta / ks2, (beta * beta - xi * xi) / ks2])
            }
            _ => None,
        }
    }

    /// The largest real wavenumber of its waves (rad/m).
    fn largest_wavenumber(&self) -> f64 {
        self.ks.map_or(self.kp.re, |ks| ks.re.max(self.kp.re))
    }
}

/// The waves leaving a face from those arriving at it, in scaled amplitudes `P`, `S` (not
/// flux-normalised): `m[out][in]` with `out` = `[P⁻_a, S⁻_a, P⁺_b, S⁺_b]` (reflected into `a`,
/// transmitted into `b`) and `in` = `[P⁺_a, S⁺_a, P⁻_b, S⁻_b]` (arriving from `a` travelling +z,
/// from `b` travelling -z), at transverse wavenumber `xi` (rad/m). Entries of SV in a fluid are 0;
/// a singular system gives zeros.
pub(super) fn scattering(a: &Side, b: &Side, xi: f64) -> [[C64; 4]; 4] {
    let zero = C64::new(0.0, 0.0);
    let mut m = [[zero; 4]; 4];
    if xi > a.largest_wavenumber().max(b.largest_wavenumber()) {
        // Evanescent everywhere: the fluid coefficients of the P waves.
        let (ka, kb) = (super::interface::axial_wavenumber(a.kp, xi * xi), super::interface::axial_wavenumber(b.kp, xi * xi));
        let den = b.density * ka + a.density * kb;
        if den.norm_sqr() > 0.0 {
            let r = (b.density * ka - a.density * kb) / den;
            m[0][0] = r;
            m[2][0] = 1.0 + r;
            m[2][2] = -r;
            m[0][2] = 1.0 - r;
        }
        return m;
    }
    // Unknowns (outgoing) and knowns (arriving): (side, wave, direction).
    let side = |k: usize| if k < 2 { a } else { b };
    let present = |k: usize| k % 2 == 0 || side(k).is_solid();
    let outgoing = |k: usize| (side(k), k % 2, if k < 2 { -1.0 } else { 1.0 });
    let arriving = |k: usize| (side(k), k % 2, if k < 2 { 1.0 } else { -1.0 });
    // Conditions: (row of the state, which side's waves: 0 both (a minus b), 1 a's, 2 b's).
    let rows: Vec<(usize, u8)> = match (a.is_solid(), b.is_solid()) {
        (true, true) => vec![(0, 0), (1, 0), (2, 0), (3, 0)],
        (false, true) => vec![(1, 0), (2, 0), (3, 2)],
        (true, false) => vec![(1, 0), (2, 0), (3, 1)],
        (false, false) => vec![(1, 0), (2, 0)],
    };
    let unknowns: Vec<usize> = (0..4).filter(|&k| present(k)).collect();
    let coefficient = |row: (usize, u8), (s, wave, dir): (&Side, usize, f64), on_a: bool| -> C64 {
        let include = match row.1 {
            0 => true,
            1 => on_a,
            _ => !on_a,
        };
        match s.state(wave, dir, xi) {
            Some(v) if include => {
                if row.1 == 0 && !on_a {
                    -v[row.0]
                } else {
                    v[row.0]
                }
            }
            _ => zero,
        }
    };
    let n = unknowns.len();
    let mut lhs = vec![vec![zero; n]; n];
    let mut rhs = vec![vec![zero; 4]; n];
    for (r, &row) in rows.iter().enumerate() {
        for (c, &k) in unknowns.iter().enumerate() {
            lhs[r][c] = coefficient(row, outgoing(k), k < 2);
        }
        for (k, v) in rhs[r].iter_mut().enumerate() {
            if present(k) {
                *v = -coefficient(row, arriving(k), k < 2);
            }
        }
    }
    let Some(x) = solve(lhs, rhs) else { return m };
    for (c, &k) in unknowns.iter().enumerate() {
        m[k] = [x[c][0], x[c][1], x[c][2], x[c][3]];
    }
    m
}

/// `X` with `A·X = B` (`A` n×n, `B` n×4) by Gaussian elimination with rows scaled to unit largest
/// entry (they mix displacements and stresses) and partial pivoting; `None` if singular or not
/// finite.
fn solve(mut a: Vec<Vec<C64>>, mut b: Vec<Vec<C64>>) -> Option<Vec<Vec<C64>>> {
    let n = a.len();
    for (row, rhs) in a.iter_mut().zip(b.iter_mut()) {
        let s = row.iter().map(|v| v.norm()).fold(0.0, f64::max);
        if s > 0.0 {
            row.iter_mut().for_each(|v| *v /= s);
            rhs.iter_mut().for_each(|v| *v /= s);
        }
    }
    for col in 0..n {
        let p = (col..n).max_by(|&x, &y| a[x][col].norm().total_cmp(&a[y][col].norm()))?;
        a.swap(col, p);
        b.swap(col, p);
        let d = a[col][col];
        if d.norm() == 0.0 {
            return None;
        }
        let (pivot_a, pivot_b) = (a[col].clone(), b[col].clone());
        for (row, rhs) in a.iter_mut().zip(b.iter_mut()).skip(col + 1) {
            let f = row[col] / d;
            row.iter_mut().zip(&pivot_a).skip(col).for_each(|(v, p)| *v -= f * p);
            rhs.iter_mut().zip(&pivot_b).for_each(|(v, p)| *v -= f * p);
        }
    }
    let mut x = vec![vec![C64::new(0.0, 0.0); 4]; n];
    for r in (0..n).rev() {
        for c in 0..4 {
            let s: C64 = (r + 1..n).map(|k| a[r][k] * x[k][c]).sum();
            x[r][c] = (b[r][c] - s) / a[r][r];
        }
    }
    x.iter().flatten().all(|v| v.re.is_finite() && v.im.is_finite()).then_some(x)
}

/// A face's filters for the march's fields, `/(nx·ny)` on the transposed spectrum layout, by
/// direction of the arriving waves (0: forward, from `a`; 1: backward, from `b`), output
/// (0: transmitted ψ, 1: transmitted s, 2: reflected ψ, 3: reflected s) and input (0: ψ, 1: s);
/// `None` where zero at every component (SV in a fluid).
pub(super) type Filters<T> = [[[Option<Arc<Vec<Complex<T>>>>; 2]; 4]; 2];

/// The filters of the face from `a` into `b` on grid `g` (see [`Filters`]): the scattering
/// matrix of each component, flux-normalised (`sqrt(Z_in/Z_out)` of the waves' impedances). A face
/// lying `offset` (m) beyond the plane it is applied on (a CT's face inside a cell) gives each
/// wave the phase of its true path ([`segment_phase`]); 0 for a face on the plane.
pub(super) fn filters(g: &Grid, a: &Side, b: &Side, offset: f64) -> Filters<f64> {
    let norm = 1.0 / g.lateral_len() as f64;
    let sides = [a, b];
    // [direction][out][in] -> (index into scattering's out, its in; the sides and waves).
    let out_index = |dir: usize, out: usize| match (dir, out) {
        (0, o) if o < 2 => 2 + o, // transmitted into b
        (0, o) => o - 2,          // reflected into a
        (_, o) if o < 2 => o,     // transmitted into a
        (_, o) => o,              // reflected into b (2 + o - 2)
    };
    let in_index = |dir: usize, wave: usize| 2 * dir + wave;
    let side_of = |k: usize| sides[k / 2];
    // A sample's values depend on its wavenumbers through `ξ = |k|` alone: each distinct `ξ` (a
    // quarter or an eighth of the samples, by the spectrum's symmetries) is solved once.
    let xis: Vec<f64> = (0..g.lateral_len())
        .into_par_iter()
        .map(|at| {
            let (kx, ky) = (Grid::wavenumber(at / g.ny, g.nx, g.dx), Grid::wavenumber(at % g.ny, g.ny, g.dy));
            (kx * kx + ky * ky).sqrt()
        })
        .collect();
    let mut distinct: Vec<u64> = xis.iter().map(|x| x.to_bits()).collect();
    distinct.sort_unstable();
    distinct.dedup();
    let solved: Vec<Values> = distinct
        .par_iter()
        .map(|&bits| {
            let xi = f64::from_bits(bits);
            let m = scattering(a, b, xi);
            std::array::from_fn(|dir| {
                std::array::from_fn(|o| {
                    std::array::from_fn(|w| {
                        let (ko, ki) = (out_index(dir, o), in_index(dir, w));
                        let (zi, zo) = (side_of(ki).impedance[ki % 2], side_of(ko).impedance[ko % 2]);
                        if zi > 0.0 && zo > 0.0 {
                            let out_side = if o < 2 { 1 - dir } else { dir };
                            let shift = segment_phase([a, b], offset, g.dz, xi, [(dir, w), (out_side, o % 2)]);
                            m[ko][ki] * (zi / zo).sqrt() * norm * (C64::i() * shift).exp()
                        } else {
                            C64::new(0.0, 0.0)
                        }
                    })
                })
            })
        })
        .collect();
    let values: Vec<Values> = xis
        .par_iter()
        .map(|x| solved[distinct.binary_search(&x.to_bits()).expect("every sample's ξ is among the distinct ones")])
        .collect();
    pack(&values)
}

/// One spectrum sample of a face's filters: `[direction][output][input]` (see [`Filters`]).
pub(super) type Values = [[[C64; 2]; 4]; 2];

/// The filters of per-sample `values` (in the spectrum's layout): one spectrum per direction,
/// output and input, `None` where it is zero at every sample.
pub(super) fn pack(values: &[Values]) -> Filters<f64> {
    let mut out: Filters<f64> = Default::default();
    for (dir, per_dir) in out.iter_mut().enumerate() {
        for (o, per_out) in per_dir.iter_mut().enumerate() {
            for (w, slot) in per_out.iter_mut().enumerate() {
                if values.iter().any(|v| v[dir][o][w] != C64::new(0.0, 0.0)) {
                    *slot = Some(Arc::new(values.iter().map(|v| v[dir][o][w]).collect()));
                }
            }
        }
    }
    out
}

/// One material pair of an elastic interface: its pixels (`None`: every pixel) and filters.
pub(super) struct ElasticPair<T> {
    pub pixels: Option<Vec<u32>>,
    pub filters: Arc<Filters<T>>,
}

impl<T> ElasticPair<T> {
    /// Whether it converts: an SV wave arrives or leaves (a solid on either side).
    pub fn converts(&self) -> bool {
        self.filters
            .iter()
            .any(|d| d.iter().enumerate().any(|(o, per_out)| per_out[1].is_some() || (o % 2 == 1 && per_out.iter().any(Option::is_some))))
    }
}

/// The single-precision copy of `f`.
pub(super) fn single_filters(f: &Filters<f64>) -> Filters<f32> {
    f.clone().map(|d| d.map(|o| o.map(|w| w.map(|v| Arc::new(v.iter().map(|&c| C32::new(c.re as f32, c.im as f32)).collect::<Vec<_>>())))))
}

/// The spectra of the first `halves` planes of `field` (`[ψ | s]`, one plane each). `work` is
/// overwritten.
pub(super) fn spectra_of<T: FftNum>(
    fft: &Fft2<T>,
    field: &[Complex<T>],
    halves: usize,
    work: &mut Vec<Complex<T>>,
    ws: &mut FftWorkspace<T>,
) -> Vec<Vec<Complex<T>>> {
    let n = fft.nx * fft.ny;
    work.resize(n, Complex::new(T::zero(), T::zero()));
    field
        .chunks_exact(n)
        .take(halves)
        .map(|half| {
            work.copy_from_slice(half);
            fft.forward(work, ws);
            ws.spectrum.clone()
        })
        .collect()
}

/// One output's spectrum into `ws`: `Σ_in spectra[in]·filters[in]` (the inputs' `None` skipped).
pub(super) fn combine<T: FftNum>(ws: &mut FftWorkspace<T>, spectra: &[Vec<Complex<T>>], filters: &[Option<Arc<Vec<Complex<T>>>>; 2]) {
    ws.spectrum.fill(Complex::new(T::zero(), T::zero()));
    for (spectrum, filter) in spectra.iter().zip(filters) {
        if let Some(f) = filter {
            ws.spectrum.iter_mut().zip(spectrum).zip(f.iter()).for_each(|((s, a), f)| *s = *s + *a * *f);
        }
    }
}

/// Crosses the pairs' face in direction `sign` (+1 forward): `field` (`[ψ | s]`, `2·nx·ny`)
/// becomes the transmitted waves, and the reflected ones (`[ψ | s]`) are returned when `keep`.
/// Pixels in no pair keep both fields. `work` is overwritten.
pub(super) fn cross<T: Real>(
    pairs: &[ElasticPair<T>],
    fft: &Fft2<T>,
    field: &mut [Complex<T>],
    sign: f64,
    keep: bool,
    work: &mut Vec<Complex<T>>,
    ws: &mut FftWorkspace<T>,
) -> Option<Wave<T>> {
    let n = fft.nx * fft.ny;
    let dir = usize::from(sign < 0.0);
    // `[ψ | s]`, or `ψ` alone where the plan carries no SV wave (faces between fluids).
    let halves = field.len() / n;
    let spectra = spectra_of(fft, field, halves, work, ws);
    let mut transmitted = field.to_vec();
    for pair in pairs {
        match &pair.pixels {
            None => transmitted.fill(zero()),
            Some(px) => px.iter().for_each(|&i| (0..halves).for_each(|h| transmitted[h * n + i as usize] = zero())),
        }
    }
    let mut reflected = if keep { vec![zero(); halves * n] } else { Vec::new() };
    work.resize(n, zero());
    for pair in pairs {
        for (o, inputs) in pair.filters[dir].iter().enumerate() {
            let target = if o < 2 { &mut transmitted } else { &mut reflected };
            if target.is_empty() || o % 2 >= halves || inputs.iter().all(Option::is_none) {
                continue;
            }
            combine(ws, &spectra, inputs);
            fft.inverse(ws, work);
            let half = &mut target[(o % 2) * n..(o % 2 + 1) * n];
            match &pair.pixels {
                None => half.iter_mut().zip(work.iter()).for_each(|(t, w)| *t += *w),
                Some(px) => px.iter().for_each(|&i| half[i as usize] += work[i as usize]),
            }
        }
    }
    field.copy_from_slice(&transmitted);
    keep.then_some(Wave::Dense(reflected))
}

/// The transpose of [`cross`] in direction `sign`: `adjoint` (`[ψ | s]`) holds the adjoint of the
/// transmitted waves and becomes that of the waves arriving; `kept` is the adjoint of the
/// reflected ones (`None`: not kept). Each output's `M·IFFT(f·FFT(·))` has the transpose
/// `IFFT(f·FFT(M·))` (the filters depend on `kx² + ky²` only: their own transposes); pixels in no
/// pair pass both fields. `work` is overwritten.
pub(super) fn cross_transposed(
    pairs: &[ElasticPair<f64>],
    fft: &Fft2,
    adjoint: &mut [C64],
    sign: f64,
    kept: Option<&[C64]>,
    work: &mut Vec<C64>,
    ws: &mut FftWorkspace,
) {
    let n = fft.nx * fft.ny;
    let dir = usize::from(sign < 0.0);
    let zero = C64::new(0.0, 0.0);
    let halves = adjoint.len() / n;
    let after = adjoint.to_vec();
    for pair in pairs {
        match &pair.pixels {
            None => adjoint.fill(zero),
            Some(px) => px.iter().for_each(|&i| (0..halves).for_each(|h| adjoint[h * n + i as usize] = zero)),
        }
    }
    let mut sums = vec![vec![zero; n]; halves];
    work.resize(n, zero);
    for pair in pairs {
        for (o, inputs) in pair.filters[dir].iter().enumerate() {
            let Some(source) = (if o < 2 { Some(&after[..]) } else { kept }) else { continue };
            if o % 2 >= halves || inputs.iter().all(Option::is_none) {
                continue;
            }
            let half = &source[(o % 2) * n..(o % 2 + 1) * n];
            match &pair.pixels {
                None => work.copy_from_slice(half),
                Some(px) => {
                    work.fill(zero);
                    px.iter().for_each(|&i| work[i as usize] = half[i as usize]);
                }
            }
            fft.forward(work, ws);
            for (sum, filter) in sums.iter_mut().zip(inputs) {
                if let Some(f) = filter {
                    sum.iter_mut().zip(&ws.spectrum).zip(f.iter()).for_each(|((s, a), f)| *s += a * f);
                }
            }
        }
    }
    for (w, sum) in sums.iter().enumerate() {
        ws.spectrum.copy_from_slice(sum);
        fft.inverse(ws, work);
        adjoint[w * n..(w + 1) * n].iter_mut().zip(work.iter()).for_each(|(a, v)| *a += v);
    }
}

/// The SV field's screen through a slab, `exp(i·(ks - k̄s)·dz - (alpha_s + sigma)·dz)` on its
/// solid pixels (`sigma` the absorbing layer) and 0 on its fluid ones, for the mean shear
/// wavenumber and attenuation `(k̄s, ā_s)` whose propagator carries the step. With
/// `continuation` (the grid's `(nx, ny)` and a reach in pixels along x and y), fluid pixels
/// within the reach of a solid one carry the SV wave on as the slab's mean solid would,
/// `exp(-(ā_s + sigma)·dz)` (`oblique_shear::CONTINUATION`).
pub(super) fn screen(
    shear: &ShearMaps,
    sponge: &[f64],
    omega: f64,
    (k_mean, a_mean): (f64, f64),
    dz: f64,
    continuation: Option<([usize; 2], [usize; 2])>,
) -> Vec<C64> {
    let near = continuation.map(|(dims, reach)| near_solid(&shear.sound_speed, dims, reach));
    shear
        .sound_speed
        .iter()
        .zip(&shear.attenuation)
        .zip(sponge)
        .enumerate()
        .map(|(p, ((&cs, &a), &s))| {
            if cs > 0.0 {
                C64::from_polar((-(a + s) * dz).exp(), (omega / cs - k_mean) * dz)
            } else if near.as_ref().is_some_and(|near| near[p]) {
                C64::new((-(a_mean + s) * dz).exp(), 0.0)
            } else {
                C64::new(0.0, 0.0)
            }
        })
        .collect()
}

/// Whether each pixel of a plane `(nx, ny)` lies within `reach` pixels (along x, along y) of a
/// pixel of positive shear speed: the solid mask dilated by a box, row by row then column by
/// column.
fn near_solid(speed: &[f64], [nx, ny]: [usize; 2], [rx, ry]: [usize; 2]) -> Vec<bool> {
    let mut rows = vec![false; nx * ny];
    for y in 0..ny {
        let row = &speed[y * nx..(y + 1) * nx];
        // Distance to the last solid pixel at or before x, then after.
        let mut last: Option<usize> = None;
        for x in 0..nx {
            if row[x] > 0.0 {
                last = Some(x);
            }
            rows[y * nx + x] = last.is_some_and(|l| x - l <= rx);
        }
        let mut next: Option<usize> = None;
        for x in (0..nx).rev() {
            if row[x] > 0.0 {
                next = Some(x);
            }
            rows[y * nx + x] |= next.is_some_and(|n| n - x <= rx);
        }
    }
    let mut out = vec![false; nx * ny];
    for x in 0..nx {
        let mut last: Option<usize> = None;
        for y in 0..ny {
            if rows[y * nx + x] {
                last = Some(y);
            }
            out[y * nx + x] = last.is_some_and(|l| y - l <= ry);
        }
        let mut next: Option<usize> = None;
        for y in (0..ny).rev() {
            if rows[y * nx + x] {
                next = Some(y);
            }
            out[y * nx + x] |= next.is_some_and(|n| n - y <= ry);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::elastic::{plate_response, Solid};
    use crate::reference::Fluid;
    use std::f64::consts::PI;

    const OMEGA: f64 = 2.0 * PI * 500e3;

    /// The solid mask dilated by a box, row then column, against every pixel's box searched
    /// directly (seeded random masks, unequal reaches, a reach wider than the plane).
    #[test]
    fn near_solid_is_the_box_dilation_of_the_solid_mask() {
        let mut state = 7u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as f64 / (1u64 << 31) as f64
        };
        for (nx, ny, rx, ry, density) in [(17, 11, 2, 1, 0.05), (9, 13, 0, 3, 0.1), (6, 5, 7, 0, 0.2), (12, 12, 3, 3, 0.0)] {
            let speed: Vec<f64> = (0..nx * ny).map(|_| if next() < density { 1500.0 } else { 0.0 }).collect();
            let fast = near_solid(&speed, [nx, ny], [rx, ry]);
            for y in 0..ny {
                for x in 0..nx {
                    let slow =
                        (0..ny).any(|yy| (0..nx).any(|xx| speed[yy * nx + xx] > 0.0 && x.abs_diff(xx) <= rx && y.abs_diff(yy) <= ry));
                    assert_eq!(fast[y * nx + x], slow, "({x}, {y}) of {nx}x{ny}, reach ({rx}, {ry})");
                }
            }
        }
    }

    fn water() -> Side {
        Side { density: 1000.0, kp: C64::new(OMEGA / 1500.0, 0.0), ks: None, impedance: [1.5e6, 0.0] }
    }

    fn bone(cs: f64, loss: f64) -> Side {
        Side {
            density: 1850.0,
            kp: C64::new(OMEGA / 2800.0, loss),
            ks: Some(C64::new(OMEGA / cs, loss)),
            impedance: [1850.0 * 2800.0, 1850.0 * cs],
        }
    }

    /// Between two fluids the scattering is the pressure coefficients `R`, `1 + R` of
    /// [`super::super::reflection_coefficient`] and their reverse `-R`, `1 - R`, to 1e-12.
    #[test]
    fn between_fluids_it_is_the_fluid_face() {
        let oil = Side { density: 900.0, kp: C64::new(OMEGA / 1400.0, 3.0), ks: None, impedance: [900.0 * 1400.0, 0.0] };
        for xi in [0.0, 500.0, 1500.0, 2200.0, 4000.0] {
            let m = scattering(&water(), &oil, xi);
            let r = super::super::reflection_coefficient(OMEGA, (1000.0, 1500.0, 0.0), (900.0, 1400.0, 3.0), xi * xi);
            for (got, want) in [(m[0][0], r), (m[2][0], 1.0 + r), (m[2][2], -r), (m[0][2], 1.0 - r)] {
                assert!((got - want).norm() < 1e-12, "xi {xi}: {got} vs {want}");
            }
        }
    }

    /// Lossless fluid-solid-fluid faces conserve the z-flux of propagating waves: for each arriving
    /// wave, `Σ |m|²·Re(kz_out)/Re(kz_in)·ρ_in/ρ_out` over the outgoing ones (the flux of a unit
    /// scaled amplitude is `|P|²·Re(kz)/(2ρω)` for either wave) is 1, to 1e-12, at angles below and
    /// beyond both critical angles, into the solid and out of it, and between two solids.
    #[test]
    fn a_lossless_face_conserves_flux() {
        let (w, b, soft) = (water(), bone(1500.0, 0.0), bone(1100.0, 0.0));
        let soft = Side { density: 1400.0, kp: C64::new(OMEGA / 2200.0, 0.0), impedance: [1400.0 * 2200.0, 1400.0 * 1100.0], ..soft };
        let kz = |s: &Side, wave: usize, xi: f64| {
            let k = if wave == 0 { s.kp } else { s.ks.unwrap_or(C64::new(0.0, 0.0)) };
            super::super::interface::axial_wavenumber(k, xi * xi).re
        };
        for (a, b) in [(w, b), (b, w), (b, soft), (soft, b)] {
            for deg in [0.0, 10.0, 25.0, 31.0, 45.0, 70.0] {
                let xi = a.largest_wavenumber().min(b.largest_wavenumber()) * f64::sin(f64::to_radians(deg)) * 0.999;
                let m = scattering(&a, &b, xi);
                let side = |k: usize| if k < 2 { &a } else { &b };
                for i in (0..4).filter(|&i| i % 2 == 0 || side(i).is_solid()) {
                    let kin = kz(side(i), i % 2, xi);
                    if kin <= 0.0 {
                        continue;
                    }
                    let flux: f64 = (0..4)
                        .filter(|&o| o % 2 == 0 || side(o).is_solid())
                        .map(|o| m[o][i].norm_sqr() * kz(side(o), o % 2, xi) / kin * side(i).density / side(o).density)
                        .sum();
                    assert!((flux - 1.0).abs() < 1e-12, "{deg}°, arriving {i}: {flux}");
                }
            }
        }
    }

    /// The half-space reflection of water on bone equals the reference's thick plate, whose back
    /// face returns nothing (to 1e-9), at angles on both sides of the critical angles.
    #[test]
    fn water_on_bone_reflects_as_the_reference_half_space() {
        let loss = 40.0;
        let solid = Solid { kp: C64::new(OMEGA / 2800.0, loss), ks: C64::new(OMEGA / 1500.0, loss), density: 1850.0 };
        let fluid = Fluid { k: C64::new(OMEGA / 1500.0, 0.0), density: 1000.0 };
        for deg in [0.0, 12.0, 28.0, 33.0, 50.0, 75.0] {
            let xi = OMEGA / 1500.0 * f64::sin(f64::to_radians(deg));
            let want = plate_response(fluid, solid, 0.6, fluid, C64::new(xi, 0.0)).reflection;
            let got = scattering(&water(), &bone(1500.0, loss), xi)[0][0];
            assert!((got - want).norm() < 1e-9, "{deg}°: {got} vs {want}");
        }
    }
}
