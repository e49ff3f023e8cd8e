//! How the exact phase change of a moved head grows with the pose, against the pose modes:
//! `cargo run --release -p has-core --example pose_linearity scenario.toml x_mm y_mm z_mm`.

use has_core::phase::wrap;
use has_core::prediction::pose::{moved_head_responses, Pose};
use has_core::prediction::{phase_change, pose_sensitivity};
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;
use std::time::Instant;

/// Each element's phase change from `h` to `moved`, the common phase removed.
fn change(moved: &[C64], h: &[C64]) -> Vec<f64> {
    phase_change(moved, h).expect("responses of the same array")
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let scenario = Scenario::load(std::path::Path::new(&args[1]))?;
    let target: [f64; 3] = std::array::from_fn(|k| args[2 + k].parse::<f64>().unwrap() * 1e-3);
    let t = Instant::now();
    let sim = Simulation::new(&scenario)?;
    let g = &sim.grid;
    println!(
        "grid {}x{}x{} dx {:.3} dy {:.3} dz {:.3} mm z0 {:.3} mm; target plane index {:.3}, x index {:.3}; built {:.1} s",
        g.nx,
        g.ny,
        g.nz,
        g.dx * 1e3,
        g.dy * 1e3,
        g.dz * 1e3,
        g.z0 * 1e3,
        (target[2] - g.z0) / g.dz,
        target[0] / g.dx,
        t.elapsed().as_secs_f64()
    );
    let h = sim.element_responses(target)?;
    let w: Vec<f64> = h.iter().map(|v| v.norm()).collect();
    let sw: f64 = w.iter().sum();
    let wrms = |v: &[f64]| (v.iter().zip(&w).map(|(x, w)| w * x * x).sum::<f64>() / sw).sqrt();
    let wdot = |a: &[f64], b: &[f64]| a.iter().zip(b).zip(&w).map(|((a, b), w)| w * a * b).sum::<f64>() / sw;
    // Continuity: the target alone moved in small steps (the array stays): the change from one
    // step to the next, and its second difference (a jump shows as a spike).
    let (plane, weights) = sim.plan.point_weights(target).unwrap();
    let field = sim.plan.transposed(plane, &weights, sim.reflections)?;
    for (name, axis, cell, array_only) in
        [("target z", 2, g.dz, false), ("target x", 0, g.dx, false), ("array -z", 2, g.dz, true), ("array -x", 0, g.dx, true)]
    {
        println!("{name}: steps of cell/8 = {:.4} mm", cell / 8.0 * 1e3);
        let mut prev: Option<Vec<C64>> = None;
        let mut prev_step: Option<Vec<f64>> = None;
        for k in -10..=10 {
            let mut p = target;
            p[axis] += k as f64 * cell / 8.0;
            let hk = if array_only {
                let mut back = [0.0; 3];
                back[axis] = -(k as f64) * cell / 8.0;
                let moved = sim.transducer.moved(&[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], target, back)?;
                sim.source.on_grid(&moved, g)?.transposed(&field)?
            } else {
                sim.element_responses(p)?
            };
            if let Some(pr) = &prev {
                let step = change(&hk, pr);
                let second = prev_step.as_ref().map(|s| step.iter().zip(s).map(|(a, b)| wrap(a - b)).collect::<Vec<_>>());
                println!(
                    "  k {k:+3} plane idx {:.3} x idx {:.3}: step RMS {:.4} rad, second difference RMS {}",
                    (p[2] - g.z0) / g.dz,
                    p[0] / g.dx,
                    wrms(&step),
                    second.map(|s| format!("{:.4}", wrms(&s))).unwrap_or_default()
                );
                prev_step = Some(step);
            }
            prev = Some(hk);
        }
    }
    let modes = pose_sensitivity(&sim, target)?;
    let mode_of = |kind: usize, axis: usize| if kind == 0 { &modes.translation[axis] } else { &modes.rotation[axis] };
    println!(
        "mode RMS (weighted): per mm x {:.4} y {:.4} z {:.4}; per deg about x {:.4} y {:.4} z {:.4}",
        wrms(&modes.translation[0]) * 1e-3,
        wrms(&modes.translation[1]) * 1e-3,
        wrms(&modes.translation[2]) * 1e-3,
        wrms(&modes.rotation[0]) * 1f64.to_radians(),
        wrms(&modes.rotation[1]) * 1f64.to_radians(),
        wrms(&modes.rotation[2]) * 1f64.to_radians()
    );
    // Independent reference: the CT registered moved by whole cells (its own plan), against
    // the shortcut, and the forward, backward and central secants over one cell.
    let text = std::fs::read_to_string(&args[1])?;
    let base = std::path::Path::new(&args[1]).parent();
    let as_read = "patient_to_transducer_mm = [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 170], [0, 0, 0, 1]]";
    println!("| shift | cells | moved CT RMS | shortcut RMS | correlation | RMS ratio |");
    let mut by_ct = std::collections::HashMap::new();
    for (axis, cell) in [(0usize, g.dx)] {
        for n in [-2i32, -1, 1, 2] {
            let mut t = [0.0; 3];
            t[axis] = n as f64 * cell * 1e3;
            let moved_text = text.replace(
                as_read,
                &format!(
                    "patient_to_transducer_mm = [[1, 0, 0, {}], [0, -1, 0, {}], [0, 0, -1, {}], [0, 0, 0, 1]]",
                    t[0],
                    t[1],
                    170.0 + t[2]
                ),
            );
            assert!(moved_text != text);
            let ct_sim = Simulation::new(&Scenario::from_toml(&moved_text, base)?)?;
            let reference = change(&ct_sim.element_responses(target)?, &h);
            let shortcut = change(&moved_head_responses(&sim, target, &Pose::shift(axis, n as f64 * cell), None)?, &h);
            println!(
                "| {} | {n:+} | {:.4} | {:.4} | {:.3} | {:.3} |",
                ["x", "y", "z"][axis],
                wrms(&reference),
                wrms(&shortcut),
                wdot(&reference, &shortcut) / (wrms(&reference) * wrms(&shortcut)),
                wrms(&shortcut) / wrms(&reference)
            );
            by_ct.insert((axis, n), reference);
        }
        let f = |n: i32| &by_ct[&(axis, n)];
        let central: Vec<f64> = f(1).iter().zip(f(-1)).map(|(a, b)| wrap(a - b) / 2.0).collect();
        let even: Vec<f64> = f(1).iter().zip(f(-1)).map(|(a, b)| (a + b) / 2.0).collect();
        let fwd = f(1);
        println!("  {}: over one cell (moved CT): forward secant RMS {:.4}, central {:.4}, even part (curvature x cell^2/2) {:.4}; corr(forward, central) {:.3}; corr(forward, -backward) {:.3}",
            ["x", "y", "z"][axis], wrms(fwd), wrms(&central), wrms(&even), wdot(fwd, &central) / (wrms(fwd) * wrms(&central)),
            -wdot(fwd, f(-1)) / (wrms(fwd) * wrms(f(-1))));
        let two: Vec<f64> = f(2).iter().zip(f(-2)).map(|(a, b)| wrap(a - b) / 4.0).collect();
        println!(
            "  central over two cells per cell RMS {:.4}, corr with central over one {:.3}",
            wrms(&two),
            wdot(&two, &central) / (wrms(&two) * wrms(&central))
        );
    }
    // Candidate linear modes from the shortcut: forward secant over a cell (the current mode),
    // central over a cell, least squares over +-1 and +-2 cells; their misfit over poses.
    println!("| axis | mode | RMS per mm | misfit RMS at q = -3, -2, -1, -0.5, +0.5, +1, +2, +3 mm | sum of squares |");
    for (kind, axis, cell, unit) in [(0, 0, g.dx, 1e-3), (0, 1, g.dy, 1e-3), (0, 2, g.dz, 1e-3), (1, 1, 0.0, 1f64.to_radians())] {
        let step = if kind == 0 { cell } else { 0.5 * g.dx / 0.15 };
        let pose = |q: f64| if kind == 0 { Pose::shift(axis, q) } else { Pose::turn(axis, q) };
        let at = |q: f64| -> Option<Vec<f64>> { moved_head_responses(&sim, target, &pose(q), None).ok().map(|m| change(&m, &h)) };
        let (Some(p1), Some(m1), Some(p2), Some(m2)) = (at(step), at(-step), at(2.0 * step), at(-2.0 * step)) else { continue };
        let central: Vec<f64> = p1.iter().zip(&m1).map(|(a, b)| wrap(a - b) / (2.0 * step)).collect();
        let forward: Vec<f64> = p1.iter().map(|a| a / step).collect();
        let lsq: Vec<f64> =
            (0..h.len()).map(|e| (wrap(p1[e] - m1[e]) * step + wrap(p2[e] - m2[e]) * 2.0 * step) / (10.0 * step * step)).collect();
        let qs = [-3.0, -2.0, -1.0, -0.5, 0.5, 1.0, 2.0, 3.0];
        let exact: Vec<Option<Vec<f64>>> = qs.iter().map(|q| at(q * unit)).collect();
        for (name, m) in [("forward", &forward), ("central", &central), ("lsq 2 cells", &lsq), ("none", &vec![0.0; h.len()])] {
            let mut ss = 0.0;
            let cols: Vec<String> = qs
                .iter()
                .zip(&exact)
                .map(|(q, ex)| match ex {
                    Some(ex) => {
                        let d: Vec<C64> = ex.iter().zip(m.iter()).map(|(a, g)| C64::from_polar(1.0, a - g * q * unit)).collect();
                        let dc = d.iter().zip(&w).map(|(d, w)| d * w).sum::<C64>().arg();
                        let mis: Vec<f64> = d.iter().map(|d| wrap(d.arg() - dc)).collect();
                        ss += wrms(&mis).powi(2);
                        format!("{:.3}", wrms(&mis))
                    }
                    None => "-".into(),
                })
                .collect();
            println!(
                "| {} {} | {name} | {:.4} | {} | {:.4} |",
                ["shift", "turn"][kind],
                ["x", "y", "z"][axis],
                wrms(m) * unit,
                cols.join(" "),
                ss
            );
        }
    }
    println!("| move | exact RMS (rad) | mode x pose RMS | misfit RMS | correlation | slope along mode / pose |");
    for (name, kind, axis, unit) in
        [("shift x mm", 0, 0, 1e-3), ("shift z mm", 0, 2, 1e-3), ("shift y mm", 0, 1, 1e-3), ("turn y deg", 1, 1, 1f64.to_radians())]
    {
        let m = mode_of(kind, axis);
        for q in [-2.0, -1.0, -0.5, 0.5, 1.0, 2.0] {
            let pose = if kind == 0 { Pose::shift(axis, q * unit) } else { Pose::turn(axis, q * unit) };
            let Ok(moved) = moved_head_responses(&sim, target, &pose, None) else {
                println!("| {name} {q:+} | refused |");
                continue;
            };
            let exact = change(&moved, &h);
            let lin: Vec<f64> = m.iter().map(|g| g * q * unit).collect();
            // Misfit: the circular difference, its weighted common phase removed.
            let d: Vec<C64> = exact.iter().zip(&lin).map(|(a, b)| C64::from_polar(1.0, a - b)).collect();
            let dc = d.iter().zip(&w).map(|(d, w)| d * w).sum::<C64>().arg();
            let mis: Vec<f64> = d.iter().map(|d| wrap(d.arg() - dc)).collect();
            let corr = wdot(&exact, &lin) / (wrms(&exact) * wrms(&lin));
            let slope = wdot(&exact, m) / wdot(m, m) / (q * unit);
            println!("| {name} {q:+} | {:.4} | {:.4} | {:.4} | {:.3} | {:.3} |", wrms(&exact), wrms(&lin), wrms(&mis), corr, slope);
        }
    }
    Ok(())
}
