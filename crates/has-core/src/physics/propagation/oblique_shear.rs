//! Mode conversion at walls oblique to the march's planes: where a solid meets another medium on
//! a planar wall tilted against the planes (a CT plate with `bone_shear_sound_speed_m_s`), each
//! plane wave arriving at the wall is reflected and transmitted as P and SV waves with the
//! coefficients of its own incidence on the wall's face ([`super::elastic::scattering`] at
//! `ξ' = |K - (K·n)·n|`, `K` the arriving wave's vector of its own wavenumber), as a fluid
//! wall's waves take theirs (`oblique.rs`), and the outputs keep the march's `(kx, ky)`.
//!
//! A wall's SV amplitude is taken in the wall's own plane of incidence (polarised along the
//! part of `n` across the wave's direction), so the coefficients depend on `ξ'` alone; the two
//! faces of a plate share their normal and so their convention, and an SV wave between them
//! converts back with the matching sign. Between faces of different normals (a wall and a face
//! on the planes, two walls at different tilts) the amplitude is carried over unprojected, and
//! the SV wave polarised across a wall's plane of incidence (SH) is not carried.
//!
//! As for fluid walls, an output evanescent along the wall's normal (beyond its critical angle)
//! is zero. Components evanescent in the arriving medium keep the coefficients on the plane,
//! except between the solid's shear wavenumber and the largest of the two media, where the
//! face's surface-wave poles lie: there they are dropped (see `elastic_wall_filters`).
//!
//! Accuracy: `docs/validation.md` ("Shear at tilted walls") gives the ITRUSST bowl through tilted
//! solid plates against the exact elastic solution, and what limits it: each tread's SV field is
//! born with an edge one tread wide (the next tread's is born a step later), which diffracts.

use super::elastic::{pack, scattering, Filters, Side, Values};
use crate::physics::grid::Grid;
use num_complex::Complex64 as C64;
use rayon::prelude::*;

/// How far (m) the SV wave a wall transmits into a solid is continued into the fluid beside the
/// solid, laterally: a shear wavelength at 500 kHz, over two Fresnel widths `sqrt(λ_s·dz)` of the
/// default grid's step (1.5 mm did up to 5 points worse through the tilted plates, 6 mm the
/// same). A tilted wall's treads meet the planes one band at a time, so each band's SV wave is
/// born a step before its neighbour's; cut at the band's edge, it would diffract over the step,
/// losing amplitude and lagging in phase (about 1 rad through a 6.5 mm plate at 20-30°, measured
/// against the exact plate). Continued, the field is smooth across the band; the next band's
/// treads then take their own transmitted wave. Beyond the solid's last face the continued wave
/// is carried on, with the solid's mean shear attenuation, within the same distance of the solid
/// and cut beyond it (`elastic::screen`); in a plan whose walls continue it this holds beside
/// every solid, faces that convert nothing included (a CT's curved walls).
pub const CONTINUATION: f64 = 3.0e-3;

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The filters (layout of [`Filters`]) of a planar wall with unit normal `n` (towards +z) between
/// `a` (before it) and `b` (beyond it), at least one of them a solid, on grid `g`.
pub(super) fn elastic_wall_filters(g: &Grid, a: &Side, b: &Side, n: [f64; 3]) -> Filters<f64> {
    let norm = 1.0 / g.lateral_len() as f64;
    let zero = C64::new(0.0, 0.0);
    let sides = [a, b];
    // The real wavenumber of `wave` (0: P, 1: SV) on side `s`, `None` for SV in a fluid.
    let wavenumber = |s: &Side, wave: usize| if wave == 0 { Some(s.kp.re) } else { s.ks.map(|k| k.re) };
    let largest = [a, b].iter().flat_map(|s| [Some(s.kp.re), s.ks.map(|k| k.re)]).flatten().fold(0.0, f64::max);
    let poles_from = [a, b].iter().filter_map(|s| s.ks.map(|k| k.re)).fold(f64::INFINITY, f64::min);
    let sample = |at: usize| {
        let mut value: Values = [[[zero; 2]; 4]; 2];
        let (i, j) = (at / g.ny, at % g.ny);
        let (kx, ky) = (Grid::wavenumber(i, g.nx, g.dx), Grid::wavenumber(j, g.ny, g.dy));
        let kt2 = kx * kx + ky * ky;
        for (dir, per_dir) in value.iter_mut().enumerate() {
            // Arriving from `a` travelling +z, or from `b` travelling -z.
            let (from, sign) = if dir == 0 { (0, 1.0) } else { (1, -1.0) };
            for wave in 0..2 {
                let Some(k) = wavenumber(sides[from], wave) else { continue };
                // The march's component; evanescent in its medium: the coefficients on the plane.
                let propagating = kt2 < k * k;
                let incident = [kx, ky, sign * (k * k - kt2).max(0.0).sqrt()];
                let along = dot(incident, n);
                let xi = if propagating { (k * k - along * along).max(0.0).sqrt() } else { kt2.sqrt() };
                // An input evanescent along z, between the solid's shear wavenumber and the
                // largest of the two media: there lie the face's surface-wave poles (the leaky
                // Rayleigh pole of a solid whose shear is faster than the fluid, near `ks/0.93`),
                // where the planar coefficients grow without bound and would feed the outputs
                // propagating waves. Dropped there; beyond every wavenumber the face crosses
                // them as between fluids, bounded, and below the shear wavenumber no pole lies.
                if !propagating && xi > poles_from && xi <= largest {
                    continue;
                }
                let m = scattering(a, b, xi);
                for (o, slot) in per_dir.iter_mut().enumerate() {
                    // Transmitted outputs go on to the other side, reflected ones back.
                    let (to, out_wave) = (if o < 2 { 1 - from } else { from }, o % 2);
                    let Some(k_out) = wavenumber(sides[to], out_wave) else { continue };
                    // The scattering's indices: out [P⁻_a, S⁻_a, P⁺_b, S⁺_b], in [P⁺_a, S⁺_a, P⁻_b, S⁻_b].
                    let (ko, ki) = (2 * to + out_wave, 2 * from + wave);
                    let (zi, zo) = (sides[from].impedance[wave], sides[to].impedance[out_wave]);
                    if zi <= 0.0 || zo <= 0.0 {
                        continue;
                    }
                    if propagating && xi >= k_out {
                        // Evanescent along the wall's normal.
                        continue;
                    }
                    slot[wave] = m[ko][ki] * (zi / zo).sqrt() * norm;
                }
            }
        }
        value
    };
    pack(&(0..g.lateral_len()).into_par_iter().map(sample).collect::<Vec<_>>())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::medium::{ShearMaps, SliceProperties};
    use std::f64::consts::PI;

    const OMEGA: f64 = 2.0 * PI * 5e5;

    fn side(rho: f64, c: f64, alpha: f64, shear: Option<(f64, f64)>) -> Side {
        let s = SliceProperties {
            sound_speed: vec![c],
            density: vec![rho],
            attenuation: vec![alpha],
            shear: shear.map(|(cs, a)| ShearMaps { sound_speed: vec![cs], attenuation: vec![a] }),
        };
        Side::of(&s, 0, OMEGA)
    }

    fn grid() -> Grid {
        Grid::new(96, 24, 0.5e-3, 0.5e-3, 2, 0.5e-3, 0.0).unwrap()
    }

    /// A wall on the planes (n = z) takes the faces' own filters (`elastic::filters`) to
    /// rounding, except where it drops what the plane's face keeps (and the march's `kz` decays):
    /// an output evanescent on the wall's face from a propagating input, and inputs evanescent
    /// along z between the solid's shear wavenumber and the largest of the two media.
    #[test]
    fn a_wall_along_the_planes_is_the_planar_face() {
        let g = grid();
        let (water, bone) = (side(1000.0, 1500.0, 0.0, None), side(1850.0, 2800.0, 46.0, Some((1700.0, 46.0))));
        let wavenumber = |s: &Side, wave: usize| if wave == 0 { s.kp.re } else { s.ks.map_or(0.0, |k| k.re) };
        let (poles_from, largest) = (OMEGA / 1700.0, OMEGA / 1500.0);
        let mut dropped = 0;
        let mut zeroed = 0;
        for (a, b) in [(&water, &bone), (&bone, &water)] {
            let (wall, planar) = (elastic_wall_filters(&g, a, b, [0.0, 0.0, 1.0]), super::super::elastic::filters(&g, a, b, 0.0));
            for dir in 0..2 {
                for o in 0..4 {
                    for w in 0..2 {
                        let (from, to) = if dir == 0 { (a, if o < 2 { b } else { a }) } else { (b, if o < 2 { a } else { b }) };
                        let (kin, kout) = (wavenumber(from, w), wavenumber(to, o % 2));
                        assert_eq!(wall[dir][o][w].is_none(), planar[dir][o][w].is_none(), "[{dir}][{o}][{w}]");
                        let (Some(wf), Some(pf)) = (&wall[dir][o][w], &planar[dir][o][w]) else { continue };
                        for (at, (wv, pv)) in wf.iter().zip(pf.iter()).enumerate() {
                            let (i, j) = (at / g.ny, at % g.ny);
                            let kt = Grid::wavenumber(i, g.nx, g.dx).hypot(Grid::wavenumber(j, g.ny, g.dy));
                            let near_poles = kt >= kin && kt > poles_from && kt <= largest;
                            if (kt < kin && kt >= kout) || near_poles {
                                assert_eq!(*wv, C64::new(0.0, 0.0), "[{dir}][{o}][{w}] at {at}");
                                zeroed += 1;
                                dropped += usize::from(near_poles && *pv != C64::new(0.0, 0.0));
                            } else {
                                assert!((wv - pv).norm() * g.lateral_len() as f64 <= 1e-12, "[{dir}][{o}][{w}] at {at}: {wv} vs {pv}");
                            }
                        }
                    }
                }
            }
        }
        assert!(zeroed > 0 && dropped > 0, "{zeroed} outputs beyond a critical angle, {dropped} near the poles tested");
    }

    /// On a wall turned 20° about y, each component of the xz-plane takes the scattering at the
    /// incidence found by geometry (`cos θ = K̂·n`, not the plane's `kt`), and outputs beyond a
    /// critical angle on the wall are zero.
    #[test]
    fn a_tilted_wall_takes_each_waves_own_incidence() {
        let g = grid();
        let (water, bone) = (side(1000.0, 1500.0, 0.0, None), side(1850.0, 2800.0, 46.0, Some((1300.0, 46.0))));
        let t = 20f64.to_radians();
        let n = [t.sin(), 0.0, t.cos()];
        let f = elastic_wall_filters(&g, &water, &bone, n);
        let norm = 1.0 / g.lateral_len() as f64;
        let (kw, kp, ks) = (OMEGA / 1500.0, OMEGA / 2800.0, OMEGA / 1300.0);
        let (mut checked, mut beyond) = (0, 0);
        for i in 0..g.nx {
            let kx = Grid::wavenumber(i, g.nx, g.dx);
            if kx.abs() >= kw {
                continue;
            }
            let at = i * g.ny; // ky = 0
            let incident = [kx, 0.0, (kw * kw - kx * kx).sqrt()];
            let cos = dot(incident, n) / kw;
            let xi = kw * (1.0 - cos * cos).sqrt();
            let m = scattering(&water, &bone, xi);
            let value = |o: usize| f[0][o][0].as_ref().map_or(C64::new(0.0, 0.0), |v| v[at] / norm);
            let flux = |z_out: f64| (1500.0 * 1000.0 / z_out).sqrt();
            // Transmitted P (beyond the wall's critical angle: zero), reflected P.
            let want_p = if xi < kp { m[2][0] * flux(2800.0 * 1850.0) } else { C64::new(0.0, 0.0) };
            beyond += usize::from(xi >= kp);
            assert!((value(0) - want_p).norm() < 1e-9, "kx {kx}: transmitted P");
            assert!((value(2) - m[0][0]).norm() < 1e-9, "kx {kx}: reflected P");
            // Transmitted SV, in the wall's own plane of incidence.
            let want_s = if xi < ks { m[3][0] * flux(1300.0 * 1850.0) } else { C64::new(0.0, 0.0) };
            assert!((value(1) - want_s).norm() < 1e-9, "kx {kx}: transmitted SV");
            checked += 1;
        }
        assert!(checked > 10 && beyond > 0, "{checked} components, {beyond} beyond the critical angle");
    }
}
