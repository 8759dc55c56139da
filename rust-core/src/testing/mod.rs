//! Test utilities shared by the core's unit tests: direction sets and the
//! chi-square goodness-of-fit harness of the sampling strategies.

pub mod chi2;
pub mod params;
pub mod programs;

use glam::DVec3;

/// A material's JSON with `"energy": "stam"` unless it names its energy:
/// the tests of a model's own formula (its programs against its native
/// path, its parameters, its tables) test Stam's f, not the default's
/// energy scaling, which has its own tests (material::energy_tests).
pub fn stam_formula(json: &str) -> String {
    let mut value: serde_json::Value =
        serde_json::from_str(json).unwrap_or_else(|e| panic!("{json}: {e}"));
    let object = value
        .as_object_mut()
        .unwrap_or_else(|| panic!("{json}: not an object"));
    object
        .entry("energy")
        .or_insert_with(|| serde_json::Value::String("stam".into()));
    value.to_string()
}

/// Pairs of directions at four incidences, around each one's mirror
/// direction (where a BRDF's features are) and towards the horizon.
pub fn directions() -> Vec<(DVec3, DVec3)> {
    let mut out = Vec::new();
    for &(ti, phi_i) in &[(0.05, 0.0), (0.5, 0.3), (1.1, 1.0), (1.45, 2.0)] {
        let wi = DVec3::new(
            f64::sin(ti) * f64::cos(phi_i),
            f64::sin(ti) * f64::sin(phi_i),
            f64::cos(ti),
        );
        for &(to, dphi) in &[(0.0, 0.0), (0.1, 0.2), (0.3, 0.5), (0.6, 2.5), (1.2, 3.0)] {
            // Around the mirror direction of wi.
            let m = DVec3::new(-wi.x, -wi.y, wi.z);
            let tilt = DVec3::new(
                f64::sin(to) * f64::cos(dphi),
                f64::sin(to) * f64::sin(dphi),
                0.0,
            );
            let wo = (m + tilt).normalize();
            if wo.z > 0.01 {
                out.push((wi, wo));
            }
        }
    }
    out
}

/// Directional-albedo estimates f cos / pdf of `n` samples drawn by `draw`
/// (a direction and its pdf; pdf 0 for a failed sample, which weighs 0).
pub fn sampled_weights(
    n: usize,
    mut draw: impl FnMut() -> (DVec3, f64),
    f: impl Fn(DVec3) -> f64,
) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let (wo, pdf) = draw();
            if pdf > 0.0 {
                f(wo) * wo.z / pdf
            } else {
                0.0
            }
        })
        .collect()
}

/// The same estimates with cosine-weighted directions from `rng`.
pub fn cosine_weights(
    n: usize,
    rng: &mut crate::benchmark::SplitMix64,
    f: impl Fn(DVec3) -> f64,
) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let (r1, r2) = (rng.next_f64(), rng.next_f64());
            let (r, phi) = (r1.sqrt(), 2.0 * std::f64::consts::PI * r2);
            let wo = DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - r1).max(1e-12).sqrt());
            std::f64::consts::PI * f(wo)
        })
        .collect()
}

/// Mean and unbiased variance.
pub fn mean_var(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var)
}
