//! Stam's "Diffraction Shaders" (SIGGRAPH 1999) as a BRDF library.
//!
//! All the physics of the project lives here: the four microsurface models
//! (isotropic and anisotropic Gaussian, fractal, periodic), the coherent
//! specular lobe, Fresnel, colour by wavelength integration and the C ABI
//! that the Mitsuba plugin calls. See `docs/physics.md` for the formulas.

// `!(x > 0.0)` is how this crate rejects NaN along with the out-of-range
// values; the negated comparisons are deliberate.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod benchmark;
pub mod error;
pub mod ffi;
pub mod float_env;
mod json;
pub mod material;
pub mod models;
pub mod optics;
pub mod program;
pub mod progress;
pub mod rigorous;
pub mod sampling;
pub mod special;
pub mod spectrum;
#[cfg(test)]
mod testing;

pub use error::StamError;
pub use material::{params, Brdf};
pub use models::{fractal, gaussian, periodic};
pub use optics::{fresnel, geometry};
