//! The linearised information of per-element acquisitions ([`has_core::inverse::estimate::information`]),
//! checked against references that are not the module: central finite differences of the basis
//! images, the closed form for independent errors, and Monte Carlo draws of correlated errors.
//! On a 256-element version of the default array to keep the marches short.

use crate::common;
use has_core::control::Control;
use has_core::inverse::cost::Measurement;
use has_core::inverse::element::build_element_model;
use has_core::inverse::estimate::information::{
    error_covariance, expected_focus, fisher, focal_fields, image_jacobian, suggest_focus_shift, Spread, CANDIDATE_SHIFTS_MM,
};
use has_core::inverse::linear::cholesky;
use has_core::inverse::prior::smooth::error_modes;
use has_core::physics::aberration::SkullScreen;
use has_core::simulation::Simulation;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// A skull-like aberration and two noise-free images of it: in focus and defocused by 5 mm.
fn study(sim: &Simulation) -> (Vec<f64>, Vec<Measurement>) {
    let truth = SkullScreen::default().phases(&sim.transducer.reference_points(), 1).unwrap();
    let known = sim.focus_shift_phases([0.0, 0.0, 5e-3]).unwrap();
    let defocused: Vec<f64> = truth.iter().zip(&known).map(|(t, k)| t + k).collect();
    let images = vec![
        Measurement { image: sim.arfi_image(&truth).unwrap(), known: vec![] },
        Measurement { image: sim.arfi_image(&defocused).unwrap(), known },
    ];
    (truth, images)
}

#[test]
fn jacobian_matches_central_differences_of_the_basis_images() {
    let sim = common::small_array();
    let (truth, images) = study(&sim);
    let model = build_element_model(&sim, &images, sim.mask_fraction, 0, Control::default()).unwrap();
    let cost = &model.cost;
    let term = &cost.terms[1];
    let j = image_jacobian(cost, &truth, &term.offset, &term.mask).unwrap();
    assert_eq!(j.dim(), (term.mask.len(), sim.n_elements()));
    let h = 1e-2;
    for e in [0, 37, 128, 255] {
        let image_at = |d: f64| {
            let phases: Vec<f64> =
                truth.iter().zip(&term.offset).enumerate().map(|(k, (t, o))| t + o + if k == e { d } else { 0.0 }).collect();
            cost.basis.image(&phases).unwrap()
        };
        let (up, down) = (image_at(h), image_at(-h));
        let (up, down) = (up.as_slice().unwrap(), down.as_slice().unwrap());
        let column = j.column(e);
        let scale = column.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "element {e} has no effect on the image");
        // Central differences err by h²/6·|∂³d| (about 2e-5 of the column here) and by the
        // single-precision basis (a few 1e-6 of the peak, divided by h): 1e-3 leaves room.
        for (row, &p) in term.mask.iter().enumerate() {
            let fd = (up[p] - down[p]) / (2.0 * h);
            assert!((column[row] - fd).abs() < 1e-3 * scale, "element {e} pixel {p}: {} vs {fd}", column[row]);
        }
    }
}

/// `E|Σ b·exp(i·delta)|²/|Σ b|²` for independent errors of variance `v`: the coherent part
/// `exp(-v)` plus the incoherent rest `Σ|b|²·(1 - exp(-v))/|Σ b|²`.
fn independent_focus(b: &[C64], v: f64) -> f64 {
    let sum = b.iter().sum::<C64>().norm_sqr();
    let power: f64 = b.iter().map(|x| x.norm_sqr()).sum();
    (-v).exp() + power * (1.0 - (-v).exp()) / sum
}

#[test]
fn expected_focus_matches_the_closed_form_and_monte_carlo() {
    let sim = common::small_array();
    let (_, images) = study(&sim);
    let model = build_element_model(&sim, &images, sim.mask_fraction, 0, Control::default()).unwrap();
    let b = focal_fields(&model.cost.basis);
    let g = b.len();

    // No information: the posterior is the prior, C = s²·I (exact up to rounding).
    let none = Array2::<f64>::zeros((g, g));
    for s in [0.3, 1.0] {
        let c = error_covariance(&none, &Spread::Independent(s)).unwrap();
        let e = expected_focus(&c, &b).unwrap();
        assert!((e - independent_focus(&b, s * s)).abs() < 1e-9, "s = {s}: {e} vs {}", independent_focus(&b, s * s));
    }

    // Correlated errors: a squared-exponential field (0.6 rad, 15 mm) plus 0.2 rad jitter,
    // against 20 000 seeded draws. The focus of a draw lies in [0, 1] with a spread near 0.15,
    // so the Monte Carlo mean is within about 0.001 (one standard error); 0.006 is six.
    let pos = sim.transducer.reference_points();
    let cov = Array2::from_shape_fn((g, g), |(m, n)| {
        let r2 = (pos[m][0] - pos[n][0]).powi(2) + (pos[m][1] - pos[n][1]).powi(2);
        0.36 * (-r2 / (2.0 * 15e-3_f64.powi(2))).exp() + if m == n { 0.04 } else { 0.0 }
    });
    let expected = expected_focus(&cov, &b).unwrap();
    let l = cholesky(&cov).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let norm = b.iter().sum::<C64>().norm_sqr();
    let draws = 20_000;
    let mut mean = 0.0;
    for _ in 0..draws {
        let z: Vec<f64> = (0..g).map(|_| StandardNormal.sample(&mut rng)).collect();
        let delta = l.dot(&ndarray::Array1::from(z));
        let f = b.iter().zip(delta.iter()).map(|(x, d)| x * C64::from_polar(1.0, *d)).sum::<C64>().norm_sqr() / norm;
        mean += f / draws as f64;
    }
    assert!((expected - mean).abs() < 6e-3, "closed form {expected:.4} vs Monte Carlo {mean:.4}");
}

#[test]
fn images_add_information_and_the_suggestion_is_the_best_candidate() {
    let sim = common::small_array();
    let (truth, images) = study(&sim);
    let model = build_element_model(&sim, &images[..1], sim.mask_fraction, 0, Control::default()).unwrap();
    let b = focal_fields(&model.cost.basis);
    let spread = Spread::Smooth(error_modes(&sim.transducer.reference_points(), 0.8, 15e-3).unwrap());
    let noise = 0.02;

    // The prior alone, one image, two images: each adds information, so the expected focus
    // of the correction rises.
    let g = sim.n_elements();
    let prior_only = expected_focus(&error_covariance(&Array2::zeros((g, g)), &spread).unwrap(), &b).unwrap();
    let one = expected_focus(&error_covariance(&fisher(&model.cost, &truth, noise).unwrap(), &spread).unwrap(), &b).unwrap();
    let both = build_element_model(&sim, &images, sim.mask_fraction, 0, Control::default()).unwrap();
    let two =
        expected_focus(&error_covariance(&fisher(&both.cost, &truth, noise).unwrap(), &spread).unwrap(), &focal_fields(&both.cost.basis))
            .unwrap();
    assert!(prior_only < one && one < two, "prior {prior_only:.3}, one image {one:.3}, two {two:.3}");

    let shifts: Vec<[f64; 3]> = CANDIDATE_SHIFTS_MM.iter().map(|s| s.map(|v| v * 1e-3)).collect();
    let s = suggest_focus_shift(&sim, &model.cost, &truth, noise, &spread, &shifts).unwrap();
    assert!((s.expected_focus_now - one).abs() < 1e-12);
    assert_eq!(s.candidates.len(), shifts.len());
    assert!(s.candidates.windows(2).all(|w| w[0].expected_focus >= w[1].expected_focus), "ranked best first");
    assert_eq!(s.shift, s.candidates[0].shift);
    assert!(s.expected_focus > s.expected_focus_now, "{} vs {}", s.expected_focus, s.expected_focus_now);
    assert_eq!(s.known, sim.focus_shift_phases(s.shift).unwrap());
    // The same ranking and values on one thread.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let single = pool.install(|| suggest_focus_shift(&sim, &model.cost, &truth, noise, &spread, &shifts).unwrap());
    assert_eq!(single, s, "one thread and the default pool differ");
    // Bad input: no candidates, non-positive noise.
    assert!(suggest_focus_shift(&sim, &model.cost, &truth, noise, &spread, &[]).is_err());
    assert!(suggest_focus_shift(&sim, &model.cost, &truth, 0.0, &spread, &shifts).is_err());
}
