//! The focal region in 3-D as a typed result: the focal metrics of `Simulation.focal_metrics`
//! and `Section.focal_metrics` (and the keys of `Field.focus()`), in the units their names give.

use crate::field::point_mm;
use crate::results::fields_dict;
use has_core::focal::FocalMetrics;
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

/// Sets the focal metrics' keys of `d` from `m`, each None when there are none (no closed -6 dB
/// region around the target).
pub(crate) fn metrics_items(d: &Bound<'_, PyDict>, m: Option<&MetricsMm>) -> PyResult<()> {
    d.set_item("focal_peak_mm", m.map(|m| m.focal_peak_mm))?;
    d.set_item("focal_peak_pa", m.map(|m| m.focal_peak_pa))?;
    d.set_item("peak_to_target_mm", m.map(|m| m.peak_to_target_mm))?;
    d.set_item("fwhm_6db_mm", m.map(|m| m.fwhm_6db_mm))?;
    d.set_item("fwhm_6db_across_mm", m.map(|m| m.fwhm_6db_across_mm))?;
    d.set_item("fwhm_3db_mm", m.map(|m| m.fwhm_3db_mm))?;
    d.set_item("focal_volume_6db_mm3", m.map(|m| m.focal_volume_6db_mm3))?;
    d.set_item("isppa_w_cm2", m.map(|m| m.isppa_w_cm2))?;
    d.set_item("mechanical_index", m.map(|m| m.mechanical_index))?;
    d.set_item("focal_tissue", m.map(|m| m.focal_tissue.as_str()))?;
    Ok(())
}

/// The focal region in 3-D around a target: the focal peak climbed to from the target, its
/// -3/-6 dB extents and -6 dB volume, and I_SPPA and the mechanical index at the peak, in the
/// tissue it lies in. Every attribute but `target_mm` is None when no closed -6 dB region lies
/// around the target inside the grid.
#[pyclass(module = "arfi._core", name = "FocalMetrics", frozen)]
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
