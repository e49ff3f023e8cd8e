//! What to estimate with: the core's `EstimateRequest` as a typed, validated Python value. Each
//! option is checked once, when the options are made (by the core's own rules), and its getter
//! reads it back in the unit of its name.

use crate::convert::{count, names, number, phases, rows};
use crate::error::{invalid, to_py};
use crate::results::fields_dict;
use has_core::inverse::element::nuisance::Nuisance;
use has_core::inverse::estimate::workflow::{EstimateRequest, Method};
use has_core::inverse::prior::Prior;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Options of a hybrid estimate (every one optional; an unknown or ill-formed one is an error
/// naming it).
///
/// - `method`: `"lbfgs"` (analytic gradient, seeded multi-start; the default), `"nelder-mead"`
///   (the paper's: zero start, <= 8000 evaluations) or `"pso"`.
/// - `max_evaluations`, `time_limit_s` (per stage), `starts` (L-BFGS only): the search's limits.
///   Per element `max_evaluations` (default 200; 120 when `fit_nuisance` fits W or the shift)
///   bounds the fit on the element basis.
/// - `seed` (default 0): the random starts, the swarm and the ambiguity assessment.
/// - `fit_amplitude`: fit one amplitude scale for all images.
/// - `threshold` (default 0.9): a rival solution counts as ambiguous when it would leave less than
///   this fraction of the ideal focus after the estimate's correction.
/// - `noise_rad`: the images' noise standard deviation (rad) where it is known (e.g. the standard
///   deviation of the difference of two reference acquisitions over sqrt(2)); by default each
///   image's floor is estimated from its background, which counts pixel-scale structure there as
///   noise. The misfit, `model_mismatch`, `prior_check` and the posterior's weights use it.
/// - `prior` (rad, per element or per group, in the sign of the estimate: subtracting it
///   corrects) with `prior_std_rad`, the expected error of each predicted phase: the estimate is
///   then the posterior optimum (the images' cost as a Gaussian likelihood at the noise plus a
///   von Mises prior `(1 - cos(phi - prior)) / prior_std_rad**2` per phase).
/// - `prior_correlation_mm`: the prediction's errors are a smooth field over the aperture,
///   correlated over this length; a per-element estimate then corrects the prediction by smooth
///   fields only (reduced-rank Gaussian random field, Solin & Särkkä 2020).
/// - `prior_modes` (per element, with `prior_correlation_mm`): error modes of known shape, shape
///   `(modes, n_elements)` in rad, each the change of the predicted phases when one input of the
///   prediction is off by one standard deviation; each mode's coefficient (standard normal a
///   priori) is fitted with the smooth corrections.
/// - `fit_nuisance`: what else the images may differ in from the model, fitted with per-element
///   phases (a list or a comma-separated string of `"amplitude"`, `"broadening"`,
///   `"registration_shift"`, `"background_phase"`, or `"all"`); group estimates fit the
///   amplitude only.
/// - `suggest` (per element): also choose the next image to take (a focus shift).
#[pyclass(module = "arfi._core", frozen)]
pub(crate) struct EstimateOptions(pub(crate) EstimateRequest);

#[pymethods]
impl EstimateOptions {
    /// The options `to_dict` writes and `replace` takes, in order.
    #[classattr]
    #[pyo3(name = "_fields")]
    const FIELDS: [&'static str; 14] = [
        "method",
        "max_evaluations",
        "time_limit_s",
        "seed",
        "starts",
        "fit_amplitude",
        "threshold",
        "noise_rad",
        "prior",
        "prior_std_rad",
        "prior_correlation_mm",
        "prior_modes",
        "fit_nuisance",
        "suggest",
    ];

    #[new]
    #[pyo3(signature = (
        *,
        method="lbfgs",
        max_evaluations=None,
        time_limit_s=None,
        seed=None,
        starts=None,
        fit_amplitude=false,
        threshold=None,
        noise_rad=None,
        prior=None,
        prior_std_rad=None,
        prior_correlation_mm=None,
        prior_modes=None,
        fit_nuisance=None,
        suggest=false,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        method: &str,
        max_evaluations: Option<&Bound<'_, PyAny>>,
        time_limit_s: Option<&Bound<'_, PyAny>>,
        seed: Option<&Bound<'_, PyAny>>,
        starts: Option<&Bound<'_, PyAny>>,
        fit_amplitude: bool,
        threshold: Option<&Bound<'_, PyAny>>,
        noise_rad: Option<&Bound<'_, PyAny>>,
        prior: Option<&Bound<'_, PyAny>>,
        prior_std_rad: Option<&Bound<'_, PyAny>>,
        prior_correlation_mm: Option<&Bound<'_, PyAny>>,
        prior_modes: Option<&Bound<'_, PyAny>>,
        fit_nuisance: Option<&Bound<'_, PyAny>>,
        suggest: bool,
    ) -> PyResult<Self> {
        let prior = Prior::from_parts(
            phases(prior, "prior")?,
            number(prior_std_rad, "prior_std_rad")?,
            number(prior_correlation_mm, "prior_correlation_mm")?.map(|l| l * 1e-3),
            rows(prior_modes, "prior_modes")?,
        )
        .map_err(to_py)?;
        let request = EstimateRequest {
            method: Method::parse(method).map_err(to_py)?,
            max_evaluations: count(max_evaluations, "max_evaluations")?,
            time_limit_s: number(time_limit_s, "time_limit_s")?,
            seed: count(seed, "seed")?.unwrap_or(0) as u64,
            starts: count(starts, "starts")?,
            fit_amplitude,
            noise_rad: number(noise_rad, "noise_rad")?,
            nuisance: Nuisance::parse(&names(fit_nuisance, "fit_nuisance")?).map_err(to_py)?,
            threshold: number(threshold, "threshold")?.unwrap_or(EstimateRequest::default().threshold),
            prior,
            suggest,
        };
        request.check().map_err(to_py)?;
        Ok(EstimateOptions(request))
    }

    /// The search method: `"lbfgs"`, `"nelder-mead"` or `"pso"`.
    #[getter]
    fn method(&self) -> &'static str {
        self.0.method.name()
    }

    /// The evaluation limit (None: the method's default).
    #[getter]
    fn max_evaluations(&self) -> Option<usize> {
        self.0.max_evaluations
    }

    /// The wall-clock limit per stage (s; None: none).
    #[getter]
    fn time_limit_s(&self) -> Option<f64> {
        self.0.time_limit_s
    }

    /// The seed of the random starts, the swarm and the ambiguity assessment.
    #[getter]
    fn seed(&self) -> u64 {
        self.0.seed
    }

    /// L-BFGS starts (None: 20).
    #[getter]
    fn starts(&self) -> Option<usize> {
        self.0.starts
    }

    /// Whether one amplitude scale for all images is fitted.
    #[getter]
    fn fit_amplitude(&self) -> bool {
        self.0.fit_amplitude
    }

    /// The fraction of the ideal focus below which a rival solution makes the estimate ambiguous.
    #[getter]
    fn threshold(&self) -> f64 {
        self.0.threshold
    }

    /// The images' noise (rad) where it is known (None: each image's background floor).
    #[getter]
    fn noise_rad(&self) -> Option<f64> {
        self.0.noise_rad
    }

    /// The predicted aberration (rad), or None.
    #[getter]
    fn prior<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.0.prior.as_ref().map(|p| p.mean().to_vec().into_pyarray(py))
    }

    /// The expected error of each predicted phase (rad), or None.
    #[getter]
    fn prior_std_rad(&self) -> Option<f64> {
        self.0.prior.as_ref().map(Prior::std_rad)
    }

    /// The length over which the prediction's errors are correlated (mm), or None.
    #[getter]
    fn prior_correlation_mm(&self) -> Option<f64> {
        self.0.prior.as_ref().and_then(Prior::correlation_length).map(|l| l * 1e3)
    }

    /// The prior's error modes, shape (modes, n_elements) in rad, or None.
    #[getter]
    fn prior_modes<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        match self.0.prior.as_ref().map(Prior::modes).filter(|m| !m.is_empty()) {
            Some(m) => Ok(Some(PyArray2::from_vec2(py, m).map_err(|e| invalid("prior_modes", e.to_string()))?)),
            None => Ok(None),
        }
    }

    /// The nuisance parameters fitted with per-element phases (names as `diagnose` reports them).
    #[getter]
    fn fit_nuisance(&self) -> Vec<&'static str> {
        self.0.nuisance.names()
    }

    /// Whether a per-element estimate also suggests the next acquisition.
    #[getter]
    fn suggest(&self) -> bool {
        self.0.suggest
    }

    /// The same options with `changes` (keyword options as the constructor takes them), checked
    /// again.
    #[pyo3(signature = (**changes))]
    fn replace<'py>(slf: &Bound<'py, Self>, changes: Option<&Bound<'py, PyDict>>) -> PyResult<Bound<'py, PyAny>> {
        let options = fields_dict(slf.as_any())?;
        if let Some(c) = changes {
            for (k, _) in c.iter() {
                if !Self::FIELDS.contains(&k.extract::<String>()?.as_str()) {
                    return Err(invalid(k.to_string(), format!("is not an estimate option (options: {})", Self::FIELDS.join(", "))));
                }
            }
            options.update(c.as_mapping())?;
        }
        slf.get_type().call((), Some(&options))
    }

    /// The options as a dict (arrays as lists), the keyword arguments that make them again.
    fn to_dict<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyDict>> {
        fields_dict(slf.as_any())
    }

    fn __repr__(&self) -> String {
        let r = &self.0;
        let mut parts = vec![format!("method='{}'", r.method.name())];
        let mut opt = |name: &str, v: Option<String>| parts.extend(v.map(|v| format!("{name}={v}")));
        opt("max_evaluations", r.max_evaluations.map(|v| v.to_string()));
        opt("time_limit_s", r.time_limit_s.map(|v| v.to_string()));
        opt("seed", (r.seed != 0).then(|| r.seed.to_string()));
        opt("starts", r.starts.map(|v| v.to_string()));
        opt("fit_amplitude", r.fit_amplitude.then(|| "True".into()));
        opt("noise_rad", r.noise_rad.map(|v| v.to_string()));
        opt("prior", r.prior.as_ref().map(|p| format!("<{} phases>", p.mean().len())));
        opt("prior_std_rad", r.prior.as_ref().map(|p| p.std_rad().to_string()));
        opt("prior_correlation_mm", r.prior.as_ref().and_then(|p| p.correlation_length()).map(|l| (l * 1e3).to_string()));
        opt("prior_modes", r.prior.as_ref().filter(|p| !p.modes().is_empty()).map(|p| format!("<{} modes>", p.modes().len())));
        opt("fit_nuisance", r.nuisance.any().then(|| format!("{:?}", r.nuisance.names())));
        opt("suggest", r.suggest.then(|| "True".into()));
        format!("EstimateOptions({})", parts.join(", "))
    }
}
