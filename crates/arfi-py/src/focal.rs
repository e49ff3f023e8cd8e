//! The focal region as typed results, in the units their names give: the focal metrics in 3-D
//! (`Simulation.focal_metrics`, `Section.focal_metrics`, `Field.focal_metrics`), what a field
//! says at its target (`Field.focus()`) and the hottest place of each tissue (`Field.hottest`).

use crate::field::point_mm;
use crate::results::fields_dict;
use has_core::focal::FocalMetrics;
use has_core::simulation::TissueHottest;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The focal metrics in the units their names give (mm, Pa, mm³, W/cm²): the attributes of a
/// `Field`, the keys of its `focus()` and of `Simulation.focal_metrics`, converted here once.
#[derive(Clone)]
pub(crate) struct MetricsMm {
    pub(crate) focal_peak_mm: [f64; 3],
    pub(crate) focal_peak_pa: f64,
    pub(crate) peak_to_target_mm: f64,
    pub(crate) fwhm_6db_mm: [f64; 2],
    pub(crate) fwhm_6db_across_mm: [f64; 2],
    pub(crate) fwhm_3db_mm: [f64; 2],
    pub(crate) focal_volume_6db_mm3: f64,
    pub(crate) isppa_w_cm2: f64,
    pub(crate) mechanical_index: f64,
    pub(crate) focal_tissue: String,
}

impl From<&FocalMetrics> for MetricsMm {
    fn from(m: &FocalMetrics) -> Self {
        MetricsMm {
            focal_peak_mm: point_mm(m.peak),
            focal_peak_pa: m.peak_pressure,
            peak_to_target_mm: m.peak_to_target() * 1e3,
            fwhm_6db_mm: m.fwhm_6db.map(|v| v * 1e3),
            fwhm_6db_across_mm: m.across_6db.map(|v| v * 1e3),
            fwhm_3db_mm: m.fwhm_3db.map(|v| v * 1e3),
            focal_volume_6db_mm3: m.volume_6db * 1e9,
            isppa_w_cm2: m.isppa * 1e-4,
            mechanical_index: m.mechanical_index,
            focal_tissue: m.tissue.clone(),
        }
    }
}

/// The focal region in 3-D around a target: the focal peak climbed to from the target, its
/// -3/-6 dB extents and -6 dB volume, and I_SPPA and the mechanical index at the peak, in the
/// tissue it lies in. Every attribute but `target_mm` is None when no closed -6 dB region lies
/// around the target inside the grid.
#[pyclass(module = "arfi._core", name = "FocalMetrics", frozen, skip_from_py_object)]
#[derive(Clone)]
pub(crate) struct CoreFocalMetrics {
    target_mm: [f64; 3],
    m: Option<MetricsMm>,
}

impl CoreFocalMetrics {
    /// The metrics `m` around `target` (m).
    pub(crate) fn new(target: [f64; 3], m: Option<MetricsMm>) -> Self {
        CoreFocalMetrics { target_mm: point_mm(target), m }
    }
}

#[pymethods]
impl CoreFocalMetrics {
    /// The attributes `to_dict` writes (the JSON keys of `arfi field` and `arfi predict`).
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 11] = [
        "target_mm",
        "focal_peak_mm",
        "focal_peak_pa",
        "peak_to_target_mm",
        "fwhm_6db_mm",
        "fwhm_6db_across_mm",
        "fwhm_3db_mm",
        "focal_volume_6db_mm3",
        "isppa_w_cm2",
        "mechanical_index",
        "focal_tissue",
    ];

    /// The target the focal peak is climbed to from (mm, transducer frame).
    #[getter]
    fn target_mm(&self) -> [f64; 3] {
        self.target_mm
    }
    /// The focal peak in 3-D near the target, sub-voxel (mm; None when the target lies outside the
    /// grid or its -6 dB region reaches the grid's edge).
    #[getter]
    fn focal_peak_mm(&self) -> Option<[f64; 3]> {
        self.m.as_ref().map(|m| m.focal_peak_mm)
    }
    /// |p| at the focal peak (Pa), in situ.
    #[getter]
    fn focal_peak_pa(&self) -> Option<f64> {
        self.m.as_ref().map(|m| m.focal_peak_pa)
    }
    /// Distance from the target to the focal peak (mm).
    #[getter]
    fn peak_to_target_mm(&self) -> Option<f64> {
        self.m.as_ref().map(|m| m.peak_to_target_mm)
    }
    /// The -6 dB extent along the beam and across it (the mean of two directions), mm.
    #[getter]
    fn fwhm_6db_mm(&self) -> Option<[f64; 2]> {
        self.m.as_ref().map(|m| m.fwhm_6db_mm)
    }
    /// The -6 dB extents across the beam: along the direction nearest x, then nearest y (mm).
    #[getter]
    fn fwhm_6db_across_mm(&self) -> Option<[f64; 2]> {
        self.m.as_ref().map(|m| m.fwhm_6db_across_mm)
    }
    /// The -3 dB extent along the beam and across it (mm).
    #[getter]
    fn fwhm_3db_mm(&self) -> Option<[f64; 2]> {
        self.m.as_ref().map(|m| m.fwhm_3db_mm)
    }
    /// Volume of the -6 dB region around the focal peak (mm³).
    #[getter]
    fn focal_volume_6db_mm3(&self) -> Option<f64> {
        self.m.as_ref().map(|m| m.focal_volume_6db_mm3)
    }
    /// Spatial-peak pulse-average intensity at the focal peak, p²/(2·ρ·c) (W/cm²).
    #[getter]
    fn isppa_w_cm2(&self) -> Option<f64> {
        self.m.as_ref().map(|m| m.isppa_w_cm2)
    }
    /// Mechanical index at the focal peak, p[MPa]/√f[MHz] (in situ).
    #[getter]
    fn mechanical_index(&self) -> Option<f64> {
        self.m.as_ref().map(|m| m.mechanical_index)
    }
    /// The tissue the focal peak lies in.
    #[getter]
    fn focal_tissue(&self) -> Option<String> {
        self.m.as_ref().map(|m| m.focal_tissue.clone())
    }

    /// The metrics as a dict of their attributes (the JSON's keys).
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        match &self.m {
            Some(m) => format!(
                "FocalMetrics({:.4e} Pa at ({:.2}, {:.2}, {:.2}) mm, {:.2} mm from the target)",
                m.focal_peak_pa, m.focal_peak_mm[0], m.focal_peak_mm[1], m.focal_peak_mm[2], m.peak_to_target_mm
            ),
            None => "FocalMetrics(no closed -6 dB region around the target)".to_string(),
        }
    }
}

/// The hottest place of one tissue class over the whole grid: `|p|` (Pa), where (mm), I_SPPA
/// (W/cm²) and the mechanical index there.
#[pyclass(module = "arfi._core", frozen, skip_from_py_object)]
#[derive(Clone)]
pub(crate) struct HottestPlace {
    tissue: String,
    pressure_pa: f64,
    position_mm: [f64; 3],
    isppa_w_cm2: f64,
    mechanical_index: f64,
    is_focus: bool,
}

/// The hottest place of each tissue class, hottest first, each knowing whether it is the focus
/// itself ([`TissueHottest::is_focus`] with the field's focal metrics `focal`).
pub(crate) fn hottest_places(hottest: &[TissueHottest], focal: Option<&FocalMetrics>) -> Vec<HottestPlace> {
    hottest
        .iter()
        .map(|h| HottestPlace {
            tissue: h.tissue.clone(),
            pressure_pa: h.pressure,
            position_mm: point_mm(h.position),
            isppa_w_cm2: h.isppa * 1e-4,
            mechanical_index: h.mechanical_index,
            is_focus: focal.is_some_and(|m| h.is_focus(m)),
        })
        .collect()
}

/// `{tissue: HottestPlace}`, hottest first.
pub(crate) fn hottest_dict<'py>(py: Python<'py>, places: &[HottestPlace]) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for h in places {
        d.set_item(&h.tissue, h.clone())?;
    }
    Ok(d)
}

#[pymethods]
impl HottestPlace {
    /// The attributes `to_dict` writes (the JSON's keys under `hottest`, keyed by tissue).
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 4] = ["pressure_pa", "position_mm", "isppa_w_cm2", "mechanical_index"];

    /// The class: `skull` (bone), `scalp` (the target's soft tissue whose straight path to the
    /// target crosses bone), else the tissue's name (`brain`, `water` …).
    #[getter]
    fn tissue(&self) -> &str {
        &self.tissue
    }
    /// `|p|` there (Pa).
    #[getter]
    fn pressure_pa(&self) -> f64 {
        self.pressure_pa
    }
    /// The grid sample's position (mm, transducer frame).
    #[getter]
    fn position_mm(&self) -> [f64; 3] {
        self.position_mm
    }
    /// Spatial-peak pulse-average intensity there, p²/(2·ρ·c) (W/cm²).
    #[getter]
    fn isppa_w_cm2(&self) -> f64 {
        self.isppa_w_cm2
    }
    /// Mechanical index there, p[MPa]/√f[MHz] (in situ).
    #[getter]
    fn mechanical_index(&self) -> f64 {
        self.mechanical_index
    }
    /// Whether this place is the focus itself: the focal peak's tissue, no hotter than the peak
    /// (a safety check flags it once, as the focal peak).
    #[getter]
    fn is_focus(&self) -> bool {
        self.is_focus
    }

    /// The place as a dict of its attributes (the JSON's keys).
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let [x, y, z] = self.position_mm;
        format!(
            "HottestPlace({}: {:.4e} Pa at ({x:.2}, {y:.2}, {z:.2}) mm, I_SPPA {:.4} W/cm², MI {:.3})",
            self.tissue, self.pressure_pa, self.isppa_w_cm2, self.mechanical_index
        )
    }
}

/// What a field says at its target: the focal metrics in 3-D (`focal_metrics`), the focal peak
/// on the plane (the lobe around the axis's point there) and along the axis, any hotter place
/// than the peak on each (None when the peak is the hottest), and the hottest place of each
/// tissue class (`hottest`, with a volume). Pa and mm; `to_dict()` is `arfi field`'s JSON.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct FieldFocus {
    pub(crate) metrics: CoreFocalMetrics,
    pub(crate) focus: has_core::focal::FieldFocus,
    pub(crate) hottest: Option<Vec<HottestPlace>>,
}

#[pymethods]
impl FieldFocus {
    /// The attributes `to_dict` writes after the focal metrics' keys (the JSON's keys, in order).
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 12] = [
        "plane_peak_pa",
        "plane_peak_x_mm",
        "plane_peak_y_mm",
        "plane_peak_to_axis_mm",
        "plane_hottest_pa",
        "plane_hottest_mm",
        "axis_peak_pa",
        "axis_peak_z_mm",
        "axis_peak_mm",
        "axis_hottest_pa",
        "axis_hottest_mm",
        "hottest",
    ];

    /// The steering target (mm, transducer frame).
    #[getter]
    fn target_mm(&self) -> [f64; 3] {
        self.metrics.target_mm
    }
    /// The focal metrics in 3-D around the target.
    #[getter]
    fn focal_metrics(&self) -> CoreFocalMetrics {
        self.metrics.clone()
    }
    /// |p| at the focal peak on the plane (Pa).
    #[getter]
    fn plane_peak_pa(&self) -> f64 {
        self.focus.plane.pressure
    }
    /// x of the plane's focal peak (mm).
    #[getter]
    fn plane_peak_x_mm(&self) -> f64 {
        self.focus.plane.position[0] * 1e3
    }
    /// y of the plane's focal peak (mm).
    #[getter]
    fn plane_peak_y_mm(&self) -> f64 {
        self.focus.plane.position[1] * 1e3
    }
    /// Distance on the plane from the axis's point to the focal peak (mm).
    #[getter]
    fn plane_peak_to_axis_mm(&self) -> f64 {
        self.focus.peak_to_axis() * 1e3
    }
    /// |p| of a place on the plane hotter than its focal peak (Pa), or None.
    #[getter]
    fn plane_hottest_pa(&self) -> Option<f64> {
        self.focus.plane.hottest.map(|h| h.0)
    }
    /// Where that place lies (x, y mm), or None.
    #[getter]
    fn plane_hottest_mm(&self) -> Option<[f64; 2]> {
        self.focus.plane.hottest.map(|h| point_mm(h.1))
    }
    /// |p| at the focal peak along the axis (Pa).
    #[getter]
    fn axis_peak_pa(&self) -> f64 {
        self.focus.axis.pressure
    }
    /// z of the axis's focal peak (mm).
    #[getter]
    fn axis_peak_z_mm(&self) -> f64 {
        self.focus.axis.position[2] * 1e3
    }
    /// The axis's focal peak (x, y, z mm).
    #[getter]
    fn axis_peak_mm(&self) -> [f64; 3] {
        point_mm(self.focus.axis.position)
    }
    /// |p| of a place on the axis hotter than its focal peak (Pa), or None.
    #[getter]
    fn axis_hottest_pa(&self) -> Option<f64> {
        self.focus.axis.hottest.map(|h| h.0)
    }
    /// Where that place lies (x, y, z mm), or None.
    #[getter]
    fn axis_hottest_mm(&self) -> Option<[f64; 3]> {
        self.focus.axis.hottest.map(|h| point_mm(h.1))
    }
    /// The hottest place of each tissue class, hottest first (`{tissue: HottestPlace}`); None for
    /// a field made without `volume=True`.
    #[getter]
    fn hottest<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.hottest.as_deref().map(|h| hottest_dict(py, h)).transpose()
    }

    /// The JSON of `arfi field`'s focus: the focal metrics' `to_dict()` (`target_mm`, then their
    /// keys, None without a closed focal region), then the attributes in `_fields` (`hottest` as
    /// `{tissue: {pressure_pa, position_mm, isppa_w_cm2, mechanical_index}}`).
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        let d = fields_dict(Bound::new(slf.py(), slf.get().metrics.clone())?.as_any())?;
        d.update(fields_dict(slf.as_any())?.as_mapping())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let [x, y, z] = point_mm(self.focus.axis.position);
        format!(
            "FieldFocus(plane peak {:.4e} Pa, {:.2} mm from the axis; axis peak {:.4e} Pa at ({x:.2}, {y:.2}, {z:.2}) mm)",
            self.focus.plane.pressure,
            self.focus.peak_to_axis() * 1e3,
            self.focus.axis.pressure
        )
    }
}
