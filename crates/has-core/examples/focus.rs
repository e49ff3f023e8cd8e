//! Simulates the default scenario (the paper's phantom experiment) without Python and prints the
//! focus: `cargo run --release -p has-core --example focus [scenario.toml]`.

use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let scenario = match std::env::args().nth(1) {
        Some(path) => Scenario::load(std::path::Path::new(&path))?,
        None => Scenario::default(),
    };
    let t = Instant::now();
    let sim = Simulation::new(&scenario)?;
    let g = &sim.grid;
    println!("{}: grid {} x {} x {} at {:.3} mm, plan built in {:.2} s", sim.name, g.nx, g.ny, g.nz, g.dx * 1e3, t.elapsed().as_secs_f64());
    let t = Instant::now();
    let field = sim.field(&[], None)?;
    let (n, peak) = field.axis_pressure.iter().enumerate().fold((0, 0.0), |a, (i, p)| if p.norm() > a.1 { (i, p.norm()) } else { a });
    println!(
        "axis peak {:.2} MPa at z = {:.2} mm (face pressure {:.3} MPa), field in {:.2} s",
        peak / 1e6,
        field.axis_z[n] * 1e3,
        field.surface_pressure / 1e6,
        t.elapsed().as_secs_f64()
    );
    let t = Instant::now();
    let image = sim.arfi_image(&[])?;
    let max = image.iter().copied().fold(f64::MIN, f64::max);
    println!("ideal MR-ARFI image {:?}, focal phase {:.3} rad, in {:.2} s", image.dim(), max, t.elapsed().as_secs_f64());
    Ok(())
}
