//! What the images determine of a per-element estimate without a prior, and the focus of the
//! alternatives it is judged against (the core's `Support`); with a prior, whether the images
//! agree with the prediction as the prior states it (the core's `PriorCheck`).

use crate::results::fields_dict;
use has_core::inverse::estimate::workflow::{PriorCheck, Support};
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

/// Per element with a prior: the images' `chi²` at the prediction against its spread over images
/// of truths the prior allows (a prior-predictive check, by seeded Monte Carlo). A `conflict`
/// (`z` above 3 and an excess above 0.2 per pixel) means the model cannot form the images about
/// the prediction or the prediction errs by more than its std: the search's move would absorb
/// that, so the prediction is recommended.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct EstimatePriorCheck(pub(crate) PriorCheck);

#[pymethods]
impl EstimatePriorCheck {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 8] =
        ["chi2_prediction", "null_mean", "null_std", "z", "excess_per_pixel", "conflict", "conflict_z", "draws"];

    /// `chi²` of the images at the prediction (cost over the noise's variance).
    #[getter]
    fn chi2_prediction(&self) -> f64 {
        self.0.chi2_prediction
    }

    /// Mean of the same `chi²` over images of truths drawn from the prior.
    #[getter]
    fn null_mean(&self) -> f64 {
        self.0.null_mean
    }

    /// Its standard deviation.
    #[getter]
    fn null_std(&self) -> f64 {
        self.0.null_std
    }

    /// `(chi2_prediction - null_mean) / null_std`.
    #[getter]
    fn z(&self) -> f64 {
        self.0.z
    }

    /// `(chi2_prediction - null_mean) / n_pixels`.
    #[getter]
    fn excess_per_pixel(&self) -> f64 {
        self.0.excess_per_pixel
    }

    /// The images conflict with the prediction as the prior states it.
    #[getter]
    fn conflict(&self) -> bool {
        self.0.conflict
    }

    /// The threshold on `z` the conflict was judged by (`prior_conflict_z`).
    #[getter]
    fn conflict_z(&self) -> f64 {
        self.0.conflict_z
    }

    /// Draws of the prior made.
    #[getter]
    fn draws(&self) -> usize {
        self.0.draws
    }

    /// The check as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let c = &self.0;
        format!(
            "EstimatePriorCheck(chi2_prediction={:.1}, null_mean={:.1}, null_std={:.1}, z={:.2}, excess_per_pixel={:.3}, conflict={})",
            c.chi2_prediction,
            c.null_mean,
            c.null_std,
            c.z,
            c.excess_per_pixel,
            if c.conflict { "True" } else { "False" }
        )
    }
}
