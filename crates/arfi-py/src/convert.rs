//! Python and NumPy inputs copied into the core's owned types (before any work leaves the GIL);
//! a value of the wrong kind is a `ValueError` naming its parameter.

use crate::error::invalid;
use has_core::inverse::cost::Measurement;
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyString};

/// Points `name` (mm, shape (n, 3), finite) in metres.
pub(crate) fn points_m(points_mm: &PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<Vec<[f64; 3]>> {
    let p = points_mm.as_array();
    if p.ncols() != 3 || p.iter().any(|v| !v.is_finite()) {
        return Err(invalid(
            name,
            format!("must be points of three finite numbers each (x, y, z in mm), shape (n, 3); got shape {:?}", p.shape()),
        ));
    }
    Ok(p.rows().into_iter().map(|r| [r[0] * 1e-3, r[1] * 1e-3, r[2] * 1e-3]).collect())
}

pub(crate) fn phases_vec(phases: Option<PyReadonlyArray1<'_, f64>>) -> Vec<f64> {
    phases.map(|p| p.as_array().to_vec()).unwrap_or_default()
}

/// Images paired with their known phases, copied out of NumPy.
pub(crate) fn measurements(
    images: Vec<PyReadonlyArray2<'_, f64>>,
    known: Vec<Option<PyReadonlyArray1<'_, f64>>>,
) -> PyResult<Vec<Measurement>> {
    if images.len() != known.len() {
        return Err(invalid("known", format!("need one entry (or None) per image, got {} for {} images", known.len(), images.len())));
    }
    Ok(images.iter().zip(known).map(|(i, k)| Measurement { image: i.as_array().to_owned(), known: phases_vec(k) }).collect())
}

/// Python's `None` reads as absent.
fn given<'a, 'py>(value: Option<&'a Bound<'py, PyAny>>) -> Option<&'a Bound<'py, PyAny>> {
    value.filter(|v| !v.is_none())
}

/// A count: a Python or NumPy integer >= 0 (not a bool); `None` when not given.
pub(crate) fn count(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<usize>> {
    let Some(v) = given(value) else { return Ok(None) };
    let bad = || invalid(name, format!("must be an integer >= 0, got {}", repr(v)));
    if v.is_instance_of::<PyBool>() {
        return Err(bad());
    }
    v.extract::<usize>().map(Some).map_err(|_| bad())
}

/// A finite real number (a Python or NumPy number, not a bool, string or complex); `None` when
/// not given.
pub(crate) fn number(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<f64>> {
    let Some(v) = given(value) else { return Ok(None) };
    let bad = || invalid(name, format!("must be a finite number, got {}", repr(v)));
    if v.is_instance_of::<PyBool>() || v.is_instance_of::<PyString>() || v.is_instance_of::<PyBytes>() || complex(v)? {
        return Err(bad());
    }
    match v.extract::<f64>() {
        Ok(x) if x.is_finite() => Ok(Some(x)),
        _ => Err(bad()),
    }
}

/// Real, finite values from an array-like of one dimension (`rows`: or two, a 1-D one being one
/// row); `None` when not given.
fn real<'py>(value: Option<&Bound<'py, PyAny>>, name: &str, rows: bool) -> PyResult<Option<Vec<Vec<f64>>>> {
    let Some(v) = given(value) else { return Ok(None) };
    if complex(v)? {
        return Err(invalid(name, "must be real, got complex values"));
    }
    let np = v.py().import("numpy")?;
    let kwargs = PyDict::new(v.py());
    kwargs.set_item("dtype", "float64")?;
    let not_numeric = || invalid(name, format!("not numeric ({})", repr(v)));
    let a = np.call_method("asarray", (v,), Some(&kwargs)).map_err(|_| not_numeric())?;
    let a: PyReadonlyArrayDyn<'py, f64> = a.extract().map_err(|_| not_numeric())?;
    let a = a.as_array();
    if a.iter().any(|x| !x.is_finite()) {
        return Err(invalid(name, "contains NaN or infinite values"));
    }
    let shape = format!("({})", a.shape().iter().map(|n| n.to_string()).collect::<Vec<_>>().join(", "));
    match (a.ndim(), rows) {
        (1, _) => Ok(Some(vec![a.iter().copied().collect()])),
        (2, true) => Ok(Some(a.outer_iter().map(|r| r.iter().copied().collect()).collect())),
        (_, false) => Err(invalid(name, format!("must be one-dimensional, got shape {shape}"))),
        (_, true) => Err(invalid(name, format!("must have shape (modes, elements), got shape {shape}"))),
    }
}

/// A flag: Python's or NumPy's `True`/`False` (not an integer); `None` when not given.
pub(crate) fn flag(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<bool>> {
    let Some(v) = given(value) else { return Ok(None) };
    v.extract::<bool>().map(Some).map_err(|_| invalid(name, format!("must be True or False, got {}", repr(v))))
}

/// A string; `None` when not given.
pub(crate) fn text(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<String>> {
    let Some(v) = given(value) else { return Ok(None) };
    v.extract::<String>().map(Some).map_err(|_| invalid(name, format!("must be a string, got {}", repr(v))))
}

/// Phases (rad): a 1-D array-like of real numbers; `None` when not given.
pub(crate) fn phases(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Vec<f64>>> {
    Ok(real(value, name, false)?.map(|mut rows| rows.remove(0)))
}

/// Rows of real numbers: a 2-D array-like (a 1-D one is one row); `None` when not given.
pub(crate) fn rows(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Vec<Vec<f64>>>> {
    real(value, name, true)
}

/// Names: a list of strings or one comma-separated string; empty when not given.
pub(crate) fn names(value: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Vec<String>> {
    let Some(v) = given(value) else { return Ok(Vec::new()) };
    if let Ok(s) = v.extract::<String>() {
        return Ok(s.split(',').map(str::trim).filter(|n| !n.is_empty()).map(String::from).collect());
    }
    v.extract::<Vec<String>>()
        .map_err(|_| invalid(name, format!("must be names (a list of strings or one comma-separated string), got {}", repr(v))))
}

/// Whether `v` holds complex numbers (NumPy's `iscomplexobj`).
fn complex(v: &Bound<'_, PyAny>) -> PyResult<bool> {
    v.py().import("numpy")?.call_method1("iscomplexobj", (v,))?.is_truthy()
}

/// `repr(v)`, for messages.
fn repr(v: &Bound<'_, PyAny>) -> String {
    v.repr().map(|r| r.to_string()).unwrap_or_else(|_| "?".into())
}
