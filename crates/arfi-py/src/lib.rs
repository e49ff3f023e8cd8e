//! Python bindings of has-core: NumPy in and out, errors mapped in [`error`].

mod error;

use error::to_py;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use num_complex::Complex64 as C64;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::Path;

fn parse_scenario(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<Scenario> {
    let base = base_dir.map(Path::new);
    match format {
        "toml" => Scenario::from_toml(text, base),
        "json" => Scenario::from_json(text, base),
        f => return Err(pyo3::exceptions::PyValueError::new_err(format!("format: must be 'toml' or 'json', got '{f}'"))),
    }
    .map_err(to_py)
}

/// The default scenario (SPEC §3) as TOML, every value written out.
#[pyfunction]
fn default_scenario_toml() -> PyResult<String> {
    Scenario::default().to_toml().map_err(to_py)
}

/// Parses and validates a scenario (`format` = "toml" | "json"), returning it as complete TOML.
#[pyfunction]
#[pyo3(signature = (text, format="toml", base_dir=None))]
fn normalize_scenario(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<String> {
    let s = parse_scenario(text, format, base_dir)?;
    s.resolve().map_err(to_py)?;
    s.to_toml().map_err(to_py)
}

/// Parses and validates a scenario, returning it as complete JSON (for `Scenario.to_dict`).
#[pyfunction]
#[pyo3(signature = (text, format="toml", base_dir=None))]
fn scenario_json(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<String> {
    let s = parse_scenario(text, format, base_dir)?;
    s.resolve().map_err(to_py)?;
    s.to_json().map_err(to_py)
}

/// Reads a scenario file and returns it as complete TOML (FileNotFoundError / ValueError).
#[pyfunction]
fn load_scenario(path: &str) -> PyResult<String> {
    let s = Scenario::load(Path::new(path)).map_err(to_py)?;
    s.resolve().map_err(to_py)?;
    s.to_toml().map_err(to_py)
}

fn phases_vec(phases: Option<PyReadonlyArray1<'_, f64>>) -> Vec<f64> {
    phases.map(|p| p.as_array().to_vec()).unwrap_or_default()
}

/// A scenario made ready to simulate (grid chosen, beam steered, HAS plan built).
#[pyclass(module = "arfi._core", frozen)]
struct CoreSimulation {
    inner: Simulation,
}

#[pymethods]
impl CoreSimulation {
    #[new]
    #[pyo3(signature = (text, format="toml", base_dir=None))]
    fn new(py: Python<'_>, text: &str, format: &str, base_dir: Option<&str>) -> PyResult<Self> {
        let s = parse_scenario(text, format, base_dir)?;
        let inner = py.detach(|| Simulation::new(&s)).map_err(to_py)?;
        Ok(CoreSimulation { inner })
    }

    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.n_elements()
    }
    #[getter]
    fn n_groups(&self) -> usize {
        self.inner.n_groups
    }
    #[getter]
    fn amplitude(&self) -> f64 {
        self.inner.amplitude
    }
    #[getter]
    fn frequency_hz(&self) -> f64 {
        self.inner.frequency
    }
    #[getter]
    fn noise_rad(&self) -> f64 {
        self.inner.noise
    }
    #[getter]
    fn mask_fraction(&self) -> f64 {
        self.inner.mask_fraction
    }
    #[getter]
    fn focus_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.focus.iter().map(|v| v * 1e3).collect::<Vec<_>>().into_pyarray(py)
    }
    #[getter]
    fn steering_phases_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.steering.clone().into_pyarray(py)
    }
    #[getter]
    fn groups<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        self.inner.groups.iter().map(|&g| g as i64).collect::<Vec<_>>().into_pyarray(py)
    }
    /// Element centres (mm), shape (n_elements, 3).
    #[getter]
    fn element_positions_mm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> =
            self.inner.transducer.elements.iter().map(|e| e.reference_point().iter().map(|v| v * 1e3).collect()).collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }
    /// Grid: dict with nx, ny, nz, dx_mm, dy_mm, dz_mm, z0_mm.
    #[getter]
    fn grid<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let g = &self.inner.grid;
        let d = PyDict::new(py);
        d.set_item("nx", g.nx)?;
        d.set_item("ny", g.ny)?;
        d.set_item("nz", g.nz)?;
        d.set_item("dx_mm", g.dx * 1e3)?;
        d.set_item("dy_mm", g.dy * 1e3)?;
        d.set_item("dz_mm", g.dz * 1e3)?;
        d.set_item("z0_mm", g.z0 * 1e3)?;
        Ok(d)
    }
    /// MR geometry: affine (4x4, mm), volume shape, plane.
    #[getter]
    fn mr_affine_mm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let a = self.inner.sampler.geometry.affine_mm();
        let rows: Vec<Vec<f64>> = a.iter().map(|r| r.to_vec()).collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }
    #[getter]
    fn mr_volume_shape(&self) -> (usize, usize, usize) {
        let s = self.inner.sampler.geometry.volume_shape();
        (s[0], s[1], s[2])
    }
    #[getter]
    fn mr_plane(&self) -> &'static str {
        self.inner.sampler.geometry.plane.name()
    }

    /// Pressure on the plane nearest `z_mm` (default: the focus) and along the axis.
    #[pyo3(signature = (phases=None, z_mm=None))]
    fn field<'py>(&self, py: Python<'py>, phases: Option<PyReadonlyArray1<'py, f64>>, z_mm: Option<f64>) -> PyResult<Bound<'py, PyDict>> {
        let phases = phases_vec(phases);
        let f = py.detach(|| self.inner.field(&phases, z_mm.map(|z| z * 1e-3))).map_err(to_py)?;
        let d = PyDict::new(py);
        let mm = |v: &[f64]| v.iter().map(|x| x * 1e3).collect::<Vec<f64>>();
        d.set_item("pressure", f.pressure.into_pyarray(py))?;
        d.set_item("x_mm", mm(&f.x).into_pyarray(py))?;
        d.set_item("y_mm", mm(&f.y).into_pyarray(py))?;
        d.set_item("z_mm", f.z * 1e3)?;
        d.set_item("axis_pressure", f.axis_pressure.into_pyarray(py))?;
        d.set_item("axis_z_mm", mm(&f.axis_z).into_pyarray(py))?;
        d.set_item("surface_pressure_pa", f.surface_pressure)?;
        Ok(d)
    }

    /// MR-ARFI phase image (rad), shape (n_u, n_v); Gaussian noise of `noise_rad` if given.
    #[pyo3(signature = (phases=None, noise_rad=0.0, seed=0))]
    fn arfi_image<'py>(
        &self,
        py: Python<'py>,
        phases: Option<PyReadonlyArray1<'py, f64>>,
        noise_rad: f64,
        seed: u64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let phases = phases_vec(phases);
        let img = py.detach(|| self.inner.noisy_arfi_image(&phases, noise_rad, seed)).map_err(to_py)?;
        Ok(img.into_pyarray(py))
    }

    /// The source-plane pressure (Pa), shape (ny, nx), for added phases.
    #[pyo3(signature = (phases=None))]
    fn source_field<'py>(&self, py: Python<'py>, phases: Option<PyReadonlyArray1<'py, f64>>) -> PyResult<Bound<'py, PyArray2<C64>>> {
        let phases = phases_vec(phases);
        let g = &self.inner.grid;
        let f = py.detach(|| self.inner.source_field(&phases)).map_err(to_py)?;
        let a = ndarray::Array2::from_shape_vec((g.ny, g.nx), f).map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
        Ok(a.into_pyarray(py))
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CoreSimulation>()?;
    m.add_function(wrap_pyfunction!(default_scenario_toml, m)?)?;
    m.add_function(wrap_pyfunction!(normalize_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(load_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(scenario_json, m)?)?;
    Ok(())
}
