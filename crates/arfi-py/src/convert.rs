//! NumPy inputs copied into the core's owned types (before any work leaves the GIL).

use crate::error::invalid;
use has_core::inverse::cost::Measurement;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

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
