//! Property tests of the entry points that take external data (scenario text, measured images,
//! phase vectors, effect parameters): any input gives a value or an `Err`, never a panic.
//! Fixed seeds, so a run is repeatable; the case counts keep the file under a minute.

use has_core::inverse::calibrate::calibrate;
use has_core::inverse::cost::{build_model, Measurement};
use has_core::inverse::diagnose::{diagnose, effect_images, DiagnoseOptions, Effect, Effects};
use has_core::inverse::estimate::Estimator;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Control;
use ndarray::Array2;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use std::sync::OnceLock;

fn config(cases: u32) -> Config {
    Config { cases, rng_seed: RngSeed::Fixed(20261123), failure_persistence: None, ..Config::default() }
}

fn sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

/// Numbers that break naive code.
fn nasty() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-1.0),
        Just(1e-300),
        Just(1e300),
        Just(-1e300),
        Just(f64::MAX),
        -10.0..10.0f64,
    ]
}

const NASTY_TOML: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e-300",
    "1e300",
    "-1e300",
    "9223372036854775807",
    "\"x\"",
    "[]",
    "[1e300, 1e300]",
    "[0, 0, 0]",
    "[nan, 0, 0]",
    "true",
    "{}",
    "1",
    "3",
];

/// The default scenario's TOML with one to three values replaced, lines dropped or cut.
fn mutated_scenario() -> impl Strategy<Value = String> {
    let lines: Vec<String> = Scenario::default().to_toml().expect("toml").lines().map(str::to_string).collect();
    let n = lines.len();
    proptest::collection::vec((0..n, 0..3usize, 0..NASTY_TOML.len(), 0..80usize), 1..4).prop_map(move |edits| {
        let mut l = lines.clone();
        for (i, how, v, cut) in edits {
            let key = l[i].split('=').next().unwrap_or("").to_string();
            l[i] = match how {
                0 if l[i].contains('=') => format!("{key}= {}", NASTY_TOML[v]),
                1 => String::new(),
                _ => l[i].chars().take(cut).collect(),
            };
        }
        l.join("\n")
    })
}

proptest! {
    #![proptest_config(config(96))]

    #[test]
    fn any_scenario_text_gives_a_simulation_or_an_error(text in prop_oneof![mutated_scenario(), ".{0,120}"]) {
        if let Ok(s) = Scenario::from_toml(&text, None) {
            let _ = Simulation::new(&s);
        }
        let _ = Scenario::from_json(&text, None);
    }
}

/// A default-shaped image (the ideal one, or zeros) with one pixel set to `v`, or any shape.
fn image() -> impl Strategy<Value = Array2<f64>> {
    let ideal = sim().arfi_image(&[]).expect("ideal");
    let (nu, nv) = ideal.dim();
    prop_oneof![
        (nasty(), 0..nu * nv, any::<bool>()).prop_map(move |(v, k, zeros)| {
            let mut a = if zeros { Array2::zeros((nu, nv)) } else { ideal.clone() };
            a[(k / nv, k % nv)] = v;
            a
        }),
        (0..6usize, 0..6usize, nasty()).prop_map(|(a, b, v)| Array2::from_elem((a, b), v)),
    ]
}

fn phases() -> impl Strategy<Value = Vec<f64>> {
    prop_oneof![Just(vec![]), proptest::collection::vec(nasty(), 0..20), proptest::collection::vec(-3.0..3.0f64, 16..=16)]
}

proptest! {
    #![proptest_config(config(64))]

    #[test]
    fn any_image_and_phases_give_a_result_or_an_error(image in image(), known in phases(), width in nasty()) {
        let s = sim();
        let _ = s.arfi_image(&known);
        let _ = s.element_phases(&known);
        let _ = calibrate(s, &image, &known, 0.5, width);
        let m = [Measurement { image: image.clone(), known: known.clone() }];
        if let Ok(model) = build_model(s, &m, 0.5, 3) {
            let e = Estimator::lbfgs().with_max_evaluations(20).expect("budget").run(&model.cost, Control::default());
            prop_assert!(e.is_ok_and(|e| e.cost.is_finite() && e.phases.iter().all(|p| p.is_finite())));
        }
        let options = DiagnoseOptions { effects: vec![Effect::Amplitude, Effect::RegistrationShift], max_iterations: 5, ..Default::default() };
        if let Ok(d) = diagnose(s, &m, &options, &Control::default()) {
            prop_assert!(d.cost_final.is_finite() && d.cost_final <= d.cost_initial);
        }
    }
}

proptest! {
    // Each case with a finite sound speed or attenuation rebuilds the HAS plan (about half a
    // second): 24 cases by default, 64 in the full mode.
    #![proptest_config(config(if std::env::var_os("ARFI_FULL_SWEEPS").is_some() { 64 } else { 24 }))]

    #[test]
    fn any_effect_parameters_give_images_or_an_error(view in proptest::collection::vec(nasty(), 9), speed in nasty(),
                                                    attenuation in nasty(), dead in proptest::collection::vec(0..40usize, 0..3)) {
        let s = sim();
        let mut e = Effects::none(s);
        let v = &mut e.view;
        (v.scale, v.broadening_width_mm, v.broadening_anisotropy_mm) = (view[0], view[1], view[2]);
        (v.shift_mm, v.background_offset_rad) = ([view[3], view[4]], view[5]);
        (v.background_slope_rad_per_mm, v.slice_offset_mm) = ([view[6], view[7]], view[8]);
        e.field.sound_speed += speed;
        e.field.attenuation_db_cm_mhz += attenuation;
        e.field.dead_groups = dead;
        if let Ok(images) = effect_images(s, &[vec![]], &e) {
            // Finite parameters give finite images; non-finite ones may propagate.
            let finite = view.iter().chain([&speed, &attenuation]).all(|x| x.is_finite() && x.abs() < 1e6);
            prop_assert!(!finite || images.iter().all(|im| im.iter().all(|x| x.is_finite())));
        }
    }
}
