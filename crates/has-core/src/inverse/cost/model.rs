//! From measured images to the cost: checks, the mask of informative pixels, the noise floor
//! from the backgrounds, and the kernels of each acquisition.

use super::{ArfiKernel, HybridCost, Term};
use crate::error::{HasError, Result};
use crate::physics::mr::focal_peak;
use crate::simulation::Simulation;
use ndarray::Array2;
use std::ops::Range;

/// One measured MR-ARFI image and the known phases (rad; one per element or per group, empty =
/// none) that were added to the steering for it.
#[derive(Debug, Clone)]
pub struct Measurement {
    /// Measured MR-ARFI phase image (rad), `(u, v)` pixels.
    pub image: Array2<f64>,
    /// Known phases added for this image (rad), per element or per group; empty = none.
    pub known: Vec<f64>,
}

/// The cost assembled from measurements, with the kernel of the plain steering (for predictions)
/// and the noise level estimated from the images' backgrounds.
#[derive(Debug, Clone)]
pub struct Model {
    /// The joint cost of paper Eq. 4 over the measurements.
    pub cost: HybridCost,
    /// Kernels of the plain steering over the same pixel box (no known phases).
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

/// Checks a measured image against the scenario's MR geometry: NaN marks a pixel without MR
/// signal (left out of every fit); other values must be finite MR phases, with a positive focal
/// maximum near the target ([`Simulation::focal_arfi`]).
pub fn check_image(sim: &Simulation, image: &Array2<f64>, name: &str) -> Result<()> {
    sim.mr.check_shape(name, [image.nrows(), image.ncols()])?;
    if let Some(((i, j), v)) = image.indexed_iter().find(|(_, v)| v.is_infinite()) {
        return Err(HasError::invalid(name, format!("pixel ({i}, {j}) is {v} (NaN marks a pixel without signal; infinity is no phase)")));
    }
    if let Some(((i, j), v)) = image.indexed_iter().find(|(_, v)| v.abs() > MAX_PHASE) {
        return Err(HasError::invalid(name, format!("pixel ({i}, {j}) is {v:e} rad, beyond any MR phase (|phase| <= {MAX_PHASE} rad)")));
    }
    let (_, peak) = sim.focal_arfi(image, name)?;
    if !(peak > 0.0) {
        return Err(HasError::invalid(name, "has no positive pixel near the target (all-zero or inverted image?)"));
    }
    Ok(())
}

/// The focal zone (paper Eq. 4): the pixels above `fraction` of the image's focal maximum (its
/// largest imaged pixel within `region`, the pixels near the target) that are connected
/// (4-neighbours) to it. Isolated noise spikes elsewhere and pixels without signal (NaN) are
/// left out. Both are measured from the image's median (its background level: the focal zone
/// covers a small part of the image), so that a background phase offset does not flood the mask
/// over the background (with zero background: `fraction` of the maximum).
pub fn mask_pixels(image: &Array2<f64>, fraction: f64, region: &Array2<bool>) -> Vec<(usize, usize)> {
    let (nu, nv) = image.dim();
    let Some((peak, max)) = focal_peak(image, region) else {
        return vec![];
    };
    let mut values: Vec<f64> = image.iter().copied().filter(|v| v.is_finite()).collect();
    let mid = values.len() / 2;
    let background = *values.select_nth_unstable_by(mid, f64::total_cmp).1;
    let level = background + fraction * (max - background);
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

/// The imaged pixels (not NaN) of `image` in the box `u x v`, row-major.
pub fn imaged_pixels(image: &Array2<f64>, u: Range<usize>, v: Range<usize>) -> Vec<(usize, usize)> {
    u.flat_map(|i| v.clone().map(move |j| (i, j))).filter(|&ij| image[ij].is_finite()).collect()
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
    let region = sim.focal_region();
    let masks: Vec<Vec<(usize, usize)>> = measurements
        .iter()
        .enumerate()
        .map(|(k, meas)| {
            check_image(sim, &meas.image, &format!("image[{k}]"))?;
            Ok(mask_pixels(&meas.image, mask_fraction, &region))
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
            Some(q) if (crate::phase::wrap(p - q)).abs() < 1e-12 => {}
            Some(_) => return None,
        }
    }
    value.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_focal_zone_grows_from_the_focus_near_the_target_over_imaged_pixels() {
        // A focus of 0.6 rad at (20, 20) with a shoulder, a brighter spot far away (outside the
        // region: skull or scalp) and a NaN pixel inside the shoulder: the zone is the focus and
        // its shoulder less the NaN pixel, at 5 % of the focal maximum.
        let mut image = Array2::zeros((40, 40));
        image[[20, 20]] = 0.6;
        image[[21, 20]] = 0.3;
        image[[19, 20]] = f64::NAN;
        image[[2, 2]] = 3.0;
        image[[3, 2]] = 2.0;
        let region = Array2::from_shape_fn((40, 40), |(i, j)| (i as f64 - 20.0).hypot(j as f64 - 20.0) < 10.0);
        assert_eq!(mask_pixels(&image, 0.05, &region), vec![(20, 20), (21, 20)]);
    }
}
