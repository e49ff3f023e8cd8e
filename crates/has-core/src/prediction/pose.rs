//! How a CT prediction moves when the CT's registration is off: the pose modes.
//!
//! A head that lies rigidly moved from where the CT's registration puts it (translated by `t`,
//! rotated by `R` about the target) sends each element the wave that the head as registered
//! sends to the array moved the other way: translated by `-t` together with the target, or
//! turned by `R⁻¹` about the target. In the water around the head both are exact statements of
//! rigid motion, and both are cheap in the reciprocal form of [`super`]: the transposed march
//! from the moved target through the registered head's plan (two per translation axis, a cell
//! either way) and the transposed projection of the source-plane field onto the moved elements,
//! which is the projection onto the array as it is of that field moved the other way (see
//! [`crate::physics::source::SourceModel::moved_weights`] and
//! [`crate::physics::source::SourceModel::transposed_rates`]). No plan is built again, unlike a
//! finite difference through a moved CT (a plan per coordinate).
//!
//! The mode of a translation is, per element, the central secant
//!
//! `g_e = (wrap(arg(h⁺_e · conj(h_e)) - c⁺) - wrap(arg(h⁻_e · conj(h_e)) - c⁻)) / (2·δ)`,
//!
//! `h^±` the responses at the steps `±δ` and `c^±` their weighted common phases, over one grid
//! cell either way (the head's staircase of cells shifts by whole cells, as a CT registered a cell
//! off resamples to). The mode of a rotation is the limit of that secant, the rate at which each
//! element's phase turns as the array turns about the target (a head's phases are linear in its
//! turn to 0.01 rad over ±1°; see `pose_modes`). Central, not one-sided: a head's phase
//! pattern is far from linear in its shift over a cell (on the head phantom at 220 kHz the
//! direction of the change turns by about a radian per mm: the changes for +1.7 mm and -1.7 mm
//! correlate at -0.3, not -1), and a forward secant `(h(δ) - h(0))/δ` carries half a cell of
//! that curvature as a bias, which predicted the change for a shift the other way worse than no
//! mode (see `docs/head.md`); the central secant is the derivative to second order in `δ`. The
//! reference (the head without bone, the estimation's model) stays where the CT is registered:
//! the images' model does not move with the patient, so only the skull's responses change, as
//! for the bone speed mode ([`super::bone_speed_sensitivity`]). The transmissions' change is
//! left out: a mode is a phase pattern.

use super::phase_change;
use crate::error::{HasError, Result};
use crate::physics::transducer::Transducer;
use crate::simulation::{reciprocal_field, Simulation};
use num_complex::Complex64 as C64;
use rayon::prelude::*;

/// The prediction's pose modes: per transducer-frame axis x, y, z, each element's change of
/// predicted phase (rad) per unit of the head's translation (m) and of its rotation about the
/// target (rad, right-handed about the axis).
#[derive(Debug, Clone, PartialEq)]
pub struct PoseSensitivity {
    /// Rad per metre of translation along x, y, z.
    pub translation: [Vec<f64>; 3],
    /// Rad per radian of rotation about the axes x, y, z through the target.
    pub rotation: [Vec<f64>; 3],
}

/// A rigid move of the head from where the CT's registration puts it: `x -> R·(x - target) +
/// target + translation` in the transducer frame (m), `R` a rotation matrix (row-major).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// The shift (m).
    pub translation: [f64; 3],
    /// The rotation about the target, row-major.
    pub rotation: [[f64; 3]; 3],
}

impl Pose {
    /// No move.
    pub const IDENTITY: Pose = Pose { translation: [0.0; 3], rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] };

    /// A turn by `angle` (rad, right-handed) about coordinate axis `axis` (0, 1, 2: x, y, z)
    /// through the target.
    pub fn turn(axis: usize, angle: f64) -> Pose {
        Pose { rotation: axis_rotation(axis, angle), ..Pose::IDENTITY }
    }

    /// A shift by `distance` (m) along coordinate axis `axis`.
    pub fn shift(axis: usize, distance: f64) -> Pose {
        Pose { translation: std::array::from_fn(|k| if k == axis { distance } else { 0.0 }), ..Pose::IDENTITY }
    }
}

/// Each element's complex pressure at `target` (m, for unit drive) through `sim`'s head moved
/// by `pose`, as the array moved the other way sees the head as registered (see the module
/// docs): the array turned by `Rᵀ` about the target and shifted by `-Rᵀ·t`, with the target, in
/// one transposed march from the moved target (none when `pose` only turns and `through_skull`,
/// the transposed march from `target`, is given) and one transposed projection onto the moved
/// array (its elements laid out anew). Exact for the wave model wherever the head stays clear of
/// the grid's edges and the moved array behind its source plane (refused otherwise).
pub fn moved_head_responses(sim: &Simulation, target: [f64; 3], pose: &Pose, through_skull: Option<&[C64]>) -> Result<Vec<C64>> {
    let (moved, back) = moved_array(sim, target, pose)?;
    let source = sim.source.on_grid(&moved, &sim.grid)?;
    match through_skull {
        Some(field) if back == [0.0; 3] => source.transposed(field),
        _ => {
            let moved_target = std::array::from_fn(|k| target[k] + back[k]);
            source.transposed(&reciprocal_field(&sim.plan, moved_target, sim.reflections)?)
        }
    }
}

/// The array moved as the head's `pose` asks (turned by `Rᵀ` about `target`, then shifted by
/// `back = -Rᵀ·t`) and `back`; refused for a planar array and where an element would reach the
/// source plane.
fn moved_array(sim: &Simulation, target: [f64; 3], pose: &Pose) -> Result<(Transducer, [f64; 3])> {
    let r = &pose.rotation;
    let inverse: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
    let back: [f64; 3] = std::array::from_fn(|i| -(0..3).map(|j| inverse[i][j] * pose.translation[j]).sum::<f64>());
    if sim.transducer.is_planar() {
        return Err(HasError::invalid(
            "transducer",
            "a planar array's elements lie in its source plane: the pose modes need a curved array before it",
        ));
    }
    let moved = sim.transducer.moved(&inverse, target, back)?;
    if moved.elements.iter().any(|e| e.z_max() >= sim.grid.z0) {
        return Err(HasError::invalid(
            "pose",
            "moves an element onto the source plane: moved heads need an array before its plane (a curved array), moved less than the half wavelength between them",
        ));
    }
    Ok((moved, back))
}

/// The pose modes of the prediction at `target` (m) through `sim`'s head (see the module docs):
/// the transposed marches of `skull_marches` and their projection, then `pose_modes`. Refused for an
/// array in its source plane (a planar array: a turned element would leave the half-space behind
/// the plane) and a single bowl.
pub fn pose_sensitivity(sim: &Simulation, target: [f64; 3]) -> Result<PoseSensitivity> {
    let (through_skull, moved) = skull_marches(sim, target, &|q| reciprocal_field(&sim.plan, q, sim.reflections))?;
    let mut fields = moved;
    fields.insert(0, through_skull);
    let mut responses = sim.source.transposed_many(&fields)?;
    let h = responses.remove(0);
    pose_modes(sim, target, &fields[0], &h, &responses)
}

/// The transposed march from `target` through `sim`'s head and the weights whose
/// projection onto the array as it is gives each element's response through the head shifted a
/// cell either way along x, y and z (in that order: `+x, -x, +y, …`): the transposed march from
/// each moved target, moved on the plane as the array moves ([`SourceModel::moved_weights`]).
/// The marches share the plan and run two at a time (on two cores six moved marches take about
/// two thirds of their time one after another). `march(q)` is the transposed march from `q`
/// through `sim`'s plan (a caller's, to count them). `(through the head, moved)`; the moved
/// ones' projection is [`pose_modes`]' `moved`.
///
/// [`SourceModel::moved_weights`]: crate::physics::source::SourceModel::moved_weights
pub(super) fn skull_marches(
    sim: &Simulation,
    target: [f64; 3],
    march: &(dyn Fn([f64; 3]) -> Result<Vec<C64>> + Sync),
) -> Result<(Vec<C64>, Vec<Vec<C64>>)> {
    let g = &sim.grid;
    let mut steps: Vec<Option<(usize, f64)>> = vec![None];
    steps.extend([g.dx, g.dy, g.dz].iter().enumerate().flat_map(|(axis, &cell)| [Some((axis, cell)), Some((axis, -cell))]));
    let march = |step: &Option<(usize, f64)>| match *step {
        None => march(target),
        Some((axis, step)) => {
            let (_, back) = moved_array(sim, target, &Pose::shift(axis, step))?;
            let moved_target = std::array::from_fn(|k| target[k] + back[k]);
            sim.source.moved_weights(&march(moved_target)?, back)
        }
    };
    let mut fields = side_by_side(&steps, march)?;
    let through_skull = fields.remove(0);
    Ok((through_skull, fields))
}

/// `march` of each of `items`, [`SIDE_BY_SIDE`] at a time whatever the cores (each transposed
/// march in flight holds its own planes); the results in order, or the first error in order.
pub(super) fn side_by_side<I: Sync, T: Send>(items: &[I], march: impl Fn(&I) -> Result<T> + Sync) -> Result<Vec<T>> {
    let mut out = Vec::with_capacity(items.len());
    for pair in items.chunks(SIDE_BY_SIDE) {
        let done: Vec<Result<T>> = pair.par_iter().map(&march).collect();
        for item in done {
            out.push(item?);
        }
    }
    Ok(out)
}

/// How many transposed marches [`side_by_side`] runs at once.
const SIDE_BY_SIDE: usize = 2;

/// The pose modes from the transposed march from `target` through `sim`'s head (`through_skull`),
/// the elements' responses `h` it gives (a prediction's `skull_responses`) and `moved`, the
/// projections of [`skull_marches`]' moved fields (made in the caller's one projection with the
/// prediction's own fields). The translations: the central secants of the responses
/// to the targets moved a cell either way. The turns: the rate of the responses as the array
/// turns about the target ([`SourceModel::transposed_rates`], the gradient of the same
/// projection), `g_e = Im(h'_e·conj(h_e))/|h_e|² - Im(Σ h'·conj(h))/Σ |h|²`, the limit of the
/// secant with its weighted common phase removed (the turns' phases are linear to 0.01 rad over
/// ±1° on the head phantom). The same modes as [`moved_head_responses`]' secants, which lay out
/// twelve moved arrays anew, to a correlation of 0.999 (the turned arrays' own quadrature layout
/// and the secant's step). (The shifts' derivative at the registration, which a march of the
/// point weights' derivative would give with three marches instead of six, is not their secant
/// over a cell: the phases are far from linear in a shift over a cell, and on the uneven shell
/// the derivative is twice the secant over a cell, which a CT registered a cell off follows.)
///
/// [`SourceModel::transposed_rates`]: crate::physics::source::SourceModel::transposed_rates
pub(super) fn pose_modes(
    sim: &Simulation,
    target: [f64; 3],
    through_skull: &[C64],
    h: &[C64],
    moved: &[Vec<C64>],
) -> Result<PoseSensitivity> {
    if h.iter().all(|v| v.norm() == 0.0) {
        return Err(HasError::invalid("target", "no element's wave reaches it"));
    }
    if moved.len() != 6 {
        return Err(HasError::invalid("moved", format!("has {} responses, the shifts need six", moved.len())));
    }
    let g = &sim.grid;
    let cells = [g.dx, g.dy, g.dz];
    let mut translation: [Vec<f64>; 3] = Default::default();
    for (axis, cell) in cells.iter().enumerate() {
        // Each side's change from `h` wrapped on its own: a single wrap of `h⁺·conj(h⁻)` would
        // fold any element whose phase moves by more than π over the two steps.
        let (up, down) = (phase_change(&moved[2 * axis], h)?, phase_change(&moved[2 * axis + 1], h)?);
        translation[axis] = up.iter().zip(&down).map(|(u, d)| (u - d) / (2.0 * cell)).collect();
    }
    // The head turned by +θ about an axis turns the array by -θ: each point moves at -(a × (q - target)).
    let turning = |axis: usize| {
        move |q: [f64; 3]| -> [f64; 3] {
            let v: [f64; 3] = std::array::from_fn(|k| q[k] - target[k]);
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut u = [0.0; 3];
            u[a] = v[b];
            u[b] = -v[a];
            u
        }
    };
    let (tx, ty, tz) = (turning(0), turning(1), turning(2));
    let rates = sim.source.transposed_rates(through_skull, &[&tx, &ty, &tz])?;
    let norm: f64 = h.iter().map(|v| v.norm_sqr()).sum();
    let rotation = std::array::from_fn(|axis| {
        let rate = &rates[axis];
        let common = rate.iter().zip(h).map(|(r, h)| (r * h.conj()).im).sum::<f64>() / norm;
        rate.iter().zip(h).map(|(r, h)| if h.norm_sqr() > 0.0 { (r * h.conj()).im / h.norm_sqr() - common } else { 0.0 }).collect()
    });
    Ok(PoseSensitivity { translation, rotation })
}

/// The right-handed rotation by `angle` (rad) about coordinate axis `axis` (0, 1, 2: x, y, z),
/// row-major.
pub fn axis_rotation(axis: usize, angle: f64) -> [[f64; 3]; 3] {
    let (s, c) = angle.sin_cos();
    let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
    let mut r = [[0.0; 3]; 3];
    r[axis][axis] = 1.0;
    r[a][a] = c;
    r[b][b] = c;
    r[a][b] = -s;
    r[b][a] = s;
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_rotations_are_right_handed() {
        // About z, x turns into y; about x, y into z; about y, z into x.
        let apply = |r: [[f64; 3]; 3], v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|i| (0..3).map(|j| r[i][j] * v[j]).sum()) };
        let q = std::f64::consts::FRAC_PI_2;
        let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(&b).all(|(a, b)| (a - b).abs() < 1e-12);
        assert!(close(apply(axis_rotation(2, q), [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0]));
        assert!(close(apply(axis_rotation(0, q), [0.0, 1.0, 0.0]), [0.0, 0.0, 1.0]));
        assert!(close(apply(axis_rotation(1, q), [0.0, 0.0, 1.0]), [1.0, 0.0, 0.0]));
    }
}
