//! The model-discrepancy workflow on data in which effects are hidden: the images are
//! simulated with the effect (at a seeded random but realistic strength), the model lacks it,
//! and the workflow must name it, measure it and close the gap to the noise. The shift and the
//! slice offset are simulated independently of the workflow's forward model (a simulation with
//! the MR slice moved); the other effects through `effect_images`.

use has_core::inverse::cost::Measurement;
use has_core::inverse::diagnose::{diagnose, effect_images, DiagnoseOptions, Diagnosis, Effect, Effects, Value};
use has_core::inverse::estimate::{condense, phase_error};
use has_core::physics::aberration::SkullScreen;
use has_core::physics::mr::add_noise;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Control;
use ndarray::Array2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::OnceLock;

const NOISE: f64 = 0.02;

fn sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

fn run(model: &Simulation, image: &Array2<f64>) -> Diagnosis {
    run_all(model, &[Measurement { image: image.clone(), known: vec![] }], &DiagnoseOptions::default())
}

fn run_all(model: &Simulation, measurements: &[Measurement], options: &DiagnoseOptions) -> Diagnosis {
    let t = std::time::Instant::now();
    let d = diagnose(model, measurements, options, &Control::default()).expect("diagnose");
    let params: Vec<_> = d
        .steps
        .iter()
        .map(|s| (s.effect.name(), s.evidence.round(), &s.params, s.equivalent.iter().map(|e| e.name()).collect::<Vec<_>>()))
        .collect();
    eprintln!("diagnose: {params:?}, alternative {:?}, gap {:.2}, in {:.1} s", d.alternative, gap(&d), t.elapsed().as_secs_f64());
    d
}

/// Images with `effects` hidden: the first with no known phases, the others with seeded random
/// known group phases (diversity), each with 0.02 rad noise.
fn hidden(effects: &Effects, images: usize, seed: u64) -> Vec<Measurement> {
    hidden_in(sim(), effects, images, seed)
}

fn hidden_in(s: &Simulation, effects: &Effects, images: usize, seed: u64) -> Vec<Measurement> {
    let knowns: Vec<Vec<f64>> = (0..images as u64)
        .map(|k| {
            if k == 0 {
                vec![]
            } else {
                SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 1.5 }
                    .phases(&vec![[0.0; 3]; 16], 7919 * seed + k)
                    .unwrap()
            }
        })
        .collect();
    let images = effect_images(s, &knowns, effects).unwrap();
    images
        .into_iter()
        .zip(knowns)
        .enumerate()
        .map(|(k, (mut image, known))| {
            add_noise(&mut image, NOISE, 1000 * seed + k as u64).unwrap();
            Measurement { image, known }
        })
        .collect()
}

/// Whether `effect` was named, or reported as explaining a named step equally well.
fn identified(d: &Diagnosis, effect: Effect) -> bool {
    d.steps.iter().any(|s| s.effect == effect || s.equivalent.contains(&effect))
}

/// A seeded random strength in `lo..hi` with a random sign.
fn strength(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    sign * rng.random_range(lo..hi)
}

fn names(d: &Diagnosis) -> Vec<&'static str> {
    d.steps.iter().map(|s| s.effect.name()).collect()
}

fn param(d: &Diagnosis, name: &str) -> f64 {
    d.steps
        .iter()
        .flat_map(|s| s.params.iter())
        .find_map(|p| match p {
            (n, Value::Number(v)) if *n == name => Some(*v),
            _ => None,
        })
        .unwrap_or(f64::NAN)
}

/// Whether `ARFI_FULL_SWEEPS` is set: the full mode runs every seed and case of a sweep
/// (docs/testing.md), the default run one of each.
fn full() -> bool {
    std::env::var_os("ARFI_FULL_SWEEPS").is_some()
}

/// Seeds per case: `ci` in the default run, `full` with `ARFI_FULL_SWEEPS=1` set (each seed is
/// one or more diagnoses, each fitting every effect of the library, some by re-marching the
/// field); the hit rates per effect come from the full runs and from examples/hidden_effects.rs
/// (10 seeds; per-effect rates: BENCHMARKS.md, section "Diagnose: hidden effects").
fn seeds(ci: u64, full: u64) -> std::ops::RangeInclusive<u64> {
    1..=if self::full() { full } else { ci }
}

/// The gap at the end: residual RMS over the noise floor (required ≤ 1.2).
fn gap(d: &Diagnosis) -> f64 {
    d.residual_rms().1 / d.noise_floor
}

#[test]
fn the_papers_story_a_model_without_broadening_meets_w_2_7_mm() {
    // Data: the scenario's W = 2.7 mm; model: no broadening, same amplitude (paper Fig. 2).
    let s = sim();
    let image = s.noisy_arfi_image(&[], NOISE, 1).unwrap();
    let model = s.with_calibration(0.0, s.amplitude().unwrap()).unwrap();
    let d = run(&model, &image);
    assert_eq!(names(&d), ["broadening"], "{:?}", d.steps);
    // Within 0.2 mm, the workflow's required accuracy for W: the fit of W on a 0.02 rad image is
    // good to about 0.05 mm, so 0.2 mm leaves a margin of four.
    assert!((param(&d, "broadening_width_mm") - 2.7).abs() < 0.2, "W = {}", param(&d, "broadening_width_mm"));
    assert!(gap(&d) < 1.2, "gap {}", gap(&d));
    assert!(d.cost_final < d.cost_initial);
}

#[test]
fn a_hidden_registration_shift_is_named_and_measured() {
    let s = sim();
    let shifted = Simulation::new(&Scenario::from_toml("[mr]\ncenter_mm = [1.1, -0.7, 85.0]\n", None).unwrap()).unwrap();
    // The scenario sets the amplitude so that its ideal image peaks at 0.6 rad, which depends on
    // where the pixels fall; keep the model's amplitude so that only the shift is hidden.
    let shifted = shifted.with_calibration(s.sampler().unwrap().broadening.width, s.amplitude().unwrap()).unwrap();
    // The slice centred at (1.1, -0.7) mm images the focus at (-1.1, +0.7) mm of its own frame.
    let image = shifted.noisy_arfi_image(&[], NOISE, 2).unwrap();
    let d = run(s, &image);
    assert_eq!(names(&d), ["registration_shift"], "{:?}", d.steps);
    // Within 0.3 mm, the workflow's required accuracy for a registration shift.
    assert!((param(&d, "dx_mm") + 1.1).abs() < 0.3 && (param(&d, "dy_mm") - 0.7).abs() < 0.3, "{:?}", d.steps[0].params);
    assert!(gap(&d) < 1.2, "gap {}", gap(&d));
}

#[test]
fn noise_only_names_nothing() {
    // The workflow's acceptance: on noise-only data no effect is named in at least 95 % of 20
    // seeds (the full run, a rate); the default run takes the first seed and allows none (0.05 of
    // one seed), so a workflow that names an effect on this noise fails it.
    let s = sim();
    let n = seeds(1, 20).count() as u64;
    let named: Vec<(u64, Vec<&str>)> = (100..100 + n)
        .map(|seed| (seed, names(&run(s, &s.noisy_arfi_image(&[], NOISE, seed).unwrap()))))
        .filter(|r| !r.1.is_empty())
        .collect();
    assert!(named.len() as f64 <= 0.05 * n as f64, "effects named on noise only: {named:?}");
}

#[test]
fn a_hidden_slice_offset_is_named_and_measured() {
    // The image is taken 4 mm deeper than the model's slice (amplitude pinned, as for the shift).
    let s = sim();
    let deeper = Simulation::new(&Scenario::from_toml("[mr]\ncenter_mm = [0.0, 0.0, 89.0]\n", None).unwrap()).unwrap();
    let deeper = deeper.with_calibration(s.sampler().unwrap().broadening.width, s.amplitude().unwrap()).unwrap();
    let d = run(s, &deeper.noisy_arfi_image(&[], NOISE, 6).unwrap());
    assert_eq!(names(&d), ["slice_offset"], "{:?}", d.steps);
    // Tolerance 1 mm: the focal depth of field is about 20 mm, so the image changes slowly with
    // depth and a 0.02 rad image places the slice only to about half a millimetre.
    assert!((param(&d, "dz_mm") - 4.0).abs() < 1.0, "dz = {}", param(&d, "dz_mm"));
    assert!(gap(&d) < 1.2, "gap {}", gap(&d));
}

#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn hidden_amplitude_broadening_and_anisotropy_over_seeds() {
    let s = sim();
    for seed in seeds(1, 2) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // Amplitude: ±8–20 % (a miscalibrated force-to-phase scale); within 2 %.
        let mut e = Effects::none(s);
        e.view.scale = 1.0 + strength(&mut rng, 0.08, 0.2);
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert_eq!(names(&d), ["amplitude"], "seed {seed}");
        assert!((param(&d, "scale") / e.view.scale - 1.0).abs() < 0.02 && gap(&d) < 1.2);
        // Broadening: W from 2.7 to 1.5–2.2 or 3.2–4.0 mm; within 0.2 mm (the required accuracy, as above).
        let mut e = Effects::none(s);
        e.view.broadening_width_mm = if rng.random_bool(0.5) { rng.random_range(3.2..4.0) } else { rng.random_range(1.5..2.2) };
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert_eq!(names(&d), ["broadening"], "seed {seed}");
        assert!((param(&d, "broadening_width_mm") - e.view.broadening_width_mm).abs() < 0.2 && gap(&d) < 1.2);
        // Anisotropic broadening: widths differing by 1–2 mm about 2.7 mm; each within 0.2 mm.
        let mut e = Effects::none(s);
        e.view.broadening_anisotropy_mm = strength(&mut rng, 1.0, 2.0);
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert_eq!(names(&d), ["broadening_anisotropic"], "seed {seed}");
        let w = e.view.widths_mm();
        assert!((param(&d, "broadening_width_u_mm") - w[0]).abs() < 0.2 && (param(&d, "broadening_width_v_mm") - w[1]).abs() < 0.2);
        assert!(gap(&d) < 1.2);
    }
}

#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn hidden_background_slice_offset_and_dropout_over_seeds() {
    let s = sim();
    for seed in seeds(1, 2) {
        let mut rng = ChaCha8Rng::seed_from_u64(10 + seed);
        // Background phase: 0.02–0.05 rad offset, ramps up to 5e-4 rad/mm (0.05 rad over the FOV).
        let mut e = Effects::none(s);
        e.view.background_offset_rad = strength(&mut rng, 0.02, 0.05);
        e.view.background_slope_rad_per_mm = [rng.random_range(-5e-4..5e-4), rng.random_range(-5e-4..5e-4)];
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert_eq!(names(&d), ["background_phase"], "seed {seed}");
        assert!((param(&d, "offset_rad") - e.view.background_offset_rad).abs() < 0.005 && gap(&d) < 1.2);
        // Slice offset: 4.5–7 mm either way; within 1 mm (the focal depth of field is ~20 mm: at
        // 3 mm a defocus is as well explained by a 0.2 mm wider broadening).
        let mut e = Effects::none(s);
        e.view.slice_offset_mm = strength(&mut rng, 4.5, 7.0);
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert_eq!(names(&d), ["slice_offset"], "seed {seed}");
        assert!((param(&d, "dz_mm") - e.view.slice_offset_mm).abs() < 1.0 && gap(&d) < 1.2);
        // One dead group of 16: named with the right group, or (a group whose loss mostly lowers
        // the focus) reported as explaining the named amplitude change equally well.
        let mut e = Effects::none(s);
        e.field.dead_groups = vec![rng.random_range(0..16)];
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert!(d.steps.len() == 1 && identified(&d, Effect::ElementDropout), "seed {seed}: {:?}", names(&d));
        if d.steps[0].effect == Effect::ElementDropout {
            assert_eq!(d.steps[0].params[0].1, Value::Indices(e.field.dead_groups.clone()));
        }
        assert!(gap(&d) < 1.2);
    }
}

#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn an_image_through_the_beam_axis_names_attenuation_sound_speed_and_dropout() {
    // In an xz image the focal material's attenuation tilts the force along the beam
    // (exp(-2·alpha·z)), its sound speed moves the focus along z, and a dead group reshapes the
    // side lobes: none of them acts as a scale or a defocus any more, so each is named alone
    // (the sweep of examples/hidden_effects.rs: every library effect 10/10 on such images).
    // The default run names the sound speed, the effect only this view pins down; the full mode
    // adds attenuation and dropout (each also named in focal-plane images by the tests above).
    let mut scenario = Scenario::default();
    scenario.mr.plane = "xz".into();
    let s = Simulation::new(&scenario).expect("xz scenario");
    let none = Effects::none(&s);
    let mut rng = ChaCha8Rng::seed_from_u64(40);
    let mut e = none.clone();
    e.field.attenuation_db_cm_mhz *= 1.0 + strength(&mut rng, 0.2, 0.5);
    if full() {
        let d = run_all(&s, &hidden_in(&s, &e, 1, 1), &DiagnoseOptions::default());
        assert_eq!(names(&d), ["attenuation"]);
        assert!((param(&d, "attenuation_db_cm_mhz") - e.field.attenuation_db_cm_mhz).abs() < 0.03 && gap(&d) < 1.2);
    }
    let mut e = none.clone();
    e.field.sound_speed += strength(&mut rng, 80.0, 120.0);
    let d = run_all(&s, &hidden_in(&s, &e, 1, 2), &DiagnoseOptions::default());
    // Named first. Sound speed and an axial registration shift both move the pattern along the
    // beam, so the workflow may add a sub-millimetre axial shift second and the speed then
    // shares the focal move with it: within 25 m/s (a 0.7 mm axial shift beside it takes up about
    // 20 m/s of the speed; the gap closes either way).
    assert_eq!(d.steps[0].effect, Effect::SoundSpeed, "{:?}", names(&d));
    let c = param(&d, "sound_speed_m_s");
    assert!((c - e.field.sound_speed).abs() < 25.0 && gap(&d) < 1.2, "{c} m/s against {}", e.field.sound_speed);
    if !full() {
        return;
    }
    let mut e = none;
    e.field.dead_groups = vec![rng.random_range(0..16)];
    let d = run_all(&s, &hidden_in(&s, &e, 1, 3), &DiagnoseOptions::default());
    assert_eq!(names(&d), ["element_dropout"]);
    // The group, or its mirror image across the xz plane (the same image: y -> -y symmetry).
    let Value::Indices(named) = &d.steps[0].params[0].1 else { panic!("dead_groups is a list of indices") };
    let mut m = e.clone();
    m.field.dead_groups = named.clone();
    let (a, b) = (effect_images(&s, &[vec![]], &e).unwrap(), effect_images(&s, &[vec![]], &m).unwrap());
    let differ = (&a[0] - &b[0]).iter().fold(0.0f64, |x, v| x.max(v.abs()));
    assert!(differ < 1e-3 * NOISE, "group {named:?} for {:?}: images differ by {differ} rad", e.field.dead_groups);
    assert!(gap(&d) < 1.2);
}

#[test]
fn hidden_attenuation_and_sound_speed_are_identified_up_to_what_the_image_can_tell() {
    // In one focal-plane image a change of the focal material's attenuation (force ∝ alpha·I)
    // or sound speed (force ∝ 1/c², the focus hardly moves at these strengths) acts almost as
    // a scale: the workflow must name it or report it as explaining the named step equally
    // well. With the amplitude known (calibrated: `amplitude` not in the library) attenuation
    // is named and measured.
    let s = sim();
    let a0 = Effects::none(s).field.attenuation_db_cm_mhz;
    let c0 = Effects::none(s).field.sound_speed;
    for seed in seeds(1, 2) {
        let mut rng = ChaCha8Rng::seed_from_u64(20 + seed);
        let mut e = Effects::none(s);
        e.field.attenuation_db_cm_mhz = a0 * (1.0 + strength(&mut rng, 0.2, 0.5));
        let data = hidden(&e, 1, seed);
        let d = run_all(s, &data, &DiagnoseOptions::default());
        assert!(d.steps.len() == 1 && identified(&d, Effect::Attenuation), "seed {seed}: {:?}", names(&d));
        let mut calibrated = DiagnoseOptions::default();
        calibrated.effects.retain(|e| *e != Effect::Amplitude);
        let d = run_all(s, &data, &calibrated);
        assert_eq!(names(&d), ["attenuation"], "seed {seed}");
        // Within 0.03 dB/cm/MHz: with the amplitude known, one 0.02 rad image determines the
        // attenuation to about 0.005 dB/cm/MHz, so the bound leaves a margin of six.
        assert!((param(&d, "attenuation_db_cm_mhz") - e.field.attenuation_db_cm_mhz).abs() < 0.03 && gap(&d) < 1.2);

        let mut e = Effects::none(s);
        e.field.sound_speed = c0 + strength(&mut rng, 80.0, 120.0);
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        assert!(d.steps.len() == 1 && identified(&d, Effect::SoundSpeed), "seed {seed}: {:?}", names(&d));
        assert!(gap(&d) < 1.2);
    }
}

#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn a_hidden_phase_aberration_is_named_from_diversity_images() {
    // One in-focus image of a 16-group aberration is explained as well by a shift, a slice
    // offset or an anisotropic blur (low-order aberrations are exactly those): the workflow
    // then reports the aberration as the alternative. Three images with known diversity phases
    // tell them apart, and the aberration is named and measured.
    let s = sim();
    let positions = s.transducer.reference_points();
    let seed = 1;
    let mut e = Effects::none(s);
    e.field.group_phases = condense(&SkullScreen::default().phases(&positions, seed).unwrap(), &s.groups).unwrap();
    let one = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
    let alternative = one.alternative.as_ref().map(|a| a.effects.clone()).unwrap_or_default();
    assert!(identified(&one, Effect::PhaseAberration) || alternative.contains(&Effect::PhaseAberration), "{:?}", names(&one));
    assert!(gap(&one) < 1.2);
    let d = run_all(s, &hidden(&e, 3, seed), &DiagnoseOptions::default());
    assert_eq!(names(&d), ["phase_aberration"]);
    assert!(gap(&d) < 1.2);
    let Value::Numbers(fitted) = &d.steps[0].params[0].1 else { panic!("group phases") };
    let corrected: Vec<f64> = e.field.group_phases.iter().zip(fitted).map(|(t, f)| t - f).collect();
    let peak = |p: &[f64]| s.arfi_image(p).unwrap().iter().copied().fold(f64::MIN, f64::max);
    let recovered = peak(&corrected) / peak(&[]);
    eprintln!(
        "phase aberration from 3 images: phase error {:.3} rad, recovered {recovered:.3}",
        phase_error(fitted, &e.field.group_phases)
    );
    // Subtracting the fitted phases refocuses as the estimators are required to from 4 such images
    // (at least 0.9 of the ideal focus on average).
    assert!(recovered > 0.9, "recovered {recovered}");
}

/// Both effects of a hidden pair are named (and a hidden shift measured within 0.3 mm). The
/// default run takes the first pair, a view effect with a shift (two effects named in turn, the
/// second one measured after the first); the full mode adds a field effect with a shift and two
/// view effects without. Each pair draws its strengths in turn from one generator, so the first
/// pair is the same in both modes.
#[test]
fn pairs_of_hidden_effects_are_both_named() {
    let s = sim();
    let mut rng = ChaCha8Rng::seed_from_u64(30);
    let pairs: [(Effect, Effect); 3] = [
        (Effect::Broadening, Effect::RegistrationShift),
        (Effect::ElementDropout, Effect::RegistrationShift),
        (Effect::Amplitude, Effect::BackgroundPhase),
    ];
    for (seed, (a, b)) in (1..).zip(pairs).take(if full() { 3 } else { 1 }) {
        let mut e = Effects::none(s);
        for effect in [a, b] {
            match effect {
                Effect::Broadening => e.view.broadening_width_mm = rng.random_range(3.2..4.0),
                Effect::RegistrationShift => {
                    let (r, t) = (rng.random_range(0.7..1.5), rng.random_range(0.0..std::f64::consts::TAU));
                    e.view.shift_mm = [r * f64::cos(t), r * f64::sin(t)];
                }
                Effect::ElementDropout => e.field.dead_groups = vec![rng.random_range(0..16)],
                Effect::Amplitude => e.view.scale = 1.0 + strength(&mut rng, 0.08, 0.2),
                _ => {
                    e.view.background_offset_rad = strength(&mut rng, 0.02, 0.05);
                    e.view.background_slope_rad_per_mm = [3e-4, -2e-4];
                }
            }
        }
        let d = run_all(s, &hidden(&e, 1, seed), &DiagnoseOptions::default());
        let mut got = names(&d);
        got.sort_unstable();
        let mut want = vec![a.name(), b.name()];
        want.sort_unstable();
        assert_eq!(got, want, "pair {seed}");
        assert!(gap(&d) < 1.2);
        if e.view.shift_mm != [0.0; 2] {
            assert!((param(&d, "dx_mm") - e.view.shift_mm[0]).abs() < 0.3 && (param(&d, "dy_mm") - e.view.shift_mm[1]).abs() < 0.3);
        }
    }
}

/// The round trip for every effect of the library: a diagnosis allowed only that effect, on
/// images with it hidden, reports its parameters by name; those names and values, set on the
/// model with `Effects::set` (what Python's `effect_images(params)` does), give back the
/// diagnosis's own model images. Images come from the same forward model both ways, so only
/// the reported form of the values (widths u/v for the anisotropy, phases with their mean
/// removed) separates them: 1e-9 rad.
#[test]
fn every_effect_round_trips_from_diagnose_to_effect_images() {
    use Value::{Indices, Number, Numbers};
    let s = sim();
    let phases: Vec<f64> = (0..16).map(|g| 1.2 * (0.7 * g as f64).sin()).collect();
    let cases: Vec<(Effect, Vec<(&str, Value)>)> = vec![
        (Effect::Amplitude, vec![("scale", Number(1.25))]),
        (Effect::Broadening, vec![("broadening_width_mm", Number(3.6))]),
        (Effect::RegistrationShift, vec![("dx_mm", Number(1.1)), ("dy_mm", Number(-0.8))]),
        (Effect::BackgroundPhase, vec![("offset_rad", Number(0.06)), ("slope_x_rad_per_mm", Number(8e-4))]),
        (Effect::SliceOffset, vec![("dz_mm", Number(6.0))]),
        (Effect::BroadeningAnisotropic, vec![("broadening_width_u_mm", Number(2.0)), ("broadening_width_v_mm", Number(3.6))]),
        (Effect::Attenuation, vec![("attenuation_db_cm_mhz", Number(0.75))]),
        (Effect::SoundSpeed, vec![("sound_speed_m_s", Number(1600.0))]),
        (Effect::ElementDropout, vec![("dead_groups", Indices(vec![5]))]),
        (Effect::PhaseAberration, vec![("group_phases_rad", Numbers(phases))]),
    ];
    assert_eq!(cases.len(), Effect::ALL.len());
    for (k, (effect, truth)) in cases.into_iter().enumerate() {
        let mut hidden_effects = Effects::none(s);
        for (name, value) in &truth {
            hidden_effects.set(name, value).unwrap();
        }
        let images = if effect == Effect::PhaseAberration { 2 } else { 1 };
        let measurements = hidden(&hidden_effects, images, 40 + k as u64);
        let options = DiagnoseOptions { effects: vec![effect], ..DiagnoseOptions::default() };
        let d = run_all(s, &measurements, &options);
        let step = d.steps.first().unwrap_or_else(|| panic!("{} was not added", effect.name()));
        assert_eq!(step.effect, effect);
        let mut back = Effects::none(s);
        for (name, value) in &step.params {
            back.set(name, value).unwrap_or_else(|e| panic!("{}: reported {name} is not accepted: {e}", effect.name()));
        }
        let knowns: Vec<Vec<f64>> = measurements.iter().map(|m| m.known.clone()).collect();
        let again = effect_images(s, &knowns, &back).unwrap();
        let worst = again.iter().zip(&step.models).map(|(a, b)| (a - b).iter().fold(0.0, |m: f64, v| m.max(v.abs()))).fold(0.0, f64::max);
        eprintln!("round trip {}: params {:?}, worst image difference {worst:.1e} rad", effect.name(), step.params);
        assert!(worst < 1e-9, "{}: effect_images of the reported params differs by {worst:.2e} rad", effect.name());
    }
}
