//! Beams uniform in y, each steered to its own angle, through the 6.5 mm cortical plate read from
//! a CT of 0.25 mm voxels and turned about y: the march (default grid, no absorbing layer, so
//! that both sides are periodic over the same window) against the exact beam
//! (`reference::beam::PlateBeam`: every plane wave of the beam through the plate at its own
//! incidence). One incidence on the plate at a time, normal incidence included, where the bowl's
//! cases mix them all: what the bowl's focal pressure averages over.
//!
//! `cargo run --release -p has-core --example tilted_beams [-- 20 shear=1300 steer=-20,0,20]`
//! (the plate's tilt in degrees; `steer=` the beams' angles to z, degrees, by default the tilt
//! and ±10° about it; `shear=` the bone as a solid of that shear speed, m/s; `w=` the waist, mm,
//! 8 by default; `dx=` and `step=` the grid, mm; `lossless=1` the bone without attenuation;
//! `thick=` the plate's thickness, mm: a plate deeper than the grid, `thick=40 lossless=1`, leaves
//! its first face alone, and the march's forward power beyond it is printed beside the face's
//! exact transmission at the beam's central incidence, `4·Z1·Z2/(Z1 + Z2)²` with `Z = ρ·c/cos θ`
//! on each side, in the same measure.)
//!
//! Printed per beam, on the plane z = 48 mm: the transmitted energy `Σ|p|²` of the march over the
//! exact one's, the largest error where the exact beam is above a tenth of its peak (of that
//! peak), the mean phase of the march against the exact beam (`arg Σ p·conj(p_exact)`) and the
//! centroids' x.
//!
//! The march's forward power through a plane is `∫ |p|²/(2Z) dA` (`RecordSpec::power`; inside a
//! reverberating layer its first pass).

use has_core::physics::grid::Grid;
use has_core::physics::propagation::{HasOptions, HasPlan, RecordSpec, Screen};
use has_core::reference::beam::PlateBeam;
use has_core::reference::elastic::Solid;
use has_core::reference::layered::Layer;
use has_core::reference::oblique::Plate;
use has_core::reference::Fluid;
use has_core::validation::tilted_slab_from;
use has_core::{Complex64 as C64, HasError};
use std::f64::consts::{LN_10, PI};

const FREQUENCY: f64 = 500e3;
const THICKNESS: f64 = 6.5e-3;
/// The plate's first face crosses the axis here (m).
const Z1: f64 = 30e-3;
/// The plane the beams are compared on (m).
const RECORD: f64 = 48e-3;

fn main() -> has_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // The value of the argument `name=value`, if given.
    let arg = |name: &str| args.iter().find_map(|a| a.strip_prefix(name)?.strip_prefix('='));
    let num = |name: &str| arg(name).and_then(|v| v.parse::<f64>().ok());
    let tilt_deg: f64 = args.iter().find_map(|a| a.parse().ok()).unwrap_or(20.0);
    let steers: Vec<f64> = match arg("steer") {
        Some(list) => list.split(',').filter_map(|v| v.parse().ok()).collect(),
        None => vec![tilt_deg - 10.0, tilt_deg, tilt_deg + 10.0],
    };
    let shear = num("shear").filter(|&cs| cs > 0.0);
    let waist = num("w").unwrap_or(8.0) * 1e-3;
    let dx = num("dx").unwrap_or(0.75) * 1e-3;
    let dz = num("step").unwrap_or(0.749) * 1e-3;
    let lossless = num("lossless").is_some_and(|v| v != 0.0);
    let thick = num("thick").map(|mm| mm * 1e-3);
    let thickness = thick.unwrap_or(THICKNESS);

    let dir = std::env::temp_dir().join(format!("arfi-tilted-beams-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| HasError::invalid("dir", e.to_string()))?;
    let mut case = tilted_slab_from(&dir, tilt_deg, shear, Z1, thickness)?;
    if lossless {
        let ct = case.scenario.ct.as_mut().expect("a tilted plate is read from a CT");
        ct.bone_attenuation_min_db_cm_mhz = Some(0.0);
        ct.bone_attenuation_max_db_cm_mhz = Some(0.0);
    }
    case.write_inputs()?;
    let medium = case.scenario.resolve()?.medium;

    let omega = 2.0 * PI * FREQUENCY;
    // 4 dB/cm at 500 kHz, as the CT's cortical bone.
    let np_m = if lossless { 0.0 } else { 4.0 * 100.0 * LN_10 / 20.0 };
    let water = Fluid { k: C64::new(omega / 1500.0, 0.0), density: 1000.0 };
    let plate = match shear {
        None => Plate::Fluid(vec![Layer { thickness, fluid: Fluid { k: C64::new(omega / 2800.0, np_m), density: 1850.0 } }]),
        Some(cs) => Plate::Solid(Solid::new(2800.0, cs, 1850.0, np_m, np_m, FREQUENCY)?, thickness),
    };
    let k = water.k.re;
    let nx = (68e-3 / dx).round() as usize;
    let grid = Grid::new(nx, 4, dx, dx, (60e-3 / dz).round() as usize, dz, 0.0)?;
    let record = grid.plane_index(RECORD);
    let z_record = grid.z(record);
    let kind = shear.map_or("fluid".to_string(), |cs| format!("solid, shear {cs:.0} m/s"));
    println!(
        "plate {thickness:.4} m turned {tilt_deg}° ({kind}{}), beams of waist {:.1} mm, dx {:.3} mm, step {:.3} mm, compared at z {:.2} mm",
        if lossless { ", lossless" } else { "" },
        waist * 1e3,
        dx * 1e3,
        dz * 1e3,
        z_record * 1e3
    );
    if thick.is_some() {
        println!("steer | incidence | march's forward power at z / source's | the same for the first face, exact (fluid, lossless)");
    } else {
        println!("steer | incidence | energy march/exact | max error/peak | mean phase rad | centroid x march, exact mm | march's power at z / source's");
    }
    for &steer_deg in &steers {
        let steer = steer_deg.to_radians();
        // Centred where it crosses the plate's middle on the axis.
        let xs = -(Z1 + 0.5 * THICKNESS) * steer.tan();
        let line: Vec<C64> = (0..nx)
            .map(|i| {
                let x = grid.x(i) - xs;
                C64::new(-(x / waist).powi(2), k * steer.sin() * x).exp()
            })
            .collect();
        let source: Vec<C64> = (0..grid.lateral_len()).map(|i| line[i % nx]).collect();
        let toward = [xs + steer.sin(), 0.0, steer.cos()];
        let options = HasOptions { sponge_width: 0.0, screen: Screen::Oblique { toward }, ..HasOptions::default() };
        let (plan, _) = HasPlan::build(&grid, &medium, FREQUENCY, &source, &options, &RecordSpec::default())?;
        let recorded = plan.propagate(&source, &RecordSpec { planes: vec![record], power: true, ..RecordSpec::default() })?;
        let power = recorded.power[record] / recorded.power[0];
        let incidence = (steer_deg - tilt_deg).to_radians();
        if thick.is_some() {
            // Snell's law across the face; none beyond the critical angle. The march's power
            // (`|p|²/(2Z)` through a plane of z) of a plane wave is its flux along its own
            // direction, so the face's flux transmission is divided by the ratio of the two
            // waves' cosines to z.
            let sin_b = 2800.0 / 1500.0 * incidence.sin();
            let flux = if sin_b.abs() < 1.0 {
                let (z1, z2) = (1000.0 * 1500.0 / incidence.cos(), 1850.0 * 2800.0 / (1.0 - sin_b * sin_b).sqrt());
                let transmitted = tilt_deg.to_radians() + sin_b.asin();
                4.0 * z1 * z2 / (z1 + z2).powi(2) * steer.cos() / transmitted.cos()
            } else {
                0.0
            };
            println!("{steer_deg:+5.0}° | {:+4.0}° | {power:.3} | {flux:.3}", incidence.to_degrees());
            continue;
        }
        let march = &recorded.planes[0][..nx];
        let beam = PlateBeam::new(&line, grid.x(0), dx, water, &plate, Z1, tilt_deg.to_radians())?;
        // Where the plane crosses the plate (its far edges at the larger tilts) holds no beam:
        // compared beyond the plate only.
        let beyond: Vec<usize> = (0..nx).filter(|&i| beam.pressure(grid.x(i), z_record).is_ok()).collect();
        let march: Vec<C64> = beyond.iter().map(|&i| march[i]).collect();
        let exact = beyond.iter().map(|&i| beam.pressure(grid.x(i), z_record)).collect::<has_core::Result<Vec<C64>>>()?;
        let xs_beyond: Vec<f64> = beyond.iter().map(|&i| grid.x(i)).collect();
        let peak = exact.iter().map(|p| p.norm()).fold(0.0, f64::max);
        let worst = (0..exact.len()).filter(|&i| exact[i].norm() > 0.1 * peak).map(|i| (march[i] - exact[i]).norm()).fold(0.0, f64::max);
        let energy = |v: &[C64]| v.iter().map(|p| p.norm_sqr()).sum::<f64>();
        let dot: C64 = march.iter().zip(&exact).map(|(a, b)| a * b.conj()).sum();
        let centroid = |v: &[C64]| v.iter().zip(&xs_beyond).map(|(p, x)| p.norm_sqr() * x).sum::<f64>() / energy(v);
        println!(
            "{steer_deg:+5.0}° | {:+4.0}° | {:.3} | {:.3} | {:+.2} | {:+.2}, {:+.2} | {power:.3}",
            steer_deg - tilt_deg,
            energy(&march) / energy(&exact),
            worst / peak,
            dot.arg(),
            centroid(&march) * 1e3,
            centroid(&exact) * 1e3
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}
