//! Properties every material must have, over random directions, wavelengths
//! and parameters (proptest): finite, non-negative outputs for any input,
//! zero below the horizon and outside the visible band, reciprocity.

use glam::DVec3;
use proptest::prelude::*;
use stam::Brdf;

/// A random valid material description spanning the accepted ranges,
/// including the extremes the issue names (sigma 1e-5..50 um, correlation
/// 0.01..1e4 um, hurst near 0 and 1, periods 0.3..100 um, coherence from 1.5
/// periods to 5 mm).
fn material() -> impl Strategy<Value = String> {
    let log_uniform = |lo: f64, hi: f64| (0.0f64..1.0).prop_map(move |t| lo * (hi / lo).powf(t));
    let fresnel = prop_oneof![
        Just("\"aluminium\"".to_string()),
        Just("\"gold\"".to_string()),
        (0.01f64..=1.0).prop_map(|r| format!("{r}")),
        (0.1f64..5.0, 0.0f64..10.0).prop_map(|(n, k)| format!("{{\"eta\":{n},\"k\":{k}}}")),
    ];
    let gaussian = (log_uniform(1e-5, 50.0), log_uniform(0.01, 1e4))
        .prop_map(|(s, t)| format!("\"surface\":\"gaussian\",\"sigma_um\":{s},\"corr_um\":{t}"));
    let anisotropic = (
        log_uniform(1e-5, 50.0),
        log_uniform(0.01, 1e4),
        log_uniform(0.01, 1e4),
    )
        .prop_map(|(s, tx, ty)| {
            format!(
                "\"surface\":\"gaussian\",\"sigma_um\":{s},\"corr_x_um\":{tx},\"corr_y_um\":{ty}"
            )
        });
    let fractal = (
        prop_oneof![Just(0.01f64), Just(0.999), Just(1.0), 0.02f64..1.0],
        log_uniform(1e-5, 50.0),
        log_uniform(0.01, 1e4),
    )
        .prop_map(|(h, s, l)| {
            format!("\"surface\":\"fractal\",\"hurst\":{h},\"sigma_um\":{s},\"lag_um\":{l}")
        });
    let periodic = (log_uniform(0.3, 100.0), 0.0f64..1.0, 0.001f64..1.0, 0.01f64..1.0, 0usize..3)
        .prop_map(|(period, coh_t, h, width_frac, kind)| {
            let coherence = (1.5 * period) * (5000.0 / (1.5 * period)).powf(coh_t);
            let profile = match kind {
                0 => format!("\"profile\":\"rect\",\"height_um\":{h},\"width_um\":{}", width_frac * period),
                1 => format!("\"profile\":\"sine\",\"height_um\":{h}"),
                _ => format!("\"profile\":{{\"heights_um\":[0,{h},{},0.05]}}", h * width_frac),
            };
            format!("\"surface\":\"periodic\",\"period_um\":{period},\"coherence_um\":{coherence},{profile}")
        });
    // The default (energy conserving) builds a table per material (0.1-0.4
    // s): one material in ten; Stam's formula for the rest.
    let energy = prop_oneof![9 => Just("stam"), 1 => Just("conserving")];
    (
        prop_oneof![gaussian, anisotropic, fractal, periodic],
        fresnel,
        energy,
    )
        .prop_map(|(surface, fresnel, energy)| {
            format!("{{{surface},\"fresnel\":{fresnel},\"energy\":\"{energy}\"}}")
        })
}

/// Directions including grazing (cos down to 1e-8), below the horizon and
/// NaN components.
fn direction() -> impl Strategy<Value = DVec3> {
    let regular = (-1.0f64..1.0, 0.0f64..std::f64::consts::TAU).prop_map(|(z, phi)| {
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    });
    let grazing = (1e-8f64..1e-3, 0.0f64..std::f64::consts::TAU).prop_map(|(z, phi)| {
        let r = (1.0 - z * z).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    });
    prop_oneof![
        6 => regular,
        2 => grazing,
        1 => Just(DVec3::new(f64::NAN, 0.0, 1.0)),
        1 => Just(DVec3::Z),
    ]
}

fn wavelength() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => 360.0f64..830.0,
        1 => Just(0.0),
        1 => Just(f64::NAN),
        1 => -10.0f64..360.0,
        1 => 830.0f64..2000.0,
    ]
}

fn ok(x: f64) -> bool {
    x.is_finite() && x >= 0.0
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn outputs_are_finite_and_non_negative(
        json in material(),
        pairs in proptest::collection::vec((direction(), direction(), wavelength()), 8),
    ) {
        let brdf = Brdf::from_json(&json).map_err(|e| TestCaseError::fail(format!("{json}: {e}")))?;
        for (wi, wo, lambda) in pairs {
            let f = brdf.eval_spectral(wi, wo, lambda);
            prop_assert!(ok(f), "{json}: f({wi:?}, {wo:?}, {lambda}) = {f}");
            if !(360.0..=830.0).contains(&lambda) || wi.z <= 0.0 || wo.z <= 0.0 || wi.is_nan() {
                prop_assert_eq!(f, 0.0);
            }
            let c = brdf.coherent_spectral(wi, lambda);
            prop_assert!(ok(c) && c <= 1.0, "{json}: coherent = {c}");
        }
        // RGB is costlier: fewer pairs.
        let wi = DVec3::new(0.3, 0.2, 0.93).normalize();
        let wo = DVec3::new(-0.25, -0.1, 0.96).normalize();
        for c in brdf.eval_rgb(wi, wo) {
            prop_assert!(ok(c), "{json}: rgb = {c}");
        }
        for c in brdf.coherent_rgb(wi) {
            prop_assert!(ok(c), "{json}: coherent rgb = {c}");
        }
    }

    /// Helmholtz reciprocity f(wi, wo) = f(wo, wi): (u, v, w), G and the
    /// half-vector cosine are all symmetric in the two directions.
    #[test]
    fn reciprocity(
        json in material(),
        wi in direction(),
        wo in direction(),
        lambda in 360.0f64..830.0,
    ) {
        let brdf = Brdf::from_json(&json).unwrap();
        let a = brdf.eval_spectral(wi, wo, lambda);
        let b = brdf.eval_spectral(wo, wi, lambda);
        prop_assert!((a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-300, "{json}: {a} vs {b}");
    }
}
