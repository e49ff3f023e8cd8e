//! The validation suite (what `arfi validate` runs) on the grids its scenarios choose by default.
//!
//! Tolerances: the suite's own (`Tolerances::default()`: focal pressure 5 %, focal position
//! 0.5 mm, axial profile 5 % of the peak over ±10 mm, focal-plane correlation 0.99; half the
//! spread of the ITRUSST benchmark's eleven codes). The layered cases meet them with the faces on
//! march planes; the shells of CT bone do not yet, and are held to where they stand so that a
//! change that makes them worse fails here.

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
            "water" | "bm3" | "bm4" => assert!(c.passes(&tol), "{} fails: {c:?}", c.name),
            // CT shells on the default grid, 2026-11-27: +10.8 % and -0.54 mm (shell), +4.8 % and
            // -1.70 mm (bm5), correlations 0.995 and 0.991.
            _ => assert!(
                c.focal_pressure_error().abs() < 0.13 && c.focal_position_error().abs() < 2.0e-3 && c.correlation > 0.985,
                "{} got worse: {c:?}",
                c.name
            ),
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}
