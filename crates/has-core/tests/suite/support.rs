//! Per-element estimation without a prior: an estimate the images do not support is flagged and
//! the recommendation names safer phases. The case of the measurement that showed the need: 1024
//! skull-like element aberrations on the default phantom, the aberrated image and three images with
//! known random group phases, 0.02 rad noise (the paper's). Foci are judged in the model, as
//! the recovered fraction is: the focal ARFI of the truth corrected, over the ideal's.

use has_core::control::Control;
use has_core::inverse::cost::Measurement;
use has_core::inverse::element::BasisCache;
use has_core::inverse::estimate::workflow::{estimate_aberration_with, EstimateReport, EstimateRequest, Recommended};
use has_core::physics::aberration::SkullScreen;
use has_core::{Scenario, Simulation};
use ndarray::Array2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// How far below the uncorrected focus (of the ideal) an unflagged estimate or a recommendation
/// may end: the noise of a focal value at 0.02 rad on the default phantom's 0.6 rad focus (about
/// 0.03 of it per pixel, less on the peak of the smoothed image) is of that order, so a smaller
/// difference is no loss the images could show.
const TOLERANCE: f64 = 0.02;

fn sims() -> &'static (Simulation, Simulation, BasisCache) {
    static SIMS: OnceLock<(Simulation, Simulation, BasisCache)> = OnceLock::new();
    SIMS.get_or_init(|| {
        let s = Simulation::new(&Scenario::default()).expect("default scenario");
        let mut per_element = s.clone();
        per_element.set_groups((0..s.n_elements()).collect()).unwrap();
        (s, per_element, BasisCache::default())
    })
}

fn peak(img: &Array2<f64>) -> f64 {
    img.iter().copied().fold(f64::MIN, f64::max)
}

/// One seed's case and estimate: the recovered fractions of the estimate, the uncorrected beam,
/// the group fit and the recommended phases, and the report.
struct Case {
    estimate: f64,
    uncorrected: f64,
    groups: f64,
    recommended: f64,
    report: EstimateReport,
    seconds: f64,
}

fn case(seed: u64) -> Case {
    let (s, per_element, cache) = sims();
    let truth = SkullScreen::default().phases(&s.transducer.reference_points(), seed).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(40_000 + seed);
    let mut m = vec![Measurement { image: s.noisy_arfi_image(&truth, 0.02, 20_000 + seed).unwrap(), known: vec![] }];
    for k in 0..3 {
        let known: Vec<f64> = (0..s.n_groups).map(|_| rng.random_range(-PI..PI)).collect();
        let added: Vec<f64> = truth.iter().zip(s.element_phases(&known).unwrap()).map(|(t, d)| t + d).collect();
        m.push(Measurement { image: s.noisy_arfi_image(&added, 0.02, 50_000 + 100 * seed + k).unwrap(), known });
    }
    let t = std::time::Instant::now();
    let request = EstimateRequest { seed, ..EstimateRequest::default() };
    let report = estimate_aberration_with(per_element, &m, &request, cache, Control::default()).unwrap();
    let seconds = t.elapsed().as_secs_f64();
    let ideal = peak(&s.arfi_image(&[]).unwrap());
    let left = |c: &[f64]| peak(&s.arfi_image(&truth.iter().zip(c).map(|(t, e)| t - e).collect::<Vec<_>>()).unwrap()) / ideal;
    let groups = s.element_phases(report.group_phases.as_ref().expect("the group warm start")).unwrap();
    Case {
        estimate: left(&report.estimate.phases),
        uncorrected: left(&vec![0.0; truth.len()]),
        groups: left(&groups),
        recommended: left(&report.recommendation.phases),
        seconds,
        report,
    }
}

/// Checks one seed: an estimate below the uncorrected focus (beyond [`TOLERANCE`]) is flagged
/// (ambiguous, and not recommended), the recommendation leaves no less than the uncorrected focus
/// by more than the tolerance, and an unconverged estimate is never recommended. Returns the
/// table's line.
fn check(seed: u64) -> String {
    let c = case(seed);
    let r = &c.report;
    let s = r.support.as_ref().expect("per element without a prior: the support is judged");
    let flagged = r.assessment.ambiguous || r.recommendation.kind != Recommended::Estimate;
    let line = format!(
        "seed {seed}: estimate {:.3}, uncorrected {:.3}, groups {:.3}, recommended {} {:.3}; determined {:.1} phases, expected focus {:.3} (model: uncorrected {:.3}, groups {:.3}); ambiguous {}, underdetermined {}, stop {}, {:.0} s",
        c.estimate,
        c.uncorrected,
        c.groups,
        r.recommendation.kind.name(),
        c.recommended,
        s.determined_phases,
        s.expected_focus,
        s.uncorrected_focus,
        s.groups_focus,
        r.assessment.ambiguous,
        r.underdetermined,
        r.estimate.stop.name(),
        c.seconds
    );
    println!("{line}");
    if c.estimate < c.uncorrected - TOLERANCE {
        assert!(flagged && r.recommendation.kind != Recommended::Estimate, "{line}");
    }
    assert!(c.recommended >= c.uncorrected - TOLERANCE, "{line}");
    assert!(r.converged() || r.recommendation.kind != Recommended::Estimate, "{line}");
    assert_eq!(r.underdetermined, !s.determines(), "{line}");
    line
}

/// Seed 8 of this case left 0.29 of the ideal focus against 0.46 uncorrected, unflagged and
/// recommended, under the pixel count test (1323 pixels for 1024 phases): the measured failure.
#[test]
fn per_element_without_a_prior_an_estimate_below_the_uncorrected_focus_is_flagged() {
    check(8);
}

/// Seeds 1–12 (about 25 s each on 2 cores).
#[test]
#[ignore = "long: run by CI (cargo test -- --ignored) and the full mode (-- --include-ignored), docs/testing.md"]
fn per_element_without_a_prior_no_unflagged_estimate_ends_below_the_uncorrected_focus_over_12_seeds() {
    for seed in 1..=12 {
        check(seed);
    }
}
