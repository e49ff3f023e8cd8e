//! The exact phase change of a head shifted along one axis, in fine steps:
//! `cargo run --release -p has-core --example pose_scan scenario.toml x_mm y_mm z_mm axis step_mm n`.

use has_core::phase::wrap;
use has_core::prediction::phase_change;
use has_core::prediction::pose::{moved_head_responses, Pose};
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;

/// Each element's phase change from `h` to `moved`, the common phase removed.
fn change(moved: &[C64], h: &[C64]) -> Vec<f64> {
    phase_change(moved, h).expect("responses of the same array")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let sim = Simulation::new(&Scenario::load(std::path::Path::new(&a[1]))?)?;
    let target: [f64; 3] = std::array::from_fn(|k| a[2 + k].parse::<f64>().unwrap() * 1e-3);
    let (axis, step, n): (usize, f64, i32) = (a[5].parse()?, a[6].parse::<f64>()? * 1e-3, a[7].parse()?);
    let h = sim.element_responses(target)?;
    let w: Vec<f64> = h.iter().map(|v| v.norm()).collect();
    let sw: f64 = w.iter().sum();
    let wrms = |v: &[f64]| (v.iter().zip(&w).map(|(x, w)| w * x * x).sum::<f64>() / sw).sqrt();
    let wdot = |a: &[f64], b: &[f64]| a.iter().zip(b).zip(&w).map(|((a, b), w)| w * a * b).sum::<f64>() / sw;
    let f: Vec<Vec<f64>> =
        (-n..=n).map(|k| change(&moved_head_responses(&sim, target, &Pose::shift(axis, k as f64 * step), None).unwrap(), &h)).collect();
    let at = |k: i32| &f[(k + n) as usize];
    println!("| q (mm) | RMS of change | corr(f(q), -f(-q)) | step RMS | second difference RMS |");
    for k in 1..=n {
        let d1: Vec<f64> = at(k).iter().zip(at(k - 1)).map(|(a, b)| wrap(a - b)).collect();
        let d2: Vec<f64> = at(k).iter().zip(at(k - 1)).zip(at(k - 2.min(k + n))).map(|((a, b), c)| wrap(a - 2.0 * b + c)).collect();
        let odd = -wdot(at(k), at(-k)) / (wrms(at(k)) * wrms(at(-k)));
        println!(
            "| {:+.2} | {:.4} / {:.4} | {odd:.3} | {:.4} | {:.4} |",
            k as f64 * step * 1e3,
            wrms(at(k)),
            wrms(at(-k)),
            wrms(&d1),
            wrms(&d2)
        );
    }
    // Per element: the least-squares line and parabola over the scan; how the parabola's part
    // (weighted) is spread over the elements.
    let qs: Vec<f64> = (-n..=n).map(|k| k as f64 * step * 1e3).collect();
    let (s2, s4) = (qs.iter().map(|q| q * q).sum::<f64>(), qs.iter().map(|q| q.powi(4)).sum::<f64>());
    let m = qs.len() as f64;
    let mut parts: Vec<(f64, f64, usize)> = (0..h.len())
        .map(|e| {
            let y: Vec<f64> = (-n..=n).map(|k| at(k)[e]).collect();
            let a = qs.iter().zip(&y).map(|(q, y)| q * y).sum::<f64>() / s2;
            // Even part: y = c + b q^2 least squares.
            let (sy, sq2y) = (y.iter().sum::<f64>(), qs.iter().zip(&y).map(|(q, y)| q * q * y).sum::<f64>());
            let b = (m * sq2y - s2 * sy) / (m * s4 - s2 * s2);
            (w[e] * (b * 4.0).powi(2), w[e] * (a * 2.0).powi(2), e)
        })
        .collect();
    let (tb, ta) = (parts.iter().map(|p| p.0).sum::<f64>(), parts.iter().map(|p| p.1).sum::<f64>());
    println!(
        "over +-{:.2} mm: weighted RMS of the line at 2 mm {:.4} rad, of the parabola at 2 mm {:.4} rad",
        n as f64 * step * 1e3,
        (ta / sw).sqrt(),
        (tb / sw).sqrt()
    );
    parts.sort_by(|x, y| y.0.total_cmp(&x.0));
    let mut acc = 0.0;
    for (i, p) in parts.iter().enumerate() {
        acc += p.0;
        if [4usize, 12, 25, 51, 127].contains(&i) {
            println!("  the {} elements with the most curvature hold {:.0} % of it", i + 1, 100.0 * acc / tb);
        }
    }
    let pts = sim.transducer.reference_points();
    for p in &parts[..6] {
        let r = pts[p.2];
        println!(
            "  element {} at ({:.0}, {:.0}, {:.0}) mm, |h| {:.2} of the mean: curvature part {:.3} rad at 2 mm, line {:.3}",
            p.2,
            r[0] * 1e3,
            r[1] * 1e3,
            r[2] * 1e3,
            w[p.2] / (sw / h.len() as f64),
            (p.0 / w[p.2]).sqrt(),
            (p.1 / w[p.2]).sqrt()
        );
    }
    Ok(())
}
