//! has-core's integration tests, one module per concept, built as one test binary: one compile
//! and link instead of one per file, and libtest runs every module's tests from one queue (two at
//! a time on two cores) instead of one file after another. `cargo test -p has-core --test suite
//! diagnose::` runs one module. The allocation count (`tests/allocations.rs`) stays a binary of
//! its own: its counting allocator sees every thread of the process.

mod common;

mod bone;
mod ct;
mod diagnose;
mod elastic_march;
mod element_basis;
mod estimation;
mod focal;
mod fuzz;
mod hemisphere;
mod information;
mod layering;
mod mode_fit;
mod modes_fit;
mod mr_tissue;
mod nuisance;
mod outline;
mod physics;
mod prediction;
mod prior;
mod reciprocity;
mod shear;
mod support;
mod validation;
