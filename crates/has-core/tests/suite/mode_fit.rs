//! A prior mode's coefficient fitted to images (`inverse::prior::mode_fit`), on images the model makes
//! itself of a known coefficient (the default scenario, three images in focus and defocused by
//! ±5 mm, 0.01 rad noise): the fit must find the coefficient within three of its own posterior
//! standard deviations (a Gaussian posterior's 99.7 %), plus the prior's pull towards zero.

use has_core::inverse::cost::Measurement;
use has_core::inverse::prior::mode_fit::{fit_mode, ModeFit};
use has_core::physics::aberration::SkullScreen;
use has_core::Control;
use has_core::{Scenario, Simulation};
use std::sync::OnceLock;

fn sim() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| Simulation::new(&Scenario::default()).expect("default scenario"))
}

/// A skull-like pattern over the elements with an RMS of 0.5 rad: a coefficient of 1 costs the
/// focus about a fifth of its intensity.
fn mode() -> Vec<f64> {
    let s = sim();
    let p = SkullScreen::default().phases(&s.transducer.reference_points(), 7).unwrap();
    let mean = p.iter().sum::<f64>() / p.len() as f64;
    let rms = (p.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / p.len() as f64).sqrt();
    p.iter().map(|v| 0.5 * (v - mean) / rms).collect()
}

/// Three noisy images of the model with the mode at `c`, each with its known defocus.
fn images(c: f64, seed: u64) -> Vec<Measurement> {
    let s = sim();
    let m = mode();
    [0.0, 5e-3, -5e-3]
        .iter()
        .enumerate()
        .map(|(k, &dz)| {
            let known = if dz == 0.0 { vec![0.0; m.len()] } else { s.focus_shift_phases([0.0, 0.0, dz]).unwrap() };
            let added: Vec<f64> = known.iter().zip(&m).map(|(k, m)| k + c * m).collect();
            Measurement { image: s.noisy_arfi_image(&added, 0.01, seed * 10 + k as u64).unwrap(), known }
        })
        .collect()
}

fn fit(c: f64, seed: u64) -> ModeFit {
    fit_mode(sim(), &mode(), &images(c, seed), &Control::default()).unwrap()
}

#[test]
fn the_fit_finds_the_coefficient_the_images_were_made_with() {
    for (c, seed) in [(0.8, 1), (0.0, 2), (-0.6, 3)] {
        let f = fit(c, seed);
        // The prior c² pulls an estimate with Fisher information 1/std² towards zero by the
        // factor 1 / (1 + std²) at most.
        let pulled = c / (1.0 + f.std * f.std);
        assert!((f.coefficient - pulled).abs() < 3.0 * f.std, "c {c}: fitted {f:?}");
        assert!(f.std < 0.2, "the images pin the coefficient: {f:?}");
        assert!((f.misfit - 1.0).abs() < 0.2, "a perfect model fits to the noise: {f:?}");
        assert!((f.scale - 1.0).abs() < 0.05, "the model's own scale: {f:?}");
        assert!(f.bracketed, "{f:?}");
    }
}

#[test]
fn a_coefficient_beyond_the_start_is_reached() {
    let f = fit(2.2, 4);
    assert!((f.coefficient - 2.2 / (1.0 + f.std * f.std)).abs() < 3.0 * f.std, "{f:?}");
    assert!(f.tried.iter().any(|t| t[0] >= 3.0 - 1e-9), "searched out to 3: {:?}", f.tried);
    assert!(f.bracketed);
}

#[test]
fn a_coefficient_beyond_the_search_is_not_bracketed() {
    // At 4.5 the smallest J tried is at the search's end, 3: said so, with the prior's spread.
    let f = fit(4.5, 6);
    assert!(!f.bracketed && f.coefficient == 3.0 && f.std == 1.0, "{f:?}");
}

#[test]
fn a_fit_is_stopped_by_its_cancel_flag() {
    let cancel = std::sync::atomic::AtomicBool::new(true);
    let e = fit_mode(sim(), &mode(), &images(0.0, 7), &Control::default().with_cancel(&cancel)).unwrap_err();
    assert!(matches!(e, has_core::HasError::Interrupted), "{e}");
}

#[test]
fn a_mode_of_the_wrong_length_is_named() {
    let e = fit_mode(sim(), &[0.0; 3], &images(0.0, 5), &Control::default()).unwrap_err();
    assert!(e.to_string().contains("mode"), "{e}");
}
