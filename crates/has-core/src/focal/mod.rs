//! Results at the target: the focal peak of a pressure map near the target, and any hotter place
//! elsewhere (a skull, scalp or the water in front of a head is never reported as the focus).
//!
//! The focal peak is the local maximum of |p| reached by climbing from the target's sample (steepest
//! ascent over the 3ⁿ - 1 neighbours of an n-dimensional map): the lobe the target lies in, not
//! the hottest sample of the map. Its -6 dB region is the set of samples at or above half of it
//! connected to it through faces; the hottest sample outside that region is reported only when it
//! is hotter than the focal peak.

mod metrics;

pub use metrics::FocalMetrics;
pub(crate) use metrics::{exposure, focal_window, FocalBox, Shortfall};

use ndarray::{ArrayD, ArrayViewD, Dimension, IxDyn};

/// The local maximum reached from `start` by steepest ascent over the neighbours (8 in 2-D, 2 in
/// 1-D, 26 in 3-D) of a non-negative map; among equal neighbours the first in row-major offset
/// order.
pub fn climb(values: &ArrayViewD<'_, f64>, start: &[usize]) -> Vec<usize> {
    let shape = values.shape();
    let offsets = neighbour_offsets(shape.len());
    let mut pos = start.to_vec();
    loop {
        let (mut best, mut best_value) = (pos.clone(), values[IxDyn(&pos)]);
        for o in &offsets {
            if let Some(q) = moved(&pos, o, shape) {
                let v = values[IxDyn(&q)];
                if v > best_value {
                    (best, best_value) = (q, v);
                }
            }
        }
        if best == pos {
            return pos;
        }
        pos = best;
    }
}

/// Every offset in {-1, 0, 1}ⁿ but zero, in row-major order (the last axis fastest).
fn neighbour_offsets(ndim: usize) -> Vec<Vec<isize>> {
    (0..3usize.pow(ndim as u32))
        .map(|k| (0..ndim).rev().map(|axis| (k / 3usize.pow(axis as u32) % 3) as isize - 1).collect::<Vec<_>>())
        .filter(|o| o.iter().any(|&d| d != 0))
        .collect()
}

/// `pos + offset` when it lies inside `shape`.
fn moved(pos: &[usize], offset: &[isize], shape: &[usize]) -> Option<Vec<usize>> {
    pos.iter().zip(offset).zip(shape).map(|((&p, &d), &n)| p.checked_add_signed(d).filter(|&q| q < n)).collect()
}

/// The samples at or above half of `values[peak]` connected to the peak through faces.
pub fn region_6db(values: &ArrayViewD<'_, f64>, peak: &[usize]) -> ArrayD<bool> {
    connected_region(values, peak, 0.5 * values[IxDyn(peak)])
}

/// The samples at or above `level` connected to `start` through faces (a flood fill; empty when
/// `start` is below `level`).
pub fn connected_region(values: &ArrayViewD<'_, f64>, start: &[usize], level: f64) -> ArrayD<bool> {
    let shape = values.shape();
    let mut inside = ArrayD::from_elem(IxDyn(shape), false);
    let first = values[IxDyn(start)];
    if first.is_nan() || first < level {
        return inside;
    }
    inside[IxDyn(start)] = true;
    let mut stack = vec![start.to_vec()];
    while let Some(p) = stack.pop() {
        for axis in 0..shape.len() {
            for step in [-1isize, 1] {
                let mut offset = vec![0; shape.len()];
                offset[axis] = step;
                if let Some(q) = moved(&p, &offset, shape) {
                    if !inside[IxDyn(&q)] && values[IxDyn(&q)] >= level {
                        inside[IxDyn(&q)] = true;
                        stack.push(q);
                    }
                }
            }
        }
    }
    inside
}

/// The focal peak climbing from `start`, and the hottest sample outside its -6 dB region when it
/// is hotter than the peak (the first in row-major order among equals).
pub fn focal_and_hottest(values: &ArrayViewD<'_, f64>, start: &[usize]) -> (Vec<usize>, Option<Vec<usize>>) {
    let peak = climb(values, start);
    let region = region_6db(values, &peak);
    let mut hottest: Option<(Vec<usize>, f64)> = None;
    for ((index, &v), &inside) in values.indexed_iter().zip(region.iter()) {
        if !inside && hottest.as_ref().map_or(true, |h| v > h.1) {
            hottest = Some((index.slice().to_vec(), v));
        }
    }
    let peak_value = values[IxDyn(&peak)];
    (peak, hottest.filter(|h| h.1 > peak_value).map(|h| h.0))
}

/// A focal peak (Pa) and where it lies (m), and a hotter place elsewhere if there is one.
#[derive(Debug, Clone, PartialEq)]
pub struct Peak<const N: usize> {
    /// |p| at the focal peak, Pa.
    pub pressure: f64,
    /// Its position, m.
    pub position: [f64; N],
    /// |p| and position of the hottest sample outside the peak's -6 dB region, when hotter.
    pub hottest: Option<(f64, [f64; N])>,
}

impl<const N: usize> Peak<N> {
    /// The focal peak of the map `values` climbing from `start`, and the hottest place outside its
    /// -6 dB region when hotter ([`focal_and_hottest`]), each placed by `at` (index to m).
    pub fn climbing(values: &ArrayViewD<'_, f64>, start: &[usize], at: impl Fn(&[usize]) -> [f64; N]) -> Self {
        let (peak, hot) = focal_and_hottest(values, start);
        Peak { pressure: values[IxDyn(&peak)], position: at(&peak), hottest: hot.map(|h| (values[IxDyn(&h)], at(&h))) }
    }
}

/// The index of the sample of `coords` nearest `at` (the first of equals).
pub(crate) fn nearest(coords: &[f64], at: f64) -> usize {
    let mut best = 0;
    for (i, c) in coords.iter().enumerate() {
        if (c - at).abs() < (coords[best] - at).abs() {
            best = i;
        }
    }
    best
}

/// What a field says at its target: the focal peak on its plane near the axis's point there, and
/// along the beam's axis near the target's depth (see the module's documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct FieldFocus {
    /// The steering target (m, transducer frame).
    pub target: [f64; 3],
    /// The point of the beam's axis (the line from the origin through the target) on the plane,
    /// x and y (m).
    pub axis_point: [f64; 2],
    /// On the plane: position x, y (m).
    pub plane: Peak<2>,
    /// Along the axis: position x, y, z (m).
    pub axis: Peak<3>,
}

impl FieldFocus {
    /// Distance (m) in the plane from the axis's point to the plane's focal peak.
    pub fn peak_to_axis(&self) -> f64 {
        (self.plane.position[0] - self.axis_point[0]).hypot(self.plane.position[1] - self.axis_point[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// |p| of Gaussian spots (amplitude, x, y, width) on the grid `x` by `y`, shape (ny, nx).
    fn spots(x: &[f64], y: &[f64], spots: &[(f64, f64, f64, f64)]) -> Array2<f64> {
        Array2::from_shape_fn((y.len(), x.len()), |(j, i)| {
            spots.iter().map(|&(a, cx, cy, w)| a * (-((x[i] - cx).powi(2) + (y[j] - cy).powi(2)) / (2.0 * w * w)).exp()).sum()
        })
    }

    #[test]
    fn the_focal_peak_is_the_lobe_at_the_start_and_a_hotter_place_is_named_apart() {
        // A focus of 0.3 MPa at (10.5, -1), a hotter spot of 0.6 MPa at (-60, -30), on a 0.5 grid.
        let x: Vec<f64> = (0..321).map(|i| -80.0 + 0.5 * i as f64).collect();
        let map = spots(&x, &x, &[(0.3e6, 10.5, -1.0, 2.0), (0.6e6, -60.0, -30.0, 3.0)]).into_dyn();
        let start = [nearest(&x, 0.0), nearest(&x, 10.0)];
        let (peak, hot) = focal_and_hottest(&map.view(), &start);
        assert_eq!([x[peak[1]], x[peak[0]]], [10.5, -1.0]);
        let hot = hot.expect("the hotter spot");
        assert_eq!([x[hot[1]], x[hot[0]]], [-60.0, -30.0]);
        // Without the hot spot nothing else is reported: the focus's own -6 dB lobe is excluded.
        let map = spots(&x, &x, &[(0.3e6, 10.5, -1.0, 2.0)]).into_dyn();
        assert_eq!(focal_and_hottest(&map.view(), &start).1, None);
    }

    #[test]
    fn along_a_line_the_peak_before_the_focus_is_not_the_focus() {
        let z: Vec<f64> = (0..400).map(|k| 0.5 * k as f64).collect();
        let line: Vec<f64> =
            z.iter().map(|&z| 0.2e6 * (-((z - 138.0) / 6.0).powi(2)).exp() + 1.0e6 * (-((z - 90.0) / 1.5).powi(2)).exp()).collect();
        let line = ArrayD::from_shape_vec(IxDyn(&[z.len()]), line).unwrap();
        let (peak, hot) = focal_and_hottest(&line.view(), &[nearest(&z, 140.0)]);
        assert_eq!((z[peak[0]], hot.map(|h| z[h[0]])), (138.0, Some(90.0)));
    }

    #[test]
    fn in_three_dimensions_the_climb_crosses_diagonals_and_the_region_stays_connected() {
        // A 3-D Gaussian lobe at (6, 5, 7) on a 12³ grid and a hotter one at (1, 1, 1): the climb
        // from (3, 3, 3) ends at the lobe, the region holds the lobe's samples above half its peak.
        let map = ArrayD::from_shape_fn(IxDyn(&[12, 12, 12]), |i| {
            let g = |c: [f64; 3], w: f64| {
                (-((i[0] as f64 - c[0]).powi(2) + (i[1] as f64 - c[1]).powi(2) + (i[2] as f64 - c[2]).powi(2)) / (2.0 * w * w)).exp()
            };
            g([6.0, 5.0, 7.0], 1.5) + 2.0 * g([1.0, 1.0, 1.0], 0.6)
        });
        let (peak, hot) = focal_and_hottest(&map.view(), &[3, 3, 3]);
        assert_eq!((peak, hot), (vec![6, 5, 7], Some(vec![1, 1, 1])));
        let region = region_6db(&map.view(), &[6, 5, 7]);
        // exp(-r²/(2·1.5²)) >= 1/2 for r² <= 3.12: the 1 + 6 + 12 samples within r² <= 2 (r² = 3
        // too: its 8 corners), and the hot lobe (below half of the peak between them) outside.
        assert_eq!(region.iter().filter(|&&v| v).count(), 1 + 6 + 12 + 8);
        assert!(!region[IxDyn(&[1, 1, 1])]);
    }

    #[test]
    fn a_connected_region_holds_what_touches_its_start_through_faces() {
        // Two blocks above the level touching only at a corner (2-D: faces are edges), and a NaN:
        // the region from one holds its 4 samples alone; from a sample below the level or NaN,
        // nothing.
        let mut map = ArrayD::from_elem(IxDyn(&[5, 5]), 0.0);
        for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1), (2, 2), (2, 3), (3, 2)] {
            map[IxDyn(&[i, j])] = 1.0;
        }
        map[IxDyn(&[4, 4])] = f64::NAN;
        let region = connected_region(&map.view(), &[1, 1], 0.5);
        assert_eq!(region.iter().filter(|&&v| v).count(), 4);
        assert!(region[IxDyn(&[0, 0])] && !region[IxDyn(&[2, 2])]);
        assert_eq!(connected_region(&map.view(), &[3, 2], 0.5).iter().filter(|&&v| v).count(), 3);
        assert!(!connected_region(&map.view(), &[4, 0], 0.5).iter().any(|&v| v));
        assert!(!connected_region(&map.view(), &[4, 4], 0.5).iter().any(|&v| v));
    }
}
