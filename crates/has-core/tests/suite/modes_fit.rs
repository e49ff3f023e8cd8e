//! Several prior modes' coefficients fitted jointly to images (`inverse::prior::modes_fit`), on
//! images the model makes itself of known coefficients (the default scenario, three images in
//! focus and defocused by ±5 mm, 0.01 rad noise), and against the one-mode search
//! (`mode_fit`) it generalises. A Gaussian posterior holds the truth within three of its
//! standard deviations 99.7 % of the time; the prior pulls a coefficient with Fisher information
//! 1/std² towards zero by the factor 1/(1 + std²) at most, which the tolerance adds. (With all
//! coefficients zero the model is the ideal focus, where the images are stationary in the
//! phases: their first derivatives vanish, the Gaussian std understates the spread, and the cases
//! avoid it. A fit through a head starts from the aberrated focus of the reference steering.)

use has_core::inverse::cost::Measurement;
use has_core::inverse::prior::mode_fit::fit_mode;
use has_core::inverse::prior::modes_fit::{fit_modes, fit_modes_with_noise};
use has_core::physics::aberration::SkullScreen;
use has_core::Control;
use has_core::{Scenario, Simulation};
use std::sync::OnceLock;

fn sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

/// Skull-like patterns over the elements (independent seeds) with an RMS of `rms` rad each.
fn modes(rms: f64) -> Vec<Vec<f64>> {
    let s = sim();
    [7, 11, 13]
        .iter()
        .map(|&seed| {
            let p = SkullScreen::default().phases(&s.transducer.reference_points(), seed).unwrap();
            let mean = p.iter().sum::<f64>() / p.len() as f64;
            let r = (p.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / p.len() as f64).sqrt();
            p.iter().map(|v| rms * (v - mean) / r).collect()
        })
        .collect()
}

/// Three noisy images of the model with the modes at `c`, each with its known defocus.
fn images(modes: &[Vec<f64>], c: &[f64], seed: u64) -> Vec<Measurement> {
    let s = sim();
    [0.0, 5e-3, -5e-3]
        .iter()
        .enumerate()
        .map(|(k, &dz)| {
            let n = s.n_elements();
            let known = if dz == 0.0 { vec![0.0; n] } else { s.focus_shift_phases([0.0, 0.0, dz]).unwrap() };
            let added: Vec<f64> = (0..n).map(|e| known[e] + modes.iter().zip(c).map(|(g, c)| c * g[e]).sum::<f64>()).collect();
            Measurement { image: s.noisy_arfi_image(&added, 0.01, seed * 10 + k as u64).unwrap(), known }
        })
        .collect()
}

#[test]
fn the_joint_fit_finds_the_coefficients_the_images_were_made_with() {
    let g = modes(0.3);
    for (c, seed) in [(vec![0.8, -0.5, 0.3], 1), (vec![0.5, 0.4, -0.7], 2), (vec![-1.2, 0.6, 1.0], 3)] {
        let f = fit_modes(sim(), &g, &images(&g, &c, seed), &Control::default()).unwrap();
        let std = f.std();
        println!(
            "truth {c:?}: fitted {:?} +- {std:?}, misfit {:.3} (at zero {:.2}), {} iterations",
            f.coefficients, f.misfit, f.misfit_at_zero, f.iterations
        );
        for m in 0..3 {
            let pulled = c[m] / (1.0 + std[m] * std[m]);
            assert!((f.coefficients[m] - pulled).abs() < 3.0 * std[m] + 0.02, "mode {m}: truth {c:?}, {f:?}");
            assert!(std[m] < 0.3, "the images pin each coefficient: {f:?}");
        }
        assert!((f.misfit - 1.0).abs() < 0.2, "a perfect model fits to the noise: {f:?}");
        assert!((f.scale - 1.0).abs() < 0.05, "the model's own scale: {f:?}");
        assert!(f.converged, "{f:?}");
        assert!(f.supported && f.evidence > 100.0, "modes off by a standard deviation are seen: {f:?}");
    }
}

#[test]
fn images_of_the_prediction_as_it_is_do_not_support_moving_it() {
    // With every coefficient zero in the images, the fall of chi-squared the fit finds is what
    // three free coefficients find in noise: below the 95 % point of chi²(3), 7.8, in 95 % of
    // noise draws (this draw: 1.8).
    let g = modes(0.3);
    let f = fit_modes(sim(), &g, &images(&g, &[0.0; 3], 8), &Control::default()).unwrap();
    println!("at zero: evidence {:.2}, coefficients {:?}", f.evidence, f.coefficients);
    assert!(!f.supported && f.evidence >= 0.0, "{f:?}");
}

#[test]
fn one_mode_fitted_jointly_agrees_with_the_one_mode_search() {
    // The same posterior found two ways: the parabolic search over marched coefficients and
    // Gauss–Newton with the images' exact derivatives. Both stop when their step is a quarter of
    // the posterior's spread: they agree within half a standard deviation.
    let g = vec![modes(0.5).remove(0)];
    let meas = images(&g, &[0.7], 4);
    let (joint, one) =
        (fit_modes(sim(), &g, &meas, &Control::default()).unwrap(), fit_mode(sim(), &g[0], &meas, &Control::default()).unwrap());
    println!("joint {:.4} +- {:.4}, search {:.4} +- {:.4}", joint.coefficients[0], joint.std()[0], one.coefficient, one.std);
    assert!((joint.coefficients[0] - one.coefficient).abs() < 0.5 * one.std, "{joint:?} against {one:?}");
    assert!((joint.std()[0] / one.std - 1.0).abs() < 0.25, "{joint:?} against {one:?}");
}

#[test]
fn modes_of_the_wrong_length_or_not_finite_are_named() {
    let g = modes(0.3);
    let meas = images(&g, &[0.0; 3], 5);
    let e = fit_modes(sim(), &[vec![0.0; 3]], &meas, &Control::default()).unwrap_err().to_string();
    assert!(e.starts_with("modes") && e.contains("mode 0 has 3 values"), "{e}");
    let mut bad = g.clone();
    bad[1][4] = f64::NAN;
    assert!(fit_modes(sim(), &bad, &meas, &Control::default()).unwrap_err().to_string().starts_with("modes"));
    assert!(fit_modes(sim(), &[], &meas, &Control::default()).unwrap_err().to_string().starts_with("modes"));
    let cancel = std::sync::atomic::AtomicBool::new(true);
    assert!(matches!(fit_modes(sim(), &g, &meas, &Control::default().with_cancel(&cancel)).unwrap_err(), has_core::HasError::Interrupted));
}

/// The images' noise where it is known replaces the background floor: chi-squared at zero (which
/// the fit does not move) scales with the inverse square of the noise, and the fit reports the
/// noise it used. A noise that is not a positive number is refused naming `noise_rad`.
#[test]
fn a_known_noise_replaces_the_background_floor() {
    let g = modes(0.3);
    let meas = images(&g, &[0.5, 0.0, -0.3], 6);
    let floor = fit_modes(sim(), &g, &meas, &Control::default()).unwrap();
    let given = 1.5 * floor.noise;
    let known = fit_modes_with_noise(sim(), &g, &meas, Some(given), &Control::default()).unwrap();
    assert_eq!(known.noise, given);
    let expected = floor.misfit_at_zero * (floor.noise / given).powi(2);
    assert!((known.misfit_at_zero / expected - 1.0).abs() < 1e-9, "{} against {expected}", known.misfit_at_zero);
    for bad in [0.0, -0.01, f64::NAN] {
        let e = fit_modes_with_noise(sim(), &g, &meas, Some(bad), &Control::default()).unwrap_err().to_string();
        assert!(e.starts_with("noise_rad"), "{e}");
    }
}
