//! `CoreSimulation`: a scenario made ready to simulate, and every computation on it.

use crate::convert::{measurements, phases_vec, points_m};
use crate::cost::CoreCostModel;
use crate::diagnose::{effects_from_dict, CoreDiagnosis};
use crate::error::{invalid, to_py};
use crate::estimate_options::EstimateOptions;
use crate::field::{CoreField, CoreSection};
use crate::focal::{hottest_dict, hottest_places, CoreFocalMetrics, MetricsMm};
use crate::interrupt::{run_interruptible, run_with_progress};
use crate::mode_fit::{CoreModeFit, CoreModesFit};
use crate::plan::{CoreGrid, CorePropagation};
use crate::results::{CoreCalibration, CoreEstimate};
use crate::scenario::CoreScenario;
use crate::scenario::{mr_affine_array, mr_volume_shape};
use crate::volume::{ct_arrays, grid_arrays, window_of_box_mm, VolumeArrays};
use has_core::control::Control;
use has_core::inverse::calibrate::calibrate;
use has_core::inverse::cost::build_model;
use has_core::inverse::diagnose::{diagnose, effect_images, DiagnoseOptions};
use has_core::inverse::element::{known_per_element, BasisCache};
use has_core::inverse::estimate::condense;
use has_core::inverse::estimate::workflow::estimate_aberration_with;
use has_core::inverse::prior::mode_fit::fit_mode;
use has_core::inverse::prior::modes_fit::fit_modes_with_noise;
use has_core::physics::aberration::SkullScreen;
use has_core::physics::source::SourceModel;
use has_core::simulation::{ExternalField, Simulation};
use num_complex::Complex64 as C64;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// A scenario made ready to simulate (grid chosen, beam steered, HAS plan built).
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct CoreSimulation {
    inner: Simulation,
    /// The element basis of the last per-element estimate, reused by the next one on the same
    /// pixel box (the object is immutable, so the simulation cannot change under it).
    basis: BasisCache,
}

impl From<Simulation> for CoreSimulation {
    fn from(inner: Simulation) -> Self {
        CoreSimulation { inner, basis: BasisCache::default() }
    }
}

/// A simulation's array projected onto its grid's first plane (with the elements' projected
/// planes once a field made them), to build another simulation of the same array on the same
/// grid without projecting it again (`Simulation::new_reusing`).
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct CoreSourceModel {
    inner: SourceModel,
}

#[pymethods]
impl CoreSourceModel {
    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.len()
    }
    fn __repr__(&self) -> String {
        format!("SourceModel({} elements)", self.inner.len())
    }
}

#[pymethods]
impl CoreSimulation {
    #[new]
    #[pyo3(signature = (scenario, source=None))]
    fn new(py: Python<'_>, scenario: &CoreScenario, source: Option<PyRef<'_, CoreSourceModel>>) -> PyResult<Self> {
        let s = &scenario.inner;
        let kept = source.map(|k| k.inner.clone());
        let inner = py
            .detach(|| match &kept {
                Some(k) => Simulation::new_reusing(s, k),
                None => Simulation::new(s),
            })
            .map_err(to_py)?;
        Ok(inner.into())
    }

    /// The simulation's source model, to share with another simulation of the same array.
    fn source_model(&self) -> CoreSourceModel {
        CoreSourceModel { inner: self.inner.source.clone() }
    }

    #[getter]
    fn n_elements(&self) -> usize {
        self.inner.n_elements()
    }
    #[getter]
    fn n_groups(&self) -> usize {
        self.inner.n_groups
    }
    /// Number of the array's default groups (16 on the paper's quadrant array: element // 64).
    #[getter]
    fn n_default_groups(&self) -> usize {
        has_core::grouping::count(&self.inner.transducer.default_groups())
    }
    /// Scale from broadened force density to ARFI phase (rad·m³/N); a ValueError says why a
    /// scenario has none (no radiation force in the MR slice).
    #[getter]
    fn amplitude(&self) -> PyResult<f64> {
        self.inner.amplitude().map_err(to_py)
    }
    #[getter]
    fn frequency_hz(&self) -> f64 {
        self.inner.frequency
    }
    /// How changes of medium are crossed (see `Propagation`).
    #[getter]
    fn propagation(&self) -> CorePropagation {
        self.inner.propagation().into()
    }
    #[getter]
    fn noise_rad(&self) -> f64 {
        self.inner.noise
    }
    #[getter]
    fn mask_fraction(&self) -> f64 {
        self.inner.mask_fraction
    }
    #[getter]
    fn focus_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.focus.iter().map(|v| v * 1e3).collect::<Vec<_>>().into_pyarray(py)
    }
    #[getter]
    fn steering_phases_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.steering.clone().into_pyarray(py)
    }
    #[getter]
    fn groups<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        self.inner.groups.iter().map(|&g| g as i64).collect::<Vec<_>>().into_pyarray(py)
    }
    /// Element centres (mm), shape (n_elements, 3).
    #[getter]
    fn element_positions_mm<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> =
            self.inner.transducer.elements.iter().map(|e| e.reference_point().iter().map(|v| v * 1e3).collect()).collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }
    /// The grid the march runs on (see `Grid`).
    #[getter]
    fn grid(&self) -> CoreGrid {
        CoreGrid::of(&self.inner)
    }
    /// MR geometry: affine (4x4, mm), volume shape, plane.
    #[getter]
    fn mr_affine_mm<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        mr_affine_array(py, &self.inner.mr)
    }
    #[getter]
    fn mr_volume_shape(&self) -> (usize, usize, usize) {
        mr_volume_shape(&self.inner.mr)
    }
    #[getter]
    fn mr_plane(&self) -> &'static str {
        self.inner.mr.plane.name()
    }

    /// Pressure on the plane nearest `z_mm` (default: the focus) and along the axis; with
    /// `volume`, also `|p|` on the whole grid and the hottest place of each tissue.
    #[pyo3(signature = (phases=None, z_mm=None, volume=false))]
    fn field(&self, py: Python<'_>, phases: Option<PyReadonlyArray1<'_, f64>>, z_mm: Option<f64>, volume: bool) -> PyResult<CoreField> {
        let phases = phases_vec(phases);
        let z = z_mm.map(|z| z * 1e-3);
        let f =
            py.detach(|| if volume { self.inner.field_with_volume(&phases, z) } else { self.inner.field(&phases, z) }).map_err(to_py)?;
        Ok(CoreField::new(py, f, &self.inner))
    }

    /// The field of pressure computed by another engine on this simulation's grid: `plane`
    /// (complex Pa, (ny, nx)) on the grid plane nearest `z_mm`, `axis` (complex Pa, one per
    /// plane, on the beam's axis) and `magnitude` (|p| in Pa, (nz, ny, nx)); its focal metrics and
    /// hottest places found as for a march.
    fn field_from_volume(
        &self,
        py: Python<'_>,
        plane: PyReadonlyArray2<'_, C64>,
        z_mm: f64,
        axis: PyReadonlyArray1<'_, C64>,
        magnitude: PyReadonlyArray3<'_, f32>,
    ) -> PyResult<CoreField> {
        let external = ExternalField {
            plane: plane.as_array().to_owned(),
            z: z_mm * 1e-3,
            axis: axis.as_array().to_vec(),
            magnitude: magnitude.as_array().iter().copied().collect(),
        };
        let f = py.detach(|| self.inner.field_from_volume(external)).map_err(to_py)?;
        Ok(CoreField::new(py, f, &self.inner))
    }

    /// The focal metrics in 3-D of the beam driven with `phases` around `target_mm` (mm, transducer
    /// frame; default the focus), from one march that records only the box around it: the keys of
    /// `Field.focus()`'s metrics and `target_mm` (each None without a closed -6 dB region).
    #[pyo3(signature = (phases=None, target_mm=None))]
    fn focal_metrics(
        &self,
        py: Python<'_>,
        phases: Option<PyReadonlyArray1<'_, f64>>,
        target_mm: Option<[f64; 3]>,
    ) -> PyResult<CoreFocalMetrics> {
        let phases = phases_vec(phases);
        let target = target_mm.map_or(self.inner.focus, |t| t.map(|v| v * 1e-3));
        let metrics = py.detach(|| self.inner.focal_metrics(&phases, target)).map_err(to_py)?;
        Ok(CoreFocalMetrics::new(target, metrics.as_ref().map(MetricsMm::from)))
    }

    /// The focal metrics around `target_mm` (mm, transducer frame) and the hottest place of each
    /// tissue class (`{tissue: HottestPlace}`, hottest first) of the beam driven with `phases`,
    /// from one march that keeps |p| on the whole grid.
    fn exposure_at<'py>(
        &self,
        py: Python<'py>,
        phases: Option<PyReadonlyArray1<'_, f64>>,
        target_mm: [f64; 3],
    ) -> PyResult<(CoreFocalMetrics, Bound<'py, PyDict>)> {
        let phases = phases_vec(phases);
        let target = target_mm.map(|v| v * 1e-3);
        let (metrics, hottest) = py.detach(|| self.inner.exposure_at(&phases, target)).map_err(to_py)?;
        let places = hottest_places(&hottest, metrics.as_ref());
        Ok((CoreFocalMetrics::new(target, metrics.as_ref().map(MetricsMm::from)), hottest_dict(py, &places)?))
    }

    /// `|p|` (Pa, float32, shape (nz, ny, nx): z, y, x) of the beam on the box `box_mm` (x0, x1,
    /// y0, y1, z0, z1 in mm, transducer frame; default the whole grid), and the 4 x 4 affine (mm)
    /// from voxel (i, j, k) = (x, y, z index) to the transducer frame.
    #[pyo3(signature = (phases=None, box_mm=None))]
    fn pressure_volume<'py>(
        &self,
        py: Python<'py>,
        phases: Option<PyReadonlyArray1<'_, f64>>,
        box_mm: Option<Vec<f64>>,
    ) -> PyResult<VolumeArrays<'py>> {
        let phases = phases_vec(phases);
        let window = window_of_box_mm(&self.inner.grid, box_mm)?;
        let v = py.detach(|| self.inner.pressure_volume(&phases, window)).map_err(to_py)?;
        Ok(grid_arrays(py, v))
    }

    /// Whether the medium holds a CT (a `[ct]` scenario).
    #[getter]
    fn has_ct(&self) -> bool {
        self.inner.medium.ct.is_some()
    }

    /// `|p|` (Pa, float32, shape (nk, nj, ni): the CT's voxels, k slowest) of the beam resampled
    /// into the voxel grid of the scenario's CT, and the CT's 4 x 4 affine to RAS+ mm.
    #[pyo3(signature = (phases=None))]
    fn pressure_volume_in_ct<'py>(&self, py: Python<'py>, phases: Option<PyReadonlyArray1<'_, f64>>) -> PyResult<VolumeArrays<'py>> {
        let phases = phases_vec(phases);
        let v = py.detach(|| self.inner.pressure_volume_in_ct(&phases)).map_err(to_py)?;
        Ok(ct_arrays(py, v))
    }

    /// The name of the tissue at each point (mm, transducer frame, shape (n, 3)): "bone" or the
    /// soft tissue's material where a CT holds tissue, else the material's name.
    fn tissue_at(&self, points_mm: PyReadonlyArray2<'_, f64>) -> PyResult<Vec<String>> {
        Ok(points_m(&points_mm, "points_mm")?.into_iter().map(|[x, y, z]| self.inner.medium.tissue_at(x, y, z)).collect())
    }

    /// The tissue class of each point (mm, transducer frame, shape (n, 3)) as the hottest places
    /// name it: "skull" for bone, "scalp" for the target's own tissue whose path to the target
    /// crosses bone, else the tissue's name (of the grid sample nearest the point).
    fn tissue_classes(&self, points_mm: PyReadonlyArray2<'_, f64>) -> PyResult<Vec<String>> {
        self.inner.tissue_classes(&points_m(&points_mm, "points_mm")?).map_err(to_py)
    }

    /// The medium at each point (mm, transducer frame, shape (n, 3)): `sound_speed_m_s` and
    /// `density_kg_m3` at the point (the CT's conversion of its voxel where a CT holds tissue),
    /// `attenuation_np_m` (amplitude, at the scenario's frequency), `shear_sound_speed_m_s` and
    /// `shear_attenuation_np_m` (0 in a fluid) and `hu`, the CT's value there (NaN outside the CT or without one).
    fn properties_at<'py>(&self, py: Python<'py>, points_mm: PyReadonlyArray2<'_, f64>) -> PyResult<Bound<'py, PyDict>> {
        let points = points_m(&points_mm, "points_mm")?;
        let m = &self.inner.medium;
        let props: Vec<_> = points.iter().map(|&[x, y, z]| m.properties_at(x, y, z, self.inner.frequency)).collect();
        let hu: Vec<f64> = points.iter().map(|&p| m.ct.as_ref().and_then(|ct| ct.hu_at(p)).unwrap_or(f64::NAN)).collect();
        let d = PyDict::new(py);
        d.set_item("sound_speed_m_s", props.iter().map(|p| p.sound_speed).collect::<Vec<_>>().into_pyarray(py))?;
        d.set_item("density_kg_m3", props.iter().map(|p| p.density).collect::<Vec<_>>().into_pyarray(py))?;
        d.set_item("attenuation_np_m", props.iter().map(|p| p.attenuation).collect::<Vec<_>>().into_pyarray(py))?;
        d.set_item("shear_sound_speed_m_s", props.iter().map(|p| p.shear_sound_speed).collect::<Vec<_>>().into_pyarray(py))?;
        d.set_item("shear_attenuation_np_m", props.iter().map(|p| p.shear_attenuation).collect::<Vec<_>>().into_pyarray(py))?;
        d.set_item("hu", hu.into_pyarray(py))?;
        Ok(d)
    }

    /// Pressure on the x–z section nearest `y_mm` (default: the focus's) for each drive in
    /// `phases`, with the sound speed there; with `target_mm`, each drive's focal metrics around it
    /// from the same march.
    #[pyo3(signature = (phases, y_mm=None, target_mm=None))]
    fn section(
        &self,
        py: Python<'_>,
        phases: Vec<PyReadonlyArray1<'_, f64>>,
        y_mm: Option<f64>,
        target_mm: Option<[f64; 3]>,
    ) -> PyResult<CoreSection> {
        let added: Vec<Vec<f64>> = phases.into_iter().map(|p| phases_vec(Some(p))).collect();
        let y = y_mm.map(|y| y * 1e-3);
        let Some(target) = target_mm.map(|t| t.map(|v| v * 1e-3)) else {
            let s = py.detach(|| self.inner.section(&added, y)).map_err(to_py)?;
            return Ok(CoreSection::new(py, s, None));
        };
        let (s, metrics) = py.detach(|| self.inner.section_with_focal_metrics(&added, y, target)).map_err(to_py)?;
        Ok(CoreSection::new(py, s, Some((target, metrics))))
    }

    /// MR-ARFI phase image (rad), shape (n_u, n_v); Gaussian noise of `noise_rad` if given.
    #[pyo3(signature = (phases=None, noise_rad=0.0, seed=0))]
    fn arfi_image<'py>(
        &self,
        py: Python<'py>,
        phases: Option<PyReadonlyArray1<'py, f64>>,
        noise_rad: f64,
        seed: u64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let phases = phases_vec(phases);
        let img = py.detach(|| self.inner.noisy_arfi_image(&phases, noise_rad, seed)).map_err(to_py)?;
        Ok(img.into_pyarray(py))
    }

    /// The focal ARFI of an image: its largest imaged (not NaN) pixel within the focal search
    /// radius of the target, as (value in rad, (i, j)).
    fn focal_arfi(&self, image: PyReadonlyArray2<'_, f64>) -> PyResult<(f64, (usize, usize))> {
        let (ij, value) = self.inner.focal_arfi(&image.as_array().to_owned(), "image").map_err(to_py)?;
        Ok((value, ij))
    }

    /// The pixels within the focal search radius of the target in the image plane, shape (n_u, n_v).
    fn focal_region<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<bool>> {
        self.inner.focal_region().into_pyarray(py)
    }

    /// Which pixels of the scenario's MR image are imaged (tissue with MR signal), shape (n_u, n_v).
    fn imaged<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<bool>>> {
        Ok(self.inner.sampler().map_err(to_py)?.imaged().clone().into_pyarray(py))
    }

    /// The same simulation with broadening width W (mm) and amplitude (rad·m³/N).
    fn with_calibration(&self, broadening_width_mm: f64, amplitude: f64) -> PyResult<Self> {
        let inner = self.inner.with_calibration(broadening_width_mm * 1e-3, amplitude).map_err(to_py)?;
        Ok(inner.into())
    }

    /// The same simulation with `calibration`'s width and amplitude, once checked that it was
    /// fitted for this scenario and frequency (where it records them).
    fn calibrated(&self, calibration: &CoreCalibration) -> PyResult<Self> {
        Ok(calibration.0.applied_to(&self.inner).map_err(to_py)?.into())
    }

    /// The same simulation with each element driven at `amplitudes` (one per element) times the
    /// scenario's amplitude; the plan is shared, the steered source projected again.
    fn with_element_amplitudes(&self, py: Python<'_>, amplitudes: PyReadonlyArray1<'_, f64>) -> PyResult<Self> {
        let a = amplitudes.as_array().to_vec();
        let inner = py.detach(|| self.inner.with_element_amplitudes(&a)).map_err(to_py)?;
        Ok(inner.into())
    }

    /// Each element's drive amplitude relative to the scenario's.
    #[getter]
    fn element_amplitudes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.element_amplitudes().to_vec().into_pyarray(py)
    }

    /// The same simulation with another element → group map.
    fn with_groups(&self, groups: PyReadonlyArray1<'_, i64>) -> PyResult<Self> {
        let g = groups.as_array();
        if let Some(v) = g.iter().find(|v| **v < 0) {
            return Err(invalid("groups", format!("negative group index {v}")));
        }
        let mut inner = self.inner.clone();
        inner.set_groups(g.iter().map(|&v| v as usize).collect()).map_err(to_py)?;
        Ok(inner.into())
    }

    /// Known per-element phases (rad) that move the focus by `shift_mm` (x, y, z in the
    /// transducer frame, mm): a displaced or defocused diversity acquisition.
    #[pyo3(signature = (shift_mm, name="shift_mm"))]
    fn focus_shift_phases<'py>(&self, py: Python<'py>, shift_mm: [f64; 3], name: &str) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let shift = shift_mm.map(|v| v * 1e-3);
        let phases = self.inner.focus_shift_phases(shift).map_err(|e| invalid(name, e.to_string()))?;
        Ok(phases.into_pyarray(py))
    }

    /// Each element's complex pressure (Pa per unit drive, no steering) at `target_mm` (mm,
    /// transducer frame; default the focus), by reciprocity: `p = Σ_e h_e·exp(i·phi_e)`.
    #[pyo3(signature = (target_mm=None))]
    fn element_responses<'py>(&self, py: Python<'py>, target_mm: Option<[f64; 3]>) -> PyResult<Bound<'py, PyArray1<C64>>> {
        let target = target_mm.map_or(self.inner.focus, |t| t.map(|v| v * 1e-3));
        let h = py.detach(|| self.inner.element_responses(target)).map_err(|e| invalid("target_mm", e.to_string()))?;
        Ok(h.into_pyarray(py))
    }

    /// Skull-like per-element phases (rad), seeded: a smooth random screen over the aperture plus
    /// per-element jitter.
    #[pyo3(signature = (seed, correlation_length_mm=12.0, peak_to_peak_rad=6.0, jitter_rad=0.5))]
    fn skull_phases<'py>(
        &self,
        py: Python<'py>,
        seed: u64,
        correlation_length_mm: f64,
        peak_to_peak_rad: f64,
        jitter_rad: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let screen = SkullScreen { correlation_length: correlation_length_mm * 1e-3, peak_to_peak: peak_to_peak_rad, jitter: jitter_rad };
        let pos = self.inner.transducer.reference_points();
        Ok(screen.phases(&pos, seed).map_err(to_py)?.into_pyarray(py))
    }

    /// Added phases, one per element or one per group, expanded to one per element.
    #[pyo3(signature = (phases, name="phases"))]
    fn element_phases<'py>(&self, py: Python<'py>, phases: PyReadonlyArray1<'py, f64>, name: &str) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(self.inner.element_phases(&phases.as_array().to_vec()).map_err(|e| to_py(e.naming(name)))?.into_pyarray(py))
    }

    /// Known phases per element from values per element, per group or per default group (the rule
    /// every image's known phases follow); errors name `name`.
    #[pyo3(signature = (known, name="known"))]
    fn known_per_element<'py>(
        &self,
        py: Python<'py>,
        known: PyReadonlyArray1<'py, f64>,
        name: &str,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(known_per_element(&self.inner, &known.as_array().to_vec()).map_err(|e| to_py(e.naming(name)))?.into_pyarray(py))
    }

    /// Per-group circular means of per-element phases.
    fn condense<'py>(&self, py: Python<'py>, phases: PyReadonlyArray1<'py, f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(condense(&phases.as_array().to_vec(), &self.inner.groups).map_err(to_py)?.into_pyarray(py))
    }

    /// Fits broadening width and amplitude to a no-aberration image.
    #[pyo3(signature = (image, known=None, mask_fraction=None, max_width_mm=10.0))]
    fn calibrate<'py>(
        &self,
        py: Python<'py>,
        image: PyReadonlyArray2<'py, f64>,
        known: Option<PyReadonlyArray1<'py, f64>>,
        mask_fraction: Option<f64>,
        max_width_mm: f64,
    ) -> PyResult<CoreCalibration> {
        let image = image.as_array().to_owned();
        let known = phases_vec(known);
        let frac = mask_fraction.unwrap_or(self.inner.mask_fraction);
        let c = py.detach(|| calibrate(&self.inner, &image, &known, frac, max_width_mm * 1e-3)).map_err(to_py)?;
        Ok(CoreCalibration(c))
    }

    /// The model-discrepancy workflow (fit each candidate effect, add the best while the BIC
    /// favours it, repeat) on images, each taken with its `known` added phases; `effects` limits
    /// the library (names as in `effect_library()`; default all).
    #[pyo3(signature = (images, known, threshold=0.0, max_iterations=1500, effects=None, time_limit_s=None))]
    #[allow(clippy::too_many_arguments)] // the Python keyword arguments
    fn diagnose<'py>(
        &self,
        py: Python<'py>,
        images: Vec<PyReadonlyArray2<'py, f64>>,
        known: Vec<Option<PyReadonlyArray1<'py, f64>>>,
        threshold: f64,
        max_iterations: usize,
        effects: Option<Vec<String>>,
        time_limit_s: Option<f64>,
    ) -> PyResult<CoreDiagnosis> {
        let measurements = measurements(images, known)?;
        let options = DiagnoseOptions::new(threshold, max_iterations, effects.as_deref(), time_limit_s).map_err(to_py)?;
        let cancel = AtomicBool::new(false);
        let r =
            run_interruptible(py, &cancel, || diagnose(&self.inner, &measurements, &options, &Control::default().with_cancel(&cancel)))?
                .map_err(to_py)?;
        Ok(CoreDiagnosis(r))
    }

    /// The model images of images taken with `known` phases under the effects of `effects`
    /// (keys: the effects' parameter names as `diagnose` reports them).
    fn effect_images<'py>(
        &self,
        py: Python<'py>,
        known: Vec<Option<PyReadonlyArray1<'py, f64>>>,
        effects: Bound<'py, PyDict>,
    ) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
        let knowns: Vec<Vec<f64>> = known.into_iter().map(phases_vec).collect();
        let e = effects_from_dict(&self.inner, &effects)?;
        let imgs = py.detach(|| effect_images(&self.inner, &knowns, &e)).map_err(to_py)?;
        Ok(imgs.into_iter().map(|m| m.into_pyarray(py)).collect())
    }

    /// The coefficient of a prior `mode` (rad per element for a coefficient of 1) fitted to
    /// images, each taken with its known added phases, the phases otherwise this model's own.
    fn fit_mode(
        &self,
        py: Python<'_>,
        images: Vec<PyReadonlyArray2<'_, f64>>,
        known: Vec<Option<PyReadonlyArray1<'_, f64>>>,
        mode: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<CoreModeFit> {
        let measurements = measurements(images, known)?;
        let mode = mode.as_array().to_vec();
        let cancel = AtomicBool::new(false);
        let fit = run_interruptible(py, &cancel, || fit_mode(&self.inner, &mode, &measurements, &Control::default().with_cancel(&cancel)))?
            .map_err(to_py)?;
        Ok(CoreModeFit(fit))
    }

    /// The coefficients of prior `modes` (rows: rad per element for a coefficient of 1) fitted
    /// jointly to images, each taken with its known added phases, the phases otherwise this
    /// model's own; the images' noise `noise_rad` where it is known (else their background floor).
    #[pyo3(signature = (images, known, modes, noise_rad=None))]
    fn fit_modes(
        &self,
        py: Python<'_>,
        images: Vec<PyReadonlyArray2<'_, f64>>,
        known: Vec<Option<PyReadonlyArray1<'_, f64>>>,
        modes: PyReadonlyArray2<'_, f64>,
        noise_rad: Option<f64>,
    ) -> PyResult<CoreModesFit> {
        let measurements = measurements(images, known)?;
        let modes: Vec<Vec<f64>> = modes.as_array().rows().into_iter().map(|r| r.to_vec()).collect();
        let cancel = AtomicBool::new(false);
        let fit = run_interruptible(py, &cancel, || {
            fit_modes_with_noise(&self.inner, &modes, &measurements, noise_rad, &Control::default().with_cancel(&cancel))
        })?
        .map_err(to_py)?;
        Ok(CoreModesFit(fit))
    }

    /// Hybrid estimation from one or more images, each with its known added phases, with
    /// `options` (an `EstimateOptions`); `progress`, a callable, is called with `(done, total)`
    /// element fields as the element basis is marched (an exception it raises stops the run and
    /// is raised here).
    #[pyo3(signature = (images, known, options, progress=None))]
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        images: Vec<PyReadonlyArray2<'py, f64>>,
        known: Vec<Option<PyReadonlyArray1<'py, f64>>>,
        options: PyRef<'py, EstimateOptions>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<CoreEstimate> {
        let measurements = measurements(images, known)?;
        let request = &options.0;
        let r = run_with_progress(py, progress.as_ref(), |control| {
            estimate_aberration_with(&self.inner, &measurements, request, &self.basis, control)
        })?;
        Ok(CoreEstimate { report: r.map_err(to_py)?, method: request.method })
    }

    /// The hybrid cost (paper Eq. 4) of images, each with its known added phases, on the per-pixel
    /// group kernels `estimate` minimises (at most 256 groups).
    #[pyo3(signature = (images, known, fit_amplitude=false))]
    fn cost_model(
        &self,
        py: Python<'_>,
        images: Vec<PyReadonlyArray2<'_, f64>>,
        known: Vec<Option<PyReadonlyArray1<'_, f64>>>,
        fit_amplitude: bool,
    ) -> PyResult<CoreCostModel> {
        let measurements = measurements(images, known)?;
        let sim = &self.inner;
        let cancel = AtomicBool::new(false);
        let model = run_interruptible(py, &cancel, || build_model(sim, &measurements, sim.mask_fraction, 3))?.map_err(to_py)?;
        let mut cost = model.cost;
        cost.fit_amplitude = fit_amplitude;
        Ok(CoreCostModel { cost: Arc::new(cost), noise: model.noise })
    }

    /// The source-plane pressure (Pa), shape (ny, nx), for added phases.
    #[pyo3(signature = (phases=None))]
    fn source_field<'py>(&self, py: Python<'py>, phases: Option<PyReadonlyArray1<'py, f64>>) -> PyResult<Bound<'py, PyArray2<C64>>> {
        let phases = phases_vec(phases);
        let g = &self.inner.grid;
        let f = py.detach(|| self.inner.source_field(&phases)).map_err(to_py)?;
        let a = ndarray::Array2::from_shape_vec((g.ny, g.nx), f).map_err(|e| invalid("field", e.to_string()))?;
        Ok(a.into_pyarray(py))
    }
}
