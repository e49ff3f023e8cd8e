//! A quick estimation study on the default scenario, without Python:
//! `cargo run --release -p has-core --example study [seed] [noise_rad]`.

use has_core::inverse::cost::{build_model, Measurement};
use has_core::inverse::estimate::{condense, phase_error, point_reflection, Estimator};
use has_core::physics::aberration::SkullScreen;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Control;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seed: u64 = std::env::args().nth(1).map_or(Ok(1), |s| s.parse())?;
    let noise: f64 = std::env::args().nth(2).map_or(Ok(0.0), |s| s.parse())?;
    let sim = Simulation::new(&Scenario::default())?;
    let positions = sim.transducer.reference_points();
    let truth = condense(&SkullScreen::default().phases(&positions, seed)?, &sim.groups)?;
    let ideal = sim.arfi_image(&[])?;
    let peak = |img: &ndarray::Array2<f64>| img.iter().copied().fold(f64::MIN, f64::max);
    let images: usize = std::env::args().nth(3).map_or(Ok(1), |s| s.parse())?;
    let mut rng_d = 1000 + seed;
    let mut measurements = vec![Measurement { image: sim.noisy_arfi_image(&truth, noise, seed)?, known: vec![] }];
    for k in 1..images {
        // Known random group phases (diversity), each image with its own noise.
        rng_d = rng_d.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let d = SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 1.5 }.phases(&vec![[0.0; 3]; sim.n_groups], rng_d)?;
        let total: Vec<f64> = truth.iter().zip(&d).map(|(t, x)| t + x).collect();
        measurements.push(Measurement { image: sim.noisy_arfi_image(&total, noise, seed * 100 + k as u64)?, known: d });
    }
    let aberrated = sim.arfi_image(&truth)?;
    let t = Instant::now();
    let model = build_model(&sim, &measurements, 0.05, 3)?;
    println!("model: {} pixels, noise {:.4} rad, {:.2} s", model.cost.n_pixels(), model.noise, t.elapsed().as_secs_f64());
    let sigma = point_reflection(&positions, &sim.groups);
    let which = std::env::args().nth(4).unwrap_or_else(|| "all".into());
    let all = [Estimator::nelder_mead(), Estimator::lbfgs().with_twins(sigma.clone()), Estimator::particle_swarm()];
    for est in all.into_iter().filter(|e| which == "all" || format!("{:?}", e.method).to_lowercase().starts_with(&which)) {
        let e = est.run(&model.cost, Control::default())?;
        let corrected: Vec<f64> = truth.iter().zip(&e.phases).map(|(t, p)| t - p).collect();
        let rec = peak(&sim.arfi_image(&corrected)?) / peak(&ideal);
        let a = e.assess(&model, sigma.as_deref(), 0.9, 0)?;
        println!(
            "{:?}: cost {:.3e} evals {} {:.3} s stop {} | aberrated {:.3} recovered {:.3} phase error {:.3} rad | ambiguous {} worst {:.3} candidates {}",
            est.method, e.cost, e.evaluations, e.seconds, e.stop.name(), peak(&aberrated) / peak(&ideal), rec, phase_error(&e.phases, &truth), a.ambiguous, a.worst_recovery, a.candidates.len()
        );
    }
    Ok(())
}
