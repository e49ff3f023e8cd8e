//! What to estimate with: the core's `EstimateRequest` as a typed, validated Python value. The
//! options are the core's (`has_core::inverse::estimate::workflow::OPTIONS`: name, kind, meaning):
//! this binding converts each by its kind, so an option added to the core needs no code here, and
//! `_core.pyi` is generated from the same list (`python python/tests/stubgen.py`).

use crate::convert::{count, flag, names, number, phases, rows, text};
use crate::error::{invalid, to_py};
use crate::results::fields_dict;
use has_core::inverse::estimate::workflow::{option_spec, EstimateRequest, OptionKind, OptionValue, OPTIONS};
use numpy::{IntoPyArray, PyArray2};
use pyo3::exceptions::PyAttributeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList};

/// Options of a hybrid estimate, by keyword (each optional: `None` or absent is the default; an
/// unknown or ill-formed one is a `ValueError` naming it), checked when made by the core's rules.
/// Each reads back as an attribute in the unit of its name; `EstimateOptions.describe()` says
/// what each means.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct EstimateOptions(pub(crate) EstimateRequest);

/// A Python value as option `name` of `kind` (`None`: not given).
fn from_py(v: &Bound<'_, PyAny>, name: &str, kind: OptionKind) -> PyResult<Option<OptionValue>> {
    let v = Some(v);
    Ok(match kind {
        OptionKind::Flag => flag(v, name)?.map(OptionValue::Flag),
        OptionKind::Count => count(v, name)?.map(|n| OptionValue::Count(n as u64)),
        OptionKind::Number => number(v, name)?.map(OptionValue::Number),
        OptionKind::Text => text(v, name)?.map(OptionValue::Text),
        OptionKind::Names => v.filter(|v| !v.is_none()).map(|_| names(v, name).map(OptionValue::Names)).transpose()?,
        OptionKind::Values => phases(v, name)?.map(OptionValue::Values),
        OptionKind::Rows => rows(v, name)?.map(OptionValue::Rows),
    })
}

/// An option's value as Python reads it (arrays for values and rows).
fn to_py_value<'py>(py: Python<'py>, value: Option<OptionValue>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        None => py.None().into_bound(py),
        Some(OptionValue::Flag(b)) => PyBool::new(py, b).to_owned().into_any(),
        Some(OptionValue::Count(n)) => n.into_pyobject(py)?.into_any(),
        Some(OptionValue::Number(x)) => x.into_pyobject(py)?.into_any(),
        Some(OptionValue::Text(t)) => t.into_pyobject(py)?.into_any(),
        Some(OptionValue::Names(n)) => PyList::new(py, n)?.into_any(),
        Some(OptionValue::Values(v)) => v.into_pyarray(py).into_any(),
        Some(OptionValue::Rows(r)) => PyArray2::from_vec2(py, &r).map_err(|e| invalid(name, e.to_string()))?.into_any(),
    })
}

#[pymethods]
impl EstimateOptions {
    /// The options `to_dict` writes and `replace` takes, in order.
    #[classattr]
    fn _fields() -> Vec<&'static str> {
        OPTIONS.iter().map(|o| o.name).collect()
    }

    /// Each option as `(name, kind, optional, meaning)`: what the stubs and `describe` are made
    /// from.
    #[classattr]
    fn _options() -> Vec<(&'static str, &'static str, bool, &'static str)> {
        OPTIONS.iter().map(|o| (o.name, o.kind.name(), o.optional, o.doc)).collect()
    }

    #[new]
    #[pyo3(signature = (**options))]
    fn new(options: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut given: Vec<(&str, OptionValue)> = Vec::new();
        for (k, v) in options.into_iter().flat_map(|d| d.iter()) {
            let spec = option_spec(&k.extract::<String>()?).map_err(to_py)?;
            if let Some(value) = from_py(&v, spec.name, spec.kind)? {
                given.push((spec.name, value));
            }
        }
        Ok(EstimateOptions(EstimateRequest::from_options(&given).map_err(to_py)?))
    }

    /// Option `name`'s value, in the unit of its name (`None`: unset, the default).
    fn __getattr__<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
        if option_spec(name).is_err() {
            return Err(PyAttributeError::new_err(format!("'EstimateOptions' object has no attribute '{name}'")));
        }
        to_py_value(py, self.0.option(name).map_err(to_py)?, name)
    }

    fn __dir__(slf: &Bound<'_, Self>) -> PyResult<Vec<String>> {
        let mut names: Vec<String> = slf.get_type().dir()?.extract()?;
        names.extend(OPTIONS.iter().map(|o| o.name.to_string()));
        Ok(names)
    }

    /// What each option means, one line each: `name (kind): meaning`.
    #[staticmethod]
    fn describe() -> String {
        OPTIONS.iter().map(|o| format!("{} ({}): {}", o.name, o.kind.name(), o.doc)).collect::<Vec<_>>().join("\n")
    }

    /// The same options with `changes` (keyword options as the constructor takes them), checked
    /// again by the constructor (an unknown name included).
    #[pyo3(signature = (**changes))]
    fn replace<'py>(slf: &Bound<'py, Self>, changes: Option<&Bound<'py, PyDict>>) -> PyResult<Bound<'py, PyAny>> {
        let options = fields_dict(slf.as_any())?;
        if let Some(c) = changes {
            options.update(c.as_mapping())?;
        }
        slf.get_type().call((), Some(&options))
    }

    /// The options as a dict (arrays as lists), the keyword arguments that make them again.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    /// The options that differ from the defaults (the method always; arrays by their size).
    fn __repr__(&self) -> PyResult<String> {
        let default = EstimateRequest::default();
        let mut parts = Vec::new();
        for o in OPTIONS {
            let value = self.0.option(o.name).map_err(to_py)?;
            if o.name != "method" && value == default.option(o.name).map_err(to_py)? {
                continue;
            }
            let shown = match value {
                None => "None".to_string(),
                Some(OptionValue::Flag(b)) => if b { "True" } else { "False" }.to_string(),
                Some(OptionValue::Count(n)) => n.to_string(),
                Some(OptionValue::Number(x)) => format!("{x:?}"),
                Some(OptionValue::Text(t)) => format!("'{t}'"),
                Some(OptionValue::Names(n)) => format!("[{}]", n.iter().map(|x| format!("'{x}'")).collect::<Vec<_>>().join(", ")),
                Some(OptionValue::Values(v)) => format!("<{} values>", v.len()),
                Some(OptionValue::Rows(r)) => format!("<{} rows>", r.len()),
            };
            parts.push(format!("{}={shown}", o.name));
        }
        Ok(format!("EstimateOptions({})", parts.join(", ")))
    }
}
