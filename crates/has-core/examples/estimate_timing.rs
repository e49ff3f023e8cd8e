//! Where the time of one hybrid estimation goes (the workload of the criterion benches, `benches/has.rs`): the default scenario, one
//! noisy (0.02 rad) MR-ARFI image with a skull-like aberration (`SkullScreen::default()`, seed
//! `--seed`, default 1) condensed to the 16 groups. Prints one JSON object:
//! `cargo run --release -p has-core --example estimate_timing [repeats] [seed]`.
//!
//! Splits `build_model` into the group source planes, the batched march of the 16 group fields
//! and the per-pixel kernels; times one cost and one cost + gradient (minimum over many calls);
//! runs Nelder–Mead and 20-start L-BFGS (evaluations, stop, seconds, evaluations per second) and
//! the ambiguity assessment that `arfi estimate` / `Simulation.estimate` add after the search.

use has_core::inverse::cost::{build_model, mask_pixels, ArfiKernel, Measurement};
use has_core::inverse::estimate::{condense, phase_error, point_reflection, Estimator};
use has_core::physics::aberration::SkullScreen;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;
use has_core::Control;
use std::time::Instant;

fn secs<T>(f: impl FnOnce() -> T) -> (f64, T) {
    let t = Instant::now();
    let out = f();
    (t.elapsed().as_secs_f64(), out)
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Minimum over `rounds` of the mean time of `calls` calls (s).
fn per_call(rounds: usize, calls: usize, mut f: impl FnMut()) -> f64 {
    (0..rounds)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..calls {
                f();
            }
            t.elapsed().as_secs_f64() / calls as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let repeats: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3).max(1);
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let (sim_s, sim) = secs(|| Simulation::new(&Scenario::default()));
    let sim = sim?;
    let positions = sim.transducer.reference_points();
    let truth = condense(&SkullScreen::default().phases(&positions, seed)?, &sim.groups)?;
    let meas = vec![Measurement { image: sim.noisy_arfi_image(&truth, 0.02, seed)?, known: vec![] }];

    // build_model as a whole, and its parts (box as build_model chooses it).
    let mut build = Vec::new();
    let mut model = None;
    for _ in 0..repeats {
        let (t, m) = secs(|| build_model(&sim, &meas, sim.mask_fraction, 3));
        build.push(t);
        model = Some(m?);
    }
    let model = model.expect("repeats >= 1");
    let k = &model.cost.terms[0].kernel;
    let (u, v) = (k.pixels[0].clone(), k.pixels[1].clone());
    let mask = mask_pixels(&meas[0].image, sim.mask_fraction, &sim.focal_region());
    let (mut sources_s, mut march_s, mut kernel_s) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..repeats {
        let (t, sources) = secs(|| sim.group_sources(&sim.groups, &[]));
        sources_s.push(t);
        let (t, recs) = secs(|| sim.record_window(&sources.expect("sources")));
        march_s.push(t);
        let recs = recs?;
        let (t, kern) = secs(|| -> Result<ArfiKernel, Box<dyn std::error::Error>> {
            let sampler = sim.sampler()?.restrict(u.clone(), v.clone())?;
            let window = &sim.sampler()?.window;
            let fields: Vec<Vec<C64>> = recs.iter().map(|r| window.extract(&r.window, &sampler.window)).collect();
            Ok(ArfiKernel::from_fields(&sampler, &fields, sim.amplitude()?, [u.clone(), v.clone()])?)
        });
        kernel_s.push(t);
        kern?;
    }

    // One cost evaluation (minimum over rounds of the mean of many calls).
    let x: Vec<f64> = (0..16).map(|g| 0.3 * (g as f64).sin()).collect();
    let cost_s = per_call(20, 2000, || {
        std::hint::black_box(model.cost.cost(std::hint::black_box(&x)));
    });
    let grad_s = per_call(20, 1000, || {
        std::hint::black_box(model.cost.cost_and_gradient(std::hint::black_box(&x)));
    });

    let sigma = point_reflection(&positions, &sim.groups);
    let mut nm_s = Vec::new();
    let mut lb_s = Vec::new();
    let mut assess_s = Vec::new();
    let (mut nm, mut lb) = (None, None);
    for _ in 0..repeats {
        let (t, e) = secs(|| Estimator::nelder_mead().run(&model.cost, Control::default()));
        nm_s.push(t);
        nm = Some(e?);
        let (t, e) = secs(|| Estimator::lbfgs().with_twins(sigma.clone()).run(&model.cost, Control::default()));
        lb_s.push(t);
        let e = e?;
        let (t, a) = secs(|| e.assess(&model, sigma.as_deref(), 0.9, seed));
        assess_s.push(t);
        a?;
        lb = Some(e);
    }
    let (nm, lb) = (nm.expect("nm"), lb.expect("lb"));
    let out = serde_json::json!({
        "seed": seed,
        "repeats": repeats,
        "threads": rayon::current_num_threads(),
        "simulation_new_s": sim_s,
        "mask_pixels": mask.len(),
        "cost_pixels": model.cost.n_pixels(),
        "kernel_box": [u.len(), v.len()],
        "build_model_s": median(&build),
        "build_model_all_s": build,
        "group_sources_s": median(&sources_s),
        "group_march_s": median(&march_s),
        "kernels_s": median(&kernel_s),
        "cost_us": cost_s * 1e6,
        "cost_and_gradient_us": grad_s * 1e6,
        "nelder_mead": {"s": median(&nm_s), "all_s": nm_s, "evaluations": nm.evaluations, "stop": nm.stop.name(), "cost": nm.cost,
                         "us_per_evaluation": median(&nm_s) / nm.evaluations as f64 * 1e6, "phase_error_rad": phase_error(&nm.phases, &truth)},
        "lbfgs": {"s": median(&lb_s), "all_s": lb_s, "evaluations": lb.evaluations, "stop": lb.stop.name(), "cost": lb.cost, "starts": lb.minima.len(),
                  "us_per_evaluation": median(&lb_s) / lb.evaluations as f64 * 1e6, "phase_error_rad": phase_error(&lb.phases, &truth)},
        "assess_s": median(&assess_s),
    });
    println!("{out}");
    Ok(())
}
