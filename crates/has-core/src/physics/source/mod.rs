//! The source plane: per-element pressure on the first plane of the grid.
//!
//! Elements lying flat in z = 0 are rasterised exactly (pixel value = face pressure × the fraction
//! of the pixel the element covers: a pressure boundary condition). Curved or tilted elements are
//! projected onto the plane `z0` in water with the Rayleigh integral for a baffled velocity source
//! (time convention `exp(-i·omega·t)`):
//! `p(r) = -(i·k / 2·pi) · p_face · ∫ exp(i·k·R) / R dS`, with `p_face = rho·c·v_n`.
//!
//! A whole spherical cap (one element, so always driven uniformly) radiates a field symmetric
//! about the z axis: the integral is evaluated once, on a radial line of the plane sampled
//! [`RADIAL_OVERSAMPLING`] times finer than the grid, interpolated onto the pixels (cubic) and
//! kept, so every later source plane of that transducer is a multiplication.

use crate::error::{HasError, Result};
use crate::physics::grid::Grid;
use crate::physics::rayleigh::Sources;
use crate::physics::transducer::{ElementShape, Surface, SurfacePoint, Transducer};
pub use crate::physics::upsample::{fourier_resample, fourier_resample_transposed};
use num_complex::{Complex32 as C32, Complex64 as C64};
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

mod motion;

/// How one element contributes to the source plane.
#[derive(Debug, Clone)]
enum Footprint {
    /// Pixel indices and covered fractions (pressure boundary condition).
    Raster(Vec<(u32, f64)>),
    /// Quadrature points for the Rayleigh projection.
    Points(Vec<SurfacePoint>),
    /// The element's projection onto the plane for unit drive (Pa per Pa of face pressure).
    Plane(Vec<C64>),
}

impl Footprint {
    /// The Rayleigh quadrature points (none for rasters and stored projections).
    fn points(&self) -> &[SurfacePoint] {
        match self {
            Footprint::Points(p) => p,
            _ => &[],
        }
    }
}

/// Radial samples per grid spacing for the projection of a cap.
pub const RADIAL_OVERSAMPLING: usize = 8;

/// Maps per-element complex drive (phasors) to the pressure on the grid's first plane.
#[derive(Debug, Clone)]
pub struct SourceModel {
    /// The array projected (compared by [`SourceModel::new_reusing`] and [`SourceModel::on_grid`]).
    transducer: Arc<Transducer>,
    grid: Grid,
    /// The grid on whose every `r`-th pixel the Rayleigh sums run ([`SourceModel::coarsening`]):
    /// `grid` itself, or the grid of the same period that a model carried to `grid` was built on
    /// ([`SourceModel::on_grid`]), its sums Fourier-resampled onto `grid`.
    lattice: Grid,
    footprints: Vec<Footprint>,
    /// Pressure amplitude on every element face (Pa).
    pub face_pressure: f64,
    /// Wavenumber (rad/m) and attenuation (Np/m) of the medium between the elements and the plane.
    wavenumber: f64,
    attenuation: f64,
    /// The projected elements' planes for unit drive, made by the first field that needs them
    /// and shared by clones.
    projections: Arc<OnceLock<Projections>>,
}

/// At most this many bytes of projected elements' planes are kept (see [`SourceModel::fields`]).
pub const PROJECTIONS_MAX_BYTES: u64 = 1 << 30;

/// Each projected element's Rayleigh integral for unit drive on the coarse pixels of the sums
/// ([`SourceModel::add_rayleigh`]), in single precision: a field of any drive is then their
/// weighted sum, instead of an integral over every quadrature point.
struct Projections {
    /// The elements projected (those with quadrature points), in increasing order.
    elements: Vec<usize>,
    /// Row-major `(cy, cx)`, one per element of `elements`.
    planes: Vec<Vec<C32>>,
}

impl std::fmt::Debug for Projections {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Projections({} elements of {} samples)", self.elements.len(), self.planes.first().map_or(0, Vec::len))
    }
}

/// The z of the first plane for a transducer: 0 for a planar array, else just in front of the
/// most forward element point (half a wavelength, at least one step).
pub fn source_plane_z(transducer: &Transducer, wavelength: f64, dz: f64) -> f64 {
    if transducer.is_planar() {
        0.0
    } else {
        let z = transducer.elements.iter().map(Surface::z_max).fold(0.0, f64::max);
        z + (0.5 * wavelength).max(dz)
    }
}

impl SourceModel {
    /// Builds the footprints. `wavenumber` and `attenuation` (rad/m, Np/m) describe the coupling
    /// medium; `face_pressure` (Pa) is the same on every element.
    pub fn new(transducer: &Transducer, grid: &Grid, face_pressure: f64, wavenumber: f64, attenuation: f64) -> Result<Self> {
        let z0 = grid.z0;
        let wavelength = 2.0 * std::f64::consts::PI / wavenumber;
        let spacing = (wavelength / 8.0).min(grid.dx.min(grid.dy) / 2.0);
        let mut model = SourceModel {
            transducer: Arc::new(transducer.clone()),
            grid: grid.clone(),
            lattice: grid.clone(),
            footprints: Vec::new(),
            face_pressure,
            wavenumber,
            attenuation,
            projections: Arc::default(),
        };
        for e in &transducer.elements {
            let footprint = if e.is_in_plane(z0) {
                Footprint::Raster(rasterise(e, grid))
            } else if e.z_max() >= z0 {
                return Err(HasError::invalid("transducer", "an element reaches beyond the source plane"));
            } else if matches!(e, Surface::Cap { .. }) {
                Footprint::Plane(model.symmetric_projection(&e.quadrature(spacing)))
            } else {
                Footprint::Points(e.quadrature(element_spacing(wavelength, z0 - e.z_max())))
            };
            model.footprints.push(footprint);
        }
        Ok(model)
    }

    /// [`SourceModel::new`] of the same arguments, reusing `kept` where it was built from them
    /// (the same array, grid, face pressure and coupling medium): a clone, which shares its
    /// projected elements' planes, made once by the first field of either ([`SourceModel::fields`]).
    /// Two simulations of one array in two media (a head with and without its bone) then project
    /// the array once: at 1024 elements of a hemisphere that is seconds.
    pub fn new_reusing(
        transducer: &Transducer,
        grid: &Grid,
        face_pressure: f64,
        wavenumber: f64,
        attenuation: f64,
        kept: Option<&SourceModel>,
    ) -> Result<Self> {
        // A model carried to its grid from another (its sums resampled) is not what `new` makes.
        let same = |m: &&SourceModel| {
            m.grid == *grid
                && m.lattice == m.grid
                && *m.transducer == *transducer
                && m.face_pressure == face_pressure
                && m.wavenumber == wavenumber
                && m.attenuation == attenuation
        };
        match kept.filter(same) {
            Some(m) => Ok(m.clone()),
            None => SourceModel::new(transducer, grid, face_pressure, wavenumber, attenuation),
        }
    }

    /// The same array's footprints on another grid (its plane 0 at the same z): the same face
    /// pressure and coupling medium. Where `grid` has the same period and origin as the grid the
    /// sums run on and samples at least as finely as they do (`SourceModel::resamples_onto`),
    /// the model keeps its sums, and their kept projections (shared), and Fourier-resamples them
    /// onto `grid` (exact for the waves the coarse pixels hold, which are the waves that leave
    /// the plane: see [`SourceModel::fields`]); else it projects the array anew.
    pub fn on_grid(&self, transducer: &Transducer, grid: &Grid) -> Result<Self> {
        if *self.transducer == *transducer && self.resamples_onto(grid) {
            return Ok(SourceModel { grid: grid.clone(), ..self.clone() });
        }
        SourceModel::new(transducer, grid, self.face_pressure, self.wavenumber, self.attenuation)
    }

    /// Whether the sums can be carried to `grid` by Fourier resampling: every element projected
    /// by quadrature points (rasters and symmetric caps are laid on the grid's own pixels), the
    /// same source plane, the same lateral period and first pixel as the sums' lattice, and at
    /// least as many samples along x and y as the coarse pixels of the sums.
    fn resamples_onto(&self, grid: &Grid) -> bool {
        let (l, r) = (&self.lattice, self.coarsening());
        let same = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
        self.footprints.iter().all(|f| matches!(f, Footprint::Points(_)))
            && grid.z0 == l.z0
            && same(grid.nx as f64 * grid.dx, l.nx as f64 * l.dx)
            && same(grid.ny as f64 * grid.dy, l.ny as f64 * l.dy)
            && same(grid.x(0), l.x(0))
            && same(grid.y(0), l.y(0))
            && grid.nx >= l.nx / r
            && grid.ny >= l.ny / r
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.footprints.len()
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.footprints.is_empty()
    }

    /// Pressure (Pa) on the first plane, row-major `(ny, nx)`, for element drive `phasors`
    /// (element `e` radiates `face_pressure · phasors[e]`). Zero phasors cost nothing.
    pub fn field(&self, phasors: &[C64]) -> Result<Vec<C64>> {
        Ok(self.fields(std::slice::from_ref(&phasors.to_vec()))?.remove(0))
    }

    /// Each element's complex pressure (Pa) at `point` (m) for unit drive with the coupling medium
    /// everywhere (no head): the Rayleigh integral of [`crate::physics::rayleigh`] summed directly,
    /// in double precision, over the element's surface at λ/8 ([`Surface::quadrature`]), times the
    /// face pressure. `Σ_e |h_e|` is the focus the array gives there in water with every element
    /// in phase: the free field that a focus through a head is measured against.
    pub fn free_field_responses(&self, point: [f64; 3]) -> Vec<C64> {
        let spacing = 2.0 * std::f64::consts::PI / self.wavenumber / 8.0;
        let (k, alpha) = (self.wavenumber, self.attenuation);
        let pre = C64::new(0.0, -k / (2.0 * std::f64::consts::PI)) * self.face_pressure;
        self.transducer
            .elements
            .par_iter()
            .map(|e| {
                let sum: C64 = e
                    .quadrature(spacing)
                    .iter()
                    .map(|q| {
                        let r = (0..3).map(|a| (point[a] - q.position[a]).powi(2)).sum::<f64>().sqrt();
                        C64::from_polar(q.area * (-alpha * r).exp() / r, k * r)
                    })
                    .sum();
                pre * sum
            })
            .collect()
    }

    /// [`SourceModel::field`] of several drives at once (`phasors[drive][element]`, one plane
    /// each). An element costs nothing where every drive leaves it at zero.
    ///
    /// Elements projected by the Rayleigh integral (curved or tilted ones) are integrated once,
    /// by the first call, each on its own for unit drive (no more work than one field's sums;
    /// `elements × (nx/r)·(ny/r)` single-precision values kept (the sums' lattice), at most
    /// [`PROJECTIONS_MAX_BYTES`], else every call sums the integral): every field, this one
    /// included, is their weighted sum (in double precision), so a later field of other drives,
    /// or of one element, costs a sum over the elements instead of over their quadrature points;
    /// the transposed projections read them too ([`SourceModel::transposed_many`]).
    pub fn fields(&self, phasors: &[Vec<C64>]) -> Result<Vec<Vec<C64>>> {
        if let Some(p) = phasors.iter().find(|p| p.len() != self.footprints.len()) {
            return Err(HasError::invalid("phasors", format!("has {} values for {} elements", p.len(), self.footprints.len())));
        }
        let zero = C64::new(0.0, 0.0);
        let mut out = vec![vec![zero; self.grid.lateral_len()]; phasors.len()];
        let mut projected: Vec<(usize, Vec<C64>)> = Vec::new();
        for (e, fp) in self.footprints.iter().enumerate() {
            let drives: Vec<C64> = phasors.iter().map(|p| p[e] * self.face_pressure).collect();
            if drives.iter().all(|&a| a == zero) {
                continue;
            }
            for (o, &a) in out.iter_mut().zip(&drives) {
                match fp {
                    Footprint::Raster(px) => px.iter().for_each(|&(i, w)| o[i as usize] += a * w),
                    Footprint::Plane(p) => o.iter_mut().zip(p).for_each(|(o, p)| *o += a * p),
                    Footprint::Points(_) => {}
                }
            }
            if matches!(fp, Footprint::Points(_)) {
                projected.push((e, drives));
            }
        }
        if projected.is_empty() {
            return Ok(out);
        }
        match self.kept_projections() {
            Some(p) => self.add_projected(p, &projected, &mut out),
            None => self.add_point_sums(&projected, &mut out),
        }
        Ok(out)
    }

    /// Adds the Rayleigh sums over the quadrature points of the elements in `projected` (each
    /// element's drives, one per field of `out`): the integral without kept projections.
    fn add_point_sums(&self, projected: &[(usize, Vec<C64>)], out: &mut [Vec<C64>]) {
        let mut positions: Vec<[f64; 3]> = Vec::new();
        let mut weights: Vec<Vec<C64>> = vec![Vec::new(); out.len()];
        for (e, drives) in projected {
            for q in self.footprints[*e].points() {
                positions.push(q.position);
                weights.iter_mut().zip(drives).for_each(|(w, a)| w.push(a * q.area));
            }
        }
        self.add_rayleigh(&positions, &weights, out);
    }

    /// The kept projections, made now if they are not yet (outside the lock: the projection runs
    /// on the pool, whose threads may call for them meanwhile and then project too; the first
    /// to finish is kept). A refusal is not kept: a later call checks the memory again.
    fn kept_projections(&self) -> Option<&Projections> {
        if self.projections.get().is_none() {
            if let Some(p) = self.project_elements() {
                let _ = self.projections.set(p);
            }
        }
        self.projections.get()
    }

    /// The projected elements' planes ([`Projections`]), or `None` beyond
    /// [`PROJECTIONS_MAX_BYTES`] or the memory available. One rayon task per element.
    fn project_elements(&self) -> Option<Projections> {
        let g = &self.lattice;
        let elements: Vec<usize> = (0..self.footprints.len()).filter(|&e| !self.footprints[e].points().is_empty()).collect();
        let (cx, cy) = self.coarse_dims();
        let bytes = (elements.len() * cx * cy * std::mem::size_of::<C32>()) as u64;
        if bytes > PROJECTIONS_MAX_BYTES || crate::memory::check(String::new, bytes, "").is_err() {
            return None;
        }
        let (xs, ys) = self.coarse_pixels();
        let planes = elements
            .par_iter()
            .map(|&e| {
                let points: Vec<([f64; 3], C64)> =
                    self.footprints[e].points().iter().map(|q| (q.position, C64::new(q.area, 0.0))).collect();
                let sources = Sources::new(&points, g.z0, self.wavenumber, self.attenuation);
                ys.iter().flat_map(|&y| sources.row(&xs, y)).map(|v| C32::new(v.re as f32, v.im as f32)).collect()
            })
            .collect();
        Some(Projections { elements, planes })
    }

    /// Adds `Σ_e drive_e · plane_e` (`projected`: each element's drives, one per field), on the
    /// coarse pixels then interpolated as [`SourceModel::add_rayleigh`] does.
    fn add_projected(&self, p: &Projections, projected: &[(usize, Vec<C64>)], out: &mut [Vec<C64>]) {
        const CHUNK: usize = 4096;
        let (cx, cy) = self.coarse_dims();
        let terms: Vec<(&[C64], &[C32])> =
            projected.iter().filter_map(|(e, d)| p.elements.binary_search(e).ok().map(|i| (&d[..], &p.planes[i][..]))).collect();
        for (set, o) in out.iter_mut().enumerate() {
            let mut coarse = vec![C64::new(0.0, 0.0); cx * cy];
            coarse.par_chunks_mut(CHUNK).enumerate().for_each(|(c, chunk)| {
                for (drives, plane) in &terms {
                    let a = drives[set];
                    chunk.iter_mut().zip(&plane[c * CHUNK..]).for_each(|(v, q)| *v += a * C64::new(q.re as f64, q.im as f64));
                }
            });
            self.add_coarse(coarse, o);
        }
    }

    /// Adds the Rayleigh integral of the points at `positions` with each set of `weights` (drive
    /// × area, `weights[set][point]`) at every pixel of the plane `out[set]`: one rayon task per
    /// row, each a single-precision blocked sum ([`crate::physics::rayleigh`]; one set:
    /// [`Sources::row`], several: [`Sources::row_many`], the kernel evaluated once).
    ///
    /// Where the grid is finer than λ/2, the sum runs on every `r`-th pixel of the sums' lattice
    /// (spacing at most λ/2) and is Fourier-interpolated onto every pixel of the grid
    /// ([`fourier_resample`]; the lattice is the grid unless the model was carried to it,
    /// [`SourceModel::on_grid`]): the waves that leave the
    /// plane have spatial frequencies up to `k`, which samples λ/2 apart hold; what they can
    /// alias is the evanescent near field of the elements closest to the plane (λ/2 before it).
    /// `r = 2` at the default λ/4 spacing: a quarter of the work, and for the hemisphere of
    /// `tests/suite/hemisphere.rs` the same focal field to four digits as the sum at every pixel.
    fn add_rayleigh(&self, positions: &[[f64; 3]], weights: &[Vec<C64>], out: &mut [Vec<C64>]) {
        let g = &self.lattice;
        let first: Vec<([f64; 3], C64)> = positions.iter().copied().zip(weights[0].iter().copied()).collect();
        let sources = Sources::new(&first, g.z0, self.wavenumber, self.attenuation);
        let (xs, ys) = self.coarse_pixels();
        let rows: Vec<Vec<Vec<C64>>> = ys
            .par_iter()
            .map(|&y| if weights.len() == 1 { vec![sources.row(&xs, y)] } else { sources.row_many(weights, &xs, y) })
            .collect();
        for (set, o) in out.iter_mut().enumerate() {
            self.add_coarse(rows.iter().flat_map(|row| row[set].iter().copied()).collect(), o);
        }
    }

    /// Adds `coarse` (on the coarse pixels of the sums, [`SourceModel::coarsening`]) to the plane
    /// `out`, Fourier-interpolated onto every pixel where they are not every pixel.
    fn add_coarse(&self, mut coarse: Vec<C64>, out: &mut [C64]) {
        let ((cx, cy), g) = (self.coarse_dims(), &self.grid);
        let fine = if (cx, cy) == (g.nx, g.ny) { coarse } else { fourier_resample(&mut coarse, cx, cy, g.nx, g.ny) };
        out.iter_mut().zip(fine).for_each(|(o, v)| *o += v);
    }

    /// The coarsening `r` of the Rayleigh sums on their lattice: the largest whole number with
    /// `r·dx ≤ λ/2` that divides both `nx` and `ny` (1: every pixel).
    fn coarsening(&self) -> usize {
        let g = &self.lattice;
        let wavelength = 2.0 * std::f64::consts::PI / self.wavenumber;
        (1..=((0.5 * wavelength / g.dx.max(g.dy) + 1e-9).floor() as usize).max(1))
            .rev()
            .find(|r| g.nx % r == 0 && g.ny % r == 0)
            .unwrap_or(1)
    }

    /// The transpose of [`SourceModel::field`]: for `weights` on the plane (row-major `(ny, nx)`),
    /// `Σ_pixels weights · field(δ_e)` for every element `e` (its pressure on the plane for unit
    /// drive, weighted and summed), with the same rasters, projections, coarse pixels and
    /// interpolation. With the transposed march as weights this is each element's pressure at
    /// one point ([`crate::Simulation::element_responses`]). Where the elements' planes are kept
    /// (any field made them) it is a dot product with each; else the Rayleigh part costs what one
    /// `field` call does.
    pub fn transposed(&self, weights: &[C64]) -> Result<Vec<C64>> {
        Ok(self.transposed_many(&[weights.to_vec()])?.remove(0))
    }

    /// [`SourceModel::transposed`] of several weight fields at once (`out[field][element]`): a dot
    /// product of each with every element's kept plane (made now if no field has made them: two
    /// fields or more repay them), else the Rayleigh kernel evaluated once for all of them at the
    /// quadrature points.
    pub fn transposed_many(&self, weights: &[Vec<C64>]) -> Result<Vec<Vec<C64>>> {
        let g = &self.grid;
        if let Some(w) = weights.iter().find(|w| w.len() != g.lateral_len()) {
            return Err(HasError::invalid("weights", format!("has {} samples, grid has {}", w.len(), g.lateral_len())));
        }
        let mut out: Vec<Vec<C64>> = weights
            .iter()
            .map(|w| {
                self.footprints
                    .iter()
                    .map(|fp| match fp {
                        Footprint::Raster(px) => px.iter().map(|&(i, a)| w[i as usize] * a).sum(),
                        Footprint::Plane(p) => p.iter().zip(w).map(|(a, w)| a * w).sum(),
                        Footprint::Points(_) => C64::new(0.0, 0.0),
                    })
                    .collect()
            })
            .collect();
        if self.footprints.iter().any(|fp| !fp.points().is_empty()) {
            // One field alone makes no planes for itself: they would cost what its sum over the
            // points costs, and their memory (0.6 GB for 1024 elements at 650 kHz).
            let kept = if weights.len() > 1 { self.kept_projections() } else { self.projections.get() };
            match kept {
                Some(p) => self.add_transposed_projected(p, weights, &mut out),
                None => {
                    let at = self.at_quadrature_points(weights);
                    for (o, at) in out.iter_mut().zip(&at) {
                        o.iter_mut().zip(self.over_points(|n, _| at[n])).for_each(|(o, v)| *o += v);
                    }
                }
            }
        }
        out.iter_mut().flatten().for_each(|o| *o *= self.face_pressure);
        Ok(out)
    }

    /// Adds, per projected element `e`, `Σ_c w_c·plane_e(c)` over the coarse pixels of each of
    /// `weights` carried to them ([`SourceModel::coarse_weights`]): the same sum as over the
    /// element's quadrature points, `Σ_q area_q·Σ_c w_c·K(c - q)`, in the other order, the kernel
    /// read from the kept planes instead of evaluated (a plane's dot product per element instead
    /// of a kernel sum per point; the planes in single precision, as every field's).
    fn add_transposed_projected(&self, p: &Projections, weights: &[Vec<C64>], out: &mut [Vec<C64>]) {
        let coarse: Vec<Vec<C64>> = weights.iter().map(|w| self.coarse_weights(w)).collect();
        let sums: Vec<Vec<C64>> = p
            .planes
            .par_iter()
            .map(|plane| {
                coarse.iter().map(|w| w.iter().zip(plane).map(|(w, q)| w * C64::new(q.re as f64, q.im as f64)).sum::<C64>()).collect()
            })
            .collect();
        for (&e, sum) in p.elements.iter().zip(&sums) {
            for (o, v) in out.iter_mut().zip(sum) {
                o[e] += v;
            }
        }
    }

    /// The Rayleigh integral of each of `weights` (fields on the plane, row-major `(ny, nx)`) at
    /// every quadrature point of the projected elements, in element order (`out[field][point]`):
    /// the transposed projection before its sum over each element's points, on the coarse
    /// pixels of [`SourceModel::add_rayleigh`] (the weights' transposed interpolation). The
    /// kernel is evaluated once for all fields.
    fn at_quadrature_points(&self, weights: &[Vec<C64>]) -> Vec<Vec<C64>> {
        let coarse: Vec<Vec<C64>> = weights.iter().map(|w| self.coarse_weights(w)).collect();
        let (xs, ys) = self.coarse_pixels();
        crate::physics::rayleigh::at_points(&coarse, &xs, &ys, self.grid.z0, &self.quadrature_points(), self.wavenumber, self.attenuation)
    }

    /// Per element, `Σ_q area_q · f(n, q)` over its quadrature points `q` (`n` counts the points
    /// of all elements in order, as [`SourceModel::at_quadrature_points`] lists them; 0 for an
    /// element without points).
    fn over_points(&self, f: impl Fn(usize, &SurfacePoint) -> C64) -> Vec<C64> {
        let mut next = 0;
        self.footprints
            .iter()
            .map(|fp| {
                fp.points()
                    .iter()
                    .map(|q| {
                        next += 1;
                        f(next - 1, q) * q.area
                    })
                    .sum()
            })
            .collect()
    }

    /// The projected elements' quadrature points, in element order.
    fn quadrature_points(&self) -> Vec<[f64; 3]> {
        self.footprints.iter().flat_map(Footprint::points).map(|q| q.position).collect()
    }

    /// Weights on every pixel carried to the coarse pixels of the sums (the transpose of their
    /// Fourier interpolation; unchanged where the sums run on every pixel).
    fn coarse_weights(&self, weights: &[C64]) -> Vec<C64> {
        let ((cx, cy), g) = (self.coarse_dims(), &self.grid);
        if (cx, cy) == (g.nx, g.ny) {
            weights.to_vec()
        } else {
            fourier_resample_transposed(weights, cx, cy, g.nx, g.ny)
        }
    }

    /// The number of coarse pixels of the sums along x and y.
    fn coarse_dims(&self) -> (usize, usize) {
        let (l, r) = (&self.lattice, self.coarsening());
        (l.nx / r, l.ny / r)
    }

    /// The x and y (m) of the coarse pixels of the sums.
    fn coarse_pixels(&self) -> (Vec<f64>, Vec<f64>) {
        let (l, r) = (&self.lattice, self.coarsening());
        ((0..l.nx / r).map(|i| l.x(r * i)).collect(), (0..l.ny / r).map(|j| l.y(r * j)).collect())
    }

    /// The projection of an element symmetric about the z axis (unit drive): the Rayleigh
    /// integral on the radial line `y = 0, x = m·h` (`h` = grid spacing / [`RADIAL_OVERSAMPLING`]),
    /// then Catmull–Rom cubic interpolation in `rho = sqrt(x² + y²)` at every pixel (the profile is
    /// even in `rho`, so `p(-h) = p(h)` closes the first interval).
    fn symmetric_projection(&self, points: &[SurfacePoint]) -> Vec<C64> {
        let g = &self.grid;
        let h = g.dx.min(g.dy) / RADIAL_OVERSAMPLING as f64;
        let rho_max = (g.x(0).powi(2) + g.y(0).powi(2)).sqrt();
        let n = (rho_max / h).ceil() as usize + 3;
        let weighted: Vec<([f64; 3], C64)> = points.iter().map(|p| (p.position, C64::new(p.area, 0.0))).collect();
        let sources = Sources::new(&weighted, g.z0, self.wavenumber, self.attenuation);
        let xs: Vec<f64> = (0..n).map(|m| m as f64 * h).collect();
        let profile: Vec<C64> = xs.par_chunks(64).flat_map_iter(|chunk| sources.row(chunk, 0.0)).collect();
        let at = |m: isize| profile[m.unsigned_abs()];
        (0..g.lateral_len())
            .map(|i| {
                let rho = g.x(i % g.nx).hypot(g.y(i / g.nx)) / h;
                let m = rho.floor() as isize;
                let t = rho - m as f64;
                let (p0, p1, p2, p3) = (at(m - 1), at(m), at(m + 1), at(m + 2));
                // Catmull–Rom: exact for cubics through p1 (t = 0) and p2 (t = 1).
                p1 + 0.5 * t * (p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0)))
            })
            .collect()
    }
}

/// Quadrature spacing on a flat element whose nearest point lies `distance` (m) before the plane:
/// `h = sqrt(λ·D) / 4`, between λ/8 and λ/3. The midpoint rule misses the curvature of the
/// phase across a cell, about `k·h²/(8·D)` = 2π/128 ≈ 0.05 rad at this `h`; its other error, a
/// factor `sinc(k·h·sin ψ / 2)` on the radiation at angle ψ from the element's normal, stays
/// below 1.5 % inside the main lobe of an element a few wavelengths wide (`sin ψ < λ/d`) at λ/3.
/// Elements far from the plane (most of a hemisphere) thus take 7 times fewer points than λ/8.
pub fn element_spacing(wavelength: f64, distance: f64) -> f64 {
    ((wavelength * distance.max(0.0)).sqrt() / 4.0).clamp(wavelength / 8.0, wavelength / 3.0)
}

/// Exact pixel coverage of a flat element lying in the plane of the grid (squares: product of 1-D
/// overlaps; discs: 8 x 8 sub-samples per pixel).
fn rasterise(e: &Surface, g: &Grid) -> Vec<(u32, f64)> {
    let Surface::Flat { center, size, shape, .. } = *e else {
        return vec![];
    };
    let half = 0.5 * size;
    let overlap = |c: f64, d: f64, lo: f64, hi: f64| ((c + 0.5 * d).min(hi) - (c - 0.5 * d).max(lo)).max(0.0) / d;
    let range = |c: f64, d: f64, n: usize, mid: usize| {
        let lo = (((c - half) / d).floor() as i64 + mid as i64 - 1).max(0) as usize;
        let hi = (((c + half) / d).ceil() as i64 + mid as i64 + 1).clamp(0, n as i64 - 1) as usize;
        lo..=hi
    };
    let mut px = Vec::new();
    for j in range(center[1], g.dy, g.ny, g.ny / 2) {
        for i in range(center[0], g.dx, g.nx, g.nx / 2) {
            let (x, y) = (g.x(i), g.y(j));
            let w = match shape {
                ElementShape::Square => {
                    overlap(x, g.dx, center[0] - half, center[0] + half) * overlap(y, g.dy, center[1] - half, center[1] + half)
                }
                ElementShape::Disc => {
                    let m = 8;
                    let mut hits = 0;
                    for a in 0..m {
                        for b in 0..m {
                            let sx = x + g.dx * ((a as f64 + 0.5) / m as f64 - 0.5) - center[0];
                            let sy = y + g.dy * ((b as f64 + 0.5) / m as f64 - 0.5) - center[1];
                            if sx * sx + sy * sy <= half * half {
                                hits += 1;
                            }
                        }
                    }
                    hits as f64 / (m * m) as f64
                }
            };
            if w > 0.0 {
                px.push(((j * g.nx + i) as u32, w));
            }
        }
    }
    px
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::transducer::Transducer;
    use crate::physics::upsample::tests::random;

    #[test]
    fn symmetric_cap_projection_matches_the_direct_sum_at_every_pixel() {
        // A small bowl (R 30 mm, aperture 24 mm, 1 MHz) on a 64 x 64 grid: the radial line and
        // interpolation against the slow obvious reference, the double-precision Rayleigh sum at
        // every pixel.
        // Catmull–Rom at h = λ/32 has an error of order (k·h)^4/384 relative to the profile's
        // curvature scale: a few 1e-5 of the peak; 2e-4 leaves room for the steep rim region.
        let k = 2.0 * std::f64::consts::PI * 1e6 / 1500.0;
        let g = Grid::new(64, 64, 0.375e-3, 0.375e-3, 2, 0.375e-3, 4e-3).unwrap();
        let bowl = Transducer::bowl(30e-3, 24e-3).unwrap();
        let fast = SourceModel::new(&bowl, &g, 1.0, k, 0.0).unwrap().field(&[C64::new(1.0, 0.0)]).unwrap();
        let points: Vec<(SurfacePoint, C64)> = bowl.elements[0]
            .quadrature((2.0 * std::f64::consts::PI / k / 8.0).min(g.dx / 2.0))
            .into_iter()
            .map(|p| (p, C64::new(1.0, 0.0)))
            .collect();
        let weighted: Vec<([f64; 3], C64)> = points.iter().map(|(p, a)| (p.position, a * p.area)).collect();
        let xs: Vec<f64> = (0..g.nx).map(|i| g.x(i)).collect();
        let slow: Vec<C64> = (0..g.ny).flat_map(|j| crate::physics::rayleigh::row_f64(&weighted, &xs, g.y(j), g.z0, k, 0.0)).collect();
        let peak = slow.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let err = fast.iter().zip(&slow).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak;
        eprintln!("[cap projection] max error {err:.2e} of the peak (tol 2e-4)");
        assert!(err < 2e-4, "max error {err:.2e} of the peak");
    }

    #[test]
    fn transposed_source_passes_the_dot_product_test() {
        // Σ w·field(d) = Σ d·transposed(w) for random drives and weights, for elements projected by
        // the Rayleigh sum on coarse pixels (a small hemisphere at λ/4) and rasterised ones (a
        // planar array). Tolerance 1e-5 of Σ|w|·|field|: both sides sum in single precision
        // (~1e-6, see rayleigh.rs).
        let k = 2.0 * std::f64::consts::PI * 1e6 / 1500.0;
        let hemisphere = Transducer::hemisphere(30e-3, 40f64.to_radians(), 24, 4e-3).unwrap();
        let planar = Transducer::planar_quadrants(4, 2.5e-3, 2.3e-3, 1e-3).unwrap();
        for (name, t, z0) in [("hemisphere", hemisphere, 9e-3), ("planar", planar, 0.0)] {
            let g = Grid::new(96, 90, 0.375e-3, 0.375e-3, 2, 0.375e-3, z0).unwrap();
            let model = SourceModel::new(&t, &g, 2.0, k, 3.0).unwrap();
            let (d, w) = (random(t.elements.len(), 3), random(g.lateral_len(), 4));
            let field = model.field(&d).unwrap();
            let lhs: C64 = w.iter().zip(&field).map(|(a, b)| a * b).sum();
            let scale: f64 = w.iter().zip(&field).map(|(a, b)| a.norm() * b.norm()).sum();
            let rhs: C64 = model.transposed(&w).unwrap().iter().zip(&d).map(|(a, b)| a * b).sum();
            let err = (lhs - rhs).norm() / scale;
            eprintln!("[{name}] transposed source: relative error {err:.1e} (tolerance 1e-5)");
            assert!(err < 1e-5, "{name}: {lhs} vs {rhs}");
        }
    }

    /// A 24-element hemisphere (radius 30 mm, 40°) at 1 MHz before a 96 x 90 plane of λ/4
    /// pixels (its sums on coarse pixels): the grid and the source model.
    fn small_hemisphere() -> (Grid, SourceModel) {
        let k = 2.0 * std::f64::consts::PI * 1e6 / 1500.0;
        let hemisphere = Transducer::hemisphere(30e-3, 40f64.to_radians(), 24, 4e-3).unwrap();
        let g = Grid::new(96, 90, 0.375e-3, 0.375e-3, 2, 0.375e-3, 9e-3).unwrap();
        let model = SourceModel::new(&hemisphere, &g, 2.0, k, 3.0).unwrap();
        (g, model)
    }

    /// A model carried to a coarser grid of the same period ([`SourceModel::on_grid`]) keeps its
    /// sums and projections and resamples them: its field is the band-limited interpolant of the
    /// same coarse sums as the model's own, so at the sums' pixels (every 3rd and 4th pixel of
    /// this grid) it equals the model's field there to rounding (1e-12 of the peak). A grid of
    /// another period is projected anew. A model is reused by [`SourceModel::new_reusing`] of its
    /// own arguments, a carried one is not (its sums are not the grid's own).
    #[test]
    fn a_model_carried_to_a_coarser_grid_of_the_same_period_resamples_its_sums() {
        let (g, model) = small_hemisphere();
        let hemisphere = Transducer::hemisphere(30e-3, 40f64.to_radians(), 24, 4e-3).unwrap();
        // The same period (36 x 33.75 mm) and first pixel; the sums run every 0.75 mm.
        let coarse = Grid::new(72, 60, 0.5e-3, 0.5625e-3, 2, 0.375e-3, 9e-3).unwrap();
        let carried = model.on_grid(&hemisphere, &coarse).unwrap();
        assert!(Arc::ptr_eq(&carried.projections, &model.projections) && carried.coarse_dims() == model.coarse_dims());
        let drive = random(model.len(), 9);
        let (a, fine) = (carried.field(&drive).unwrap(), model.field(&drive).unwrap());
        let peak = fine.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let mut compared = 0;
        for (j, i) in (0..coarse.ny).step_by(4).flat_map(|j| (0..coarse.nx).step_by(3).map(move |i| (j, i))) {
            let (fi, fj) = (4 * i / 3, 3 * j / 2);
            assert!((coarse.x(i) - g.x(fi)).abs() < 1e-12 && (coarse.y(j) - g.y(fj)).abs() < 1e-12);
            let err = (a[j * coarse.nx + i] - fine[fj * g.nx + fi]).norm();
            assert!(err < 1e-12 * peak, "pixel ({i}, {j}): {err:e} of {peak}");
            compared += 1;
        }
        assert_eq!(compared, 24 * 15);
        let other = Grid::new(60, 60, 0.5e-3, 0.5e-3, 2, 0.375e-3, 9e-3).unwrap();
        assert!(!Arc::ptr_eq(&model.on_grid(&hemisphere, &other).unwrap().projections, &model.projections));
        let k = model.wavenumber;
        let reused = SourceModel::new_reusing(&hemisphere, &g, 2.0, k, 3.0, Some(&model)).unwrap();
        assert!(Arc::ptr_eq(&reused.projections, &model.projections));
        for (grid, pressure, kept) in [(&g, 2.5, &model), (&coarse, 2.0, &carried)] {
            let fresh = SourceModel::new_reusing(&hemisphere, grid, pressure, k, 3.0, Some(kept)).unwrap();
            assert!(!Arc::ptr_eq(&fresh.projections, &model.projections));
        }
    }

    /// Fields as weighted sums of the elements' kept planes against the Rayleigh sum over every
    /// quadrature point of the driven elements (`add_rayleigh`), for a small hemisphere on
    /// coarse pixels: random drives, two at once, and one element alone. Within 1e-5 of the
    /// field's peak: both sum in single precision (~1e-6 each, see rayleigh.rs).
    #[test]
    fn fields_from_kept_element_planes_match_the_sum_over_points() {
        let (g, model) = small_hemisphere();
        assert_eq!(model.coarsening(), 2);
        let n = model.len();
        let mut alone = vec![C64::new(0.0, 0.0); n];
        alone[7] = C64::new(0.3, -1.2);
        let drives = [random(n, 5), random(n, 6), alone];
        let fields = model.fields(&drives).unwrap();
        assert!(model.projections.get().is_some_and(|p| p.planes.len() == n));
        for (d, field) in drives.iter().zip(&fields) {
            let driven: Vec<(usize, Vec<C64>)> =
                (0..n).filter(|&e| d[e] != C64::new(0.0, 0.0)).map(|e| (e, vec![d[e] * model.face_pressure])).collect();
            let mut direct = vec![vec![C64::new(0.0, 0.0); g.lateral_len()]];
            model.add_point_sums(&driven, &mut direct);
            let peak = direct[0].iter().map(|v| v.norm()).fold(0.0, f64::max);
            let err = field.iter().zip(&direct[0]).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak;
            assert!(peak > 0.0 && err < 1e-5, "error {err:.1e} of the peak");
        }
        // A later call with the kept planes gives the same field as the first.
        assert_eq!(model.field(&drives[0]).unwrap(), fields[0]);
    }

    /// The transposed projection from the kept planes against its sum over every quadrature
    /// point (the kernel at each point, summed over each element's points: the path without kept
    /// planes), for the small hemisphere on coarse pixels and three random weight fields. Within
    /// 1e-5 of the largest response: both sum in single precision (~1e-6 each).
    #[test]
    fn transposed_projections_from_kept_planes_match_the_sum_over_points() {
        let (g, model) = small_hemisphere();
        let weights = [random(g.lateral_len(), 8), random(g.lateral_len(), 9), random(g.lateral_len(), 10)];
        // One field alone makes no planes; two do.
        let alone = model.transposed(&weights[0]).unwrap();
        assert!(model.projections.get().is_none());
        let fast = model.transposed_many(&weights).unwrap();
        assert!(model.projections.get().is_some());
        let at = model.at_quadrature_points(&weights);
        for (k, (fast, at)) in fast.iter().zip(&at).enumerate() {
            let slow: Vec<C64> = model.over_points(|n, _| at[n]).into_iter().map(|v| v * model.face_pressure).collect();
            let peak = slow.iter().map(|v| v.norm()).fold(0.0, f64::max);
            let err = fast.iter().zip(&slow).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak;
            eprintln!("[transposed from kept planes] field {k}: {err:.1e} of the largest response (tolerance 1e-5)");
            assert!(peak > 0.0 && err < 1e-5, "field {k}: {err:.1e}");
            if k == 0 {
                let alone_err = alone.iter().zip(&slow).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max) / peak;
                assert!(alone_err < 1e-9, "one field alone sums over the points: {alone_err:.1e}");
            }
        }
    }

    #[test]
    fn rasterised_square_carries_its_area_and_nearly_its_centroid() {
        let g = Grid::new(64, 64, 0.7e-3, 0.7e-3, 2, 0.7e-3, 0.0).unwrap();
        let e = Surface::Flat { center: [1.3e-3, -2.1e-3, 0.0], normal: [0.0, 0.0, 1.0], size: 2.3e-3, shape: ElementShape::Square };
        let px = rasterise(&e, &g);
        let area: f64 = px.iter().map(|&(_, w)| w * g.dx * g.dy).sum();
        assert!((area / 2.3e-3f64.powi(2) - 1.0).abs() < 1e-12);
        let cx: f64 = px.iter().map(|&(i, w)| w * g.dx * g.dy * g.x(i as usize % 64)).sum::<f64>() / area;
        // Partly covered edge pixels put their share at the pixel centre: the centroid is exact
        // only to a fraction of a pixel (here the two edges' errors nearly cancel).
        assert!((cx - 1.3e-3).abs() < 0.05 * g.dx, "centroid off by {} m", cx - 1.3e-3);
    }
}
