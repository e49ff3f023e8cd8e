//! Scenario files: parse, validate and write them back as complete TOML or JSON.

use crate::error::{invalid, to_py};
use has_core::scenario::Scenario;
use pyo3::prelude::*;
use std::path::Path;

pub(crate) fn parse_scenario(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<Scenario> {
    let base = base_dir.map(Path::new);
    match format {
        "toml" => Scenario::from_toml(text, base),
        "json" => Scenario::from_json(text, base),
        f => return Err(invalid("format", format!("must be 'toml' or 'json', got '{f}'"))),
    }
    .map_err(to_py)
}

/// The default scenario (the paper's phantom experiment) as TOML, every value written out.
#[pyfunction]
pub(crate) fn default_scenario_toml() -> PyResult<String> {
    Scenario::default().to_toml().map_err(to_py)
}

/// Parses and validates a scenario (`format` = "toml" | "json"), returning it as complete TOML.
#[pyfunction]
#[pyo3(signature = (text, format="toml", base_dir=None))]
pub(crate) fn normalize_scenario(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<String> {
    validated_scenario(text, format, base_dir)?.to_toml().map_err(to_py)
}

/// Parses and validates a scenario, returning it as complete TOML with the `[grid]` it resolves
/// to written out.
#[pyfunction]
#[pyo3(signature = (text, base_dir=None))]
pub(crate) fn scenario_toml_with_grid(text: &str, base_dir: Option<&str>) -> PyResult<String> {
    let s = parse_scenario(text, "toml", base_dir)?;
    has_core::simulation::with_chosen_grid(&s).and_then(|s| s.to_toml()).map_err(to_py)
}

/// Parses a scenario, returning it as complete JSON (for `Scenario.to_dict`, whose text was
/// validated as a whole when it was normalised: resolving it again would read its CT again).
#[pyfunction]
#[pyo3(signature = (text, format="toml", base_dir=None))]
pub(crate) fn scenario_json(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<String> {
    parse_scenario(text, format, base_dir)?.to_json().map_err(to_py)
}

/// A parsed scenario whose values have also been checked together (`Scenario::resolve`).
fn validated_scenario(text: &str, format: &str, base_dir: Option<&str>) -> PyResult<Scenario> {
    let s = parse_scenario(text, format, base_dir)?;
    s.resolve().map_err(to_py)?;
    Ok(s)
}
