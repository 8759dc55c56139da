//! Sampling as program operations (crate::program): the warps a model's
//! or the material's sampling programs share.

use crate::optics::geometry::MIN_COS;
use crate::optics::program::Vec3;
use crate::program::{Builder, Mask, Value};
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

/// The largest f32 below 1: uniforms are clamped into [0, U_MAX] (the
/// native `unit_interval`, whose 1 - 2^-52 rounds to 1 in f32).
pub const U_MAX: f64 = 1.0 - 1.0 / 16_777_216.0;

/// A renderer's uniform as `warps::unit_interval` takes it: NaN and
/// infinities to 0, then into [0, U_MAX].
pub fn unit_interval_program(u: Value) -> Value {
    u.finite().select(u, 0.0).clamp(0.0, U_MAX)
}

/// `Mixture::sample_direction`'s first step: the component `j` of `count`
/// equally weighted ones that the uniform r0 picks, and r0 remapped into
/// [0, U_MAX] inside it (for the component's own choices).
pub fn component_choice(r0: Value, count: usize) -> (Value, Value) {
    let scaled = r0 * count as f64;
    let j = scaled.floor().min((count - 1) as f64);
    (j, (scaled - j).clamp(0.0, U_MAX))
}

/// values[j] for the component `j` of `component_choice` (a chain of
/// selects: a program has no indexed registers).
pub fn pick<'a>(j: Value<'a>, values: &[Value<'a>]) -> Value<'a> {
    values[1..]
        .iter()
        .enumerate()
        .fold(values[0], |acc, (i, &v)| {
            j.eq((i + 1) as f64).select(v, acc)
        })
}

/// The defensive part's direction (`warps::cosine_direction` where
/// `cosine`, else `warps::uniform_direction`) from r1 and the azimuth's
/// cosine and sine (2 pi r2, which a model's lobe may share).
pub fn defensive_direction_program<'a>(
    cosine: Mask<'a>,
    r1: Value<'a>,
    cos_phi: Value<'a>,
    sin_phi: Value<'a>,
) -> Vec3<'a> {
    let z_cos = (1.0 - r1).max(0.0).sqrt().max(2.0 * MIN_COS);
    let z_uni = (1.0 - r1).max(2.0 * MIN_COS);
    let rho = cosine.select(r1.sqrt(), (1.0 - z_uni * z_uni).max(0.0).sqrt());
    [rho * cos_phi, rho * sin_phi, cosine.select(z_cos, z_uni)]
}

/// `warps::defensive_density` at the outgoing cosine.
pub fn defensive_density_program(cos_o: Value) -> Value {
    (cos_o * (1.0 / PI) + 0.5 / PI) * 0.5
}
