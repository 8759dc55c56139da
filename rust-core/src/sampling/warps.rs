//! Hemisphere warps, inverse CDFs and discrete choices shared by every
//! strategy (no surface model here).

use crate::optics::geometry::MIN_COS;
use glam::DVec3;
use std::f64::consts::PI;

/// The largest f64 below 1: uniforms are kept in [0, 1).
pub const ONE_MINUS: f64 = 1.0 - f64::EPSILON;

/// Van der Corput radical inverse of `index` in `base`.
pub fn radical_inverse(mut index: usize, base: usize) -> f64 {
    let (mut value, mut scale) = (0.0, 1.0 / base as f64);
    while index > 0 {
        value += (index % base) as f64 * scale;
        index /= base;
        scale /= base as f64;
    }
    value
}

/// Standard normal CDF.
#[inline]
pub fn normal_cdf(x: f64) -> f64 {
    0.5 * libm::erfc(-x * std::f64::consts::FRAC_1_SQRT_2)
}

/// (u, v) -> wo = (-wi.x - u, -wi.y - v, +sqrt(1 - x^2 - y^2)).
#[inline]
pub fn uv_to_direction(wi: DVec3, u: f64, v: f64) -> Option<DVec3> {
    let x = -wi.x - u;
    let y = -wi.y - v;
    let r2 = x * x + y * y;
    if !(r2 < 1.0) {
        return None;
    }
    let z = (1.0 - r2).sqrt();
    if z > MIN_COS {
        Some(DVec3::new(x, y, z))
    } else {
        None
    }
}

/// Solid-angle density of the defensive part: an equal mixture of cosine-
/// weighted and uniform sampling of the hemisphere. The uniform half keeps
/// the weights f cos / pdf bounded at the horizon, where Stam's G ~ 1/cos_o
/// makes f diverge (cosine weights grow like f there).
#[inline]
pub fn defensive_density(cos_o: f64) -> f64 {
    0.5 * (cos_o / PI + 0.5 / PI)
}

#[inline]
pub fn uniform_direction(r1: f64, r2: f64) -> DVec3 {
    let z = (1.0 - r1).max(MIN_COS * 2.0);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * r2;
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

#[inline]
pub fn cosine_direction(r1: f64, r2: f64) -> DVec3 {
    let r = r1.sqrt();
    let phi = 2.0 * PI * r2;
    DVec3::new(
        r * phi.cos(),
        r * phi.sin(),
        (1.0 - r1).max(0.0).sqrt().max(MIN_COS * 2.0),
    )
}

/// Maps NaN and values outside [0, 1) into [0, 1).
#[inline]
pub fn unit_interval(x: f64) -> f64 {
    if x >= 0.0 {
        x.min(ONE_MINUS)
    } else {
        0.0
    }
}

/// Index i with cumsum(prob)[i-1] <= t < cumsum(prob)[i] (prob sums to ~1).
pub fn pick(prob: &[f64], t: f64) -> usize {
    let mut acc = 0.0;
    for (i, p) in prob.iter().enumerate() {
        acc += p;
        if t < acc {
            return i;
        }
    }
    // Rounding left t above the total: the last non-zero entry.
    prob.iter().rposition(|&p| p > 0.0).unwrap_or(0)
}

/// Index i with cdf[i-1] <= t < cdf[i] (cdf non-decreasing, ending at ~1):
/// never an entry of zero mass.
pub fn pick_cdf(cdf: &[f64], t: f64) -> usize {
    let i = cdf.partition_point(|&c| c <= t);
    if i < cdf.len() {
        return i;
    }
    // Rounding left t above the total: the last entry of non-zero mass.
    let mut last = cdf.len().saturating_sub(1);
    while last > 0 && !(cdf[last] > cdf[last - 1]) {
        last -= 1;
    }
    last
}

/// Inverse of the standard normal CDF (Acklam's rational approximation,
/// relative error < 1.2e-9), for p in (0, 1); clamps p into [1e-300, 1 - eps].
pub fn inverse_normal(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    const P_LOW: f64 = 0.02425;
    let p = if p >= 1e-300 {
        p.min(ONE_MINUS)
    } else {
        1e-300
    };
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < P_LOW {
        tail((-2.0 * p.ln()).sqrt())
    } else if p <= 1.0 - P_LOW {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    }
}
