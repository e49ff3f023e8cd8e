//! Focal metrics of a beam in 3-D: the focal peak near the target with its sub-voxel position, the
//! -3 dB and -6 dB extents along the beam and across it, the -6 dB volume, and the exposure at the
//! peak (in-situ pressure, I_SPPA, mechanical index) with the tissue it lies in.
//!
//! The peak is the local maximum of |p| reached by climbing from the target's voxel (see
//! [`super::climb`]); its position and value are refined by a parabola through it and its two
//! neighbours along each axis. An extent is the distance between the two points where |p|,
//! trilinearly interpolated along a line through the refined peak, falls to 1/2 (-6 dB) or 1/√2
//! (-3 dB) of its interpolated value there. The -6 dB volume counts the voxels of the peak's -6 dB
//! region ([`super::region_6db`]) and, on its surface, the fraction of each voxel where the
//! interpolated |p| is above the level. I_SPPA = p²/(2·ρ·c) with ρ and c at the peak; MI = p/√f (p in MPa, f in MHz)
//! (in situ, no derating: the simulation is of the tissue itself).

use super::{climb, region_6db};
use crate::numeric::{parabola, unit};
use crate::physics::grid::Grid;
use crate::physics::propagation::Window;
use ndarray::{Array3, ArrayD, IxDyn};

/// Metrics of the focal region of one beam; lengths in m, pressures in Pa.
#[derive(Debug, Clone, PartialEq)]
pub struct FocalMetrics {
    /// The steering target (m).
    pub target: [f64; 3],
    /// The focal peak, sub-voxel (m).
    pub peak: [f64; 3],
    /// |p| at the focal peak (Pa), refined with the peak's position.
    pub peak_pressure: f64,
    /// The -6 dB extent along the beam (the line from the array's centre through the target) and
    /// across it: the mean of the two extents in [`FocalMetrics::across_6db`] (m).
    pub fwhm_6db: [f64; 2],
    /// The -6 dB extents across the beam: along the direction nearest x, then nearest y (m).
    pub across_6db: [f64; 2],
    /// The -3 dB extent along the beam and across it (the mean of the two directions) (m).
    pub fwhm_3db: [f64; 2],
    /// Volume of the -6 dB region (m³).
    pub volume_6db: f64,
    /// Spatial-peak pulse-average intensity at the peak, p²/(2·ρ·c) (W/m²).
    pub isppa: f64,
    /// Mechanical index at the peak, p/√f with p in MPa and f in MHz.
    pub mechanical_index: f64,
    /// The tissue the peak lies in, by class as the hottest places name them: `skull` for bone,
    /// `scalp` for the target's tissue beyond bone, else the medium's name for it.
    pub tissue: String,
}

impl FocalMetrics {
    /// Distance from the target to the focal peak (m).
    pub fn peak_to_target(&self) -> f64 {
        (0..3).map(|k| (self.peak[k] - self.target[k]).powi(2)).sum::<f64>().sqrt()
    }
}

/// |p| recorded on a box of the grid, index `[plane, row, column]`.
pub(crate) struct FocalBox<'a> {
    pub(crate) grid: &'a Grid,
    pub(crate) window: &'a Window,
    pub(crate) magnitude: Array3<f64>,
}

/// Why a box cannot give the metrics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Shortfall {
    /// The -6 dB region or an extent reaches a face of the box inside the grid: a larger box is
    /// needed.
    TooSmall,
    /// No pressure at the target's lobe (or the region reaches the grid's own edge).
    NoFocus,
}

/// The exposure at a pressure amplitude `pressure` (Pa) in a medium of `density` (kg/m³) and
/// `sound_speed` (m/s) at `frequency` (Hz): I_SPPA `p² / (2·ρ·c)` (W/m²) and the mechanical index
/// `p[MPa] / √f[MHz]` (in situ).
pub(crate) fn exposure(pressure: f64, density: f64, sound_speed: f64, frequency: f64) -> (f64, f64) {
    (pressure * pressure / (2.0 * density * sound_speed), pressure * 1e-6 / (frequency * 1e-6).sqrt())
}

/// The properties the metrics need at the peak: density (kg/m³), sound speed (m/s), tissue name.
pub(crate) type PeakTissue = (f64, f64, String);

impl FocalBox<'_> {
    /// Position (m) of a fractional box index `[plane, row, column]`.
    fn position(&self, f: [f64; 3]) -> [f64; 3] {
        let (g, w) = (self.grid, self.window);
        [g.x(w.cols.start) + f[2] * g.dx, g.y(w.rows.start) + f[1] * g.dy, g.z(w.planes.start) + f[0] * g.dz]
    }

    /// The fractional box index of a position (m).
    fn index_of(&self, p: [f64; 3]) -> [f64; 3] {
        let (g, w) = (self.grid, self.window);
        [(p[2] - g.z(w.planes.start)) / g.dz, (p[1] - g.y(w.rows.start)) / g.dy, (p[0] - g.x(w.cols.start)) / g.dx]
    }

    /// |p| trilinearly interpolated at a fractional box index; `None` outside the box.
    fn sample(&self, f: [f64; 3]) -> Option<f64> {
        let shape = self.magnitude.shape();
        let mut base = [0usize; 3];
        let mut frac = [0.0; 3];
        for k in 0..3 {
            let last = (shape[k] - 1) as f64;
            if !(f[k] >= 0.0 && f[k] <= last) {
                return None;
            }
            let b = f[k].floor().min((last - 1.0).max(0.0));
            base[k] = b as usize;
            frac[k] = f[k] - b;
        }
        let mut v = 0.0;
        for corner in 0..8 {
            let mut w = 1.0;
            let mut at = [0usize; 3];
            for k in 0..3 {
                let up = (corner >> k) & 1 == 1;
                at[k] = (base[k] + usize::from(up)).min(shape[k] - 1);
                w *= if up { frac[k] } else { 1.0 - frac[k] };
            }
            if w > 0.0 {
                v += w * self.magnitude[at];
            }
        }
        Some(v)
    }

    /// The peak index refined by a parabola through it and its two neighbours along each axis
    /// (where it opens downwards): the fractional index, and |p| there as the peak's value plus
    /// each axis's rise to its vertex. The peak is a local maximum, so each vertex lies within
    /// half a sample of it.
    fn refined(&self, peak: [usize; 3]) -> ([f64; 3], f64) {
        let m = &self.magnitude;
        let v0 = m[peak];
        let mut f = peak.map(|i| i as f64);
        let mut value = v0;
        for k in 0..3 {
            if peak[k] == 0 || peak[k] + 1 >= m.shape()[k] {
                continue;
            }
            let (mut lo, mut hi) = (peak, peak);
            lo[k] -= 1;
            hi[k] += 1;
            if let Some(p) = parabola([(-1.0, m[lo]), (0.0, v0), (1.0, m[hi])]).filter(|p| p.curvature < 0.0) {
                f[k] += p.vertex;
                value += p.value - v0;
            }
        }
        (f, value)
    }

    /// The distance between the two points where |p| falls below `level` on the line through
    /// `from` (m) along the unit vector `u`; `None` when the line leaves the box first.
    fn extent(&self, from: [f64; 3], u: [f64; 3], level: f64) -> Option<f64> {
        let h = 0.05 * self.grid.dx.min(self.grid.dy).min(self.grid.dz);
        let crossing = |sign: f64| -> Option<f64> {
            let at = |t: f64| self.sample(self.index_of([0, 1, 2].map(|k| from[k] + sign * t * u[k])));
            let (mut t, mut before) = (0.0, at(0.0)?);
            loop {
                let next = at(t + h)?;
                if next < level {
                    // Linear between the last sample above the level and the first below it.
                    return Some(t + h * (before - level) / (before - next));
                }
                (t, before) = (t + h, next);
            }
        };
        Some(crossing(1.0)? + crossing(-1.0)?)
    }

    /// The metrics of the box for the beam steered to `target` (m) at `frequency` (Hz); `tissue`
    /// gives the properties at a point. `along` is the beam's direction (unit vector).
    pub(crate) fn metrics(
        &self,
        target: [f64; 3],
        along: [f64; 3],
        frequency: f64,
        tissue: impl Fn([f64; 3]) -> PeakTissue,
    ) -> std::result::Result<FocalMetrics, Shortfall> {
        let g = self.grid;
        let start = self.index_of(target).map(|f| f.round().max(0.0) as usize);
        let shape = self.magnitude.shape().to_vec();
        let start: Vec<usize> = (0..3).map(|k| start[k].min(shape[k] - 1)).collect();
        let dynamic = self.magnitude.view().into_dyn();
        let peak = climb(&dynamic, &start);
        if !(dynamic[IxDyn(&peak)] > 0.0) {
            return Err(Shortfall::NoFocus);
        }
        let region = region_6db(&dynamic, &peak);
        self.check_inside(&region)?;
        let (f, peak_pressure) = self.refined([peak[0], peak[1], peak[2]]);
        let position = self.position(f);
        let [u, v] = across(along);
        // The levels are relative to the interpolated |p| at the refined peak (not the parabola's
        // value): the interpolation across a line then scales the line and its level alike.
        let top = self.sample(f).ok_or(Shortfall::TooSmall)?;
        let extents = |level: f64| -> std::result::Result<[f64; 3], Shortfall> {
            let e = |d: [f64; 3]| self.extent(position, d, level * top).ok_or(Shortfall::TooSmall);
            Ok([e(along)?, e(u)?, e(v)?])
        };
        let six = extents(0.5)?;
        let three = extents(std::f64::consts::FRAC_1_SQRT_2)?;
        let (density, sound_speed, name) = tissue(position);
        let (isppa, mechanical_index) = exposure(peak_pressure, density, sound_speed, frequency);
        let voxels = self.region_voxels(&region, 0.5 * peak_pressure);
        Ok(FocalMetrics {
            target,
            peak: position,
            peak_pressure,
            fwhm_6db: [six[0], 0.5 * (six[1] + six[2])],
            across_6db: [six[1], six[2]],
            fwhm_3db: [three[0], 0.5 * (three[1] + three[2])],
            volume_6db: voxels * g.dx * g.dy * g.dz,
            isppa,
            mechanical_index,
            tissue: name,
        })
    }

    /// The volume (in voxels) where |p| is at least `level` in and around `region`: a voxel of the
    /// region whose 26 neighbours are all in it counts whole; one on its surface, or next to it,
    /// counts the fraction of its 2 x 2 x 2 sub-samples (trilinear |p|) at or above the level.
    fn region_voxels(&self, region: &ArrayD<bool>, level: f64) -> f64 {
        const SUB: usize = 2;
        let region = region.view().into_dimensionality::<ndarray::Ix3>().expect("a box is 3-D");
        let shape = region.shape().to_vec();
        let inside = |i: [isize; 3]| (0..3).all(|k| i[k] >= 0 && (i[k] as usize) < shape[k]) && region[i.map(|v| v as usize)];
        // The bounding box of the region, one voxel wider on each side.
        let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
        for (index, _) in region.indexed_iter().filter(|(_, &v)| v) {
            let index = [index.0, index.1, index.2];
            for k in 0..3 {
                lo[k] = lo[k].min(index[k].saturating_sub(1));
                hi[k] = hi[k].max((index[k] + 2).min(shape[k]));
            }
        }
        let mut total = 0.0;
        for n in lo[0]..hi[0] {
            for j in lo[1]..hi[1] {
                for i in lo[2]..hi[2] {
                    let at = [n as isize, j as isize, i as isize];
                    let neighbours = (0..27).map(|k| [at[0] + k / 9 - 1, at[1] + (k / 3) % 3 - 1, at[2] + k % 3 - 1]);
                    let count = neighbours.filter(|&q| inside(q)).count();
                    if count == 27 {
                        total += 1.0;
                    } else if count > 0 {
                        let offset = |s: usize| (s as f64 + 0.5) / SUB as f64 - 0.5;
                        let hits = (0..SUB * SUB * SUB)
                            .filter(|&s| {
                                let f =
                                    [n as f64 + offset(s / (SUB * SUB)), j as f64 + offset((s / SUB) % SUB), i as f64 + offset(s % SUB)];
                                self.sample(f).is_some_and(|v| v >= level)
                            })
                            .count();
                        total += hits as f64 / (SUB * SUB * SUB) as f64;
                    }
                }
            }
        }
        total
    }

    /// `Err(TooSmall)` when the region reaches a face of the box that lies inside the grid,
    /// `Err(NoFocus)` when it reaches the grid's own edge (no closed focal region).
    fn check_inside(&self, region: &ArrayD<bool>) -> std::result::Result<(), Shortfall> {
        let (g, w) = (self.grid, self.window);
        let ranges = [(&w.planes, g.nz), (&w.rows, g.ny), (&w.cols, g.nx)];
        for (k, (range, n)) in ranges.into_iter().enumerate() {
            let len = region.shape()[k];
            for (face, at_grid_edge) in [(0, range.start == 0), (len - 1, range.end == n)] {
                if region.index_axis(ndarray::Axis(k), face).iter().any(|&v| v) {
                    return Err(if at_grid_edge { Shortfall::NoFocus } else { Shortfall::TooSmall });
                }
            }
        }
        Ok(())
    }
}

/// Two unit vectors across the beam direction `along`: the first nearest x, the second
/// completing a right-handed set (x and y for a beam along z).
fn across(along: [f64; 3]) -> [[f64; 3]; 2] {
    let cross = |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let u = unit(cross([0.0, 1.0, 0.0], along));
    [u, cross(along, u)]
}

/// The box around the target voxel `[i, j, n]` reaching `lateral` (m) sideways and `axial` (m)
/// along z, clipped to the grid.
pub(crate) fn focal_window(g: &Grid, target: [usize; 3], lateral: f64, axial: f64) -> Window {
    let range = |c: usize, reach: f64, d: f64, n: usize| {
        let r = (reach / d).ceil() as usize;
        c.saturating_sub(r)..(c + r + 1).min(n)
    };
    Window {
        cols: range(target[0], lateral, g.dx, g.nx),
        rows: range(target[1], lateral, g.dy, g.ny),
        planes: range(target[2], axial, g.dz, g.nz),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of |p| = p0·exp(-(x²+y²)/(2·s²) - (z - z0)²/(2·sz²)) on the grid `g`.
    fn gaussian(g: &Grid, w: &Window, p0: f64, centre: [f64; 3], s: f64, sz: f64) -> Array3<f64> {
        Array3::from_shape_fn((w.planes.len(), w.rows.len(), w.cols.len()), |(n, j, i)| {
            let (x, y, z) = (g.x(w.cols.start + i) - centre[0], g.y(w.rows.start + j) - centre[1], g.z(w.planes.start + n) - centre[2]);
            p0 * (-(x * x + y * y) / (2.0 * s * s) - z * z / (2.0 * sz * sz)).exp()
        })
    }

    #[test]
    fn a_gaussian_focus_gives_its_own_widths_position_volume_and_exposure() {
        // A Gaussian spot off the grid points: FWHM = 2·√(2 ln 2)·s at -6 dB, 2·√(ln 2)·s at -3 dB
        // (of the amplitude); the -6 dB region is an ellipsoid of semi-axes √(2 ln 2)·(s, s, sz).
        let g = Grid::new(64, 64, 0.5e-3, 0.5e-3, 200, 0.5e-3, 0.0).unwrap();
        let centre = [0.13e-3, -0.21e-3, 60.17e-3];
        let (s, sz) = (1.5e-3, 6e-3);
        let target = [0.0, 0.0, 60e-3];
        let t = g.nearest(target).unwrap();
        let w = focal_window(&g, t, 10e-3, 30e-3);
        let b = FocalBox { grid: &g, window: &w, magnitude: gaussian(&g, &w, 1.2e6, centre, s, sz) };
        let m = b.metrics(target, [0.0, 0.0, 1.0], 0.5e6, |_| (1000.0, 1500.0, "water".into())).unwrap();
        // The parabola through three samples of a Gaussian 0.5 mm apart (a third of s) places its
        // peak to within 2 % of the spacing and its value to 0.1 %.
        for k in 0..3 {
            assert!((m.peak[k] - centre[k]).abs() < 0.01e-3, "{k}: {:?} vs {centre:?}", m.peak);
        }
        assert!((m.peak_pressure / 1.2e6 - 1.0).abs() < 1e-3, "{}", m.peak_pressure);
        let six = 2.0 * (2.0 * 2f64.ln()).sqrt();
        let three = 2.0 * 2f64.ln().sqrt();
        // Along the beam the samples are a twelfth of sz apart: within 0.5 %. Across, a third of s:
        // a straight line between samples near the half level overestimates the convex flank by
        // about 1 % of the width; within 2 %.
        assert!((m.fwhm_6db[0] / (six * sz) - 1.0).abs() < 0.005 && (m.fwhm_6db[1] / (six * s) - 1.0).abs() < 0.02, "{:?}", m.fwhm_6db);
        assert!((m.fwhm_3db[0] / (three * sz) - 1.0).abs() < 0.005 && (m.fwhm_3db[1] / (three * s) - 1.0).abs() < 0.02, "{:?}", m.fwhm_3db);
        assert_eq!(m.fwhm_6db[1], 0.5 * (m.across_6db[0] + m.across_6db[1]));
        // The ellipsoid is about 740 voxels, its surface sub-sampled on trilinear |p| between samples
        // a third of s apart (2 % below seen): within 3 %.
        let ellipsoid = 4.0 / 3.0 * std::f64::consts::PI * (2.0 * 2f64.ln()).powf(1.5) * s * s * sz;
        assert!((m.volume_6db / ellipsoid - 1.0).abs() < 0.03, "{} vs {ellipsoid}", m.volume_6db);
        // By hand: 1.2 MPa in water at 0.5 MHz: I = (1.2e6)²/(2·1000·1500) = 480 kW/m² = 48 W/cm²;
        // MI = 1.2/√0.5 = 1.697 (within the 0.1 % of the peak's value, doubled for I).
        assert!((m.isppa / 480e3 - 1.0).abs() < 2e-3 && (m.mechanical_index / (1.2 / 0.5f64.sqrt()) - 1.0).abs() < 1e-3);
        let p = m.peak_pressure;
        assert_eq!((m.isppa, m.mechanical_index), (p * p / (2.0 * 1000.0 * 1500.0), p * 1e-6 / 0.5f64.sqrt()));
        assert!((m.peak_to_target() - 0.3e-3).abs() < 0.02e-3);
    }

    #[test]
    fn a_box_that_cuts_the_focal_region_asks_for_a_larger_one() {
        let g = Grid::new(64, 64, 0.5e-3, 0.5e-3, 200, 0.5e-3, 0.0).unwrap();
        let target = [0.0, 0.0, 60e-3];
        let w = focal_window(&g, g.nearest(target).unwrap(), 10e-3, 5e-3);
        let b = FocalBox { grid: &g, window: &w, magnitude: gaussian(&g, &w, 1e6, target, 1.5e-3, 6e-3) };
        assert_eq!(b.metrics(target, [0.0, 0.0, 1.0], 0.5e6, |_| (1000.0, 1500.0, "water".into())), Err(Shortfall::TooSmall));
    }
}
