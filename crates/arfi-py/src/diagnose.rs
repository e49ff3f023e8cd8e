//! The diagnosis library and results: effects from a dict by the core's parameter table, the
//! library itself, and a diagnosis as a typed result.

use crate::error::{invalid, to_py};
use crate::results::fields_dict;
use has_core::inverse::diagnose::{Alternative, Candidate, Diagnosis, Effect, Effects, Parameter, Step, Value, ValueKind, PARAMETERS};
use has_core::simulation::Simulation;
use ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// [`Effects`] from a dict keyed by the parameter names `diagnose` reports (the core's table;
/// others: ValueError).
pub(crate) fn effects_from_dict(sim: &Simulation, d: &Bound<'_, PyDict>) -> PyResult<Effects> {
    let mut e = Effects::none(sim);
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        let p = Parameter::named(&key).map_err(to_py)?;
        let wrong = |what: &str| invalid(format!("effects[{key:?}]"), format!("must be {what}"));
        let value = match p.kind {
            ValueKind::Number => Value::Number(v.extract().map_err(|_| wrong("a number"))?),
            ValueKind::Numbers => Value::Numbers(v.extract().map_err(|_| wrong("a list of numbers"))?),
            ValueKind::Indices => Value::Indices(v.extract().map_err(|_| wrong("a list of group indices"))?),
        };
        e.set(&key, &value).map_err(to_py)?;
    }
    Ok(e)
}

/// The effect library: the effects in the order ties are broken, and every parameter as
/// `(name, effect, meaning)` (the names `diagnose` reports and `effect_images` accepts).
#[pyfunction]
pub(crate) fn effect_library() -> (Vec<&'static str>, Vec<(&'static str, &'static str, &'static str)>) {
    (Effect::ALL.iter().map(Effect::name).collect(), PARAMETERS.iter().map(|p| (p.name, p.effect.name(), p.meaning)).collect())
}

/// A list of images as NumPy arrays.
fn arrays<'py>(py: Python<'py>, images: &[Array2<f64>]) -> Vec<Bound<'py, PyArray2<f64>>> {
    images.iter().map(|m| m.clone().into_pyarray(py)).collect()
}

/// The model-discrepancy workflow's outcome: the effects added to the model, in order, and the
/// gap before and after. `to_dict` (the JSON of `arfi diagnose`) leaves out the model images.
#[pyclass(module = "arfi._core", name = "Diagnosis", frozen)]
pub(crate) struct CoreDiagnosis(pub(crate) Diagnosis);

#[pymethods]
impl CoreDiagnosis {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 12] = [
        "effects",
        "rejected",
        "cost_initial",
        "cost_final",
        "noise_floor",
        "n_pixels",
        "residual_rms_initial",
        "residual_rms_final",
        "total_evidence",
        "stop",
        "alternative",
        "names",
    ];

    /// The effects added, in order.
    #[getter]
    fn effects(&self) -> Vec<DiagnosisStep> {
        self.0.steps.iter().map(|s| DiagnosisStep { step: s.clone(), n_pixels: self.0.n_pixels }).collect()
    }

    /// Candidates of the last round, none of which passed.
    #[getter]
    fn rejected(&self) -> Vec<EffectCandidate> {
        self.0.rejected.iter().cloned().map(EffectCandidate).collect()
    }

    /// Names of the effects added, in order.
    #[getter]
    fn names(&self) -> Vec<&'static str> {
        self.0.steps.iter().map(|s| s.effect.name()).collect()
    }

    /// Cost of the starting model (rad², every pixel of every image).
    #[getter]
    fn cost_initial(&self) -> f64 {
        self.0.cost_initial
    }

    /// Cost of the final model (rad²).
    #[getter]
    fn cost_final(&self) -> f64 {
        self.0.cost_final
    }

    /// Noise standard deviation from the image backgrounds (rad, RMS over the images).
    #[getter]
    fn noise_floor(&self) -> f64 {
        self.0.noise_floor
    }

    /// Imaged pixels (with MR signal) over all images.
    #[getter]
    fn n_pixels(&self) -> usize {
        self.0.n_pixels
    }

    /// Residual RMS (rad) of the starting model.
    #[getter]
    fn residual_rms_initial(&self) -> f64 {
        self.0.residual_rms().0
    }

    /// Residual RMS (rad) of the final model.
    #[getter]
    fn residual_rms_final(&self) -> f64 {
        self.0.residual_rms().1
    }

    /// The sum of the steps' evidence: `(J_initial - J_final) / sigma² - K·ln n`.
    #[getter]
    fn total_evidence(&self) -> f64 {
        self.0.total_evidence
    }

    /// `"converged"` (no candidate passes the threshold) or `"time limit"` (the effects added
    /// before `time_limit_s` passed).
    #[getter]
    fn stop(&self) -> &'static str {
        self.0.stop.name()
    }

    /// The other set of effects fitted in full when `phase_aberration` competed with simpler
    /// effects; None when there was none.
    #[getter]
    fn alternative(&self) -> Option<AlternativeFit> {
        self.0.alternative.clone().map(AlternativeFit)
    }

    /// The model's image of each measurement before the first step (rad).
    #[getter]
    fn models_initial<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray2<f64>>> {
        arrays(py, &self.0.models_initial)
    }

    /// The final model's image of each measurement (rad).
    #[getter]
    fn models_final<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray2<f64>>> {
        arrays(py, &self.0.models_final)
    }

    /// The result as a dict (the JSON `arfi diagnose` writes), without the model images.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let names: Vec<String> = self.0.steps.iter().map(|s| format!("'{}'", s.effect.name())).collect();
        let (rms0, rms1) = self.0.residual_rms();
        format!(
            "Diagnosis(names=[{}], residual_rms {:.4} -> {:.4} rad, noise_floor={:.4}, stop='{}')",
            names.join(", "),
            rms0,
            rms1,
            self.0.noise_floor,
            self.0.stop.name()
        )
    }
}

/// One effect added to the model.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct DiagnosisStep {
    step: Step,
    n_pixels: usize,
}

#[pymethods]
impl DiagnosisStep {
    /// The attributes `to_dict` writes, in order (the model images left out).
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 8] =
        ["name", "params", "cost_before", "cost_after", "evidence", "residual_rms_after", "equivalent", "candidates"];

    /// The effect added.
    #[getter]
    fn name(&self) -> &'static str {
        self.step.effect.name()
    }

    /// Its fitted parameters, named with their units (the names `effect_images` accepts).
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let params = PyDict::new(py);
        for (k, v) in &self.step.params {
            match v {
                Value::Number(x) => params.set_item(*k, *x)?,
                Value::Numbers(x) => params.set_item(*k, x.clone())?,
                Value::Indices(x) => params.set_item(*k, x.clone())?,
            }
        }
        Ok(params)
    }

    /// Cost before this step (rad²).
    #[getter]
    fn cost_before(&self) -> f64 {
        self.step.cost_before
    }

    /// Cost after this step (rad²).
    #[getter]
    fn cost_after(&self) -> f64 {
        self.step.cost_after
    }

    /// The step's evidence: the BIC gain in units of the noise variance,
    /// `(J_before - J_after) / sigma² - k·ln n`.
    #[getter]
    fn evidence(&self) -> f64 {
        self.step.evidence
    }

    /// Residual RMS (rad) after this step.
    #[getter]
    fn residual_rms_after(&self) -> f64 {
        (self.step.cost_after / self.n_pixels.max(1) as f64).sqrt()
    }

    /// Other effects that explain the data as well (the images cannot tell them apart).
    #[getter]
    fn equivalent(&self) -> Vec<&'static str> {
        self.step.equivalent.iter().map(Effect::name).collect()
    }

    /// Every candidate tried at this step.
    #[getter]
    fn candidates(&self) -> Vec<EffectCandidate> {
        self.step.candidates.iter().cloned().map(EffectCandidate).collect()
    }

    /// The model's image of each measurement after this step (rad).
    #[getter]
    fn models<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray2<f64>>> {
        arrays(py, &self.step.models)
    }

    /// The step as a dict of its attributes, without the model images.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        format!("DiagnosisStep(name='{}', evidence={:.1})", self.step.effect.name(), self.step.evidence)
    }
}

/// One candidate effect's fit at one step.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct EffectCandidate(Candidate);

#[pymethods]
impl EffectCandidate {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 4] = ["name", "cost", "evidence", "failure"];

    /// The candidate effect.
    #[getter]
    fn name(&self) -> &'static str {
        self.0.effect.name()
    }

    /// Best cost (rad²) with the effect fitted; None when it could not be fitted (see `failure`).
    #[getter]
    fn cost(&self) -> Option<f64> {
        self.0.cost.is_finite().then_some(self.0.cost)
    }

    /// `(J_before - J) / sigma² - k·ln n`; None when it could not be fitted.
    #[getter]
    fn evidence(&self) -> Option<f64> {
        self.0.evidence.is_finite().then_some(self.0.evidence)
    }

    /// Why the fit failed; None when it did not.
    #[getter]
    fn failure(&self) -> Option<String> {
        self.0.failure.clone()
    }

    /// The candidate as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        format!("EffectCandidate(name='{}', evidence={:.1})", self.0.effect.name(), self.0.evidence)
    }
}

/// Another set of effects fitted in full: within about 10 of the reported total evidence the
/// data do not decide between them (Kass & Raftery 1995).
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct AlternativeFit(Alternative);

#[pymethods]
impl AlternativeFit {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 3] = ["effects", "total_evidence", "cost"];

    /// The effects of the other path, in order.
    #[getter]
    fn effects(&self) -> Vec<&'static str> {
        self.0.effects.iter().map(Effect::name).collect()
    }

    /// Its total evidence (BIC units).
    #[getter]
    fn total_evidence(&self) -> f64 {
        self.0.total_evidence
    }

    /// Its final cost (rad²).
    #[getter]
    fn cost(&self) -> f64 {
        self.0.cost
    }

    /// The alternative as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        format!("AlternativeFit(effects={:?}, total_evidence={:.1})", self.effects(), self.0.total_evidence)
    }
}
