//! A calibration as a JSON file (the keys `arfi calibrate --json` writes: `broadening_width_mm`,
//! `amplitude`, `cost`, `n_pixels`, `noise_rad`, `scenario`, `frequency_hz`; others ignored), and
//! the check that it is applied to the simulation it was fitted for.
//!
//! Only the width and the amplitude are required, so that a calibration can be written by hand
//! (e.g. W = 0 to model no broadening); what a file does not record is not checked.

use crate::error::{HasError, Result};
use crate::inverse::calibrate::Calibration;
use crate::scenario::Outline;
use crate::simulation::Simulation;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The file's keys, in the order written.
#[derive(Serialize, Deserialize)]
struct CalibrationJson {
    broadening_width_mm: f64,
    amplitude: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cost: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n_pixels: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    noise_rad: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    scenario: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    frequency_hz: Option<f64>,
}

/// `Some(x)` for a finite value, None for NaN (not recorded).
fn recorded(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

impl Calibration {
    /// A calibration from its width W (m) and amplitude (rad·m³/N), fitted for nothing in
    /// particular: W finite and ≥ 0 (0: no broadening), the amplitude finite and > 0.
    pub fn new(broadening_width: f64, amplitude: f64) -> Result<Self> {
        let c = Calibration { broadening_width, amplitude, cost: f64::NAN, n_pixels: 0, noise: f64::NAN, scenario: None, frequency: None };
        c.check()?;
        Ok(c)
    }

    /// The same calibration recorded as fitted for `scenario` at `frequency` (Hz, finite > 0);
    /// None leaves that unrecorded (not checked where it is applied).
    pub fn fitted_for(mut self, scenario: Option<String>, frequency: Option<f64>) -> Result<Self> {
        self.scenario = scenario;
        self.frequency = frequency;
        self.check()?;
        Ok(self)
    }

    /// The width, amplitude and frequency within their ranges.
    fn check(&self) -> Result<()> {
        if !(self.broadening_width.is_finite() && self.broadening_width >= 0.0) {
            return Err(HasError::invalid(
                "broadening_width_mm",
                format!("must be a finite number >= 0, got {}", self.broadening_width * 1e3),
            ));
        }
        crate::error::require_positive("amplitude", self.amplitude)?;
        if let Some(f) = self.frequency {
            crate::error::require_positive("frequency_hz", f)?;
        }
        Ok(())
    }

    /// The calibration from the text of its JSON file; `path` names it in errors.
    pub fn from_json(text: &str, path: &str) -> Result<Self> {
        let bad = |reason: String| HasError::BadFile { path: path.to_string(), reason: format!("not a calibration file ({reason})") };
        // An object only: serde would also read a struct from a list of its values.
        let value: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(e.to_string()))?;
        if !value.is_object() {
            return Err(bad("not a JSON object".into()));
        }
        let j: CalibrationJson = serde_json::from_value(value).map_err(|e| bad(e.to_string()))?;
        let c = Calibration {
            broadening_width: j.broadening_width_mm * 1e-3,
            amplitude: j.amplitude,
            cost: j.cost.unwrap_or(f64::NAN),
            n_pixels: j.n_pixels.unwrap_or(0),
            noise: j.noise_rad.unwrap_or(f64::NAN),
            scenario: j.scenario,
            frequency: j.frequency_hz,
        };
        c.check().map_err(|e| bad(e.to_string()))?;
        Ok(c)
    }

    /// The JSON text of the file (pretty, newline-terminated); what is not recorded is left out.
    pub fn to_json(&self) -> String {
        let j = CalibrationJson {
            broadening_width_mm: self.broadening_width * 1e3,
            amplitude: self.amplitude,
            cost: recorded(self.cost),
            n_pixels: (self.n_pixels > 0).then_some(self.n_pixels),
            noise_rad: recorded(self.noise),
            scenario: self.scenario.clone(),
            frequency_hz: self.frequency,
        };
        // Infallible: plain numbers (finite by `recorded` and `check`) and strings.
        serde_json::to_string_pretty(&j).expect("a calibration serialises") + "\n"
    }

    /// Reads the calibration file at `path`.
    pub fn load(path: &Path) -> Result<Self> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| HasError::reading(&name, &e))?;
        Calibration::from_json(&text, &name)
    }

    /// Writes the calibration file at `path`, whole or not at all (a temporary file in the same
    /// folder, renamed over `path`).
    pub fn save(&self, path: &Path) -> Result<()> {
        let name = path.display().to_string();
        let file = path.file_name().ok_or_else(|| HasError::invalid("path", format!("{name}: not a file name")))?;
        static SAVES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = SAVES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let tmp = path.with_file_name(format!(".{}.{}.{n}.tmp", file.to_string_lossy(), std::process::id()));
        let write = || -> std::io::Result<()> {
            use std::io::Write;
            // A new file (never one already there, nor a link's target), on disk before the rename.
            let mut f = std::fs::OpenOptions::new().write(true).create_new(true).open(&tmp)?;
            f.write_all(self.to_json().as_bytes())?;
            f.sync_all()?;
            std::fs::rename(&tmp, path)
        };
        write().map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            if e.kind() == std::io::ErrorKind::NotFound {
                HasError::FileNotFound { path: name, named_by: Some("its folder does not exist".into()) }
            } else {
                HasError::BadFile { path: name, reason: format!("cannot write: {e}") }
            }
        })
    }

    /// Checks that the calibration was fitted for `sim`'s scenario and frequency (where it
    /// records them): W and the amplitude depend on the array, the MR protocol and the frequency.
    pub fn check_for(&self, sim: &Simulation) -> Result<()> {
        self.check_against(&sim.name, sim.frequency)
    }

    /// [`Calibration::check_for`] from the scenario's [`Outline`], before a simulation is built
    /// to apply it.
    pub fn check_for_outline(&self, outline: &Outline) -> Result<()> {
        self.check_against(outline.name(), outline.frequency())
    }

    /// Checks that the calibration was fitted for the scenario named `scenario` at `frequency`
    /// (Hz), where it records them.
    pub fn check_against(&self, scenario: &str, frequency: f64) -> Result<()> {
        let scenario_differs = self.scenario.as_deref().is_some_and(|s| s != scenario);
        let frequency_differs = self.frequency.is_some_and(|f| (f - frequency).abs() > 1e-9 * frequency);
        if scenario_differs || frequency_differs {
            let made = match (&self.scenario, self.frequency) {
                (Some(s), Some(f)) => format!("scenario {s:?} at {f} Hz"),
                (Some(s), None) => format!("scenario {s:?}"),
                (None, Some(f)) => format!("{f} Hz"),
                (None, None) => unreachable!("a difference needs a recorded value"),
            };
            return Err(HasError::invalid(
                "calibration",
                format!("made for {made}, not scenario {scenario:?} at {frequency} Hz: calibrate on this scenario's image"),
            ));
        }
        Ok(())
    }

    /// `sim` with this calibration's width and amplitude, after [`Calibration::check_for`].
    pub fn applied_to(&self, sim: &Simulation) -> Result<Simulation> {
        self.check_for(sim)?;
        sim.with_calibration(self.broadening_width, self.amplitude)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_round_trip_keeps_every_recorded_value_and_leaves_out_the_rest() {
        let c = Calibration {
            broadening_width: 2.7e-3,
            amplitude: 3.2e-6,
            cost: 0.12,
            n_pixels: 345,
            noise: 0.02,
            scenario: Some("default".into()),
            frequency: Some(650e3),
        };
        let back = Calibration::from_json(&c.to_json(), "c.json").unwrap();
        assert!((back.broadening_width - c.broadening_width).abs() < 1e-15);
        assert_eq!((back.amplitude, back.cost, back.n_pixels, back.noise), (c.amplitude, c.cost, c.n_pixels, c.noise));
        assert_eq!((back.scenario, back.frequency), (c.scenario, c.frequency));
        let hand = Calibration::new(0.0, 1.0).unwrap();
        let text = hand.to_json();
        assert!(!text.contains("cost") && !text.contains("scenario"), "{text}");
        let back = Calibration::from_json(&text, "c.json").unwrap();
        assert!(back.cost.is_nan() && back.n_pixels == 0 && back.scenario.is_none());
    }

    #[test]
    fn a_calibration_applies_only_where_it_was_fitted() {
        let c = Calibration::new(2e-3, 1.0).unwrap().fitted_for(Some("a".into()), Some(5e5)).unwrap();
        assert!(c.check_against("a", 5e5).is_ok());
        let e = c.check_against("b", 5e5).unwrap_err().to_string();
        assert!(e.starts_with("calibration: made for scenario \"a\" at 500000 Hz, not scenario \"b\""), "{e}");
        assert!(c.check_against("a", 6.5e5).is_err());
        // What a calibration does not record is not checked.
        assert!(Calibration::new(2e-3, 1.0).unwrap().check_against("any", 1.0).is_ok());
        assert!(Calibration::new(2e-3, 1.0).unwrap().fitted_for(None, Some(0.0)).is_err());
    }

    #[test]
    fn a_malformed_file_names_itself_and_the_key() {
        let e = Calibration::from_json(r#"{"amplitude": 1.0}"#, "c.json").unwrap_err().to_string();
        assert!(e.starts_with("c.json: not a calibration file") && e.contains("broadening_width_mm"), "{e}");
        let e = Calibration::from_json(r#"{"broadening_width_mm": -1, "amplitude": 1.0}"#, "c.json").unwrap_err().to_string();
        assert!(e.contains("broadening_width_mm: must be a finite number >= 0"), "{e}");
        let e = Calibration::from_json(r#"{"broadening_width_mm": 1, "amplitude": 0}"#, "c.json").unwrap_err().to_string();
        assert!(e.contains("amplitude"), "{e}");
        assert!(Calibration::from_json("[1, 2]", "c.json").is_err());
        let e = Calibration::load(Path::new("/nonexistent/c.json")).unwrap_err();
        assert!(matches!(e, HasError::FileNotFound { .. }), "{e}");
    }
}
