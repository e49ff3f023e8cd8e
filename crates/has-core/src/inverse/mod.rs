//! The inverse layer: from measured MR-ARFI images back to the phase aberration. It uses the
//! forward model (physics, simulation) and nothing outside it uses it. Its families, each using
//! only those listed before it:
//!
//! - [`linear`]: small dense linear algebra (variable projection, Cholesky) the families share.
//! - [`cost`]: the hybrid cost of paper Eq. 4 on per-pixel group kernels, the [`cost::Objective`]
//!   every estimator minimises, and the way from measured images to it (masks, noise floor).
//! - [`calibrate`]: the broadening width fitted to a no-aberration image (paper Eq. 2).
//! - [`calibration_file`]: a calibration saved, loaded and checked against the scenario it was fitted for.
//! - [`element`]: per-element estimation's own model: the field basis of every element, its cost
//!   and gradient, and the nuisance and MR view fitted with the phases.
//! - [`prior`]: a predicted aberration as prior (independent or smooth errors) and the fit of a
//!   prediction's error mode to images.
//! - [`estimate`]: the estimators, the assessment of their answer, the information of
//!   per-element acquisitions (and the next to take), and the estimation workflow as one call.
//! - [`diagnose`]: the model-discrepancy workflow, which names the effects the model lacks.

pub mod calibrate;
pub mod calibration_file;
pub mod cost;
pub mod diagnose;
pub mod element;
pub mod estimate;
pub mod linear;
pub mod prior;
