//! Pressure volumes as NumPy arrays: `|p|` in 3-D with its 4 x 4 affine (mm), on a box of the
//! simulation grid or on a CT's voxels.

use crate::error::{invalid, to_py};
use has_core::physics::grid::Grid;
use has_core::physics::propagation::Window;
use has_core::simulation::{window_affine, window_of_box, CtPressureVolume, PressureVolume};
use ndarray::{Array2, Array3, ArrayView3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyArrayMethods};
use pyo3::prelude::*;

/// A pressure volume as NumPy arrays: `|p|` (z, y, x or the CT's k, j, i) and its affine (mm).
pub(crate) type VolumeArrays<'py> = (Bound<'py, PyArray3<f32>>, Bound<'py, PyArray2<f64>>);

/// The 4 x 4 homogeneous matrix of an affine map's 3 x 4 rows, times `scale` (e.g. m -> mm).
pub(crate) fn affine_4x4(rows: &[[f64; 4]; 3], scale: f64) -> Array2<f64> {
    let mut a = Array2::<f64>::eye(4);
    for (r, row) in rows.iter().enumerate() {
        for (c, x) in row.iter().enumerate() {
            a[[r, c]] = x * scale;
        }
    }
    a
}

/// The box of `g` within `box_mm` (x0, x1, y0, y1, z0, z1 in mm); `None`: none asked for.
pub(crate) fn window_of_box_mm(g: &Grid, box_mm: Option<Vec<f64>>) -> PyResult<Option<Window>> {
    let Some(b) = box_mm else { return Ok(None) };
    if b.len() != 6 {
        return Err(invalid("box_mm", format!("must be six numbers (x0, x1, y0, y1, z0, z1 in mm), got {}", b.len())));
    }
    window_of_box(g, [b[0], b[2], b[4]].map(|v| v * 1e-3), [b[1], b[3], b[5]].map(|v| v * 1e-3)).map(Some).map_err(to_py)
}

/// A volume on a box of the grid as NumPy arrays (affine in the transducer frame, mm).
pub(crate) fn grid_arrays(py: Python<'_>, v: PressureVolume) -> VolumeArrays<'_> {
    let shape = (v.window.planes.len(), v.window.rows.len(), v.window.cols.len());
    let pressure = Array3::from_shape_vec(shape, v.pressure).expect("one value per voxel of the box");
    (pressure.into_pyarray(py), affine_4x4(&v.affine, 1e3).into_pyarray(py))
}

/// `magnitude`, `|p|` on the whole grid `g` (plane, row, column), as a read-only NumPy array that
/// borrows it (no copy: a whole hemisphere's volume is hundreds of megabytes) with `owner` as its
/// base object, and its affine in the transducer frame (mm).
///
/// # Safety
/// `magnitude` must stay where it is and unchanged for as long as `owner` lives.
pub(crate) unsafe fn borrowed_grid_arrays<'py>(g: &Grid, magnitude: &[f32], owner: Bound<'py, PyAny>) -> PyResult<VolumeArrays<'py>> {
    let py = owner.py();
    let view = ArrayView3::from_shape((g.nz, g.ny, g.nx), magnitude).map_err(|e| invalid("volume", e.to_string()))?;
    // SAFETY: the caller keeps `magnitude` in place and unchanged while `owner`, the array's base
    // object, lives; the array is made read-only before Python sees it.
    let array = unsafe { PyArray3::borrow_from_array(&view, owner) };
    let readonly = array.readwrite().make_nonwriteable();
    Ok(((*readonly).clone(), affine_4x4(&window_affine(g, &Window::whole(g)), 1e3).into_pyarray(py)))
}

/// A volume on a CT's voxels as NumPy arrays (the CT's RAS affine, mm).
pub(crate) fn ct_arrays(py: Python<'_>, v: CtPressureVolume) -> VolumeArrays<'_> {
    let pressure = Array3::from_shape_vec((v.shape[0], v.shape[1], v.shape[2]), v.pressure).expect("one value per CT voxel");
    (pressure.into_pyarray(py), affine_4x4(&v.ras_affine, 1.0).into_pyarray(py))
}
