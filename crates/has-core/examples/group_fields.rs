//! Times the 16 group fields of the default scenario in one batch (there is no Python binding for
//! the batch) and prints one JSON object; `benches/bench_core.py` runs it:
//! `cargo run --release -p has-core --example group_fields [repeats]`.
//!
//! Each group's source plane carries the steering phasors of that group's elements and zeros
//! elsewhere; the 16 planes are marched together to the end of the MR slab
//! (`Simulation::record_window`, one field per rayon task).

use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::time::Instant;

/// Peak resident set size of this process (bytes), from /proc (Linux); 0 elsewhere.
fn peak_rss() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok()))
        .map_or(0, |kb| kb * 1024)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let repeats: usize = std::env::args().nth(1).map(|s| s.parse()).transpose()?.unwrap_or(5).max(1);
    let t = Instant::now();
    let sim = Simulation::new(&Scenario::default())?;
    let build = t.elapsed().as_secs_f64();
    let mut sources_s = Vec::new();
    let mut batch_s = Vec::new();
    for _ in 0..repeats {
        let t = Instant::now();
        let sources = sim.group_sources(&sim.groups, &[])?;
        sources_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let recs = sim.record_window(&sources)?;
        batch_s.push(t.elapsed().as_secs_f64());
        assert_eq!(recs.len(), sim.n_groups);
    }
    let total: Vec<f64> = sources_s.iter().zip(&batch_s).map(|(a, b)| a + b).collect();
    let median = |v: &[f64]| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let list = |v: &[f64]| v.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>().join(", ");
    println!(
        "{{\"groups\": {}, \"threads\": {}, \"repeats\": {repeats}, \"build_s\": {build:.4}, \"sources_s\": [{}], \"batch_s\": [{}], \
         \"median_s\": {:.4}, \"min_s\": {:.4}, \"peak_rss_bytes\": {}}}",
        sim.n_groups,
        rayon::current_num_threads(),
        list(&sources_s),
        list(&batch_s),
        median(&total),
        total.iter().copied().fold(f64::INFINITY, f64::min),
        peak_rss()
    );
    Ok(())
}
