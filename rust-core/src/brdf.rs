//! The material: a plan built once from parameters, evaluated many times.

pub struct Brdf;
