//! Scenario files: parse, validate and write them back as complete TOML or JSON.

use crate::error::{invalid, to_py};
use crate::results::CoreCalibration;
use has_core::physics::mr::MrGeometry;
use has_core::scenario::{Outline, Scenario};
use ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use std::path::Path;

pub(crate) fn parse_scenario(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<Scenario> {
    let base = base_dir.map(Path::new);
    match format {
        "toml" => Scenario::from_toml(text, base),
        "json" => Scenario::from_json(text, base),
        f => return Err(invalid("format", format!("must be 'toml' or 'json', got '{f}'"))),
    }
    .map_err(to_py)
}

/// A validated scenario, parsed once and handed to simulations and predictions as it is (what
/// `arfi.Scenario` holds). Values in file units; `base_dir` resolves its relative paths.
#[pyclass(module = "arfi._core", name = "CoreScenario", frozen)]
pub(crate) struct CoreScenario {
    pub(crate) inner: Scenario,
}

#[pymethods]
impl CoreScenario {
    /// Parses `text` (`format` = "toml" | "json") and checks its values together
    /// (`Scenario::resolve`: the CT is read once here).
    #[new]
    #[pyo3(signature = (text, format="toml", base_dir=None))]
    fn new(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<Self> {
        let inner = parse_scenario(text, format, base_dir)?;
        inner.resolve().map_err(to_py)?;
        Ok(CoreScenario { inner })
    }

    /// The embedded default: the paper's phantom experiment.
    #[staticmethod]
    fn default() -> Self {
        CoreScenario { inner: Scenario::default() }
    }

    /// Complete TOML, every default written out; with `chosen_grid` the `[grid]` it resolves to
    /// as well.
    #[pyo3(signature = (chosen_grid=false))]
    fn to_toml(&self, chosen_grid: bool) -> PyResult<String> {
        if chosen_grid {
            has_core::simulation::with_chosen_grid(&self.inner).and_then(|s| s.to_toml()).map_err(to_py)
        } else {
            self.inner.to_toml().map_err(to_py)
        }
    }

    /// Complete JSON, every default written out.
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(to_py)
    }

    /// The head of a `[ct]` scenario with the CT's bone, driven with the reference steering
    /// (`Scenario::with_ct_bone`).
    fn with_ct_bone(&self) -> PyResult<Self> {
        Ok(CoreScenario { inner: self.inner.with_ct_bone().map_err(to_py)? })
    }

    /// The scenario's outline: its transducer and `[mr]` checked, its CT and grid not read.
    fn outline(&self) -> PyResult<CoreOutline> {
        Ok(CoreOutline { inner: self.inner.outline().map_err(to_py)? })
    }

    #[getter]
    fn name(&self) -> &str {
        &self.inner.name
    }

    /// The folder its relative paths resolve against (None: the working directory).
    #[getter]
    fn base_dir(&self) -> Option<String> {
        self.inner.base_dir.as_ref().map(|p| p.display().to_string())
    }

    fn __repr__(&self) -> String {
        format!("CoreScenario(name={:?})", self.inner.name)
    }
}

/// Shape of the MR image volume of `mr` (NIfTI order, a singleton along the slice normal).
pub(crate) fn mr_volume_shape(mr: &MrGeometry) -> (usize, usize, usize) {
    let s = mr.volume_shape();
    (s[0], s[1], s[2])
}

/// The 4 x 4 affine (mm, transducer frame) of `mr`'s image volume as a NumPy array.
pub(crate) fn mr_affine_array<'py>(py: Python<'py>, mr: &MrGeometry) -> Bound<'py, PyArray2<f64>> {
    let a = mr.affine_mm();
    Array2::from_shape_fn((4, 4), |(r, c)| a[r][c]).into_pyarray(py)
}

/// What a scenario fixes before a simulation is built (elements, default groups, focus, MR
/// geometry), with the simulation's own rules for phases and images: inputs are checked against
/// it before the build.
#[pyclass(module = "arfi._core", name = "ScenarioOutline", frozen)]
pub(crate) struct CoreOutline {
    inner: Outline,
}

#[pymethods]
impl CoreOutline {
    /// Number of elements of the array.
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.n_elements()
    }
    /// Number of the array's default groups.
    #[getter]
    fn n_default_groups(&self) -> usize {
        has_core::grouping::count(self.inner.default_groups())
    }
    /// The steering target (mm, transducer frame).
    #[getter]
    fn focus_mm(&self) -> [f64; 3] {
        self.inner.focus().map(|v| v * 1e3)
    }
    /// Shape of the MR image volume (a singleton along the slice normal).
    #[getter]
    fn mr_volume_shape(&self) -> (usize, usize, usize) {
        mr_volume_shape(self.inner.mr())
    }
    /// The MR image's 4 x 4 affine (mm, transducer frame).
    #[getter]
    fn mr_affine_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        mr_affine_array(py, self.inner.mr())
    }
    /// Phases added to the steering, per element or per group (`groups` contiguous groups, or
    /// the default ones), as one per element; a ValueError naming `name` otherwise.
    #[pyo3(signature = (phases, name="phases", groups=None))]
    fn element_phases<'py>(
        &self,
        py: Python<'py>,
        phases: PyReadonlyArray1<'py, f64>,
        name: &str,
        groups: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(self.inner.element_phases(name, &phases.as_array().to_vec(), groups).map_err(to_py)?.into_pyarray(py))
    }
    /// An image's known phases (per element, per group or per default group) as one per
    /// element; a ValueError naming `name` otherwise.
    #[pyo3(signature = (known, name="known", groups=None))]
    fn known_per_element<'py>(
        &self,
        py: Python<'py>,
        known: PyReadonlyArray1<'py, f64>,
        name: &str,
        groups: Option<usize>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(self.inner.known_per_element(name, &known.as_array().to_vec(), groups).map_err(to_py)?.into_pyarray(py))
    }
    /// A prior's predicted phases as the estimate with `groups` groups takes them (per element,
    /// per group, and for per-element estimates per default group); a ValueError naming `name`.
    #[pyo3(signature = (prior, name="prior", groups=None))]
    fn check_prior(&self, prior: PyReadonlyArray1<'_, f64>, name: &str, groups: Option<usize>) -> PyResult<()> {
        self.inner.check_prior(name, &prior.as_array().to_vec(), groups).map_err(to_py)
    }
    /// Checks that `calibration` was fitted for this scenario and frequency (where it records
    /// them), before anything is built; an error names `name`.
    #[pyo3(signature = (calibration, name="calibration"))]
    fn check_calibration(&self, calibration: &CoreCalibration, name: &str) -> PyResult<()> {
        calibration.0.check_for_outline(&self.inner).map_err(|e| to_py(e.naming(name)))
    }
    /// Per-element values (e.g. transmissions): a ValueError naming `name` unless one per element.
    #[pyo3(signature = (n_values, name))]
    fn check_per_element(&self, n_values: usize, name: &str) -> PyResult<()> {
        self.inner.check_per_element(name, n_values).map_err(to_py)
    }
    /// An MR-ARFI image file's shape (rows, columns) and 4 x 4 affine (mm) against the
    /// scenario's MR geometry; a ValueError naming `name` otherwise.
    #[pyo3(signature = (shape, affine_mm, name="image"))]
    fn check_image(&self, shape: [usize; 2], affine_mm: PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<()> {
        let a = affine_mm.as_array();
        if a.dim() != (4, 4) {
            return Err(invalid(name, format!("affine must be 4 x 4, got {:?}", a.dim())));
        }
        let affine: [[f64; 4]; 4] = std::array::from_fn(|r| std::array::from_fn(|c| a[[r, c]]));
        self.inner.mr().check_file(name, shape, &affine).map_err(to_py)
    }
    fn __repr__(&self) -> String {
        format!("ScenarioOutline({} elements, MR {:?})", self.inner.n_elements(), self.inner.mr().matrix)
    }
}

/// `groups` contiguous groups of `n_elements` by element number (`group = e·G / n`), the map a
/// simulation with that many groups uses; a ValueError naming `groups` outside 1..=n_elements.
#[pyfunction]
pub(crate) fn contiguous_groups<'py>(py: Python<'py>, n_elements: usize, groups: usize) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let g = has_core::grouping::contiguous(n_elements, groups).map_err(to_py)?;
    Ok(g.into_iter().map(|v| v as i64).collect::<Vec<_>>().into_pyarray(py))
}
