//! The 3-D pressure amplitude of a beam on a box of the grid: what a volume file holds (NIfTI,
//! to lay over the patient's images).

use super::Simulation;
use crate::error::{HasError, Result};
use crate::focal::exposure;
use crate::memory;
use crate::numeric::affine_apply;
use crate::physics::ct::CtMedium;
use crate::physics::grid::Grid;
use crate::physics::medium::Medium;
use crate::physics::propagation::{RecordSpec, Window};
use rayon::prelude::*;

/// `|p|` on a box of the grid, with the map from its voxels to the transducer frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PressureVolume {
    /// The box: plane, row and column index ranges of the grid.
    pub window: Window,
    /// `|p|` (Pa) in single precision, row-major (plane, row, column): x fastest, then y, then z.
    pub pressure: Vec<f32>,
    /// Position (m, transducer frame) of voxel `(i, j, k)` (column, row, plane within the box):
    /// `affine · (i, j, k, 1)`.
    pub affine: [[f64; 4]; 3],
}

/// `|p|` resampled into the voxel grid of the scenario's CT, to open on top of it.
#[derive(Debug, Clone, PartialEq)]
pub struct CtPressureVolume {
    /// The CT's shape `(nk, nj, ni)`.
    pub shape: [usize; 3],
    /// `|p|` (Pa) in single precision, row-major `(k, j, i)` as the CT's voxels: zero outside the
    /// simulation grid.
    pub pressure: Vec<f32>,
    /// The CT file's affine from voxel (i, j, k) to RAS+ mm.
    pub ras_affine: [[f64; 4]; 3],
}

/// Bytes a voxel takes while a volume is made: the march sums the box's complex pressure in
/// single precision (8), made `|p|` in place.
pub(crate) const BYTES_PER_VOXEL: u64 = 8;

impl Simulation {
    /// `|p|` of the beam driven with `added` (phases added to the steering, per element or per
    /// group; empty: the steering alone) on `window` (`None`: the whole grid), from one march.
    /// Refused before the march when it would not fit in memory.
    pub fn pressure_volume(&self, added: &[f64], window: Option<Window>) -> Result<PressureVolume> {
        let g = &self.grid;
        let window = window.unwrap_or_else(|| Window::whole(g));
        if window.is_empty() || window.planes.end > g.nz || window.rows.end > g.ny || window.cols.end > g.nx {
            return Err(HasError::invalid("window", "must be a box of the grid holding at least one sample"));
        }
        let shape = [window.cols.len(), window.rows.len(), window.planes.len()];
        memory::check(
            || format!("a pressure volume of {} x {} x {} voxels", shape[0], shape[1], shape[2]),
            window.len() as u64 * BYTES_PER_VOXEL,
            "crop it to a box around the focus (--volume-box-mm, or box_mm in Python)",
        )?;
        let spec = RecordSpec { magnitude: Some(window.clone()), reflections: self.reflections, ..RecordSpec::default() };
        let pressure = self.plan.propagate(&self.source_field(added)?, &spec)?.magnitude;
        let affine = window_affine(g, &window);
        Ok(PressureVolume { window, pressure, affine })
    }
}

/// `magnitude` (`|p|` on every sample of `g`, as [`crate::simulation::FieldVolume`] keeps it)
/// on `window` (`None`: the whole grid) as a volume.
pub fn crop_volume(g: &Grid, magnitude: &[f32], window: Option<Window>) -> PressureVolume {
    let whole = Window::whole(g);
    let window = window.unwrap_or_else(|| whole.clone());
    let pressure = if window == whole { magnitude.to_vec() } else { whole.extract(magnitude, &window) };
    PressureVolume { affine: window_affine(g, &window), window, pressure }
}

/// The affine from voxel `(i, j, k)` of `window` (column, row, plane within it) to the
/// transducer frame (m).
pub fn window_affine(g: &Grid, window: &Window) -> [[f64; 4]; 3] {
    let origin = [g.x(window.cols.start), g.y(window.rows.start), g.z(window.planes.start)];
    [[g.dx, 0.0, 0.0, origin[0]], [0.0, g.dy, 0.0, origin[1]], [0.0, 0.0, g.dz, origin[2]]]
}

impl Simulation {
    /// `|p|` of the beam driven with `added` resampled into the voxel grid of the scenario's CT
    /// (trilinear between the simulation's samples; zero where a voxel lies outside the grid),
    /// with the CT's own affine: a viewer lays it on the CT without a transform. Needs a `[ct]`
    /// scenario; refused before the march when the two volumes would not fit in memory.
    pub fn pressure_volume_in_ct(&self, added: &[f64]) -> Result<CtPressureVolume> {
        let Some(ct) = self.medium.ct.as_ref() else {
            return Err(HasError::invalid("volume_ct", "needs a scenario with a [ct] section: the CT is the grid it is resampled into"));
        };
        let g = &self.grid;
        check_ct_volume(ct, "pressure", (g.nx * g.ny * g.nz) as u64 * BYTES_PER_VOXEL)?;
        Ok(resample_into_ct(g, &self.pressure_volume(added, None)?.pressure, ct))
    }
}

/// Refuses a volume of `quantity` (e.g. "pressure") on the CT's voxels when it and `other_bytes`
/// (what its making holds beside it) would not fit in memory.
pub fn check_ct_volume(ct: &CtMedium, quantity: &str, other_bytes: u64) -> Result<()> {
    let (shape, _, _) = ct.voxel_grid();
    memory::check(
        || format!("a {quantity} volume on the CT's {} x {} x {} voxels", shape[2], shape[1], shape[0]),
        shape.iter().product::<usize>() as u64 * 4 + other_bytes,
        "crop the CT, or use a coarser grid",
    )
}

/// `magnitude` (`|p|` on every sample of `grid`, row-major plane, row, column) resampled into the
/// voxel grid of `ct` (trilinear between the grid's samples; zero where a voxel lies outside the
/// grid), with the CT file's own affine.
pub fn resample_into_ct(grid: &Grid, magnitude: &[f32], ct: &CtMedium) -> CtPressureVolume {
    let (shape, ras_affine, to_frame) = ct.voxel_grid();
    let [nk, nj, ni] = shape;
    let mut pressure = vec![0.0f32; nk * nj * ni];
    pressure.par_chunks_mut(ni * nj).enumerate().for_each(|(k, plane)| {
        for (f, out) in plane.iter_mut().enumerate() {
            let p = affine_apply(&to_frame, [(f % ni) as f64, (f / ni) as f64, k as f64]);
            *out = trilinear(grid, magnitude, p);
        }
    });
    CtPressureVolume { shape, pressure, ras_affine }
}

/// `values` (one per grid sample, row-major (plane, row, column)) at the point `p` (m), trilinear
/// between the eight samples around it; zero outside the grid.
fn trilinear(g: &Grid, values: &[f32], p: [f64; 3]) -> f32 {
    let at = g.fractional_index(p);
    let n = [g.nx, g.ny, g.nz];
    if (0..3).any(|a| !(at[a] >= 0.0 && at[a] <= (n[a] - 1) as f64)) {
        return 0.0;
    }
    let base: [usize; 3] = std::array::from_fn(|a| (at[a].floor() as usize).min(n[a] - 2));
    let w: [f64; 3] = std::array::from_fn(|a| at[a] - base[a] as f64);
    let mut sum = 0.0;
    for corner in 0..8 {
        let pick = |a: usize| corner >> a & 1;
        let weight: f64 = (0..3).map(|a| if pick(a) == 1 { w[a] } else { 1.0 - w[a] }).product();
        let (i, j, k) = (base[0] + pick(0), base[1] + pick(1), base[2] + pick(2));
        sum += weight * values[(k * g.ny + j) * g.nx + i] as f64;
    }
    sum as f32
}

/// The pulse-average intensity `I = |p|² / (2·ρ·c)` (W/m², single precision; its largest value is
/// I_SPPA) of the continuous wave at `frequency` (Hz) in `medium` on `window` of `magnitude` (`|p|`
/// in Pa on every sample of `grid`, row-major plane, row, column, as
/// [`crate::simulation::FieldVolume`] keeps it), ρ and c the medium's at each sample (the CT's
/// conversion where it holds tissue), as the focal metrics and the hottest places take them.
/// Refused when the window is not a box of the grid or the new volume would not fit in memory.
pub fn intensity_on_window(medium: &Medium, frequency: f64, grid: &Grid, magnitude: &[f32], window: &Window) -> Result<Vec<f32>> {
    let g = grid;
    if magnitude.len() != g.lateral_len() * g.nz {
        return Err(HasError::invalid(
            "magnitude",
            format!("needs one |p| per grid sample ({}), got {}", g.lateral_len() * g.nz, magnitude.len()),
        ));
    }
    if window.is_empty() || window.planes.end > g.nz || window.rows.end > g.ny || window.cols.end > g.nx {
        return Err(HasError::invalid("window", "must be a box of the grid holding at least one sample"));
    }
    let (ni, nj) = (window.cols.len(), window.rows.len());
    memory::check(
        || format!("an intensity volume of {} x {} x {} voxels", ni, nj, window.planes.len()),
        window.len() as u64 * 4,
        "crop it to a box around the focus (--volume-box-mm, or box_mm in Python)",
    )?;
    let mut out = vec![0.0f32; window.len()];
    out.par_chunks_mut(ni * nj).zip(window.planes.clone()).for_each(|(plane, k)| {
        for (f, value) in plane.iter_mut().enumerate() {
            let (i, j) = (window.cols.start + f % ni, window.rows.start + f / ni);
            *value = intensity_at(medium, frequency, magnitude[(k * g.ny + j) * g.nx + i], [g.x(i), g.y(j), g.z(k)]);
        }
    });
    Ok(out)
}

/// [`intensity_on_window`] of a volume on the CT's voxels ([`resample_into_ct`]): ρ and c the
/// medium's at each voxel's centre (the CT's conversion of that voxel where it holds tissue); zero
/// where `|p|` is. Refused without a CT of that shape, or when the new volume would not fit in
/// memory.
pub fn intensity_in_ct(medium: &Medium, frequency: f64, v: &CtPressureVolume) -> Result<Vec<f32>> {
    let Some(ct) = medium.ct.as_ref() else {
        return Err(HasError::invalid("in_ct", "needs a scenario with a [ct] section: the CT is the grid it is resampled into"));
    };
    let (shape, _, to_frame) = ct.voxel_grid();
    if shape != v.shape || v.pressure.len() != shape.iter().product::<usize>() {
        return Err(HasError::invalid("volume", "is not on this scenario's CT voxels"));
    }
    let [_, nj, ni] = shape;
    memory::check(
        || format!("an intensity volume on the CT's {} x {} x {} voxels", ni, nj, shape[0]),
        v.pressure.len() as u64 * 4,
        "crop the CT, or use a coarser grid",
    )?;
    let mut out = vec![0.0f32; v.pressure.len()];
    out.par_chunks_mut(ni * nj).zip(v.pressure.par_chunks(ni * nj)).enumerate().for_each(|(k, (plane, pressure))| {
        for (f, (value, &p)) in plane.iter_mut().zip(pressure).enumerate() {
            if p > 0.0 {
                *value = intensity_at(medium, frequency, p, affine_apply(&to_frame, [(f % ni) as f64, (f / ni) as f64, k as f64]));
            }
        }
    });
    Ok(out)
}

/// `I = p² / (2·ρ·c)` (W/m²) of `|p|` = `pressure` (Pa) at `position` (m, transducer frame).
fn intensity_at(medium: &Medium, frequency: f64, pressure: f32, position: [f64; 3]) -> f32 {
    let [x, y, z] = position;
    let m = medium.properties_at(x, y, z, frequency);
    exposure(pressure as f64, m.density, m.sound_speed, frequency).0 as f32
}

/// The box of `grid` holding the samples within `[lo, hi]` (m, per axis x, y, z), or why there
/// is none.
pub fn window_of_box(grid: &Grid, lo: [f64; 3], hi: [f64; 3]) -> Result<Window> {
    if (0..3).any(|k| !(lo[k].is_finite() && hi[k].is_finite() && lo[k] < hi[k])) {
        return Err(HasError::invalid("box_mm", "needs finite bounds, each lower than its upper"));
    }
    let inside = |n: usize, at: &dyn Fn(usize) -> f64, k: usize| {
        let first = (0..n).find(|&i| at(i) >= lo[k] && at(i) <= hi[k])?;
        let last = (first..n).take_while(|&i| at(i) <= hi[k]).last()?;
        Some(first..last + 1)
    };
    let ranges = (inside(grid.nx, &|i| grid.x(i), 0), inside(grid.ny, &|j| grid.y(j), 1), inside(grid.nz, &|n| grid.z(n), 2));
    match ranges {
        (Some(cols), Some(rows), Some(planes)) => Ok(Window { planes, rows, cols }),
        _ => {
            let span = |a: f64, b: f64| format!("{:.1} to {:.1}", a * 1e3, b * 1e3);
            Err(HasError::invalid(
                "box_mm",
                format!(
                    "x {}, y {}, z {} mm holds no sample of the grid (x {}, y {}, z {} mm)",
                    span(lo[0], hi[0]),
                    span(lo[1], hi[1]),
                    span(lo[2], hi[2]),
                    span(grid.x(0), grid.x(grid.nx - 1)),
                    span(grid.y(0), grid.y(grid.ny - 1)),
                    span(grid.z(0), grid.z(grid.nz - 1))
                ),
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;

    /// The volume is `|p|` of the planes a plain recording keeps (the same march, summed and taken
    /// in single precision: within 1e-6 of the peak, a few float32 roundings), on the box asked
    /// for; its affine puts voxel (0, 0, 0) on the box's first sample and steps by the grid's
    /// spacing.
    #[test]
    fn the_volume_is_the_magnitude_of_the_recorded_planes() {
        let sim = Simulation::new(&Scenario::from_toml("[transducer]\nelements_per_side = 4\n", None).unwrap()).unwrap();
        let g = &sim.grid;
        let lo = [-3e-3, -2e-3, sim.focus[2] - 2e-3];
        let hi = [3e-3, 2e-3, sim.focus[2] + 2e-3];
        let window = window_of_box(g, lo, hi).unwrap();
        assert!(g.x(window.cols.start) >= lo[0] && g.x(window.cols.start - 1) < lo[0]);
        assert!(g.z(window.planes.end - 1) <= hi[2] && g.z(window.planes.end) > hi[2]);
        let added: Vec<f64> = (0..sim.n_elements()).map(|e| 0.3 * ((e * 5) % 7) as f64 - 0.9).collect();
        let v = sim.pressure_volume(&added, Some(window.clone())).unwrap();
        let planes: Vec<usize> = window.planes.clone().collect();
        let spec = RecordSpec { planes: planes.clone(), reflections: sim.reflections, ..RecordSpec::default() };
        let rec = sim.plan.propagate(&sim.source_field(&added).unwrap(), &spec).unwrap();
        let mut expected = Vec::new();
        for plane in &rec.planes {
            for r in window.rows.clone() {
                expected.extend(window.cols.clone().map(|c| plane[r * g.nx + c].norm() as f32));
            }
        }
        let peak = expected.iter().fold(0.0f32, |m, &p| m.max(p));
        assert_eq!(v.pressure.len(), expected.len());
        for (a, b) in v.pressure.iter().zip(&expected) {
            assert!((a - b).abs() <= 1e-6 * peak, "{a} vs {b}");
        }
        assert_eq!(v.affine[0], [g.dx, 0.0, 0.0, g.x(window.cols.start)]);
        assert_eq!(v.affine[2], [0.0, 0.0, g.dz, g.z(window.planes.start)]);
        let outside = window_of_box(g, [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]).unwrap_err().to_string();
        assert!(outside.contains("holds no sample of the grid"), "{outside}");
        assert!(window_of_box(g, hi, lo).is_err());
    }

    /// A 64-element bowl (50 mm, 40 mm wide, 500 kHz) in water (1000 kg/m³, 1500 m/s) before a
    /// bone plate (1850 kg/m³, 2800 m/s) from z = 30 to 35 mm; `reflections` as asked.
    fn plate(reflections: bool) -> Simulation {
        let text = format!(
            "frequency_hz = 500000.0\n[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 50.0\n\
             aperture_diameter_mm = 40.0\nelements = 64\n[[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\n\
             density_kg_m3 = 1000.0\n[[material]]\nname = \"bone\"\nsound_speed_m_s = 2800.0\ndensity_kg_m3 = 1850.0\n\
             attenuation_db_cm_mhz = 10.0\n[medium]\nbackground = \"water\"\n[[region]]\nmaterial = \"bone\"\n\
             shape = \"slab\"\nz_min_mm = 30.0\nz_max_mm = 35.0\n[grid]\nreflections = {reflections}\nspacing_mm = 0.75\n"
        );
        Simulation::new(&Scenario::from_toml(&text, None).unwrap()).unwrap()
    }

    /// Through a reverberating plate with reflections towards the source (every plane summed from
    /// several sweeps), the volume is still `|p|` of the planes recorded in double precision,
    /// within 1e-6 of the peak (float32 sums of a few terms).
    #[test]
    fn through_a_reverberating_plate_the_volume_sums_every_sweep() {
        let sim = plate(true);
        assert!(sim.propagation().reverberation.is_some() && sim.reflections);
        let g = &sim.grid;
        let window = window_of_box(g, [-5e-3, -5e-3, 20e-3], [5e-3, 5e-3, 40e-3]).unwrap();
        let v = sim.pressure_volume(&[], Some(window.clone())).unwrap();
        let spec = RecordSpec { planes: window.planes.clone().collect(), reflections: true, ..RecordSpec::default() };
        let rec = sim.plan.propagate(&sim.source_field(&[]).unwrap(), &spec).unwrap();
        let mut expected = Vec::new();
        for plane in &rec.planes {
            for r in window.rows.clone() {
                expected.extend(window.cols.clone().map(|c| plane[r * g.nx + c].norm()));
            }
        }
        let peak = expected.iter().fold(0.0f64, |m: f64, &p| m.max(p));
        assert_eq!(v.pressure.len(), expected.len());
        for (a, b) in v.pressure.iter().zip(&expected) {
            assert!((*a as f64 - b).abs() <= 1e-6 * peak, "{a} vs {b}");
        }
    }

    /// The intensity volume is `p² / (2·ρ·c)` by hand with the materials' own ρ and c as the
    /// scenario states them (water 1000 kg/m³ · 1500 m/s, bone 1850 · 2800), in front of the bone
    /// slab, inside it and behind it (samples at least 0.1 mm from its faces, where the material
    /// is not in doubt), to single precision (1e-6 relative); a box holds the whole grid's values.
    #[test]
    fn intensity_is_p_squared_over_twice_the_impedance_of_each_samples_material() {
        let sim = plate(false);
        let g = &sim.grid;
        let whole = Window::whole(g);
        let magnitude = sim.pressure_volume(&[], None).unwrap().pressure;
        let intensity = intensity_on_window(&sim.medium, sim.frequency, g, &magnitude, &whole).unwrap();
        let (mut in_bone, mut in_water) = (0, 0);
        for (s, (&p, &i)) in magnitude.iter().zip(&intensity).enumerate() {
            let z = g.z(s / g.lateral_len());
            let rho_c = if (30.1e-3..=34.9e-3).contains(&z) {
                in_bone += 1;
                1850.0 * 2800.0
            } else if !(29.9e-3..=35.1e-3).contains(&z) {
                in_water += 1;
                1000.0 * 1500.0
            } else {
                continue;
            };
            let want = (p as f64).powi(2) / (2.0 * rho_c);
            assert!((i as f64 - want).abs() <= 1e-6 * want, "sample {s}: {i} vs {want}");
        }
        assert!(in_bone > 0 && in_water > 0);
        let window = window_of_box(g, [-5e-3, -5e-3, 28e-3], [5e-3, 5e-3, 37e-3]).unwrap();
        assert_eq!(intensity_on_window(&sim.medium, sim.frequency, g, &magnitude, &window).unwrap(), whole.extract(&intensity, &window));
        let beyond = Window { planes: g.nz - 1..g.nz + 1, ..window };
        assert!(intensity_on_window(&sim.medium, sim.frequency, g, &magnitude, &beyond).unwrap_err().to_string().starts_with("window"));
        assert!(intensity_on_window(&sim.medium, sim.frequency, g, &magnitude[1..], &whole)
            .unwrap_err()
            .to_string()
            .starts_with("magnitude"));
    }

    /// Trilinear interpolation gives a field linear in x, y and z exactly (to float32) at the
    /// samples and between them, and zero outside the grid.
    #[test]
    fn trilinear_is_exact_on_a_linear_field() {
        let g = Grid::new(6, 5, 1e-3, 2e-3, 4, 0.5e-3, 10e-3).unwrap();
        let f = |p: [f64; 3]| 10.0 + 2e3 * p[0] + 3e3 * p[1] + 4e3 * (p[2] - g.z0);
        let mut values = Vec::new();
        for k in 0..g.nz {
            for j in 0..g.ny {
                for i in 0..g.nx {
                    values.push(f([g.x(i), g.y(j), g.z(k)]) as f32);
                }
            }
        }
        for p in [[g.x(1), g.y(2), g.z(1)], [0.3e-3, -1.7e-3, 11.2e-3], [g.x(5), g.y(4), g.z(3)]] {
            let (got, want) = (trilinear(&g, &values, p) as f64, f(p));
            assert!((got - want).abs() < 1e-5 * want.abs(), "{p:?}: {got} vs {want}");
        }
        assert_eq!(trilinear(&g, &values, [0.0, 0.0, 9e-3]), 0.0);
        assert_eq!(trilinear(&g, &values, [g.x(5) + 1e-4, 0.0, 11e-3]), 0.0);
    }
}
