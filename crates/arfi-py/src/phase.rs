//! Phase arithmetic of the core for NumPy arrays: wrapping and the paper's phase error.

use crate::error::invalid;
use has_core::phase;
use numpy::{IntoPyArray, PyArrayDyn, PyReadonlyArray1, PyReadonlyArrayDyn};
use pyo3::prelude::*;

/// Phases (any shape) wrapped to (-pi, pi].
#[pyfunction]
pub(crate) fn wrap_phases<'py>(py: Python<'py>, phases: PyReadonlyArrayDyn<'py, f64>) -> Bound<'py, PyArrayDyn<f64>> {
    phases.as_array().mapv(phase::wrap).into_pyarray(py)
}

/// RMS of the wrapped difference `estimate - truth` after removing the best common offset (the
/// paper's phase error).
#[pyfunction]
pub(crate) fn phase_error(estimate: PyReadonlyArray1<'_, f64>, truth: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
    let (a, b) = (estimate.as_slice()?, truth.as_slice()?);
    if a.is_empty() {
        return Err(invalid("estimate", "has no phases"));
    }
    if a.len() != b.len() {
        return Err(invalid("truth", format!("needs one phase per estimated phase ({}), got {}", a.len(), b.len())));
    }
    Ok(phase::phase_error(a, b))
}
