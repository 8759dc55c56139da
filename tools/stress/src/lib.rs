//! Numerical stress of the Stam core and the run-time/error survey of its
//! accuracy knobs.
//!
//! - [`run`]: the stress runner (random materials over the accepted ranges,
//!   random and hostile directions and wavelengths, every ABI entry point in
//!   f32 beside the Rust API in f64). The `stress` binary and the CI test
//!   call it.
//! - [`pareto`]: the accuracy knobs, their configurations and the error of
//!   each against the exhaustive f64 reference (the `pareto` binary and the
//!   `pareto` criterion bench share the list).
//! - [`gen`]: deterministic random generators (materials, directions,
//!   wavelengths); no external RNG so that a seed reproduces a run exactly.
//! - [`programs`]: the material's exported programs (stam.h's
//!   `stam_brdf_export_program`) run on hostile lanes with the core's CPU
//!   executor, and their contract (the runner and the fuzz test use it).
//! - [`materials`]: the project's shared list of test materials
//!   (tests/materials.json), which the survey and the tests draw from.

// `!(x <= y)` is how NaN is caught along with the out-of-range values, as in
// the core.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod gen;
pub mod materials;
pub mod pareto;
pub mod programs;
pub mod run;
