//! What a march keeps: the planes, the axis, boxes and the power asked for ([`RecordSpec`]), and
//! the recorder that adds each sweep's pressure to them.
//!
//! The march carries the flux-normalised field `ψ = p·sqrt(Z_s/Z)` (see [`super::interface`]);
//! the recorder turns it into pressure. Recorded values are the total pressure on the plane: at
//! an interface plane, the side before the interface (incident forward wave plus the backward
//! wave leaving it), which equals the side after it by pressure continuity. Where the march
//! carries shear (`elastic.rs`) only `ψ`, the compressional wave, is recorded.

use super::march::{double, Real};
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::{Complex, Complex64 as C64};
use std::ops::Range;

/// What to keep while marching.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordSpec {
    /// Planes to keep whole, `(ny, nx)` each (in increasing plane order).
    pub planes: Vec<usize>,
    /// Keep a sample of every plane on the beam's axis: the line through the origin (the array's
    /// centre) `x = axis_slope[0]·z`, `y = axis_slope[1]·z`, bilinearly interpolated between
    /// pixels (on the pixel `nx/2`, `ny/2` for a zero slope: the z axis).
    pub axis: bool,
    /// Lateral offset per unit depth (dx/dz, dy/dz) of the recorded axis (see `axis`).
    pub axis_slope: [f64; 2],
    /// Keep a box of samples: planes × rows × columns.
    pub window: Option<Window>,
    /// Keep `|p|` on a box in single precision ([`Recording::magnitude`]): 8 bytes a sample
    /// while marching (the complex sum), 4 after, where `window` takes 16.
    pub magnitude: Option<Window>,
    /// Keep the power `∫ |p|² / (2·Z) dA` (W) of the forward wave through every plane (inside a
    /// reverberating layer: of its first pass; inside a solid: of its compressional wave).
    pub power: bool,
    /// Add the waves reflected back towards the source at changes of impedance (single
    /// reflections, plus what leaves a reverberating layer backwards). The forward march then
    /// runs to the last plane, so reflections from deeper interfaces count.
    pub reflections: bool,
}

/// A box of the grid: plane indices, rows (y) and columns (x).
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// Plane indices n (along z).
    pub planes: Range<usize>,
    /// Row indices j (along y).
    pub rows: Range<usize>,
    /// Column indices i (along x).
    pub cols: Range<usize>,
}

impl Window {
    /// Every sample of `g`.
    pub fn whole(g: &Grid) -> Self {
        Window { planes: 0..g.nz, rows: 0..g.ny, cols: 0..g.nx }
    }
    /// Number of samples in the box.
    pub fn len(&self) -> usize {
        self.planes.len() * self.rows.len() * self.cols.len()
    }
    /// Whether the box is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The samples of `sub` (a box inside this one) out of `data` recorded on this box.
    pub fn extract<T: Copy>(&self, data: &[T], sub: &Window) -> Vec<T> {
        let (nr, nc) = (self.rows.len(), self.cols.len());
        let mut out = Vec::with_capacity(sub.len());
        for n in sub.planes.clone() {
            for r in sub.rows.clone() {
                let base = ((n - self.planes.start) * nr + (r - self.rows.start)) * nc;
                out.extend_from_slice(&data[base + sub.cols.start - self.cols.start..base + sub.cols.end - self.cols.start]);
            }
        }
        out
    }
}

/// What was kept (see [`RecordSpec`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    /// Complex pressure (Pa) of the planes asked for, `(ny, nx)` each, in increasing plane order
    /// (duplicates kept once).
    pub planes: Vec<Vec<C64>>,
    /// On-axis complex pressure (Pa), one per plane from 0 to the last one marched.
    pub axis: Vec<C64>,
    /// Window complex pressure (Pa), row-major (plane, row, column).
    pub window: Vec<C64>,
    /// `|p|` (Pa) on the `magnitude` box, row-major (plane, row, column), single precision.
    pub magnitude: Vec<f32>,
    /// Power of the forward wave (W), one per plane from 0 to the last one marched.
    pub power: Vec<f64>,
}

impl RecordSpec {
    /// Whether nothing is to be kept (a march for it would be wasted).
    pub fn records_nothing(&self) -> bool {
        self.planes.is_empty() && !self.axis && self.window.is_none() && self.magnitude.is_none() && !self.power
    }

    pub(super) fn last_plane(&self, nz: usize) -> usize {
        let mut last = self.planes.iter().copied().max().unwrap_or(0);
        for w in self.window.iter().chain(&self.magnitude) {
            last = last.max(w.planes.end.saturating_sub(1));
        }
        if self.axis || self.power || self.reflections {
            last = nz - 1;
        }
        last
    }
}

/// The field on one plane (`(ny, nx)`, sample `i` given by `field(i)`) at lateral position
/// (x, y) (m), bilinearly interpolated between the four pixels around it (exactly a pixel's
/// value on it); zero outside the grid.
pub(crate) fn bilinear(g: &Grid, field: impl Fn(usize) -> C64, x: f64, y: f64) -> C64 {
    let (u, v) = (x / g.dx + (g.nx / 2) as f64, y / g.dy + (g.ny / 2) as f64);
    let (i0, j0) = (u.floor(), v.floor());
    let (fu, fv) = (u - i0, v - j0);
    let at = |i: f64, j: f64| {
        if i < 0.0 || j < 0.0 || i >= g.nx as f64 || j >= g.ny as f64 {
            C64::new(0.0, 0.0)
        } else {
            field(j as usize * g.nx + i as usize)
        }
    };
    let row = |j: f64| at(i0, j) * (1.0 - fu) + if fu > 0.0 { at(i0 + 1.0, j) * fu } else { C64::new(0.0, 0.0) };
    row(j0) * (1.0 - fv) + if fv > 0.0 { row(j0 + 1.0) * fv } else { C64::new(0.0, 0.0) }
}

/// Adds each sweep's contribution to the recording (planes beyond `last` are not kept).
pub(super) struct Recorder<'a> {
    grid: &'a Grid,
    spec: &'a RecordSpec,
    planes: Vec<usize>,
    last: usize,
    rec: Recording,
    /// The complex pressure on the `magnitude` box as (re, im) pairs in single precision,
    /// made `|p|` in place by [`Recorder::finish`].
    magnitude: Vec<f32>,
}

impl<'a> Recorder<'a> {
    pub(super) fn new(grid: &'a Grid, spec: &'a RecordSpec, last: usize) -> Self {
        let mut planes = spec.planes.clone();
        planes.sort_unstable();
        planes.dedup();
        let zero = C64::new(0.0, 0.0);
        let rec = Recording {
            planes: vec![vec![zero; grid.lateral_len()]; planes.len()],
            axis: if spec.axis { vec![zero; last + 1] } else { Vec::new() },
            window: vec![zero; spec.window.as_ref().map_or(0, Window::len)],
            magnitude: Vec::new(),
            power: if spec.power { vec![0.0; last + 1] } else { Vec::new() },
        };
        let magnitude = vec![0.0; 2 * spec.magnitude.as_ref().map_or(0, Window::len)];
        Recorder { grid, spec, planes, last, rec, magnitude }
    }

    /// What was recorded: the magnitude box's pairs (re, im) become `|p|` in place, sample `i`
    /// written over pair `i/2`'s half (at or before the pair it reads, so never over an unread
    /// one), and the second half is released.
    pub(super) fn finish(mut self) -> Recording {
        let mut m = std::mem::take(&mut self.magnitude);
        let n = m.len() / 2;
        for i in 0..n {
            // Squares of pressures (< 1e19 Pa²) stay far inside single precision's range.
            m[i] = (m[2 * i] * m[2 * i] + m[2 * i + 1] * m[2 * i + 1]).sqrt();
        }
        m.truncate(n);
        m.shrink_to_fit();
        self.rec.magnitude = m;
        self.rec
    }

    /// Adds `field` (the flux-normalised field `ψ` of one wave on plane `n`, in the medium
    /// `before`) as pressure `p = ψ·sqrt(Z/Z_s)` (`Z_s` of the `source` medium).
    pub(super) fn add<T: Real>(&mut self, n: usize, field: &[Complex<T>], before: &SliceProperties, source: &SliceProperties) {
        let g = self.grid;
        if n > self.last {
            return;
        }
        let same = std::ptr::eq(before, source);
        let pressure = |i: usize| {
            let v = double(field[i]);
            if same {
                v
            } else {
                v * pressure_scale(before, source, i)
            }
        };
        if let Ok(k) = self.planes.binary_search(&n) {
            self.rec.planes[k].iter_mut().enumerate().for_each(|(i, a)| *a += pressure(i));
        }
        if self.spec.axis {
            let z = g.z(n);
            self.rec.axis[n] += bilinear(g, pressure, self.spec.axis_slope[0] * z, self.spec.axis_slope[1] * z);
        }
        if let Some(w) = self.spec.window.as_ref().filter(|w| w.planes.contains(&n)) {
            let (nr, nc) = (w.rows.len(), w.cols.len());
            for (k, r) in w.rows.clone().enumerate() {
                let base = ((n - w.planes.start) * nr + k) * nc;
                self.rec.window[base..base + nc]
                    .iter_mut()
                    .zip(r * g.nx + w.cols.start..r * g.nx + w.cols.end)
                    .for_each(|(a, i)| *a += pressure(i));
            }
        }
        if let Some(w) = self.spec.magnitude.as_ref().filter(|w| w.planes.contains(&n)) {
            let (nr, nc) = (w.rows.len(), w.cols.len());
            for (k, r) in w.rows.clone().enumerate() {
                let base = 2 * ((n - w.planes.start) * nr + k) * nc;
                self.magnitude[base..base + 2 * nc].chunks_exact_mut(2).zip(r * g.nx + w.cols.start..r * g.nx + w.cols.end).for_each(
                    |(a, i)| {
                        let p = pressure(i);
                        a[0] += p.re as f32;
                        a[1] += p.im as f32;
                    },
                );
            }
        }
    }

    /// Adds what `other` (a recorder of the same spec) recorded.
    pub(super) fn absorb(&mut self, other: Recorder) {
        let (rec, more) = (&mut self.rec, other.rec);
        rec.planes.iter_mut().zip(&more.planes).for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(a, b)| *a += b));
        rec.axis.iter_mut().zip(&more.axis).for_each(|(a, b)| *a += b);
        rec.window.iter_mut().zip(&more.window).for_each(|(a, b)| *a += b);
        self.magnitude.iter_mut().zip(&other.magnitude).for_each(|(a, b)| *a += b);
        rec.power.iter_mut().zip(&more.power).for_each(|(a, b)| *a += b);
    }

    /// Sets the power `Σ |ψ|²/(2·Z_s)·dA` of the forward wave `field` through plane `n` (`Z_s` of
    /// the `source` medium: `|ψ|²/Z_s = |p|²/Z`).
    pub(super) fn power<T: Real>(&mut self, n: usize, source: &SliceProperties, field: &[Complex<T>]) {
        if self.spec.power && n <= self.last {
            let g = self.grid;
            let p: f64 = field
                .iter()
                .zip(&source.sound_speed)
                .zip(&source.density)
                .map(|((&v, c), rho)| double(v).norm_sqr() / (2.0 * rho * c))
                .sum();
            self.rec.power[n] = p * g.dx * g.dy;
        }
    }
}

/// `sqrt(Z/Z_s)` at pixel `i`: the pressure of a unit flux-normalised field in the medium
/// `before`, for the source medium `source`.
pub(super) fn pressure_scale(before: &SliceProperties, source: &SliceProperties, i: usize) -> f64 {
    ((before.density[i] * before.sound_speed[i]) / (source.density[i] * source.sound_speed[i])).sqrt()
}
