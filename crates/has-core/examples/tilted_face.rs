//! One face tilted against the march's planes, alone: water, then from the face on a medium of
//! sound speed `c` and density `rho` (a voxel map of 0.25 mm voxels, lossless), the face's normal
//! turned by `tilt` about y. Beams uniform in y (Gaussian, 8 mm waist) steered to each angle
//! cross it; printed: the march's forward power `∫|p|²/(2Z) dA` on the plane z = 48 mm (beyond the
//! face for the whole beam) over the source's, beside the face's exact transmission in the same
//! measure at the beam's central incidence `θ` (Snell's law across the face to `θ_b`):
//! `4·Z1·Z2/(Z1 + Z2)² · cos(steer)/cos(tilt + θ_b)`, `Z1 = ρ_w·c_w/cos θ`,
//! `Z2 = ρ·c/cos θ_b`.
//!
//! With the impedance matched (`rho=535.714` against `c=2800`: `ρ·c` of water) the face passes
//! everything at normal incidence: what the march adds or loses there is its step's, not a
//! coefficient's.
//!
//! `cargo run --release -p has-core --example tilted_face [-- 20 c=2800 rho=1850 steer=10,20,30]`
//! (the tilt in degrees; `steer=` the beams' angles to z, by default the tilt and ±10° about it;
//! `dx=` and `step=` the grid, mm; `interfaces=normal-incidence` the pointwise face.)

use has_core::physics::grid::Grid;
use has_core::physics::material::Material;
use has_core::physics::medium::{Medium, VoxelMap};
use has_core::physics::propagation::{HasOptions, HasPlan, InterfaceModel, RecordSpec, Screen};
use has_core::{Complex64 as C64, HasError};
use std::f64::consts::PI;

const FREQUENCY: f64 = 500e3;
/// The face crosses the axis here (m).
const Z1: f64 = 30e-3;
const WAIST: f64 = 8e-3;
const VOXEL: f64 = 0.25e-3;

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
    let (c, rho) = (num("c").unwrap_or(2800.0), num("rho").unwrap_or(1850.0));
    let dx = num("dx").unwrap_or(0.75) * 1e-3;
    let dz = num("step").unwrap_or(0.749) * 1e-3;
    let interfaces = match arg("interfaces") {
        Some(name) => InterfaceModel::parse(name).ok_or_else(|| HasError::invalid("interfaces", "angular or normal-incidence"))?,
        None => InterfaceModel::default(),
    };
    let tilt = tilt_deg.to_radians();

    // The medium beyond the face, voxel by voxel (4 rows over ±4 mm in y: the beam is uniform).
    let (nx_v, nz_v) = (320usize, 280usize);
    let origin = [-(nx_v as f64 - 1.0) * VOXEL / 2.0, -3e-3, 15e-3];
    let count = nx_v * 4 * nz_v;
    let (mut speed, mut density) = (vec![1500.0; count], vec![1000.0; count]);
    for k in 0..nz_v {
        for i in 0..nx_v {
            let (x, z) = (origin[0] + i as f64 * VOXEL, origin[2] + k as f64 * VOXEL);
            if tilt.sin() * x + tilt.cos() * (z - Z1) > 0.0 {
                for j in 0..4 {
                    speed[(k * 4 + j) * nx_v + i] = c;
                    density[(k * 4 + j) * nx_v + i] = rho;
                }
            }
        }
    }
    let voxels = VoxelMap {
        origin,
        spacing: [VOXEL, 2e-3, VOXEL],
        shape: [nz_v, 4, nx_v],
        sound_speed: speed,
        density,
        attenuation_db_cm_mhz: vec![0.0; count],
        attenuation_power: 1.0,
    };
    voxels.validate()?;
    let medium = Medium { voxels: Some(voxels), ..Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0)?) };

    let k = 2.0 * PI * FREQUENCY / 1500.0;
    let nx = (68e-3 / dx).round() as usize;
    let grid = Grid::new(nx, 4, dx, dx, (60e-3 / dz).round() as usize, dz, 0.0)?;
    let record = grid.plane_index(48e-3);
    println!(
        "face turned {tilt_deg}°, water into c {c} m/s, rho {rho} kg/m³ (lossless), dx {:.3} mm, step {:.3} mm, power at z {:.2} mm",
        dx * 1e3,
        dz * 1e3,
        grid.z(record) * 1e3
    );
    println!("steer | incidence | march's power / source's | exact | march/exact");
    for &steer_deg in &steers {
        let steer = steer_deg.to_radians();
        // Centred where it crosses the face 3.25 mm deep on the axis.
        let xs = -(Z1 + 3.25e-3) * steer.tan();
        let source: Vec<C64> = (0..grid.lateral_len())
            .map(|p| {
                let x = grid.x(p % nx) - xs;
                C64::new(-(x / WAIST).powi(2), k * steer.sin() * x).exp()
            })
            .collect();
        let toward = [xs + steer.sin(), 0.0, steer.cos()];
        let options = HasOptions { sponge_width: 0.0, screen: Screen::Oblique { toward }, interfaces, ..HasOptions::default() };
        let (plan, _) = HasPlan::build(&grid, &medium, FREQUENCY, &source, &options, &RecordSpec::default())?;
        let recorded = plan.propagate(&source, &RecordSpec { power: true, ..RecordSpec::default() })?;
        let power = recorded.power[record] / recorded.power[0];
        let incidence = steer - tilt;
        let sin_b = c / 1500.0 * incidence.sin();
        let exact = if sin_b.abs() < 1.0 {
            let (z1, z2) = (1000.0 * 1500.0 / incidence.cos(), rho * c / (1.0 - sin_b * sin_b).sqrt());
            4.0 * z1 * z2 / (z1 + z2).powi(2) * steer.cos() / (tilt + sin_b.asin()).cos()
        } else {
            0.0
        };
        println!("{steer_deg:+5.0}° | {:+4.0}° | {power:.3} | {exact:.3} | {:.3}", incidence.to_degrees(), power / exact);
    }
    Ok(())
}
