//! The one place where has-core errors become Python exceptions.

use has_core::HasError;
use pyo3::exceptions::{PyFileNotFoundError, PyKeyboardInterrupt, PyValueError};
use pyo3::PyErr;

/// `FileNotFound` → `FileNotFoundError`; `Interrupted` → `KeyboardInterrupt`; every other
/// error → `ValueError` (its message starts with the parameter or file it concerns).
pub fn to_py(e: HasError) -> PyErr {
    match e {
        HasError::FileNotFound { .. } => PyFileNotFoundError::new_err(e.to_string()),
        HasError::Interrupted => PyKeyboardInterrupt::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}
