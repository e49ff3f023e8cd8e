//! Per-element estimation on the default scenario, without Python:
//! `cargo run --release -p has-core --example element_basis [seed] [images]`.
//! Builds the element basis, checks it against the direct image, and estimates 1024 phases from
//! `images` noise-free images with known random steering-offset diversity.

use has_core::control::Control;
use has_core::inverse::cost::{build_model, Measurement, Objective};
use has_core::inverse::element::build_element_model;
use has_core::inverse::estimate::{condense, phase_error, Estimator};
use has_core::physics::aberration::SkullScreen;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seed: u64 = std::env::args().nth(1).map_or(Ok(1), |s| s.parse())?;
    let images: usize = std::env::args().nth(2).map_or(Ok(8), |s| s.parse())?;
    let per_side: usize = std::env::args().nth(3).map_or(Ok(16), |s| s.parse())?;
    let evals: usize = std::env::args().nth(4).map_or(Ok(500), |s| s.parse())?;
    let sc = Scenario::from_toml(&format!("[transducer]\nelements_per_side = {per_side}\n"), None)?;
    let sim = Simulation::new(&sc)?;
    let n = sim.n_elements();
    let positions = sim.transducer.reference_points();
    let truth = SkullScreen::default().phases(&positions, seed)?;
    let peak = |img: &ndarray::Array2<f64>| img.iter().copied().fold(f64::MIN, f64::max);
    let ideal = peak(&sim.arfi_image(&[])?);
    let mut measurements = vec![Measurement { image: sim.arfi_image(&truth)?, known: vec![] }];
    for k in 1..images {
        // Known diversity: random group phases.
        let dg = SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 1.5 }
            .phases(&vec![[0.0; 3]; sim.n_groups], 1000 + k as u64)?;
        let d = sim.element_phases(&dg)?;
        let total: Vec<f64> = truth.iter().zip(&d).map(|(t, x)| t + x).collect();
        measurements.push(Measurement { image: sim.arfi_image(&total)?, known: d });
    }
    let t = Instant::now();
    let report = |d: usize, n: usize| {
        if d % 256 == 0 {
            eprintln!("basis {d}/{n}")
        }
    };
    let model = build_element_model(&sim, &measurements, sim.mask_fraction, 0, Control::default().with_progress(&report))?;
    let b = &model.cost.basis;
    println!(
        "basis: {} samples x {} elements, {:.0} MB, {:.1} s",
        b.n_samples(),
        b.n_elements(),
        b.bytes() as f64 / 1e6,
        t.elapsed().as_secs_f64()
    );
    let full = sim.arfi_image(&truth)?;
    let img = b.image(&truth)?;
    let p = &b.sampler.pixels;
    let sub = full.slice(ndarray::s![p[0].clone(), p[1].clone()]);
    let err = (&img - &sub).iter().map(|x| x.abs()).fold(0.0, f64::max) / peak(&full);
    println!("basis image vs direct: max rel err {err:.2e}");
    let t = Instant::now();
    let (c0, g0) = model.cost.cost_and_gradient(&vec![0.0; n]);
    println!("cost+grad {} images: {:.3} s, cost {c0:.4e}", images, t.elapsed().as_secs_f64());
    let mut x = vec![0.0; n];
    for e in [3usize, n / 2, n - 5] {
        let h = 1e-2;
        x[e] = h;
        let cp = model.cost.cost(&x);
        x[e] = -h;
        let cm = model.cost.cost(&x);
        x[e] = 0.0;
        println!("grad[{e}] analytic {:.5e} numeric {:.5e}", g0[e], (cp - cm) / (2.0 * h));
    }
    // 16-group warm start then per-element L-BFGS.
    let gm = build_model(&sim, &measurements, sim.mask_fraction, 3)?;
    let ge = Estimator::lbfgs().run(&gm.cost, Control::default())?;
    let start = sim.element_phases(&ge.phases)?;
    let aberr = peak(&sim.arfi_image(&truth)?) / ideal;
    let corr = |est: &[f64]| -> Result<f64, Box<dyn std::error::Error>> {
        let c: Vec<f64> = truth.iter().zip(est).map(|(t, e)| t - e).collect();
        Ok(peak(&sim.arfi_image(&c)?) / ideal)
    };
    let circ = sim.element_phases(&condense(&truth, &sim.groups)?)?;
    println!("aberrated {aberr:.3}; ideal 16-group {:.3}; 16-group estimate {:.3}", corr(&circ)?, corr(&start)?);
    let t = Instant::now();
    let e = Estimator::lbfgs().with_starts(1)?.with_max_evaluations(evals)?.with_start(start)?.run(&model.cost, Control::default())?;
    println!(
        "element L-BFGS: cost {:.3e} evals {} {:.1} s stop {} | recovered {:.3} phase error {:.3} rad",
        e.cost,
        e.evaluations,
        t.elapsed().as_secs_f64(),
        e.stop.name(),
        corr(&e.phases)?,
        phase_error(&e.phases, &truth)
    );
    Ok(())
}
