//! Changes of medium between two slabs: the pressure reflection and transmission of each plane
//! wave of the angular spectrum.
//!
//! For a plane wave of transverse wavenumber `kt` crossing a planar interface from medium `a`
//! into medium `b` (densities `rho`, complex wavenumbers `k = omega/c + i·alpha`), with
//! `kz = sqrt(k² - kt²)` (the root with `Im kz >= 0`, so evanescent waves decay):
//!
//! `R_ab(kt) = (rho_b·kz_a - rho_a·kz_b) / (rho_b·kz_a + rho_a·kz_b)`,  `T_ab = 1 + R_ab`
//!
//! (pressure continuity and continuity of the normal particle velocity; e.g. Brekhovskikh,
//! *Waves in Layered Media*, 1980, §2). This is exact at a planar interface, including total
//! reflection beyond the critical angle; a wave crossing back from `b` to `a` sees
//! `R_ba = -R_ab`. At normal incidence `R = (Z_b - Z_a) / (Z_a + Z_b)`.
//!
//! Where the interface varies across the slice, the field is decomposed by material pair as in
//! the wave-propagation method (Brenner & Singer, Appl Opt 32(26), 1993): the reflected wave is
//! `Σ_pairs M_ab(x, y) · IFFT(R_ab · FFT(p))`, with `M_ab` the pixels where slab `n - 1` holds
//! `a` and slab `n` holds `b`. Slices with more distinct pairs than [`MAX_SPECTRAL_PAIRS`] (voxel
//! maps and CTs of continuously varying properties) use the normal-incidence coefficient pixel
//! by pixel.
//!
//! The march carries the *flux-normalised* field `ψ = p·sqrt(Z_s/Z)` (`Z = rho·c` of the pixel's
//! medium, `Z_s` of the source's): the angular spectrum keeps `Σ|ψ|²`, so a wave moving across
//! the plane from one impedance into another (the risers of a staircase face, which no z
//! interface sees) keeps its power instead of its pressure, and a wall's treads take the loss its
//! risers do not (`risers.rs`). Crossing a face, `ψ` is transmitted
//! by `(1 + R)·sqrt(Z_a/Z_b)`, which is `sqrt(1 - R²)` at normal incidence in either direction;
//! reflected waves stay in the medium they came from and keep `R`. Recorded values are pressures
//! (`p = ψ·sqrt(Z/Z_s)`).
//!
//! A CT face inside a cell is applied at the nearest plane (the cell takes the impedance at its
//! centre) while the cell's averaged slowness keeps the delay through it; what the plane cannot
//! keep is where the face reflects. A per-pixel face is therefore given the phase of its true
//! position ([`face_phase`]): reflected forward-going waves carry `R·exp(i·φ)`, backward-going
//! ones `-R·exp(-i·φ)`, with `φ = 2·(omega·s_m + i·alpha_m)·δ` for the misplaced material
//! (slowness `s_m`, attenuation `alpha_m`, thickness `δ`, signed: + when the face lies beyond the
//! plane) found from the averaged slowness of the cells on either side. Without it the round
//! trips inside a curved bone wall, whose faces snap by up to half a step, add up with phases
//! spread over ±k·dz and the wall's reverberation is lost.

use super::elastic::{filters, single_filters, ElasticPair, Filters, Side};
use super::faces::{face_phase, is_wall};
use super::walls::{walls, WallFilters, WallGroup, WallKey, Walls};
use crate::physics::fft::{Fft2, FftWorkspace};
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::{Complex, Complex32 as C32, Complex64 as C64};
use rayon::prelude::*;
use rustfft::FftNum;
use std::collections::HashMap;
use std::sync::Arc;

mod layered_faces;
use layered_faces::LayeredFaces;
mod transposed;

/// How a change of medium between slabs is applied.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum InterfaceModel {
    /// Plane-wave coefficients of every angular-spectrum component (angle-dependent, with total
    /// reflection beyond the critical angle), and the reverberation between interfaces that
    /// reflect strongly (thin layers such as bone plates).
    #[default]
    Angular,
    /// The normal-incidence coefficient `T = 2·Z_b / (Z_a + Z_b)` pixel by pixel, one way (the
    /// original HAS step; overestimates the transmission of oblique waves).
    NormalIncidence,
}

impl InterfaceModel {
    /// Parses `"angular"` or `"normal-incidence"`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "angular" => Some(InterfaceModel::Angular),
            "normal-incidence" => Some(InterfaceModel::NormalIncidence),
            _ => None,
        }
    }

    /// The name used in scenario files.
    pub fn name(&self) -> &'static str {
        match self {
            InterfaceModel::Angular => "angular",
            InterfaceModel::NormalIncidence => "normal-incidence",
        }
    }
}

/// More distinct material pairs than this on one interface plane: normal incidence per pixel.
pub const MAX_SPECTRAL_PAIRS: usize = 8;

/// At most this many distinct material pairs get a spectral coefficient in one plan (each is a
/// full spectrum, 16 bytes per grid sample); interfaces needing more use normal incidence per
/// pixel (a voxel map of continuously varying properties).
pub const MAX_PLAN_PAIRS: usize = 64;

/// At most this many bytes of a plan's spectra for faces between a solid and another medium
/// (`elastic.rs`: 4-16 spectra per material pair, 16 bytes per grid sample each); interfaces
/// needing more cross per pixel and convert no shear.
pub const MAX_ELASTIC_BYTES: u64 = 512 << 20;

/// The number of spectra the elastic filters of the pair at pixel `i` from `from` into `to` hold:
/// per direction, the waves arriving times the waves leaving (SV only in a solid).
fn spectra(from: &SliceProperties, to: &SliceProperties, i: usize) -> usize {
    let waves = |s: &SliceProperties| if s.shear_speed(i) > 0.0 { 2 } else { 1 };
    let (a, b) = (waves(from), waves(to));
    a * (a + b) + b * (a + b)
}

/// Spectral coefficients shared by every interface of a plan, by material pair (fluid pairs,
/// oblique walls, and pairs with a solid, [`super::elastic`]).
#[derive(Default)]
pub(crate) struct Coefficients(
    HashMap<(Key, Key), Arc<Vec<C64>>>,
    pub(super) HashMap<WallKey, WallFilters>,
    HashMap<(Key, Key), Arc<Filters<f64>>>,
    HashMap<layered_faces::FaceKey, Arc<Filters<f64>>>,
);

impl Coefficients {
    /// The spectra the plan's elastic filters hold (region pairs and a CT's faces between
    /// layers), which [`MAX_ELASTIC_BYTES`] bounds.
    fn elastic_spectra(&self) -> usize {
        self.2.values().chain(self.3.values()).map(|f| f.iter().flatten().flatten().flatten().count()).sum()
    }
}

/// One interface plane: the operator `p ↦ R ⊛ p` giving the reflected wave of an incident one
/// (in double precision, or single for a single-precision march).
pub(crate) struct Interface<T: FftNum = f64> {
    /// Largest normal-incidence `|R|` on the plane (how strongly it reflects).
    pub strength: f64,
    /// Whether the slabs after it take two reference media (`references.rs`): faces on the plane
    /// between layers that cover part of it (a CT's, or a region's that ends beside the beam),
    /// between which the waves in bone run in every direction of the spectrum (a plate, not a
    /// cap about the focus).
    pub two_media: bool,
    kind: Kind<T>,
}

enum Kind<T: FftNum> {
    /// `R(x, y)` applied pixel by pixel, kept on the pixels where it is not zero (in increasing
    /// order; through a head, the few percent of the plane where the slices differ), with the
    /// factor `exp(i·φ)` of each face's true position (`None`: every face on the plane).
    /// Pixels of oblique walls among them take their walls' filters instead (`oblique.rs`).
    Pointwise { pixels: Arc<Vec<u32>>, r: Vec<T>, phase: Option<Vec<Complex<T>>>, walls: Option<Walls<T>> },
    /// `Σ_pairs M_ab · IFFT(R_ab · FFT(p))`.
    Spectral(Vec<Pair<T>>),
    /// Pairs of which at least one holds a solid: ψ and the SV field crossed together
    /// ([`super::elastic`]).
    Elastic(Vec<ElasticPair<T>>),
}

struct Pair<T: FftNum> {
    /// `sqrt(Z_a/Z_b)`: the flux normalisation of the wave crossing from `a` into `b`.
    scale: f64,
    /// The pixels of this pair; `None`: every pixel.
    pixels: Option<Vec<u32>>,
    /// `R_ab(kx, ky) / (nx·ny)` in the transposed spectrum layout `(nx, ny)`.
    coefficient: Arc<Vec<Complex<T>>>,
}

/// The slabs about an interface that its faces read: `column[face - 1]` and `column[face]` on
/// either side of it, [`super::oblique::normal_slabs`] more on each side (repeated at the
/// grid's ends).
pub(crate) struct Around<'a> {
    pub column: Vec<&'a SliceProperties>,
    pub face: usize,
}

impl Around<'_> {
    /// The slab before the face's `from` and the one after its `to`.
    pub(super) fn outer(&self) -> (&SliceProperties, &SliceProperties) {
        (self.column[self.face - 2], self.column[self.face + 1])
    }
}

/// A pointwise interface's pixels, their coefficients `R` and their faces' factors `exp(i·φ)`.
pub(crate) type PointwiseFaces<'a, T> = (&'a Arc<Vec<u32>>, &'a [T], Option<&'a [Complex<T>]>);

/// Properties of one pixel as exact bits (equal bits: the same material): sound speed, density,
/// attenuation, shear speed and shear attenuation.
pub(super) type Key = [u64; 5];

/// A material pair's first pixel and all its pixels.
type PairPixels = (usize, Vec<u32>);

/// [`key`] with the shear wave's bits left 0 (a face that converts no shear).
pub(super) fn fluid_key(s: &SliceProperties, i: usize) -> Key {
    [s.sound_speed[i].to_bits(), s.density[i].to_bits(), s.attenuation[i].to_bits(), 0, 0]
}

pub(super) fn key(s: &SliceProperties, i: usize) -> Key {
    let mut key = fluid_key(s, i);
    if let Some(m) = &s.shear {
        key[3..].copy_from_slice(&[m.sound_speed[i].to_bits(), m.attenuation[i].to_bits()]);
    }
    key
}

impl Interface {
    /// The same operator in single precision; `copy` gives each spectral coefficient's
    /// single-precision copy (shared as the originals are).
    pub(crate) fn single(&self, copy: &mut impl FnMut(&Arc<Vec<C64>>) -> Arc<Vec<C32>>) -> Interface<f32> {
        let kind = match &self.kind {
            Kind::Pointwise { pixels, r, phase, walls } => Kind::Pointwise {
                pixels: pixels.clone(),
                r: r.iter().map(|&r| r as f32).collect(),
                phase: phase.as_ref().map(|p| p.iter().map(|&p| C32::new(p.re as f32, p.im as f32)).collect()),
                walls: walls.as_ref().map(|w| Walls {
                    grouped: w.grouped.clone(),
                    groups: w
                        .groups
                        .iter()
                        .map(|g| WallGroup {
                            members: g.members.clone(),
                            filters: Arc::new(g.filters.as_ref().clone().map(|d| d.map(|o| o.map(|w| w.map(|f| copy(&f)))))),
                            normal: g.normal,
                            ahead: g.ahead.clone(),
                        })
                        .collect(),
                    kept: w.kept.clone(),
                }),
            },
            Kind::Spectral(pairs) => Kind::Spectral(
                pairs.iter().map(|p| Pair { scale: p.scale, pixels: p.pixels.clone(), coefficient: copy(&p.coefficient) }).collect(),
            ),
            Kind::Elastic(pairs) => Kind::Elastic(
                pairs.iter().map(|p| ElasticPair { pixels: p.pixels.clone(), filters: Arc::new(single_filters(&p.filters)) }).collect(),
            ),
        };
        Interface { strength: self.strength, two_media: self.two_media, kind }
    }

    /// The interface from slab `from` into slab `to`, or `None` where they are equal. With
    /// `around` (the slabs before `from` and after `to`), a pointwise interface gives its faces
    /// the phases of their positions inside the cells ([`face_phase`]) and, with the angular
    /// model, a wall's faces the coefficient of the staircase's treads (`risers.rs`); without,
    /// its faces lie on the plane (the faces of regions, which the default grid puts on planes).
    pub fn new(
        grid: &Grid,
        from: &SliceProperties,
        to: &SliceProperties,
        omega: f64,
        model: InterfaceModel,
        around: Option<&Around>,
        shared: &mut Coefficients,
    ) -> Option<Self> {
        if from == to {
            return None;
        }
        let n = from.sound_speed.len();
        let normal: Vec<f64> = (0..n)
            .into_par_iter()
            .map(|i| {
                let (za, zb) = (from.density[i] * from.sound_speed[i], to.density[i] * to.sound_speed[i]);
                (zb - za) / (za + zb)
            })
            .collect();
        let strength = normal.par_iter().map(|r| r.abs()).reduce(|| 0.0, f64::max);
        let pointwise = |shared: &mut Coefficients| {
            let pixels: Vec<u32> = (0..n as u32).into_par_iter().filter(|&i| normal[i as usize] != 0.0).collect();
            let slabs = around.map(|a| {
                let (before, after) = a.outer();
                [before, from, to, after]
            });
            // A CT's or voxel map's walls cross the planes as staircases whose risers the angular
            // spectrum passes unreflected: their treads take that share of the wall's loss.
            let wall: Vec<bool> = pixels
                .par_iter()
                .map(|&i| model == InterfaceModel::Angular && slabs.is_some_and(|slabs| is_wall(slabs, i as usize)))
                .collect();
            let r = pixels
                .par_iter()
                .zip(&wall)
                .map(|(&i, &wall)| {
                    let (i, r) = (i as usize, normal[i as usize]);
                    if wall {
                        super::risers::tread_coefficient(r, grid, (from, to), i)
                    } else {
                        r
                    }
                })
                .collect();
            let phase = slabs.and_then(|slabs| {
                let phase: Vec<C64> =
                    pixels.par_iter().map(|&i| (C64::i() * face_phase(slabs, i as usize, omega, grid.dz)).exp()).collect();
                phase.iter().any(|&p| p != C64::new(1.0, 0.0)).then_some(phase)
            });
            let walls = around.and_then(|a| walls(grid, omega, a, &pixels, &wall, shared));
            Some(Interface { strength, two_media: false, kind: Kind::Pointwise { pixels: Arc::new(pixels), r, phase, walls } })
        };
        if model == InterfaceModel::NormalIncidence {
            return pointwise(shared);
        }
        // A planar wall of a CT or voxel map takes its own filters even where its plane holds few
        // material pairs (a CT sampled on its own voxels): the pairs' coefficients are the plane's.
        let mut made = around.map(|_| pointwise(shared));
        if made.as_ref().is_some_and(|i| i.as_ref().is_some_and(|i| i.walls().is_some())) {
            return made.flatten();
        }
        // A CT's or voxel map's faces on the plane where a solid meets another medium convert,
        // where they lie between layers (`layered_faces.rs`).
        if let Some(a) = around {
            match layered_faces::converting_faces(grid, (from, to), a, omega, strength, shared) {
                LayeredFaces::Converting(i) => return Some(i),
                LayeredFaces::Pass => return None,
                LayeredFaces::No => {}
            }
        }
        let mut pointwise = |shared: &mut Coefficients| made.take().unwrap_or_else(|| pointwise(shared));
        // Faces of material regions (on planes between planar slabs) convert shear; a CT's or a
        // voxel map's others, whose treads may step across the planes, cross as between fluids.
        // Where a region's faces cover part of the plane (a cylinder's end: a plate that ends
        // beside the beam), the slabs after it take two reference media, as after a CT's faces
        // between layers (`layered_faces.rs`): one mean wavenumber of the bone and the water
        // beside it serves neither (a plate of radius 35 mm: +10.8 % as a fluid, +15.6 % as a
        // solid; with two, -0.1 and -0.8 %).
        let shear = around.is_none();
        let mut pairs: HashMap<(Key, Key), PairPixels> = HashMap::new();
        for i in 0..n {
            let (a, b) = if shear { (key(from, i), key(to, i)) } else { (fluid_key(from, i), fluid_key(to, i)) };
            if a != b {
                let e = pairs.entry((a, b)).or_insert_with(|| (i, Vec::new()));
                e.1.push(i as u32);
            }
            if pairs.len() > MAX_SPECTRAL_PAIRS {
                return pointwise(shared);
            }
        }
        let elastic = shear && pairs.values().any(|&(first, _)| from.shear_speed(first) > 0.0 || to.shear_speed(first) > 0.0);
        if elastic {
            // Pairs with a solid hold 4-16 spectra each (`elastic::Filters`): bounded in bytes.
            let held = shared.elastic_spectra();
            let new: usize =
                pairs.iter().filter(|(k, _)| !shared.2.contains_key(*k)).map(|(_, &(first, _))| spectra(from, to, first)).sum();
            if ((held + new) * n * 16) as u64 > MAX_ELASTIC_BYTES {
                return pointwise(shared);
            }
        } else if shared.0.len() + pairs.keys().filter(|k| !shared.0.contains_key(*k)).count() > MAX_PLAN_PAIRS {
            return pointwise(shared);
        }
        // In order of each pair's first pixel, so the sum is the same on every run.
        let mut pairs: Vec<((Key, Key), PairPixels)> = pairs.into_iter().collect();
        pairs.sort_unstable_by_key(|p| p.1 .0);
        if elastic {
            let pairs: Vec<ElasticPair<f64>> = pairs
                .into_iter()
                .map(|(k, (first, pixels))| ElasticPair {
                    filters: shared
                        .2
                        .entry(k)
                        .or_insert_with(|| Arc::new(filters(grid, &Side::of(from, first, omega), &Side::of(to, first, omega), 0.0)))
                        .clone(),
                    pixels: (pixels.len() < n).then_some(pixels),
                })
                .collect();
            let two_media = pairs.iter().any(|p| p.pixels.is_some());
            return Some(Interface { strength, two_media, kind: Kind::Elastic(pairs) });
        }
        let pairs: Vec<Pair<f64>> = pairs
            .into_iter()
            .map(|(k, (first, pixels))| Pair {
                scale: (impedance(from, first) / impedance(to, first)).sqrt(),
                coefficient: shared
                    .0
                    .entry(k)
                    .or_insert_with(|| Arc::new(spectral_reflection(grid, omega, medium_at(from, first), medium_at(to, first))))
                    .clone(),
                pixels: (pixels.len() < n).then_some(pixels),
            })
            .collect();
        let two_media = pairs.iter().any(|p| p.pixels.is_some());
        Some(Interface { strength, two_media, kind: Kind::Spectral(pairs) })
    }
}

impl<T: FftNum> Interface<T> {
    /// What it holds, as ids of whole planes (arrays as long as the grid's plane): a pointwise
    /// coefficient map (at most a plane: its pixels and their coefficients; a second with its
    /// faces' factors); or each material pair's spectral coefficient (shared between interfaces:
    /// the same id) and, where pairs split the plane, their pixel lists (one plane's worth).
    pub(crate) fn planes(&self) -> Vec<usize> {
        let own = self as *const Self as usize;
        match &self.kind {
            // The pixels and coefficients, and the faces' factors (8 or 16 bytes a pixel).
            Kind::Pointwise { phase, walls, .. } => {
                let mut planes = if phase.is_some() { vec![own, own + 1] } else { vec![own] };
                if let Some(w) = walls {
                    planes.extend(
                        w.groups.iter().flat_map(|g| g.filters.iter().flatten().flatten().flatten().map(|f| Arc::as_ptr(f) as usize)),
                    );
                }
                planes
            }
            Kind::Spectral(pairs) => pairs
                .iter()
                .map(|p| Arc::as_ptr(&p.coefficient) as usize)
                .chain(pairs.iter().any(|p| p.pixels.is_some()).then_some(own))
                .collect(),
            Kind::Elastic(pairs) => pairs
                .iter()
                .flat_map(|p| p.filters.iter().flatten().flatten().flatten().map(|f| Arc::as_ptr(f) as usize))
                .chain(pairs.iter().any(|p| p.pixels.is_some()).then_some(own))
                .collect(),
        }
    }

    /// The pixels where a pointwise interface's `R` is not zero, its values there and the faces'
    /// factors (`None` where every face lies on the plane), or `None` for a spectral interface.
    pub(crate) fn pointwise(&self) -> Option<PointwiseFaces<'_, T>> {
        match &self.kind {
            Kind::Pointwise { pixels, r, phase, .. } => Some((pixels, r, phase.as_deref())),
            Kind::Spectral(_) | Kind::Elastic(_) => None,
        }
    }

    /// The oblique walls of a pointwise interface, if any.
    pub(crate) fn walls(&self) -> Option<&Walls<T>> {
        match &self.kind {
            Kind::Pointwise { walls, .. } => walls.as_ref(),
            Kind::Spectral(_) | Kind::Elastic(_) => None,
        }
    }

    /// Whether it converts between compressional and shear waves: a solid meets another medium
    /// on the plane, or on an oblique wall among its pixels.
    pub(crate) fn converts_shear(&self) -> bool {
        self.elastic().is_some_and(|pairs| pairs.iter().any(|p| p.converts())) || self.walls().is_some_and(|w| w.converts())
    }

    /// The pairs of an interface where a solid meets another medium on a plane, if it is one.
    pub(crate) fn elastic(&self) -> Option<&[ElasticPair<T>]> {
        match &self.kind {
            Kind::Elastic(pairs) => Some(pairs),
            _ => None,
        }
    }

    /// The normal of the interface's first oblique wall (in the order of their first treads), if
    /// it has one: a plate's two faces share it.
    pub(crate) fn wall_normal(&self) -> Option<[f64; 3]> {
        self.walls().and_then(|w| w.groups.first()).map(|g| g.normal)
    }

    /// `out ← R ⊛ p`: the wave reflected by this interface from the incident wave `p` (for a
    /// wave crossing in the other direction, the reflection is `-R ⊛ p`). `out` and `work` are
    /// as long as `p`; `work` is overwritten.
    pub fn reflect(&self, fft: &Fft2<T>, p: &[Complex<T>], out: &mut [Complex<T>], work: &mut [Complex<T>], ws: &mut FftWorkspace<T>) {
        match &self.kind {
            // The march crosses oblique walls itself (`march::cross`); here they would take the
            // treads' coefficients.
            Kind::Pointwise { pixels, r, .. } => scale_pixels(pixels, r, p, out),
            Kind::Spectral(pairs) => {
                let pairs = pairs.iter().map(|p| (&p.pixels, &p.coefficient[..]));
                filter_pairs(fft, pairs, p, out, work, ws);
            }
            // The P wave's reflection alone (the march crosses these faces in `elastic::cross`).
            Kind::Elastic(pairs) => {
                let pairs = pairs.iter().filter_map(|p| p.filters[0][2][0].as_ref().map(|f| (&p.pixels, &f[..])));
                filter_pairs(fft, pairs, p, out, work, ws);
            }
        }
    }
}

/// `out ← Σ_pairs M · IFFT(f · FFT(p))` over `(pixels, filter)` pairs (`None`: every pixel).
fn filter_pairs<'a, T: FftNum>(
    fft: &Fft2<T>,
    pairs: impl Iterator<Item = (&'a Option<Vec<u32>>, &'a [Complex<T>])>,
    p: &[Complex<T>],
    out: &mut [Complex<T>],
    work: &mut [Complex<T>],
    ws: &mut FftWorkspace<T>,
) {
    work.copy_from_slice(p);
    fft.forward(work, ws);
    let spectrum = ws.spectrum.clone();
    out.fill(Complex::new(T::zero(), T::zero()));
    for (pixels, coefficient) in pairs {
        ws.spectrum.iter_mut().zip(&spectrum).zip(coefficient.iter()).for_each(|((s, a), r)| *s = a * r);
        fft.inverse(ws, work);
        match pixels {
            None => out.iter_mut().zip(work.iter()).for_each(|(o, w)| *o = *o + w),
            Some(px) => px.iter().for_each(|&i| out[i as usize] = out[i as usize] + work[i as usize]),
        }
    }
}

impl<T: FftNum + Into<f64>> Interface<T> {
    /// `ψ ← sqrt(Z_from/Z_to)·ψ` on the pixels the interface changes, for a wave that has crossed
    /// it in the direction `sign` (+1: from slab `n - 1` into slab `n`; -1 back) as a pressure
    /// (`ψ + sign·R ⊛ ψ`): what makes the crossing transmit the flux-normalised field (see the
    /// module doc). Diagonal, so its own transpose.
    pub fn normalise_transmitted(&self, field: &mut [Complex<T>], sign: f64) {
        let power = |s: f64| T::from_f64(if sign < 0.0 { 1.0 / s } else { s }).expect("a finite scale");
        match &self.kind {
            Kind::Pointwise { pixels, r, walls, .. } => pixels.iter().zip(r).enumerate().for_each(|(m, (&i, &r))| {
                // A wall's filter transmits the flux-normalised field itself.
                if walls.as_ref().is_some_and(|w| w.grouped[m]) {
                    return;
                }
                let f = &mut field[i as usize];
                *f = *f * power(flux_scale(r.into()));
            }),
            Kind::Spectral(pairs) => {
                for pair in pairs {
                    let s = power(pair.scale);
                    match &pair.pixels {
                        None => field.iter_mut().for_each(|f| *f = *f * s),
                        Some(px) => px.iter().for_each(|&i| field[i as usize] = field[i as usize] * s),
                    }
                }
            }
            // Its filters transmit the flux-normalised fields themselves.
            Kind::Elastic(_) => {}
        }
    }
}

/// `sqrt(Z_a/Z_b)` of a face whose normal-incidence coefficient is `r`: `Z_a/Z_b = (1 - R)/(1 + R)`
/// for `R = (Z_b - Z_a)/(Z_a + Z_b)`. The flux normalisation of a wave crossing it from `a` into `b`.
fn flux_scale(r: f64) -> f64 {
    ((1.0 - r) / (1.0 + r)).sqrt()
}

/// `rho·c` of pixel `i`.
pub(super) fn impedance(s: &SliceProperties, i: usize) -> f64 {
    s.density[i] * s.sound_speed[i]
}

/// `out ← R·p` for `R` non-zero only on `pixels` (with values `r`): zero elsewhere.
fn scale_pixels<T: FftNum>(pixels: &[u32], r: &[T], p: &[Complex<T>], out: &mut [Complex<T>]) {
    out.fill(Complex::new(T::zero(), T::zero()));
    pixels.iter().zip(r).for_each(|(&i, &r)| out[i as usize] = p[i as usize] * r);
}

/// (density, complex wavenumber at `omega`) of pixel `i`.
pub(super) fn medium_at(s: &SliceProperties, i: usize) -> (f64, f64, f64) {
    (s.density[i], s.sound_speed[i], s.attenuation[i])
}

/// `kz = sqrt(k² - kt²)` for the complex wavenumber `k = omega/c + i·alpha`, the root with
/// `Im kz >= 0`.
pub(crate) fn axial_wavenumber(k: C64, kt2: f64) -> C64 {
    let kz = (k * k - kt2).sqrt();
    if kz.im < 0.0 {
        -kz
    } else {
        kz
    }
}

/// The plane-wave pressure reflection coefficient from `a` into `b`, each `(rho, c, alpha)`.
pub fn reflection_coefficient(omega: f64, a: (f64, f64, f64), b: (f64, f64, f64), kt2: f64) -> C64 {
    let kza = axial_wavenumber(C64::new(omega / a.1, a.2), kt2);
    let kzb = axial_wavenumber(C64::new(omega / b.1, b.2), kt2);
    let (num, den) = (b.0 * kza - a.0 * kzb, b.0 * kza + a.0 * kzb);
    if den.norm_sqr() > 0.0 {
        num / den
    } else {
        C64::new(0.0, 0.0)
    }
}

/// `R_ab(kx, ky) / (nx·ny)` on the transposed spectrum layout `(nx, ny)`.
fn spectral_reflection(g: &Grid, omega: f64, a: (f64, f64, f64), b: (f64, f64, f64)) -> Vec<C64> {
    let norm = 1.0 / g.lateral_len() as f64;
    let mut r = Vec::with_capacity(g.lateral_len());
    for i in 0..g.nx {
        let kx = Grid::wavenumber(i, g.nx, g.dx);
        for j in 0..g.ny {
            let ky = Grid::wavenumber(j, g.ny, g.dy);
            r.push(reflection_coefficient(omega, a, b, kx * kx + ky * ky) * norm);
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    const WATER: (f64, f64, f64) = (1000.0, 1500.0, 0.0);
    const BONE: (f64, f64, f64) = (1850.0, 2800.0, 0.0);

    #[test]
    fn normal_incidence_gives_the_impedance_formula() {
        let omega = 2.0 * PI * 5e5;
        let r = reflection_coefficient(omega, WATER, BONE, 0.0);
        let (za, zb) = (1.5e6, 1850.0 * 2800.0);
        assert!((r - C64::new((zb - za) / (za + zb), 0.0)).norm() < 1e-14);
        // The reverse crossing reflects with the opposite sign at every angle.
        for s in [0.0, 0.3, 0.6, 0.9, 1.2] {
            let kt2 = (s * omega / 1500.0).powi(2);
            let sum = reflection_coefficient(omega, WATER, BONE, kt2) + reflection_coefficient(omega, BONE, WATER, kt2);
            assert!(sum.norm() < 1e-12, "{s}: {sum}");
        }
    }

    #[test]
    fn beyond_the_critical_angle_the_reflection_is_total() {
        // Critical angle asin(1500/2800) = 32.4°: |R| = 1 beyond it (lossless), < 1 before.
        let omega = 2.0 * PI * 5e5;
        let k = omega / 1500.0;
        for deg in [33.0_f64, 45.0, 60.0, 80.0] {
            let r = reflection_coefficient(omega, WATER, BONE, (k * deg.to_radians().sin()).powi(2));
            assert!((r.norm() - 1.0).abs() < 1e-12, "{deg}°: |R| = {}", r.norm());
        }
        let r = reflection_coefficient(omega, WATER, BONE, (k * 30f64.to_radians().sin()).powi(2));
        assert!(r.norm() < 0.999, "30°: |R| = {}", r.norm());
    }

    #[test]
    fn energy_flux_is_conserved_at_oblique_incidence() {
        // Lossless media below the critical angle: |R|² + |T|²·(rho_a·kz_b)/(rho_b·kz_a) = 1.
        let omega = 2.0 * PI * 5e5;
        for deg in [0.0_f64, 10.0, 20.0, 30.0] {
            let kt2 = (omega / 1500.0 * deg.to_radians().sin()).powi(2);
            let r = reflection_coefficient(omega, WATER, BONE, kt2);
            let t = r + 1.0;
            let kz = |c: f64| axial_wavenumber(C64::new(omega / c, 0.0), kt2).re;
            let (kza, kzb) = (kz(1500.0), kz(2800.0));
            let flux = r.norm_sqr() + t.norm_sqr() * (WATER.0 * kzb) / (BONE.0 * kza);
            assert!((flux - 1.0).abs() < 1e-12, "{deg}°: {flux}");
        }
    }
}
