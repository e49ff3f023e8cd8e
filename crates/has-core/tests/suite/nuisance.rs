//! Per-element estimation on images the model did not make: the images come from a
//! simulation of the default phantom on a finer grid (λ/6 instead of the model's λ/4: its own
//! discretisation of the same physics) with nuisance hidden at seeded random, realistic
//! strengths: an amplitude scale of 0.85–1.15, a broadening width of 2.9–3.5 mm (the model's is
//! 2.7 mm), and per image a background phase offset of ±0.01–0.04 rad with ramps up to
//! 3·10⁻⁴ rad/mm. Each case is the clinical one: 1024 skull-like element aberrations, four images
//! at 0.02 rad (the aberrated one and three defocused by +5, -5 and +10 mm), and a CT-like
//! prediction (smooth 5 rad peak-to-peak error over 15 mm plus 0.3 rad jitter) as a smooth prior.
//!
//! Per-seed values (`ARFI_FULL_SWEEPS=1`, seeds 1–5): BENCHMARKS.md, section "Nuisance fitted
//! with the phases".

use has_core::control::Control;
use has_core::inverse::cost::Measurement;
use has_core::inverse::diagnose::{effect_images, Effects};
use has_core::inverse::element::nuisance::Nuisance;
use has_core::inverse::element::BasisCache;
use has_core::inverse::estimate::workflow::{estimate_aberration_with, EstimateReport, EstimateRequest};
use has_core::inverse::prior::Prior;
use has_core::physics::aberration::SkullScreen;
use has_core::physics::mr::add_noise;
use has_core::{Scenario, Simulation};
use ndarray::Array2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::OnceLock;

const NOISE: f64 = 0.02;

fn model() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

/// The default phantom on a grid of λ/6 (0.45 mm) in place of the model's λ/4 (0.68 mm).
fn data_sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| {
        let spacing = 1500.0 / 550e3 / 6.0 * 1e3;
        let text = format!("[grid]\nspacing_mm = {spacing}\nstep_mm = {spacing}\n");
        Simulation::new(&Scenario::from_toml(&text, None).expect("scenario")).expect("fine-grid simulation")
    })
}

fn peak(img: &Array2<f64>) -> f64 {
    img.iter().copied().fold(f64::MIN, f64::max)
}

/// Seeds: 1 in the default run, 1–5 with `ARFI_FULL_SWEEPS=1` (CI time: each seed takes about
/// two minutes on two cores). Every assertion holds for each seed (no rate), and seed 1 is the
/// closest to the limits (with the nuisance fitted it recovers just above the 0.85 required, and
/// the model as it is recovers least on it), so it fails first if the nuisance fit breaks.
fn seeds() -> std::ops::RangeInclusive<u64> {
    1..=if std::env::var_os("ARFI_FULL_SWEEPS").is_some() { 5 } else { 1 }
}

/// A seeded random value in `lo..hi` with a random sign.
fn signed(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    sign * rng.random_range(lo..hi)
}

/// One case: the truth, the measurements, the hidden background offsets and the prediction.
struct Case {
    truth: Vec<f64>,
    measurements: Vec<Measurement>,
    offsets: Vec<f64>,
    prediction: Vec<f64>,
}

fn case(seed: u64) -> Case {
    let (m, d) = (model(), data_sim());
    let positions = m.transducer.reference_points();
    let truth = SkullScreen::default().phases(&positions, seed).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0xb0d1 + seed);
    let mut effects = Effects::none(d);
    effects.view.scale = 1.0 + signed(&mut rng, 0.0, 0.15);
    effects.view.broadening_width_mm = rng.random_range(2.9..3.5);
    let mut knowns = vec![vec![0.0; m.n_elements()]];
    for dz in [5e-3, -5e-3, 10e-3] {
        knowns.push(m.focus_shift_phases([0.0, 0.0, dz]).unwrap());
    }
    let mut offsets = vec![];
    let measurements = knowns
        .into_iter()
        .enumerate()
        .map(|(k, known)| {
            // Each acquisition drifts on its own.
            effects.view.background_offset_rad = signed(&mut rng, 0.01, 0.04);
            effects.view.background_slope_rad_per_mm = [signed(&mut rng, 0.0, 3e-4), signed(&mut rng, 0.0, 3e-4)];
            offsets.push(effects.view.background_offset_rad);
            let applied: Vec<f64> = truth.iter().zip(&known).map(|(t, p)| t + p).collect();
            let mut image = effect_images(d, &[applied], &effects).unwrap().remove(0);
            add_noise(&mut image, NOISE, 100 * seed + k as u64).unwrap();
            Measurement { image, known }
        })
        .collect();
    let error = SkullScreen { correlation_length: 15e-3, peak_to_peak: 5.0, jitter: 0.3 }.phases(&positions, 1000 + seed).unwrap();
    let prediction = truth.iter().zip(&error).map(|(t, e)| t + e).collect();
    Case { truth, measurements, offsets, prediction }
}

/// Focal ARFI of the data's simulation after subtracting `estimate`, over its ideal (marched
/// once on the fine grid and kept).
fn recovered(truth: &[f64], estimate: &[f64]) -> f64 {
    static IDEAL: OnceLock<f64> = OnceLock::new();
    let d = data_sim();
    let ideal = *IDEAL.get_or_init(|| peak(&d.arfi_image(&[]).unwrap()));
    let corrected: Vec<f64> = truth.iter().zip(estimate).map(|(t, e)| t - e).collect();
    peak(&d.arfi_image(&corrected).unwrap()) / ideal
}

/// The per-element model, and one element basis cache per set of nuisance fitted (the basis
/// depends on the pixel box and the views fitted): with several seeds whose images give the same
/// box the 1024 element marches run once per cache, not once per estimate. A cache only hands
/// back a basis built for the same simulation, box and window, so the estimates are unchanged.
fn per_element() -> &'static (Simulation, [BasisCache; 2]) {
    static PER_ELEMENT: OnceLock<(Simulation, [BasisCache; 2])> = OnceLock::new();
    PER_ELEMENT.get_or_init(|| {
        let mut s = model().clone();
        s.set_groups((0..s.n_elements()).collect()).unwrap();
        (s, Default::default())
    })
}

fn estimate(c: &Case, nuisance: Nuisance, seed: u64) -> EstimateReport {
    let (sim, caches) = per_element();
    let cache = &caches[usize::from(nuisance.any())];
    let prior = Prior::new(c.prediction.clone(), 0.8).unwrap().with_correlation_length(15e-3).unwrap();
    let request = EstimateRequest { prior: Some(prior), seed, nuisance, ..EstimateRequest::default() };
    estimate_aberration_with(sim, &c.measurements, &request, cache, Control::default()).unwrap()
}

/// Without the nuisance every seed's misfit is 1.6–3.6 and flagged; with it fitted the misfit is
/// within 2.5 % of the noise expectation and every background offset comes out within about
/// 0.001 rad of the hidden one (per-seed values: BENCHMARKS.md, section "Nuisance fitted with the
/// phases").
/// Asserted with the amplitude, W and the backgrounds fitted: the misfit within 10 % of the
/// noise expectation and no mismatch flagged (the residual is noise: the finer grid's own
/// discretisation is absorbed by W and the scale), at least 0.85 of the ideal focus and 0.05
/// above the prediction alone, each hidden background offset found within 0.005 rad (0.25 of
/// the noise per pixel; thousands of pixels determine it). Without them the model is flagged as
/// mismatched (misfit above 1.3) and recovers less.
#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn per_element_fits_nuisance_on_data_from_another_simulation() {
    let nuisance = Nuisance::parse(&["amplitude", "broadening", "background_phase"]).unwrap();
    for seed in seeds() {
        let c = case(seed);
        let alone = recovered(&c.truth, &c.prediction);
        let fitted = estimate(&c, nuisance, seed);
        let with = recovered(&c.truth, &fitted.estimate.phases);
        let n = fitted.nuisance.as_ref().expect("fitted nuisance reported");
        let plain = estimate(&c, Nuisance::default(), seed);
        let without = recovered(&c.truth, &plain.estimate.phases);
        let line = format!(
            "seed {seed}: prediction alone {alone:.3}, as it is {without:.3} (misfit {:.2}), with nuisance {with:.3} (misfit {:.3}; scale {:.3}, W {:.2} mm, offsets {:?} vs hidden {:?})",
            plain.assessment.misfit,
            fitted.assessment.misfit,
            n.scale,
            n.broadening_width_mm,
            n.background.iter().map(|b| (b[0] * 1e3).round() / 1e3).collect::<Vec<_>>(),
            c.offsets.iter().map(|b| (b * 1e3).round() / 1e3).collect::<Vec<_>>(),
        );
        println!("{line}");
        assert!(fitted.assessment.misfit < 1.1 && !fitted.assessment.mismatch, "{line}");
        assert!(with >= 0.85 && with >= alone + 0.05, "{line}");
        for (b, hidden) in n.background.iter().zip(&c.offsets) {
            assert!((b[0] - hidden).abs() < 0.005, "{line}");
        }
        assert!(plain.assessment.mismatch && plain.assessment.misfit > 1.3 && without < with, "{line}");
    }
}
