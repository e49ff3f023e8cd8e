//! The responses at a target near a grid plane, approached from either side:
//! `cargo run --release -p has-core --example plane_jump scenario.toml x_mm y_mm z_mm`.

use has_core::phase::wrap;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let sim = Simulation::new(&Scenario::load(std::path::Path::new(&args[1]))?)?;
    let target: [f64; 3] = std::array::from_fn(|k| args[2 + k].parse::<f64>().unwrap() * 1e-3);
    let g = &sim.grid;
    let t = (target[2] - g.z0) / g.dz;
    println!("target plane index {t:.6}");
    let plane = t.round();
    let on = [target[0], target[1], g.z0 + plane * g.dz];
    let h = sim.element_responses(on)?;
    let w: Vec<f64> = h.iter().map(|v| v.norm()).collect();
    let sw: f64 = w.iter().sum();
    for f in [-0.5, -0.1, -0.01, -1e-4, 1e-4, 0.01, 0.1, 0.5, 0.9, 0.99, 0.9999] {
        let p = [on[0], on[1], on[2] + f * g.dz];
        let hk = sim.element_responses(p)?;
        let c: Vec<C64> = hk.iter().zip(&h).map(|(m, h)| m * h.conj()).collect();
        let common = c.iter().sum::<C64>().arg();
        let d: Vec<f64> = c.iter().map(|c| wrap(c.arg() - common)).collect();
        let rms = (d.iter().zip(&w).map(|(d, w)| w * d * d).sum::<f64>() / sw).sqrt();
        let amp = hk.iter().map(|v| v.norm()).sum::<f64>() / sw;
        println!("plane {plane} + {f} cell: phase change RMS {rms:.4} rad, common {common:+.4}, amplitude ratio {amp:.4}");
    }
    // The same at the next plane from below, for comparison with on-plane.
    let next = [on[0], on[1], on[2] + g.dz];
    let hn = sim.element_responses(next)?;
    let c: Vec<C64> = hn.iter().zip(&h).map(|(m, h)| m * h.conj()).collect();
    let common = c.iter().sum::<C64>().arg();
    let rms = (c.iter().zip(&w).map(|(c, w)| w * wrap(c.arg() - common).powi(2)).sum::<f64>() / sw).sqrt();
    println!("plane {} (on it): phase change RMS {rms:.4} rad", plane + 1.0);
    Ok(())
}
