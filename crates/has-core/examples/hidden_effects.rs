//! The model-discrepancy workflow on images in which effects are hidden at seeded random
//! strengths (the ranges of `tests/suite/diagnose.rs`), for measuring how often each is named:
//! `cargo run --release -p has-core --example hidden_effects -- SEEDS IMAGES EFFECT[+EFFECT] ...`
//! (e.g. `4 1 broadening slice_offset broadening+registration_shift`). Each case prints what
//! was named, the equally good explanations, the alternative path, the final gap (residual RMS
//! over the noise floor) and the time; the last line gives, per case, how often the hidden
//! effects were all named, and how often named or reported as equivalent. Environment:
//! `ARFI_PLANE` = `xz` or `yz` images a plane through the beam axis instead of the default
//! `xy` focal plane; `ARFI_FIRST_SEED` (default 1) continues a sweep.

use has_core::inverse::cost::Measurement;
use has_core::inverse::diagnose::{diagnose, effect_images, DiagnoseOptions, Effect, Effects};
use has_core::inverse::estimate::condense;
use has_core::physics::aberration::SkullScreen;
use has_core::physics::mr::add_noise;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Control;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::TAU;

fn strength(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    (if rng.random_bool(0.5) { 1.0 } else { -1.0 }) * rng.random_range(lo..hi)
}

/// Hides `effect` in `e` at a random strength.
fn hide(s: &Simulation, e: &mut Effects, effect: Effect, rng: &mut ChaCha8Rng, seed: u64) {
    let v = &mut e.view;
    match effect {
        Effect::Amplitude => v.scale = 1.0 + strength(rng, 0.08, 0.2),
        Effect::Broadening => {
            v.broadening_width_mm = if rng.random_bool(0.5) { rng.random_range(3.2..4.0) } else { rng.random_range(1.5..2.2) }
        }
        Effect::BroadeningAnisotropic => v.broadening_anisotropy_mm = strength(rng, 1.0, 2.0),
        Effect::RegistrationShift => {
            let (r, t) = (rng.random_range(0.7..1.5), rng.random_range(0.0..TAU));
            v.shift_mm = [r * t.cos(), r * t.sin()];
        }
        Effect::BackgroundPhase => {
            v.background_offset_rad = strength(rng, 0.02, 0.05);
            v.background_slope_rad_per_mm = [rng.random_range(-5e-4..5e-4), rng.random_range(-5e-4..5e-4)];
        }
        Effect::SliceOffset => v.slice_offset_mm = strength(rng, 4.5, 7.0),
        Effect::Attenuation => e.field.attenuation_db_cm_mhz *= 1.0 + strength(rng, 0.2, 0.5),
        Effect::SoundSpeed => e.field.sound_speed += strength(rng, 80.0, 120.0),
        Effect::ElementDropout => e.field.dead_groups = vec![rng.random_range(0..s.n_groups)],
        Effect::PhaseAberration => {
            let positions = s.transducer.reference_points();
            e.field.group_phases = condense(&SkullScreen::default().phases(&positions, seed).expect("screen"), &s.groups).expect("groups");
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let seeds: u64 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(2);
    let images: u64 = args.next().map(|a| a.parse()).transpose()?.unwrap_or(1).max(1);
    let cases: Vec<String> = args.collect();
    let mut scenario = Scenario::default();
    if let Ok(plane) = std::env::var("ARFI_PLANE") {
        scenario.mr.plane = plane;
    }
    let s = Simulation::new(&scenario)?;
    let mut summary = Vec::new();
    for case in &cases {
        let hidden: Vec<Effect> =
            case.split('+').map(|n| Effect::from_name(n).ok_or_else(|| format!("unknown effect {n}"))).collect::<Result<_, _>>()?;
        let (mut named, mut identified) = (0, 0);
        let first: u64 = std::env::var("ARFI_FIRST_SEED").ok().map(|s| s.parse()).transpose()?.unwrap_or(1);
        for seed in first..first + seeds {
            let mut rng = ChaCha8Rng::seed_from_u64(seed * 7919 + case.len() as u64);
            let mut e = Effects::none(&s);
            for &h in &hidden {
                hide(&s, &mut e, h, &mut rng, seed);
            }
            let diversity = SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 1.5 };
            let knowns: Vec<Vec<f64>> = (0..images)
                .map(|k| if k == 0 { Ok(vec![]) } else { diversity.phases(&vec![[0.0; 3]; 16], 7919 * seed + k) })
                .collect::<Result<_, _>>()?;
            let mut meas = Vec::new();
            for (k, (mut image, known)) in effect_images(&s, &knowns, &e)?.into_iter().zip(knowns).enumerate() {
                add_noise(&mut image, 0.02, 1000 * seed + k as u64)?;
                meas.push(Measurement { image, known });
            }
            let t = std::time::Instant::now();
            let d = diagnose(&s, &meas, &DiagnoseOptions::default(), &Control::default())?;
            let names: Vec<&str> = d.steps.iter().map(|st| st.effect.name()).collect();
            let all_named = hidden.iter().all(|h| d.steps.iter().any(|st| st.effect == *h));
            let all_identified = hidden.iter().all(|h| d.steps.iter().any(|st| st.effect == *h || st.equivalent.contains(h)));
            named += all_named as usize;
            identified += all_identified as usize;
            let equivalent: Vec<Vec<&str>> = d.steps.iter().map(|st| st.equivalent.iter().map(|x| x.name()).collect()).collect();
            let alternative = d.alternative.as_ref().map(|a| (a.effects.iter().map(|x| x.name()).collect::<Vec<_>>(), a.total_evidence));
            println!(
                "{case} seed {seed}: named {names:?} (equivalent {equivalent:?}), total evidence {:.0}, alternative {alternative:?}, gap {:.2}, {:.1} s",
                d.total_evidence,
                d.residual_rms().1 / d.noise_floor,
                t.elapsed().as_secs_f64()
            );
        }
        summary.push(format!("{case}: named {named}/{seeds}, named or equivalent {identified}/{seeds}"));
    }
    println!("{}", summary.join("; "));
    Ok(())
}
