//! Planar walls oblique to the march's planes on a pointwise interface: which treads belong to
//! one (a material pair whose treads' fitted normals on the plane agree), their shared filters
//! (`oblique.rs`), and the crossing through them.

use super::elastic::{combine, spectra_of, Filters, Side};
use super::interface::{key, medium_at, Around, Coefficients, Key};
use super::oblique::{bin_centre, bin_of, wall_filters, wall_normals, NormalBin};
use super::oblique_shear::{elastic_wall_filters, CONTINUATION};
use crate::numeric::unit;
use crate::physics::fft::{Fft2, FftWorkspace};
use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::Complex;
use rustfft::FftNum;
use std::sync::Arc;

/// A planar wall of a plan: its two materials (with their shear) and its binned normal.
pub(super) type WallKey = (Key, Key, NormalBin);

/// A wall's filters in the layout of [`Filters`]: a fluid wall's `τ` and `R` on `ψ`
/// ([`super::oblique::wall_filters`]), a solid's with mode conversion
/// ([`super::oblique_shear::elastic_wall_filters`]).
pub(super) type WallFilters = Arc<Filters<f64>>;

/// The waves leaving a plane's walls ([`Walls::cross`]): per grouped pixel the transmitted ψ and s
/// and the reflected ψ and s; and the SV wave continued ahead of the treads (plane index, value).
pub(crate) type WallWaves<T> = ([Vec<Complex<T>>; 4], Vec<(u32, Complex<T>)>);

/// The treads of oblique walls on a pointwise interface, by wall (materials and binned normal).
pub(crate) struct Walls<T: FftNum> {
    /// Per pixel of the interface (in its order): whether a wall's filters give its waves.
    pub grouped: Vec<bool>,
    pub groups: Vec<WallGroup<T>>,
    /// Where a wall converts to or from shear: the pixels of the reflected wave it keeps, the
    /// interface's pixels followed by the SV field's at its treads (offset by a plane).
    pub kept: Option<Arc<Vec<u32>>>,
}

/// One wall's treads on a plane: their positions in the interface's pixel list and the wall's
/// filters.
pub(crate) struct WallGroup<T: FftNum> {
    pub members: Vec<u32>,
    pub filters: Arc<Filters<T>>,
    /// The wall's unit normal (its bin's centre, towards +z).
    pub normal: [f64; 3],
    /// Per direction (forward, back), where the wall transmits an SV wave (into a solid): the
    /// fluid's pixels within [`super::oblique_shear::CONTINUATION`] of its treads (plane indices,
    /// none a tread of any wall), where the transmitted SV wave is continued.
    pub ahead: [Vec<u32>; 2],
}

impl<T: FftNum> WallGroup<T> {
    /// Whether crossing in direction `dir` (0 forward, 1 back) transmits an SV wave: its treads
    /// and the pixels ahead of them take it.
    pub(crate) fn transmits_sv(&self, dir: usize) -> bool {
        self.filters[dir][1].iter().any(Option::is_some)
    }
}

/// A plane whose wall treads hold more than this many material pairs (each planar wall costs two
/// inverse FFTs per crossing; a textured skull's faces hold many) keeps the treads'
/// normal-incidence coefficients.
pub const MAX_PLANE_WALLS: usize = 4;

/// A wall takes filters on a plane where at least this share of its treads there have normals
/// within [`PLANAR_SPREAD`] of their mean.
pub const PLANAR_SHARE: f64 = 0.8;

/// The largest angle (rad) between a planar wall's tread normals and their mean: above the
/// fitted normal's scatter on a staircase of cells (about 1°), below a cap's turn across one
/// plane away from its pole (at 5°, `bm5` at a 0.25 mm step took filters where its cap curves and
/// came out 2 % higher).
pub const PLANAR_SPREAD: f64 = 3.0 * std::f64::consts::PI / 180.0;

/// A wall needs at least this many treads on a plane to take its filters.
pub const MIN_WALL_PIXELS: usize = 8;

/// At most this many distinct walls in one plan (4-18 spectra each).
pub const MAX_PLAN_WALLS: usize = 16;

impl<T: FftNum> Walls<T> {
    /// Whether its walls' filters give SV waves (a solid on a side).
    pub(crate) fn converts(&self) -> bool {
        self.kept.is_some()
    }

    /// The waves of `field` (`ψ`, or `[ψ | s]` where the march carries shear) crossing the walls
    /// in the direction `sign` (+1 forward, -1 back): the transmitted ψ and s and the reflected ψ
    /// and s at each grouped pixel, indexed as the interface's `pixels` (zero at the others);
    /// the reflected ones only if `reflected`, the SV ones only where the walls convert (else
    /// empty); and the transmitted SV wave at the pixels ahead of the treads (plane index,
    /// value). `work` is overwritten.
    pub(crate) fn cross(
        &self,
        fft: &Fft2<T>,
        pixels: &[u32],
        field: &[Complex<T>],
        (sign, reflected): (f64, bool),
        work: &mut Vec<Complex<T>>,
        ws: &mut FftWorkspace<T>,
    ) -> WallWaves<T> {
        let zero = Complex::new(T::zero(), T::zero());
        let n = fft.nx * fft.ny;
        let halves = if self.converts() { field.len() / n } else { 1 };
        let spectra = spectra_of(fft, field, halves, work, ws);
        let wanted = |o: usize| (o < 2 || reflected) && (o % 2 == 0 || halves == 2);
        let mut out: [Vec<Complex<T>>; 4] = std::array::from_fn(|o| vec![zero; if wanted(o) { pixels.len() } else { 0 }]);
        let dir = usize::from(sign < 0.0);
        let mut ahead = Vec::new();
        for g in &self.groups {
            for (o, wave) in out.iter_mut().enumerate().filter(|(_, w)| !w.is_empty()) {
                let inputs = &g.filters[dir][o];
                if inputs.iter().all(Option::is_none) {
                    continue;
                }
                combine(ws, &spectra, inputs);
                fft.inverse(ws, work);
                g.members.iter().for_each(|&m| wave[m as usize] = work[pixels[m as usize] as usize]);
                if o == 1 {
                    ahead.extend(g.ahead[dir].iter().map(|&i| (i, work[i as usize])));
                }
            }
        }
        (out, ahead)
    }
}

/// The treads of planar walls among a pointwise interface's `pixels` (`wall`: the pixel is a face
/// between two layers), by the layers' materials, with their filters (shared through `shared`).
/// A wall is planar where at least [`PLANAR_SHARE`] of its treads on the plane have normals
/// within [`PLANAR_SPREAD`] of their mean: those take the filters of the mean's bin, the rest
/// (the rims of a finite wall, whose side faces bend the normal) keep the treads' coefficients.
/// On a curved wall (a cap) each plane's treads turn through many normals and none do; a wall
/// along the planes (its normal within half a [`super::oblique::NORMAL_BIN`] of z) keeps the planar
/// coefficients, which are exact for it. `None`
/// where no wall is planar, where the plane holds more than [`MAX_PLANE_WALLS`] material pairs,
/// or where the plan holds [`MAX_PLAN_WALLS`] filters already.
pub(super) fn walls(
    grid: &Grid,
    omega: f64,
    around: &Around,
    pixels: &[u32],
    wall: &[bool],
    shared: &mut Coefficients,
) -> Option<Walls<f64>> {
    let (before, after) = around.outer();
    let members: Vec<usize> = (0..pixels.len()).filter(|&m| wall[m]).collect();
    let materials = |m: usize| (key(before, pixels[m] as usize), key(after, pixels[m] as usize));
    // By material pair, in order of first pixel.
    let mut by_pair: Vec<((Key, Key), Vec<usize>)> = Vec::new();
    for &m in &members {
        match by_pair.iter().position(|p| p.0 == materials(m)) {
            Some(p) => by_pair[p].1.push(m),
            None if by_pair.len() < MAX_PLANE_WALLS => by_pair.push((materials(m), vec![m])),
            None => return None,
        }
    }
    let mut groups: Vec<(WallKey, Vec<u32>)> = Vec::new();
    for ((a, b), treads) in by_pair {
        if treads.len() < MIN_WALL_PIXELS {
            continue;
        }
        let at: Vec<u32> = treads.iter().map(|&m| pixels[m]).collect();
        let normals = wall_normals(grid, &around.column, around.face, &at);
        let mean = |keep: &dyn Fn(&[f64; 3]) -> bool| {
            unit(normals.iter().filter(|n| keep(n)).fold([0.0; 3], |s, n| [s[0] + n[0], s[1] + n[1], s[2] + n[2]]))
        };
        let near = |m: [f64; 3]| move |n: &[f64; 3]| n[0] * m[0] + n[1] * m[1] + n[2] * m[2] >= PLANAR_SPREAD.cos();
        // The mean of all, then of those near it (the rim left out).
        let first = mean(&|_| true);
        let normal = mean(&near(first));
        let held: Vec<u32> = treads.iter().zip(&normals).filter(|(_, n)| near(normal)(n)).map(|(&m, _)| m as u32).collect();
        // A wall along the planes (its bin the axis) keeps the planar coefficients, exact there.
        let bin = bin_of(normal);
        if bin.0 > 0 && (held.len() as f64) >= PLANAR_SHARE * treads.len() as f64 {
            groups.push(((a, b, bin), held));
        }
    }
    let new = groups.iter().filter(|g| !shared.1.contains_key(&g.0)).count();
    if groups.is_empty() || shared.1.len() + new > MAX_PLAN_WALLS {
        return None;
    }
    let mut grouped = vec![false; pixels.len()];
    let groups: Vec<WallGroup<f64>> = groups
        .into_iter()
        .map(|(k, members)| {
            members.iter().for_each(|&m| grouped[m as usize] = true);
            let i = pixels[members[0] as usize] as usize;
            let filters =
                shared.1.entry(k).or_insert_with(|| Arc::new(filters_of(grid, omega, (before, after), i, bin_centre(k.2)))).clone();
            WallGroup { members, filters, normal: bin_centre(k.2), ahead: [Vec::new(), Vec::new()] }
        })
        .collect();
    let mut groups = groups;
    continue_sv(grid, around, pixels, &grouped, &mut groups);
    // The SV field's reflected wave is kept at every grouped tread where any wall converts.
    let converts = groups.iter().any(|g| {
        g.filters.iter().flatten().enumerate().any(|(o, inputs)| (o % 2 == 1 && inputs.iter().any(Option::is_some)) || inputs[1].is_some())
    });
    let kept = converts.then(|| {
        let n = grid.lateral_len() as u32;
        let shear = (0..pixels.len()).filter(|&m| grouped[m]).map(|m| n + pixels[m]);
        Arc::new(pixels.iter().copied().chain(shear).collect())
    });
    Some(Walls { grouped, groups, kept })
}

/// Gives each wall that transmits an SV wave (into a solid) the fluid's pixels ahead of its
/// treads (`WallGroup::ahead`): fluid on both sides of the face, within
/// [`super::oblique_shear::CONTINUATION`] of a tread, no tread of any wall and claimed by the
/// first such wall alone (the march writes each once).
fn continue_sv(grid: &Grid, around: &Around, pixels: &[u32], grouped: &[bool], groups: &mut [WallGroup<f64>]) {
    let (from, to) = (around.column[around.face - 1], around.column[around.face]);
    let reach = [(CONTINUATION / grid.dx).round() as i64, (CONTINUATION / grid.dy).round() as i64];
    for dir in 0..2 {
        let mut taken = vec![false; grid.lateral_len()];
        (0..pixels.len()).filter(|&m| grouped[m]).for_each(|m| taken[pixels[m] as usize] = true);
        for g in groups.iter_mut().filter(|g| g.transmits_sv(dir)) {
            let mut ahead = Vec::new();
            for &m in &g.members {
                let p = pixels[m as usize] as i64;
                let (x, y) = (p % grid.nx as i64, p / grid.nx as i64);
                for yy in (y - reach[1]).max(0)..=(y + reach[1]).min(grid.ny as i64 - 1) {
                    for xx in (x - reach[0]).max(0)..=(x + reach[0]).min(grid.nx as i64 - 1) {
                        let q = (yy * grid.nx as i64 + xx) as usize;
                        if !taken[q] && from.shear_speed(q) <= 0.0 && to.shear_speed(q) <= 0.0 {
                            taken[q] = true;
                            ahead.push(q as u32);
                        }
                    }
                }
            }
            ahead.sort_unstable();
            g.ahead[dir] = ahead;
        }
    }
}

/// The filters of the wall at pixel `i` between slabs `before` and `after` with unit normal `n`:
/// with mode conversion where a side is a solid, else a fluid wall's `τ` and `R` on `ψ`.
fn filters_of(grid: &Grid, omega: f64, (before, after): (&SliceProperties, &SliceProperties), i: usize, n: [f64; 3]) -> Filters<f64> {
    let (a, b) = (Side::of(before, i, omega), Side::of(after, i, omega));
    if a.is_solid() || b.is_solid() {
        return elastic_wall_filters(grid, &a, &b, n);
    }
    let [tau, r, tau_back, r_back] = wall_filters(grid, omega, medium_at(before, i), medium_at(after, i), n).map(Arc::new);
    let mut f: Filters<f64> = Default::default();
    f[0][0][0] = Some(tau);
    f[0][2][0] = Some(r);
    f[1][0][0] = Some(tau_back);
    f[1][2][0] = Some(r_back);
    f
}
