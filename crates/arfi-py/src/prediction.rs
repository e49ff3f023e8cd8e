//! `predict`: the CT-based prediction of each element's aberration, as a typed result.

use crate::convert::points_m;
use crate::error::{invalid, to_py};
use crate::interrupt::run_with_progress;
use crate::scenario::CoreScenario;
use crate::simulation::CoreSimulation;
use crate::volume::affine_4x4;
use has_core::prediction::{predict_scenario_with, predict_targets_with, with_amplitude, PoseSensitivity, Prediction, PredictionOptions};
use num_complex::Complex64 as C64;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// A prediction's kept skull simulation with the scenario it was built from.
type Kept = (CoreSimulation, CoreScenario);

/// Builds the scenario's simulation and predicts at `target_mm` (default: the focus), by
/// reciprocity (see `has_core::prediction`): the prediction and, with `keep_simulation`, the
/// skull's `CoreSimulation` (its ARFI amplitude not calibrated), else `None`. With
/// `bone_speed_sensitivity`, the prediction also holds
/// `bone_speed_sensitivity_rad_per_percent` (one more simulation of the skull); with
/// `pose_sensitivity`, `pose_sensitivity_rad_per_mm` and `pose_sensitivity_rad_per_deg` (six
/// more transposed marches through the skull, no plan).
#[pyfunction]
#[pyo3(signature = (scenario, target_mm=None, bone_speed_sensitivity=false, keep_simulation=false, pose_sensitivity=false))]
pub(crate) fn predict(
    py: Python<'_>,
    scenario: &CoreScenario,
    target_mm: Option<[f64; 3]>,
    bone_speed_sensitivity: bool,
    keep_simulation: bool,
    pose_sensitivity: bool,
) -> PyResult<(CorePrediction, Option<Kept>)> {
    let scenario = &scenario.inner;
    let target = target_mm.map(|t| t.map(|v| v * 1e-3));
    let options = PredictionOptions { bone_speed_sensitivity, keep_simulation, pose_sensitivity };
    let run = py.detach(|| predict_scenario_with(scenario, target, options)).map_err(to_py)?;
    let prediction = CorePrediction {
        prediction: run.prediction,
        bone_speed_sensitivity: run.bone_speed_sensitivity,
        pose: run.pose_sensitivity,
        simulation: None,
    };
    // The kept simulation with the scenario it was built from.
    let kept = run.simulation.map(|sim| (CoreSimulation::from(sim), CoreScenario { inner: with_amplitude(scenario.clone()) }));
    Ok((prediction, kept))
}

/// `predict` at each of `targets_mm` (mm, transducer frame) from one plan of each head (see
/// `has_core::prediction::predict_targets_with`): each prediction equals `predict`'s at its
/// target, and each target beyond the first costs its transposed marches, not a plan. Targets
/// outside the grid or the CT are refused by index before anything is built; `progress`, a
/// callable, is called with `(done, total)` transposed marches (an exception it raises stops the
/// run and is raised here).
#[pyfunction]
#[pyo3(signature = (scenario, targets_mm, bone_speed_sensitivity=false, keep_simulation=false, pose_sensitivity=false, progress=None))]
pub(crate) fn predict_targets(
    py: Python<'_>,
    scenario: &CoreScenario,
    targets_mm: PyReadonlyArray2<'_, f64>,
    bone_speed_sensitivity: bool,
    keep_simulation: bool,
    pose_sensitivity: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Vec<CorePrediction>, Option<Kept>)> {
    let scenario = &scenario.inner;
    let targets = points_m(&targets_mm, "targets_mm")?;
    let options = PredictionOptions { bone_speed_sensitivity, keep_simulation, pose_sensitivity };
    let run =
        run_with_progress(py, progress.as_ref(), |control| predict_targets_with(scenario, &targets, options, control))?.map_err(to_py)?;
    let predictions = run
        .runs
        .into_iter()
        .map(|r| CorePrediction {
            prediction: r.prediction,
            bone_speed_sensitivity: r.bone_speed_sensitivity,
            pose: r.pose_sensitivity,
            simulation: None,
        })
        .collect();
    let kept = run.simulation.map(|sim| (CoreSimulation::from(sim), CoreScenario { inner: with_amplitude(scenario.clone()) }));
    Ok((predictions, kept))
}

/// The tissue class at each of `targets_mm` (shape (n, 3), mm, transducer frame) as the skull's
/// simulation names it (`skull`, `scalp`, the CT's soft tissue by name, the coupling medium's),
/// without building a plan.
#[pyfunction]
pub(crate) fn target_tissues(py: Python<'_>, scenario: &CoreScenario, targets_mm: PyReadonlyArray2<'_, f64>) -> PyResult<Vec<String>> {
    let scenario = &scenario.inner;
    let targets = points_m(&targets_mm, "targets_mm")?;
    py.detach(|| has_core::prediction::target_tissues(scenario, &targets)).map_err(to_py)
}

/// The voxel grid of the scenario's CT: its shape `(nk, nj, ni)`, the file's 4 x 4 affine from
/// voxel (i, j, k) to RAS+ mm, and the 4 x 4 map from voxel (i, j, k) to the transducer frame
/// (mm), as the core reads them: for volumes written on the CT's voxels.
#[pyfunction]
#[allow(clippy::type_complexity)]
pub(crate) fn ct_voxel_grid<'py>(
    py: Python<'py>,
    scenario: &CoreScenario,
) -> PyResult<((usize, usize, usize), Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
    let scenario = &scenario.inner;
    let resolved = py.detach(|| scenario.resolve()).map_err(to_py)?;
    let ct = resolved.medium.ct.as_ref().ok_or_else(|| invalid("scenario", "has no [ct]: the CT is the grid asked for"))?;
    let ([nk, nj, ni], ras, to_frame) = ct.voxel_grid();
    Ok(((nk, nj, ni), affine_4x4(&ras, 1.0).into_pyarray(py), affine_4x4(&to_frame, 1e3).into_pyarray(py)))
}

/// What the scenario's CT bone does to each element's wave at the target, by reciprocity.
///
/// Each element's complex pressure `h_e` at the target (unit drive) is computed through the head
/// with its CT and through the same head with the CT's bone read as soft tissue (the
/// *reference*: the head without its skull, which the estimation's model assumes), from one
/// transposed march each instead of one march per element. `phases_rad` is
/// `arg(h_skull · conj(h_reference))` less its weighted circular mean: the aberration in the sign
/// of an estimate's `phases_rad` (driving the reference steering minus it corrects; it is the
/// `--prior` of `arfi estimate`). The focal pressures (Pa) are exact sums of the responses.
#[pyclass(module = "arfi._core", name = "Prediction", frozen)]
pub(crate) struct CorePrediction {
    prediction: Prediction,
    bone_speed_sensitivity: Option<Vec<f64>>,
    pose: Option<PoseSensitivity>,
    simulation: Option<Py<PyAny>>,
}

/// Rows of `modes` scaled by `factor`, as a `(rows, elements)` array.
fn rows(modes: &[Vec<f64>; 3], factor: f64) -> Vec<Vec<f64>> {
    modes.iter().map(|m| m.iter().map(|v| v * factor).collect()).collect()
}

#[pymethods]
impl CorePrediction {
    /// Predicted aberration per element (rad, wrapped to (-pi, pi]).
    #[getter]
    fn phases_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.prediction.phases.clone().into_pyarray(py)
    }

    /// Per element, `|h_skull| / |h_reference|` at the target.
    #[getter]
    fn transmission<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.prediction.transmission.clone().into_pyarray(py)
    }

    /// Steering phases (rad) toward the target through the head without bone (straight-ray times
    /// of flight; at the focus, those of the estimation's model).
    #[getter]
    fn reference_steering_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.prediction.reference_steering.clone().into_pyarray(py)
    }

    /// The point predicted for (transducer frame, mm); between grid points the fields are
    /// interpolated there (band-limited across, an angular-spectrum sub-step along z).
    #[getter]
    fn target_mm(&self) -> (f64, f64, f64) {
        let t = self.prediction.target.map(|v| v * 1e3);
        (t[0], t[1], t[2])
    }

    /// Focal |p| (Pa) of the reference steering in the head without bone.
    #[getter]
    fn reference_pa(&self) -> f64 {
        self.prediction.reference_pressure
    }

    /// The most any phases give (Pa) in the head without bone, `sum |h_reference|`:
    /// `reference_pa` falls short of it by what straight rays miss without any bone (refraction,
    /// oblique paths through soft tissue), which a correction relative to the reference steering
    /// keeps.
    #[getter]
    fn reference_optimal_pa(&self) -> f64 {
        self.prediction.reference_optimal_pressure
    }

    /// Focal |p| (Pa) of the reference steering through the skull (the aberrated focus).
    #[getter]
    fn uncorrected_pa(&self) -> f64 {
        self.prediction.uncorrected_pressure
    }

    /// Focal |p| (Pa) of the scenario's own steering toward the target (straight rays through the
    /// CT's bone) through the skull.
    #[getter]
    fn ray_steering_pa(&self) -> f64 {
        self.prediction.ray_steering_pressure
    }

    /// Focal |p| (Pa) of the reference steering minus `phases_rad` through the skull.
    #[getter]
    fn corrected_pa(&self) -> f64 {
        self.prediction.corrected_pressure
    }

    /// The most any phases give (Pa) through the skull at this drive amplitude: `sum |h_skull|`.
    #[getter]
    fn optimal_pa(&self) -> f64 {
        self.prediction.optimal_pressure
    }

    /// The focus (Pa) the array gives at the target in water with every element in phase,
    /// `sum |h_water|` (direct Rayleigh sums): what a focus through the head is measured against.
    #[getter]
    fn water_pa(&self) -> f64 {
        self.prediction.water_pressure
    }

    /// Per element, `h_skull`: its complex pressure (Pa) at the target through the skull when it
    /// alone is driven with a unit phasor.
    #[getter]
    fn skull_responses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<C64>> {
        self.prediction.skull_responses.clone().into_pyarray(py)
    }

    /// Per element, how `phases_rad` moves (rad) per percent of the CT conversion's bone sound
    /// speed (`predict(..., bone_speed_sensitivity=True)`; else None): a finite difference over
    /// +10 % through the wave model, its weighted common phase removed. `s` times it is the
    /// prediction's error if the conversion's bone is `s` percent off: give it to an estimate as
    /// a prior mode (`prior_modes`; the CLI's `--prior-bone-speed-std-percent`).
    #[getter]
    fn bone_speed_sensitivity_rad_per_percent<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.bone_speed_sensitivity.clone().map(|g| g.into_pyarray(py))
    }

    /// Per element, how `phases_rad` moves (rad) per millimetre that the head lies shifted along
    /// the transducer frame's x, y and z from where the CT is registered (`predict(...,
    /// pose_sensitivity=True)`; else None): rows x, y, z, a column per element. The head's
    /// responses through the moved head are the registered head's to the array and target moved
    /// the other way, differenced over one grid cell either way, their weighted common phase
    /// removed.
    #[getter]
    fn pose_sensitivity_rad_per_mm<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.pose
            .as_ref()
            .map(|p| PyArray2::from_vec2(py, &rows(&p.translation, 1e-3)).map_err(|e| invalid("pose", e.to_string())))
            .transpose()
    }

    /// Per element, how `phases_rad` moves (rad) per degree that the head lies turned about the
    /// axes x, y and z through the target (right-handed) from where the CT is registered (as
    /// `pose_sensitivity_rad_per_mm`; rows x, y, z).
    #[getter]
    fn pose_sensitivity_rad_per_deg<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        let per_deg = 1f64.to_radians();
        self.pose
            .as_ref()
            .map(|p| PyArray2::from_vec2(py, &rows(&p.rotation, per_deg)).map_err(|e| invalid("pose", e.to_string())))
            .transpose()
    }

    /// The skull's simulation the prediction marched (`predict(..., keep_simulation=True)`; else
    /// None): fields, sections and element maps of the predicted drives without building its
    /// plan again. Its ARFI amplitude is not calibrated: not for MR-ARFI images.
    #[getter]
    fn simulation(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.simulation.as_ref().map(|s| s.clone_ref(py))
    }

    /// The skull's simulation the prediction marched, or a `ValueError` naming `prediction` that
    /// says how to keep it: what its section, focal metrics and report need.
    fn kept_simulation(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        self.simulation(py).ok_or_else(|| invalid("prediction", "has no simulation; predict with keep_simulation=True"))
    }

    /// The same prediction holding `simulation` (what `predict(..., keep_simulation=True)`
    /// attaches: the skull's `arfi.Simulation`).
    fn with_simulation(&self, simulation: Py<PyAny>) -> Self {
        CorePrediction {
            prediction: self.prediction.clone(),
            bone_speed_sensitivity: self.bone_speed_sensitivity.clone(),
            pose: self.pose.clone(),
            simulation: Some(simulation),
        }
    }

    /// Focal |p| (Pa) at the target through this prediction's skull when the array drives the
    /// reference steering minus `phases_rad` (one per element): e.g. an estimate's, another
    /// prediction's, or zeros for the uncorrected beam; exact in the model.
    fn pressure_with(&self, phases_rad: Vec<f64>) -> PyResult<f64> {
        self.prediction.pressure_with(&phases_rad).map_err(|e| to_py(e.naming("phases_rad")))
    }

    /// Phases (rad) to add to a simulation's own `steering_rad` to drive the corrected array
    /// (reference steering minus the prediction), e.g.
    /// `sim.field(p.correction_rad(sim.steering_phases_rad))`.
    fn correction_rad<'py>(&self, py: Python<'py>, steering_rad: Vec<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let steering = &steering_rad;
        let p = &self.prediction;
        if steering.len() != p.phases.len() {
            return Err(crate::error::invalid("steering_rad", format!("has {} values for {} elements", steering.len(), p.phases.len())));
        }
        let c: Vec<f64> = p.reference_steering.iter().zip(&p.phases).zip(steering).map(|((r, ph), s)| r - ph - s).collect();
        Ok(c.into_pyarray(py))
    }

    /// The JSON `arfi predict` writes: the per-element vectors, `target_mm` and the focal
    /// pressures under `focal_pressure_pa` (each attribute's name without `_pa`).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = &self.prediction;
        let d = PyDict::new(py);
        d.set_item("phases_rad", p.phases.clone())?;
        d.set_item("transmission", p.transmission.clone())?;
        d.set_item("reference_steering_rad", p.reference_steering.clone())?;
        d.set_item("target_mm", self.target_mm())?;
        let focal = PyDict::new(py);
        for (name, value) in [
            ("reference", self.reference_pa()),
            ("reference_optimal", self.reference_optimal_pa()),
            ("uncorrected", self.uncorrected_pa()),
            ("ray_steering", self.ray_steering_pa()),
            ("corrected", self.corrected_pa()),
            ("optimal", self.optimal_pa()),
            ("water", self.water_pa()),
        ] {
            focal.set_item(name, value)?;
        }
        d.set_item("focal_pressure_pa", focal)?;
        if let Some(g) = &self.bone_speed_sensitivity {
            d.set_item("bone_speed_sensitivity_rad_per_percent", g.clone())?;
        }
        if let Some(pose) = &self.pose {
            d.set_item("pose_sensitivity_rad_per_mm", rows(&pose.translation, 1e-3))?;
            d.set_item("pose_sensitivity_rad_per_deg", rows(&pose.rotation, 1f64.to_radians()))?;
        }
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let p = &self.prediction;
        format!(
            "Prediction({} elements, uncorrected {:.3} MPa, corrected {:.3} MPa, optimal {:.3} MPa)",
            p.phases.len(),
            p.uncorrected_pressure / 1e6,
            p.corrected_pressure / 1e6,
            p.optimal_pressure / 1e6
        )
    }
}
