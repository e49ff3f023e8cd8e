//! Where a face of a CT or a voxel map lies inside its cells: the phase of its true position,
//! which the reflected waves carry ([`face_phase`]), and whether it is a wall between two layers
//! ([`is_wall`]), which oblique walls' filters and the treads' coefficients need.

use super::elastic::Side;
use super::interface::{axial_wavenumber, impedance};
use crate::physics::medium::SliceProperties;
use num_complex::Complex64 as C64;

/// The complex phase `φ = 2·(κ_P·f - κ_C·g)·dz`, `κ = omega·s + i·alpha`, of the face between
/// slabs `P` and `C` at pixel `i` (`slabs` = the slab before `P`, `P`, `C`, the slab after `C`;
/// `s` slowness, `alpha` attenuation; the true path of the wave reflected at the face less the
/// marched one, there and back): a face inside `C` (whose centre lies beyond it) leaves the fraction `f = (s_C - s_N)/(s_P - s_N)` of
/// `C` in `P`'s material, a face inside `P` the fraction `g = (s_P - s_A)/(s_C - s_A)` of `P` in
/// `C`'s. Each is taken only where the cell beyond it is of the material its centre holds
/// (impedance within [`FACE_NEIGHBOUR`] of the jump: a face between two layers at least a step
/// thick) and whose slowness differs from the other side's (by more than 1e-6: a change of
/// density alone leaves the fraction undefined), and held below one half (the centre decides the
/// side).
pub(super) fn face_phase(slabs: [&SliceProperties; 4], i: usize, omega: f64, dz: f64) -> C64 {
    let (f, g) = fractions(slabs, i);
    let kappa = |s: &SliceProperties| C64::new(omega / s.sound_speed[i], s.attenuation[i]);
    2.0 * kappa(slabs[1]) * f * dz - 2.0 * kappa(slabs[2]) * g * dz
}

/// The fractions `(f, g)` of [`face_phase`]: of `C` in `P`'s material and of `P` in `C`'s (each 0
/// where not taken).
fn fractions(slabs: [&SliceProperties; 4], i: usize) -> (f64, f64) {
    let [a, p, c, n] = slabs.map(|s| 1.0 / s.sound_speed[i]);
    let (before_is_p, after_is_c) = layered_sides(slabs, i);
    let differ = |x: f64, y: f64| (x - y).abs() > 1e-6 * x.abs().max(y.abs());
    let f = if after_is_c && differ(p, n) { ((c - n) / (p - n)).clamp(0.0, 0.5) } else { 0.0 };
    let g = if before_is_p && differ(c, a) { ((p - a) / (c - a)).clamp(0.0, 0.5) } else { 0.0 };
    (f, g)
}

/// The signed distance (m) from the plane to the face's true position at pixel `i` (`slabs` as
/// in [`face_phase`]): `f·dz` into `C`, `-g·dz` into `P`.
pub(super) fn face_offset(slabs: [&SliceProperties; 4], i: usize, dz: f64) -> f64 {
    let (f, g) = fractions(slabs, i);
    (f - g) * dz
}

/// The phase (complex: its imaginary part the loss) that a face's wave `(in, out)` lacks when the
/// face, between media `sides = [a, b]`, is applied on the plane but lies `offset` (m) beyond it
/// (`+`: inside the cell after the plane, a segment of `a`'s material there; `-`: a segment of
/// `b`'s inside the cell before). `in` and `out` are `(side, wave)`, wave 0 P and 1 SV, at
/// transverse wavenumber `xi`; `dz` (m) is the step. Truly, a leg on the segment's side runs
/// `kz(segment's wave)·|offset|` to the face, and a leg on the cell's side runs
/// `kz(side's wave)·(dz - |offset|)` in its own material; the march gives the first nothing (the
/// face sits on the plane) and carries the second across the whole cell in the cell's averaged
/// medium, `kz(k̄)·dz`, with `k̄ = f·k_segment + (1 - f)·k_side` (`f = |offset|/dz`, complex: the
/// slowness and the attenuation averaged by length as a CT's cell holds them; for SV the mean over
/// the cell's solids, the side's own shear where the segment is a fluid). Each leg adds what the
/// march lacks: `kz(segment)·|offset|`, or `kz(side)·(dz - |offset|) - kz(k̄)·dz`. At normal
/// incidence this is [`face_phase`]'s `2·κ·δ` for P reflected at a fluid face and nothing for P
/// transmitted; obliquely it is the exact path of every wave for a cell that the march steps in
/// its averaged medium (a slab of one medium, or two references of which the cell is one,
/// `references.rs`). Beyond a medium's critical angle a leg's factor may exceed one: it undoes the
/// march's decay across the cell where the wave truly decays over the segment alone, and the
/// product stays passive.
pub(super) fn segment_phase(sides: [&Side; 2], offset: f64, dz: f64, xi: f64, waves: [(usize, usize); 2]) -> C64 {
    let zero = C64::new(0.0, 0.0);
    if offset == 0.0 {
        return zero;
    }
    let (material, cell) = if offset > 0.0 { (0, 1) } else { (1, 0) };
    let (delta, f) = (offset.abs(), (offset.abs() / dz).min(1.0));
    let k = |s: &Side, wave: usize| if wave == 0 { Some(s.kp) } else { s.ks };
    let kz = |k: C64| axial_wavenumber(k, xi * xi);
    let averaged = |wave: usize| match (k(sides[material], wave), k(sides[cell], wave)) {
        (Some(m), Some(c)) => Some(f * m + (1.0 - f) * c),
        (_, c) => c,
    };
    let leg = |(side, wave): (usize, usize)| {
        if side == material {
            k(sides[material], wave).map_or(zero, |k| kz(k) * delta)
        } else {
            match (k(sides[cell], wave), averaged(wave)) {
                (Some(own), Some(mean)) => kz(own) * (dz - delta) - kz(mean) * dz,
                _ => zero,
            }
        }
    };
    waves.iter().map(|&w| leg(w)).sum()
}

/// Whether the face between `P` and `C` at pixel `i` (`slabs` as in [`face_phase`]) is a wall
/// between two layers: the cells on both sides of it hold its two materials
/// ([`layered_sides`]). Inside graded or textured bone the neighbours differ, and the slowness
/// gradient there is texture, not a wall's normal.
pub(super) fn is_wall(slabs: [&SliceProperties; 4], i: usize) -> bool {
    let (before_is_p, after_is_c) = layered_sides(slabs, i);
    before_is_p && after_is_c
}

/// Whether, at pixel `i` of the face between `P` and `C` (`slabs` as in [`face_phase`]), the
/// cell before `P` is of `P`'s material and the cell after `C` of `C`'s: impedance within
/// [`FACE_NEIGHBOUR`] of the face's jump.
fn layered_sides(slabs: [&SliceProperties; 4], i: usize) -> (bool, bool) {
    let [a, p, c, n] = slabs.map(|s| impedance(s, i));
    let jump = (c - p).abs();
    ((a - p).abs() <= FACE_NEIGHBOUR * jump, (n - c).abs() <= FACE_NEIGHBOUR * jump)
}

/// A cell next to a face counts as the material of the face's side when its impedance is within
/// this fraction of the face's jump of it.
const FACE_NEIGHBOUR: f64 = 0.1;

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Cells of `dz` about a face at `face` (m; water before it, bone after), each holding the
    /// slowness and attenuation averaged over it and the impedance at its centre, as a CT's cells do.
    fn cells_about(face: f64, dz: f64, centres: [f64; 4]) -> [SliceProperties; 4] {
        let (water, bone) = ((1500.0, 1000.0, 0.0), (2800.0, 1850.0, 46.0));
        centres.map(|z| {
            let bone_part = ((z + 0.5 * dz - face) / dz).clamp(0.0, 1.0);
            let slowness = bone_part / bone.0 + (1.0 - bone_part) / water.0;
            let centre = if z >= face { bone } else { water };
            let c = 1.0 / slowness;
            SliceProperties {
                sound_speed: vec![c],
                density: vec![centre.0 * centre.1 / c],
                attenuation: vec![bone_part * bone.2 + (1.0 - bone_part) * water.2],
                shear: None,
            }
        })
    }

    /// The face's phase is the path the reflected wave lacks, there and back: a face 0.2 mm
    /// beyond the plane where the jump is applied gives `2·k_water·0.2 mm` (water lies between),
    /// one 0.2 mm before it `-2·(k_bone + i·alpha_bone)·0.2 mm` (bone lies between); on the plane,
    /// nothing. To rounding (1e-12 rad).
    #[test]
    fn a_face_inside_a_cell_gets_the_phase_of_its_position() {
        let (omega, dz) = (2.0 * PI * 5e5, 0.75e-3);
        let plane = 30e-3;
        let centres = [plane - 1.5 * dz, plane - 0.5 * dz, plane + 0.5 * dz, plane + 1.5 * dz];
        for (offset, want) in [
            (0.2e-3, C64::new(2.0 * omega / 1500.0 * 0.2e-3, 0.0)),
            (-0.2e-3, -2.0 * C64::new(omega / 2800.0, 46.0) * 0.2e-3),
            (0.0, C64::new(0.0, 0.0)),
        ] {
            let cells = cells_about(plane + offset, dz, centres);
            let phase = face_phase([&cells[0], &cells[1], &cells[2], &cells[3]], 0, omega, dz);
            assert!((phase - want).norm() < 1e-12, "offset {offset}: {phase} vs {want}");
        }
    }

    /// The segment's phase (water `a`, solid bone `b`, cells of 0.75 mm, the face 0.2 mm off the
    /// plane). At normal incidence: nothing on the plane; for P reflected into water
    /// [`face_phase`]'s path there and back, `2·k·δ` through water (face beyond the plane) or
    /// `-2·κ·δ` through bone (face before it); nothing for P transmitted (the averaged cell keeps
    /// its delay); for P converted to SV the difference of their paths in bone. At any incidence,
    /// up to grazing in water (beyond bone's critical angles), the phase plus what the march gives
    /// the cell-side legs (`kz(k̄)·dz`, the cell's averaged wavenumber) is each wave's true path
    /// (the segment in its material, the rest of the cell in the side's), and so passive: the
    /// reflected and transmitted waves' factors are at most one. To rounding (1e-12 rad).
    #[test]
    fn a_misplaced_face_gives_each_wave_the_phase_of_its_true_path() {
        let (omega, dz, delta) = (2.0 * PI * 5e5, 0.75e-3, 0.2e-3);
        let water = Side { density: 1000.0, kp: C64::new(omega / 1500.0, 0.0), ks: None, impedance: [1.5e6, 0.0] };
        let bone = Side {
            density: 1850.0,
            kp: C64::new(omega / 2800.0, 46.0),
            ks: Some(C64::new(omega / 1500.0, 46.0)),
            impedance: [1850.0 * 2800.0, 1850.0 * 1500.0],
        };
        let sides = [&water, &bone];
        let zero = C64::new(0.0, 0.0);
        let close = |got: C64, want: C64| (got - want).norm() < 1e-12;
        let (reflected, transmitted, converted) = ([(0, 0), (0, 0)], [(0, 0), (1, 0)], [(0, 0), (1, 1)]);
        for waves in [reflected, transmitted, converted] {
            assert!(close(segment_phase(sides, 0.0, dz, 0.3 * omega / 1500.0, waves), zero));
        }
        let at_normal = |offset: f64, waves| segment_phase(sides, offset, dz, 0.0, waves);
        assert!(close(at_normal(delta, reflected), 2.0 * water.kp * delta));
        assert!(close(at_normal(-delta, reflected), -2.0 * bone.kp * delta));
        assert!(close(at_normal(delta, transmitted), zero));
        assert!(close(at_normal(-delta, transmitted), zero));
        assert!(close(at_normal(-delta, converted), (bone.ks.unwrap() - bone.kp) * delta));
        let cells = cells_about(30e-3 + delta, dz, [28.875e-3, 29.625e-3, 30.375e-3, 31.125e-3]);
        let fluid = face_phase([&cells[0], &cells[1], &cells[2], &cells[3]], 0, omega, dz);
        assert!(close(at_normal(delta, reflected), fluid));
        for xi in (0..=20).map(|j| j as f64 * 0.05 * omega / 1500.0) {
            let kz = |k: C64| axial_wavenumber(k, xi * xi);
            for offset in [delta, -delta] {
                // The segment's material and the cell's side, and the cell's averaged wavenumbers.
                let (seg, side) = if offset > 0.0 { (&water, &bone) } else { (&bone, &water) };
                let f = delta / dz;
                let mean_p = f * seg.kp + (1.0 - f) * side.kp;
                let mean_s = side.ks.map(|s| seg.ks.map_or(s, |m| f * m + (1.0 - f) * s));
                let on_segment = |s: &Side| std::ptr::eq(s, seg);
                // (side, wave) -> (true path, what the march gives it).
                let leg = |(k, wave): (usize, usize)| {
                    let s = sides[k];
                    let own = if wave == 0 { s.kp } else { s.ks.unwrap() };
                    if on_segment(s) {
                        (kz(own) * delta, zero)
                    } else {
                        let mean = if wave == 0 { mean_p } else { mean_s.unwrap() };
                        (kz(own) * (dz - delta), kz(mean) * dz)
                    }
                };
                let mut cases = vec![reflected, transmitted, [(1, 0), (1, 0)], [(1, 0), (0, 0)]];
                if offset < 0.0 {
                    cases.push(converted); // SV on the segment's side only (water's cell has none)
                } else {
                    cases.push([(1, 1), (1, 1)]); // SV reflected in bone's cell
                }
                for waves in cases {
                    let (truth, marched) = waves.iter().map(|&w| leg(w)).fold((zero, zero), |(a, b), (t, m)| (a + t, b + m));
                    let got = segment_phase(sides, offset, dz, xi, waves) + marched;
                    assert!(close(got, truth), "xi {xi:.0}, offset {offset}, {waves:?}: {got} vs {truth}");
                    assert!(got.im >= -1e-12, "xi {xi:.0}, offset {offset}, {waves:?}: gains {:.3}", (-got.im).exp());
                }
            }
        }
    }

    /// A face between a layer of water and one of bone is a wall wherever inside its cells it
    /// lies; a face inside a ramp of impedance (graded or textured bone: the cells beyond it
    /// differ from the cells at it by more than a tenth of its jump) is not.
    #[test]
    fn a_wall_lies_between_two_layers() {
        let dz = 0.75e-3;
        let centres = [-1.5 * dz, -0.5 * dz, 0.5 * dz, 1.5 * dz];
        for offset in [-0.3e-3, 0.0, 0.3e-3] {
            let cells = cells_about(offset, dz, centres);
            assert!(is_wall([&cells[0], &cells[1], &cells[2], &cells[3]], 0), "face at {offset}");
        }
        let ramp: Vec<SliceProperties> = (0..4)
            .map(|k| SliceProperties {
                sound_speed: vec![1500.0 + 300.0 * k as f64],
                density: vec![1000.0 + 200.0 * k as f64],
                attenuation: vec![0.0],
                shear: None,
            })
            .collect();
        assert!(!is_wall([&ramp[0], &ramp[1], &ramp[2], &ramp[3]], 0));
    }
}
