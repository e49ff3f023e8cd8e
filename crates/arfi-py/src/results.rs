//! Typed results of calibration and hybrid estimation: the core's structs behind getters that
//! convert units (m to mm) in one place. `to_dict` writes the JSON from the same getters, so an
//! attribute and its JSON key are one name.

use crate::error::to_py;
use crate::support::{EstimatePriorCheck, EstimateSupport};
use has_core::inverse::calibrate::Calibration;
use has_core::inverse::element::nuisance::FittedNuisance;
use has_core::inverse::estimate::information::{Candidate, ShiftSuggestion};
use has_core::inverse::estimate::workflow::{EstimateReport, Method, Recommended};
use numpy::{IntoPyArray, PyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::PathBuf;

/// Millimetres of a shift in metres.
fn mm(shift: [f64; 3]) -> [f64; 3] {
    shift.map(|v| v * 1e3)
}

/// A result object as a dict of the attributes its class lists in `_fields` (the JSON of the
/// result, in that order): arrays become lists, nested results dicts, `None` stays `None`.
pub(crate) fn fields_dict<'py>(obj: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(obj.py());
    for name in obj.getattr("_fields")?.extract::<Vec<String>>()? {
        d.set_item(&name, plain(&obj.getattr(name.as_str())?)?)?;
    }
    Ok(d)
}

/// `name(field=value, ...)` over the attributes its class lists in `_fields`.
pub(crate) fn fields_repr(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<String> {
    let mut parts = Vec::new();
    for field in obj.getattr("_fields")?.extract::<Vec<String>>()? {
        parts.push(format!("{field}={}", obj.getattr(field.as_str())?.repr()?));
    }
    Ok(format!("{name}({})", parts.join(", ")))
}

/// A getter's value in JSON-ready form (a dict's values too).
fn plain<'py>(v: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    if let Ok(dict) = v.cast::<PyDict>() {
        let out = PyDict::new(v.py());
        for (k, x) in dict.iter() {
            out.set_item(k, plain(&x)?)?;
        }
        Ok(out.into_any())
    } else if v.hasattr("to_dict")? {
        v.call_method0("to_dict")
    } else if v.hasattr("tolist")? {
        v.call_method0("tolist")
    } else if let Ok(list) = v.cast::<PyList>() {
        let items = list.iter().map(|x| plain(&x)).collect::<PyResult<Vec<_>>>()?;
        Ok(PyList::new(v.py(), items)?.into_any())
    } else {
        Ok(v.clone())
    }
}

/// The broadening filter fitted to a no-aberration image (paper Eq. 2), with the scenario and
/// frequency it was fitted for.
#[pyclass(module = "arfi._core", name = "Calibration", frozen)]
pub(crate) struct CoreCalibration(pub(crate) Calibration);

#[pymethods]
impl CoreCalibration {
    /// Its attributes, in the order of its file's keys (`repr`).
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 7] = ["broadening_width_mm", "amplitude", "cost", "n_pixels", "noise_rad", "scenario", "frequency_hz"];

    /// A calibration written by hand: width W (mm, >= 0; 0 is no broadening) and amplitude
    /// (rad·m³/N, > 0); `scenario` and `frequency_hz`, when given, are checked where it is applied.
    #[new]
    #[pyo3(signature = (broadening_width_mm, amplitude, *, scenario=None, frequency_hz=None))]
    fn new(broadening_width_mm: f64, amplitude: f64, scenario: Option<String>, frequency_hz: Option<f64>) -> PyResult<Self> {
        let c = Calibration::new(broadening_width_mm * 1e-3, amplitude).and_then(|c| c.fitted_for(scenario, frequency_hz));
        Ok(CoreCalibration(c.map_err(to_py)?))
    }

    /// The calibration in the JSON file at `path` (as `save` or `arfi calibrate --json` write
    /// it; only `broadening_width_mm` and `amplitude` are required).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        Ok(CoreCalibration(Calibration::load(&path).map_err(to_py)?))
    }

    /// Writes the calibration as JSON at `path`, whole or not at all.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.0.save(&path).map_err(to_py)
    }

    /// Gaussian width W (mm).
    #[getter]
    fn broadening_width_mm(&self) -> f64 {
        self.0.broadening_width * 1e3
    }

    /// Scale from broadened force density (N/m³) to ARFI phase (rad).
    #[getter]
    fn amplitude(&self) -> f64 {
        self.0.amplitude
    }

    /// The squared difference over the mask at the fit (rad²); None when not recorded.
    #[getter]
    fn cost(&self) -> Option<f64> {
        self.0.cost.is_finite().then_some(self.0.cost)
    }

    /// Masked pixels the cost sums over; None when not recorded.
    #[getter]
    fn n_pixels(&self) -> Option<usize> {
        (self.0.n_pixels > 0).then_some(self.0.n_pixels)
    }

    /// Noise level of the image background (rad); None when not recorded.
    #[getter]
    fn noise_rad(&self) -> Option<f64> {
        self.0.noise.is_finite().then_some(self.0.noise)
    }

    /// The scenario's name it was fitted for; None: not recorded (applies to any).
    #[getter]
    fn scenario(&self) -> Option<String> {
        self.0.scenario.clone()
    }

    /// The frequency it was fitted at (Hz); None: not recorded (applies to any).
    #[getter]
    fn frequency_hz(&self) -> Option<f64> {
        self.0.frequency
    }

    /// The calibration file's document (what `save` writes and `arfi calibrate --json` starts
    /// with): what was not recorded is left out, not None.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        Ok(py.import("json")?.call_method1("loads", (self.0.to_json(),))?.cast_into::<PyDict>()?)
    }

    fn __repr__(slf: &Bound<'_, Self>) -> PyResult<String> {
        fields_repr(slf.as_any(), "Calibration")
    }
}

/// A hybrid estimate of the aberration, one phase per group (or per element with one group per
/// element). Subtract `phases_rad` to correct.
#[pyclass(module = "arfi._core", name = "Estimate", frozen)]
pub(crate) struct CoreEstimate {
    pub(crate) report: EstimateReport,
    pub(crate) method: Method,
}

#[pymethods]
impl CoreEstimate {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 33] = [
        "phases_rad",
        "cost",
        "evaluations",
        "seconds",
        "ambiguous",
        "method",
        "stop",
        "noise_floor",
        "n_pixels",
        "scale",
        "margin",
        "worst_recovery",
        "candidate_phases_rad",
        "candidate_costs",
        "candidate_recoveries",
        "suggested_phases_rad",
        "suggested_separation",
        "cost_history",
        "misfit",
        "model_mismatch",
        "group_phases_rad",
        "underdetermined",
        "kept_prediction",
        "prior_used",
        "posterior_cost",
        "nuisance",
        "next_acquisition",
        "converged",
        "support",
        "prior_check",
        "supported",
        "recommended",
        "recommended_phases_rad",
    ];

    /// The estimated phases (rad) in (-pi, pi], zero circular mean: subtract them to correct.
    #[getter]
    fn phases_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.report.estimate.phases.clone().into_pyarray(py)
    }

    /// The images' hybrid cost at the estimate (paper Eq. 4, rad²), with a prior too.
    #[getter]
    fn cost(&self) -> f64 {
        self.report.image_cost
    }

    /// Cost evaluations over all runs.
    #[getter]
    fn evaluations(&self) -> usize {
        self.report.estimate.evaluations
    }

    /// Wall-clock time of the estimation (s).
    #[getter]
    fn seconds(&self) -> f64 {
        self.report.estimate.seconds
    }

    /// True when clearly different solutions fit within the noise (see `worst_recovery` and
    /// `suggested_phases_rad`); per element with a prior, end points of searches of the element
    /// posterior from draws of the prior.
    #[getter]
    fn ambiguous(&self) -> bool {
        self.report.assessment.ambiguous
    }

    /// The estimator: `"nelder-mead"`, `"pso"` or `"lbfgs"`.
    #[getter]
    fn method(&self) -> &'static str {
        self.method.name()
    }

    /// Why the search ended: `"converged"`, `"evaluation limit"`, `"time limit"`,
    /// `"interrupted"`, or `"prediction kept"` (no search: see `kept_prediction`).
    #[getter]
    fn stop(&self) -> &'static str {
        self.report.estimate.stop.name()
    }

    /// Noise level of the images' background (rad).
    #[getter]
    fn noise_floor(&self) -> f64 {
        self.report.noise
    }

    /// Masked pixels over all images.
    #[getter]
    fn n_pixels(&self) -> usize {
        self.report.n_pixels
    }

    /// The amplitude scale at the estimate: the images' amplitude over the model's (1 unless
    /// fitted: `fit_amplitude`, or per element the fitted nuisance's).
    #[getter]
    fn scale(&self) -> f64 {
        self.report.scale
    }

    /// Cost margin of the candidates: `noise_floor²·chi²_0.95(G - 1)` (rad²) on the images
    /// alone, `chi²_0.95(G)/2` on a posterior (negative log posterior).
    #[getter]
    fn margin(&self) -> f64 {
        self.report.assessment.margin
    }

    /// The least focus (of the ideal) a correction with `phases_rad` leaves if another candidate
    /// were the truth (1 with one candidate); `ambiguous` when below the threshold (0.9).
    #[getter]
    fn worst_recovery(&self) -> f64 {
        self.report.assessment.worst_recovery
    }

    /// The phases (rad) of every candidate solution that fits within the margin.
    #[getter]
    fn candidate_phases_rad(&self) -> Vec<Vec<f64>> {
        self.report.assessment.candidates.iter().map(|c| c.phases.clone()).collect()
    }

    /// Their costs (rad²).
    #[getter]
    fn candidate_costs(&self) -> Vec<f64> {
        self.report.assessment.candidates.iter().map(|c| c.cost).collect()
    }

    /// The focus (of the ideal) the correction with `phases_rad` leaves if each were the truth.
    #[getter]
    fn candidate_recoveries(&self) -> Vec<f64> {
        self.report.assessment.candidates.iter().map(|c| c.predicted_recovery).collect()
    }

    /// Known group phases (rad) to add for one more acquisition that would best separate the
    /// candidates; per element with `suggest=True` (or with a prior, when `ambiguous`), the known
    /// per-element phases of `next_acquisition`; per element with a prior otherwise zeros.
    #[getter]
    fn suggested_phases_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        match &self.report.suggestion {
            Some(next) => next.known.clone().into_pyarray(py),
            None => self.report.assessment.suggested_phases.clone().into_pyarray(py),
        }
    }

    /// The smallest squared image difference between candidates with the suggested phases, in
    /// units of `noise_floor²`.
    #[getter]
    fn suggested_separation(&self) -> f64 {
        self.report.assessment.suggested_separation
    }

    /// The best cost after each evaluation of the winning run.
    #[getter]
    fn cost_history<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.report.estimate.history.clone().into_pyarray(py)
    }

    /// Best cost over its noise expectation, `cost / (n_pixels·noise_floor²)`: about 1 when the
    /// model explains the images.
    #[getter]
    fn misfit(&self) -> f64 {
        self.report.assessment.misfit
    }

    /// The cost is above the 95 % chi-square point of the noise and the misfit above 1.2: the
    /// model cannot explain the images (e.g. element-level aberrations fitted with group phases)
    /// and the correction may make the focus worse. Not judged (False) when `kept_prediction`:
    /// nothing was fitted.
    #[getter]
    fn model_mismatch(&self) -> bool {
        self.report.assessment.mismatch
    }

    /// Per-element estimation without a prior: the default-group estimate (rad) that
    /// warm-started it; None otherwise.
    #[getter]
    fn group_phases_rad<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.report.group_phases.clone().map(|g| g.into_pyarray(py))
    }

    /// Per-element estimation only: the images cannot determine a phase per element (one
    /// acquisition, or, without a prior, images that determine too few combinations of phases
    /// for the correction to be expected to beat the uncorrected beam or the group fit:
    /// `support`). Then also `ambiguous`, unless the prediction was kept.
    #[getter]
    fn underdetermined(&self) -> bool {
        self.report.underdetermined
    }

    /// Per-element estimation with a prior from one acquisition: `phases_rad` is the prediction
    /// itself, unsearched (one in-focus image cannot check a per-element correction of a
    /// prediction: one that fits it better than the truth can leave less focus). `misfit` then
    /// measures the prediction against the image; `model_mismatch` is not judged.
    #[getter]
    fn kept_prediction(&self) -> bool {
        self.report.kept_prediction
    }

    /// A predicted aberration entered the estimate (the posterior optimum; `ambiguous` judged on
    /// the posterior).
    #[getter]
    fn prior_used(&self) -> bool {
        self.report.prior_used
    }

    /// With a prior: the minimised negative log posterior (at the prediction when
    /// `kept_prediction`), `cost / (2·noise_floor²) + Σ (1 - cos(phi - prior)) / prior_std_rad²`;
    /// None without one.
    #[getter]
    fn posterior_cost(&self) -> Option<f64> {
        self.report.prior_used.then_some(self.report.estimate.cost)
    }

    /// Per-element estimates that fitted nuisance parameters (`fit_nuisance`); None otherwise.
    #[getter]
    fn nuisance(&self) -> Option<NuisanceFit> {
        self.report.nuisance.clone().map(NuisanceFit)
    }

    /// Per-element estimates made with `suggest=True`: the next image to take; None otherwise.
    #[getter]
    fn next_acquisition(&self) -> Option<NextAcquisition> {
        self.report.suggestion.clone().map(NextAcquisition)
    }

    /// The search converged: False when it stopped at its evaluation or time limit (`stop`), so
    /// that `phases_rad` is where it was stopped, not a minimum (True for a kept prediction).
    #[getter]
    fn converged(&self) -> bool {
        self.report.converged()
    }

    /// Per element without a prior: what the images determine of the estimate and the focus of
    /// the alternatives it is judged against; None otherwise.
    #[getter]
    fn support(&self) -> Option<EstimateSupport> {
        self.report.support.clone().map(EstimateSupport)
    }

    /// Per element with a prior (searched): whether the images agree with the prediction as the
    /// prior states it; None otherwise.
    #[getter]
    fn prior_check(&self) -> Option<EstimatePriorCheck> {
        self.report.prior_check.clone().map(EstimatePriorCheck)
    }

    /// Whether `phases_rad` is the correction to apply (`recommended == "estimate"`).
    #[getter]
    fn supported(&self) -> bool {
        self.report.recommendation.kind == Recommended::Estimate
    }

    /// Which phases to apply: `"estimate"`; `"prediction"` (the prior as given) when an estimate
    /// with a prior ends in `model_mismatch` or its images conflict with the prediction
    /// (`prior_check`); per element without a prior, `"uncorrected"` (zero
    /// phases) or `"groups"` (the default-group fit on its elements) when the images do not
    /// support the estimate or its search did not converge (see `support`).
    #[getter]
    fn recommended(&self) -> &'static str {
        self.report.recommendation.kind.name()
    }

    /// The phases to apply (subtract), rad: those `recommended` names.
    #[getter]
    fn recommended_phases_rad<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.report.recommendation.phases.clone().into_pyarray(py)
    }

    /// The result as a dict of its attributes (the JSON `arfi estimate` writes).
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let r = &self.report;
        format!(
            "Estimate({} phases, method='{}', cost={:.4}, misfit={:.3}, ambiguous={}, stop='{}')",
            r.estimate.phases.len(),
            self.method.name(),
            r.image_cost,
            r.assessment.misfit,
            if r.assessment.ambiguous { "True" } else { "False" },
            r.estimate.stop.name()
        )
    }
}

/// Nuisance parameters fitted jointly with per-element phases, named as the model-discrepancy
/// workflow's parameters; the model's values for those not fitted.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct NuisanceFit(FittedNuisance);

#[pymethods]
impl NuisanceFit {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 8] =
        ["fitted", "scale", "broadening_width_mm", "dx_mm", "dy_mm", "offset_rad", "slope_x_rad_per_mm", "slope_y_rad_per_mm"];

    /// The effects fitted (`"amplitude"`, `"broadening"`, `"registration_shift"`,
    /// `"background_phase"`).
    #[getter]
    fn fitted(&self) -> Vec<&'static str> {
        self.0.fitted.names()
    }

    /// Scale on the force-to-phase amplitude (1: the model's).
    #[getter]
    fn scale(&self) -> f64 {
        self.0.scale
    }

    /// Width W of the Gaussian broadening (mm).
    #[getter]
    fn broadening_width_mm(&self) -> f64 {
        self.0.broadening_width_mm
    }

    /// Shift of the images against the model along their first axis (mm).
    #[getter]
    fn dx_mm(&self) -> f64 {
        self.0.shift_mm[0]
    }

    /// Shift of the images against the model along their second axis (mm).
    #[getter]
    fn dy_mm(&self) -> f64 {
        self.0.shift_mm[1]
    }

    /// Per image: the constant background phase (rad).
    #[getter]
    fn offset_rad(&self) -> Vec<f64> {
        self.0.background.iter().map(|b| b[0]).collect()
    }

    /// Per image: the background phase ramp along the image's first axis (rad/mm).
    #[getter]
    fn slope_x_rad_per_mm(&self) -> Vec<f64> {
        self.0.background.iter().map(|b| b[1]).collect()
    }

    /// Per image: the background phase ramp along the image's second axis (rad/mm).
    #[getter]
    fn slope_y_rad_per_mm(&self) -> Vec<f64> {
        self.0.background.iter().map(|b| b[2]).collect()
    }

    /// The fit as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let n = &self.0;
        format!(
            "NuisanceFit(fitted=[{}], scale={:.4}, broadening_width_mm={:.3}, dx_mm={:.3}, dy_mm={:.3})",
            n.fitted.names().iter().map(|f| format!("'{f}'")).collect::<Vec<_>>().join(", "),
            n.scale,
            n.broadening_width_mm,
            n.shift_mm[0],
            n.shift_mm[1]
        )
    }
}

/// The next image to take for a per-element estimate: a focus shift, chosen among `candidates`
/// for raising most the focal intensity the correction is expected to leave (relative to the
/// ideal, on the linearised posterior). Its known phases are the estimate's
/// `suggested_phases_rad` (or `Simulation.focus_shift_phases(focus_shift_mm)`).
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct NextAcquisition(ShiftSuggestion);

#[pymethods]
impl NextAcquisition {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 4] = ["focus_shift_mm", "expected_focus_now", "expected_focus", "candidates"];

    /// The focus shift (mm; x, y, z) to image with next.
    #[getter]
    fn focus_shift_mm(&self) -> [f64; 3] {
        mm(self.0.shift)
    }

    /// Expected focal ARFI, relative to the ideal, after the correction from the images so far.
    #[getter]
    fn expected_focus_now(&self) -> f64 {
        self.0.expected_focus_now
    }

    /// The same with the suggested image added.
    #[getter]
    fn expected_focus(&self) -> f64 {
        self.0.expected_focus
    }

    /// Every candidate shift tried, best first.
    #[getter]
    fn candidates(&self) -> Vec<ShiftCandidate> {
        self.0.candidates.iter().cloned().map(ShiftCandidate).collect()
    }

    /// The suggestion as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let s = mm(self.0.shift);
        format!(
            "NextAcquisition(focus_shift_mm=[{:.1}, {:.1}, {:.1}], expected_focus_now={:.3}, expected_focus={:.3})",
            s[0], s[1], s[2], self.0.expected_focus_now, self.0.expected_focus
        )
    }
}

/// One focus shift considered for the next acquisition.
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct ShiftCandidate(Candidate);

#[pymethods]
impl ShiftCandidate {
    /// The attributes `to_dict` writes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 2] = ["focus_shift_mm", "expected_focus"];

    /// The focus shift (mm; x, y, z).
    #[getter]
    fn focus_shift_mm(&self) -> [f64; 3] {
        mm(self.0.shift)
    }

    /// Expected focal ARFI, relative to the ideal, after the correction from all images and this
    /// one.
    #[getter]
    fn expected_focus(&self) -> f64 {
        self.0.expected_focus
    }

    /// The candidate as a dict of its attributes.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let s = mm(self.0.shift);
        format!("ShiftCandidate(focus_shift_mm=[{:.1}, {:.1}, {:.1}], expected_focus={:.3})", s[0], s[1], s[2], self.0.expected_focus)
    }
}
