//! MR-ARFI images as a scanner sees them: bone gives no signal and does not move, so it is absent
//! (NaN) from images, the focal ARFI and the Eq. 4 mask are taken near the target among imaged
//! pixels, and every fit leaves pixels without signal out.
//!
//! The scenario: a 500 kHz bowl focused 50 mm deep, through 5 mm of porous bone (20 dB/cm/MHz)
//! into brain, imaged on the x–z plane through the beam axis, so that the image crosses the
//! bone plate. Per unit |p|² the porous bone takes about 7 times the brain's radiation force, and
//! the beam meets it before it has lost its amplitude: a model that let bone move would put its
//! brightest pixel in the plate (checked below, so that the test can fail).

use has_core::control::Control;
use has_core::inverse::cost::{build_model, check_image, Measurement};
use has_core::inverse::diagnose::{diagnose, DiagnoseOptions};
use has_core::inverse::estimate::workflow::{estimate_aberration, EstimateRequest};
use has_core::physics::mr::{add_noise, focal_peak};
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use ndarray::Array2;

/// The plate: z from 20 to 25 mm.
const PLATE_MM: (f64, f64) = (20.0, 25.0);

/// The bowl through the bone plate into brain; `bone_mr` is appended to the bone's material (e.g.
/// to make it move).
fn through_plate(bone_mr: &str) -> Simulation {
    let text = format!(
        "frequency_hz = 500000.0\n\
         [transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 50.0\naperture_diameter_mm = 50.0\nelements = 64\n\
         [focus]\nposition_mm = [0.0, 0.0, 50.0]\n\
         [[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
         [[material]]\nname = \"bone\"\nsound_speed_m_s = 2400.0\ndensity_kg_m3 = 1700.0\nattenuation_db_cm_mhz = 20.0\n{bone_mr}\n\
         [[material]]\nname = \"brain\"\nsound_speed_m_s = 1546.0\ndensity_kg_m3 = 1040.0\nattenuation_db_cm_mhz = 0.6\n\
         [[region]]\nmaterial = \"bone\"\nshape = \"slab\"\nz_min_mm = {}\nz_max_mm = {}\n\
         [[region]]\nmaterial = \"brain\"\nshape = \"slab\"\nz_min_mm = {}\nz_max_mm = 90.0\n\
         [grid]\nspacing_mm = 0.5\nstep_mm = 0.5\n\
         [mr]\nplane = \"xz\"\ncenter_mm = [0.0, 0.0, 40.0]\nfov_mm = [40.0, 60.0]\nmatrix = [40, 60]\nslice_thickness_mm = 3.0\n",
        PLATE_MM.0, PLATE_MM.1, PLATE_MM.1
    );
    Simulation::new(&Scenario::from_toml(&text, None).unwrap()).unwrap()
}

/// z (mm) of image row `j` (the image's second axis is z on the x–z plane).
fn row_z_mm(sim: &Simulation, j: usize) -> f64 {
    sim.mr.pixel_center(1, j) * 1e3
}

#[test]
fn bone_is_absent_from_images_and_the_focus_sets_the_amplitude() {
    let sim = through_plate("");
    let image = sim.arfi_image(&[]).unwrap();
    // Pixels are 1 mm: a row whose centre lies inside the plate by more than half a pixel is
    // wholly bone, one outside it by as much has none.
    for j in 0..image.ncols() {
        let z = row_z_mm(&sim, j);
        let inside = z > PLATE_MM.0 + 0.5 && z < PLATE_MM.1 - 0.5;
        let outside = z < PLATE_MM.0 - 0.5 || z > PLATE_MM.1 + 0.5;
        for i in 0..image.nrows() {
            if inside {
                assert!(image[[i, j]].is_nan(), "bone pixel ({i}, {j}) at z = {z} mm is {}", image[[i, j]]);
            }
            if outside {
                assert!(image[[i, j]].is_finite(), "tissue or water pixel ({i}, {j}) at z = {z} mm is NaN");
            }
        }
    }
    // Water in front of the plate gives signal but feels no force: exactly zero.
    let water_row = (0..image.ncols()).find(|&j| row_z_mm(&sim, j) < PLATE_MM.0 - 1.0).unwrap();
    assert!(image.column(water_row).iter().all(|&v| v == 0.0));
    // The ideal amplitude is set at the focus: the focal ARFI is the scenario's 0.6 rad (to
    // rounding), within a pixel (1.5 mm) of the axis and 4 mm of the target along it (the
    // force peak of a bowl of this Fresnel number lies a few mm before its centre of curvature:
    // 2.5 mm here).
    let ((i, j), focal) = sim.focal_arfi(&image, "image").unwrap();
    let (x, z) = (sim.mr.pixel_center(0, i) * 1e3, row_z_mm(&sim, j));
    println!("focal ARFI {focal:.4} rad at x = {x:.1} mm, z = {z:.1} mm");
    assert!((focal - 0.6).abs() < 1e-9, "{focal}");
    assert!(x.abs() < 1.5 && (z - 50.0).abs() < 4.0, "({x}, {z})");
    // The test discriminates: with bone that moves and gives signal, the brightest pixel is in
    // the plate, several times the focus (the skull ring of a model that shows bone's absorbed
    // force as displacement; its global maximum would have set the amplitude).
    let moving = through_plate("mr_signal = true\ndisplacement_scale = 1.0");
    let image = moving.arfi_image(&[]).unwrap();
    let ((_, jmax), max) = focal_peak(&image, &Array2::from_elem(image.dim(), true)).unwrap();
    let focal_moving = image[[i, j]];
    println!("bone that moves: brightest {max:.3} rad at z = {:.1} mm, focus {focal_moving:.3} rad", row_z_mm(&moving, jmax));
    let z_max = row_z_mm(&moving, jmax);
    assert!(z_max > PLATE_MM.0 - 1.0 && z_max < PLATE_MM.1 + 1.0, "brightest pixel at z = {z_max} mm");
    assert!(max > 1.5 * focal_moving, "{max} vs {focal_moving}");
}

#[test]
fn images_without_signal_in_places_are_fitted_on_their_imaged_pixels() {
    // An aberrated image through the plate with noise: NaN in the bone stays NaN, the image
    // passes the checks, the mask holds only imaged pixels around the focus, and a 16-group
    // estimate from it runs and fits to the noise (misfit about 1).
    let sim = through_plate("");
    let truth: Vec<f64> = (0..sim.n_groups).map(|g| 0.8 * ((g as f64) * 1.3).sin()).collect();
    let mut image = sim.arfi_image(&truth).unwrap();
    add_noise(&mut image, 0.02, 7).unwrap();
    assert!(image.iter().any(|v| v.is_nan()));
    check_image(&sim, &image, "image").unwrap();
    let m = vec![Measurement { image: image.clone(), known: vec![] }];
    let model = build_model(&sim, &m, sim.mask_fraction, 3).unwrap();
    // The noise floor from the imaged background: the pairs with a NaN pixel are left out (with
    // them it would be NaN). Tolerance: 1.4826·MAD of about 2000 pairs scatters by ~3 %.
    println!("noise floor {:.4} rad (0.02 added)", model.noise);
    assert!((model.noise - 0.02).abs() < 0.004, "{}", model.noise);
    let report = estimate_aberration(&sim, &m, &EstimateRequest::default(), Control::default()).unwrap();
    let misfit = report.assessment.misfit;
    println!("16-group estimate through the plate: {} pixels, misfit {misfit:.2}", report.n_pixels);
    assert!(report.n_pixels > 10);
    // The misfit's chi-square spread for ~100 pixels is about ±0.3 (95 %).
    assert!(misfit < 1.4, "{misfit}");
}

#[test]
fn images_with_no_signal_near_the_target_are_refused_by_name() {
    let sim = through_plate("");
    let mut image = sim.arfi_image(&[]).unwrap();
    let region = sim.focal_region();
    image.zip_mut_with(&region, |v, &near| {
        if near {
            *v = f64::NAN
        }
    });
    let e = check_image(&sim, &image, "image[1]").unwrap_err().to_string();
    assert!(e.starts_with("image[1]") && e.contains("no imaged pixel") && e.contains("focal_search_radius_mm"), "{e}");
    let mut image = sim.arfi_image(&[]).unwrap();
    image[[0, 0]] = f64::INFINITY;
    let e = check_image(&sim, &image, "image").unwrap_err().to_string();
    assert!(e.contains("pixel (0, 0) is inf"), "{e}");
}

#[test]
fn diagnose_names_nothing_on_noise_through_the_plate() {
    // The model is right and the image is the ideal beam plus noise, with the plate's pixels
    // absent: no effect may be named, and the pixel count is that of the imaged pixels.
    let sim = through_plate("");
    let mut image = sim.arfi_image(&[]).unwrap();
    add_noise(&mut image, 0.02, 3).unwrap();
    let imaged = image.iter().filter(|v| v.is_finite()).count();
    let d = diagnose(&sim, &[Measurement { image, known: vec![] }], &DiagnoseOptions::default(), &Control::default()).unwrap();
    println!("diagnose: {} steps, {} pixels of {}", d.steps.len(), d.n_pixels, 40 * 60);
    assert_eq!(d.n_pixels, imaged);
    assert!(d.steps.is_empty(), "named {:?}", d.steps.iter().map(|s| s.effect).collect::<Vec<_>>());
}
