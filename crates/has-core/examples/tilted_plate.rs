//! The ITRUSST bowl through a 6.5 mm cortical plate turned 0-30° about y: the march on its
//! default grid (the plate read from a CT of 0.25 mm voxels) against the exact angular-spectrum
//! solution through the fluid plate, and the exact solid plate (shear 1500 m/s) beside it.
//!
//! `cargo run --release -p has-core --example tilted_plate [-- 10 20 step=0.25 shear=1500]`
//! (angles in degrees; `step=` the march's step in mm instead of the default grid's; `shear=` the
//! CT's bone as a solid of that shear speed, m/s, against the exact solid plate; `interfaces=`
//! and `screen=` as in a scenario's `[grid]`)

use has_core::reference::oblique::ObliqueBowl;
use has_core::validation::{compare, tilted_plate, tilted_plate_from, Exact};

fn main() -> has_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // The value of the argument `name=value`, if given.
    let arg = |name: &str| args.iter().find_map(|a| a.strip_prefix(name)?.strip_prefix('='));
    let step_mm: Option<f64> = arg("step").and_then(|v| v.parse().ok());
    let shear: Option<f64> = arg("shear").and_then(|v| v.parse().ok());
    let z1_mm: f64 = arg("z1").and_then(|v| v.parse().ok()).unwrap_or(30.0);
    let angles: Vec<f64> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let angles = if angles.is_empty() { vec![0.0, 10.0, 20.0, 30.0] } else { angles };
    let dir = std::env::temp_dir().join(format!("arfi-tilted-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| has_core::HasError::invalid("dir", e.to_string()))?;
    let kind = if shear.is_some() { "solid" } else { "fluid" };
    println!("tilt | march/exact {kind} | march focus - exact (x, z mm) | exact {kind} peak, (x, z) mm | axial profile, focal-plane correlation | exact solid (cs 1500) peak, (x, z) mm | s");
    for &t in &angles {
        let mut case = tilted_plate_from(&dir, t, shear, z1_mm * 1e-3)?;
        case.scenario.grid.step_mm = step_mm;
        case.scenario.grid.interfaces = arg("interfaces").map(String::from);
        case.scenario.grid.screen = arg("screen").map(String::from);
        let c = compare(&case)?;
        let solid = match tilted_plate(&dir, t, Some(1500.0))?.exact()? {
            Exact::Oblique(s) => s,
            _ => unreachable!("a tilted plate's exact solution is oblique"),
        };
        let (sp, sv) = ObliqueBowl::peak(&solid, [0.0, 0.0, 59e-3], 12e-3, 15e-3)?;
        println!(
            "{t:4.0}° | {} | {:.1} %, {:.4} | {sv:.3} at ({:+.2}, {:.2}) | {:.0}",
            c.against_exact(),
            100.0 * c.axial_error,
            c.correlation,
            sp[0] * 1e3,
            sp[2] * 1e3,
            c.seconds
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
