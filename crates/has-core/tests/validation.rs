//! The validation suite (what `arfi validate` runs) on the grids its scenarios choose by default.
//!
//! Tolerances: the suite's own (`Tolerances::default()`: focal pressure 5 %, focal position
//! 0.5 mm, axial profile 5 % of the peak over ±10 mm, focal-plane correlation 0.99; half the
//! spread of the ITRUSST benchmark's eleven codes). The layered cases meet them with the faces on
//! march planes, and so does `bm5`; the concentric `shell` meets them but for its axial profile
//! (5.5 % of the peak before the focus on the default grid), and is held there so that a change
//! that makes it worse fails here; with a step of 0.25 mm both shells meet every tolerance.

use has_core::validation::{compare, suite, Tolerances};

#[test]
fn water_plates_and_layered_skull_match_their_exact_solutions_on_the_default_grid() {
    let dir = std::env::temp_dir().join(format!("arfi-validation-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tol = Tolerances::default();
    for case in suite(&dir).unwrap() {
        let c = compare(&case).unwrap();
        eprintln!(
            "[validation] {:6} focal {:+.2} %, position {:+.2} mm, axial {:.2} %, correlation {:.4}, step {:.3} mm",
            c.name,
            100.0 * c.focal_pressure_error(),
            c.focal_position_error() * 1e3,
            100.0 * c.axial_error,
            c.correlation,
            c.step * 1e3
        );
        match c.name.as_str() {
            "water" | "bm3" | "bm4" | "bm5" => assert!(c.passes(&tol), "{} fails: {c:?}", c.name),
            // The concentric shell on the default grid, 2026-11-27: +4.4 %, -0.33 mm, axial 5.5 %,
            // correlation 0.998 (the faces' risers, where the staircase of a wall tilted against
            // the planes lets the wave into the bone without crossing a plane's face, transmit a
            // few percent too much).
            _ => assert!(
                c.focal_pressure_error().abs() < tol.focal_pressure
                    && c.focal_position_error().abs() < tol.focal_position
                    && c.axial_error < 0.06
                    && c.correlation > tol.focal_plane_correlation,
                "{} got worse: {c:?}",
                c.name
            ),
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
    let dir = std::env::temp_dir().join(format!("arfi-validation-fine-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tol = Tolerances::default();
    for mut case in suite(&dir).unwrap().into_iter().filter(|c| c.name == "shell" || c.name == "bm5") {
        case.scenario.grid.step_mm = Some(0.25);
        let c = compare(&case).unwrap();
        assert!(c.passes(&tol), "{} fails at 0.25 mm: {c:?}", c.name);
    }
    std::fs::remove_dir_all(&dir).ok();
}
