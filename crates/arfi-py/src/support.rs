//! What the images determine of a per-element estimate without a prior, and the focus of the
//! alternatives it is judged against (the core's `Support`).

use crate::results::fields_dict;
use has_core::inverse::estimate::workflow::Support;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Per element without a prior: what the images determine of the estimate and the focus (of the
/// ideal) of each choice. The estimate is recommended when `expected_focus` reaches both
/// alternatives and its search converged; else the uncorrected beam, or the group fit when the
/// model puts it 0.2 of the ideal above the uncorrected beam.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct EstimateSupport(pub(crate) Support);

#[pymethods]
impl EstimateSupport {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 6] =
        ["determined_phases", "expected_focus", "uncorrected_focus", "groups_focus", "determined", "converged"];

    /// Independent combinations of phases the images determine below the spread of a uniform
    /// phase (degrees of freedom for signal of the linearised posterior, `tr(F·C)`).
    #[getter]
    fn determined_phases(&self) -> f64 {
        self.0.determined_phases
    }

    /// Expected focus after the estimate's correction, on the linearised posterior with
    /// independent uniform phases before the images (conservative).
    #[getter]
    fn expected_focus(&self) -> f64 {
        self.0.expected_focus
    }

    /// The uncorrected beam's focus on the model at the estimate (an in-focus image without known
    /// phases shows it).
    #[getter]
    fn uncorrected_focus(&self) -> f64 {
        self.0.uncorrected_focus
    }

    /// The focus the default-group fit's correction leaves on the model at the estimate.
    #[getter]
    fn groups_focus(&self) -> f64 {
        self.0.groups_focus
    }

    /// `expected_focus` reaches both alternatives (else the estimate is `underdetermined`).
    #[getter]
    fn determined(&self) -> bool {
        self.0.determines()
    }

    /// The search converged (it did not stop at its evaluation or time limit).
    #[getter]
    fn converged(&self) -> bool {
        self.0.converged
    }

    /// The support as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let s = &self.0;
        format!(
            "EstimateSupport(determined_phases={:.1}, expected_focus={:.3}, uncorrected_focus={:.3}, groups_focus={:.3}, converged={})",
            s.determined_phases,
            s.expected_focus,
            s.uncorrected_focus,
            s.groups_focus,
            if s.converged { "True" } else { "False" }
        )
    }
}
