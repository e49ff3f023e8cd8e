//! The transposes of an interface's crossings and reflections, which the transposed march
//! (`transpose.rs`: element responses by reciprocity) applies in reverse order.

use super::{flux_scale, scale_pixels, Interface, Kind};
use crate::physics::fft::{Fft2, FftWorkspace};
use crate::physics::propagation::oblique::opposite;
use num_complex::Complex64 as C64;

impl Interface {
    /// The transpose of crossing a pointwise interface that has oblique walls in the direction
    /// `sign` (`march::cross`): `adjoint` (`ψ`, or `[ψ | s]`) holds the adjoint of the field
    /// after the crossing and becomes that of the field before it; `kept` is the adjoint of the
    /// kept reflected wave written out on a field as long. A wall's `M·IFFT(f·FFT)` has the
    /// transpose `IFFT(f(-k)·FFT(M·))`; the other pixels are diagonal, and the SV field passes
    /// except where a wall's transmitted SV wave replaces it (its treads and the pixels ahead of
    /// them). `work` is overwritten.
    pub fn cross_transposed_walls(
        &self,
        fft: &Fft2,
        adjoint: &mut [C64],
        sign: f64,
        kept: Option<&[C64]>,
        work: &mut Vec<C64>,
        ws: &mut FftWorkspace,
    ) {
        let Kind::Pointwise { pixels, r, phase, walls: Some(walls) } = &self.kind else { return };
        let zero = C64::new(0.0, 0.0);
        let n = fft.nx * fft.ny;
        let halves = if walls.converts() { adjoint.len() / n } else { 1 };
        let after = adjoint.to_vec();
        let dir = usize::from(sign < 0.0);
        let face = |m: usize| phase.as_ref().map_or(C64::new(1.0, 0.0), |p| if sign < 0.0 { 1.0 / p[m] } else { p[m] });
        for (m, (&i, &r)) in pixels.iter().zip(r).enumerate() {
            let i = i as usize;
            if walls.grouped[m] {
                adjoint[i] = zero;
                continue;
            }
            let s = if sign < 0.0 { 1.0 / flux_scale(r) } else { flux_scale(r) };
            adjoint[i] = s * (1.0 + sign * r) * after[i] + kept.map_or(zero, |k| sign * r * face(m) * k[i]);
        }
        // The SV field that a wall's transmitted wave replaces (at its treads and ahead of them).
        if halves == 2 {
            for g in walls.groups.iter().filter(|g| g.transmits_sv(dir)) {
                g.members.iter().for_each(|&m| adjoint[n + pixels[m as usize] as usize] = zero);
                g.ahead[dir].iter().for_each(|&i| adjoint[n + i as usize] = zero);
            }
        }
        let mut sums = vec![vec![zero; n]; halves];
        let dims = (fft.nx, fft.ny);
        work.resize(n, zero);
        for g in &walls.groups {
            for (o, inputs) in g.filters[dir].iter().enumerate() {
                let source = if o < 2 { Some(&after[..]) } else { kept };
                let (Some(source), half) = (source, o % 2) else { continue };
                if half >= halves || inputs.iter().all(Option::is_none) {
                    continue;
                }
                work.fill(zero);
                for &m in &g.members {
                    let i = pixels[m as usize] as usize;
                    work[i] = if o < 2 { source[half * n + i] } else { face(m as usize) * source[half * n + i] };
                }
                if o == 1 {
                    g.ahead[dir].iter().for_each(|&i| work[i as usize] = source[n + i as usize]);
                }
                fft.forward(work, ws);
                for (sum, filter) in sums.iter_mut().zip(inputs) {
                    if let Some(f) = filter {
                        sum.iter_mut().zip(&ws.spectrum).enumerate().for_each(|(at, (s, a))| *s += a * f[opposite(dims, at)]);
                    }
                }
            }
        }
        for (half, sum) in sums.iter().enumerate() {
            ws.spectrum.copy_from_slice(sum);
            fft.inverse(ws, work);
            adjoint[half * n..(half + 1) * n].iter_mut().zip(work.iter()).for_each(|(a, w)| *a += w);
        }
    }

    /// `out ← Rᵀ p`, the transpose of [`Interface::reflect`]: `Σ_pairs IFFT(R_ab · FFT(M_ab · p))`
    /// (each pair's pixels taken before its filter, not after; `R_ab` depends on `kx² + ky²`
    /// only, so the filter is its own transpose). With `faces` (the direction of the incident
    /// wave, ±1), a pointwise `R` carries its faces' factors (`exp(±i·φ)`): the transpose of the
    /// reflected wave's operator rather than of the crossing's. `work` is overwritten.
    pub fn reflect_transposed(&self, fft: &Fft2, p: &[C64], out: &mut [C64], work: &mut [C64], ws: &mut FftWorkspace, faces: Option<f64>) {
        match &self.kind {
            // A pointwise R is diagonal: its own transpose.
            Kind::Pointwise { pixels, r, phase, .. } => {
                scale_pixels(pixels, r, p, out);
                if let (Some(sign), Some(phase)) = (faces, phase) {
                    pixels.iter().zip(phase).for_each(|(&i, &f)| out[i as usize] *= if sign < 0.0 { 1.0 / f } else { f });
                }
            }
            // The transpose of `reflect`'s P wave alone (the transposed march crosses these
            // faces in `elastic::cross_transposed`).
            Kind::Elastic(pairs) => {
                let pairs = pairs.iter().filter_map(|p| p.filters[0][2][0].as_ref().map(|f| (&p.pixels, &f[..])));
                transposed_pairs(fft, pairs, p, out, work, ws);
            }
            Kind::Spectral(pairs) => transposed_pairs(fft, pairs.iter().map(|p| (&p.pixels, &p.coefficient[..])), p, out, work, ws),
        }
    }
}

/// `out ← Σ_pairs IFFT(f · FFT(M · p))` over `(pixels, filter)` pairs, the transpose of
/// `filter_pairs` (each filter depends on `kx² + ky²` only: its own transpose).
fn transposed_pairs<'a>(
    fft: &Fft2,
    pairs: impl Iterator<Item = (&'a Option<Vec<u32>>, &'a [C64])>,
    p: &[C64],
    out: &mut [C64],
    work: &mut [C64],
    ws: &mut FftWorkspace,
) {
    let mut sum = vec![C64::new(0.0, 0.0); p.len()];
    for (pixels, coefficient) in pairs {
        match pixels {
            None => work.copy_from_slice(p),
            Some(px) => {
                work.fill(C64::new(0.0, 0.0));
                px.iter().for_each(|&i| work[i as usize] = p[i as usize]);
            }
        }
        fft.forward(work, ws);
        sum.iter_mut().zip(&ws.spectrum).zip(coefficient.iter()).for_each(|((s, a), r)| *s += a * r);
    }
    ws.spectrum.copy_from_slice(&sum);
    fft.inverse(ws, out);
}
