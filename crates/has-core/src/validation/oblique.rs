//! A case whose exact field is not axisymmetric (a plate tilted against the axis): the focal
//! peak found in 3-D on both sides, the profile along z through the exact peak and the plane of
//! the grid nearest it.

use super::{Case, Comparison, WINDOW};
use crate::error::{HasError, Result};
use crate::numeric::{parabola, pearson};
use crate::reference::oblique::ObliqueBowl;
use crate::simulation::window_of_box;
use crate::simulation::Simulation;

/// Half-widths of the box searched for the focal peak, across and along z, m: a plate tilted by
/// up to 30° moves it a few mm aside and 10-15 mm short.
const SEARCH: [f64; 2] = [12e-3, 15e-3];

/// The focal peak of `sim`'s beam and of `exact`, compared as [`super::compare`] compares an
/// axisymmetric case.
pub(super) fn compare_oblique(case: &Case, sim: &Simulation, exact: &ObliqueBowl) -> Result<Comparison> {
    let t = std::time::Instant::now();
    let p0 = sim.source.face_pressure;
    let nominal = sim.focus;
    let (e_point, p_exact) = exact.peak([0.0, 0.0, nominal[2] - 5e-3], SEARCH[0], SEARCH[1])?;
    let (g, lo, hi) = (&sim.grid, [-SEARCH[0], -SEARCH[0], e_point[2] - SEARCH[1]], [SEARCH[0], SEARCH[0], e_point[2] + SEARCH[1]]);
    let window = window_of_box(g, lo, hi)?;
    let volume = sim.pressure_volume(&[], Some(window.clone()))?;
    let (nx, ny) = (window.cols.len(), window.rows.len());
    let at = |n: usize, j: usize, i: usize| f64::from(volume.pressure[(n * ny + j) * nx + i]) / p0;
    // The peak beyond the plate, where the exact field is given (inside bone the standing wave
    // can be higher).
    let beyond = |v: usize| {
        let (n, j, i) = (v / (nx * ny), (v / nx) % ny, v % nx);
        exact.covers([g.x(window.cols.start + i), g.y(window.rows.start + j), g.z(window.planes.start + n)])
    };
    let best = (0..volume.pressure.len())
        .filter(|&v| beyond(v))
        .max_by(|&a, &b| volume.pressure[a].total_cmp(&volume.pressure[b]))
        .ok_or_else(|| HasError::invalid("window", "holds no sample beyond the plate"))?;
    let (n, j, i) = (best / (nx * ny), (best / nx) % ny, best % nx);
    // A parabola through the neighbours on each axis (in the box's interior), in cells.
    let offset = |lo: usize, mid: usize, len: usize, f: &dyn Fn(usize) -> f64| {
        if mid > lo && mid + 1 < lo + len {
            match parabola([(-1.0, f(mid - 1)), (0.0, f(mid)), (1.0, f(mid + 1))]) {
                Some(p) if p.curvature < 0.0 => p.vertex.clamp(-1.0, 1.0),
                _ => 0.0,
            }
        } else {
            0.0
        }
    };
    let (ox, oy, oz) =
        (offset(0, i, nx, &|i| at(n, j, i)), offset(0, j, ny, &|j| at(n, j, i)), offset(0, n, window.planes.len(), &|n| at(n, j, i)));
    let (gi, gj, gn) = (window.cols.start + i, window.rows.start + j, window.planes.start + n);
    let s_point = [g.x(gi) + ox * g.dx, g.y(gj) + oy * g.dy, g.z(gn) + oz * g.dz];
    let p_sim = at(n, j, i);
    // The profile along z through the exact peak's column, and the plane nearest the exact peak.
    let col = (0..nx)
        .min_by(|&a, &b| (g.x(window.cols.start + a) - e_point[0]).abs().total_cmp(&(g.x(window.cols.start + b) - e_point[0]).abs()))
        .unwrap_or(0);
    let row = (0..ny).min_by(|&a, &b| g.y(window.rows.start + a).abs().total_cmp(&g.y(window.rows.start + b).abs())).unwrap_or(0);
    let mut axis = Vec::new();
    let mut axial_error: f64 = 0.0;
    for n in 0..window.planes.len() {
        let z = g.z(window.planes.start + n);
        let (x, y) = (g.x(window.cols.start + col), g.y(window.rows.start + row));
        let Ok(e) = exact.pressure([x, y, z]).map(|v| v.norm()) else { continue };
        let s = at(n, row, col);
        if (z - e_point[2]).abs() <= WINDOW {
            axial_error = axial_error.max((s - e).abs() / p_exact);
        }
        axis.push([z, s, e]);
    }
    let plane = (0..window.planes.len())
        .min_by(|&a, &b| (g.z(window.planes.start + a) - e_point[2]).abs().total_cmp(&(g.z(window.planes.start + b) - e_point[2]).abs()))
        .ok_or_else(|| HasError::invalid("window", "holds no plane"))?;
    let z = g.z(window.planes.start + plane);
    let (mut a, mut b, mut line) = (Vec::new(), Vec::new(), Vec::new());
    for jj in 0..ny {
        for ii in 0..nx {
            let (x, y) = (g.x(window.cols.start + ii), g.y(window.rows.start + jj));
            if (x - e_point[0]).hypot(y) <= WINDOW {
                let (s, e) = (at(plane, jj, ii), exact.pressure([x, y, z])?.norm());
                a.push(s);
                b.push(e);
                if jj == row {
                    line.push([x, s, e]);
                }
            }
        }
    }
    Ok(Comparison {
        name: case.name.clone(),
        description: case.description.clone(),
        focal_pressure: [p_sim, p_exact],
        focal_z: [s_point[2], e_point[2]],
        focal_point: [s_point, e_point],
        axial_error,
        correlation: pearson(&a, &b),
        axis,
        focal_line: line,
        step: g.dz,
        spacing: g.dx,
        seconds: t.elapsed().as_secs_f64(),
        tolerances: case.tolerances,
    })
}
