//! CT-based prediction of the per-element aberration: a bone shell read from a CT NIfTI,
//! shifted off the focus so that each element's wave crosses it at its own angle and
//! thickness; the predicted phases, applied through the ordinary forward march, must restore the
//! focus.
//!
//! Run with `cargo test --release -p has-core --test prediction -- --nocapture` to see the numbers.

use has_core::nifti;
use has_core::prediction::predict;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::path::PathBuf;

/// HU of the shell: ψ = 0.4 in the porosity model (2340 m/s, 1720 kg/m³).
const SHELL_HU: f32 = 1200.0;

/// A fresh folder for one test's files.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("arfi-prediction-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A CT (0.5 mm voxels, identity transform) of bone inside the sphere of radius `outer` about
/// `center` and outside that of radius `inner` about `inner_center` (m, transducer frame), air
/// (the coupling medium: water) elsewhere, with 4 mm of margin.
fn shell_ct(center: [f64; 3], outer: f64, inner_center: [f64; 3], inner: f64) -> Vec<u8> {
    let h = 0.5e-3;
    let half = outer + 4e-3;
    let n = (2.0 * half / h).ceil() as usize;
    let corner = center.map(|c| c - half + 0.5 * h);
    let mut values = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [corner[0] + i as f64 * h, corner[1] + j as f64 * h, corner[2] + k as f64 * h];
                let r = |c: [f64; 3]| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
                values.push(if r(inner_center) >= inner && r(center) <= outer { SHELL_HU } else { -1000.0 });
            }
        }
    }
    // RAS x and y are the frame's negated (identity patient-to-transducer transform).
    let mm = |v: f64| v * 1e3;
    let affine = [[-mm(h), 0.0, 0.0, -mm(corner[0])], [0.0, -mm(h), 0.0, -mm(corner[1])], [0.0, 0.0, mm(h), mm(corner[2])]];
    nifti::encode([n, n, n], &values, affine)
}

/// A 128-element bowl (R 50 mm, aperture 56 mm) at 500 kHz in water focused at its centre of
/// curvature, with `[ct]` reading `shell.nii` from `dir`.
fn bowl_through_shell(dir: &std::path::Path) -> Simulation {
    let text = "frequency_hz = 500000.0\n\
        [transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 50.0\naperture_diameter_mm = 56.0\nelements = 128\n\
        [focus]\nposition_mm = [0.0, 0.0, 50.0]\n\
        [[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
        [ct]\nfile = \"shell.nii\"\n";
    Simulation::new(&Scenario::from_toml(text, Some(dir)).unwrap()).unwrap()
}

#[test]
fn predicted_phases_restore_the_focus_through_a_shifted_uneven_shell() {
    // A shell of outer radius 20 mm whose centre lies 4 mm beside and 4 mm before the focus, its
    // inner surface (radius 15 mm) shifted 4 mm from the outer one: 1 to 9 mm of bone, crossed
    // by each element's path at an angle and length of its own. (A shell of even thickness merely
    // shifted aberrates little: 3 mm shifted by (5, 0, -4) mm left 0.98 of the best focus.) The
    // checks:
    // - the shell aberrates: the uncorrected focus is below 0.8 of the best the skull allows
    //   (Σ|h_e|, every element's wave arriving in phase);
    // - the predicted phases restore at least 0.9 of that best (the target), applied as
    //   added phases through the forward march of the whole array (`Simulation::field`), which
    //   must also agree with the prediction's own focal pressure (the sum of reciprocal
    //   responses) to 1e-5 (single-precision Rayleigh sums).
    let dir = scratch("shifted");
    std::fs::write(dir.join("shell.nii"), shell_ct([4e-3, 0.0, 46e-3], 20e-3, [0.0, 0.0, 46e-3], 15e-3)).unwrap();
    let sim = bowl_through_shell(&dir);
    let p = predict(sim.clone(), None).unwrap();
    let best = p.optimal_pressure;
    let mean_t = p.transmission.iter().sum::<f64>() / p.transmission.len() as f64;
    println!(
        "uneven shell: focal |p| (MPa) water {:.3}, uncorrected {:.3}, straight-ray CT steering {:.3}, predicted {:.3}, best {:.3}; \
         predicted/best {:.3}, uncorrected/best {:.3}; transmission {:.3} mean, phases {:.2} rad peak to peak",
        p.reference_pressure / 1e6,
        p.uncorrected_pressure / 1e6,
        p.ray_pressure / 1e6,
        p.corrected_pressure / 1e6,
        best / 1e6,
        p.corrected_pressure / best,
        p.uncorrected_pressure / best,
        mean_t,
        p.phases.iter().copied().fold(f64::NEG_INFINITY, f64::max) - p.phases.iter().copied().fold(f64::INFINITY, f64::min)
    );
    assert!(p.uncorrected_pressure < 0.8 * best, "the shell does not aberrate enough for the test");
    assert!(p.corrected_pressure >= 0.9 * best, "predicted {:.3e} of best {best:.3e}", p.corrected_pressure);
    // The same correction through the forward march: added phases on top of the scenario's own
    // steering.
    let added: Vec<f64> = (0..sim.n_elements()).map(|e| p.reference_steering[e] - p.phases[e] - sim.steering[e]).collect();
    let field = sim.field(&added, Some(p.target[2])).unwrap();
    let g = &sim.grid;
    let index = |v: f64, d: f64, n: usize| ((v / d).round() as i64 + (n / 2) as i64) as usize;
    let marched = field.pressure[[index(p.target[1], g.dy, g.ny), index(p.target[0], g.dx, g.nx)]].norm();
    let err = (marched - p.corrected_pressure).abs() / p.corrected_pressure;
    println!(
        "forward march with the predicted phases: {:.4} MPa (prediction {:.4} MPa, error {err:.1e}, tolerance 1e-5)",
        marched / 1e6,
        p.corrected_pressure / 1e6
    );
    assert!(err < 1e-5);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_prediction_needs_a_ct() {
    let text = "[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 40.0\naperture_diameter_mm = 30.0\nelements = 16\n\
                [focus]\nposition_mm = [0.0, 0.0, 40.0]\n[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n";
    let sim = Simulation::new(&Scenario::from_toml(text, None).unwrap()).unwrap();
    let err = predict(sim, None).unwrap_err().to_string();
    assert!(err.contains("ct") && err.contains("CT of the head"), "{err}");
}
