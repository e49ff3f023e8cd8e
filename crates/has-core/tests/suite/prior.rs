//! Estimation with a predicted aberration as prior (the clinical starting point: a CT-based
//! skull simulation), on synthetic data from the default scenario with a perfect model. Every
//! check is against the known applied aberration over seeds 1–5; tolerances are stated where used.

use has_core::control::Control;
use has_core::inverse::cost::Measurement;
use has_core::inverse::element::nuisance::Nuisance;
use has_core::inverse::estimate::workflow::{estimate_aberration, EstimateReport, EstimateRequest, Recommended, CONFLICT_Z};
use has_core::inverse::estimate::{condense, phase_error, wrap};
use has_core::inverse::prior::smooth::error_modes;
use has_core::inverse::prior::Prior;
use has_core::physics::aberration::SkullScreen;
use has_core::{Scenario, Simulation};
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::sync::OnceLock;

fn sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

/// Seeds of a sweep: `1..=ci` in the default run, `1..=full` with `ARFI_FULL_SWEEPS=1` set (CI
/// time).
fn seeds(ci: u64, full: u64) -> std::ops::RangeInclusive<u64> {
    1..=if std::env::var_os("ARFI_FULL_SWEEPS").is_some() { full } else { ci }
}

fn peak(img: &Array2<f64>) -> f64 {
    img.iter().copied().fold(f64::MIN, f64::max)
}

/// `s` with one group per element (per-element estimation).
fn per_element(s: &Simulation) -> Simulation {
    let mut e = s.clone();
    e.set_groups((0..s.n_elements()).collect()).unwrap();
    e
}

/// The focal ARFI (of `ideal`) of `s` with `truth` corrected by `estimate`.
fn focus_left(s: &Simulation, truth: &[f64], estimate: &[f64], ideal: f64) -> f64 {
    let c: Vec<f64> = truth.iter().zip(estimate).map(|(t, e)| t - e).collect();
    peak(&s.arfi_image(&c).unwrap()) / ideal
}

/// Skull-like 16-group aberration for a seed.
fn group_truth(seed: u64) -> Vec<f64> {
    let s = sim();
    let positions = s.transducer.reference_points();
    condense(&SkullScreen::default().phases(&positions, seed).unwrap(), &s.groups).unwrap()
}

/// A prediction of `truth` with independent Gaussian errors of `error_rad` per phase (seeded).
fn predicted(truth: &[f64], error_rad: f64, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5eed ^ seed);
    let normal = Normal::new(0.0, error_rad).unwrap();
    truth.iter().map(|t| wrap(t + normal.sample(&mut rng))).collect()
}

/// Focal ARFI after subtracting `estimate` (per group), over the ideal.
fn recovered(truth: &[f64], estimate: &[f64]) -> f64 {
    let s = sim();
    let corrected: Vec<f64> = truth.iter().zip(estimate).map(|(t, e)| t - e).collect();
    peak(&s.arfi_image(&corrected).unwrap()) / peak(&s.arfi_image(&[]).unwrap())
}

fn one_image(truth: &[f64], noise: f64, seed: u64) -> Vec<Measurement> {
    vec![Measurement { image: sim().noisy_arfi_image(truth, noise, seed).unwrap(), known: vec![] }]
}

/// One image at 0.02 rad (the paper's noise level), where images alone are ambiguous (the twin
/// fits within the noise), with predictions of 0.3 and 0.6 rad error per group. The posterior's
/// phase error is at most the prediction's, its focus at most about 0.01 below the prediction's
/// (where the prediction alone gives 0.95–1.0, so a little image noise costs a little focus) and
/// at least the images-alone estimate's; at 0.6 rad the image raises the mean recovery over
/// seeds 1–5 by about 0.09 (0.79 to 0.88).
///
/// Every check per case runs on seed 1 by default; the mean gain over seeds 1–5 (a statistic)
/// with `ARFI_FULL_SWEEPS=1`, and by default the single-seed form of it: on seed 1 the 0.6 rad
/// prediction gains from the image.
#[test]
fn one_image_with_a_prior_is_never_worse_than_the_prior_and_never_a_twin() {
    let mut gain = 0.0;
    let seeds = seeds(1, 5);
    let n = seeds.clone().count() as f64;
    for seed in seeds {
        let truth = group_truth(seed);
        let m = one_image(&truth, 0.02, seed);
        let alone = estimate_aberration(sim(), &m, &EstimateRequest::default(), Control::default()).unwrap();
        assert!(!alone.prior_used && (alone.image_cost - alone.estimate.cost).abs() <= 1e-9 * alone.image_cost);
        for error in [0.3, 0.6] {
            let prediction = predicted(&truth, error, seed);
            let prior = Prior::new(prediction.clone(), error).unwrap();
            let request = EstimateRequest { prior: Some(prior), ..EstimateRequest::default() };
            let post = estimate_aberration(sim(), &m, &request, Control::default()).unwrap();
            let (r_prior, r_images, r_post) =
                (recovered(&truth, &prediction), recovered(&truth, &alone.estimate.phases), recovered(&truth, &post.estimate.phases));
            let (e_prior, e_post) = (phase_error(&prediction, &truth), phase_error(&post.estimate.phases, &truth));
            let case = format!("seed {seed}, error {error}: recovered prior {r_prior:.3} images {r_images:.3} posterior {r_post:.3}; phase error prior {e_prior:.3} posterior {e_post:.3}");
            println!("{case}");
            assert!(post.prior_used, "{case}");
            // Phase error: 0.01 rad of slack for the noise (the posterior may trade a little).
            assert!(e_post <= e_prior + 0.01, "{case}");
            // Focus: 0.02 of slack where the prediction is already near the ideal focus.
            assert!(r_post >= r_prior - 0.02, "{case}");
            // The images alone may land on the twin; with the prior, never below them.
            assert!(r_post >= r_images, "{case}");
            // Ambiguity judged on the posterior: a confident answer is a good one.
            assert!(post.assessment.ambiguous || r_post > 0.9, "{case}");
            if error == 0.6 {
                gain += (r_post - r_prior) / n;
            }
        }
    }
    // A poor prediction gains from one image on average (about +0.09 over seeds 1-5; asserted above
    // +0.04, less than half of it, leaving room for the spread between seeds), and on seed 1 alone
    // (the default run) by the same margin.
    assert!(gain > 0.04, "mean gain over the prediction {gain:.3}");
}

/// A prior of the wrong length is refused, naming the parameter; per element it is condensed
/// to the groups (circular means).
#[test]
fn prior_lengths_per_group_and_per_element() {
    let s = sim();
    let truth = group_truth(1);
    let m = one_image(&truth, 0.02, 1);
    let bad = EstimateRequest { prior: Some(Prior::new(vec![0.0; 7], 0.5).unwrap()), ..EstimateRequest::default() };
    let e = estimate_aberration(s, &m, &bad, Control::default()).unwrap_err().to_string();
    assert!(e.starts_with("prior:") && e.contains("1024") && e.contains("16"), "{e}");
    let per_element: Vec<f64> = s.groups.iter().map(|&g| truth[g]).collect();
    let request = EstimateRequest { prior: Some(Prior::new(per_element, 0.3).unwrap()), ..EstimateRequest::default() };
    let r = estimate_aberration(s, &m, &request, Control::default()).unwrap();
    // The prediction is the truth: the image (0.02 rad noise) moves the posterior well within the
    // prediction's stated error S = 0.3 rad (about 0.12 rad; asserted below S/2).
    let err = phase_error(&r.estimate.phases, &truth);
    assert!(err < 0.15 && r.prior_used, "phase error {err}");
}

/// Per element (1024 phases) from 4 images at 0.02 rad noise, the aberrated one and three
/// defocused ones (the focus moved by +5, -5 and +10 mm along the axis with known phases), with a
/// CT-like prediction whose error is a smooth field (15 mm correlation, 5 rad peak to peak) plus
/// 0.3 rad per-element jitter: alone it recovers 0.70–0.83 of the ideal focus over seeds 1–5
/// (mean 0.74). With the smooth prior (0.8 rad, 15 mm) the estimate reaches 0.87–0.91 (mean
/// 0.885), each seed 0.04–0.19 above the prediction alone; three images of random known group
/// phases instead reach less (mean 0.85), and with them the independent prior 0.63–0.79 (mean
/// 0.72, below the prediction alone: 1024 free phases fit the noise). Per-seed values:
/// BENCHMARKS.md, sections "Smooth-error prior and defocused images" and "Ladder constants".
/// Asserted: every seed at least 0.85 and 0.03 above the prediction alone (margins for rounding
/// differences of the single-precision basis across machines). Seed 1 in the default run (each
/// seed marches 1024 element fields twice), 1–5 with `ARFI_FULL_SWEEPS=1`.
///
/// From the aberrated image alone (one acquisition) the estimate must be the prediction itself,
/// exactly: the posterior optimum of that one image can leave far less than the prediction
/// (0.53 against 0.72 on seed 1), and nothing in the data flags it.
#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn per_element_with_a_smooth_prior_and_defocused_images_lifts_a_prediction_of_0_7_above_0_85() {
    let s = sim();
    let per_element = per_element(s);
    let positions = s.transducer.reference_points();
    let ideal = peak(&s.arfi_image(&[]).unwrap());
    for seed in seeds(1, 5) {
        let truth = SkullScreen::default().phases(&positions, seed).unwrap();
        let recovered = |est: &[f64]| focus_left(s, &truth, est, ideal);
        let mut m = vec![Measurement { image: s.noisy_arfi_image(&truth, 0.02, seed).unwrap(), known: vec![] }];
        for (k, dz) in [5e-3, -5e-3, 10e-3].into_iter().enumerate() {
            let known = s.focus_shift_phases([0.0, 0.0, dz]).unwrap();
            let added: Vec<f64> = truth.iter().zip(&known).map(|(t, d)| t + d).collect();
            m.push(Measurement { image: s.noisy_arfi_image(&added, 0.02, seed * 10 + k as u64 + 1).unwrap(), known });
        }
        let error = SkullScreen { correlation_length: 15e-3, peak_to_peak: 5.0, jitter: 0.3 }.phases(&positions, 1000 + seed).unwrap();
        let prediction: Vec<f64> = truth.iter().zip(&error).map(|(t, e)| t + e).collect();
        let prior = Prior::new(prediction.clone(), 0.8).unwrap().with_correlation_length(15e-3).unwrap();
        let request = EstimateRequest { prior: Some(prior), seed, ..EstimateRequest::default() };
        let one = estimate_aberration(&per_element, &m[..1], &request, Control::default()).unwrap();
        assert!(one.kept_prediction && one.estimate.evaluations == 0 && !one.assessment.mismatch, "seed {seed}");
        assert!(one.estimate.phases.iter().zip(&prediction).all(|(e, p)| wrap(e - p).abs() < 1e-12), "seed {seed}");
        let r = estimate_aberration(&per_element, &m, &request, Control::default()).unwrap();
        assert!(!r.kept_prediction, "seed {seed}");
        let (alone, post) = (recovered(&prediction), recovered(&r.estimate.phases));
        println!("seed {seed}: prediction alone {alone:.3}, with 4 images {post:.3} ({} evaluations)", r.estimate.evaluations);
        assert!(r.prior_used && post > 0.85 && post > alone + 0.03, "seed {seed}: {post:.3} vs prediction alone {alone:.3}");
    }
}

/// A 256-element hemisphere (150 mm radius of curvature, out to 60°) at 220 kHz focused 150 mm
/// deep, in water with a brain-like attenuating slab from 90 to 210 mm: the transcranial
/// geometry without bone.
fn hemisphere() -> Simulation {
    let text = "frequency_hz = 220000.0\n\
        [transducer]\nkind = \"hemisphere\"\nradius_of_curvature_mm = 150.0\npolar_angle_max_deg = 60.0\nelements = 256\n\
        [focus]\nposition_mm = [0.0, 0.0, 150.0]\n\
        [[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\nattenuation_db_cm_mhz = 0.0\n\
        [[material]]\nname = \"brain\"\nsound_speed_m_s = 1540.0\ndensity_kg_m3 = 1040.0\nattenuation_db_cm_mhz = 0.6\n\
        [[region]]\nmaterial = \"brain\"\nshape = \"slab\"\nz_min_mm = 90.0\nz_max_mm = 210.0\n";
    Simulation::new(&Scenario::from_toml(text, None).unwrap()).unwrap()
}

/// Images of `s` with per-element `truth` added, in focus and with the focus moved ±5 mm along
/// the axis, at `transmission` of the model's scale, with seeded noise of `noise` (rad).
fn focus_and_defocus_images(s: &Simulation, truth: &[f64], transmission: f64, noise: f64, seed: u64) -> Vec<Measurement> {
    let image = |known: Vec<f64>, k: u64| {
        let added: Vec<f64> = truth.iter().zip(&known).map(|(t, d)| t + d).collect();
        let mut img = s.arfi_image(&added).unwrap() * transmission;
        let mut rng = ChaCha8Rng::seed_from_u64(100 * seed + k);
        let normal = Normal::new(0.0, noise).unwrap();
        img.mapv_inplace(|v| v + normal.sample(&mut rng));
        Measurement { image: img, known }
    };
    [0.0, 5e-3, -5e-3].into_iter().enumerate().map(|(k, dz)| image(s.focus_shift_phases([0.0, 0.0, dz]).unwrap(), k as u64)).collect()
}

/// The [`hemisphere`] per element with a skull-like truth of `seed` (15 mm, 4 rad peak to peak,
/// 0.2 rad jitter): what the tests of a per-element prior share.
struct SkullCase {
    sim: Simulation,
    per_element: Simulation,
    truth: Vec<f64>,
    ideal: f64,
    seed: u64,
}

impl SkullCase {
    fn new(seed: u64) -> Self {
        let sim = hemisphere();
        let positions = sim.transducer.reference_points();
        let truth = SkullScreen { correlation_length: 15e-3, peak_to_peak: 4.0, jitter: 0.2 }.phases(&positions, seed).unwrap();
        let ideal = peak(&sim.arfi_image(&[]).unwrap());
        SkullCase { per_element: per_element(&sim), sim, truth, ideal, seed }
    }

    /// The focal ARFI (of the ideal) the truth leaves corrected by `estimate`.
    fn left(&self, estimate: &[f64]) -> f64 {
        focus_left(&self.sim, &self.truth, estimate, self.ideal)
    }

    /// The truth off by seeded independent normal errors of `error_rad` per element.
    fn prediction(&self, error_rad: f64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(0xe77 ^ self.seed);
        let normal = Normal::new(0.0, error_rad).unwrap();
        self.truth.iter().map(|t| t + normal.sample(&mut rng)).collect()
    }

    /// The per-element estimate from `images` with `prediction` as prior of `std_rad`.
    fn estimate(&self, images: &[Measurement], prediction: &[f64], std_rad: f64) -> EstimateReport {
        let prior = Some(Prior::new(prediction.to_vec(), std_rad).unwrap());
        let request = EstimateRequest { prior, seed: self.seed, ..EstimateRequest::default() };
        estimate_aberration(&self.per_element, images, &request, Control::default()).unwrap()
    }
}

/// Per element with a prior, the estimate starts from the prediction (no default-group fit) and
/// its ambiguity is judged on the element posterior (searches from draws of the prior; rivals
/// within the images' noise margin, scored by the focus the correction would leave were they the
/// truth). The [`hemisphere`] with a skull-like truth and three images at 0.02 rad, the
/// prediction off by independent normal errors of the prior's std per element, as the prior
/// says: with ±0.15 rad (the tutorial's) and ±0.4 rad the estimate must leave at least the
/// prediction's focus less 0.01 (the noise's share, as above), and with ±0.15 rad the estimate is
/// not ambiguous: the solutions such a prior allows differ by far less than the 0.1 of the focus
/// the flag needs. With ±0.15 rad the prediction leaves about 0.98 and the estimate about as
/// much; with ±0.4 rad about 0.86 and 0.92.
#[test]
fn with_a_prior_the_per_element_estimate_starts_from_it_and_is_judged_on_its_posterior() {
    let case = SkullCase::new(2);
    let m = focus_and_defocus_images(&case.sim, &case.truth, 1.0, 0.02, case.seed);
    for std_rad in [0.15, 0.4] {
        let prediction = case.prediction(std_rad);
        let r = case.estimate(&m, &prediction, std_rad);
        let (alone, post, a) = (case.left(&prediction), case.left(&r.estimate.phases), &r.assessment);
        println!(
            "prior +-{std_rad}: prediction {alone:.3}, estimate {post:.3}; {} candidate(s), worst recovery {:.3}",
            a.candidates.len(),
            a.worst_recovery
        );
        assert!(r.prior_used && r.group_phases.is_none() && !a.candidates.is_empty(), "prior +-{std_rad}");
        // Images the model forms, a prediction as good as the prior says: no conflict.
        let check = r.prior_check.as_ref().expect("a searched estimate with a prior is checked");
        assert!(!check.conflict && check.z < CONFLICT_Z, "prior +-{std_rad}: false conflict {check:?}");
        assert!(post >= alone - 0.01, "prior +-{std_rad}: {post:.3} vs prediction alone {alone:.3}");
        assert_eq!(a.ambiguous, a.worst_recovery < EstimateRequest::default().threshold, "prior +-{std_rad}");
        if std_rad < 0.2 {
            assert!(!a.ambiguous && a.worst_recovery > 0.95, "prior +-{std_rad}: worst recovery {:.3}", a.worst_recovery);
        }
    }
}

/// With a prior, images the model cannot form about the prediction are not absorbed: the
/// [`hemisphere`] as above (prior ±0.3 rad, the prediction off by that much, three images at
/// 0.02 rad) with the images moved by one MR pixel along u, which the model does not know. The
/// search then fits them about as well as the noise allows (misfit 1.04-1.17, below the
/// mismatch rule's 1.2) by moving its phases, and leaves less focus than the prediction alone
/// (0.009-0.035 of the optimum lower on six seeds, measured on the focal pressure). The
/// prior-predictive check sees the images' cost at the prediction far above what images of
/// truths within the prior leave (z 12-25 there against 3; on images the model forms, -3.9 to
/// -0.4), and the prediction is recommended as given.
#[test]
fn with_a_prior_images_the_model_cannot_form_recommend_the_prediction() {
    for seed in [1, 2] {
        let case = SkullCase::new(seed);
        let mut m = focus_and_defocus_images(&case.sim, &case.truth, 1.0, 0.02, seed);
        for measurement in m.iter_mut() {
            // One pixel along u (rows), as np.roll: the last row comes round to the first.
            let rows = measurement.image.nrows();
            let shifted = Array2::from_shape_fn(measurement.image.dim(), |(i, j)| measurement.image[[(i + rows - 1) % rows, j]]);
            measurement.image = shifted;
        }
        let prediction = case.prediction(0.3);
        let r = case.estimate(&m, &prediction, 0.3);
        let check = r.prior_check.as_ref().expect("a searched estimate with a prior is checked");
        let (alone, post, applied) = (case.left(&prediction), case.left(&r.estimate.phases), case.left(&r.recommendation.phases));
        println!(
            "seed {seed}: prediction {alone:.3}, estimate {post:.3}, recommended {:?} {applied:.3}; misfit {:.2}; {check:?}",
            r.recommendation.kind, r.assessment.misfit
        );
        assert!(check.conflict && check.z > CONFLICT_Z, "seed {seed}: the shifted images were not seen: {check:?}");
        assert_eq!(r.recommendation.kind, Recommended::Prediction, "seed {seed}");
        assert_eq!(applied, alone, "seed {seed}: the prediction is applied as given");
    }
}

/// A prediction worse than its prior says is not a conflict: the images, which the model forms,
/// are fitted and the estimate applied. The [`hemisphere`] as above, the prior stated ±0.3 rad,
/// the prediction off by 0.5 rad per element (seed 3: the prediction leaves 0.78 of the ideal
/// focal ARFI, the estimate 0.87; z -3.4). Such a prediction loses focal amplitude, which the
/// check's refitted scale absorbs (with the scale held at 1 the check called such predictions
/// conflicts, at z 4-23 on the 256-element planar array, and the prediction was applied:
/// 0.02-0.06 of the focal pressure lost).
#[test]
fn with_a_prior_a_prediction_worse_than_its_std_is_no_conflict() {
    let case = SkullCase::new(3);
    let m = focus_and_defocus_images(&case.sim, &case.truth, 1.0, 0.02, case.seed);
    let prediction = case.prediction(0.5);
    let r = case.estimate(&m, &prediction, 0.3);
    let check = r.prior_check.as_ref().expect("a searched estimate with a prior is checked");
    let (alone, post) = (case.left(&prediction), case.left(&r.estimate.phases));
    println!("stated 0.3, off by 0.5: prediction {alone:.3}, estimate {post:.3}; {check:?}");
    assert!(!check.conflict, "a prediction worse than its std called a conflict: {check:?}");
    assert_eq!(r.recommendation.kind, Recommended::Estimate);
    assert!(post > alone + 0.02, "the estimate {post:.3} should raise the prediction's {alone:.3}");
}

/// A seeded smooth field with the covariance a smooth prior of `std_rad` over `length` (m)
/// claims ([`error_modes`] with standard normal coefficients).
fn smooth_field(positions: &[[f64; 3]], std_rad: f64, length: f64, seed: u64) -> Vec<f64> {
    let modes = error_modes(positions, std_rad, length).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(0xf1e1d ^ seed);
    let a: Vec<f64> = modes.iter().map(|_| Normal::new(0.0, 1.0).unwrap().sample(&mut rng)).collect();
    (0..positions.len()).map(|e| modes.iter().zip(&a).map(|(w, c)| w[e] * c).sum()).collect()
}

/// Per element with a smooth prior and a fitted amplitude scale, the transcranial case of the
/// README (a CT prediction as prior ±0.5 rad over 40 mm, three images at 0.02 rad, the images
/// weaker than the bone-free model by the skull's transmission, `--fit-nuisance amplitude`):
/// the estimate must never end below the prediction alone by more than the noise explains.
///
/// Hemisphere of 256 elements ([`hemisphere`]), a skull-like truth (15 mm, 4 rad peak to peak,
/// 0.2 rad jitter), a prediction whose error is a smooth field of 0.15 rad over 40 mm (so the
/// prediction alone gives 0.99–1.0 of the ideal focus, as in the README's case), images of the
/// truth in focus and with the focus moved ±5 mm along the axis, at 0.3 of the model's scale
/// (focal ARFI 0.18 rad) with 0.02 rad noise.
///
/// Tolerance 0.06 of the ideal focus: under its own weights, noise moves the posterior optimum
/// by at most half the prior's spread in any direction (a direction of data precision `r` times
/// the prior's moves by `g/(1 + r)` with `g ~ N(0, r)`: variance `r/(1 + r)²` ≤ 1/4 of the prior's),
/// so by at most `S/2 = 0.25` rad RMS over the elements, a focal loss of at most
/// `1 - exp(-(S/2)²) = 0.06`. The scale is fitted on every pixel of the box (see
/// [`has_core::inverse::element::fits_whole_box`]): on the focal-zone masks alone it comes out
/// near 0.5 instead of 0.3 and the estimate falls to 0.66–0.82 of the ideal focus where the
/// prediction alone leaves 0.99 (seeds 1–4); on the whole box the scale is 0.29–0.31 and the
/// estimate stays within 0.031 of the prediction. Every seed catches a fit on the masks, so seed
/// 1 runs by default (one estimate on 256 elements), 1–4 with `ARFI_FULL_SWEEPS=1`.
#[test]
fn a_smooth_prior_with_a_fitted_scale_is_never_worse_than_the_prediction_beyond_the_noise() {
    let s = hemisphere();
    let per_element = per_element(&s);
    let positions = s.transducer.reference_points();
    let ideal = peak(&s.arfi_image(&[]).unwrap());
    let (std_rad, length, transmission, noise) = (0.5, 40e-3, 0.3, 0.02);
    for seed in seeds(1, 4) {
        let truth = SkullScreen { correlation_length: 15e-3, peak_to_peak: 4.0, jitter: 0.2 }.phases(&positions, seed).unwrap();
        let recovered = |est: &[f64]| focus_left(&s, &truth, est, ideal);
        let m = focus_and_defocus_images(&s, &truth, transmission, noise, seed);
        let error = smooth_field(&positions, 0.15, length, seed);
        let prediction: Vec<f64> = truth.iter().zip(&error).map(|(t, e)| t + e).collect();
        let prior = Prior::new(prediction.clone(), std_rad).unwrap().with_correlation_length(length).unwrap();
        let nuisance = Nuisance { amplitude: true, ..Nuisance::default() };
        let request = EstimateRequest { prior: Some(prior), nuisance, seed, ..EstimateRequest::default() };
        let r = estimate_aberration(&per_element, &m, &request, Control::default()).unwrap();
        let (alone, post) = (recovered(&prediction), recovered(&r.estimate.phases));
        let scale = r.nuisance.as_ref().map_or(f64::NAN, |f| f.scale);
        println!("seed {seed}: prediction alone {alone:.3}, posterior {post:.3} (fitted scale {scale:.3})");
        assert!(r.prior_used && !r.kept_prediction, "seed {seed}");
        assert!(post >= alone - 0.06, "seed {seed}: {post:.3} vs prediction alone {alone:.3}");
    }
}

/// A prediction off by a mode of known shape (what a misjudged CT constant does: one pattern over
/// the whole aperture, with element-scale detail from each element's own path through bone):
/// with that mode in the prior ([`Prior::with_modes`]) the images fit its one coefficient, and
/// the estimate must beat the smooth prior alone by at least 0.05 of the ideal focus and leave at
/// least 0.95. The [`hemisphere`] with a skull-like truth, three images at 0.02 rad; the
/// prediction is the truth plus 1.5 times the mode (a detailed field: 5 mm correlation, 2 rad
/// peak to peak, 0.3 rad jitter; 1.5 standard deviations of the mode's coefficient) and the
/// prior ±0.3 rad over 30 mm, which cannot follow detail finer than its 30 mm. The margin 0.05
/// is what images must add over a poor prediction. And a mode must not cost a good prediction:
/// off only by a smooth field of the prior's kind (0.1 rad over 30 mm), the estimate with the mode
/// must leave at least what the smooth prior alone leaves less 0.01 (the noise's share, as in the
/// tests above). The poor prediction leaves about 0.67, the smooth prior alone about as much,
/// with the mode about 0.99; the good prediction leaves about 1.0 all three ways (alone, smooth
/// prior, with the mode; above 1 where a phase error shifts the model's image peak onto a
/// brighter pixel: the ideal is that peak).
#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn a_mode_of_known_shape_in_the_prior_is_fitted_as_one_number() {
    let s = hemisphere();
    let per_element = per_element(&s);
    let positions = s.transducer.reference_points();
    let ideal = peak(&s.arfi_image(&[]).unwrap());
    let seed = 3;
    let truth = SkullScreen { correlation_length: 15e-3, peak_to_peak: 4.0, jitter: 0.2 }.phases(&positions, seed).unwrap();
    let mode = SkullScreen { correlation_length: 5e-3, peak_to_peak: 2.0, jitter: 0.3 }.phases(&positions, 77).unwrap();
    let prediction: Vec<f64> = truth.iter().zip(&mode).map(|(t, g)| t + 1.5 * g).collect();
    let m = focus_and_defocus_images(&s, &truth, 1.0, 0.02, seed);
    let smooth = Prior::new(prediction.clone(), 0.3).unwrap().with_correlation_length(30e-3).unwrap();
    let left = |prior: Prior| {
        let request = EstimateRequest { prior: Some(prior), seed, ..EstimateRequest::default() };
        let r = estimate_aberration(&per_element, &m, &request, Control::default()).unwrap();
        focus_left(&s, &truth, &r.estimate.phases, ideal)
    };
    let (alone, without, with) =
        (focus_left(&s, &truth, &prediction, ideal), left(smooth.clone()), left(smooth.with_modes(vec![mode.clone()]).unwrap()));
    println!("prediction {alone:.3}, smooth prior {without:.3}, with the mode {with:.3}");
    assert!(with >= 0.95 && with >= without + 0.05, "prediction {alone:.3}, smooth prior {without:.3}, with the mode {with:.3}");
    let good: Vec<f64> = truth.iter().zip(smooth_field(&positions, 0.1, 30e-3, seed)).map(|(t, e)| t + e).collect();
    let smooth_good = Prior::new(good.clone(), 0.3).unwrap().with_correlation_length(30e-3).unwrap();
    let (alone, without, with) =
        (focus_left(&s, &truth, &good, ideal), left(smooth_good.clone()), left(smooth_good.with_modes(vec![mode.clone()]).unwrap()));
    println!("good prediction {alone:.3}, smooth prior {without:.3}, with the mode {with:.3}");
    assert!(with >= without - 0.01, "good prediction {alone:.3}, smooth prior {without:.3}, with the mode {with:.3}");
    // Refused where they cannot be fitted: a group estimate, and a prior without a correlation.
    let request = |prior: Prior| EstimateRequest { prior: Some(prior), seed, ..EstimateRequest::default() };
    let independent = Prior::new(prediction.clone(), 0.3).unwrap().with_modes(vec![vec![0.1; 256]]).unwrap();
    let err = |sim: &Simulation, p: Prior| estimate_aberration(sim, &m, &request(p), Control::default()).unwrap_err().to_string();
    assert!(err(&per_element, independent.clone()).starts_with("prior_modes"));
    assert!(err(&s, independent.with_correlation_length(30e-3).unwrap()).starts_with("prior_modes"));
    let short = Prior::new(prediction.clone(), 0.3).unwrap().with_correlation_length(30e-3).unwrap().with_modes(vec![vec![0.1; 10]]);
    assert!(err(&per_element, short.unwrap()).starts_with("prior_modes"));
    // Predicted phases per default group are spread to the elements; the modes stay per element.
    let per_group = condense(&prediction, &s.groups).unwrap();
    let spread = Prior::new(per_group, 0.3).unwrap().with_correlation_length(30e-3).unwrap().with_modes(vec![mode]).unwrap();
    assert!(estimate_aberration(&per_element, &m, &request(spread), Control::default()).is_ok());
}
