//! The core's analyses of plain NumPy arrays that the reports use: the lobe around a point and an
//! MR-ARFI image's noise.

use crate::error::invalid;
use has_core::focal::connected_region as connected_region_core;
use has_core::physics::mr::noise_floor;
use numpy::{IntoPyArray, PyArrayDyn, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;

/// The samples of `values` (any number of dimensions) at or above `level` connected to `start`
/// (an index per axis) through faces: a boolean array of the same shape, empty (all False) when
/// `start` lies below `level`.
#[pyfunction]
pub(crate) fn connected_region<'py>(
    py: Python<'py>,
    values: PyReadonlyArrayDyn<'py, f64>,
    start: Vec<i64>,
    level: f64,
) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
    let values = values.as_array();
    let inside = start.len() == values.ndim() && start.iter().zip(values.shape()).all(|(&i, &n)| i >= 0 && (i as u64) < n as u64);
    if !inside {
        return Err(invalid("start", format!("must be an index inside the array's shape {:?}, got {start:?}", values.shape())));
    }
    let start: Vec<usize> = start.iter().map(|&i| i as usize).collect();
    Ok(connected_region_core(&values, &start, level).into_pyarray(py))
}

/// The noise (rad) of an MR-ARFI image (n_u, n_v) from its background: the standard deviation of
/// white Gaussian noise from the median absolute deviation of the image filtered by the 3 x 3
/// mask of second differences along u times v (`1.4826 · MAD / 6`, blind to a signal linear
/// along u or v, such as a background phase, and to the few windows on the focus); windows with a
/// NaN pixel (no signal) skipped.
#[pyfunction]
pub(crate) fn image_noise_rad(image: PyReadonlyArray2<'_, f64>) -> f64 {
    noise_floor(&image.as_array().to_owned(), &[0..0, 0..0])
}
