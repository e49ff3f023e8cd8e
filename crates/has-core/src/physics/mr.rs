//! The MR-ARFI forward model after the pressure field: radiation force, slab average over the
//! slice, Gaussian broadening (paper Eq. 2–3), area average onto MR pixels, amplitude, noise.
//!
//! Radiation force density (paper Eq. 1) with the plane-wave intensity `I = |p|² / (2·rho·c)`:
//! `F = 2·alpha·I / c = alpha·|p|² / (rho·c²)` (N/m³), weighted by each tissue's displacement
//! scale (bone absorbs but does not move, [`crate::physics::tissue`]). Everything after `|p|²` is
//! linear, so the map from `|p|²` samples to the image is one fixed operator, [`MrSampler`].
//! Pixels without MR signal (mostly bone) are absent from images: NaN.

use crate::error::{require_non_negative, require_positive, HasError, Result};
use crate::physics::grid::Grid;
use crate::physics::medium::Medium;
use crate::physics::propagation::Window;
use crate::physics::tissue::IMAGED_FRACTION;
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::ops::Range;

/// Orientation of the MR slice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MrPlane {
    /// Perpendicular to the beam: image axes (x, y), slice along z.
    Xy,
    /// Containing the beam axis: image axes (x, z), slice along y.
    Xz,
    /// Containing the beam axis: image axes (y, z), slice along x.
    Yz,
}

impl MrPlane {
    /// Parses `"xy"`, `"xz"` or `"yz"`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "xy" => Ok(MrPlane::Xy),
            "xz" => Ok(MrPlane::Xz),
            "yz" => Ok(MrPlane::Yz),
            _ => Err(HasError::invalid("mr.plane", format!("must be \"xy\", \"xz\" or \"yz\", got \"{s}\""))),
        }
    }
    /// The name used in scenario files.
    pub fn name(&self) -> &'static str {
        match self {
            MrPlane::Xy => "xy",
            MrPlane::Xz => "xz",
            MrPlane::Yz => "yz",
        }
    }
    /// Frame axes (0 = x, 1 = y, 2 = z) of image axis u, image axis v and the slice normal.
    pub fn axes(&self) -> [usize; 3] {
        match self {
            MrPlane::Xy => [0, 1, 2],
            MrPlane::Xz => [0, 2, 1],
            MrPlane::Yz => [1, 2, 0],
        }
    }
}

/// The MR image geometry (metres). Pixel `(i, j)` is centred at
/// `center + (-fov/2 + (i + 0.5)·fov_u/n_u, -fov/2 + (j + 0.5)·fov_v/n_v)` along the image axes.
#[derive(Debug, Clone, PartialEq)]
pub struct MrGeometry {
    /// Orientation of the slice.
    pub plane: MrPlane,
    /// Centre of the slice in the transducer frame, m.
    pub center: [f64; 3],
    /// Field of view along image axes u and v, m.
    pub fov: [f64; 2],
    /// Pixels along u and v.
    pub matrix: [usize; 2],
    /// Slice thickness along the normal, m; the force is averaged over it (a boxcar profile).
    pub slice_thickness: f64,
}

impl MrGeometry {
    /// Checks sizes.
    pub fn validate(&self) -> Result<()> {
        require_positive("mr.fov_mm[0]", self.fov[0])?;
        require_positive("mr.fov_mm[1]", self.fov[1])?;
        require_positive("mr.slice_thickness_mm", self.slice_thickness)?;
        if self.matrix[0] == 0 || self.matrix[1] == 0 || self.matrix[0] * self.matrix[1] > 4096 * 4096 {
            return Err(HasError::invalid("mr.matrix", format!("must be positive and at most 4096 x 4096, got {:?}", self.matrix)));
        }
        if !self.center.iter().all(|c| c.is_finite()) {
            return Err(HasError::invalid("mr.center_mm", "must be finite"));
        }
        Ok(())
    }

    /// Pixel size along u and v (m).
    pub fn pixel_size(&self) -> [f64; 2] {
        [self.fov[0] / self.matrix[0] as f64, self.fov[1] / self.matrix[1] as f64]
    }

    /// Centre of pixel `i` along image axis `a` (0 = u, 1 = v), metres.
    pub fn pixel_center(&self, a: usize, i: usize) -> f64 {
        let ax = self.plane.axes()[a];
        self.center[ax] - 0.5 * self.fov[a] + (i as f64 + 0.5) * self.pixel_size()[a]
    }

    /// Shape of the 3-D NIfTI volume `(nx, ny, nz)`: the image with a singleton along the normal.
    pub fn volume_shape(&self) -> [usize; 3] {
        let mut s = [1; 3];
        let ax = self.plane.axes();
        s[ax[0]] = self.matrix[0];
        s[ax[1]] = self.matrix[1];
        s
    }

    /// Checks an image's shape (rows, columns) against the MR matrix; an error naming `name`.
    pub fn check_shape(&self, name: &str, shape: [usize; 2]) -> Result<()> {
        if shape != self.matrix {
            return Err(HasError::invalid(
                name,
                format!("has shape ({}, {}), the scenario's MR matrix is {} x {}", shape[0], shape[1], self.matrix[0], self.matrix[1]),
            ));
        }
        Ok(())
    }

    /// Checks that an image file lies on this geometry: its shape ([`MrGeometry::check_shape`])
    /// and its 4 x 4 affine (mm) within 1 µm of [`MrGeometry::affine_mm`], so that an image of
    /// another plane, centre, field of view or slice is refused by name.
    pub fn check_file(&self, name: &str, shape: [usize; 2], affine_mm: &[[f64; 4]; 4]) -> Result<()> {
        self.check_shape(name, shape)?;
        let expected = self.affine_mm();
        if (0..3).any(|r| (0..4).any(|c| !((affine_mm[r][c] - expected[r][c]).abs() <= 1e-3))) {
            return Err(HasError::invalid(
                name,
                "its affine does not match the scenario's MR geometry ([mr] plane, center_mm, fov_mm, slice_thickness_mm): an image of another scenario",
            ));
        }
        Ok(())
    }

    /// Pixels whose centres lie within `radius` (m) of `point` (m, transducer frame) in the image
    /// plane (the distance along the slice normal is not counted).
    pub fn pixels_near(&self, point: [f64; 3], radius: f64) -> Array2<bool> {
        let ax = self.plane.axes();
        Array2::from_shape_fn((self.matrix[0], self.matrix[1]), |(i, j)| {
            let (du, dv) = (self.pixel_center(0, i) - point[ax[0]], self.pixel_center(1, j) - point[ax[1]]);
            du * du + dv * dv <= radius * radius
        })
    }

    /// The 4 x 4 affine mapping NIfTI voxel indices of [`MrGeometry::volume_shape`] to the
    /// transducer frame in millimetres.
    pub fn affine_mm(&self) -> [[f64; 4]; 4] {
        let ax = self.plane.axes();
        let px = self.pixel_size();
        let mut a = [[0.0; 4]; 4];
        a[3][3] = 1.0;
        for (k, &f) in ax.iter().enumerate() {
            let (step, start) = if k < 2 { (px[k], self.pixel_center(k, 0)) } else { (self.slice_thickness, self.center[f]) };
            a[f][f] = step * 1e3;
            a[f][3] = start * 1e3;
        }
        a
    }
}

/// The Gaussian broadening of the force map before pixel averaging (paper Eq. 2–3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Broadening {
    /// Width W (m) of the Gaussian `exp(-(x² + y²) / (2·W²))` (normalised to unit integral); 0 = none.
    pub width: f64,
}

/// The linear map from `|p|²` samples in a grid window to MR pixels, without the amplitude:
/// `image[u, v] = Σ_s w_s · Σ_{a,b} M_u[u, a] · M_v[v, b] · coef · |p|²`, where
/// `coef = s_d · alpha / (rho·c²)` with the tissue's displacement scale `s_d`, `w_s` the slice
/// profile, and `M = P·G` pixel averaging after Gaussian broadening along each image axis. A
/// pixel is imaged where at least [`IMAGED_FRACTION`] of the part of it the window covers (over
/// the slice) is tissue with MR signal. A sampler may cover only a box of pixels
/// ([`MrSampler::restrict`]).
#[derive(Debug, Clone)]
pub struct MrSampler {
    /// The image geometry it samples onto.
    pub geometry: MrGeometry,
    /// The Gaussian broadening applied before pixel averaging.
    pub broadening: Broadening,
    /// The grid window to record.
    pub window: Window,
    /// The pixels produced: ranges along u and v.
    pub pixels: [Range<usize>; 2],
    /// Displacement coefficient `s_d·alpha / (rho·c²)` per window sample (plane, row, column).
    force_coefficient: Vec<f64>,
    /// Which of the pixels produced are imaged (tissue with MR signal), `(n_u, n_v)`.
    imaged: Array2<bool>,
    /// Slice-profile weights along the slice normal (sums to the covered fraction of the slice).
    slab_weights: Vec<f64>,
    /// Window sample coordinates along u and v (m) and their spacings.
    samples: [Vec<f64>; 2],
    spacing: [f64; 2],
    /// `M_u` (pixels u x samples u), `M_v` (pixels v x samples v).
    m: [Array2<f64>; 2],
    /// Shift (m, along u and v) of the image content against the pixel grid: pixel centres sample
    /// the field at `centre - shift` (a registration offset; zero for the scenario's geometry).
    pub shift: [f64; 2],
}

impl MrSampler {
    /// Builds the window and operators for `geometry` on `grid` (broadening `width` in metres).
    pub fn new(grid: &Grid, medium: &Medium, frequency: f64, geometry: &MrGeometry, broadening: Broadening) -> Result<Self> {
        geometry.validate()?;
        require_non_negative("arfi.broadening_width_mm", broadening.width)?;
        let ax = geometry.plane.axes();
        // Sample coordinates of the grid along frame axes x, y, z.
        let coords = |axis: usize| -> (Vec<f64>, f64) {
            match axis {
                0 => ((0..grid.nx).map(|i| grid.x(i)).collect(), grid.dx),
                1 => ((0..grid.ny).map(|j| grid.y(j)).collect(), grid.dy),
                _ => ((0..grid.nz).map(|n| grid.z(n)).collect(), grid.dz),
            }
        };
        let reach = 4.0 * broadening.width;
        let mut ranges = [0..0, 0..0, 0..0];
        let mut samples: [Vec<f64>; 2] = [vec![], vec![]];
        let mut spacing = [0.0; 2];
        let mut slab_weights = vec![];
        for (k, &a) in ax.iter().enumerate() {
            let (c, d) = coords(a);
            let (lo, hi) = if k < 2 {
                let half = 0.5 * geometry.fov[k];
                (geometry.center[a] - half - reach - d, geometry.center[a] + half + reach + d)
            } else {
                let half = 0.5 * geometry.slice_thickness;
                (geometry.center[a] - half - d, geometry.center[a] + half + d)
            };
            let mut range = index_range(&c, lo, hi);
            if range.is_empty() {
                return Err(HasError::invalid("mr", "the MR slice lies outside the simulation grid"));
            }
            let local = c[range.clone()].to_vec();
            if k < 2 {
                samples[k] = local;
                spacing[k] = d;
            } else {
                let t = geometry.slice_thickness;
                let lo = geometry.center[a] - 0.5 * t;
                // Each sample's cell's share of the slice: `overlap` is a fraction of the cell.
                let weights: Vec<f64> = local.iter().map(|&s| overlap(s, d, lo, lo + t) * d / t).collect();
                // Planes whose cells miss the slice add nothing to any image: not recorded.
                let first = weights.iter().position(|&w| w > 0.0).unwrap_or(0);
                let last = weights.iter().rposition(|&w| w > 0.0).map_or(first, |l| l + 1);
                slab_weights = weights[first..last].to_vec();
                range = range.start + first..range.start + last;
            }
            ranges[a] = range;
        }
        let window = Window { planes: ranges[2].clone(), rows: ranges[1].clone(), cols: ranges[0].clone() };
        let mut force_coefficient = Vec::with_capacity(window.len());
        let mut signal = Vec::with_capacity(window.len());
        for n in window.planes.clone() {
            for j in window.rows.clone() {
                for i in window.cols.clone() {
                    let (x, y, z) = (grid.x(i), grid.y(j), grid.z(n));
                    let tissue = medium.mr_response_at(x, y, z);
                    force_coefficient.push(tissue.displacement_scale * medium.properties_at(x, y, z, frequency).force_coefficient());
                    signal.push(if tissue.signal { 1.0 } else { 0.0 });
                }
            }
        }
        let pixels = [0..geometry.matrix[0], 0..geometry.matrix[1]];
        let averages = [0, 1].map(|k| {
            let centres: Vec<f64> = pixels[k].clone().map(|i| geometry.pixel_center(k, i)).collect();
            pixel_average(&centres, geometry.pixel_size()[k], &samples[k], spacing[k])
        });
        let cover = |q: &[f64]| averages[0].dot(&slab_map(&window, ax, &slab_weights, |s| q[s]).t()).dot(&averages[1].t());
        let (with_signal, covered) = (cover(&signal), cover(&vec![1.0; window.len()]));
        let imaged = ndarray::Zip::from(&with_signal).and(&covered).map_collect(|&s, &c| s >= IMAGED_FRACTION * c - 1e-12);
        let m = [
            axis_operator(geometry, 0, pixels[0].clone(), &samples[0], spacing[0], broadening.width, 0.0),
            axis_operator(geometry, 1, pixels[1].clone(), &samples[1], spacing[1], broadening.width, 0.0),
        ];
        Ok(MrSampler {
            geometry: geometry.clone(),
            broadening,
            window,
            pixels,
            force_coefficient,
            imaged,
            slab_weights,
            samples,
            spacing,
            m,
            shift: [0.0; 2],
        })
    }

    /// The same sampler with another broadening width (m), on the same window.
    pub fn with_broadening(&self, width: f64) -> Result<Self> {
        self.with_view([width; 2], self.shift)
    }

    /// The same sampler with broadening widths `widths` (m, along u and v: an anisotropic
    /// Gaussian when they differ; `broadening.width` then holds their mean) and the image content
    /// shifted by `shift` (m, along u and v), on the same window. A shift moves the pixels over
    /// the recorded window: keep it well inside the window's margin (4 W plus a sample beyond the
    /// field of view).
    pub fn with_view(&self, widths: [f64; 2], shift: [f64; 2]) -> Result<Self> {
        require_non_negative("broadening_width_mm", widths[0])?;
        require_non_negative("broadening_width_mm", widths[1])?;
        if !shift.iter().all(|v| v.is_finite()) {
            return Err(HasError::invalid("shift_mm", "must be finite"));
        }
        let mut s = self.clone();
        s.broadening = Broadening { width: 0.5 * (widths[0] + widths[1]) };
        s.shift = shift;
        s.m = [0, 1]
            .map(|k| axis_operator(&self.geometry, k, self.pixels[k].clone(), &self.samples[k], self.spacing[k], widths[k], shift[k]));
        Ok(s)
    }

    /// A sampler producing only pixels `u x v` (ranges within [`MrSampler::pixels`]), reading only
    /// the part of the window they depend on.
    pub fn restrict(&self, u: Range<usize>, v: Range<usize>) -> Result<Self> {
        let wanted = [u, v];
        let ax = self.geometry.plane.axes();
        let mut s = self.clone();
        let mut cut = [0..0, 0..0];
        for k in 0..2 {
            let r = &wanted[k];
            if r.is_empty() || r.start < self.pixels[k].start || r.end > self.pixels[k].end {
                return Err(HasError::invalid("pixels", format!("box {r:?} lies outside {:?}", self.pixels[k])));
            }
            let rows = (r.start - self.pixels[k].start)..(r.end - self.pixels[k].start);
            let m = self.m[k].slice(ndarray::s![rows, ..]);
            let nz: Vec<usize> = (0..m.ncols()).filter(|&j| m.column(j).iter().any(|&x| x != 0.0)).collect();
            let (a0, a1) = (nz.first().copied().unwrap_or(0), nz.last().map_or(0, |l| l + 1));
            s.m[k] = m.slice(ndarray::s![.., a0..a1]).to_owned();
            s.samples[k] = self.samples[k][a0..a1].to_vec();
            cut[k] = a0..a1;
            s.pixels[k] = r.clone();
        }
        // Window ranges along frame axes (x = cols, y = rows, z = planes).
        let mut ranges = [self.window.cols.clone(), self.window.rows.clone(), self.window.planes.clone()];
        for k in 0..2 {
            let base = ranges[ax[k]].start;
            ranges[ax[k]] = base + cut[k].start..base + cut[k].end;
        }
        s.window = Window { planes: ranges[2].clone(), rows: ranges[1].clone(), cols: ranges[0].clone() };
        s.force_coefficient = self.window.extract(&self.force_coefficient, &s.window);
        let (u0, v0) = (self.pixels[0].start, self.pixels[1].start);
        s.imaged =
            self.imaged.slice(ndarray::s![wanted[0].start - u0..wanted[0].end - u0, wanted[1].start - v0..wanted[1].end - v0]).to_owned();
        Ok(s)
    }

    /// Which pixels of [`MrSampler::pixels`] are imaged (tissue with MR signal), `(n_u, n_v)`.
    pub fn imaged(&self) -> &Array2<bool> {
        &self.imaged
    }

    /// Sets the pixels of `image` (the sampler's pixel box) that are not imaged to NaN, as a
    /// scanner leaves them.
    pub fn blank_unimaged(&self, image: &mut Array2<f64>) {
        image.zip_mut_with(&self.imaged, |v, &imaged| {
            if !imaged {
                *v = f64::NAN
            }
        });
    }

    /// The MR-ARFI phase image (rad) from the recorded window of the complex pressure: the force
    /// image times `amplitude` (rad·m³/N), its pixels without signal NaN.
    pub fn arfi_image(&self, window_field: &[num_complex::Complex64], amplitude: f64) -> Result<Array2<f64>> {
        let mut image = self.force_image(window_field)? * amplitude;
        self.blank_unimaged(&mut image);
        Ok(image)
    }

    /// The image `(n_u, n_v)` of force density (N/m³), broadened and pixel-averaged, from the
    /// recorded window of the complex pressure.
    pub fn force_image(&self, window_field: &[num_complex::Complex64]) -> Result<Array2<f64>> {
        let power: Vec<f64> = window_field.iter().map(|p| p.norm_sqr()).collect();
        self.apply(&power)
    }

    /// The linear operator applied to any real per-sample quantity `q` (|p|², or one part of a
    /// cross product p_g·conj(p_h)): returns `Σ w · M_u · M_v · coef · q` on the sampler's pixels.
    pub fn apply(&self, q: &[f64]) -> Result<Array2<f64>> {
        let w = &self.window;
        if q.len() != w.len() {
            return Err(HasError::invalid("window", format!("has {} samples, expected {}", q.len(), w.len())));
        }
        let map = slab_map(w, self.geometry.plane.axes(), &self.slab_weights, |s| q[s] * self.force_coefficient[s]);
        // image[u, v] = Σ_a Σ_b M_u[u, a] · map[b, a] · M_v[v, b]
        Ok(self.m[0].dot(&map.t()).dot(&self.m[1].t()))
    }

    /// The adjoint of [`MrSampler::apply`]: for an image-shaped `r` (pixels u x v), the
    /// per-sample `q̄` with `<apply(q), r> = <q, q̄>` for every `q`; it maps `∂J/∂image` to
    /// `∂J/∂|p|²`.
    pub fn apply_adjoint(&self, r: &Array2<f64>) -> Result<Vec<f64>> {
        if r.dim() != (self.pixels[0].len(), self.pixels[1].len()) {
            return Err(HasError::invalid("image", format!("has shape {:?}, the sampler's pixel box is {:?}", r.dim(), self.pixels)));
        }
        // map̄[a, b] = Σ_u Σ_v M_u[u, a] · r[u, v] · M_v[v, b]
        let map = self.m[0].t().dot(r).dot(&self.m[1]);
        let w = &self.window;
        let ax = self.geometry.plane.axes();
        let dims = [w.cols.len(), w.rows.len(), w.planes.len()];
        let mut q = vec![0.0; w.len()];
        for n in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let s = (n * dims[1] + j) * dims[0] + i;
                    let idx = [i, j, n];
                    q[s] = map[[idx[ax[0]], idx[ax[1]]]] * self.force_coefficient[s] * self.slab_weights[idx[ax[2]]];
                }
            }
        }
        Ok(q)
    }
}

/// The window samples `f(s)` collapsed along the slice normal with the slice profile `w`: a map
/// indexed `[b][a]` (samples along image axes v and u).
fn slab_map(w: &Window, ax: [usize; 3], slab_weights: &[f64], f: impl Fn(usize) -> f64) -> Array2<f64> {
    let dims = [w.cols.len(), w.rows.len(), w.planes.len()]; // sizes along x, y, z
    let mut map = Array2::<f64>::zeros((dims[ax[1]], dims[ax[0]]));
    for n in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let s = (n * dims[1] + j) * dims[0] + i;
                let idx = [i, j, n];
                map[[idx[ax[1]], idx[ax[0]]]] += f(s) * slab_weights[idx[ax[2]]];
            }
        }
    }
    map
}

/// The imaged pixel with the largest value among `region` (pixels without signal, NaN, are
/// skipped): its index and value; `None` when the region holds no imaged pixel.
pub fn focal_peak(image: &Array2<f64>, region: &Array2<bool>) -> Option<((usize, usize), f64)> {
    image
        .indexed_iter()
        .filter(|(ij, v)| v.is_finite() && region.get(*ij).copied().unwrap_or(false))
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(ij, v)| (ij, *v))
}

/// `M = P·G` along image axis `k`: Gaussian broadening on the samples, then the area average over
/// the pixels in `pixels`, whose centres are moved by `-shift` (m).
fn axis_operator(g: &MrGeometry, k: usize, pixels: Range<usize>, samples: &[f64], d: f64, width: f64, shift: f64) -> Array2<f64> {
    let px = g.pixel_size()[k];
    let centres: Vec<f64> = pixels.map(|i| g.pixel_center(k, i) - shift).collect();
    pixel_average(&centres, px, samples, d).dot(&gaussian(samples, d, width))
}

/// Indices of the sorted coordinates `c` that lie within `[lo, hi]`.
fn index_range(c: &[f64], lo: f64, hi: f64) -> std::ops::Range<usize> {
    let start = c.iter().position(|&v| v >= lo).unwrap_or(c.len());
    let end = c.iter().rposition(|&v| v <= hi).map_or(start, |e| e + 1).max(start);
    start..end
}

/// Length of `[s - d/2, s + d/2] ∩ [lo, hi]` divided by `d`.
fn overlap(s: f64, d: f64, lo: f64, hi: f64) -> f64 {
    ((s + 0.5 * d).min(hi) - (s - 0.5 * d).max(lo)).max(0.0) / d
}

/// `P[p, i]`: the fraction of pixel `p` (width `px`) covered by sample cell `i` (width `d`), so
/// that `P · f` is the area average of the piecewise-constant samples over each pixel.
fn pixel_average(centres: &[f64], px: f64, samples: &[f64], d: f64) -> Array2<f64> {
    Array2::from_shape_fn((centres.len(), samples.len()), |(p, i)| {
        let (lo, hi) = (centres[p] - 0.5 * px, centres[p] + 0.5 * px);
        overlap(samples[i], d, lo, hi) * d / px
    })
}

/// Discrete convolution with the unit-integral Gaussian of width `w` on uniform samples spaced
/// `d`: `G[i, j] = g(i - j) / Σ_m g(m)`, `g(m) = exp(-(m·d)² / (2·w²))`; identity when `w = 0`.
fn gaussian(samples: &[f64], d: f64, w: f64) -> Array2<f64> {
    let n = samples.len();
    if w <= 0.0 {
        return Array2::eye(n);
    }
    // In samples, r = w/d: g(m) = exp(-(m/r)²/2). Written this way (and g(0) = 1 exactly) a
    // width far below the spacing, whose square underflows, still gives the identity.
    let r = w / d;
    let reach = (4.0 * r).ceil();
    let g = |m: f64| if m == 0.0 { 1.0 } else { (-0.5 * (m / r).powi(2)).exp() };
    // The normalisation sums the whole kernel (±4 W), which may reach past the window; beyond
    // 10^7 terms (absurd widths) it takes the integral value sqrt(2π)·r.
    let sum: f64 =
        if reach <= 1e7 { (-(reach as i64)..=reach as i64).map(|m| g(m as f64)).sum() } else { (2.0 * std::f64::consts::PI).sqrt() * r };
    // Offsets beyond the window never pair two samples.
    let half = reach.min(n as f64) as i64;
    let g: Vec<f64> = (-half..=half).map(|m| g(m as f64)).collect();
    Array2::from_shape_fn((n, n), |(i, j)| {
        let m = j as i64 - i as i64;
        if m.abs() <= half {
            g[(m + half) as usize] / sum
        } else {
            0.0
        }
    })
}

/// Adds seeded Gaussian noise of standard deviation `sigma` (rad) to an image (ChaCha8 stream).
pub fn add_noise(image: &mut Array2<f64>, sigma: f64, seed: u64) -> Result<()> {
    require_non_negative("noise_rad", sigma)?;
    if sigma == 0.0 {
        return Ok(());
    }
    let normal = Normal::new(0.0, sigma).map_err(|e| HasError::invalid("noise_rad", e.to_string()))?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    image.iter_mut().for_each(|v| *v += normal.sample(&mut rng));
    Ok(())
}

/// The noise level (rad) of an ARFI image from its background, for noise independent between
/// pixels: `1.4826 · MAD / 6` of the image filtered by the 3 x 3 mask `[1 -2 1; -2 4 -2; 1 -2 1]`
/// (the second difference along u times that along v; Immerkær, Comput Vis Image Underst 64:300,
/// 1996), the standard deviation of white Gaussian noise (the mask's coefficients square to 36).
/// The mask cancels what is linear along u or along v (a background phase ramp, the beam's force
/// along a path that runs along an image axis) and leaves of a smooth signal its mixed fourth
/// derivative, where differences of neighbours take a signal's gradient for noise: on a 650 kHz
/// head's images, whose background the beam's force fills, they read 0.024–0.025 rad for 0.02 of
/// noise, the mask 0.0196–0.0208. Noise correlated between pixels (interpolated or k-space
/// filtered images) reads low, several-fold for zero-filled ones: give it where it is known
/// instead (`arfi estimate --noise-rad`). Over the windows that keep clear of `exclude` (u and v
/// ranges around the focus), or over the whole image when fewer than 50 remain (the median
/// ignores the few windows on the focus); windows holding a pixel without signal (NaN) are
/// skipped. An image narrower than 3 pixels takes `1.4826 · MAD / √2` of the differences of
/// neighbours along u.
pub fn noise_floor(image: &Array2<f64>, exclude: &[Range<usize>; 2]) -> f64 {
    const MASK: [[f64; 3]; 3] = [[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]];
    let (nu, nv) = image.dim();
    if nu < 3 || nv < 3 {
        return neighbour_floor(image);
    }
    let touches = |r: &Range<usize>, centre: usize| !r.is_empty() && r.start <= centre + 1 && centre <= r.end;
    let filtered = |outside: bool| -> Vec<f64> {
        let mut d = Vec::new();
        for j in 1..nv - 1 {
            for i in 1..nu - 1 {
                if outside && touches(&exclude[0], i) && touches(&exclude[1], j) {
                    continue;
                }
                let value: f64 =
                    (0..3).flat_map(|a| (0..3).map(move |b| (a, b))).map(|(a, b)| MASK[a][b] * image[[i + a - 1, j + b - 1]]).sum();
                if value.is_finite() {
                    d.push(value);
                }
            }
        }
        d
    };
    let mut d = filtered(true);
    if d.len() < 50 {
        d = filtered(false);
    }
    robust_std(d) / 6.0
}

/// `1.4826 · MAD / √2` of the differences of neighbouring pixels along u (NaN pairs skipped): the
/// floor of an image too narrow for [`noise_floor`]'s mask.
fn neighbour_floor(image: &Array2<f64>) -> f64 {
    let d: Vec<f64> = image.windows((2, 1)).into_iter().map(|w| w[[1, 0]] - w[[0, 0]]).filter(|v| v.is_finite()).collect();
    robust_std(d) / std::f64::consts::SQRT_2
}

/// `1.4826 · MAD` of `values` (the standard deviation of Gaussian values; 0 for none).
fn robust_std(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let med = median(&mut values);
    let mut dev: Vec<f64> = values.iter().map(|v| (v - med).abs()).collect();
    1.4826 * median(&mut dev)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform force density images as itself whatever the grid: the slice profile's weights
    /// are each sample's share of the slice, so that the amplitude (rad·m³/N) means the same on
    /// any grid. Reference: `coef·|p|²` of the medium by hand; to rounding (1e-12), with the
    /// slice normal along y (a coronal slice) and along z.
    #[test]
    fn a_uniform_force_density_images_as_itself_on_any_grid() {
        use crate::physics::material::Material;
        let tissue = Material::new("tissue", 1540.0, 1040.0, 0.5).unwrap();
        let medium = Medium::homogeneous(tissue.clone());
        let f = 650e3;
        let expected = medium.properties_at(0.0, 0.0, 0.1, f).force_coefficient() * 1e10;
        for plane in [MrPlane::Xz, MrPlane::Xy] {
            let geometry = MrGeometry { plane, center: [0.0, 0.0, 0.1], fov: [20e-3, 20e-3], matrix: [10, 10], slice_thickness: 4e-3 };
            for (d, n) in [(0.4e-3, 128), (0.7e-3, 72)] {
                let grid = Grid::new(n, n, d, d, (0.1 / d) as usize + 40, d, 0.02).unwrap();
                let sampler = MrSampler::new(&grid, &medium, f, &geometry, Broadening { width: 1e-3 }).unwrap();
                let image = sampler.force_image(&vec![num_complex::Complex64::new(1e5, 0.0); sampler.window.len()]).unwrap();
                let centre = image[[5, 5]];
                assert!((centre / expected - 1.0).abs() < 1e-12, "{plane:?}, spacing {d}: {centre} vs {expected}");
            }
        }
    }

    #[test]
    fn pixel_average_and_gaussian_preserve_a_constant() {
        let s: Vec<f64> = (0..200).map(|i| i as f64 * 0.5e-3).collect();
        let centres: Vec<f64> = (0..30).map(|p| 20e-3 + p as f64 * 1.4e-3).collect();
        let m = pixel_average(&centres, 1.4e-3, &s, 0.5e-3).dot(&gaussian(&s, 0.5e-3, 2.7e-3));
        for r in m.rows() {
            assert!((r.sum() - 1.0).abs() < 1e-12, "{}", r.sum());
        }
    }

    #[test]
    fn a_kernel_wider_than_the_window_keeps_the_gaussian_normalisation() {
        // 40 samples of 0.5 mm: a 6 mm kernel reaches 48 samples, past the window. Reference:
        // the direct sum of g over ±48 (the definition), to rounding.
        let s: Vec<f64> = (0..40).map(|i| i as f64 * 0.5e-3).collect();
        let (d, w) = (0.5e-3, 6e-3);
        let direct: f64 = (-48..=48).map(|m: i32| (-(m as f64 * d).powi(2) / (2.0 * w * w)).exp()).sum();
        let g = gaussian(&s, d, w);
        assert!((g[[0, 0]] * direct - 1.0).abs() < 1e-12, "{}", g[[0, 0]] * direct);
        // Absurd widths give a finite, nearly flat kernel instead of an allocation failure.
        let g = gaussian(&s, d, 1e300);
        assert!(g.iter().all(|v| v.is_finite() && *v >= 0.0));
        // A width whose square underflows (hypothesis found 1e-300 mm giving NaN) is the identity.
        for w in [1e-303, 5e-324] {
            assert_eq!(gaussian(&s, d, w), Array2::<f64>::eye(40), "w = {w}");
        }
    }

    #[test]
    fn affine_maps_pixel_centres() {
        let g = MrGeometry { plane: MrPlane::Xy, center: [0.0, 0.0, 0.085], fov: [0.18, 0.135], matrix: [128, 96], slice_thickness: 3e-3 };
        let a = g.affine_mm();
        assert!((a[0][3] - (-90.0 + 0.703125)).abs() < 1e-9);
        assert!((a[0][0] - 1.40625).abs() < 1e-12 && (a[2][2] - 3.0).abs() < 1e-12 && (a[2][3] - 85.0).abs() < 1e-9);
        assert_eq!(g.volume_shape(), [128, 96, 1]);
        let g = MrGeometry { plane: MrPlane::Yz, ..g };
        assert_eq!(g.volume_shape(), [1, 128, 96]);
    }

    #[test]
    fn the_noise_floor_skips_pixels_without_signal() {
        // Seeded noise of 0.02 rad on 128 x 96 pixels, a third of them NaN (no signal): the floor
        // comes from the imaged windows alone (with NaN windows it would be NaN); 1.4826·MAD over
        // ~8000 windows scatters by about 1.5 %.
        let mut a = Array2::zeros((128, 96));
        add_noise(&mut a, 0.02, 11).unwrap();
        a.slice_mut(ndarray::s![.., ..32]).fill(f64::NAN);
        let floor = noise_floor(&a, &[0..0, 0..0]);
        assert!((floor - 0.02).abs() < 0.001, "{floor}");
    }

    #[test]
    fn the_noise_floor_is_blind_to_a_signal_that_fills_the_background() {
        // 0.02 rad of seeded noise on 128 x 96 pixels over a beam's force along its path: a ridge
        // 20 pixels wide that runs 10 degrees off the v axis and fades along it, rising to 2 rad;
        // a background phase ramp of 0.5 rad; a focal spot of 6 rad (excluded). Reference: the
        // noise's own standard deviation. Differences of neighbours along u read 32 % high on
        // this image; the mask reads the noise to the MAD's scatter (about 1.5 % over ~11 000
        // windows) plus what is left of the ridge, its mixed fourth derivative. A white image
        // narrower than 3 pixels falls back to the differences. Tolerance 5 %.
        let (nu, nv) = (128, 96);
        let mut a = Array2::from_shape_fn((nu, nv), |(i, j)| {
            let (u, v) = (i as f64 - 64.0, j as f64);
            let across = u - 0.18 * (v - 48.0);
            let ridge = 2.0 * (-v / 60.0).exp() * (-0.5 * (across / 10.0).powi(2)).exp();
            let spot = 6.0 * (-0.5 * ((u.powi(2) + (v - 48.0).powi(2)) / 4.0)).exp();
            ridge + spot + 0.5 * (i + j) as f64 / (nu + nv) as f64
        });
        add_noise(&mut a, 0.02, 5).unwrap();
        let floor = noise_floor(&a, &[54..74, 38..58]);
        let neighbours = neighbour_floor(&a);
        eprintln!("[noise floor] mask {floor:.4} rad, neighbour differences {neighbours:.4} rad (noise 0.02)");
        assert!((floor / 0.02 - 1.0).abs() < 0.05, "{floor}");
        let mut thin = Array2::zeros((4000, 2));
        add_noise(&mut thin, 0.02, 6).unwrap();
        assert!((noise_floor(&thin, &[0..0, 0..0]) / 0.02 - 1.0).abs() < 0.05);
    }

    #[test]
    fn focal_peak_looks_only_near_the_target_among_imaged_pixels() {
        let g = MrGeometry { plane: MrPlane::Xy, center: [0.0, 0.0, 0.085], fov: [0.18, 0.135], matrix: [128, 96], slice_thickness: 3e-3 };
        let region = g.pixels_near([0.01, 0.0, 0.085], 0.02);
        let mut image = Array2::zeros((128, 96));
        image[[10, 10]] = 5.0; // a hot pixel 70 mm away: a skull ring, scalp
        image[[71, 48]] = f64::NAN; // the brightest place near the target has no signal
        image[[72, 48]] = 0.6;
        assert_eq!(focal_peak(&image, &region), Some(((72, 48), 0.6)));
        // 20 mm about (10, 0) mm: pixel 71 is centred at x = 10.55 mm, pixel 85 at 30.2 mm.
        assert!(region[[71, 48]] && !region[[85, 48]] && !region[[10, 10]]);
        image.fill(f64::NAN);
        assert_eq!(focal_peak(&image, &region), None);
    }

    #[test]
    fn noise_is_seeded() {
        let mut a = Array2::zeros((4, 4));
        let mut b = Array2::zeros((4, 4));
        add_noise(&mut a, 0.02, 7).unwrap();
        add_noise(&mut b, 0.02, 7).unwrap();
        assert_eq!(a, b);
        assert!(a.iter().any(|v| *v != 0.0));
    }
}
