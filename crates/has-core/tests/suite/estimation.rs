//! Hybrid estimation on synthetic data from the default scenario: the estimators' acceptance checks.
//! Every check is against the known applied aberration; tolerances are stated where used.

use has_core::control::Control;
use has_core::inverse::calibrate::calibrate;
use has_core::inverse::cost::{build_model, ArfiKernel, Measurement};
use has_core::inverse::estimate::{condense, phase_error, point_reflection, Estimator};
use has_core::physics::aberration::SkullScreen;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use ndarray::Array2;
use std::sync::OnceLock;

fn sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

fn peak(img: &Array2<f64>) -> f64 {
    img.iter().copied().fold(f64::MIN, f64::max)
}

/// Skull-like 16-group aberration (smooth over the array, several radians peak to peak) for a seed.
fn group_truth(seed: u64) -> Vec<f64> {
    let s = sim();
    condense(&SkullScreen::default().phases(&s.transducer.reference_points(), seed).unwrap(), &s.groups).unwrap()
}

/// Recovered fraction: focal ARFI after subtracting the estimate, over the ideal focal ARFI.
fn recovered(truth: &[f64], estimate: &[f64]) -> f64 {
    let s = sim();
    let corrected: Vec<f64> = if truth.len() == estimate.len() {
        truth.iter().zip(estimate).map(|(t, e)| t - e).collect()
    } else {
        truth.iter().zip(&s.groups).map(|(t, &g)| t - estimate[g]).collect()
    };
    peak(&s.arfi_image(&corrected).unwrap()) / peak(&s.arfi_image(&[]).unwrap())
}

/// Random known group phases for diversity image `k`.
fn diversity(seed: u64, k: u64) -> Vec<f64> {
    SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 1.5 }.phases(&vec![[0.0; 3]; 16], 7919 * seed + k).unwrap()
}

fn measurements(truth: &[f64], noise: f64, images: u64, seed: u64) -> Vec<Measurement> {
    let s = sim();
    let mut m = vec![Measurement { image: s.noisy_arfi_image(truth, noise, seed).unwrap(), known: vec![] }];
    for k in 1..images {
        let d = diversity(seed, k);
        let total: Vec<f64> = if truth.len() == 16 {
            truth.iter().zip(&d).map(|(t, x)| t + x).collect()
        } else {
            truth.iter().zip(&s.groups).map(|(t, &g)| t + d[g]).collect()
        };
        m.push(Measurement { image: s.noisy_arfi_image(&total, noise, 1000 * seed + k).unwrap(), known: d });
    }
    m
}

fn lbfgs() -> Estimator {
    Estimator::lbfgs().with_twins(point_reflection(&sim().transducer.reference_points(), &sim().groups))
}

#[test]
fn kernel_image_equals_the_direct_simulation() {
    // Same field, same operators, different order of summation: equal to rounding (1e-9 of peak).
    let s = sim();
    let truth = group_truth(11);
    let k = ArfiKernel::build(s, &s.groups, &[], 50..78, 35..61).unwrap();
    let direct = s.arfi_image(&truth).unwrap();
    let fast = k.image(&truth).unwrap();
    let scale = peak(&direct);
    for ((i, j), v) in fast.indexed_iter() {
        assert!((v - direct[[50 + i, 35 + j]]).abs() < 1e-9 * scale, "pixel ({i}, {j})");
    }
}

#[test]
fn gradient_matches_finite_differences() {
    let s = sim();
    let truth = group_truth(12);
    let model = build_model(s, &measurements(&truth, 0.02, 2, 12), 0.05, 3).unwrap();
    let x: Vec<f64> = (0..16).map(|g| 0.3 * (g as f64).sin()).collect();
    let (_, grad) = model.cost.cost_and_gradient(&x);
    let h = 1e-6;
    for g in 0..16 {
        let mut a = x.clone();
        let mut b = x.clone();
        a[g] += h;
        b[g] -= h;
        let fd = (model.cost.cost(&a) - model.cost.cost(&b)) / (2.0 * h);
        // Central differences are accurate to O(h²) ≈ 1e-12 relative plus rounding ~1e-10/h.
        assert!((fd - grad[g]).abs() <= 1e-5 * grad.iter().map(|v| v.abs()).fold(0.0, f64::max), "group {g}: {fd} vs {}", grad[g]);
    }
}

#[test]
fn noise_free_single_image_recovers_the_focus() {
    let mut fractions = Vec::new();
    for seed in 1..=5 {
        let truth = group_truth(seed);
        let model = build_model(sim(), &measurements(&truth, 0.0, 1, seed), 0.05, 3).unwrap();
        let e = lbfgs().run(&model.cost, Control::default()).unwrap();
        fractions.push(recovered(&truth, &e.phases));
    }
    let mean = fractions.iter().sum::<f64>() / fractions.len() as f64;
    eprintln!("noise-free single image: recovered {fractions:.3?}, mean {mean:.3}");
    assert!(mean >= 0.95, "{fractions:?}");
}

#[test]
fn four_diversity_images_at_0_02_rad_recover_the_focus() {
    let mut fractions = Vec::new();
    for seed in 1..=5 {
        let truth = group_truth(seed);
        let model = build_model(sim(), &measurements(&truth, 0.02, 4, seed), 0.05, 3).unwrap();
        let e = lbfgs().run(&model.cost, Control::default()).unwrap();
        fractions.push(recovered(&truth, &e.phases));
    }
    let mean = fractions.iter().sum::<f64>() / fractions.len() as f64;
    eprintln!("4 images at 0.02 rad: recovered {fractions:.3?}, mean {mean:.3}");
    assert!(mean >= 0.90, "{fractions:?}");
}

#[test]
fn single_noisy_image_never_gives_a_silent_bad_answer() {
    // Every estimate recovering < 0.8 must be flagged; unflagged ones must recover >= 0.9.
    let s = sim();
    let sigma = point_reflection(&s.transducer.reference_points(), &s.groups);
    for noise in [0.005, 0.02] {
        for seed in 1..=5 {
            let truth = group_truth(seed);
            let model = build_model(s, &measurements(&truth, noise, 1, seed), 0.05, 3).unwrap();
            let e = lbfgs().run(&model.cost, Control::default()).unwrap();
            let a = e.assess(&model, sigma.as_deref(), 0.9, seed).unwrap();
            let r = recovered(&truth, &e.phases);
            eprintln!(
                "noise {noise} seed {seed}: recovered {r:.3}, ambiguous {} (worst {:.3}, {} candidates)",
                a.ambiguous,
                a.worst_recovery,
                a.candidates.len()
            );
            if r < 0.8 {
                assert!(a.ambiguous, "noise {noise} seed {seed}: recovered {r:.3} without a flag");
                assert!(a.suggested_phases.len() == 16 && a.suggested_separation > 0.0);
            }
            if !a.ambiguous {
                assert!(r >= 0.9, "noise {noise} seed {seed}: unflagged estimate recovered {r:.3}");
            }
        }
    }
}

#[test]
fn nelder_mead_from_zero_recovers_the_applied_phases_or_ends_at_a_true_local_minimum() {
    // The paper's Figure 3 setting: random group aberrations (uniform jitter of ±0.4 rad, seeds
    // 1–10), one noise-free image, zero start, the paper's limits. One in-focus image leaves
    // genuine local minima near the twin of the truth, so Nelder–Mead cannot find the truth
    // from zero on every seed; what it must do is end either at the applied phases or at a true
    // local minimum (an L-BFGS polish from its end point does not reach the truth), never stall
    // on a slope. Which seeds end where depends chaotically on the model (a change of the
    // interface treatment moves single seeds between the truth and a local minimum 0.2–0.45 rad
    // off), so the test asserts a rate, not a list of seeds. Without restarts shaped by the local
    // curvature Nelder–Mead stalls 0.1–0.3 rad off the truth with the truth downhill, which the
    // polish check below catches. L-BFGS with the analytic gradient recovers the applied phases.
    let s = sim();
    let mut recovered_phases = 0;
    for seed in 1..=10 {
        let truth = SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 0.4 }.phases(&vec![[0.0; 3]; 16], seed).unwrap();
        let model = build_model(s, &measurements(&truth, 0.0, 1, seed), 0.05, 3).unwrap();
        let nm = Estimator::nelder_mead().run(&model.cost, Control::default()).unwrap();
        assert!(nm.evaluations <= 8000);
        let err = phase_error(&nm.phases, &truth);
        let polish =
            Estimator::lbfgs().with_starts(1).unwrap().with_start(nm.phases.clone()).unwrap().run(&model.cost, Control::default()).unwrap();
        let polished = phase_error(&polish.phases, &truth);
        eprintln!(
            "Nelder-Mead noise-free seed {seed}: recovered {:.4} (aberrated {:.4}), phase error {err:.3} rad, cost {:.2e}, {} evaluations; polished {polished:.3} rad",
            recovered(&truth, &nm.phases),
            recovered(&truth, &[0.0; 16]),
            nm.cost,
            nm.evaluations
        );
        // 0.15 rad: the end point lies in the truth's basin (the polish then reaches < 1e-3);
        // 0.2 rad: a distinct minimum, well beyond the 0.03 rad the polish moves such points.
        if err < 0.15 {
            recovered_phases += 1;
        } else {
            assert!(polished > 0.2, "seed {seed}: Nelder-Mead stopped at {err:.3} rad with the truth downhill ({polished:.3})");
        }
        if seed == 3 {
            let lb = lbfgs().run(&model.cost, Control::default()).unwrap();
            let e = phase_error(&lb.phases, &truth);
            eprintln!("L-BFGS noise-free seed 3: phase error {e:.2e} rad");
            assert!(e < 0.01, "phase error {e}");
        }
    }
    // At least 4 of 10 (40 %): the share of these seeds whose end point lies in the truth's basin
    // is 40 % with either interface model (normal incidence or angular), though the seeds differ.
    assert!(recovered_phases >= 4, "Nelder-Mead recovered the applied phases on {recovered_phases} of 10 seeds");
}

#[test]
fn calibration_recovers_width_and_amplitude() {
    // A no-aberration image with W = 2.7 mm, the scenario amplitude and 0.02 rad noise.
    let s = sim();
    for seed in [1, 2, 3] {
        let image = s.noisy_arfi_image(&[], 0.02, seed).unwrap();
        let c = calibrate(s, &image, &[], 0.05, 10e-3).unwrap();
        eprintln!(
            "calibration seed {seed}: W {:.3} mm, amplitude ratio {:.4}, noise {:.4}",
            c.broadening_width * 1e3,
            c.amplitude / s.amplitude().unwrap(),
            c.noise
        );
        assert!((c.broadening_width - 2.7e-3).abs() < 0.1e-3);
        assert!((c.amplitude / s.amplitude().unwrap() - 1.0).abs() < 0.02);
        assert!((c.noise - 0.02).abs() < 0.002);
    }
}

#[test]
fn evaluation_and_time_limits_are_honoured() {
    let s = sim();
    let truth = group_truth(4);
    let model = build_model(s, &measurements(&truth, 0.02, 1, 4), 0.05, 3).unwrap();
    let e = Estimator::nelder_mead().with_max_evaluations(100).unwrap().run(&model.cost, Control::default()).unwrap();
    assert_eq!(e.evaluations, 100);
    assert_eq!(e.stop.name(), "evaluation limit");
    let e = Estimator::lbfgs().with_time_limit(0.05).unwrap().run(&model.cost, Control::default()).unwrap();
    assert!(e.seconds < 1.0, "{}", e.seconds);
    assert!(e.phases.len() == 16 && e.minima.iter().all(|m| m.phases.len() == 16));
    // Cancelled before the first evaluation: the start (zero) comes back, flagged.
    let cancel = std::sync::atomic::AtomicBool::new(true);
    let e = Estimator::particle_swarm().run(&model.cost, Control::default().with_cancel(&cancel)).unwrap();
    assert_eq!(e.stop.name(), "interrupted");
    assert_eq!(e.phases, vec![0.0; 16]);
}

#[test]
fn estimation_is_deterministic() {
    let s = sim();
    let truth = group_truth(5);
    let model = build_model(s, &measurements(&truth, 0.02, 1, 5), 0.05, 3).unwrap();
    for est in [Estimator::nelder_mead(), Estimator::particle_swarm().with_seed(9), lbfgs().with_seed(9)] {
        let a = est.run(&model.cost, Control::default()).unwrap();
        let b = est.run(&model.cost, Control::default()).unwrap();
        assert_eq!(a.phases, b.phases);
        assert_eq!(a.cost, b.cost);
    }
}

/// The workflow the CLI and Python run: per group on the kernels (here from two noise-free
/// images, one with known diversity phases, which determine the aberration: recovered to 0.01
/// rad, the L-BFGS tolerance), and the requests it refuses, each naming the parameter.
#[test]
fn the_estimation_workflow_estimates_per_group_and_names_what_it_refuses() {
    use has_core::inverse::estimate::workflow::{estimate_aberration, EstimateRequest, Method};
    let s = sim();
    let truth = group_truth(3);
    let m = measurements(&truth, 0.0, 2, 3);
    let r = estimate_aberration(s, &m, &EstimateRequest::default(), Control::default()).unwrap();
    let err = phase_error(&r.estimate.phases, &truth);
    assert!(err < 0.01, "phase error {err}");
    assert!(!r.assessment.ambiguous && !r.underdetermined && r.group_phases.is_none() && r.n_pixels > 0);
    assert_eq!(r.scale, 1.0);
    let e = Method::parse("bfgs").unwrap_err().to_string();
    assert!(e.starts_with("method:"), "{e}");
    let mut per_element = s.clone();
    per_element.set_groups((0..s.n_elements()).collect()).unwrap();
    let request = EstimateRequest { method: Method::NelderMead, ..EstimateRequest::default() };
    let e = estimate_aberration(&per_element, &m, &request, Control::default()).unwrap_err().to_string();
    assert!(e.contains("per-element") && e.contains("lbfgs"), "{e}");
    let mut many = s.clone();
    many.set_groups((0..s.n_elements()).map(|e| e % 300).collect()).unwrap();
    let e = estimate_aberration(&many, &m, &EstimateRequest::default(), Control::default()).unwrap_err().to_string();
    assert!(e.starts_with("groups: 300 groups"), "{e}");
}
