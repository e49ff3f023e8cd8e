//! Where a CT prediction's time goes, stage by stage, through the public API:
//! `cargo run --release -p has-core --example predict_timing -- head.toml [targets]`
//! (e.g. the scenario of `arfi phantom --array hemisphere`). Prints the scenario's resolution
//! (the CT read and converted), the skull's simulation (resolution again, source model, steering
//! and the plan), one transposed march with its projection, and the whole prediction at the
//! focus, then at `targets` points (default 3) from one plan of each head.

use has_core::control::Control;
use has_core::prediction::{predict_scenario, predict_targets_with, with_amplitude, PredictionOptions};
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: predict_timing SCENARIO.toml [targets]")?;
    let n: usize = std::env::args().nth(2).map(|s| s.parse()).transpose()?.unwrap_or(3);
    let scenario = with_amplitude(Scenario::load(std::path::Path::new(&path))?);
    let t = Instant::now();
    let resolved = scenario.resolve()?;
    println!("resolve (CT read and converted): {:.1} s", t.elapsed().as_secs_f64());
    drop(resolved);
    let t = Instant::now();
    let sim = Simulation::new(&scenario)?;
    let g = &sim.grid;
    println!(
        "skull's simulation (resolve, source, steering, plan): {:.1} s; grid {} x {} x {}",
        t.elapsed().as_secs_f64(),
        g.nx,
        g.ny,
        g.nz
    );
    let focus = sim.focus;
    let t = Instant::now();
    let h = sim.element_responses(focus)?;
    println!("one transposed march and projection ({} elements): {:.1} s", h.len(), t.elapsed().as_secs_f64());
    drop(sim);
    has_core::memory::release_freed();
    let t = Instant::now();
    predict_scenario(&scenario, None)?;
    println!("prediction at the focus: {:.1} s", t.elapsed().as_secs_f64());
    let targets: Vec<[f64; 3]> = (0..n).map(|k| [focus[0] + 5e-3 * k as f64, focus[1], focus[2]]).collect();
    let t = Instant::now();
    predict_targets_with(&scenario, &targets, PredictionOptions::default(), Control::default())?;
    println!("prediction at {n} targets: {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
