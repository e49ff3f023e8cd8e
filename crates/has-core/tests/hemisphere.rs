//! A hemispherical array against references that are not the code: the focal-plane field of the
//! whole projection-and-march path against a direct Rayleigh–Sommerfeld sum over the element
//! faces in water, with a quadrature of its own (polar rings on each disc, not the march's
//! square cells).

mod common;

use common::pearson;
use has_core::physics::transducer::Surface;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::time::Instant;

const F: f64 = 650e3;
const C_WATER: f64 = 1500.0;

fn hemisphere_in_water(focus_mm: [f64; 3]) -> Scenario {
    let text = format!(
        "frequency_hz = {F}\n\
         [transducer]\nkind = \"hemisphere\"\nradius_of_curvature_mm = 150.0\npolar_angle_max_deg = 60.0\nelements = 1024\n\
         [focus]\nposition_mm = [{}, {}, {}]\n\
         [[material]]\nname = \"water\"\nsound_speed_m_s = {C_WATER}\ndensity_kg_m3 = 1000.0\nattenuation_db_cm_mhz = 0.0\n\
         [arfi]\namplitude_rad_m3_per_n = 1.0\n",
        focus_mm[0], focus_mm[1], focus_mm[2]
    );
    Scenario::from_toml(&text, None).unwrap()
}

/// Polar-ring quadrature of a flat disc: `rings` rings of equal width, about one point per
/// `a / rings` along each ring, each point carrying its ring segment's exact area.
fn disc_points(center: [f64; 3], normal: [f64; 3], diameter: f64, rings: usize) -> Vec<([f64; 3], f64)> {
    let a = 0.5 * diameter;
    let helper = if normal[2].abs() < 0.9 { [0.0, 0.0, 1.0] } else { [1.0, 0.0, 0.0] };
    let cross = |p: [f64; 3], q: [f64; 3]| [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]];
    let u = cross(normal, helper);
    let lu = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = u.map(|v| v / lu);
    let v = cross(normal, u);
    let dr = a / rings as f64;
    let mut pts = Vec::new();
    for j in 0..rings {
        let r = (j as f64 + 0.5) * dr;
        let n = ((2.0 * PI * r / dr).ceil() as usize).max(1);
        let area = PI * (((j + 1) as f64 * dr).powi(2) - (j as f64 * dr).powi(2)) / n as f64;
        for m in 0..n {
            let phi = 2.0 * PI * (m as f64 + 0.5) / n as f64;
            let (s, c) = (r * phi.sin(), r * phi.cos());
            pts.push((std::array::from_fn(|k| center[k] + c * u[k] + s * v[k]), area));
        }
    }
    pts
}

/// The focal-plane pressure of the hemisphere steered to `focus_mm`, through `Simulation`, against
/// the direct sum `p(r) = -(i·k/2π)·p_face·Σ_e exp(i·φ_e) ∫ exp(i·k·R)/R dS` with the steering
/// phases of straight-line time of flight, `φ_e = k·(d_max - d_e)`, computed here.
fn compare(focus_mm: [f64; 3]) -> (f64, f64, f64) {
    let t = Instant::now();
    let sim = Simulation::new(&hemisphere_in_water(focus_mm)).unwrap();
    let field = sim.field(&[], None).unwrap();
    let built = t.elapsed().as_secs_f64();
    let focus = focus_mm.map(|v| v * 1e-3);
    let k = 2.0 * PI * F / C_WATER;
    let elements: Vec<Vec<([f64; 3], f64)>> = sim
        .transducer
        .elements
        .iter()
        .map(|e| match *e {
            // 12 rings on a 6.6 mm disc: 0.28 mm (λ/8) apart.
            Surface::Flat { center, normal, size, .. } => disc_points(center, normal, size, 12),
            Surface::Cap { .. } => unreachable!("a hemisphere is made of flat elements"),
        })
        .collect();
    let distance = |p: [f64; 3], q: [f64; 3]| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
    let d: Vec<f64> = sim.transducer.elements.iter().map(|e| distance(e.reference_point(), focus)).collect();
    let d_max = d.iter().copied().fold(0.0, f64::max);
    let drive: Vec<C64> = d.iter().map(|&de| C64::from_polar(1.0, k * (d_max - de))).collect();
    // Pixels within 6 mm (2.6 λ) of the focus: the main lobe and the first side lobes.
    let (nx, ny) = (field.x.len(), field.y.len());
    let pixels: Vec<(usize, usize)> = (0..ny)
        .flat_map(|j| (0..nx).map(move |i| (i, j)))
        .filter(|&(i, j)| (field.x[i] - focus[0]).hypot(field.y[j] - focus[1]) <= 6e-3)
        .collect();
    let reference: Vec<C64> = pixels
        .par_iter()
        .map(|&(i, j)| {
            let r = [field.x[i], field.y[j], field.z];
            let sum: C64 = elements
                .iter()
                .zip(&drive)
                .map(|(pts, a)| a * pts.iter().map(|&(q, area)| C64::from_polar(area / distance(r, q), k * distance(r, q))).sum::<C64>())
                .sum();
            C64::new(0.0, -k / (2.0 * PI)) * field.surface_pressure * sum
        })
        .collect();
    let has: Vec<C64> = pixels.iter().map(|&(i, j)| field.pressure[[j, i]]).collect();
    let (a, b): (Vec<f64>, Vec<f64>) = has.iter().zip(&reference).map(|(h, r)| (h.norm(), r.norm())).unzip();
    let peak = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let (correlation, peak_ratio) = (pearson(&a, &b), peak(&a) / peak(&b));
    eprintln!(
        "[hemisphere {focus_mm:?}] {} pixels: correlation {correlation:.4}, peak ratio {peak_ratio:.4}; Simulation::new + field {built:.1} s, \
         reference {:.1} s",
        pixels.len(),
        t.elapsed().as_secs_f64() - built
    );
    (correlation, peak_ratio, built)
}

/// 1024 elements of 6.6 mm on a 150 mm hemisphere out to 60°, 650 kHz, water: focal-plane
/// magnitude correlation ≥ 0.99 and peak within 3 % of the direct sum, at the centre of curvature
/// and steered 10 mm off it laterally and 10 mm along the axis. (The march itself is exact in
/// water; what is tested is the source plane: the projection of elements up to 60° off the axis,
/// its adaptive quadrature, and the lateral extent of the grid.)
#[test]
fn hemisphere_focal_plane_matches_a_direct_rayleigh_sommerfeld_sum() {
    for focus in [[0.0, 0.0, 150.0], [10.0, 0.0, 140.0]] {
        let (correlation, peak_ratio, _) = compare(focus);
        assert!(correlation >= 0.99, "focus {focus:?}: correlation {correlation:.4}");
        assert!((peak_ratio - 1.0).abs() <= 0.03, "focus {focus:?}: peak ratio {peak_ratio:.4}");
    }
}

/// Bad hemispheres are refused naming the key; tissue on a path before the source plane (where
/// the march cannot see it) is refused naming the region and the plane.
#[test]
fn bad_hemispheres_and_tissue_behind_the_source_plane_are_refused() {
    let hemisphere = |keys: &str| format!("[transducer]\nkind = \"hemisphere\"\n{keys}\n[focus]\nposition_mm = [0.0, 0.0, 150.0]\n");
    for (keys, named) in [
        ("polar_angle_max_deg = 95.0", "transducer.polar_angle_max_deg"),
        ("polar_angle_max_deg = 0.0", "transducer.polar_angle_max_deg"),
        ("aperture_diameter_mm = 100.0", "transducer.aperture_diameter_mm"),
        ("elements = 0", "transducer.elements"),
    ] {
        let err = Scenario::from_toml(&hemisphere(keys), None).and_then(|s| s.resolve()).unwrap_err().to_string();
        assert!(err.contains(named), "{keys}: {err}");
    }
    let base = hemisphere("");
    // A skull-like slab at 60-66 mm: the elements out to 60° put the source plane at 81 mm.
    let slab = format!(
        "frequency_hz = 220000.0\n{base}[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
         [[material]]\nname = \"bone\"\nsound_speed_m_s = 2800.0\ndensity_kg_m3 = 1900.0\nattenuation_db_cm_mhz = 10.0\n\
         [medium]\nbackground = \"water\"\n[[region]]\nmaterial = \"bone\"\nshape = \"slab\"\nz_min_mm = 60.0\nz_max_mm = 66.0\n"
    );
    let err = Simulation::new(&Scenario::from_toml(&slab, None).unwrap()).err().expect("refused").to_string();
    assert!(err.contains("region[0] (bone)") && err.contains("before the source plane"), "{err}");
    // Beyond the plane it is accepted (only the checks run here: the grid and the plane).
    let text = slab.replace("z_min_mm = 60.0\nz_max_mm = 66.0", "z_min_mm = 85.0\nz_max_mm = 91.0");
    let r = Scenario::from_toml(&text, None).unwrap().resolve().unwrap();
    let g = has_core::simulation::choose_grid(&r).unwrap();
    // R·(1 - cos 60°) = 75 mm, plus the rim discs' tilt (3.3 mm · sin 60°) and λ/2 (3.4 mm).
    assert!((g.z0 - 81.3e-3).abs() < 0.1e-3, "source plane at {} mm", g.z0 * 1e3);
    r.medium.check_before_source_plane(g.z0, &r.transducer.reference_points(), r.focus, 0.5e-3, r.frequency).unwrap();
}
