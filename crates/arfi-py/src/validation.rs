//! The validation suite: its cases and their comparisons with the exact solutions, as typed
//! results.

use crate::error::to_py;
use crate::interrupt::run_interruptible;
use has_core::validation::{compare, suite, tilted_plate, Case, Comparison, Tolerances};
use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// One case of the validation suite: a scenario as a user writes it (default grid) and its
/// exact solution.
#[pyclass(module = "arfi._core", name = "ValidationCase", frozen)]
pub(crate) struct CoreValidationCase(Case);

#[pymethods]
impl CoreValidationCase {
    /// Short name (`water`, `bm3`, `bm4`, `bm3_solid`, `shell`, `bm5`, `tilt0`, `tilt10`, `tilt20`, `tilt30`, `tilt0_shear1500`, ...).
    #[getter]
    fn name(&self) -> &str {
        &self.0.name
    }

    /// What the case is.
    #[getter]
    fn description(&self) -> &str {
        &self.0.description
    }

    /// The case's scenario as TOML (to run it with the other verbs).
    #[getter]
    fn scenario_toml(&self) -> PyResult<String> {
        self.0.scenario.to_toml().map_err(to_py)
    }

    /// Runs the case on its default grid and compares it with the exact solution (a few
    /// seconds; Ctrl-C interrupts at its end).
    fn run(&self, py: Python<'_>) -> PyResult<CoreComparison> {
        let cancel = AtomicBool::new(false);
        let c = run_interruptible(py, &cancel, || compare(&self.0))?.map_err(to_py)?;
        Ok(CoreComparison(c))
    }

    fn __repr__(&self) -> String {
        format!("ValidationCase(name={:?})", self.0.name)
    }
}

/// The suite's cases (the tilted plates last, fluid then solid); a case's CT is written to `dir` (which must exist) when its case runs.
#[pyfunction]
pub(crate) fn validation_cases(dir: PathBuf) -> PyResult<Vec<CoreValidationCase>> {
    Ok(suite(&dir).map_err(to_py)?.into_iter().map(CoreValidationCase).collect())
}

/// The ITRUSST bowl through the 6.5 mm cortical plate 30 mm from the apex turned `tilt_deg`
/// about y, read from a CT of 0.25 mm voxels written to `dir` (which must exist) when the case
/// runs; its exact solution that of the fluid plate, or of a solid of shear speed `shear_m_s`.
#[pyfunction]
#[pyo3(signature = (dir, tilt_deg, shear_m_s=None))]
pub(crate) fn tilted_plate_case(dir: PathBuf, tilt_deg: f64, shear_m_s: Option<f64>) -> PyResult<CoreValidationCase> {
    Ok(CoreValidationCase(tilted_plate(&dir, tilt_deg, shear_m_s).map_err(to_py)?))
}

/// One case's comparison: `|p|/p0` simulated and exact (`p0` the element face pressure).
#[pyclass(module = "arfi._core", name = "ValidationResult", frozen)]
pub(crate) struct CoreComparison(Comparison);

/// `(z or x in mm, simulated, exact)` rows as an `(n, 3)` array.
fn rows<'py>(py: Python<'py>, r: &[[f64; 3]]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = r.iter().flat_map(|v| [v[0] * 1e3, v[1], v[2]]).collect();
    numpy::ndarray::Array2::from_shape_vec((r.len(), 3), flat).expect("rows of three").into_pyarray(py)
}

#[pymethods]
impl CoreComparison {
    /// The case's short name.
    #[getter]
    fn name(&self) -> &str {
        &self.0.name
    }

    /// What the case is.
    #[getter]
    fn description(&self) -> &str {
        &self.0.description
    }

    /// Focal peak `|p|/p0`: (simulated, exact).
    #[getter]
    fn focal_pressure(&self) -> (f64, f64) {
        (self.0.focal_pressure[0], self.0.focal_pressure[1])
    }

    /// Focal peak's depth on the axis, mm: (simulated, exact).
    #[getter]
    fn focal_z_mm(&self) -> (f64, f64) {
        (self.0.focal_z[0] * 1e3, self.0.focal_z[1] * 1e3)
    }

    /// Relative error of the focal peak pressure.
    #[getter]
    fn focal_pressure_error(&self) -> f64 {
        self.0.focal_pressure_error()
    }

    /// Error of the focal position, mm.
    #[getter]
    fn focal_position_error_mm(&self) -> f64 {
        self.0.focal_position_error() * 1e3
    }

    /// The focal peak in 3-D (mm, transducer frame), simulated and exact.
    #[getter]
    fn focal_point_mm(&self) -> ([f64; 3], [f64; 3]) {
        let [s, e] = self.0.focal_point;
        (s.map(|v| v * 1e3), e.map(|v| v * 1e3))
    }

    /// Largest axial error from 10 mm before to 10 mm after the focus, relative to the exact peak.
    #[getter]
    fn axial_error(&self) -> f64 {
        self.0.axial_error
    }

    /// Pearson correlation of the focal plane's `|p|` within 10 mm of the axis.
    #[getter]
    fn correlation(&self) -> f64 {
        self.0.correlation
    }

    /// The axis: `(n, 3)` rows of z (mm), simulated and exact `|p|/p0`.
    #[getter]
    fn axis<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows(py, &self.0.axis)
    }

    /// The focal plane across x at y = 0: `(n, 3)` rows of x (mm), simulated and exact `|p|/p0`.
    #[getter]
    fn focal_line<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows(py, &self.0.focal_line)
    }

    /// The grid's plane step, mm.
    #[getter]
    fn step_mm(&self) -> f64 {
        self.0.step * 1e3
    }

    /// The grid's lateral spacing, mm.
    #[getter]
    fn spacing_mm(&self) -> f64 {
        self.0.spacing * 1e3
    }

    /// Seconds the simulation and comparison took.
    #[getter]
    fn seconds(&self) -> f64 {
        self.0.seconds
    }

    /// What the case must meet: `(focal_pressure, focal_position_mm, axial_profile,
    /// focal_plane_correlation)`, the suite's or a tilted plate's own.
    #[getter]
    fn tolerances(&self) -> (f64, f64, f64, f64) {
        as_tuple(&self.0.tolerances)
    }

    /// Whether every metric is within the case's [`tolerances`].
    #[getter]
    fn passed(&self) -> bool {
        self.0.passed()
    }

    /// What the march is compared with: `"exact"` (the case's exact solution).
    #[getter]
    fn engine(&self) -> &'static str {
        "exact"
    }

    fn __repr__(&self) -> String {
        let c = &self.0;
        format!(
            "ValidationResult(name={:?}, focal_pressure_error={:+.4}, focal_position_error_mm={:+.3}, axial_error={:.4}, correlation={:.4}, passed={})",
            c.name,
            c.focal_pressure_error(),
            c.focal_position_error() * 1e3,
            c.axial_error,
            c.correlation,
            self.passed()
        )
    }
}

/// The suite's tolerances: `focal_pressure` (relative), `focal_position_mm`, `axial_profile`
/// (relative to the exact peak), `focal_plane_correlation` (smallest).
#[pyfunction]
pub(crate) fn validation_tolerances() -> (f64, f64, f64, f64) {
    as_tuple(&Tolerances::default())
}

fn as_tuple(t: &Tolerances) -> (f64, f64, f64, f64) {
    (t.focal_pressure, t.focal_position * 1e3, t.axial_profile, t.focal_plane_correlation)
}
