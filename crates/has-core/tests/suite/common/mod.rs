//! Helpers shared by the test modules of the suite.

use has_core::inverse::element::basis_grid;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;

/// The default scenario with a 256-element array (8 x 8 per quadrant), to keep the marches of
/// per-element tests short.
pub fn small_array() -> Simulation {
    Simulation::new(&Scenario::from_toml("[transducer]\nelements_per_side = 8\n", None).unwrap()).unwrap()
}

/// The simulation an element basis of `sim` is marched on (`basis_grid`: a coarser grid through
/// soft tissue and water), whose images the basis reproduces to single precision.
pub fn basis_model(sim: &Simulation) -> Simulation {
    match basis_grid(sim).unwrap() {
        Some(g) => sim.on_grid(g).unwrap(),
        None => sim.clone(),
    }
}

/// Sub-sample peak of equally spaced samples by a parabola through the largest sample and its two
/// neighbours: (fractional index, value).
pub fn parabolic_peak(y: &[f64]) -> (f64, f64) {
    let samples: Vec<(f64, f64)> = y.iter().enumerate().map(|(i, &v)| (i as f64, v)).collect();
    has_core::numeric::parabolic_peak(&samples)
}

#[allow(unused_imports)] // (not every test file correlates)
pub use has_core::numeric::pearson;
