//! Optics that knows no surface model: the geometry of a direction pair
//! (`geometry`) and the Fresnel reflectance with its metals (`fresnel`,
//! `metals`).

pub mod fresnel;
pub mod geometry;
pub mod metals;
