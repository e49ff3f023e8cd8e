//! What the pose modes' parts cost on a scenario: the plan, a transposed march, a projection, the
//! six moved fields' projection and the turns' rates:
//! `cargo run --release -p has-core --example pose_timing scenario.toml x_mm y_mm z_mm`.

use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let scenario = Scenario::load(std::path::Path::new(&args[1]))?;
    let target: [f64; 3] = std::array::from_fn(|k| args[2 + k].parse::<f64>().expect("x y z in mm") * 1e-3);
    let t = Instant::now();
    let sim = Simulation::new(&scenario)?;
    println!("plan built in {:.1} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    let (plane, weights) = sim.plan.point_weights(target).ok_or("the target lies outside the grid")?;
    let field = sim.plan.transposed(plane, &weights, sim.reflections)?;
    println!("one transposed march {:.1} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    sim.source.transposed(&field)?;
    println!("one projection {:.1} s", t.elapsed().as_secs_f64());
    let g = &sim.grid;
    let shifts = [[g.dx, 0.0, 0.0], [-g.dx, 0.0, 0.0], [0.0, g.dy, 0.0], [0.0, -g.dy, 0.0], [0.0, 0.0, g.dz], [0.0, 0.0, -g.dz]];
    let t = Instant::now();
    let moved: Vec<_> = shifts.iter().map(|&s| sim.source.moved_weights(&field, s)).collect::<Result<_, _>>()?;
    println!("six moved fields {:.2} s", t.elapsed().as_secs_f64());
    let t = Instant::now();
    sim.source.transposed_many(&moved)?;
    println!("their projection {:.1} s", t.elapsed().as_secs_f64());
    let turning = |axis: usize| {
        move |q: [f64; 3]| -> [f64; 3] {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut u = [0.0; 3];
            u[a] = q[b] - target[b];
            u[b] = -(q[a] - target[a]);
            u
        }
    };
    let (tx, ty, tz) = (turning(0), turning(1), turning(2));
    let t = Instant::now();
    sim.source.transposed_rates(&field, &[&tx, &ty, &tz])?;
    println!("the turns' rates {:.1} s", t.elapsed().as_secs_f64());
    Ok(())
}
