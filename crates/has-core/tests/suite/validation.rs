//! The validation suite (what `arfi validate` runs) on the grids its scenarios choose by default.
//!
//! Tolerances: the suite's own (`Tolerances::default()`: focal pressure 5 %, focal position
//! 0.5 mm, axial profile 5 % of the peak over ±10 mm, focal-plane correlation 0.99; half the
//! spread of the ITRUSST benchmark's eleven codes), or a plate from a CT's (`Tolerances::OBLIQUE`,
//! and `Tolerances::OBLIQUE_SOLID` for the tilted solid plates).
//! Every case meets them on the default grid: the layered ones with their faces on march planes,
//! the CT shells with the staircase of their walls' faces given the loss of its risers
//! (`physics/propagation/risers.rs`).

use has_core::validation::{compare, lossy_shells, suite, thin_shells, tilted_plate, Case, Comparison, Tolerances};

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

/// Every case of `arfi validate` within its own tolerances: the suite's for water, the layers,
/// the shells and the untilted plate from a CT (fluid and solid); [`Tolerances::OBLIQUE`] for the
/// ITRUSST plate from a CT turned 10, 20 and 30° about y, against the exact solution through the
/// fluid plate (`reference::oblique`).
///
/// The plates are also held where they are, tighter, so that a change that makes one worse
/// fails: their treads take the coefficients of each plane wave's incidence on the plate's face
/// (total reflection beyond the critical angle, `propagation/oblique.rs`) and the slabs the tilted
/// plate crosses propagate bone and water each in its own medium (`propagation/references.rs`):
/// +0.8 (untilted), -2.3, +4.3 and +4.1 % focal pressure, the focus 0.31, 0.40, 0.88 and 0.56 mm
/// off (with one mean medium and the oblique screen's rays refracted through the plate, tilted:
/// +3.5, +13.2 and +10.3 %, 0.65-1.53 mm; with the treads at normal incidence and unbent rays:
/// +30, +54 and +61 %, 1.8-3.4 mm). The untilted plate's faces lie inside the CT's cells, off
/// the planes: they are applied as faces between bone and water, given the phase of where they
/// lie (`interface/layered_faces.rs`; treated as the cells' averaged media it was +8.3 %, 2.4 mm
/// off). The plates as solids (shear 1500 m/s) are held against the exact elastic plate, tilted
/// to [`Tolerances::OBLIQUE_SOLID`].
#[test]
fn every_case_of_the_suite_matches_its_exact_solution_on_the_default_grid_within_its_tolerances() {
    let dir = scratch("test");
    let cases = suite(&dir).unwrap();
    assert!(cases.iter().any(|c| c.name == "tilt30") && cases.iter().any(|c| c.name == "bm5"));
    for case in cases {
        let c = compared(&case);
        assert!(c.passed(), "{} fails: {c:?}", c.name);
        // (focal pressure off exact by less than, focal position in m) held for the plates.
        let held = match c.name.as_str() {
            // Measured +0.8 and +1.2 %, 0.31 and 0.34 mm.
            "tilt0" => Some((0.03, 0.45e-3)),
            "tilt0_shear1500" => Some((0.03, 0.45e-3)),
            "tilt10" => Some((0.04, 0.6e-3)),
            "tilt20" => Some((0.07, 1.2e-3)),
            "tilt30" => Some((0.07, 1.0e-3)),
            // Measured +0.4, +4.7, -0.2 %, 1.02, 1.05, 1.93 mm.
            "tilt10_shear1500" => Some((0.03, 1.3e-3)),
            "tilt20_shear1500" => Some((0.07, 1.3e-3)),
            "tilt30_shear1500" => Some((0.03, 2.2e-3)),
            _ => None,
        };
        if let Some((pressure, position)) = held {
            assert!(c.focal_pressure_error().abs() < pressure, "{} got worse: {c:?}", c.name);
            assert!(c.focal_position_error().abs() < position, "{} focus moved: {c:?}", c.name);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The untilted plate from a CT, its first face moved against the planes (30.1 and 30.45 mm:
/// inside a cell, not where the suite has it) and as a fluid or a solid of shear 1300, 1500 and
/// 1700 m/s (cortical bone's range), against the exact plate. Its faces convert on the planes
/// between the pure media beyond their cells, each wave given its true path over the misplaced
/// segment less the face cell's marched one (`interface/layered_faces.rs`, `faces.rs`): measured
/// within 0.2 % and 0.11 mm, the axial profile within 0.6 % and the focal-plane correlation
/// 1.0000 for the first face anywhere from 30.0 to 30.6 mm. Held to 1 %, 0.25 mm, an axial
/// profile of 2 % and a correlation of 0.999 (the suite's are 5 %, 0.5 mm, 5 %, 0.99): taking
/// the segment's own axial wavenumber for the march's left +0.7 to +4.1 %, 0.35 mm and 5.7 %, and
/// faces treated as between the cells' averaged media (no conversion, one mean medium in the
/// plate's slabs) were +8 % and 2.4 mm off as a fluid and 2.9 mm off as a solid.
#[test]
fn an_untilted_ct_plate_converts_on_the_planes_wherever_its_faces_lie() {
    let dir = scratch("untilted");
    for z1 in [30.1e-3, 30.45e-3] {
        for shear in [None, Some(1300.0), Some(1500.0), Some(1700.0)] {
            let case = has_core::validation::tilted_plate_from(&dir, 0.0, shear, z1).unwrap();
            let c = compared(&case);
            assert!(c.focal_pressure_error().abs() < 0.01, "{} at {z1}: {c:?}", c.name);
            assert!(c.focal_position_error().abs() < 0.25e-3, "{} at {z1}: {c:?}", c.name);
            assert!(c.axial_error < 0.02 && c.correlation > 0.999, "{} at {z1}: {c:?}", c.name);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// BM3's plate as a region that ends beside the beam (a cylinder of radius 35 mm about the axis,
/// water beyond; the beam is about 17 mm in radius at the plate), as a fluid and as solids of
/// shear 1300, 1500 and 1700 m/s, against the unbounded plate's exact solution. Its faces cover
/// part of their planes, and the slabs after them take two reference media: measured -0.1, -1.6,
/// -0.8 and +0.1 %, the focus within 0.36, 0.48, 0.02 and 0.02 mm (with one mean medium +10.8 %
/// and 2.3 mm as a fluid, +15.6 % as a solid of 1500 m/s). Held to 5 % and 0.6 mm (1300 m/s lies
/// near the suite's 0.5 mm).
#[test]
fn a_region_plate_that_ends_beside_the_beam_matches_the_unbounded_plate() {
    let dir = scratch("finite-plate");
    let fluid = suite(&dir).unwrap().into_iter().find(|c| c.name == "bm3").unwrap();
    let solids = [1300.0, 1500.0, 1700.0].map(|cs| has_core::validation::solid_plate(cs).unwrap());
    for mut case in std::iter::once(fluid).chain(solids) {
        for region in case.scenario.regions.iter_mut().flatten() {
            region.shape = "cylinder".into();
            region.radius_mm = Some(35.0);
        }
        let c = compared(&case);
        assert!(c.focal_pressure_error().abs() < 0.05, "{}: {c:?}", c.name);
        assert!(c.focal_position_error().abs() < 0.6e-3, "{}: {c:?}", c.name);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The tilted plate as a solid of shear faster than water (1700 m/s; the suite holds 1500 m/s:
/// the CT's bone shear, with the
/// compressional wave's attenuation) against the exact elastic solution through it
/// (`reference::elastic` in `reference::oblique`), on the default grid. Its walls convert at each
/// wave's own incidence (`physics/propagation/oblique_shear.rs`): measured +0.4, +4.7, -0.2 %
/// (1500 m/s) and -8.3, +1.0, -7.5 % (1700 m/s) focal pressure at 10, 20 and 30°, the focus
/// within 1.0-1.9 and 0.4-0.7 mm; the same CT marched without shear (a fluid bone) is -9 to
/// -60 % and up to 10 mm off there (-32 to -60 % at 20-30°, where shear carries most of what
/// crosses). Held within 12 % and 1.0 mm at 1700 m/s, so that a change that makes them worse
/// fails, and so that losing the conversion fails at once.
#[test]
fn tilted_solid_plates_convert_at_their_walls_towards_the_exact_elastic_solution() {
    let dir = scratch("tilted-solid");
    for (cs, position) in [(1700.0, 1.0e-3)] {
        for tilt in [10.0, 20.0, 30.0] {
            let case = tilted_plate(&dir, tilt, Some(cs)).unwrap();
            let c = compared(&case);
            assert!(c.focal_pressure_error().abs() < 0.12, "{} got worse: {c:?}", c.name);
            assert!(c.focal_position_error().abs() < position, "{} focus moved: {c:?}", c.name);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The suite's caps as solids (shear 1300, 1500, 1700 m/s) against the exact solid shell
/// (`reference::solid_shell`: P-SV conversion at both surfaces). The march converts nothing at a
/// CT's curved faces and carries the caps as fluids. About the focus (`shell_*`, every ray at
/// normal incidence, where no wave converts) that is right in pressure: measured +1.3, +0.5,
/// +0.5 %, the focus 1.30, 0.40 and 0.41 mm short; met at up to 16° (`bm5_*`) it is not: +33.1,
/// -4.1, +0.3 %, the focus 3.29 mm short, 0.03 mm and 2.85 mm deep (the exact solid cap's focal
/// pressure is 0.77, 1.07 and 1.02 times the fluid cap's). Held where they are, so that a change
/// that makes them worse fails and converting at curved faces shows as a gain
/// (`docs/validation.md`).
#[test]
fn solid_caps_are_held_where_the_fluid_march_leaves_them() {
    let dir = scratch("solid-caps");
    for cs in [1300.0, 1500.0, 1700.0] {
        for case in has_core::validation::solid_shells(&dir, cs).unwrap() {
            let c = compared(&case);
            // (focal pressure, focal position in m) held.
            let (pressure, position) = match c.name.as_str() {
                "bm5_shear1300" => (0.36, 3.6e-3),
                "bm5_shear1700" => (0.03, 3.2e-3),
                "shell_shear1300" => (0.03, 1.5e-3),
                _ => (0.06, 0.5e-3),
            };
            assert!(c.focal_pressure_error().abs() < pressure, "{} got worse: {c:?}", c.name);
            assert!(c.focal_position_error().abs() < position, "{} focus moved: {c:?}", c.name);
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The CT shells stay within every tolerance as the step shrinks: with 0.25 mm (a third of the
/// default) shell +0.1 %, -0.35 mm, axial 4.2 %; bm5 +3.1 %, -0.21 mm, 3.6 %.
#[test]
fn ct_shells_match_their_exact_solutions_with_a_fine_step() {
    let dir = scratch("fine");
    let tol = Tolerances::default();
    for mut case in suite(&dir).unwrap().into_iter().filter(|c| c.name == "shell" || c.name == "bm5") {
        case.scenario.grid.step_mm = Some(0.25);
        let c = compared(&case);
        assert!(c.passes(&tol), "{} fails at 0.25 mm: {c:?}", c.name);
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Thinner caps (3, 3.5, 4 mm), near the wall's half-wave thickness (2.8 mm at 500 kHz), where
/// the reverberation inside the wall decides what crosses it. On the default grid the 4 mm cap
/// meets every tolerance, the 3.5 mm cap all but its focal position (0.58 mm short), the 3 mm cap
/// only the correlation (5.6 % low, 0.85 mm short, axial 8.6 %): the march loses transmission in
/// thin walls tilted against the planes. Held there, so that a change that makes them worse
/// fails, until that error is found (`docs/validation.md`).
#[test]
fn thin_ct_shells_are_held_where_they_are() {
    let dir = scratch("thin");
    let tol = Tolerances::default();
    for case in thin_shells(&dir).unwrap() {
        let c = compared(&case);
        // (focal pressure, focal position in m, axial profile) held; correlation as the suite's.
        let (pressure, position, axial) = match c.name.as_str() {
            "shell3" => (0.065, 0.95e-3, 0.095),
            "shell3.5" => (tol.focal_pressure, 0.65e-3, tol.axial_profile),
            _ => (tol.focal_pressure, tol.focal_position, tol.axial_profile),
        };
        assert_held(&c, (pressure, position, axial));
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The suite's caps (`shell`, `bm5`) with cortical bone of 2 and 8 dB/cm at 500 kHz (ITRUSST's is
/// 4), against their exact solutions on the default grid. Measured: 2 dB/cm `shell` +1.9 %,
/// -0.41 mm, axial 4.8 %; `bm5` +2.8 %, -0.36 mm, 3.6 % (the suite's tolerances met); 8 dB/cm
/// `shell` -0.5 %, **-0.59 mm, axial 6.8 %**; `bm5` +4.1 %, -0.30 mm, 5.0 %. The 8 dB/cm caps are
/// held where they are (`docs/validation.md`), so that a change that makes them worse fails.
#[test]
fn ct_shells_of_other_bone_losses_match_their_exact_solutions() {
    let dir = scratch("lossy");
    let tol = Tolerances::default();
    for db_cm in [2.0, 8.0] {
        for case in lossy_shells(&dir, db_cm).unwrap() {
            let c = compared(&case);
            match c.name.as_str() {
                "shell_8db" => assert_held(&c, (tol.focal_pressure, 0.65e-3, 0.075)),
                "bm5_8db" => assert_held(&c, (tol.focal_pressure, tol.focal_position, 0.055)),
                _ => assert!(c.passes(&tol), "{} fails: {c:?}", c.name),
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A tilted plate of another thickness (`tilted_slab_from`) is that thick in its CT: along the
/// normal of a 20° plate 10 mm thick, bone from 0.3 to 9.7 mm past its first face and water from
/// 0.3 mm before to 0.3 mm beyond it (a voxel of 0.25 mm and the conversion's interpolation
/// between voxel centres blur a face by less); the 6.5 mm plate ends at 6.5 mm; a thickness of
/// zero or less is refused by name.
#[test]
fn a_tilted_slab_is_as_thick_as_it_is_asked() {
    let dir = scratch("tilted-slab");
    let (z1, tilt) = (30e-3, 20f64.to_radians());
    let speed_at = |case: &Case, depth: f64| {
        let medium = case.scenario.resolve().unwrap().medium;
        let (s, c) = tilt.sin_cos();
        // A point of the plate's frame `depth` along the normal from the first face's axis point.
        medium.properties_at(depth * s, 0.0, z1 + depth * c, 5e5).sound_speed
    };
    for (thickness, tag) in [(10e-3, "thick"), (6.5e-3, "default")] {
        let case = has_core::validation::tilted_slab_from(&dir.join(tag), 20.0, None, z1, thickness).unwrap();
        std::fs::create_dir_all(dir.join(tag)).unwrap();
        case.write_inputs().unwrap();
        assert!((speed_at(&case, -0.3e-3) - 1500.0).abs() < 1.0, "{tag}: water before the plate");
        for depth in [0.3e-3, 0.5 * thickness, thickness - 0.3e-3] {
            assert!((speed_at(&case, depth) - 2800.0).abs() < 1.0, "{tag}: bone at {depth}");
        }
        assert!((speed_at(&case, thickness + 0.3e-3) - 1500.0).abs() < 1.0, "{tag}: water beyond the plate");
    }
    let err = has_core::validation::tilted_slab_from(&dir, 20.0, None, z1, 0.0).unwrap_err();
    assert!(err.to_string().contains("thickness"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
