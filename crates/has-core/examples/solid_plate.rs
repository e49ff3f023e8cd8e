//! The ITRUSST bowl through the 6.5 mm cortical plate on the planes (BM3) as a solid: the march,
//! which carries the shear wave there, against the exact elastic solution.
//!
//! `cargo run --release -p has-core --example solid_plate [-- 0 1300 1500 step=0.25 radius=35]`
//! (shear speeds in m/s, 0 for the fluid plate; `step=` the march's step in mm instead of the
//! default grid's; `radius=` the plate a cylinder of that radius in mm about the axis, against the
//! exact solution of the unbounded plate)

use has_core::validation::{compare, solid_plate};

fn main() -> has_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let step_mm: Option<f64> = args.iter().find_map(|a| a.strip_prefix("step=")?.parse().ok());
    let speeds: Vec<f64> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let speeds = if speeds.is_empty() { vec![1500.0] } else { speeds };
    println!("shear m/s | march/exact | march focus - exact (x, z mm) | exact peak, (x, z) mm | march peak | s");
    for &cs in &speeds {
        // 0: the same plate as a fluid (the suite's `bm3`).
        let mut case = if cs > 0.0 { solid_plate(cs)? } else { has_core::validation::suite(&std::env::temp_dir())?.swap_remove(1) };
        case.scenario.grid.step_mm = step_mm;
        // `radius=` makes the plate a cylinder of that radius (mm) about the axis.
        if let Some(r) = args.iter().find_map(|a| a.strip_prefix("radius=")?.parse::<f64>().ok()) {
            for region in case.scenario.regions.iter_mut().flatten() {
                region.shape = "cylinder".into();
                region.radius_mm = Some(r);
            }
        }
        let c = compare(&case)?;
        println!("{cs:6.0} | {} | {:.3} | {:.1}", c.against_exact(), c.focal_pressure[0], c.seconds);
    }
    Ok(())
}
