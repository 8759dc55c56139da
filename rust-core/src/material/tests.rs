use super::*;
use crate::spectrum::SRGB_LUMINANCE;
use crate::testing::directions;

/// The RGB path against the 1 nm reference integration of the spectral
/// path, for the spectrally smooth models and each Fresnel kind. The
/// error is relative to the largest channel.
#[test]
fn rgb_matches_1nm_reference_for_smooth_models() {
    let materials = [
        r#"{"surface":"gaussian","sigma_um":0.03,"corr_um":2.0,"fresnel":"gold"}"#,
        r#"{"surface":"gaussian","sigma_um":0.12,"corr_um":3.0,"fresnel":"copper"}"#,
        r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":4.0}"#,
        r#"{"surface":"gaussian","sigma_um":2.0,"corr_um":10.0,"fresnel":{"eta":1.5,"k":0}}"#,
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":1.0,"corr_y_um":12.0,"fresnel":"silver"}"#,
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":1.0,"fresnel":"gold"}"#,
        r#"{"surface":"fractal","hurst":0.3,"sigma_um":0.05,"lag_um":2.0,"fresnel":0.8}"#,
    ];
    let mut worst: f64 = 0.0;
    for json in materials {
        let brdf = Brdf::from_json(json).unwrap();
        for (wi, wo) in directions() {
            let fast = brdf.eval_rgb(wi, wo);
            // Saturated spectral colours fall outside the sRGB gamut; the
            // outputs are gamut-mapped and so is the reference.
            let reference = gamut_map(brdf.eval_rgb_reference(wi, wo, 1.0));
            let scale = reference.iter().cloned().fold(0.0, f64::max);
            if scale < 1e-12 {
                continue;
            }
            for c in 0..3 {
                let e = (fast[c] - reference[c]).abs() / scale;
                if e > worst {
                    worst = e;
                }
                assert!(
                    e < 5e-3,
                    "{json} wi {wi:?} wo {wo:?}: {fast:?} vs {reference:?}"
                );
            }
        }
    }
    println!(
        "RGB vs 1 nm reference, smooth models: worst error {worst:.2e} of the largest channel"
    );
}

#[test]
fn gamut_mapping_keeps_luminance_and_in_gamut_colours() {
    let luminance = |c: [f64; 3]| {
        SRGB_LUMINANCE[0] * c[0] + SRGB_LUMINANCE[1] * c[1] + SRGB_LUMINANCE[2] * c[2]
    };
    assert_eq!(gamut_map([0.2, 0.5, 0.1]), [0.2, 0.5, 0.1]);
    for rgb in [[-0.59, 1.0, -0.08], [2.0, -0.3, 0.1], [-1e-3, 0.2, 3.0]] {
        let m = gamut_map(rgb);
        assert!(m.iter().all(|&c| c >= -1e-15), "{m:?}");
        assert!(
            m.iter().any(|&c| c.abs() < 1e-12),
            "{m:?} touches the gamut"
        );
        assert!((luminance(m) - luminance(rgb)).abs() < 1e-12);
        // Hue kept: the mapped colour lies on the segment from the
        // original towards its grey.
        let y = luminance(rgb);
        let t = (m[1] - rgb[1]) / (y - rgb[1]);
        for c in 0..3 {
            assert!((m[c] - (rgb[c] + t * (y - rgb[c]))).abs() < 1e-12);
        }
    }
    assert_eq!(gamut_map([-1.0, 0.1, 0.1]), [0.0; 3]);
}

/// The compact disc's RGB keeps the luminance of the exact projection
/// (a reference fine enough to resolve its peaks) within 1%.
#[test]
fn compact_disc_rgb_keeps_luminance() {
    let brdf = Brdf::from_json(r#"{"surface":"cd","coherence_um":10}"#).unwrap();
    let wi = DVec3::new(0.3, 0.0, 0.954).normalize();
    let mut checked = 0;
    for i in 0..40 {
        let t = -0.9 + 1.8 * i as f64 / 39.0;
        let wo = DVec3::new(t, 0.02, (1.0 - t * t - 0.0004).sqrt());
        let exact = brdf.eval_rgb_reference(wi, wo, 0.02);
        let y_exact = SRGB_LUMINANCE
            .iter()
            .zip(exact)
            .map(|(w, c)| w * c)
            .sum::<f64>();
        if y_exact < 1e-6 {
            continue;
        }
        let fast = brdf.eval_rgb(wi, wo);
        let y_fast = SRGB_LUMINANCE
            .iter()
            .zip(fast)
            .map(|(w, c)| w * c)
            .sum::<f64>();
        assert!(
            (y_fast - y_exact).abs() < 1e-2 * y_exact,
            "{fast:?} vs {exact:?}"
        );
        checked += 1;
    }
    assert!(checked > 5);
}

#[test]
fn flat_spectrum_maps_to_equal_rgb() {
    // Fresnel constant and a kernel with no wavelength dependence: the
    // H = 1 fractal is the geometric-optics (Beckmann) limit.
    let brdf = Brdf::from_json(
        r#"{"surface":"fractal","hurst":1.0,"sigma_um":0.2,"lag_um":1.0,"fresnel":0.5}"#,
    )
    .unwrap();
    let wi = DVec3::new(0.3, 0.1, 0.9).normalize();
    let wo = DVec3::new(-0.25, -0.05, 0.95).normalize();
    let spectral = brdf.eval_spectral(wi, wo, 550.0);
    let rgb = brdf.eval_rgb(wi, wo);
    for c in rgb {
        assert!(
            (c - spectral).abs() < 1e-6 * spectral,
            "{rgb:?} vs {spectral}"
        );
    }
}

#[test]
fn coherent_rgb_matches_reference() {
    let brdf =
        Brdf::from_json(r#"{"surface":"gaussian","sigma_um":0.06,"corr_um":2.0,"fresnel":"gold"}"#)
            .unwrap();
    for &ct in &[1.0, 0.7, 0.3, 0.05] {
        let wi = DVec3::new((1.0f64 - ct * ct).sqrt(), 0.0, ct);
        let fast = brdf.coherent_rgb(wi);
        let reference = spectrum::integrate_rgb_reference(|l| brdf.coherent_spectral(wi, l), 1.0)
            .map(|c| c.max(0.0));
        let scale = reference.iter().cloned().fold(0.0, f64::max);
        for c in 0..3 {
            assert!(
                (fast[c] - reference[c]).abs() < 2e-3 * scale,
                "{fast:?} vs {reference:?}"
            );
        }
    }
}
