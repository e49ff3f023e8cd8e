//! The diagnosis library and results: effects from a dict by the core's parameter table, the
//! library itself, and a diagnosis as a dict.

use crate::error::{invalid, to_py};
use has_core::inverse::diagnose::{Diagnosis, Effect, Effects, Parameter, Value, ValueKind, PARAMETERS};
use has_core::simulation::Simulation;
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

/// The diagnosis as the dict `Diagnosis` reads (the JSON of `arfi diagnose`).
pub(crate) fn diagnosis_dict<'py>(py: Python<'py>, r: &Diagnosis) -> PyResult<Bound<'py, PyDict>> {
    let candidates = |cands: &[has_core::inverse::diagnose::Candidate]| -> PyResult<Vec<Bound<'py, PyDict>>> {
        cands
            .iter()
            .map(|c| {
                let d = PyDict::new(py);
                d.set_item("name", c.effect.name())?;
                // A candidate that could not be fitted has no cost or evidence (JSON null).
                let finite = |x: f64| x.is_finite().then_some(x);
                d.set_item("cost", finite(c.cost))?;
                d.set_item("evidence", finite(c.evidence))?;
                d.set_item("failure", c.failure.clone())?;
                Ok(d)
            })
            .collect()
    };
    let images =
        |imgs: &[ndarray::Array2<f64>]| -> Vec<Bound<'py, PyArray2<f64>>> { imgs.iter().map(|m| m.clone().into_pyarray(py)).collect() };
    let n = r.n_pixels.max(1) as f64;
    let mut steps = Vec::new();
    for step in &r.steps {
        let e = PyDict::new(py);
        e.set_item("name", step.effect.name())?;
        let params = PyDict::new(py);
        for (k, v) in &step.params {
            match v {
                Value::Number(x) => params.set_item(*k, *x)?,
                Value::Numbers(x) => params.set_item(*k, x.clone())?,
                Value::Indices(x) => params.set_item(*k, x.clone())?,
            }
        }
        e.set_item("params", params)?;
        e.set_item("cost_before", step.cost_before)?;
        e.set_item("cost_after", step.cost_after)?;
        e.set_item("evidence", step.evidence)?;
        e.set_item("residual_rms_after", (step.cost_after / n).sqrt())?;
        e.set_item("equivalent", step.equivalent.iter().map(|x| x.name()).collect::<Vec<_>>())?;
        e.set_item("candidates", candidates(&step.candidates)?)?;
        e.set_item("models", images(&step.models))?;
        steps.push(e);
    }
    let d = PyDict::new(py);
    let (rms0, rms1) = r.residual_rms();
    d.set_item("effects", steps)?;
    d.set_item("rejected", candidates(&r.rejected)?)?;
    d.set_item("cost_initial", r.cost_initial)?;
    d.set_item("cost_final", r.cost_final)?;
    d.set_item("noise_floor", r.noise_floor)?;
    d.set_item("n_pixels", r.n_pixels)?;
    d.set_item("residual_rms_initial", rms0)?;
    d.set_item("residual_rms_final", rms1)?;
    d.set_item("total_evidence", r.total_evidence)?;
    d.set_item("stop", r.stop.name())?;
    let alternative = match &r.alternative {
        Some(a) => {
            let x = PyDict::new(py);
            x.set_item("effects", a.effects.iter().map(|e| e.name()).collect::<Vec<_>>())?;
            x.set_item("total_evidence", a.total_evidence)?;
            x.set_item("cost", a.cost)?;
            Some(x)
        }
        None => None,
    };
    d.set_item("alternative", alternative)?;
    d.set_item("models_initial", images(&r.models_initial))?;
    d.set_item("models_final", images(&r.models_final))?;
    Ok(d)
}
