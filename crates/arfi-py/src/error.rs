//! The one place where errors become Python exceptions: has-core's, and the bindings' own
//! conversion errors (shaped like the core's: `name: reason`).

use has_core::HasError;
use pyo3::exceptions::{PyFileNotFoundError, PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::PyErr;

pyo3::create_exception!(
    arfi,
    MemoryLimitError,
    PyValueError,
    "A request that would need more memory than this machine has for it (a ValueError): the message names it, what it needs and how to make it smaller."
);

/// `FileNotFound` → `FileNotFoundError`; `Interrupted` → `KeyboardInterrupt`; `TooLarge` →
/// `MemoryLimitError` (a `ValueError`); every other error → `ValueError` (its message starts with
/// the parameter or file it concerns).
pub fn to_py(e: HasError) -> PyErr {
    match e {
        HasError::FileNotFound { .. } => PyFileNotFoundError::new_err(e.to_string()),
        HasError::TooLarge { .. } => MemoryLimitError::new_err(e.to_string()),
        HasError::Interrupted => PyKeyboardInterrupt::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

/// A `ValueError` about parameter `name`, worded as the core words its own.
pub fn invalid(name: impl Into<String>, reason: impl Into<String>) -> PyErr {
    to_py(HasError::invalid(name, reason))
}

/// A worker thread of a long computation panicked: a bug of arfi's, reported as `RuntimeError`.
pub fn worker_panicked() -> PyErr {
    PyRuntimeError::new_err("the computation failed unexpectedly (worker thread panicked)")
}
