//! The pose modes against the obvious reference, the central secants of the responses projected
//! onto the moved arrays themselves (`moved_head_responses`), per mode:
//! `cargo run --release -p has-core --example pose_compare scenario.toml` (at the focus).

use has_core::prediction::pose::{moved_head_responses, Pose};
use has_core::prediction::{phase_change, pose_sensitivity};
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let scenario = Scenario::load(std::path::Path::new(&args[1]))?;
    let sim = Simulation::new(&scenario)?;
    let target = sim.focus;
    let t = Instant::now();
    let fast = pose_sensitivity(&sim, target)?;
    println!("fast modes {:.1} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let h = sim.element_responses(target)?;
    let g = &sim.grid;
    let reach =
        sim.transducer.reference_points().iter().map(|p| (0..3).map(|k| (p[k] - target[k]).powi(2)).sum::<f64>().sqrt()).sum::<f64>()
            / sim.transducer.elements.len() as f64;
    let turn = 0.5 * g.dx.min(g.dy).min(g.dz) / reach;
    let cells = [g.dx, g.dy, g.dz];
    let w: Vec<f64> = h.iter().map(|v| v.norm()).collect();
    let sw: f64 = w.iter().sum();
    let rms = |v: &[f64]| (v.iter().zip(&w).map(|(x, w)| w * x * x).sum::<f64>() / sw).sqrt();
    let corr = |a: &[f64], b: &[f64]| a.iter().zip(b).zip(&w).map(|((x, y), w)| w * x * y).sum::<f64>() / sw / (rms(a) * rms(b));
    for kind in 0..2 {
        for axis in 0..3 {
            let (pose, step): (Box<dyn Fn(f64) -> Pose>, f64) = if kind == 0 {
                (Box::new(move |d| Pose::shift(axis, d)), cells[axis])
            } else {
                (Box::new(move |a| Pose::turn(axis, a)), turn)
            };
            let up = phase_change(&moved_head_responses(&sim, target, &pose(step), None)?, &h)?;
            let down = phase_change(&moved_head_responses(&sim, target, &pose(-step), None)?, &h)?;
            let slow: Vec<f64> = up.iter().zip(&down).map(|(u, d)| (u - d) / (2.0 * step)).collect();
            let f = if kind == 0 { &fast.translation[axis] } else { &fast.rotation[axis] };
            let unit = if kind == 0 { 1e-3 } else { 1f64.to_radians() };
            let diff: Vec<f64> = f.iter().zip(&slow).map(|(a, b)| (a - b) * unit).collect();
            println!(
                "{} {}: slow RMS {:.4} rad per {}, fast {:.4}, correlation {:.4}, difference RMS {:.4}",
                if kind == 0 { "shift" } else { "turn" },
                ["x", "y", "z"][axis],
                rms(&slow) * unit,
                if kind == 0 { "mm" } else { "deg" },
                rms(f) * unit,
                corr(f, &slow),
                rms(&diff)
            );
        }
    }
    println!("slow modes {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
