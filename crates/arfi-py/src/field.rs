//! Typed beam results: a plane and the axis of one drive ([`CoreField`]) and the x–z section of
//! several ([`CoreSection`]), their arrays made NumPy arrays once (an attribute returns the same
//! array each time) with lengths in mm.

use crate::error::{invalid, to_py};
use crate::focal::{hottest_dict, hottest_places, CoreFocalMetrics, FieldFocus, HottestPlace, MetricsMm};
use crate::volume::{borrowed_grid_arrays, ct_arrays, grid_arrays, window_of_box_mm};
use has_core::focal::FocalMetrics;
use has_core::physics::ct::CtMedium;
use has_core::physics::grid::Grid;
use has_core::physics::medium::Medium;
use has_core::physics::propagation::Window;
use has_core::simulation::{
    check_ct_volume, crop_volume, intensity_in_ct, intensity_on_window, resample_into_ct, window_affine, PressureVolume,
};
use has_core::{Field, Section, Simulation};
use num_complex::Complex64 as C64;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyUntypedArrayMethods, ToPyArray};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::OnceLock;

/// Millimetres of lengths in metres.
fn mm(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x * 1e3).collect()
}

/// Complex pressure amplitude (Pa) on one plane and along the beam's axis (the line from the
/// array's centre through the target): the arrays `arfi field` writes to its `.npz`.
#[pyclass(module = "arfi._core", name = "Field", frozen)]
pub(crate) struct CoreField {
    pressure: Py<PyArray2<C64>>,
    x_mm: Py<PyArray1<f64>>,
    y_mm: Py<PyArray1<f64>>,
    axis_pressure: Py<PyArray1<C64>>,
    axis_x_mm: Py<PyArray1<f64>>,
    axis_y_mm: Py<PyArray1<f64>>,
    axis_z_mm: Py<PyArray1<f64>>,
    /// The core's field (its arrays copied into the NumPy ones above, which a user may change;
    /// its `magnitude`, the volume, kept here alone).
    field: Field,
    /// The field's focal metrics in the units of the attributes.
    metrics: Option<MetricsMm>,
    target: [f64; 3],
    focus: OnceLock<has_core::focal::FieldFocus>,
    /// The grid the volume lies on; the medium (the intensity's ρ and c; its CT, shared, what the
    /// volume may be laid on) and the frequency (Hz): copies, so that a field does not keep its
    /// simulation's plan alive.
    grid: Grid,
    medium: Medium,
    frequency: f64,
}

impl CoreField {
    /// The field `f` of a beam of `sim` (steered to its focus).
    pub(crate) fn new(py: Python<'_>, f: Field, sim: &Simulation) -> Self {
        let axis = |k: usize| f.axis_xy.iter().map(|p| p[k] * 1e3).collect::<Vec<f64>>().into_pyarray(py).unbind();
        CoreField {
            x_mm: mm(&f.x).into_pyarray(py).unbind(),
            y_mm: mm(&f.y).into_pyarray(py).unbind(),
            axis_x_mm: axis(0),
            axis_y_mm: axis(1),
            axis_z_mm: mm(&f.axis_z).into_pyarray(py).unbind(),
            pressure: f.pressure.to_pyarray(py).unbind(),
            axis_pressure: f.axis_pressure.to_pyarray(py).unbind(),
            target: sim.focus,
            focus: OnceLock::new(),
            metrics: f.metrics.as_ref().map(MetricsMm::from),
            field: f,
            grid: sim.grid.clone(),
            medium: sim.medium.clone(),
            frequency: sim.frequency,
        }
    }

    /// `|p|` on every grid sample, kept by a field made with `volume=True`.
    fn magnitude(&self) -> PyResult<&[f32]> {
        match self.field.volume.as_ref() {
            Some(volume) => Ok(&volume.magnitude),
            None => Err(invalid("volume", "this field kept no volume: make it with sim.field(phases, volume=True)")),
        }
    }

    /// The CT of a `[ct]` scenario, refused for `in_ct` with `box_mm` or without a CT.
    fn ct_for(&self, box_mm: &Option<Vec<f64>>) -> PyResult<&CtMedium> {
        if box_mm.is_some() {
            return Err(invalid("box_mm", "crops the volume on the simulation grid; in_ct takes the CT's own voxel grid"));
        }
        match self.medium.ct.as_deref() {
            Some(ct) => Ok(ct),
            None => Err(invalid("in_ct", "needs a scenario with a [ct] section: the CT is the grid it is resampled into")),
        }
    }

    /// The hottest place of each tissue class, with a volume.
    fn hottest_places(&self) -> Option<Vec<HottestPlace>> {
        self.field.volume.as_ref().map(|v| hottest_places(&v.hottest, self.field.metrics.as_ref()))
    }

    /// The plane's and the axis's focal peaks, found on the first call.
    fn plane_and_axis(&self) -> &has_core::focal::FieldFocus {
        self.focus.get_or_init(|| self.field.focus(self.target))
    }
}

/// Intensities in W/m² as W/cm², in place.
fn w_cm2(mut values: Vec<f32>) -> Vec<f32> {
    values.iter_mut().for_each(|v| *v *= 1e-4);
    values
}

/// A position in metres as millimetres.
pub(crate) fn point_mm<const N: usize>(p: [f64; N]) -> [f64; N] {
    p.map(|v| v * 1e3)
}

#[pymethods]
impl CoreField {
    /// Complex pressure amplitude (Pa) on the plane, shape (ny, nx).
    #[getter]
    fn pressure(&self, py: Python<'_>) -> Py<PyArray2<C64>> {
        self.pressure.clone_ref(py)
    }

    /// x of each column (mm).
    #[getter]
    fn x_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.x_mm.clone_ref(py)
    }

    /// y of each row (mm).
    #[getter]
    fn y_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.y_mm.clone_ref(py)
    }

    /// z of the plane (mm).
    #[getter]
    fn z_mm(&self) -> f64 {
        self.field.z * 1e3
    }

    /// Complex pressure amplitude (Pa) along the axis, one sample per grid plane.
    #[getter]
    fn axis_pressure(&self, py: Python<'_>) -> Py<PyArray1<C64>> {
        self.axis_pressure.clone_ref(py)
    }

    /// z of each axis sample (mm).
    #[getter]
    fn axis_z_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.axis_z_mm.clone_ref(py)
    }

    /// x of each axis sample (mm; 0 for a target on the z axis).
    #[getter]
    fn axis_x_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.axis_x_mm.clone_ref(py)
    }

    /// y of each axis sample (mm).
    #[getter]
    fn axis_y_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.axis_y_mm.clone_ref(py)
    }

    /// Pressure amplitude on every element face (Pa).
    #[getter]
    fn surface_pressure_pa(&self) -> f64 {
        self.field.surface_pressure
    }

    /// The steering target (mm, transducer frame).
    #[getter]
    fn target_mm(&self) -> (f64, f64, f64) {
        let t = point_mm(self.target);
        (t[0], t[1], t[2])
    }

    /// The field's focal metrics in 3-D around the target: the focal peak, its -3/-6 dB extents
    /// and -6 dB volume, I_SPPA and MI there (the attributes' values; `focus()` holds them too).
    #[getter]
    fn focal_metrics(&self) -> CoreFocalMetrics {
        CoreFocalMetrics::new(self.target, self.metrics.clone())
    }

    /// The hottest place of each tissue class over the whole grid, hottest first
    /// (`{tissue: HottestPlace}`: `skull` for bone, `scalp` for the target's soft tissue whose
    /// straight path to the target crosses bone, else the tissue's name). None for a field made
    /// without `volume=True`.
    #[getter]
    fn hottest<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.hottest_places().as_deref().map(|h| hottest_dict(py, h)).transpose()
    }

    /// What the field says at its target (a `FieldFocus`: the focal metrics in 3-D, the focal
    /// peaks on the plane and along the axis, any hotter place on each, and the hottest place of
    /// each tissue); its `to_dict()` is the JSON of `arfi field`. Pa and mm.
    fn focus(&self) -> FieldFocus {
        FieldFocus {
            metrics: CoreFocalMetrics::new(self.target, self.metrics.clone()),
            focus: self.plane_and_axis().clone(),
            hottest: self.hottest_places(),
        }
    }

    /// `|p|` (Pa) of this beam in 3-D, from the march that made the field (with `volume=True`), as an
    /// `arfi.PressureVolume`: on the simulation grid (transducer frame), cropped to `box_mm` (x0,
    /// x1, y0, y1, z0, z1 in mm) if given; with `in_ct` (a `[ct]` scenario) resampled into the
    /// CT's voxel grid with the CT's own RAS affine. The whole grid's is a read-only view of the
    /// field's own memory (no second copy of the grid).
    #[pyo3(signature = (box_mm=None, in_ct=false))]
    fn pressure_volume<'py>(slf: &Bound<'py, Self>, box_mm: Option<Vec<f64>>, in_ct: bool) -> PyResult<Bound<'py, PyAny>> {
        let (py, this) = (slf.py(), slf.get());
        let (magnitude, grid) = (this.magnitude()?, &this.grid);
        let ((pressure, affine), frame) = if in_ct {
            let ct = this.ct_for(&box_mm)?;
            check_ct_volume(ct, "pressure", 0).map_err(to_py)?;
            (ct_arrays(py, py.detach(|| resample_into_ct(grid, magnitude, ct))), "ct")
        } else {
            match window_of_box_mm(grid, box_mm)? {
                Some(window) if window != Window::whole(grid) => {
                    (grid_arrays(py, crop_volume(grid, magnitude, Some(window))), "transducer")
                }
                // SAFETY: the volume lives in this frozen field, which nothing changes or moves
                // while it lives, and the field is the array's base object.
                _ => (unsafe { borrowed_grid_arrays(grid, magnitude, slf.clone().into_any()) }?, "transducer"),
            }
        };
        py.import("arfi.io.volume")?.getattr("PressureVolume")?.call1((pressure, affine, frame))
    }

    /// The pulse-average intensity I = |p|² / (2·ρ·c) (W/cm²; its largest value is I_SPPA) of
    /// this beam in 3-D, ρ and c the medium's at each voxel (the CT's conversion where it holds
    /// tissue), as an `arfi.IntensityVolume`: on the simulation grid (transducer frame), cropped to `box_mm` (x0, x1, y0, y1, z0, z1 in mm) if
    /// given; with `in_ct` (a `[ct]` scenario) on the CT's voxel grid with its own RAS affine, from
    /// |p| resampled there (as `pressure_volume(in_ct=True)`) and ρ, c at each CT voxel.
    #[pyo3(signature = (box_mm=None, in_ct=false))]
    fn intensity_volume<'py>(slf: &Bound<'py, Self>, box_mm: Option<Vec<f64>>, in_ct: bool) -> PyResult<Bound<'py, PyAny>> {
        let (py, this) = (slf.py(), slf.get());
        let (magnitude, grid, medium, f) = (this.magnitude()?, &this.grid, &this.medium, this.frequency);
        let ((intensity, affine), frame) = if in_ct {
            let ct = this.ct_for(&box_mm)?;
            check_ct_volume(ct, "intensity", 4 * ct.voxel_grid().0.iter().product::<usize>() as u64).map_err(to_py)?;
            let mut v = py.detach(|| resample_into_ct(grid, magnitude, ct));
            v.pressure = w_cm2(py.detach(|| intensity_in_ct(medium, f, &v)).map_err(to_py)?);
            (ct_arrays(py, v), "ct")
        } else {
            let window = window_of_box_mm(grid, box_mm)?.unwrap_or_else(|| Window::whole(grid));
            let values = w_cm2(py.detach(|| intensity_on_window(medium, f, grid, magnitude, &window)).map_err(to_py)?);
            let affine = window_affine(grid, &window);
            (grid_arrays(py, PressureVolume { window, pressure: values, affine }), "transducer")
        };
        py.import("arfi.io.volume")?.getattr("IntensityVolume")?.call1((intensity, affine, frame))
    }

    /// Writes [`pressure_volume`](Self::pressure_volume)`(box_mm, in_ct)` as NIfTI (`.nii` or
    /// `.nii.gz`) at `path`, atomically.
    #[pyo3(signature = (path, box_mm=None, in_ct=false))]
    fn to_nifti(slf: &Bound<'_, Self>, path: Bound<'_, PyAny>, box_mm: Option<Vec<f64>>, in_ct: bool) -> PyResult<()> {
        Self::pressure_volume(slf, box_mm, in_ct)?.call_method1("to_nifti", (path,))?;
        Ok(())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let shape = self.pressure.bind(py).shape().to_vec();
        format!("Field(z_mm={:.2}, plane {} x {}, {} axis samples)", self.field.z * 1e3, shape[1], shape[0], self.axis_z_mm.bind(py).len())
    }
}

/// The beam on the x–z plane nearest `y_mm`: complex pressure amplitude (Pa) of each drive and the
/// sound speed (m/s) the march used, every grid plane from the source plane on.
#[pyclass(module = "arfi._core", name = "Section", frozen)]
pub(crate) struct CoreSection {
    pressure: Py<PyArray3<C64>>,
    sound_speed_m_s: Py<PyArray2<f64>>,
    x_mm: Py<PyArray1<f64>>,
    z_mm: Py<PyArray1<f64>>,
    y: f64,
    /// Each drive's focal metrics around the target (m) they were sought around, if asked for.
    focal_metrics: Option<([f64; 3], Vec<Option<MetricsMm>>)>,
}

impl CoreSection {
    /// The section `s`, with each drive's focal metrics around `target` (m) if made with them.
    pub(crate) fn new(py: Python<'_>, s: Section, focal_metrics: Option<([f64; 3], Vec<Option<FocalMetrics>>)>) -> Self {
        CoreSection {
            x_mm: mm(&s.x).into_pyarray(py).unbind(),
            z_mm: mm(&s.z).into_pyarray(py).unbind(),
            y: s.y,
            pressure: s.pressure.into_pyarray(py).unbind(),
            sound_speed_m_s: s.sound_speed.into_pyarray(py).unbind(),
            focal_metrics: focal_metrics.map(|(t, m)| (t, m.iter().map(|m| m.as_ref().map(MetricsMm::from)).collect())),
        }
    }
}

#[pymethods]
impl CoreSection {
    /// Complex pressure amplitude (Pa), shape (drives, nz, nx), in the order the phases were given.
    #[getter]
    fn pressure(&self, py: Python<'_>) -> Py<PyArray3<C64>> {
        self.pressure.clone_ref(py)
    }

    /// Sound speed (m/s) of the slab each plane was reached through, shape (nz, nx).
    #[getter]
    fn sound_speed_m_s(&self, py: Python<'_>) -> Py<PyArray2<f64>> {
        self.sound_speed_m_s.clone_ref(py)
    }

    /// x of each column (mm).
    #[getter]
    fn x_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.x_mm.clone_ref(py)
    }

    /// z of each row (mm): every grid plane from the source plane on.
    #[getter]
    fn z_mm(&self, py: Python<'_>) -> Py<PyArray1<f64>> {
        self.z_mm.clone_ref(py)
    }

    /// y of the section (mm): the grid row nearest the one asked for.
    #[getter]
    fn y_mm(&self) -> f64 {
        self.y * 1e3
    }

    /// Each drive's focal metrics in 3-D around the target asked for ([`CoreFocalMetrics`]), from
    /// the section's own march; None when the section was made without a target.
    #[getter]
    fn focal_metrics(&self) -> Option<Vec<CoreFocalMetrics>> {
        let (target, metrics) = self.focal_metrics.as_ref()?;
        Some(metrics.iter().map(|m| CoreFocalMetrics::new(*target, m.clone())).collect())
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        let shape = self.pressure.bind(py).shape().to_vec();
        format!("Section(y_mm={:.2}, {} drives, {} planes x {} columns)", self.y * 1e3, shape[0], shape[1], shape[2])
    }
}
