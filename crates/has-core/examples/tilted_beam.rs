//! A collimated beam (Gaussian, 6 mm waist, along z) through a 6.5 mm plate read from a CT of
//! 0.25 mm voxels and turned by each angle about y: the march's coherent transmission
//! `Σ p·conj(p_w) / Σ |p_w|²` on a plane beyond the plate (`p_w` the field without it) against the
//! exact plate's, `Σ |A(k)|²·t(ξ')·exp(-i·(K·n)·d) / Σ |A(k)|²` over the beam's angular spectrum
//! (`t` the plate's plane-wave transmission at each component's incidence `ξ'` on it,
//! `reference::elastic` or `reference::layered`). One angle of incidence at a time, where the
//! bowl's cases mix them all: what a wall's coefficients and the staircase of its treads do.
//!
//! `cargo run --release -p has-core --example tilted_beam [-- 10 20 30 shear=1500 hu=1500 step=0.5]`
//! (`shear=` the bone voxels' shear speed in m/s, 0 for fluid bone; `hu=` the plate's HU, 1500 by
//! default: porosity 0.25, 2475 m/s and 20 dB/cm at 500 kHz, lossy enough that the reverberation
//! inside the plate fades and each path through it shows; `step=` the march's step in mm.)

use has_core::nifti::Volume;
use has_core::physics::ct::{BoneShear, CtMedium, HuConversion};
use has_core::physics::grid::Grid;
use has_core::physics::material::Material;
use has_core::physics::medium::Medium;
use has_core::physics::propagation::{HasOptions, HasPlan, RecordSpec};
use has_core::reference::elastic::{plate_response, Solid};
use has_core::reference::layered::{transmission, Layer};
use has_core::reference::Fluid;
use has_core::Complex64 as C64;
use std::f64::consts::PI;
use std::sync::Arc;

const FREQUENCY: f64 = 500e3;
const THICKNESS: f64 = 6.5e-3;
const WAIST: f64 = 6e-3;
/// The plate's first face crosses the axis here (m).
const Z1: f64 = 20e-3;

fn main() -> has_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |name: &str| args.iter().find_map(|a| a.strip_prefix(name)?.strip_prefix('=')?.parse::<f64>().ok());
    let angles: Vec<f64> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let angles = if angles.is_empty() { vec![10.0, 20.0, 30.0] } else { angles };
    let (shear, hu, step) = (arg("shear").unwrap_or(1500.0), arg("hu").unwrap_or(1500.0), arg("step").unwrap_or(0.5) * 1e-3);
    let water = Material::new("water", 1500.0, 1000.0, 0.0)?;
    let dx = 0.5e-3;
    let g = Grid::new((64e-3 / dx) as usize, (24e-3 / dx) as usize, dx, dx, (55e-3 / step) as usize, step, 0.0)?;
    let source: Vec<C64> = (0..g.lateral_len())
        .map(|i| {
            let (x, y) = (g.x(i % g.nx), g.y(i / g.nx));
            C64::new((-(x * x + y * y) / (WAIST * WAIST)).exp(), 0.0)
        })
        .collect();
    let spec = RecordSpec { planes: vec![g.nz - 1], ..RecordSpec::default() };
    let free = Medium::homogeneous(water.clone());
    let march = |medium: &Medium| -> has_core::Result<Vec<C64>> {
        let (plan, _) = HasPlan::build(&g, medium, FREQUENCY, &source, &HasOptions::default(), &spec)?;
        Ok(plan.propagate(&source, &spec)?.planes.remove(0))
    };
    let without = march(&free)?;
    // The conversion's bone at `hu`, its shear wave as lossy as its compressional one.
    let mut conversion = HuConversion::named("aubry2003")?;
    conversion.soft_tissue = water.clone();
    let fluid = conversion.properties(hu, FREQUENCY).expect("bone HU");
    let db_cm_mhz = fluid.attenuation * 20.0 / 10f64.ln() / 100.0 / (FREQUENCY / 1e6);
    let dense = shear / solid_fraction(&conversion, hu);
    conversion.bone_shear = BoneShear { sound_speed: dense, attenuation_db_cm_mhz: db_cm_mhz };
    let bone = conversion.properties(hu, FREQUENCY).expect("bone HU");
    let kw = 2.0 * PI * FREQUENCY / 1500.0;
    let entry = Fluid { k: C64::new(kw, 0.0), density: 1000.0 };
    let plate = |xi: f64| -> has_core::Result<C64> {
        let kt = C64::new(xi, 0.0);
        Ok(if shear > 0.0 {
            let s =
                Solid::new(bone.sound_speed, bone.shear_sound_speed, bone.density, bone.attenuation, bone.shear_attenuation, FREQUENCY)?;
            plate_response(entry, s, THICKNESS, entry, kt).transmission
        } else {
            let layer = Layer {
                thickness: THICKNESS,
                fluid: Fluid { k: C64::new(2.0 * PI * FREQUENCY / bone.sound_speed, bone.attenuation), density: bone.density },
            };
            transmission(entry, &[layer], entry, kt)
        })
    };
    println!(
        "bone: {:.0} m/s, {:.0} kg/m^3, {:.0} Np/m; shear {:.0} m/s, {:.0} Np/m",
        bone.sound_speed, bone.density, bone.attenuation, bone.shear_sound_speed, bone.shear_attenuation
    );
    println!("tilt | exact |t|, arg | march |t|, arg | march/exact | phase off (rad) | carries shear");
    for &tilt in &angles {
        let t = tilt.to_radians();
        let n = [t.sin(), 0.0, t.cos()];
        let ct = CtMedium::new(plate_ct(hu, n), identity(), conversion.clone(), "tilted plate")?;
        let mut medium = free.clone();
        medium.ct = Some(Arc::new(ct));
        let (plan, _) = HasPlan::build(&g, &medium, FREQUENCY, &source, &HasOptions::default(), &spec)?;
        let through = plan.propagate(&source, &spec)?.planes.remove(0);
        let num: C64 = through.iter().zip(&without).map(|(a, b)| a * b.conj()).sum();
        let measured = num / without.iter().map(|b| b.norm_sqr()).sum::<f64>();
        // The exact plate, component by component of the beam's spectrum |A|² = exp(-kt²w²/2).
        let (mut sum, mut weight) = (C64::new(0.0, 0.0), 0.0);
        for i in 0..g.nx {
            for j in 0..g.ny {
                let (kx, ky) = (Grid::wavenumber(i, g.nx, g.dx), Grid::wavenumber(j, g.ny, g.dy));
                let kt2 = kx * kx + ky * ky;
                if kt2 >= kw * kw {
                    continue;
                }
                let a2 = (-kt2 * WAIST * WAIST / 2.0).exp();
                let along = kx * n[0] + ky * n[1] + (kw * kw - kt2).sqrt() * n[2];
                sum += a2 * plate((kw * kw - along * along).max(0.0).sqrt())? * C64::from_polar(1.0, -along * THICKNESS);
                weight += a2;
            }
        }
        let exact = sum / weight;
        println!(
            "{tilt:4.0}° | {:.4}, {:+.2} | {:.4}, {:+.2} | {:.3} | {:+.2} | {}",
            exact.norm(),
            exact.arg(),
            measured.norm(),
            measured.arg(),
            measured.norm() / exact.norm(),
            (measured / exact).arg(),
            plan.carries_shear()
        );
    }
    Ok(())
}

/// The share of the dense bone's shear speed a voxel of `hu` keeps under `conversion` (its solid
/// fraction, 1 - porosity).
fn solid_fraction(conversion: &HuConversion, hu: f64) -> f64 {
    let mut c = conversion.clone();
    c.bone_shear = BoneShear { sound_speed: 1000.0, attenuation_db_cm_mhz: 0.0 };
    c.properties(hu, FREQUENCY).map_or(1.0, |p| p.shear_sound_speed / 1000.0)
}

/// The plate `0 <= n·(r - (0, 0, Z1)) < THICKNESS` as a CT of 0.25 mm voxels (HU `hu`, water
/// -1000 elsewhere) over x ±24, y ±12, z 0-50 mm, its RAS x and y the frame's negated.
fn plate_ct(hu: f64, n: [f64; 3]) -> Volume {
    let (sp, [ni, nj, nk], [x0, y0]) = (0.25e-3, [192usize, 96, 200], [-24e-3, -12e-3]);
    let values = (0..ni * nj * nk)
        .map(|f| {
            let (x, z) = (x0 + (f % ni) as f64 * sp, (f / (ni * nj)) as f64 * sp);
            if (0.0..THICKNESS).contains(&(x * n[0] + (z - Z1) * n[2])) {
                hu as f32
            } else {
                -1000.0
            }
        })
        .collect();
    let mm = sp * 1e3;
    Volume { shape: [nk, nj, ni], values, affine: [[-mm, 0.0, 0.0, -x0 * 1e3], [0.0, -mm, 0.0, -y0 * 1e3], [0.0, 0.0, mm, 0.0]] }
}

fn identity() -> [[f64; 4]; 4] {
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
}
