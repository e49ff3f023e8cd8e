//! The validation suite: the propagation on the grid a scenario chooses by default, against the
//! exact solutions of [`crate::reference`], case by case (the ITRUSST benchmark's source SC1 in
//! water, through a cortical plate, the flat layered skull, and spherical shells of cortical bone
//! read from a CT).
//!
//! Each case compares, on the beam axis and in the focal plane, `|p|/p0` of the simulation
//! (`p0` the element face pressure) with the exact `|p|/p0`: the focal peak (located between
//! planes by a parabola), its position, the axial profile from 10 mm before to 10 mm after the
//! exact focus, and the correlation of the focal plane's `|p|` within 10 mm of the axis.

mod cases;
mod oblique;

pub use cases::{
    lossy_shells, solid_plate, solid_shells, suite, thin_shells, tilted_plate, tilted_plate_from, tilted_plates, tilted_slab_from, Case,
    Exact, SOLID_TILT_SHEAR,
};

use crate::error::Result;
use crate::numeric::{parabolic_peak, pearson};
use crate::simulation::Simulation;

/// How close the simulation must come (the targets of a planning tool: half the spread of the
/// eleven codes of the ITRUSST benchmark, Aubry et al., JASA 152(2), 2022: 10 % and 1 mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Relative error of the focal peak pressure.
    pub focal_pressure: f64,
    /// Error of the focal peak's position along the axis, m.
    pub focal_position: f64,
    /// Largest error along the axis from 10 mm before to 10 mm after the focus, relative to the
    /// exact focal peak.
    pub axial_profile: f64,
    /// Smallest Pearson correlation of `|p|` in the focal plane within 10 mm of the axis.
    pub focal_plane_correlation: f64,
}

impl Tolerances {
    /// A plate read from a CT and tilted against the march's planes: the march's measured
    /// accuracy there (tilted 10-30°, -2.3 to +4.3 % focal pressure, the focus up to 0.9 mm off,
    /// 7.7 % axial profile, correlation 0.986 on the default grid; -11 to +6 % for steps of
    /// 0.25-0.9 mm), rounded up so that the install check holds what is known and fails on what
    /// is worse. Not a planning tool's target: read in-situ pressures through bone met obliquely
    /// as uncertain by that much.
    pub const OBLIQUE: Tolerances =
        Tolerances { focal_pressure: 0.15, focal_position: 3e-3, axial_profile: 0.30, focal_plane_correlation: 0.95 };

    /// The same plate as a solid, tilted (untilted, its faces convert on the planes and it is
    /// held to the suite's tolerances), against the exact elastic plate: the
    /// focal pressure held to the ITRUSST spread, the rest to the march's measured accuracy at the
    /// suite's shear speed, 1500 m/s, at 10-30° rounded up (focal pressure within 4.7 %, focus up
    /// to 1.93 mm off, axial profile up to 14.4 %, focal-plane correlation down to 0.905: each
    /// tread's SV wave is born a step after its neighbour's, see `docs/validation.md`). At 1700
    /// m/s the plates meet it; at 1300 m/s, 20-30°, they do not (-23 and -31 %).
    pub const OBLIQUE_SOLID: Tolerances =
        Tolerances { focal_pressure: 0.10, focal_position: 2.5e-3, axial_profile: 0.20, focal_plane_correlation: 0.85 };
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances { focal_pressure: 0.05, focal_position: 0.5e-3, axial_profile: 0.05, focal_plane_correlation: 0.99 }
    }
}

/// Half-length of the axial window and radius of the focal-plane window about the focus, m.
pub const WINDOW: f64 = 10e-3;

/// One case's comparison.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// The case's short name.
    pub name: String,
    /// What it is.
    pub description: String,
    /// Focal peak `|p|/p0`: simulated, exact.
    pub focal_pressure: [f64; 2],
    /// Focal peak position on the axis (z, m): simulated, exact.
    pub focal_z: [f64; 2],
    /// Focal peak in 3-D (m): simulated, exact (on the axis for an axisymmetric case).
    pub focal_point: [[f64; 3]; 2],
    /// Largest axial error in the window, relative to the exact peak.
    pub axial_error: f64,
    /// Pearson correlation of the focal plane's `|p|` within [`WINDOW`] of the axis.
    pub correlation: f64,
    /// z of each simulated axis sample (m), its `|p|/p0` and the exact `|p|/p0` there.
    pub axis: Vec<[f64; 3]>,
    /// The focal plane across x (y = 0): x (m), simulated and exact `|p|/p0`.
    pub focal_line: Vec<[f64; 3]>,
    /// Plane step of the grid the case ran on, m.
    pub step: f64,
    /// Lateral spacing, m.
    pub spacing: f64,
    /// Seconds the simulation took.
    pub seconds: f64,
    /// What the case must meet ([`Case::tolerances`]).
    pub tolerances: Tolerances,
}

impl Comparison {
    /// One line for a table: the focal pressure's error (%), the simulated focus less the exact
    /// one in x and z (mm), and the exact peak (`|p|/p0`) with its x and z (mm).
    pub fn against_exact(&self) -> String {
        let [s, e] = self.focal_point;
        format!(
            "{:+6.1} % | ({:+.2}, {:+.2}) | {:.3} at ({:+.2}, {:.2})",
            100.0 * self.focal_pressure_error(),
            (s[0] - e[0]) * 1e3,
            (s[2] - e[2]) * 1e3,
            self.focal_pressure[1],
            e[0] * 1e3,
            e[2] * 1e3
        )
    }

    /// Relative error of the focal peak.
    pub fn focal_pressure_error(&self) -> f64 {
        self.focal_pressure[0] / self.focal_pressure[1] - 1.0
    }

    /// Error of the focal position, m: the 3-D distance between the peaks, negative when the
    /// simulated one lies short of the exact one (on the axis, the difference in z).
    pub fn focal_position_error(&self) -> f64 {
        let [s, e] = self.focal_point;
        let d = ((s[0] - e[0]).powi(2) + (s[1] - e[1]).powi(2) + (s[2] - e[2]).powi(2)).sqrt();
        if s[2] < e[2] {
            -d
        } else {
            d
        }
    }

    /// Whether every metric is within the case's own tolerances.
    pub fn passed(&self) -> bool {
        self.passes(&self.tolerances)
    }

    /// Whether every metric is within `tol`.
    pub fn passes(&self, tol: &Tolerances) -> bool {
        self.focal_pressure_error().abs() <= tol.focal_pressure
            && self.focal_position_error().abs() <= tol.focal_position
            && self.axial_error <= tol.axial_profile
            && self.correlation >= tol.focal_plane_correlation
    }
}

/// Runs `case` on its scenario's default grid (writing its inputs first) and compares it with its
/// exact solution.
pub fn compare(case: &Case) -> Result<Comparison> {
    let t = std::time::Instant::now();
    case.write_inputs()?;
    let sim = Simulation::new(&case.scenario)?;
    let exact = case.exact()?;
    if let Exact::Oblique(oblique) = &exact {
        return oblique::compare_oblique(case, &sim, oblique);
    }
    let p0 = sim.source.face_pressure;
    // The exact peak by a 10 µm scan over ±15 mm of the nominal focus.
    let nominal = sim.focus[2];
    let (z_exact, p_exact) = (0..=3000).map(|i| nominal - 15e-3 + i as f64 * 1e-5).try_fold((0.0, 0.0), |b, z| {
        let p = exact.pressure(0.0, z)?.norm();
        Ok::<_, crate::HasError>(if p > b.1 { (z, p) } else { b })
    })?;
    // One march: the axis, and the grid's plane nearest the exact focus.
    let plane = sim.field(&[], Some(z_exact))?;
    let axis: Vec<(f64, f64)> = plane.axis_z.iter().zip(&plane.axis_pressure).map(|(&z, p)| (z, p.norm() / p0)).collect();
    // The simulated peak in the same range (inside bone the standing wave can be higher).
    let near: Vec<(f64, f64)> = axis.iter().copied().filter(|&(z, _)| exact.covers(z) && (z - nominal).abs() <= 15e-3).collect();
    let (z_sim, p_sim) = parabolic_peak(&near);
    let mut rows = Vec::new();
    let mut axial_error: f64 = 0.0;
    for &(z, p) in &axis {
        if exact.covers(z) {
            let e = exact.pressure(0.0, z)?.norm();
            if (z - z_exact).abs() <= WINDOW {
                axial_error = axial_error.max((p - e).abs() / p_exact);
            }
            rows.push([z, p, e]);
        }
    }
    // The focal plane, exact values at its own z.
    let (mut a, mut b, mut line) = (Vec::new(), Vec::new(), Vec::new());
    for (j, &y) in plane.y.iter().enumerate() {
        for (i, &x) in plane.x.iter().enumerate() {
            if x.hypot(y) <= WINDOW {
                let (s, e) = (plane.pressure[[j, i]].norm() / p0, exact.pressure(x.hypot(y), plane.z)?.norm());
                a.push(s);
                b.push(e);
                if y == 0.0 {
                    line.push([x, s, e]);
                }
            }
        }
    }
    Ok(Comparison {
        name: case.name.clone(),
        description: case.description.clone(),
        focal_pressure: [p_sim, p_exact],
        focal_z: [z_sim, z_exact],
        focal_point: [[0.0, 0.0, z_sim], [0.0, 0.0, z_exact]],
        axial_error,
        correlation: pearson(&a, &b),
        axis: rows,
        focal_line: line,
        step: sim.grid.dz,
        spacing: sim.grid.dx,
        seconds: t.elapsed().as_secs_f64(),
        tolerances: case.tolerances,
    })
}
