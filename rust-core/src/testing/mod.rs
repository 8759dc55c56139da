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
