//! `predict`: the CT-based prediction of each element's aberration.

use crate::error::to_py;
use crate::scenario::parse_scenario;
use crate::simulation::CoreSimulation;
use has_core::prediction::{predict_scenario_with, PredictionOptions};
use numpy::IntoPyArray;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Builds the scenario's simulation and predicts at `target_mm` (default: the focus), by
/// reciprocity (see `has_core::prediction`): dict with `phases_rad`, `transmission`,
/// `reference_steering_rad` (per element), `target_mm` and the focal pressures (Pa)
/// `reference_pa`, `reference_optimal_pa`, `uncorrected_pa`, `ray_steering_pa`, `corrected_pa`, `optimal_pa`,
/// and `skull_responses` (complex Pa per unit drive, per element); with
/// `bone_speed_sensitivity`, also `bone_speed_sensitivity_rad_per_percent` (per element; one
/// more simulation of the skull), else that key is `None`; with `keep_simulation`, `simulation`:
/// the skull's `CoreSimulation` (its ARFI amplitude not calibrated), else `None`.
#[pyfunction]
#[pyo3(signature = (text, format="toml", base_dir=None, target_mm=None, bone_speed_sensitivity=false, keep_simulation=false))]
pub(crate) fn predict<'py>(
    py: Python<'py>,
    text: &str,
    format: &str,
    base_dir: Option<&str>,
    target_mm: Option<[f64; 3]>,
    bone_speed_sensitivity: bool,
    keep_simulation: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let scenario = parse_scenario(text, format, base_dir)?;
    let target = target_mm.map(|t| t.map(|v| v * 1e-3));
    let options = PredictionOptions { bone_speed_sensitivity, keep_simulation };
    let run = py.detach(|| predict_scenario_with(&scenario, target, options)).map_err(to_py)?;
    let p = run.prediction;
    let d = PyDict::new(py);
    d.set_item("phases_rad", p.phases.into_pyarray(py))?;
    d.set_item("transmission", p.transmission.into_pyarray(py))?;
    d.set_item("reference_steering_rad", p.reference_steering.into_pyarray(py))?;
    d.set_item("target_mm", p.target.map(|v| v * 1e3).to_vec())?;
    d.set_item("reference_pa", p.reference_pressure)?;
    d.set_item("uncorrected_pa", p.uncorrected_pressure)?;
    d.set_item("ray_steering_pa", p.ray_steering_pressure)?;
    d.set_item("corrected_pa", p.corrected_pressure)?;
    d.set_item("optimal_pa", p.optimal_pressure)?;
    d.set_item("reference_optimal_pa", p.reference_optimal_pressure)?;
    d.set_item("skull_responses", p.skull_responses.into_pyarray(py))?;
    d.set_item("bone_speed_sensitivity_rad_per_percent", run.bone_speed_sensitivity.map(|g| g.into_pyarray(py)))?;
    d.set_item("simulation", run.simulation.map(CoreSimulation::from))?;
    Ok(d)
}
