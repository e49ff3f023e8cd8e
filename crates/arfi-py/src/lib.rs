//! Python bindings of has-core: NumPy in and out, errors mapped in [`error`].

mod arrays;
mod convert;
mod cost;
mod diagnose;
mod error;
mod estimate_options;
mod field;
mod focal;
mod interrupt;
mod mode_fit;
mod phase;
mod plan;
mod prediction;
mod results;
mod scenario;
mod simulation;
mod support;
mod validation;
mod volume;

use has_core::inverse::estimate::workflow::Method;
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use scenario::contiguous_groups;

/// Hands the memory the allocator holds free back to the system (glibc's `malloc_trim`): call
/// after dropping a simulation whose HAS plan is large, before building the next.
#[pyfunction]
fn release_freed() {
    has_core::memory::release_freed();
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("MemoryLimitError", m.py().get_type::<error::MemoryLimitError>())?;
    m.add_class::<simulation::CoreSimulation>()?;
    m.add_class::<simulation::CoreSourceModel>()?;
    m.add_class::<cost::CoreCostModel>()?;
    m.add_class::<mode_fit::CoreModeFit>()?;
    m.add_class::<mode_fit::CoreModesFit>()?;
    m.add_class::<results::CoreCalibration>()?;
    m.add_class::<plan::CoreGrid>()?;
    m.add_class::<plan::CorePropagation>()?;
    m.add_class::<plan::CoreReverberation>()?;
    m.add_class::<results::CoreEstimate>()?;
    m.add_class::<estimate_options::EstimateOptions>()?;
    m.add_class::<results::NuisanceFit>()?;
    m.add_class::<results::NextAcquisition>()?;
    m.add_class::<results::ShiftCandidate>()?;
    m.add_class::<support::EstimateSupport>()?;
    m.add_class::<support::EstimatePriorCheck>()?;
    m.add_class::<diagnose::CoreDiagnosis>()?;
    m.add_class::<diagnose::DiagnosisStep>()?;
    m.add_class::<diagnose::EffectCandidate>()?;
    m.add_class::<diagnose::AlternativeFit>()?;
    m.add_class::<prediction::CorePrediction>()?;
    m.add_class::<field::CoreField>()?;
    m.add_class::<field::CoreSection>()?;
    m.add_class::<focal::CoreFocalMetrics>()?;
    m.add_class::<focal::FieldFocus>()?;
    m.add_class::<focal::HottestPlace>()?;
    m.add_class::<validation::CoreValidationCase>()?;
    m.add_class::<validation::CoreComparison>()?;
    m.add_function(wrap_pyfunction!(contiguous_groups, m)?)?;
    m.add_class::<scenario::CoreOutline>()?;
    m.add_class::<scenario::CoreScenario>()?;
    m.add_function(wrap_pyfunction!(diagnose::effect_library, m)?)?;
    m.add_function(wrap_pyfunction!(prediction::predict, m)?)?;
    m.add_function(wrap_pyfunction!(prediction::predict_targets, m)?)?;
    m.add_function(wrap_pyfunction!(prediction::target_tissues, m)?)?;
    m.add_function(wrap_pyfunction!(prediction::ct_voxel_grid, m)?)?;
    m.add_function(wrap_pyfunction!(release_freed, m)?)?;
    m.add_function(wrap_pyfunction!(phase::wrap_phases, m)?)?;
    m.add_function(wrap_pyfunction!(arrays::connected_region, m)?)?;
    m.add_function(wrap_pyfunction!(arrays::image_noise_rad, m)?)?;
    m.add_function(wrap_pyfunction!(phase::phase_error, m)?)?;
    m.add("METHODS", PyTuple::new(m.py(), Method::ALL.map(|m| m.name()))?)?;
    m.add_function(wrap_pyfunction!(validation::validation_cases, m)?)?;
    m.add_function(wrap_pyfunction!(validation::tilted_plate_case, m)?)?;
    m.add_function(wrap_pyfunction!(validation::validation_tolerances, m)?)?;
    Ok(())
}
