//! # has-core
//!
//! Hybrid Angular Spectrum (HAS) beam propagation and the MR-ARFI forward model used for
//! hybrid simulation–MR-ARFI phase aberration correction of focused-ultrasound beams
//! (Vyas, Kaye & Butts Pauly, Med Phys 41(3), 2014). Pure Rust; no Python.
//!
//! Conventions: SI units; the transducer frame (beam along +z, planar array in z = 0); time
//! dependence `exp(-i·omega·t)`, so a phase `phi` on an element delays its emission by
//! `phi / (2·pi·f)` and multiplies its complex drive by `exp(+i·phi)`.
//!
//! The main types are re-exported here: [`Scenario`], [`Simulation`], [`Field`], [`HasPlan`],
//! [`Estimator`], [`diagnose()`].
//!
//! ```no_run
//! use has_core::{Scenario, Simulation};
//! let sim = Simulation::new(&Scenario::default()).unwrap();
//! let image = sim.arfi_image(&[]).unwrap(); // ideal MR-ARFI image, rad
//! ```

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod aberration;
pub mod arfi;
pub mod basis;
pub mod calibrate;
pub mod cost;
pub mod diagnose;
pub mod error;
pub mod estimate;
pub mod estimation;
pub mod fft;
pub mod grid;
pub mod has;
pub mod medium;
pub mod memory;
pub mod phase;
pub mod rayleigh;
pub mod scenario;
pub mod simulation;
pub mod source;
pub mod steering;
pub mod transducer;

pub use diagnose::{diagnose, Diagnosis};
pub use error::{HasError, Result};
pub use estimate::{Estimate, Estimator};
pub use grid::Grid;
pub use has::{HasOptions, HasPlan, InterfaceModel, RecordSpec, Recording};
pub use medium::{Material, Medium};
pub use num_complex::Complex64;
pub use scenario::Scenario;
pub use simulation::{Field, Simulation};
pub use transducer::Transducer;
