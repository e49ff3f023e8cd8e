//! Seeded skull-like phase aberrations for simulation studies.
//!
//! A smooth Gaussian random phase screen over the aperture (shot noise of Gaussian bumps of width
//! `correlation_length` with random signs and centres, about four bumps per correlation area),
//! scaled to `peak_to_peak` over the elements, plus independent per-element jitter. The defaults
//! (12 mm, 6 rad) lie in the skull-like range the studies assume (correlation length of order
//! 10–15 mm, several radians peak to peak); a per-group case is the group condensation of such a
//! screen.

use crate::error::{require_non_negative, require_positive, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The lateral bounding box of `positions`: the smallest and largest x and y (m).
pub fn lateral_bounds(positions: &[[f64; 3]]) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in positions {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Parameters of the screen (SI: metres, radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkullScreen {
    /// Correlation length of the smooth screen (width of its Gaussian bumps), m.
    pub correlation_length: f64,
    /// Peak-to-peak range of the smooth screen over the elements, rad.
    pub peak_to_peak: f64,
    /// Standard deviation of the independent per-element jitter, rad.
    pub jitter: f64,
}

impl Default for SkullScreen {
    /// 12 mm correlation length, 6 rad peak to peak, 0.5 rad per-element jitter.
    fn default() -> Self {
        SkullScreen { correlation_length: 12e-3, peak_to_peak: 6.0, jitter: 0.5 }
    }
}

impl SkullScreen {
    /// Per-element phases (rad) at element centres `positions` (m).
    pub fn phases(&self, positions: &[[f64; 3]], seed: u64) -> Result<Vec<f64>> {
        require_positive("correlation_length", self.correlation_length)?;
        require_non_negative("peak_to_peak", self.peak_to_peak)?;
        require_non_negative("jitter", self.jitter)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (lo, hi) = lateral_bounds(positions);
        let l = self.correlation_length;
        let (x0, x1, y0, y1) = (lo[0] - 2.0 * l, hi[0] + 2.0 * l, lo[1] - 2.0 * l, hi[1] + 2.0 * l);
        let bumps = (4.0 * (x1 - x0) * (y1 - y0) / (l * l)).ceil() as usize;
        let normal = Normal::new(0.0, 1.0).map_err(|e| crate::HasError::invalid("screen", e.to_string()))?;
        let centres: Vec<(f64, f64, f64)> =
            (0..bumps).map(|_| (rng.random_range(x0..x1), rng.random_range(y0..y1), normal.sample(&mut rng))).collect();
        let smooth: Vec<f64> = positions
            .iter()
            .map(|p| centres.iter().map(|&(cx, cy, a)| a * (-((p[0] - cx).powi(2) + (p[1] - cy).powi(2)) / (2.0 * l * l)).exp()).sum())
            .collect();
        let (mn, mx) = smooth.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let scale = if mx > mn { self.peak_to_peak / (mx - mn) } else { 0.0 };
        let mean = 0.5 * (mx + mn);
        Ok(smooth.iter().map(|v| (v - mean) * scale + self.jitter * normal.sample(&mut rng)).collect())
    }
}
