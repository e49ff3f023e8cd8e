//! Calibration of the broadening filter from a no-aberration image (paper Eq. 2 and Fig. 2).
//!
//! The model image is `A · (F ⊛ g_W)` sampled on the MR pixels; for each width W the amplitude A
//! is the linear least-squares fit over the focal zone (pixels above `mask_fraction` of the
//! measured focal maximum connected to it) dilated by half the largest width searched (imaged
//! pixels only), and W minimises
//! the remaining squared difference (a scan, then golden-section refinement).

use crate::error::{require_positive, HasError, Result};
use crate::inverse::cost::{check_image, imaged_pixels, mask_pixels};
use crate::physics::mr::noise_floor;
use crate::simulation::Simulation;
use ndarray::Array2;

/// The fitted broadening and amplitude, with the scenario and frequency they were fitted for (a
/// width and an amplitude belong to one array, one MR protocol and one frequency: applied to
/// another they would be silently wrong).
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// Gaussian width W (m).
    pub broadening_width: f64,
    /// Scale from broadened force density (N/m³) to ARFI phase (rad).
    pub amplitude: f64,
    /// Final squared difference over the mask (rad²); NaN when not recorded (a hand-written file).
    pub cost: f64,
    /// Number of masked pixels the cost sums over; 0 when not recorded.
    pub n_pixels: usize,
    /// Noise level of the image background (rad); NaN when not recorded.
    pub noise: f64,
    /// The scenario's name it was fitted for; None when not recorded (applies to any).
    pub scenario: Option<String>,
    /// The frequency it was fitted at (Hz); None when not recorded (applies to any).
    pub frequency: Option<f64>,
}

/// Fits W (searched in `[0, max_width]`, m, at most the MR field of view) and A to a measured image of the beam steered with
/// `known` phases added (per element or per group; empty = none).
pub fn calibrate(sim: &Simulation, image: &Array2<f64>, known: &[f64], mask_fraction: f64, max_width: f64) -> Result<Calibration> {
    check_image(sim, image, "image")?;
    if !(mask_fraction > 0.0 && mask_fraction < 1.0) {
        return Err(HasError::invalid("mask_fraction", "must lie in (0, 1)"));
    }
    require_positive("max_width_mm", max_width * 1e3)?;
    // A Gaussian wider than the field of view blurs the image flat: no wider width can fit better,
    // and the search's cost grows with the width.
    let max_width = max_width.min(sim.mr.fov[0].max(sim.mr.fov[1]));
    let rec = sim.record_window(&[sim.source_field(known)?])?.remove(0);
    let power: Vec<f64> = rec.window.iter().map(|p| p.norm_sqr()).collect();
    // The focal zone, dilated by the blur reach of the largest width: pixels with little signal
    // still constrain the width through the tails.
    let zone = mask_pixels(image, mask_fraction, &sim.focal_region());
    let m = sim.mr.matrix;
    let px = sim.mr.pixel_size();
    let reach = [(0.5 * max_width / px[0]).ceil() as usize, (0.5 * max_width / px[1]).ceil() as usize];
    let (u0, u1) = (zone.iter().map(|p| p.0).min().unwrap_or(0), zone.iter().map(|p| p.0).max().unwrap_or(0) + 1);
    let (v0, v1) = (zone.iter().map(|p| p.1).min().unwrap_or(0), zone.iter().map(|p| p.1).max().unwrap_or(0) + 1);
    let (u, v) = (
        u0.saturating_sub(reach[0])..u1.saturating_add(reach[0]).min(m[0]),
        v0.saturating_sub(reach[1])..v1.saturating_add(reach[1]).min(m[1]),
    );
    let mask = imaged_pixels(image, u.clone(), v.clone());
    let measured: Vec<f64> = mask.iter().map(|&ij| image[ij]).collect();
    let fit = |w: f64| -> Result<(f64, f64)> {
        let f = sim.sampler()?.with_broadening(w)?.apply(&power)?;
        let model: Vec<f64> = mask.iter().map(|&ij| f[ij]).collect();
        let ff: f64 = model.iter().map(|x| x * x).sum();
        let fm: f64 = model.iter().zip(&measured).map(|(x, y)| x * y).sum();
        let a = if ff > 0.0 { fm / ff } else { 0.0 };
        let j = model.iter().zip(&measured).map(|(x, y)| (a * x - y).powi(2)).sum();
        Ok((j, a))
    };
    // Scan, then golden-section search around the best scan point.
    let n = 40;
    let step = max_width / n as f64;
    let scan = (0..=n).map(|i| Ok((i as f64 * step, fit(i as f64 * step)?.0))).collect::<Result<Vec<_>>>()?;
    let (i_best, _) =
        scan.iter().enumerate().min_by(|a, b| a.1 .1.total_cmp(&b.1 .1)).ok_or_else(|| HasError::invalid("image", "empty"))?;
    let (mut lo, mut hi) = ((i_best as f64 - 1.0).max(0.0) * step, (i_best as f64 + 1.0).min(n as f64) * step);
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (hi - r * (hi - lo), lo + r * (hi - lo));
    let (mut fc, mut fd) = (fit(c)?.0, fit(d)?.0);
    while hi - lo > 1e-7 {
        if fc < fd {
            hi = d;
            d = c;
            fd = fc;
            c = hi - r * (hi - lo);
            fc = fit(c)?.0;
        } else {
            lo = c;
            c = d;
            fc = fd;
            d = lo + r * (hi - lo);
            fd = fit(d)?.0;
        }
    }
    let w = 0.5 * (lo + hi);
    let (cost, amplitude) = fit(w)?;
    if !(amplitude > 0.0) {
        return Err(HasError::invalid("image", "the calibration image does not resemble the simulated focus (no positive amplitude fits)"));
    }
    let noise = noise_floor(image, &[u, v]);
    Ok(Calibration {
        broadening_width: w,
        amplitude,
        cost,
        n_pixels: mask.len(),
        noise,
        scenario: Some(sim.name.clone()),
        frequency: Some(sim.frequency),
    })
}
