//! Walls oblique to the march's planes: each plane wave crossing a wall takes the coefficients of
//! its incidence on the wall's own face, not on the plane.
//!
//! A wall between two layers (a CT plate, a skull table) crosses the planes as a staircase; its
//! treads are where the march applies a change of medium. A tread's per-pixel coefficient
//! (`risers.rs`) is the face's at normal incidence: it passes what the wall reflects totally
//! (beyond the critical angle, 32° from water into cortical bone): for a focused beam through a
//! plate tilted by 20° that alone makes the focus some 40 % too strong (`docs/validation.md`). Here the tread's pixels `M`
//! of one wall (its two materials `a`, `b` and its unit normal `n`, binned) take
//!
//! `ψ_t = M · IFFT(τ · FFT(ψ))`, `ψ_r = M · IFFT(R · FFT(ψ))`,
//!
//! where, for the plane wave `K = (kx, ky, ±kz)` of the incident medium (`|K| = omega/c`),
//! `R = R_ab(kt')` is the planar coefficient ([`super::reflection_coefficient`]) at the
//! tangential wavenumber `kt'² = |K|² - (K·n)²` on the wall's face and `τ = (1 + R)·sqrt(Z_a/Z_b)`
//! the face's pressure transmission carried by the flux-normalised field `ψ`, as at a face on a
//! plane (`interface`), but zero beyond the critical angle on the wall's face (`kt'` above
//! `b`'s wavenumber). There the transmitted wave is evanescent along the wall's normal and dies
//! within a wavelength; where the face lies on a plane the march's own `kz` decays it, but the
//! march carries the wave of an oblique wall along z, where it would propagate. Evanescent
//! components of the incident medium keep the plane's coefficients.
//!
//! The mask is applied after the filter, as for the material pairs of planar faces: the filter
//! acts on the whole field, so each tread pixel takes the coefficient of the waves that arrive
//! there (a pseudo-differential operator) rather than of the narrow strip's own diffraction.
//!
//! The normal is the gradient of a plane fitted to the slowness over the cells within
//! [`NORMAL_SMOOTHING`] of each tread ([`wall_normals`]): one cell's staircase alone gives its
//! tread a normal tens of degrees off the wall's. Only planar walls take filters (their treads'
//! normals on a plane within `interface::PLANAR_SPREAD` of their mean): a curved wall turns
//! through many normals on each plane. The slabs after such a wall's plane also refract the
//! oblique screen's rays through it (`operators::refract`).

use crate::physics::grid::Grid;
use crate::physics::medium::SliceProperties;
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The width (standard deviation, m) of the Gaussian that smooths the slowness before its
/// gradient gives a wall's normal: a few cells of the default grid, well below the radius of
/// curvature of a skull's tables.
pub const NORMAL_SMOOTHING: f64 = 1.0e-3;

/// Slabs on each side of a face that the normal's smoothing reads: three widths of the
/// Gaussian, as across the plane (a window cut shorter along z than across tilts the normal).
pub(crate) fn normal_slabs(dz: f64) -> usize {
    (3.0 * NORMAL_SMOOTHING / dz).ceil() as usize
}

/// Normals are binned to cones of this polar step (rad): within a bin every pixel takes the
/// centre's coefficients, an error of at most half a step in the angle of incidence.
pub const NORMAL_BIN: f64 = 2.5 * PI / 180.0;

/// A normal's bin: polar index and azimuthal index.
pub(crate) type NormalBin = (u32, u32);

/// The bin of unit normal `n` (oriented towards +z): `θ = acos(n_z)` in steps of
/// [`NORMAL_BIN`], the ring of that polar angle in `max(1, round(2π·sin θ/NORMAL_BIN))`
/// azimuthal steps.
pub(crate) fn bin_of(n: [f64; 3]) -> NormalBin {
    let n = if n[2] < 0.0 { [-n[0], -n[1], -n[2]] } else { n };
    let polar = (n[2].clamp(-1.0, 1.0).acos() / NORMAL_BIN).round() as u32;
    let ring = ring_size(polar);
    let azimuth = n[1].atan2(n[0]).rem_euclid(2.0 * PI);
    (polar, ((azimuth * ring as f64 / (2.0 * PI)).round() as u32) % ring)
}

fn ring_size(polar: u32) -> u32 {
    ((2.0 * PI * (polar as f64 * NORMAL_BIN).sin() / NORMAL_BIN).round() as u32).max(1)
}

/// The unit normal at the centre of `bin`.
pub(crate) fn bin_centre((polar, azimuth): NormalBin) -> [f64; 3] {
    let theta = polar as f64 * NORMAL_BIN;
    let phi = 2.0 * PI * azimuth as f64 / ring_size(polar) as f64;
    [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
}

/// Unit normals (oriented towards +z) at `pixels` of the face at plane `face` of `column`, the
/// slabs before successive planes (`column[face - 1]` and `column[face]` the slabs on either side
/// of it, [`normal_slabs`] more on each side): the gradient of the plane that fits the slowness
/// best in least squares with the Gaussian weights `G(r - r0)` of width [`NORMAL_SMOOTHING`] (the
/// cells within three widths, at the face's point `r0` on the plane). The fit, unlike the
/// Gaussian's derivative, is not tilted where the grid's edges cut the window. A pixel whose fit
/// has no gradient gets the axis.
pub(crate) fn wall_normals(grid: &Grid, column: &[&SliceProperties], face: usize, pixels: &[u32]) -> Vec<[f64; 3]> {
    let (reach_x, reach_y) = ((3.0 * NORMAL_SMOOTHING / grid.dx).ceil() as i64, (3.0 * NORMAL_SMOOTHING / grid.dy).ceil() as i64);
    let gauss = |d: f64| (-0.5 * (d / NORMAL_SMOOTHING).powi(2)).exp();
    let wx: Vec<f64> = (-reach_x..=reach_x).map(|i| gauss(i as f64 * grid.dx)).collect();
    let wy: Vec<f64> = (-reach_y..=reach_y).map(|j| gauss(j as f64 * grid.dy)).collect();
    // Slab m's centre lies (m - face + 0.5)·dz past the face's plane.
    let slabs: Vec<(f64, f64, &SliceProperties)> = column
        .iter()
        .enumerate()
        .map(|(m, s)| {
            let dz = (m as f64 - face as f64 + 0.5) * grid.dz;
            (dz, gauss(dz), *s)
        })
        .collect();
    let (nx, ny) = (grid.nx as i64, grid.ny as i64);
    pixels
        .par_iter()
        .map(|&p| {
            let (x0, y0) = ((p as usize % grid.nx) as i64, (p as usize / grid.nx) as i64);
            // Weighted sums for the least-squares plane s ≈ s̄ + g·(r - r̄).
            let (mut w_sum, mut s_sum) = (0.0, 0.0);
            let (mut r_sum, mut sr_sum, mut rr_sum) = ([0.0; 3], [0.0; 3], [[0.0; 3]; 3]);
            for &(dz, wz, slab) in &slabs {
                for (jj, &wyj) in wy.iter().enumerate() {
                    let y = y0 + jj as i64 - reach_y;
                    if y < 0 || y >= ny {
                        continue;
                    }
                    for (ii, &wxi) in wx.iter().enumerate() {
                        let x = x0 + ii as i64 - reach_x;
                        if x < 0 || x >= nx {
                            continue;
                        }
                        let (w, s) = (wxi * wyj * wz, 1.0 / slab.sound_speed[(y * nx + x) as usize]);
                        let r = [(x - x0) as f64 * grid.dx, (y - y0) as f64 * grid.dy, dz];
                        w_sum += w;
                        s_sum += w * s;
                        for a in 0..3 {
                            r_sum[a] += w * r[a];
                            sr_sum[a] += w * s * r[a];
                            for b in 0..3 {
                                rr_sum[a][b] += w * r[a] * r[b];
                            }
                        }
                    }
                }
            }
            let (s_mean, r_mean) = (s_sum / w_sum, r_sum.map(|v| v / w_sum));
            let cov: [[f64; 3]; 3] = std::array::from_fn(|a| std::array::from_fn(|b| rr_sum[a][b] / w_sum - r_mean[a] * r_mean[b]));
            let rhs: [f64; 3] = std::array::from_fn(|a| sr_sum[a] / w_sum - s_mean * r_mean[a]);
            let g = solve3(cov, rhs).unwrap_or([0.0, 0.0, 1.0]);
            let norm = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            if norm > 0.0 {
                let s = if g[2] < 0.0 { -1.0 / norm } else { 1.0 / norm };
                [g[0] * s, g[1] * s, g[2] * s]
            } else {
                [0.0, 0.0, 1.0]
            }
        })
        .collect()
}

/// `x` with `m·x = b` (Cramer's rule), `None` where `m` is singular.
fn solve3(m: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    if d.abs() <= f64::MIN_POSITIVE {
        return None;
    }
    Some(std::array::from_fn(|c| {
        let mut mc = m;
        (0..3).for_each(|r| mc[r][c] = b[r]);
        det(mc) / d
    }))
}

/// The filters of one wall (materials `a` before the face, `b` beyond it, each `(rho, c,
/// alpha)`, unit normal `n`) on the transposed spectrum layout `(nx, ny)`, each divided by
/// `nx·ny` (the inverse FFT's normalisation): `[τ_ab, R_ab]` for waves in `a` travelling to +z,
/// `[τ_ba, R_ba]` for waves in `b` travelling to -z.
pub(crate) fn wall_filters(g: &Grid, omega: f64, a: (f64, f64, f64), b: (f64, f64, f64), n: [f64; 3]) -> [Vec<C64>; 4] {
    let norm = 1.0 / g.lateral_len() as f64;
    let len = g.lateral_len();
    let mut out =
        [vec![C64::new(0.0, 0.0); len], vec![C64::new(0.0, 0.0); len], vec![C64::new(0.0, 0.0); len], vec![C64::new(0.0, 0.0); len]];
    for i in 0..g.nx {
        let kx = Grid::wavenumber(i, g.nx, g.dx);
        for j in 0..g.ny {
            let ky = Grid::wavenumber(j, g.ny, g.dy);
            let kt2 = kx * kx + ky * ky;
            let at = i * g.ny + j;
            for (from, to, direction, slot) in [(a, b, 1.0, 0), (b, a, -1.0, 2)] {
                let k = omega / from.1;
                let z_ratio = (from.0 * from.1 / (to.0 * to.1)).sqrt();
                let (r, t) = if kt2 < k * k {
                    let kz = direction * (k * k - kt2).sqrt();
                    let along = kx * n[0] + ky * n[1] + kz * n[2];
                    let tangential = (k * k - along * along).max(0.0);
                    let r = super::reflection_coefficient(omega, from, to, tangential);
                    // Beyond the critical angle on the wall's face the transmitted wave is
                    // evanescent along its normal.
                    let evanescent = tangential >= (omega / to.1).powi(2);
                    (r, if evanescent { C64::new(0.0, 0.0) } else { (1.0 + r) * z_ratio })
                } else {
                    let r = super::reflection_coefficient(omega, from, to, kt2);
                    (r, (1.0 + r) * z_ratio)
                };
                out[slot][at] = t * norm;
                out[slot + 1][at] = r * norm;
            }
        }
    }
    out
}

/// Index of `-k` for the spectrum sample at `at` of the transposed layout `(nx, ny)`: a filter
/// applied between the forward and inverse FFTs has as its transpose the same operator with the
/// filter at `-k`.
pub(crate) fn opposite((nx, ny): (usize, usize), at: usize) -> usize {
    let (i, j) = (at / ny, at % ny);
    ((nx - i) % nx) * ny + (ny - j) % ny
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_hold_their_centres_and_neighbours() {
        for n in [[0.0, 0.0, 1.0], [0.34202, 0.0, 0.93969], [-0.2, 0.3, 0.9327], [0.0, -0.5, -0.866f64]] {
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let n = [n[0] / len, n[1] / len, n[2] / len];
            let c = bin_centre(bin_of(n));
            let dot = (c[0] * n[0] + c[1] * n[1] + c[2] * n[2]).abs();
            // Half a polar step plus half an azimuthal step on the ring.
            assert!(dot.acos() <= NORMAL_BIN, "{n:?} -> {c:?}");
            assert_eq!(bin_of(c), bin_of(n));
        }
    }

    const WATER: (f64, f64, f64) = (1000.0, 1500.0, 0.0);
    const BONE: (f64, f64, f64) = (1850.0, 2800.0, 46.0);

    /// Each filter sample against the angle of incidence found by geometry, `cos θ = K̂·n`: `R`
    /// is the planar coefficient at `kt' = k·sin θ`, `τ = (1 + R)·sqrt(Z_a/Z_b)` below the critical
    /// angle (`sin θ < c_a/c_b` from water into bone) and zero beyond it; waves travelling back
    /// through bone take `R_ba` at their own angle. On the plane's normal (n = z) the forward
    /// filters are the planar face's own.
    #[test]
    fn wall_filters_take_the_angle_of_incidence_on_the_wall() {
        let g = Grid::new(32, 24, 0.4e-3, 0.5e-3, 2, 0.5e-3, 0.0).unwrap();
        let omega = 2.0 * PI * 5e5;
        let norm = 1.0 / g.lateral_len() as f64;
        let za_zb = (WATER.0 * WATER.1 / (BONE.0 * BONE.1)).sqrt();
        let mut beyond = 0;
        for tilt in [0.0f64, 20.0, 35.0] {
            let t = tilt.to_radians();
            let n = [t.sin(), 0.0, t.cos()];
            let [tau, r, tau_back, r_back] = wall_filters(&g, omega, WATER, BONE, n);
            for i in 0..g.nx {
                for j in 0..g.ny {
                    let (kx, ky) = (Grid::wavenumber(i, g.nx, g.dx), Grid::wavenumber(j, g.ny, g.dy));
                    let at = i * g.ny + j;
                    let (ka, kb) = (omega / WATER.1, omega / BONE.1);
                    let kt = kx.hypot(ky);
                    if kt >= ka {
                        continue;
                    }
                    // Forward, in water.
                    let kz = (ka * ka - kt * kt).sqrt();
                    let cos = ((kx * n[0] + ky * n[1] + kz * n[2]) / ka).clamp(-1.0, 1.0);
                    let sin = (1.0 - cos * cos).sqrt();
                    let want_r = super::super::reflection_coefficient(omega, WATER, BONE, (ka * sin).powi(2));
                    let critical = sin >= WATER.1 / BONE.1;
                    beyond += usize::from(critical);
                    let want_t = if critical { C64::new(0.0, 0.0) } else { (1.0 + want_r) * za_zb };
                    assert!((r[at] / norm - want_r).norm() < 1e-9, "tilt {tilt}, ({kx}, {ky}): R");
                    assert!((tau[at] / norm - want_t).norm() < 1e-9, "tilt {tilt}, ({kx}, {ky}): τ");
                    if tilt == 0.0 {
                        let planar = super::super::reflection_coefficient(omega, WATER, BONE, kt * kt);
                        assert!((r[at] / norm - planar).norm() < 1e-9);
                    }
                    // Back, in bone.
                    if kt < kb {
                        let kz = -(kb * kb - kt * kt).sqrt();
                        let cos = ((kx * n[0] + ky * n[1] + kz * n[2]) / kb).clamp(-1.0, 1.0);
                        let want = super::super::reflection_coefficient(omega, BONE, WATER, kb * kb * (1.0 - cos * cos));
                        assert!((r_back[at] / norm - want).norm() < 1e-9, "tilt {tilt}: R back");
                        assert!((tau_back[at] / norm - (1.0 + want) / za_zb).norm() < 1e-9, "tilt {tilt}: τ back");
                    }
                }
            }
        }
        assert!(beyond > 10, "no sample beyond the critical angle tested");
    }

    /// A plate turned 20° about y whose cells average the slowness over them (as a CT's do):
    /// the smoothed gradient gives every tread of its first face, away from the grid's edges, the
    /// plate's normal to 1°, where one cell's staircase alone is tens of degrees off.
    #[test]
    fn the_normal_of_a_staircased_wall_is_the_walls() {
        let g = Grid::new(64, 24, 0.5e-3, 0.5e-3, 40, 0.5e-3, 0.0).unwrap();
        let t = 20f64.to_radians();
        let n = [t.sin(), 0.0, t.cos()];
        let z1 = 10.1e-3;
        // Bone beyond the face x·sin t + (z - z1)·cos t = 0, 8 x 8 samples per cell; slab m lies
        // before plane m.
        let cell = |x: f64, z: f64| {
            let mut s = 0.0;
            for a in 0..8 {
                for b in 0..8 {
                    let (xx, zz) = (x + (a as f64 - 3.5) / 8.0 * g.dx, z + (b as f64 - 3.5) / 8.0 * g.dz);
                    s += if xx * n[0] + (zz - z1) * n[2] >= 0.0 { 1.0 / 2800.0 } else { 1.0 / 1500.0 };
                }
            }
            64.0 / s
        };
        let slab = |m: usize| SliceProperties {
            sound_speed: (0..g.lateral_len()).map(|p| cell(g.x(p % g.nx), g.z(m) - 0.5 * g.dz)).collect(),
            density: vec![1000.0; g.lateral_len()],
            attenuation: vec![0.0; g.lateral_len()],
            shear: None,
        };
        let slabs: Vec<SliceProperties> = (0..g.nz).map(slab).collect();
        let (mut checked, reach) = (0, normal_slabs(g.dz));
        for plane in reach + 1..g.nz - reach - 2 {
            let column: Vec<&SliceProperties> = (plane - reach..=plane + reach + 1).map(|m| &slabs[m]).collect();
            // Pixels of the middle row whose face lies within half a step of this plane, 4 mm
            // from the grid's edges.
            let pixels: Vec<u32> = (8..g.nx - 8)
                .filter(|&i| ((z1 - g.x(i) * t.tan()) - g.z(plane)).abs() <= 0.5 * g.dz)
                .map(|i| (12 * g.nx + i) as u32)
                .collect();
            for m in wall_normals(&g, &column, reach + 1, &pixels) {
                let angle = (m[0] * n[0] + m[1] * n[1] + m[2] * n[2]).clamp(-1.0, 1.0).acos().to_degrees();
                assert!(angle < 1.0, "plane {plane}: {m:?} is {angle:.2}° off");
                checked += 1;
            }
        }
        assert!(checked > 20, "{checked} treads checked");
    }
}
