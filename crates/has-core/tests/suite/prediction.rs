//! CT-based prediction of the per-element aberration: a bone shell read from a CT NIfTI,
//! shifted off the focus so that each element's wave crosses it at its own angle and
//! thickness; the predicted phases, applied through the ordinary forward march, must restore the
//! focus.
//!
//! Run with `cargo test --release -p has-core --test suite prediction:: -- --nocapture` to see the numbers.

use has_core::nifti;
use has_core::prediction::{predict, predict_scenario, predict_scenario_with, PredictionOptions};
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

/// A CT (voxels of `h`, identity transform) of `hu` inside the sphere of radius `outer` about
/// `center` and outside that of radius `inner` about `inner_center`, below `z_below` (m,
/// transducer frame), air (the coupling medium: water) elsewhere, with 4 mm of margin.
fn shell_ct(hu: f32, center: [f64; 3], outer: f64, inner_center: [f64; 3], inner: f64, z_below: f64, h: f64) -> Vec<u8> {
    let half = outer + 4e-3;
    let n = (2.0 * half / h).ceil() as usize;
    let corner = center.map(|c| c - half + 0.5 * h);
    let mut values = Vec::with_capacity(n * n * n);
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = [corner[0] + i as f64 * h, corner[1] + j as f64 * h, corner[2] + k as f64 * h];
                let r = |c: [f64; 3]| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
                let bone = r(inner_center) >= inner && r(center) <= outer && p[2] < z_below;
                values.push(if bone { hu } else { -1000.0 });
            }
        }
    }
    // RAS x and y are the frame's negated (identity patient-to-transducer transform).
    let mm = |v: f64| v * 1e3;
    let affine = [[-mm(h), 0.0, 0.0, -mm(corner[0])], [0.0, -mm(h), 0.0, -mm(corner[1])], [0.0, 0.0, mm(h), mm(corner[2])]];
    nifti::encode([n, n, n], &values, affine)
}

/// A 128-element bowl (R 50 mm, aperture 56 mm) at 500 kHz in water focused at its centre of
/// curvature, with `[ct]` reading `shell.nii` from `dir`, and `tail` after its `file` (more
/// `[ct]` keys, or a `[grid]`).
fn bowl_through_shell(dir: &std::path::Path, tail: &str) -> Simulation {
    Simulation::new(&bowl_scenario(dir, tail)).unwrap()
}

fn bowl_scenario(dir: &std::path::Path, tail: &str) -> Scenario {
    let text = format!(
        "frequency_hz = 500000.0\n\
        [transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 50.0\naperture_diameter_mm = 56.0\nelements = 128\n\
        [focus]\nposition_mm = [0.0, 0.0, 50.0]\n\
        [[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
        [ct]\nfile = \"shell.nii\"\n{tail}"
    );
    Scenario::from_toml(&text, Some(dir)).unwrap()
}

#[test]
fn predicted_phases_restore_the_focus_through_a_shifted_uneven_shell() {
    // A shell of outer radius 20 mm whose centre lies 4 mm beside and 4 mm before the focus, its
    // inner surface (radius 15 mm) shifted 4 mm from the outer one: 1 to 9 mm of bone, crossed
    // by each element's path at an angle and length of its own. (A shell of even thickness merely
    // shifted aberrates little: 3 mm shifted by (5, 0, -4) mm leaves 0.98 of the best focus.) The
    // checks:
    // - the shell aberrates: the uncorrected focus is below 0.8 of the best the skull allows
    //   (Σ|h_e|, every element's wave arriving in phase);
    // - the predicted phases restore at least 0.9 of that best (the prediction's required
    //   accuracy), applied as added phases through the forward march of the whole array
    //   (`Simulation::field`), which must also agree with the prediction's own focal pressure
    //   (the sum of reciprocal responses) to 1e-5 (single-precision Rayleigh sums).
    let dir = scratch("shifted");
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, [4e-3, 0.0, 46e-3], 20e-3, [0.0, 0.0, 46e-3], 15e-3, f64::INFINITY, 0.5e-3))
        .unwrap();
    let sim = bowl_through_shell(&dir, "");
    let p = predict(sim.clone(), None).unwrap();
    let best = p.optimal_pressure;
    let mean_t = p.transmission.iter().sum::<f64>() / p.transmission.len() as f64;
    println!(
        "uneven shell: focal |p| (MPa) water {:.3}, uncorrected {:.3}, straight-ray CT steering {:.3}, predicted {:.3}, best {:.3}; \
         predicted/best {:.3}, uncorrected/best {:.3}; transmission {:.3} mean, phases {:.2} rad peak to peak",
        p.reference_pressure / 1e6,
        p.uncorrected_pressure / 1e6,
        p.ray_steering_pressure / 1e6,
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
    // From the scenario (what `arfi predict` calls), its simulation built without the ARFI
    // amplitude's march: the same prediction to the last bit (the amplitude scales images only).
    let q = predict_scenario(&bowl_scenario(&dir, ""), None).unwrap();
    assert_eq!(q, p);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_prediction_needs_a_ct() {
    let text = "[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 40.0\naperture_diameter_mm = 30.0\nelements = 16\n\
                [focus]\nposition_mm = [0.0, 0.0, 40.0]\n[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n";
    let sim = Simulation::new(&Scenario::from_toml(text, None).unwrap()).unwrap();
    let err = predict(sim, None).unwrap_err().to_string();
    assert!(err.contains("ct") && err.contains("CT of the head"), "{err}");
    let keep = PredictionOptions { keep_simulation: true, ..PredictionOptions::default() };
    let err = predict_scenario_with(&Scenario::from_toml(text, None).unwrap(), None, keep).err().map(|e| e.to_string());
    assert!(err.as_deref().is_some_and(|e| e.starts_with("ct") && e.contains("CT of the head")), "{err:?}");
}

/// Pressure transmission of a plane wave at normal incidence through a layer of `(rho, c, alpha)`
/// (kg/m³, m/s, Np/m) and thickness `d` (m) between water half-spaces, every reflection inside
/// the layer included: the exit-face pressure over the entry-face incident pressure, from the
/// 2x2 transfer matrix of (p, v) (`M = [[cos kd, i·sin kd / Y], [i·Y·sin kd, cos kd]]`,
/// `Y = k / (omega·rho)`; time convention `exp(-i·omega·t)`).
fn layer_transmission(layer: (f64, f64, f64), d: f64, frequency: f64) -> has_core::Complex64 {
    use has_core::Complex64 as C64;
    let omega = 2.0 * std::f64::consts::PI * frequency;
    let k = C64::new(omega / layer.1, layer.2);
    let (y, yw) = (k / (omega * layer.0), C64::new(1.0 / 1.5e6, 0.0));
    let (cos, sin) = ((k * d).cos(), (k * d).sin());
    let m = [[cos, C64::i() * sin / y], [C64::i() * y * sin, cos]];
    // Incident 1 and reflected r on the entry side, t on the exit side:
    // (t, yw·t) = M · (1 + r, yw·(1 - r)).
    let (a, b) = (m[0][0] + m[0][1] * yw, m[0][0] - m[0][1] * yw);
    let (c, e) = (m[1][0] + m[1][1] * yw, m[1][0] - m[1][1] * yw);
    let r = (c - yw * a) / (yw * b - e);
    a + b * r
}

#[test]
fn a_concentric_shell_costs_the_layer_transmission_and_leaves_the_focus() {
    // The bowl focused at the centre of a 3 mm bone shell (inner radius 25 mm): every element's
    // path meets the shell at normal incidence, so each element's transmission must be the exact
    // planar layer's |T| (with its reverberation) over that of the reference (the shell read as
    // soft tissue), its predicted phase the same for every element, the focal pressure |T| of
    // water's and the focus in place. Only the half of the shell before the focus is bone: the
    // far half would send its echo back into the focus (a concave mirror about it), which a
    // single transmission does not hold (with the whole shell the focus gets 0.44 of water's
    // focal pressure against |T| = 0.33). Grid 0.375 mm (λ/8) and CT voxels of 0.25 mm: at 0.75 mm
    // and 0.5 mm the cells that average bone and water grade the faces, which then reflect less
    // (transmission 12–16 % above the exact layer's; the same as a plate in tests/suite/ct.rs).
    // Checked over the elements' polar angle (0 to 34°), this also tests what marching along z
    // does to an oblique layer.
    let dir = scratch("concentric");
    let center = [0.0, 0.0, 50e-3];
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, center, 28e-3, center, 25e-3, center[2], 0.25e-3)).unwrap();
    let sim = bowl_through_shell(&dir, "[grid]\nspacing_mm = 0.375\n");
    let f = sim.frequency;
    let bone = has_core::physics::ct::HuConversion::named("aubry2003").unwrap().properties(SHELL_HU as f64, f).unwrap();
    let brain = has_core::Material::new("brain", 1546.0, 1040.0, 0.6).unwrap().properties(f);
    let t_bone = layer_transmission((bone.density, bone.sound_speed, bone.attenuation), 3e-3, f);
    let t_brain = layer_transmission((brain.density, brain.sound_speed, brain.attenuation), 3e-3, f);
    let p = predict(sim.clone(), None).unwrap();
    let polar: Vec<f64> = sim
        .transducer
        .elements
        .iter()
        .map(|e| {
            let q = e.reference_point();
            let v = [q[0] - center[0], q[1] - center[1], q[2] - center[2]];
            (-v[2] / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).acos().to_degrees()
        })
        .collect();
    println!(
        "exact layer at normal incidence: |T| bone {:.4}, brain {:.4}, ratio {:.4}; arg(T_bone / T_brain) {:.3} rad",
        t_bone.norm(),
        t_brain.norm(),
        t_bone.norm() / t_brain.norm(),
        (t_bone / t_brain).arg()
    );
    // Tolerances: transmission within 10 % of the exact layer's (what 0.375 mm cells still grade
    // of the faces, and a sphere of radius 8 λ taken for a plane), 15 % beyond 27°, the predicted
    // phase the same for every polar angle to 0.2 rad (about 10 % of the bone's 1.9 rad against
    // soft tissue). Beyond 27° the wall is tilted against the planes by as much, and the march
    // loses transmission through a thin tilted wall (the validation's 3 mm cap too:
    // tests/suite/validation.rs); giving the treads the loss of the risers, which makes thicker walls
    // right, adds to that loss here. Shear waves, which a fluid model leaves out, carry part of
    // the flux beyond about 25° anyway (docs/validation.md).
    let exact = t_bone.norm() / t_brain.norm();
    let mut phase_range = (f64::INFINITY, f64::NEG_INFINITY);
    for (lo, hi) in [(0.0, 10.0), (10.0, 20.0), (20.0, 27.0), (27.0, 35.0)] {
        let sel: Vec<usize> = (0..polar.len()).filter(|&e| polar[e] >= lo && polar[e] < hi).collect();
        let mean = |v: &[f64]| sel.iter().map(|&e| v[e]).sum::<f64>() / sel.len() as f64;
        let (t, phase) = (mean(&p.transmission), mean(&p.phases));
        println!(
            "elements at {lo:>2}–{hi:>2}° ({:>3}): transmission {t:.4} ({:+.1} % of exact), predicted phase {phase:+.3} rad",
            sel.len(),
            100.0 * (t / exact - 1.0)
        );
        let tolerance = if lo < 27.0 { 0.1 } else { 0.15 };
        assert!((t / exact - 1.0).abs() < tolerance, "{lo}–{hi}°: transmission {t} against {exact}");
        phase_range = (phase_range.0.min(phase), phase_range.1.max(phase));
    }
    assert!(phase_range.1 - phase_range.0 < 0.2, "predicted phases vary by {:.3} rad with the polar angle", phase_range.1 - phase_range.0);
    let water = {
        let text = "frequency_hz = 500000.0\n[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 50.0\naperture_diameter_mm = 56.0\nelements = 128\n\
                    [focus]\nposition_mm = [0.0, 0.0, 50.0]\n[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
                    [grid]\nspacing_mm = 0.375\n";
        Simulation::new(&Scenario::from_toml(text, None).unwrap()).unwrap()
    };
    let (fs, fw) = (sim.field(&[], None).unwrap(), water.field(&[], None).unwrap());
    let peak = |f: &has_core::Field| {
        let (mut best, mut at) = (0.0, (0, 0));
        for ((j, i), v) in f.pressure.indexed_iter() {
            if v.norm() > best {
                (best, at) = (v.norm(), (i, j));
            }
        }
        (best, f.x[at.0], f.y[at.1])
    };
    let ((ps, xs, ys), (pw, _, _)) = (peak(&fs), peak(&fw));
    let axis = |f: &has_core::Field| {
        let k = (0..f.axis_pressure.len()).max_by(|&a, &b| f.axis_pressure[a].norm().total_cmp(&f.axis_pressure[b].norm())).unwrap();
        f.axis_z[k]
    };
    println!(
        "focal plane peak: {:.4} of water's (exact |T| {:.4}), at ({:.2}, {:.2}) mm; axis peak at {:.2} mm (water {:.2} mm)",
        ps / pw,
        t_bone.norm(),
        xs * 1e3,
        ys * 1e3,
        axis(&fs) * 1e3,
        axis(&fw) * 1e3
    );
    assert!((ps / pw / t_bone.norm() - 1.0).abs() < 0.1, "focal ratio {} against |T| {}", ps / pw, t_bone.norm());
    // In place: laterally on the centre pixel, along the axis within 1 mm of water's peak.
    assert!(xs.abs() < 0.2e-3 && ys.abs() < 0.2e-3 && (axis(&fs) - axis(&fw)).abs() < 1e-3);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn straight_rays_focus_through_a_concentric_soft_tissue_sphere() {
    // A sphere of soft tissue (HU 40: brain, 1546 m/s, 0.6 dB/cm/MHz) of radius 28 mm about the
    // focus: every element's path crosses 28 mm of it along a radius, at normal incidence, so the
    // straight-ray steering is exact and every wave must arrive at the focus in phase (no bone:
    // the reference is the head itself). The vertical screen marches each oblique path with the
    // phase of its vertical extent; the oblique screen along the path (see
    // `physics::propagation::Screen`). The oblique screen falls short of the best focus by about
    // 0.02 %, the vertical one by about 0.2 % (paths at 34° from the axis at most; out to 60°, a
    // 650 kHz hemisphere through a 60 mm sphere, about 0.04 % and 3 %). Tolerance: a shortfall
    // below 0.05 %, and the vertical screen's at least three times the oblique one's.
    let dir = scratch("tissue-sphere");
    let center = [0.0, 0.0, 50e-3];
    std::fs::write(dir.join("shell.nii"), shell_ct(40.0, center, 28e-3, center, 0.0, f64::INFINITY, 0.5e-3)).unwrap();
    let gain = |screen: &str| {
        let p = predict(bowl_through_shell(&dir, &format!("[grid]\nscreen = \"{screen}\"\n")), None).unwrap();
        p.reference_pressure / p.reference_optimal_pressure
    };
    let (oblique, vertical) = (gain("oblique"), gain("vertical"));
    println!("straight rays through a concentric tissue sphere: {oblique:.6} of the best focus (vertical screen {vertical:.6})");
    assert!(oblique > 0.9995 && 1.0 - vertical > 3.0 * (1.0 - oblique), "oblique {oblique}, vertical {vertical}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_ten_percent_error_in_the_ct_conversion_costs_focus() {
    // The uneven shell as the truth (default porosity constants); predictions from the same CT
    // with one constant 10 % off, driven on the true skull: how much of the best focus each keeps
    // (reported). Checked: every wrong one still beats no correction, and a sound speed 10 % off
    // costs more than a density or an attenuation 10 % off (the phase is what the prediction is
    // for; were a key not to reach the model, its prediction would be the truth's).
    let dir = scratch("sensitivity");
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, [4e-3, 0.0, 46e-3], 20e-3, [0.0, 0.0, 46e-3], 15e-3, f64::INFINITY, 0.5e-3))
        .unwrap();
    let truth = predict(bowl_through_shell(&dir, ""), None).unwrap();
    let best = truth.optimal_pressure;
    println!(
        "true constants: predicted {:.4} of the best, uncorrected {:.4}",
        truth.corrected_pressure / best,
        truth.uncorrected_pressure / best
    );
    let mut worst_kept = Vec::new();
    for (key, default) in [("bone_sound_speed_m_s", 2900.0), ("bone_density_kg_m3", 2200.0), ("bone_attenuation_max_db_cm_mhz", 80.0)] {
        let mut worst: f64 = 1.0;
        for factor in [0.9, 1.1] {
            let wrong = predict(bowl_through_shell(&dir, &format!("{key} = {}\n", default * factor)), None).unwrap();
            let kept = truth.pressure_with(&wrong.phases).unwrap() / best;
            let rms = (wrong.phases.iter().zip(&truth.phases).map(|(a, b)| has_core::phase::wrap(a - b).powi(2)).sum::<f64>()
                / truth.phases.len() as f64)
                .sqrt();
            println!("ct.{key} x {factor}: phase error {rms:.3} rad RMS, keeps {kept:.4} of the best focus");
            assert!(kept > truth.uncorrected_pressure / best, "{key} x {factor}: {kept}");
            worst = worst.min(kept);
        }
        worst_kept.push(worst);
    }
    assert!(worst_kept[0] < worst_kept[1] && worst_kept[0] < worst_kept[2], "{worst_kept:?}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn the_estimates_model_and_the_patients_steering_are_the_predictions_reference() {
    // `[ct] without_bone = true` is the medium a prediction's reference uses: the model of the
    // MR-ARFI estimate its prior is meant for.
    let dir = scratch("without-bone");
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, [4e-3, 0.0, 46e-3], 20e-3, [0.0, 0.0, 46e-3], 15e-3, f64::INFINITY, 0.5e-3))
        .unwrap();
    let skull = bowl_through_shell(&dir, "");
    let model = bowl_through_shell(&dir, "without_bone = true\n");
    assert_eq!(Some(model.medium.clone()), skull.medium.without_bone());
    assert_ne!(model.medium, skull.medium);
    // `steer_without_bone = true` keeps the bone in the medium but drives the model's steering:
    // the prediction's reference steering (and its focus shifts move the focus as the model's do).
    let patient = bowl_through_shell(
        &dir,
        "steer_without_bone = true
",
    );
    assert_eq!(patient.medium, skull.medium);
    assert_eq!(patient.steering_medium(), &model.medium);
    assert_eq!(skull.steering_medium(), &skull.medium);
    assert_eq!(patient.steering, model.steering);
    assert_ne!(patient.steering, skull.steering);
    assert_eq!(patient.focus_shift_phases([0.0, 0.0, 5e-3]).unwrap(), model.focus_shift_phases([0.0, 0.0, 5e-3]).unwrap());
    assert_eq!(predict(patient, None).unwrap().reference_steering, model.steering);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn the_bone_speed_sensitivity_follows_each_elements_layer() {
    // The uneven shell (outer sphere 4 mm off the inner one): each element's path to the focus
    // crosses 1–9 mm of bone. Reference, not the code: per element, the exact planar layer's
    // transmission phase (with its reverberation) for its straight-path thickness, at the shell's
    // sound speed and at that of a bone speed 10 % higher, per percent and less its weighted
    // common phase. The paths meet the outer face within 16° of its normal, and a plane layer
    // at normal incidence misses what the wave model keeps: refraction into the faster bone
    // (a path up to 11 % longer at 16°), faces that are not parallel, and the 0.5 mm cells'
    // grading of them. The model's sensitivity regressed on the layers' has a slope of about 1.2
    // and a correlation of about 0.95. Tolerance: correlation at least 0.93 (the shape over the aperture,
    // which is what an estimate fits the mode's coefficient on) and a slope of 0.9–1.4.
    use has_core::physics::ct::{BoneModel, HuConversion};
    use has_core::prediction::{bone_speed_sensitivity, BONE_SPEED_STEP};
    let dir = scratch("bone-speed");
    let (outer_c, inner_c) = ([4e-3, 0.0, 46e-3], [0.0, 0.0, 46e-3]);
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, outer_c, 20e-3, inner_c, 15e-3, f64::INFINITY, 0.5e-3)).unwrap();
    let scenario = bowl_scenario(&dir, "");
    let sim = Simulation::new(&scenario).unwrap();
    let (f, target) = (sim.frequency, sim.focus);
    let positions = sim.transducer.reference_points();
    let p = predict_scenario(&scenario, None).unwrap();
    let g = bone_speed_sensitivity(&scenario, &p).unwrap();
    let layer = |speed_factor: f64| {
        let mut c = HuConversion::named("aubry2003").unwrap();
        if let BoneModel::Porosity(q) = &mut c.bone {
            q.bone_sound_speed *= speed_factor;
        }
        let b = c.properties(SHELL_HU as f64, f).unwrap();
        (b.density, b.sound_speed, b.attenuation)
    };
    let (slow, fast) = (layer(1.0), layer(1.0 + BONE_SPEED_STEP));
    let r = |p: [f64; 3], c: [f64; 3]| ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
    let change: Vec<has_core::Complex64> = positions
        .iter()
        .zip(&p.skull_responses)
        .map(|(q, h)| {
            let steps = 20_000;
            let d = (0..steps)
                .filter(|&s| {
                    let t = (s as f64 + 0.5) / steps as f64;
                    let x = [q[0] + t * (target[0] - q[0]), q[1] + t * (target[1] - q[1]), q[2] + t * (target[2] - q[2])];
                    r(x, inner_c) >= 15e-3 && r(x, outer_c) <= 20e-3
                })
                .count() as f64
                * r(*q, target)
                / steps as f64;
            let t = layer_transmission(fast, d, f) / layer_transmission(slow, d, f);
            has_core::Complex64::from_polar(h.norm(), t.arg())
        })
        .collect();
    let common = change.iter().sum::<has_core::Complex64>().arg();
    let exact: Vec<f64> = change.iter().map(|c| has_core::phase::wrap(c.arg() - common) / (100.0 * BONE_SPEED_STEP)).collect();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let corr = dot(&g, &exact) / (rms(&g) * rms(&exact) * g.len() as f64);
    let slope = dot(&g, &exact) / dot(&exact, &exact);
    // The largest angle between an element's path and the outer face's normal where it enters.
    let incidence = positions
        .iter()
        .map(|q| {
            let u = [target[0] - q[0], target[1] - q[1], target[2] - q[2]].map(|v| v / r(target, *q));
            let (mut t, mut x) = (0.0, *q);
            while r(x, outer_c) > 20e-3 {
                t += 1e-5;
                x = [q[0] + t * u[0], q[1] + t * u[1], q[2] + t * u[2]];
            }
            let n = [x[0] - outer_c[0], x[1] - outer_c[1], x[2] - outer_c[2]].map(|v| v / 20e-3);
            (-(n[0] * u[0] + n[1] * u[1] + n[2] * u[2])).acos().to_degrees()
        })
        .fold(0.0, f64::max);
    println!(
        "bone speed sensitivity: RMS {:.4} rad/% (exact layers {:.4}), slope {slope:.3}, correlation {corr:.3}; incidence up to {incidence:.1}°",
        rms(&g),
        rms(&exact),
    );
    assert!(corr > 0.93 && (0.9..1.4).contains(&slope), "slope {slope}, correlation {corr}");
    let soft = bowl_scenario(&dir, "conversion = \"schneider-mast\"\n");
    assert!(bone_speed_sensitivity(&soft, &p).unwrap_err().to_string().starts_with("ct.conversion"));
    // `arfi predict --bone-speed-sensitivity --report` builds the plans in another order (the
    // faster bone's on the skull's grid and source model, the reference head's, then the skull's,
    // which it keeps) and projects every march at once: the same values to the last bit, and the kept simulation is the skull's (its own march of a drive equals a
    // fresh simulation's).
    let options = PredictionOptions { bone_speed_sensitivity: true, keep_simulation: true, ..PredictionOptions::default() };
    let run = predict_scenario_with(&scenario, None, options).unwrap();
    assert_eq!(run.prediction, p);
    assert_eq!(predict(sim.clone(), None).unwrap(), p);
    assert_eq!(run.bone_speed_sensitivity.as_deref(), Some(&g[..]));
    let kept = run.simulation.unwrap();
    let added: Vec<f64> = (0..kept.n_elements()).map(|e| p.reference_steering[e] - p.phases[e] - kept.steering[e]).collect();
    assert_eq!(kept.steering, sim.steering);
    assert_eq!(kept.field(&added, None).unwrap().pressure, sim.field(&added, None).unwrap().pressure);
    // Its build recorded the steered beam's section through the target (kept through the
    // shell's reverberation): the same as a fresh simulation's march of it.
    assert!(kept.propagation().reverberation.is_some_and(|z| z.2 > 0));
    let (a, b) =
        (kept.section(&[vec![], added.clone()], Some(target[1])).unwrap(), sim.section(&[vec![], added], Some(target[1])).unwrap());
    assert_eq!(a.pressure, b.pressure);
    let soft_run = predict_scenario_with(&soft, None, options).err().map(|e| e.to_string());
    assert!(soft_run.is_some_and(|e| e.starts_with("ct.conversion")));
    let keep = PredictionOptions { keep_simulation: true, ..PredictionOptions::default() };
    let outside = predict_scenario_with(&scenario, Some([0.0, 0.0, 1.0]), keep).err().map(|e| e.to_string());
    assert!(outside.as_deref().is_some_and(|e| e.starts_with("target") && e.contains("outside the grid")), "{outside:?}");
    std::fs::remove_dir_all(dir).ok();
}

/// The uneven shell of the pose tests (outer radius 20 mm about (4, 0, 46) mm, inner 15 mm about
/// (0, 0, 46) mm, 0.5 mm CT) written to `dir`: its simulation, the target (2, -1, 48) mm, each
/// element's response there and the pose modes.
fn uneven_shell_pose(dir: &std::path::Path) -> (Simulation, [f64; 3], Vec<has_core::Complex64>, has_core::prediction::PoseSensitivity) {
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, [4e-3, 0.0, 46e-3], 20e-3, [0.0, 0.0, 46e-3], 15e-3, f64::INFINITY, 0.5e-3))
        .unwrap();
    let sim = Simulation::new(&bowl_scenario(dir, "")).unwrap();
    let target = [2e-3, -1e-3, 48e-3];
    let h = sim.element_responses(target).unwrap();
    let modes = has_core::prediction::pose_sensitivity(&sim, target).unwrap();
    (sim, target, h, modes)
}

/// The RMS of a phase pattern (rad).
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// The correlation of two phase patterns about zero.
fn corr(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>() / (rms(a) * rms(b) * a.len() as f64)
}

#[test]
fn a_moved_head_is_the_array_moved_the_other_way() {
    // The uneven shell again, the head moved rigidly off its registration. Reference, not the
    // code's shortcut (the array and target moved the other way through the registered head's
    // own plan): each element's response through a new simulation whose CT is registered moved
    // (its own plan, the CT resampled onto the grid anew). Moves by whole cells (0.75 mm), alone
    // or with a turn, so that the CT's resampling onto the moved grid is the same staircase
    // shifted (a sub-cell move of the CT resamples to another staircase; measured: a 0.05 mm
    // move changes the phases by 0.005 rad RMS where the shortcut gives 0.04). Measured: the
    // phase changes agree to a correlation of 0.975-0.9997 and RMS within 2 %. Tolerance:
    // correlation at least 0.97, RMS ratio 0.9–1.1. The translation modes are central secants
    // over a cell either way: the same tolerance against half the moved CTs' difference between
    // a cell forward and a cell back.
    use has_core::prediction::pose::{moved_head_responses, Pose};
    let dir = scratch("pose");
    let (sim, target, h, modes) = uneven_shell_pose(&dir);
    let t_mm = target.map(|v| v * 1e3);
    // The CT's registration moved rigidly: x -> R·(x - target) + target + shift (mm).
    let through_moved_ct = |pose: &Pose| {
        let r = pose.rotation;
        let row = |i: usize| {
            let offset = t_mm[i] - (0..3).map(|j| r[i][j] * t_mm[j]).sum::<f64>() + pose.translation[i] * 1e3;
            format!("[{}, {}, {}, {}]", r[i][0], r[i][1], r[i][2], offset)
        };
        let tail = format!("patient_to_transducer_mm = [{}, {}, {}, [0, 0, 0, 1]]\n", row(0), row(1), row(2));
        Simulation::new(&bowl_scenario(&dir, &tail)).unwrap().element_responses(target).unwrap()
    };
    let change = |moved: &[has_core::Complex64]| -> Vec<f64> {
        let c: Vec<has_core::Complex64> = moved.iter().zip(&h).map(|(m, h)| m * h.conj()).collect();
        let common = c.iter().sum::<has_core::Complex64>().arg();
        c.iter().map(|c| has_core::phase::wrap(c.arg() - common)).collect()
    };
    let g = &sim.grid;
    let per_cell = |axis: usize, d: f64| Some(modes.translation[axis].iter().map(|v| v * d).collect::<Vec<_>>());
    let turned = Pose { translation: [g.dx, -g.dy, 0.0], rotation: Pose::turn(0, 0.9_f64.to_radians()).rotation };
    for (name, pose, mode) in [
        ("a cell along x", Pose::shift(0, g.dx), per_cell(0, g.dx)),
        ("a cell along y", Pose::shift(1, g.dy), per_cell(1, g.dy)),
        ("a cell along z", Pose::shift(2, g.dz), per_cell(2, g.dz)),
        ("two cells along x", Pose::shift(0, 2.0 * g.dx), None),
        ("a cell along x and -y, turned 0.9 deg about x", turned, None),
    ] {
        let moved_ct = through_moved_ct(&pose);
        let reference = change(&moved_ct);
        let shortcut = change(&moved_head_responses(&sim, target, &pose, None).unwrap());
        // The mode against the moved CTs' central difference: a cell forward against a cell back.
        let mode_reference = mode.as_ref().map(|_| {
            let back = change(&through_moved_ct(&Pose { translation: pose.translation.map(|t| -t), ..pose }));
            reference.iter().zip(&back).map(|(f, b)| 0.5 * (f - b)).collect::<Vec<f64>>()
        });
        for (what, v) in [("moved array", Some(shortcut)), ("mode", mode)] {
            let reference = if what == "mode" { mode_reference.as_ref().unwrap_or(&reference) } else { &reference };
            let Some(v) = v else { continue };
            let (c, ratio) = (corr(&v, reference), rms(&v) / rms(reference));
            println!(
                "{name}, {what}: phase change RMS {:.3} rad (moved CT {:.3}), ratio {ratio:.3}, correlation {c:.4}",
                rms(&v),
                rms(reference)
            );
            assert!(c > 0.97 && (0.9..1.1).contains(&ratio), "{name}, {what}: ratio {ratio}, correlation {c}");
        }
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn the_pose_modes_are_the_moved_arrays_secants() {
    // The fast modes (each moved target's field moved on the source plane as the array moves,
    // and the turns' rates from the kernel's gradient) against the slow, obvious reference: the
    // central secants of the responses projected onto arrays moved a cell either way (turned
    // half a cell at the elements), each laid out anew. The shifts are the same sums but for the
    // coarse pixels' sampling of the kernel; the turns differ by the secant's step and by the
    // turned elements' own quadrature layout. Measured on the uneven shell: shifts correlate at
    // 0.9998 or better, turns at 0.998 or better, RMS within 1.3 %. Tolerance: correlation 0.99,
    // RMS ratio within 5 %.
    use has_core::prediction::phase_change;
    use has_core::prediction::pose::{moved_head_responses, Pose};
    let dir = scratch("pose-fast");
    let (sim, target, h, modes) = uneven_shell_pose(&dir);
    let g = &sim.grid;
    let points = sim.transducer.reference_points();
    let reach = points.iter().map(|p| (0..3).map(|k| (p[k] - target[k]).powi(2)).sum::<f64>().sqrt()).sum::<f64>() / points.len() as f64;
    let turn = 0.5 * g.dx.min(g.dy).min(g.dz) / reach;
    for axis in 0..3 {
        let cell = [g.dx, g.dy, g.dz][axis];
        for (kind, pose, step, fast) in [
            ("shift", Pose::shift(axis, cell), cell, &modes.translation[axis]),
            ("turn", Pose::turn(axis, turn), turn, &modes.rotation[axis]),
        ] {
            let minus = if kind == "shift" { Pose::shift(axis, -step) } else { Pose::turn(axis, -step) };
            let up = phase_change(&moved_head_responses(&sim, target, &pose, None).unwrap(), &h).unwrap();
            let down = phase_change(&moved_head_responses(&sim, target, &minus, None).unwrap(), &h).unwrap();
            let slow: Vec<f64> = up.iter().zip(&down).map(|(u, d)| (u - d) / (2.0 * step)).collect();
            let (c, ratio) = (corr(fast, &slow), rms(fast) / rms(&slow));
            println!("{kind} along axis {axis}: correlation {c:.5}, RMS ratio {ratio:.4}");
            assert!(c > 0.99 && (0.95..1.05).contains(&ratio), "{kind} {axis}: correlation {c}, ratio {ratio}");
        }
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn turning_a_head_about_the_centre_of_its_spherical_shell_changes_no_phase() {
    // A shell concentric with the target (outer radius 20 mm, 4 mm thick): a turn about the
    // target leaves every path through it as it was, so the rotation modes vanish but for the
    // staircase of the sphere's cells along the turned paths, while a shift moves each path's
    // crossing. Reference: symmetry. Measured: 1° (0.35 mm at the shell) changes the phases by
    // 0.024 rad RMS, 1 mm by at least 0.128 (a turn moves each path across the staircase of
    // 0.75 mm cells, not across the bone). Tolerance: each rotation mode's phase change for 1°
    // at most a quarter of the smallest translation mode's for 1 mm (RMS).
    use has_core::prediction::pose_sensitivity;
    let dir = scratch("pose-concentric");
    let c = [0.0, 0.0, 48e-3];
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, c, 20e-3, c, 16e-3, f64::INFINITY, 0.5e-3)).unwrap();
    let sim = Simulation::new(&bowl_scenario(&dir, "")).unwrap();
    let modes = pose_sensitivity(&sim, c).unwrap();
    let shift = modes.translation.iter().map(|m| rms(m) * 1e-3).fold(f64::INFINITY, f64::min);
    let turn = modes.rotation.iter().map(|m| rms(m) * 1f64.to_radians()).fold(0.0, f64::max);
    println!("concentric shell: RMS phase change for 1 mm at least {shift:.4} rad, for 1 degree at most {turn:.4} rad");
    assert!(turn < 0.25 * shift, "turn {turn}, shift {shift}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn many_targets_share_their_plans_and_each_equals_its_own_prediction() {
    // One plan of each head for three targets (bone speed and pose modes too): each target's
    // values equal a prediction made for it alone, to the last bit; the marches are counted for
    // the progress; bad targets are refused by index before anything is built.
    use has_core::control::Control;
    use has_core::prediction::predict_targets_with;
    let dir = scratch("targets");
    std::fs::write(dir.join("shell.nii"), shell_ct(SHELL_HU, [4e-3, 0.0, 46e-3], 20e-3, [0.0, 0.0, 46e-3], 15e-3, f64::INFINITY, 0.5e-3))
        .unwrap();
    let scenario = bowl_scenario(&dir, "");
    let targets = [[2e-3, -1e-3, 48e-3], [0.0, 0.0, 50e-3], [-3e-3, 2e-3, 44e-3]];
    let options = PredictionOptions { bone_speed_sensitivity: true, pose_sensitivity: true, keep_simulation: true };
    let reports = std::sync::Mutex::new(Vec::new());
    let progress = |done: usize, total: usize| reports.lock().unwrap().push((done, total));
    let run = predict_targets_with(&scenario, &targets, options, Control::default().with_progress(&progress)).unwrap();
    assert_eq!(run.runs.len(), 3);
    for (target, got) in targets.iter().zip(&run.runs) {
        let alone = predict_scenario_with(&scenario, Some(*target), options).unwrap();
        assert_eq!(got.prediction, alone.prediction);
        assert_eq!(got.bone_speed_sensitivity, alone.bone_speed_sensitivity);
        assert_eq!(got.pose_sensitivity, alone.pose_sensitivity);
    }
    // Per target: the faster bone's march, the reference head's, the skull's and six moved ones.
    let reports = reports.into_inner().unwrap();
    assert_eq!(reports.len(), 27);
    assert_eq!(reports.last(), Some(&(27, 27)));
    assert!(run.simulation.is_some());
    let refused = |targets: &[[f64; 3]]| {
        predict_targets_with(&scenario, targets, PredictionOptions::default(), Control::default()).err().map(|e| e.to_string()).unwrap()
    };
    assert!(refused(&[]).starts_with("targets: none given"));
    let off_grid = refused(&[targets[0], [0.0, 0.0, 1e-3]]);
    assert!(off_grid.starts_with("targets: target 1 (0.0, 0.0, 1.0) mm lies outside the grid"), "{off_grid}");
    let off_ct = refused(&[[0.0, 0.0, 15e-3]]);
    assert!(off_ct.starts_with("targets: target 0 (0.0, 0.0, 15.0) mm lies outside the CT (its box spans"), "{off_ct}");
    assert!(refused(&[[f64::NAN, 0.0, 0.05]]).starts_with("targets"));
    // Cancelled: ends at the next march.
    let cancel = std::sync::atomic::AtomicBool::new(true);
    let cancelled = predict_targets_with(&scenario, &targets[..1], PredictionOptions::default(), Control::default().with_cancel(&cancel));
    assert!(matches!(cancelled, Err(has_core::HasError::Interrupted)));
    std::fs::remove_dir_all(dir).ok();
}
