//! Sampling as program operations (crate::program): the warps a model's
//! or the material's sampling programs share.

use crate::optics::program::Vec3;
use crate::program::{Builder, Value};
use std::f64::consts::PI;

/// `warps::cosine_direction` (Malley: a uniform disc point lifted to the
/// hemisphere), density cos / pi.
pub fn cosine_direction_program<'a>(b: &'a Builder, r1: Value<'a>, r2: Value<'a>) -> Vec3<'a> {
    let r = r1.clamp(0.0, 1.0).sqrt();
    let phi = r2 * (2.0 * PI);
    let z = (1.0 - r * r).max(0.0).sqrt();
    let _ = b;
    [r * phi.cos(), r * phi.sin(), z]
}

/// The density of `cosine_direction_program` at unit wo (0 below the
/// horizon).
pub fn cosine_density_program(wo: Vec3) -> Value {
    (wo[2] * (1.0 / PI)).max(0.0)
}
