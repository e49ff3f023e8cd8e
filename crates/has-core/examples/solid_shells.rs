//! The suite's caps of cortical bone (`shell` about the focus, `bm5` met at up to 16°) read from
//! CTs as solids, against the exact solid shell (P-SV conversion at both surfaces): the march
//! converts nothing at a CT's curved faces, so this measures what it leaves out there, beside the
//! exact fluid shell's focus.
//!
//! `cargo run --release -p has-core --example solid_shells [-- 1300 1500 1700 step=0.5]`
//! (shear speeds in m/s; `step=` the march's step in mm instead of the default grid's)

use has_core::validation::{compare, solid_shells, suite, Exact};

fn main() -> has_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let step_mm: Option<f64> = args.iter().find_map(|a| a.strip_prefix("step=")?.parse().ok());
    let speeds: Vec<f64> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let speeds = if speeds.is_empty() { vec![1500.0] } else { speeds };
    let dir = std::env::temp_dir().join(format!("arfi-solid-shells-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| has_core::HasError::invalid("dir", e.to_string()))?;
    // The exact fluid shells' focal peaks, for what shear changes.
    let fluid: Vec<(String, f64)> = suite(&dir)?
        .into_iter()
        .filter(|c| c.name == "shell" || c.name == "bm5")
        .map(|c| match c.exact() {
            Ok(Exact::Shell(s, _)) => Ok((c.name.clone(), peak(&s))),
            Ok(_) => unreachable!("a shell's exact solution is a shell's"),
            Err(e) => Err(e),
        })
        .collect::<has_core::Result<_>>()?;
    println!("case | march/exact solid | focus off (mm) | axial profile | focal-plane correlation | exact solid / exact fluid peak | s");
    for &cs in &speeds {
        for mut case in solid_shells(&dir, cs)? {
            case.scenario.grid.step_mm = step_mm;
            let c = compare(&case)?;
            let base = case.name.split('_').next().unwrap_or_default();
            let fluid_peak = fluid.iter().find(|(n, _)| n == base).map_or(f64::NAN, |f| f.1);
            println!(
                "{} | {:+.1} % | {:+.2} | {:.1} % | {:.4} | {:.3} / {:.3} | {:.0}",
                c.name,
                100.0 * c.focal_pressure_error(),
                c.focal_position_error() * 1e3,
                100.0 * c.axial_error,
                c.correlation,
                c.focal_pressure[1],
                fluid_peak,
                c.seconds
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// The largest `|p|/p0` on the axis within 10 mm of the bowl's focus (64 mm), 0.05 mm apart.
fn peak(s: &has_core::reference::shell::ShellBowl) -> f64 {
    (0..=400).filter_map(|i| s.pressure(0.0, 54e-3 + 0.05e-3 * i as f64).ok()).map(|p| p.norm()).fold(0.0, f64::max)
}
