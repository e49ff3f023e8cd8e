//! The grid a scenario is simulated on: spacing, step, lateral size and planes chosen from the
//! scenario's wavelengths, aperture and focus unless its `[grid]` gives them.

use crate::error::{HasError, Result};
use crate::memory;
use crate::physics::grid::{fft_friendly, Grid};
use crate::physics::propagation::HasOptions;
use crate::physics::source::source_plane_z;
use crate::scenario::{GridSpec, Resolved, Scenario};

/// The scenario with the `[grid]` it resolves to written out (spacing, step, lateral size, last
/// plane, absorbing layer, reflections, interface model): a template that simulates as the
/// scenario does (the spacings to the rounding of their mm values).
pub fn with_chosen_grid(scenario: &Scenario) -> Result<Scenario> {
    let r = scenario.resolve()?;
    let g = choose_grid(&r)?;
    let mut s = scenario.clone();
    s.grid = GridSpec {
        spacing_mm: Some(g.dx * 1e3),
        step_mm: Some(g.dz * 1e3),
        lateral_size_mm: Some(g.nx as f64 * g.dx * 1e3),
        z_max_mm: Some(g.z(g.nz - 1) * 1e3),
        sponge_width_mm: Some(r.grid.sponge_width_mm.unwrap_or(HasOptions::default().sponge_width * 1e3)),
        reflections: Some(r.grid.reflections.unwrap_or(false)),
        interfaces: Some(r.grid.interface_model()?.name().to_string()),
        screen: Some(r.grid.screen_model(r.focus)?.name().to_string()),
    };
    Ok(s)
}

/// The grid for a scenario: spacing λ_min/4 unless given (refused above λ_min/2), a square
/// lateral extent covering the aperture (and an off-axis focus) with 20 mm margins, planes from
/// the source plane to 1.5 x the focal depth and the MR field of view, one of them on the focus.
pub fn choose_grid(r: &Resolved) -> Result<Grid> {
    let wavelength = r.medium.min_sound_speed() / r.frequency;
    let dx = match r.grid.spacing_mm {
        Some(s) => {
            let s = s * 1e-3;
            if s > 0.5 * wavelength {
                return Err(HasError::invalid(
                    "grid.spacing_mm",
                    format!(
                        "{:.3} mm is too coarse for {:.0} kHz (shortest wavelength {:.3} mm): use at most {:.3} mm (λ/2); {:.3} mm (λ/4) is recommended",
                        s * 1e3, r.frequency / 1e3, wavelength * 1e3, 0.5 * wavelength * 1e3, 0.25 * wavelength * 1e3
                    ),
                ));
            }
            s
        }
        None => 0.25 * wavelength,
    };
    let z0 = source_plane_z(&r.transducer, wavelength, dx);
    let ax = r.mr.plane.axes();
    let mr_z_end = if ax[1] == 2 { r.mr.center[2] + 0.5 * r.mr.fov[1] } else { r.mr.center[2] + r.mr.slice_thickness };
    let z_end = r.grid.z_max_mm.map_or((1.5 * r.focus[2]).max(mr_z_end), |z| z * 1e-3);
    let faces = marked_faces(r, z0, z_end);
    let (z0, dz) = match r.grid.step_mm {
        Some(s) if s * 1e-3 > wavelength => {
            return Err(HasError::invalid("grid.step_mm", format!("must not exceed the wavelength ({:.3} mm)", wavelength * 1e3)))
        }
        Some(s) => (align_source_plane(z0, s * 1e-3, &faces), s * 1e-3),
        None if faces.is_empty() => (z0, step_to_focus(z0, r.focus[2], dx)),
        None => steps_on_faces(z0, dx, &faces, r.focus[2]),
    };
    let extent = r.transducer.lateral_extent().max(r.focus[0].abs().max(r.focus[1].abs()) + 10e-3);
    let size = r.grid.lateral_size_mm.map_or(2.0 * (extent + 20e-3), |s| s * 1e-3);
    // (1e-9 of a sample below an integer counts as that integer, so that the size and last plane
    // written out by `with_chosen_grid` give back the same grid.)
    let n = fft_friendly((size / dx - 1e-9).ceil() as usize);
    if z_end <= z0 + dz {
        return Err(HasError::invalid("grid.z_max_mm", format!("must lie beyond the source plane at {:.1} mm", z0 * 1e3)));
    }
    let nz = ((z_end - z0) / dz - 1e-9).ceil() as usize + 1;
    let bytes = (n * n) as u64 * 16 * 8;
    if nz > 100_000 {
        return Err(HasError::invalid("grid.step_mm", format!("{nz} planes to the last one; use a larger step or grid.z_max_mm")));
    }
    memory::check(|| format!("a {n} x {n} grid"), bytes, "use a coarser grid.spacing_mm or a smaller grid.lateral_size_mm")?;
    Grid::new(n, n, dx, dx, nz, dz, z0)
}

/// The default step: at most the lateral spacing `dx`, and a whole number of steps from the
/// source plane `z0` to the focal depth `focus_z` (m), so that a plane lies exactly on the focus.
fn step_to_focus(z0: f64, focus_z: f64, dx: f64) -> f64 {
    if focus_z > z0 + dx {
        (focus_z - z0) / ((focus_z - z0) / dx).ceil()
    } else {
        dx
    }
}

/// A face whose rounding to the nearest plane would change the beam by more than this: its
/// normal-incidence reflection coefficient, or the phase (rad) a shift of half a step
/// `λ_min/8` gives the wave (`omega·|1/c_a - 1/c_b|·λ_min/8`). Water to the paper's phantom
/// (1533 m/s): 0.03 and 0.02, left where it falls; water to skin (1610 m/s): 0.08; to bone: 0.3
/// and above.
pub const FACE_CONTRAST: f64 = 0.05;

/// The default step goes no finer than this fraction of the lateral spacing to put planes on
/// the faces of a thin layer (1/32: 0.023 mm at 500 kHz).
pub const FINEST_STEP_FRACTION: f64 = 1.0 / 32.0;

/// At most this many steps are tried for the lattice of faces (a deep grid of many planes tries
/// those nearest the spacing).
const MAX_STEP_CANDIDATES: usize = 4096;

/// A face lies on a plane when it is within this fraction of a step of one.
const ON_PLANE: f64 = 0.02;

/// The z of every region face between the source plane `z0` and `z_end` (m) across which the
/// medium changes by [`FACE_CONTRAST`] or more, sorted.
fn marked_faces(r: &Resolved, z0: f64, z_end: f64) -> Vec<f64> {
    let m = &r.medium;
    let eighth = m.min_sound_speed() / r.frequency / 8.0;
    let omega = 2.0 * std::f64::consts::PI * r.frequency;
    let mut faces: Vec<f64> = Vec::new();
    for region in &m.regions {
        let (z_min, z_max) = region.shape.z_range();
        let [cx, cy] = region.shape.axis_point();
        for z in [z_min, z_max] {
            if z <= z0 || z >= z_end || faces.iter().any(|f| (f - z).abs() < 1e-9) {
                continue;
            }
            let eps = 1e-7;
            let (a, b) = (m.properties_at(cx, cy, z - eps, r.frequency), m.properties_at(cx, cy, z + eps, r.frequency));
            let reflection = ((b.impedance() - a.impedance()) / (a.impedance() + b.impedance())).abs();
            let phase = omega * (1.0 / a.sound_speed - 1.0 / b.sound_speed).abs() * eighth;
            if reflection.max(phase) >= FACE_CONTRAST {
                faces.push(z);
            }
        }
    }
    faces.sort_by(f64::total_cmp);
    faces
}

/// The default step with planes on `faces` (sorted, m): the largest `dz <= dz_max` that puts a
/// whole number of steps between the first face and every other (within [`ON_PLANE`] of a
/// step), also to the focal depth `focus_z` where one of at least half `dz_max` does; the source
/// plane moves forward from `z0` by less than a step to the first plane of that lattice. Where no
/// step down to `dz_max/4` (or the thinnest layer) fits every face, the one that comes closest.
fn steps_on_faces(z0: f64, dz_max: f64, faces: &[f64], focus_z: f64) -> (f64, f64) {
    let misfit = |dz: f64, targets: &[f64]| {
        targets.iter().map(|&z| (z - faces[0]) / dz).map(|steps| (steps - steps.round()).abs()).fold(0.0, f64::max)
    };
    let span = |targets: &[f64]| targets.iter().fold(0.0_f64, |m, &z| m.max((z - faces[0]).abs()));
    let mut with_focus = faces.to_vec();
    with_focus.push(focus_z);
    let candidates = |targets: &[f64], floor: f64| {
        let s = span(targets);
        let first = if s > 0.0 { (s / dz_max - 1e-9).ceil() as usize } else { 1 };
        (first.max(1)..)
            .map(move |m| if s > 0.0 { s / m as f64 } else { dz_max / m as f64 })
            .take_while(move |&dz| dz >= floor * (1.0 - 1e-12))
            .take(MAX_STEP_CANDIDATES)
    };
    // Down to a quarter of dz_max, and further where a layer is thinner than that, but not
    // below [`FINEST_STEP_FRACTION`] of it (a thinner layer is refused by name).
    let thinnest = faces.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let floor = (0.25 * dz_max).min(thinnest).max(FINEST_STEP_FRACTION * dz_max);
    let dz = candidates(&with_focus, 0.5 * dz_max)
        .find(|&dz| misfit(dz, &with_focus) <= ON_PLANE)
        .or_else(|| candidates(faces, floor).find(|&dz| misfit(dz, faces) <= ON_PLANE))
        .unwrap_or_else(|| {
            candidates(faces, floor).map(|dz| (dz, misfit(dz, faces))).fold((dz_max, f64::INFINITY), |b, c| if c.1 < b.1 { c } else { b }).0
        });
    (align_source_plane(z0, dz, faces), dz)
}

/// The source plane at or after `z0`, less than a step `dz` beyond it, that puts planes nearest
/// to the faces (the first face exactly when they share a lattice).
fn align_source_plane(z0: f64, dz: f64, faces: &[f64]) -> f64 {
    match faces.first() {
        Some(&f) if f > z0 => {
            let offset = (f - z0).rem_euclid(dz);
            // Move forward by the offset (a whole number of steps then reaches the face).
            if offset > dz * (1.0 - 1e-9) {
                z0
            } else {
                z0 + offset
            }
        }
        _ => z0,
    }
}

/// `grid` at a lateral spacing of at most `spacing` (m), coarser than its own: the same lateral
/// period (even, FFT-friendly sizes, the spacing shrunk to fill the period; for a grid of even
/// sizes the same first pixel too, so that a source plane's sums carry over by Fourier
/// resampling, [`crate::physics::source::SourceModel::on_grid`]), the same source plane, steps
/// chosen as [`choose_grid`] chooses them for the lateral spacing (a plane on the focal depth `focus_z`),
/// and planes up to at least its last one.
pub fn coarser_grid(grid: &Grid, focus_z: f64, spacing: f64) -> Result<Grid> {
    if !(spacing > grid.dx.max(grid.dy)) {
        return Err(HasError::invalid("spacing", format!("{spacing} m is not coarser than the grid's {} m", grid.dx.max(grid.dy))));
    }
    let even = |n: usize| {
        let mut m = fft_friendly(n);
        while m % 2 == 1 {
            m = fft_friendly(m + 1);
        }
        m
    };
    let lateral = |n: usize, d: f64| even((n as f64 * d / spacing - 1e-9).ceil() as usize);
    let (nx, ny) = (lateral(grid.nx, grid.dx), lateral(grid.ny, grid.dy));
    let (dx, dy) = (grid.nx as f64 * grid.dx / nx as f64, grid.ny as f64 * grid.dy / ny as f64);
    let dz = step_to_focus(grid.z0, focus_z, dx.min(dy).max(grid.dz));
    let depth = grid.z(grid.nz - 1) - grid.z0;
    let nz = (depth / dz - 1e-9).ceil() as usize + 1;
    Grid::new(nx, ny, dx, dy, nz, dz, grid.z0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `arfi scenario` writes the chosen grid; read back, it must give the very same grid (sizes
    /// within 1e-9 of a sample of an integer count are that count).
    #[test]
    fn the_written_grid_resolves_to_the_same_grid() {
        let bowl = "frequency_hz = 500000.0\n[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 64.0\n\
                    aperture_diameter_mm = 64.0\n[focus]\nposition_mm = [0.0, 0.0, 64.0]\n[grid]\nspacing_mm = 0.375\n";
        for s in [Scenario::default(), Scenario::from_toml(bowl, None).unwrap()] {
            let written = Scenario::from_toml(&with_chosen_grid(&s).unwrap().to_toml().unwrap(), None).unwrap();
            assert!(written.grid.step_mm.is_some() && written.grid.interfaces.as_deref() == Some("angular"));
            let (a, b) = (choose_grid(&written.resolve().unwrap()).unwrap(), choose_grid(&s.resolve().unwrap()).unwrap());
            assert_eq!((a.nx, a.ny, a.nz), (b.nx, b.ny, b.nz));
            // Spacings pass through mm in the file: equal to the last bit or two.
            for (x, y) in [(a.dx, b.dx), (a.dy, b.dy), (a.dz, b.dz), (a.z0, b.z0)] {
                assert!((x - y).abs() <= 1e-14 * x.abs().max(y.abs()), "{x} vs {y}");
            }
        }
    }

    /// The flat layered skull's faces (26, 30, 31.5, 35.5, 36.5 mm) and the focus (64 mm) share
    /// a lattice of 0.5 mm: the default step is the largest that puts planes on all of them,
    /// the source plane moved forward onto it.
    #[test]
    fn the_default_step_puts_planes_on_layer_faces() {
        let faces = [26e-3, 30e-3, 31.5e-3, 35.5e-3, 36.5e-3];
        let (z0, dz) = steps_on_faces(10.07e-3, 0.75e-3, &faces, 64e-3);
        assert!((dz - 0.5e-3).abs() < 1e-12, "{dz}");
        assert!(z0 >= 10.07e-3 && z0 < 10.07e-3 + dz);
        for z in faces.iter().chain([&64e-3]) {
            let n = (z - z0) / dz;
            assert!((n - n.round()).abs() < 1e-9, "{z}: plane {n}");
        }
        // One face: the step to the focus, and a plane on the face.
        let (z0, dz) = steps_on_faces(10.07e-3, 0.75e-3, &[30.2e-3], 64e-3);
        let n = (30.2e-3 - z0) / dz;
        assert!(dz <= 0.75e-3 && (n - n.round()).abs() < 0.02, "{dz} {n}");
    }

    /// The paper's phantom (1533 m/s) is too close to water to need a plane on its face: the
    /// default scenario's grid is the step to the focus from the unmoved source plane.
    #[test]
    fn faint_faces_leave_the_grid_alone() {
        let r = Scenario::default().resolve().unwrap();
        let g = choose_grid(&r).unwrap();
        let wavelength = r.medium.min_sound_speed() / r.frequency;
        assert!(marked_faces(&r, g.z0, 1.0).is_empty());
        assert_eq!(g.dz, step_to_focus(g.z0, r.focus[2], 0.25 * wavelength));
    }

    /// A coarser grid has the grid's lateral period and first pixel (even sizes), a spacing of at
    /// most the one asked for, and the grid's depth, from the same source plane, with a plane on
    /// the focus and steps of at most its spacing; a spacing that is not coarser is refused.
    #[test]
    fn a_coarser_grid_covers_the_grid_with_a_plane_on_the_focus() {
        let r = Scenario::default().resolve().unwrap();
        let g = choose_grid(&r).unwrap();
        for spacing in [1.5 * g.dx, 1.37 * g.dx, 2.9 * g.dx] {
            let c = coarser_grid(&g, r.focus[2], spacing).unwrap();
            assert_eq!(c.z0, g.z0);
            assert!(c.dx <= spacing && c.dy <= spacing && c.dx > g.dx, "{} {} for {spacing}", c.dx, c.dy);
            assert!(c.nx % 2 == 0 && c.ny % 2 == 0, "{} x {}", c.nx, c.ny);
            assert!((c.nx as f64 * c.dx - g.nx as f64 * g.dx).abs() < 1e-12 && (c.ny as f64 * c.dy - g.ny as f64 * g.dy).abs() < 1e-12);
            assert!((c.x(0) - g.x(0)).abs() < 1e-12 && (c.y(0) - g.y(0)).abs() < 1e-12);
        }
        let spacing = 1.5 * g.dx;
        let c = coarser_grid(&g, r.focus[2], spacing).unwrap();
        assert!(c.z(c.nz - 1) >= g.z(g.nz - 1) - 1e-12 && c.dz <= spacing);
        let steps = (r.focus[2] - c.z0) / c.dz;
        assert!((steps - steps.round()).abs() < 1e-9, "{steps} steps to the focus");
        assert!(coarser_grid(&g, r.focus[2], g.dx).is_err());
    }
}
