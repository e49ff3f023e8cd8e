//! The hybrid cost (paper Eq. 4) as a Python object.

use crate::error::{invalid, to_py};
use has_core::inverse::cost::HybridCost;
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// The hybrid cost of a set of images, for users' own optimisers and for checking it in NumPy.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct CoreCostModel {
    pub(crate) cost: Arc<HybridCost>,
    pub(crate) noise: f64,
}

impl CoreCostModel {
    /// The phases, checked: one finite value per group.
    fn phases(&self, phases: PyReadonlyArray1<'_, f64>) -> PyResult<Vec<f64>> {
        let p = phases.as_array().to_vec();
        if p.len() != self.cost.n_groups {
            return Err(invalid("phases", format!("has {} values for {} groups", p.len(), self.cost.n_groups)));
        }
        if let Some(x) = p.iter().find(|x| !x.is_finite()) {
            return Err(invalid("phases", format!("must be finite, got {x}")));
        }
        Ok(p)
    }
}

#[pymethods]
impl CoreCostModel {
    #[getter]
    fn n_groups(&self) -> usize {
        self.cost.n_groups
    }

    #[getter]
    fn n_pixels(&self) -> usize {
        self.cost.n_pixels()
    }

    #[getter]
    fn fit_amplitude(&self) -> bool {
        self.cost.fit_amplitude
    }

    #[getter]
    fn noise_rad(&self) -> f64 {
        self.noise
    }

    /// `J(phases)`, phases in rad, one per group.
    fn cost(&self, py: Python<'_>, phases: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
        let p = self.phases(phases)?;
        Ok(py.detach(|| self.cost.cost(&p)))
    }

    /// `(J, ∂J/∂phases)`.
    fn cost_and_gradient<'py>(&self, py: Python<'py>, phases: PyReadonlyArray1<'py, f64>) -> PyResult<(f64, Bound<'py, PyArray1<f64>>)> {
        let p = self.phases(phases)?;
        let (j, g) = py.detach(|| self.cost.cost_and_gradient(&p));
        Ok((j, g.into_pyarray(py)))
    }

    /// The amplitude scale at `phases` (1 unless `fit_amplitude`).
    fn scale(&self, py: Python<'_>, phases: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
        let p = self.phases(phases)?;
        Ok(py.detach(|| self.cost.scale(&p)))
    }

    /// Per image: the kernels of its masked pixels (`diagonal` (n, G), `upper` (n, G(G-1)/2)
    /// complex, row by row), `measured_rad` (n,) and `offset_rad` (G,).
    fn terms<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.cost
            .terms
            .iter()
            .map(|t| {
                let (diag, upper) = t.kernel.kernels_at(&t.mask).map_err(to_py)?;
                let d = PyDict::new(py);
                d.set_item("diagonal", diag.into_pyarray(py))?;
                d.set_item("upper", upper.into_pyarray(py))?;
                d.set_item("measured_rad", t.measured.clone().into_pyarray(py))?;
                d.set_item("offset_rad", t.offset.clone().into_pyarray(py))?;
                Ok(d)
            })
            .collect()
    }
}
