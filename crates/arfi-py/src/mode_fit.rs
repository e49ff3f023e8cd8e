//! `ModeFit` and `ModesFit`: prior modes' coefficients fitted to images, as typed results.

use has_core::inverse::prior::mode_fit::ModeFit;
use has_core::inverse::prior::modes_fit::ModesFit;
use pyo3::prelude::*;

/// A prior mode's coefficient fitted to MR-ARFI images on a model that holds what the mode
/// linearises (the bone-speed mode on the head with the CT's bone).
#[pyclass(module = "arfi._core", name = "ModeFit", frozen)]
pub(crate) struct CoreModeFit(pub(crate) ModeFit);

#[pymethods]
impl CoreModeFit {
    /// The fitted coefficient (the mode's units; standard normal a priori).
    #[getter]
    fn coefficient(&self) -> f64 {
        self.0.coefficient
    }

    /// Its posterior standard deviation.
    #[getter]
    fn std(&self) -> f64 {
        self.0.std
    }

    /// The fitted amplitude scale (the images' amplitude over the model's).
    #[getter]
    fn scale(&self) -> f64 {
        self.0.scale
    }

    /// Chi-squared per pixel at the coefficient (about 1 when the model explains the images).
    #[getter]
    fn misfit(&self) -> f64 {
        self.0.misfit
    }

    /// Pixels fitted over all images.
    #[getter]
    fn n_pixels(&self) -> usize {
        self.0.n_pixels
    }

    /// The noise level (rad) the cost is normalised by.
    #[getter]
    fn noise_rad(&self) -> f64 {
        self.0.noise
    }

    /// Each coefficient tried with its cost (chi-squared plus the prior's c²), in increasing
    /// coefficient.
    #[getter]
    fn tried(&self) -> Vec<(f64, f64)> {
        self.0.tried.iter().map(|t| (t[0], t[1])).collect()
    }

    /// Whether the best coefficient lies between two tried (false: at the search's end, three
    /// prior standard deviations out, with the prior's spread as `std`).
    #[getter]
    fn bracketed(&self) -> bool {
        self.0.bracketed
    }

    fn __repr__(&self) -> String {
        let f = &self.0;
        format!(
            "ModeFit(coefficient={:.4}, std={:.4}, scale={:.4}, misfit={:.3}, n_pixels={})",
            f.coefficient, f.std, f.scale, f.misfit, f.n_pixels
        )
    }
}

/// Several prior modes' coefficients fitted jointly to MR-ARFI images on a model that holds what
/// they linearise (a CT prediction's pose and bone-speed modes on the head with the CT's bone),
/// by Gauss–Newton with the images' exact derivatives.
#[pyclass(module = "arfi._core", name = "ModesFit", frozen)]
pub(crate) struct CoreModesFit(pub(crate) ModesFit);

#[pymethods]
impl CoreModesFit {
    /// The fitted coefficients (each mode's units: one prior standard deviation).
    #[getter]
    fn coefficients(&self) -> Vec<f64> {
        self.0.coefficients.clone()
    }

    /// Their posterior standard deviations.
    #[getter]
    fn std(&self) -> Vec<f64> {
        self.0.std()
    }

    /// Their posterior covariance (rows, in the coefficients' units).
    #[getter]
    fn covariance(&self) -> Vec<Vec<f64>> {
        self.0.covariance.clone()
    }

    /// The fitted amplitude scale (the images' amplitude over the model's).
    #[getter]
    fn scale(&self) -> f64 {
        self.0.scale
    }

    /// Chi-squared per pixel at the fitted coefficients (about 1 when the model explains the
    /// images).
    #[getter]
    fn misfit(&self) -> f64 {
        self.0.misfit
    }

    /// Chi-squared per pixel with every coefficient zero (the prediction as it is).
    #[getter]
    fn misfit_at_zero(&self) -> f64 {
        self.0.misfit_at_zero
    }

    /// Pixels fitted over all images.
    #[getter]
    fn n_pixels(&self) -> usize {
        self.0.n_pixels
    }

    /// The noise level (rad) the cost is normalised by.
    #[getter]
    fn noise_rad(&self) -> f64 {
        self.0.noise
    }

    /// Gauss–Newton iterations made (each one batch march of every image and its derivatives).
    #[getter]
    fn iterations(&self) -> usize {
        self.0.iterations
    }

    /// Whether the last step was short against the posterior's spread (false: the iterations ran
    /// out first).
    #[getter]
    fn converged(&self) -> bool {
        self.0.converged
    }

    /// The fall of the image cost (chi-squared) from the prediction as it is to the fit.
    #[getter]
    fn evidence(&self) -> f64 {
        self.0.evidence
    }

    /// The 95 % point of chi-squared with as many degrees of freedom as modes, which `evidence`
    /// must exceed.
    #[getter]
    fn threshold(&self) -> f64 {
        self.0.threshold
    }

    /// Whether `evidence` exceeds `threshold`: the images support moving the prediction along
    /// the modes.
    #[getter]
    fn supported(&self) -> bool {
        self.0.supported
    }

    /// Per coefficient, whether it ended at the fit's bound (four prior standard deviations).
    #[getter]
    fn at_bound(&self) -> Vec<bool> {
        self.0.at_bound.clone()
    }

    fn __repr__(&self) -> String {
        let f = &self.0;
        format!(
            "ModesFit(coefficients={:?}, std={:?}, scale={:.4}, misfit={:.3}, n_pixels={})",
            f.coefficients.iter().map(|c| (c * 1e4).round() / 1e4).collect::<Vec<_>>(),
            f.std().iter().map(|c| (c * 1e4).round() / 1e4).collect::<Vec<_>>(),
            f.scale,
            f.misfit,
            f.n_pixels
        )
    }
}
