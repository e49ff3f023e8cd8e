//! A CT's or voxel map's faces on a plane between layers (a plate, layered bone): each face's
//! plane waves reflected and transmitted exactly, P and SV converted where a solid meets another
//! medium (as at a region's face, [`super::super::elastic`]), with the face placed where it lies
//! inside its cell.
//!
//! A face inside a cell is applied at the nearest plane, and the cell holds neither medium: its
//! slowness is averaged, its impedance the centre's, its shear the centre's solid's. Its
//! scattering is therefore taken between the pure media beyond the face cells (the slabs before
//! and after the pair, which [`super::super::faces::is_wall`] requires to be of the face's two
//! materials), and each wave is given the phase of its true path over the misplaced segment
//! ([`super::super::faces::segment_phase`]). Only where the impedance jumps (by more than
//! [`IMPEDANCE_JUMP`]) is a face applied: the cell's other plane, between it and the pure cell
//! of its centre's material, would scatter the same waves a second time (through a 6.5 mm solid
//! plate on the default grid, 35-44 % too little pressure; as a fluid, up to 10 % as the plate
//! moves against the planes); there, and at faces weaker than that (`|R|` below 2.5 %), the
//! fields pass.
//!
//! A plane qualifies when it holds at most [`MAX_SPECTRAL_PAIRS`] pairs of media, each face lies
//! between layers, and each pair's face is flat (one offset over the plane, to [`FLAT`]); its slabs after it then take two reference
//! media (`references.rs`): within a plate the waves run in every direction of the spectrum, and
//! a mean wavenumber of bone and the water beside a finite plate serves neither (through the
//! untilted 6.5 mm plate from a CT, as a fluid: +8.3 % focal pressure and 2.4 mm; with both,
//! +1.4 % and 0.2 mm). A cap about the focus crosses each plane in a ring of faces at many
//! offsets and does not qualify (were some of its planes to, which ones would change with the
//! bone's speed, and the march with them), nor do a head's curved, textured walls: their faces cross per
//! pixel or as between fluids ([`super::Interface::new`]), and convert nothing.

use super::super::elastic::{filters, ElasticPair, Side};
use super::super::faces::{face_offset, is_wall};
use super::{impedance, key, Around, Coefficients, Interface, Key, Kind, MAX_ELASTIC_BYTES, MAX_SPECTRAL_PAIRS};
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use std::collections::HashMap;
use std::sync::Arc;

/// A face converts where the impedance on either side differs by more than this fraction of the
/// larger.
pub(super) const IMPEDANCE_JUMP: f64 = 0.05;

/// A face is a layer where its offset is the same over the plane to this fraction of the step
/// (rounding in the CT's averaging; a curved face's offsets differ by a part of a cell).
const FLAT: f64 = 1e-6;

/// The media on either side of a face (beyond the face cells) and its offset from the plane (m,
/// as exact bits).
pub(super) type FaceKey = (Key, Key, u64);

/// What a plane of a CT's faces holds (see the module doc).
pub(super) enum LayeredFaces {
    /// It does not qualify: its faces cross as between fluids.
    No,
    /// Only face cells' other planes: both fields pass (no interface).
    Pass,
    /// Faces that convert.
    Converting(Interface),
}

/// The interface from `from` into `to` whose faces convert shear (see the module doc).
/// `strength` is the plane's largest normal-incidence `|R|`.
pub(super) fn converting_faces(
    grid: &Grid,
    (from, to): (&SliceProperties, &SliceProperties),
    around: &Around,
    omega: f64,
    strength: f64,
    shared: &mut Coefficients,
) -> LayeredFaces {
    let (before, after) = around.outer();
    let slabs = [before, from, to, after];
    let n = from.sound_speed.len();
    // Per pair of media: the first pixel, the face's offset there, and its pixels.
    let mut layers: HashMap<(Key, Key), (usize, f64, Vec<u32>)> = HashMap::new();
    for i in 0..n {
        if key(from, i) == key(to, i) {
            continue;
        }
        let (za, zb) = (impedance(from, i), impedance(to, i));
        if (zb - za).abs() <= IMPEDANCE_JUMP * za.max(zb) {
            continue; // a face cell's other plane, or a weak face: the fields pass
        }
        if !is_wall(slabs, i) {
            return LayeredFaces::No;
        }
        let offset = face_offset(slabs, i, grid.dz);
        let e = layers.entry((key(before, i), key(after, i))).or_insert_with(|| (i, offset, Vec::new()));
        if (offset - e.1).abs() > FLAT * grid.dz {
            return LayeredFaces::No; // a curved face (a cap's ring): no layer
        }
        e.2.push(i as u32);
        if layers.len() > MAX_SPECTRAL_PAIRS {
            return LayeredFaces::No;
        }
    }
    let faces: HashMap<FaceKey, (usize, Vec<u32>)> =
        layers.into_iter().map(|((a, b), (first, offset, pixels))| ((a, b, offset.to_bits()), (first, pixels))).collect();
    if faces.is_empty() {
        return LayeredFaces::Pass;
    }
    let held = shared.elastic_spectra();
    let new: usize =
        faces.iter().filter(|(k, _)| !shared.3.contains_key(*k)).map(|(_, &(first, _))| super::spectra(before, after, first)).sum();
    if ((held + new) * n * 16) as u64 > MAX_ELASTIC_BYTES {
        return LayeredFaces::No;
    }
    // In order of each face's first pixel, so the sum is the same on every run.
    let mut faces: Vec<(FaceKey, (usize, Vec<u32>))> = faces.into_iter().collect();
    faces.sort_unstable_by_key(|f| f.1 .0);
    let pairs = faces
        .into_iter()
        .map(|(k, (first, pixels))| ElasticPair {
            filters: shared
                .3
                .entry(k)
                .or_insert_with(|| {
                    let (a, b) = (Side::of(before, first, omega), Side::of(after, first, omega));
                    Arc::new(filters(grid, &a, &b, f64::from_bits(k.2)))
                })
                .clone(),
            pixels: (pixels.len() < n).then_some(pixels),
        })
        .collect();
    LayeredFaces::Converting(Interface { strength, two_media: true, kind: Kind::Elastic(pairs) })
}
