//! Slabs that a planar wall oblique to the planes crosses: two reference media instead of one.
//!
//! The HAS step propagates the whole plane in one mean medium `k̄` and corrects each pixel by a
//! screen. A screen gives a pixel the phase of one direction only (the line to the focus, refracted
//! by the wall: `operators::refract`), and a wall tilted against the planes sends the waves in bone
//! in directions that no single ray stands for: through a plate tilted by 20-30° the focus came
//! out 10-13 % too strong. Where such a wall crosses the slab, each pixel instead takes the waves
//! of the two media it lies between, each propagated exactly for every direction of the angular
//! spectrum (the wave-propagation method, Brenner & Singer, Appl Opt 32(26), 1993; with linear
//! weights between the two references, the phase-shift-plus-interpolation of Gazdag & Sguazzero,
//! Geophysics 49(2), 1984):
//!
//! `ψ' = Σ_r w_r(x, y) · S_r(x, y) · IFFT(P_r · FFT(ψ))`,
//!
//! with `P_r` the propagator of reference `r` (wavenumber `k_r`, attenuation `α_r`), `S_r` the
//! vertical screen of the pixel's deviation from it, and `w_r` the pixel's weight, linear in its
//! wavenumber between the two references (`w_0 + w_1 = 1`; a pixel of either medium takes that
//! medium's wave alone). The references are the extreme wavenumbers among the pixels that carry
//! the reference beam (at least [`FIELD_FLOOR`] of its peak), fixed when the plan is built, so
//! the step stays linear in the source. Walls about the focus (a cap, a shell) keep the single
//! mean and the oblique screen, whose rays are right there: with two references the shells of
//! the validation suite move 0.8-0.9 mm short of their exact focus.

use super::operators::screen;
use crate::physics::medium::SliceProperties;
use num_complex::Complex64 as C64;

/// Pixels carrying at least this fraction of the reference beam's peak (flux-normalised
/// magnitude) choose the references.
pub const FIELD_FLOOR: f64 = 1e-3;

/// A slab takes two references only where those pixels' wavenumbers span more than this
/// fraction of the larger: bone against water or brain, not soft tissues against each other.
pub const REFERENCE_SPREAD: f64 = 0.05;

/// The two reference media of a slab: `(k, alpha)` (rad/m, Np/m), the smaller wavenumber first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct References(pub [(f64, f64); 2]);

impl References {
    /// The references of a slab (see the module doc) for the reference beam `field` (the
    /// flux-normalised field entering it), rounded to multiples of `quantum` as the mean
    /// wavenumber is (so that slabs of equal media share their propagators); `None` where the
    /// slab does not mix media [`REFERENCE_SPREAD`] apart. Each reference's attenuation is the
    /// field-weighted mean over the pixels by their weights on it (sequential sums: the same with
    /// any number of threads).
    pub fn of(field: &[C64], props: &SliceProperties, omega: f64, quantum: f64) -> Option<Self> {
        let peak = field.iter().map(|p| p.norm_sqr()).fold(0.0, f64::max).sqrt();
        let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
        for (p, c) in field.iter().zip(&props.sound_speed) {
            if peak > 0.0 && p.norm_sqr().sqrt() >= FIELD_FLOOR * peak {
                lo = lo.min(omega / c);
                hi = hi.max(omega / c);
            }
        }
        let round = |v: f64| (v / quantum).round() * quantum;
        let (lo, hi) = (round(lo), round(hi));
        if !(hi - lo > REFERENCE_SPREAD * hi) {
            return None;
        }
        let media = [(lo, 0.0), (hi, 0.0)];
        let mut alpha = [(0.0, 0.0); 2];
        for ((p, c), a) in field.iter().zip(&props.sound_speed).zip(&props.attenuation) {
            let m = p.norm_sqr().sqrt();
            let w1 = weight(omega / c, media);
            for (r, w) in [(0, 1.0 - w1), (1, w1)] {
                alpha[r].0 += m * w * a;
                alpha[r].1 += m * w;
            }
        }
        let mean = |(num, den): (f64, f64)| if den > 0.0 { round(num / den) } else { 0.0 };
        Some(References([(lo, mean(alpha[0])), (hi, mean(alpha[1]))]))
    }

    /// The screen of reference `r` over a distance `dz` (m), each pixel's weight on it folded in:
    /// `w_r · exp(i·(k - k_r)·dz - (alpha + sigma)·dz)` (`sponge`: the absorbing layer `sigma`).
    pub fn screen(&self, r: usize, props: &SliceProperties, sponge: &[f64], omega: f64, dz: f64) -> Vec<C64> {
        let (k, a) = self.0[r];
        let mut s = screen(props, sponge, omega, k, a, None, dz);
        s.iter_mut().zip(&props.sound_speed).for_each(|(s, c)| {
            let w1 = weight(omega / c, self.0);
            *s *= if r == 0 { 1.0 - w1 } else { w1 };
        });
        s
    }
}

/// The weight on the second reference of a pixel of wavenumber `k`: linear between the two,
/// clamped to [0, 1].
fn weight(k: f64, [(lo, _), (hi, _)]: [(f64, f64); 2]) -> f64 {
    ((k - lo) / (hi - lo)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::fft::Fft2;
    use crate::physics::grid::Grid;
    use crate::physics::propagation::operators::propagator;
    use std::f64::consts::PI;

    const F: f64 = 5e5;
    const WATER: f64 = 1500.0;
    const BONE: f64 = 2800.0;

    /// Bone where x > 0, water where x < 0, lossless, no sponge.
    fn halves(g: &Grid) -> SliceProperties {
        let n = g.lateral_len();
        SliceProperties {
            sound_speed: (0..n).map(|p| if g.x(p % g.nx) > 0.0 { BONE } else { WATER }).collect(),
            density: vec![1000.0; n],
            attenuation: vec![0.0; n],
            shear: None,
        }
    }

    /// A plane wave `exp(i·kx·x)` of the grid's spectrum (0-61° in bone, 0-28° in water)
    /// crossing a slab of water and bone side by side, stepped with the two references: each
    /// pixel gains exactly `exp(i·kz·dz)` of its own medium at the wave's angle (to 1e-9), which
    /// one mean medium and a screen along z give only at normal incidence.
    #[test]
    fn each_medium_propagates_every_direction_exactly() {
        let g = Grid::new(128, 4, 0.25e-3, 0.25e-3, 2, 0.5e-3, 0.0).unwrap();
        let omega = 2.0 * PI * F;
        let props = halves(&g);
        let fft = Fft2::new(g.nx, g.ny);
        // Unrounded references (a plan rounds them to 1e-4 of k, which the screen makes up for at
        // normal incidence only).
        let quantum = omega / WATER * 1e-12;
        for m in [0usize, 2, 4, 5] {
            let kx = Grid::wavenumber(m, g.nx, g.dx);
            let wave: Vec<C64> = (0..g.lateral_len()).map(|p| C64::from_polar(1.0, kx * g.x(p % g.nx))).collect();
            let refs = References::of(&wave, &props, omega, quantum).expect("water and bone are far apart");
            let sponge = vec![0.0; g.lateral_len()];
            let mut out = vec![C64::new(0.0, 0.0); g.lateral_len()];
            for r in 0..2 {
                let (k, a) = refs.0[r];
                let mut part = wave.clone();
                let mut ws = fft.workspace(false);
                fft.filter(&mut part, &mut ws, None, &propagator(&g, g.dz, k, a), Some(&refs.screen(r, &props, &sponge, omega, g.dz)));
                out.iter_mut().zip(&part).for_each(|(o, p)| *o += p);
            }
            for p in 0..g.lateral_len() {
                let x = g.x(p % g.nx);
                let k = omega / props.sound_speed[p];
                // The screen keeps the pixel's own medium's normal-incidence phase; the wave's
                // direction in it gives kz.
                let want = wave[p] * C64::from_polar(1.0, (k * k - kx * kx).sqrt() * g.dz);
                assert!((out[p] - want).norm() < 1e-9, "kx {kx:.0}, x {x:.4}: {} vs {}", out[p], want);
            }
        }
    }

    /// Media closer than the spread, or a field that carries nothing: one reference.
    #[test]
    fn one_reference_where_the_media_are_alike() {
        let g = Grid::new(16, 4, 0.5e-3, 0.5e-3, 2, 0.5e-3, 0.0).unwrap();
        let omega = 2.0 * PI * F;
        let mut props = halves(&g);
        let field = vec![C64::new(1.0, 0.0); g.lateral_len()];
        assert!(References::of(&field, &props, omega, 1e-3).is_some());
        assert!(References::of(&vec![C64::new(0.0, 0.0); g.lateral_len()], &props, omega, 1e-3).is_none());
        props.sound_speed.iter_mut().for_each(|c| *c = if *c > 2000.0 { 1560.0 } else { 1500.0 });
        assert!(References::of(&field, &props, omega, 1e-3).is_none(), "brain against water is one medium");
    }
}
