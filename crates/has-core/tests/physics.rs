//! Physics checks of the HAS propagation against references that are not the code itself:
//! O'Neil's analytic bowl axis, a direct Rayleigh–Sommerfeld sum, energy conservation, plane-wave
//! absorption, Snell's-law refraction, and linearity in the source.
//!
//! Run with `cargo test --release -p has-core --test physics -- --nocapture` to see the measured
//! numbers. Each tolerance is stated next to its assertion with the reason for it.

use has_core::grid::Grid;
use has_core::has::{HasOptions, HasPlan, RecordSpec};
use has_core::medium::{Material, Medium, Region, Shape};
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::transducer::Surface;
use has_core::Complex64 as C64;
use std::f64::consts::PI;

const F: f64 = 550e3;
const C_WATER: f64 = 1500.0;
const RHO_WATER: f64 = 1000.0;

/// A scenario in lossless water only (a water-only medium needs an explicit ARFI amplitude: there
/// is no radiation force to calibrate it on). `transducer` and `grid` are TOML table bodies.
fn water_scenario(transducer: &str, grid: &str) -> Scenario {
    let text = format!(
        "name = \"water\"\nfrequency_hz = {F}\n\
         [transducer]\n{transducer}\n\
         [focus]\nposition_mm = [0.0, 0.0, 85.0]\n\
         [[material]]\nname = \"water\"\nsound_speed_m_s = {C_WATER}\ndensity_kg_m3 = {RHO_WATER}\nattenuation_db_cm_mhz = 0.0\n\
         [grid]\n{grid}\n\
         [arfi]\namplitude_rad_m3_per_n = 1.0\n"
    );
    Scenario::from_toml(&text, None).unwrap()
}

/// Sub-sample peak of equally spaced samples `y` by a parabola through the largest sample and its
/// neighbours: (fractional index, value).
fn parabolic_peak(y: &[f64]) -> (f64, f64) {
    let n = (0..y.len()).fold(0, |b, i| if y[i] > y[b] { i } else { b });
    if n == 0 || n + 1 == y.len() {
        return (n as f64, y[n]);
    }
    let (a, b, c) = (y[n - 1], y[n], y[n + 1]);
    let d = a - 2.0 * b + c;
    let off = if d < 0.0 { 0.5 * (a - c) / d } else { 0.0 };
    (n as f64 + off, b - 0.25 * (a - c) * off)
}

fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

// ---------------------------------------------------------------------------------------------
// 1. O'Neil's spherical bowl
// ---------------------------------------------------------------------------------------------

/// O'Neil (JASA 21, 1949) on-axis pressure of a spherical cap with uniform normal velocity, relative
/// to the face pressure rho·c·u0: `|p/p0| = |2/(1 - z/R) · sin(k/2·(sqrt((z-h)² + a²) - z))|`, z from
/// the apex, h the cap depth, a the aperture radius; `k·h` at z = R.
fn oneil(z: f64, k: f64, r: f64, a: f64) -> f64 {
    let h = r - (r * r - a * a).sqrt();
    if (z - r).abs() < 1e-9 * r {
        return k * h;
    }
    (2.0 / (1.0 - z / r) * (0.5 * k * (((z - h).powi(2) + a * a).sqrt() - z)).sin()).abs()
}

#[test]
fn bowl_axis_matches_oneil() {
    let (r, aperture) = (85e-3, 80e-3);
    let a = 0.5 * aperture;
    let k = 2.0 * PI * F / C_WATER;
    let scenario = water_scenario("kind = \"bowl\"\nradius_of_curvature_mm = 85.0\naperture_diameter_mm = 80.0", "");
    let t = std::time::Instant::now();
    let sim = Simulation::new(&scenario).unwrap();
    let built = t.elapsed().as_secs_f64();
    let field = sim.field(&[], None).unwrap();
    let g = &sim.grid;
    let p0 = field.surface_pressure;
    let has: Vec<f64> = field.axis_pressure.iter().map(|p| p.norm() / p0).collect();

    // Analytic peak by a fine scan (1 µm) around the centre of curvature.
    let (mut z_ref, mut p_ref) = (0.0, 0.0);
    let mut z = 0.6 * r;
    while z < 1.2 * r {
        let v = oneil(z, k, r, a);
        if v > p_ref {
            (z_ref, p_ref) = (z, v);
        }
        z += 1e-6;
    }
    let (n_peak, p_has) = parabolic_peak(&has);
    let z_has = g.z0 + n_peak * g.dz;
    let mut profile_err: f64 = 0.0;
    let mut z_worst = 0.0;
    for (n, v) in has.iter().enumerate() {
        let z = g.z(n);
        if (0.5 * r..=1.3 * r).contains(&z) {
            let e = (v - oneil(z, k, r, a)).abs() / p_ref;
            if e > profile_err {
                (profile_err, z_worst) = (e, z);
            }
        }
    }
    eprintln!(
        "[oneil] grid {}x{}x{} dx {:.3} mm z0 {:.2} mm (built in {built:.1} s); analytic peak |p/p0| {p_ref:.3} at {:.3} mm \
         (k·h = {:.3}); HAS peak {p_has:.3} at {:.3} mm: pressure error {:+.2} %, position error {:+.3} mm; \
         axis profile 0.5R–1.3R max error {:.2} % of peak (at {:.1} mm)",
        g.nx, g.ny, g.nz, g.dx * 1e3, g.z0 * 1e3,
        z_ref * 1e3, k * (r - (r * r - a * a).sqrt()), z_has * 1e3,
        100.0 * (p_has / p_ref - 1.0), (z_has - z_ref) * 1e3, 100.0 * profile_err, z_worst * 1e3
    );
    // Tolerances from the issue: 3 % on the focal pressure (quadrature of the Rayleigh projection
    // at λ/8 and the λ/4 sampling of the source plane), 0.5 mm on the focal position (a fraction of
    // the λ/4 step, after parabolic interpolation), 5 % of the peak along the axis.
    assert!((p_has / p_ref - 1.0).abs() < 0.03);
    assert!((z_has - z_ref).abs() < 0.5e-3);
    assert!(profile_err < 0.05);
}
