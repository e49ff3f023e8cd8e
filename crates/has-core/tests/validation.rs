//! The validation suite (what `arfi validate` runs) on the grids its scenarios choose by default.
//!
//! Tolerances: the suite's own (`Tolerances::default()`: focal pressure 5 %, focal position
//! 0.5 mm, axial profile 5 % of the peak over ±10 mm, focal-plane correlation 0.99; half the
//! spread of the ITRUSST benchmark's eleven codes). The layered cases meet them with the faces on
//! march planes, and so does `bm5`; the concentric `shell` meets them but for its axial profile
//! (5.5 % of the peak before the focus on the default grid), and is held there so that a change
//! that makes it worse fails here; with a step of 0.25 mm both shells meet every tolerance.

use has_core::validation::{compare, suite, thin_shells, Case, Comparison, Tolerances};

/// A new folder for a test's CT files.
fn scratch(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("arfi-validation-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The case compared with its exact solution, its numbers printed.
fn compared(case: &Case) -> Comparison {
    let c = compare(case).unwrap();
    eprintln!(
        "[validation] {:9} focal {:+.2} %, position {:+.2} mm, axial {:.2} %, correlation {:.4}, step {:.3} mm",
        c.name,
        100.0 * c.focal_pressure_error(),
        c.focal_position_error() * 1e3,
        100.0 * c.axial_error,
        c.correlation,
        c.step * 1e3
    );
    c
}

/// `c` within the focal pressure error, focal position error (m) and axial profile error given,
/// and the suite's focal-plane correlation: where a case is held until it meets the suite's.
fn assert_held(c: &Comparison, (pressure, position, axial): (f64, f64, f64)) {
    assert!(
        c.focal_pressure_error().abs() < pressure
            && c.focal_position_error().abs() < position
            && c.axial_error < axial
            && c.correlation > Tolerances::default().focal_plane_correlation,
        "{} got worse: {c:?}",
        c.name
    );
}

#[test]
fn water_plates_and_layered_skull_match_their_exact_solutions_on_the_default_grid() {
    let dir = scratch("test");
    let tol = Tolerances::default();
    for case in suite(&dir).unwrap() {
        let c = compared(&case);
        match c.name.as_str() {
            "water" | "bm3" | "bm4" | "bm5" => assert!(c.passes(&tol), "{} fails: {c:?}", c.name),
            // The concentric shell on the default grid: +4.4 %, -0.33 mm, axial 5.5 %, correlation
            // 0.998 (the faces' risers, where the staircase of a wall tilted against the planes
            // lets the wave into the bone without crossing a plane's face, transmit a few percent
            // too much: docs/validation.md).
            _ => assert_held(&c, (tol.focal_pressure, tol.focal_position, 0.06)),
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The CT shells converge on their exact solutions as the step shrinks: with 0.25 mm (a third of
/// the default) both meet every tolerance (2026-11-27: shell +2.4 %, -0.28 mm, axial 3.1 %,
/// correlation 0.998; bm5 +3.5 %, -0.19 mm, 4.0 %, 0.996). Marching the pressure instead of the
/// flux-normalised field, the shell stayed 6 % high and 1.6 mm short at 0.19 mm.
#[test]
fn ct_shells_match_their_exact_solutions_with_a_fine_step() {
    let dir = scratch("fine");
    let tol = Tolerances::default();
    for mut case in suite(&dir).unwrap().into_iter().filter(|c| c.name == "shell" || c.name == "bm5") {
        case.scenario.grid.step_mm = Some(0.25);
        let c = compare(&case).unwrap();
        assert!(c.passes(&tol), "{} fails at 0.25 mm: {c:?}", c.name);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Thinner caps (3, 3.5, 4 mm), near the wall's half-wave thickness (2.8 mm at 500 kHz), where
/// the reverberation inside the wall decides what crosses it. On the default grid the 3.5 mm cap
/// meets every tolerance but its axial profile (5.1 %) and focal position (0.53 mm short), the
/// 4 mm cap all but its focal pressure (5.1 % high) and axial profile (6.9 %), the 3 mm cap only
/// the correlation (4.2 % low, 0.80 mm short, axial 7.0 %). Held there, so that a change that
/// makes them worse fails, until the march's errors in thin tilted walls are found
/// (`docs/validation.md`).
#[test]
fn thin_ct_shells_are_held_where_they_are() {
    let dir = scratch("thin");
    let tol = Tolerances::default();
    for case in thin_shells(&dir).unwrap() {
        let c = compared(&case);
        // (focal pressure, focal position in m, axial profile) held; correlation as the suite's.
        let (pressure, position, axial) = match c.name.as_str() {
            "shell3" => (0.05, 0.9e-3, 0.08),
            "shell3.5" => (tol.focal_pressure, 0.6e-3, 0.06),
            _ => (0.06, tol.focal_position, 0.075),
        };
        assert_held(&c, (pressure, position, axial));
    }
    std::fs::remove_dir_all(&dir).ok();
}
