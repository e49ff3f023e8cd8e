//! `ModeFit`: a prior mode's coefficient fitted to images, as a typed result.

use has_core::inverse::prior::mode_fit::ModeFit;
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

    /// The fitted image scale.
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
