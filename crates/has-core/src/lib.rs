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

#![warn(missing_docs)]
// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod control;
pub mod error;
pub mod focal;
pub mod grouping;
pub mod inverse;
pub mod memory;
pub mod nifti;
pub mod numeric;
pub mod phase;
pub mod physics;
pub mod prediction;
pub mod reference;
pub mod scenario;
pub mod section;
pub mod simulation;
pub mod validation;

pub use control::Control;
pub use error::{HasError, Result};
pub use inverse::diagnose::{diagnose, Diagnosis};
pub use inverse::estimate::{Estimate, Estimator};
pub use num_complex::Complex64;
pub use physics::grid::Grid;
pub use physics::medium::{Material, Medium};
pub use physics::propagation::{HasOptions, HasPlan, InterfaceModel, RecordSpec, Recording};
pub use physics::transducer::Transducer;
pub use scenario::Scenario;
pub use section::Section;
pub use simulation::{Field, Simulation};
