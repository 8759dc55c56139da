//! Optics that knows no surface model: the geometry of a direction pair
//! (`geometry`) and the Fresnel reflectance with its metals (`fresnel`,
//! `metals`), and a grating's profile (`profile`).

pub mod fresnel;
pub mod geometry;
/// Optical constants (eta, k) of aluminium, silver, gold, copper and chromium
/// at 350..850 nm, generated from Mitsuba 3's data files.
pub mod metals;
#[cfg(test)]
mod param_tests;
pub mod profile;
/// The pair geometry and Fresnel lookups as program operations.
pub mod program;
