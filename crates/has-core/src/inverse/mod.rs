//! The inverse layer: phase arithmetic, the hybrid cost and its per-element field basis, the
//! estimators, a predicted aberration as prior and the estimation workflow, what per-element
//! acquisitions tell (and which to take next), calibration, and the model-discrepancy workflow.

pub mod basis;
pub mod calibrate;
pub mod cost;
pub mod diagnose;
pub mod estimate;
pub mod estimation;
pub mod information;
pub mod linear;
pub mod mode_fit;
pub mod nuisance;
pub mod phase;
pub mod prior;
pub mod smooth_prior;
pub mod view_fit;
