//! Regressions found by the stress tool (tools/stress).

use glam::DVec3;
use stam::Brdf;

/// Fractal with hurst 1e-3 at the exact mirror direction: the density is
/// astronomically large (f clamps to f64::MAX). The RGB-mode pdf, a mixture
/// over wavelengths, overflowed to +inf and was returned as 0, so f > 0 with
/// pdf = 0 there (found by the stress run, seed 2).
#[test]
fn overflowing_pdf_is_clamped_not_zeroed() {
    let brdf = Brdf::from_json(
        r#"{"surface":"fractal","hurst":0.001,"sigma_um":0.0011738499517819252,"lag_um":1225.2517406604404,"fresnel":"copper"}"#,
    )
    .unwrap();
    let wi = DVec3::new(0.48739001154899597, -0.5172346830368042, 0.7035049796104431);
    let wo = DVec3::new(-wi.x, -wi.y, wi.z);
    assert!(brdf.eval_rgb(wi, wo).iter().any(|&c| c > 0.0));
    for lambda in [None, Some(550.0)] {
        let p = brdf.pdf(wi, wo, lambda);
        assert!(p.is_finite() && p > 0.0, "pdf {p} at lambda {lambda:?}");
    }
}

/// coherence_um at exactly its documented minimum, 1.5 x period_um, must be
/// accepted. serde_json's default float parser is not correctly rounded (it
/// can be 1 ulp off), so "coherence_um": 1.5 * period printed exactly was
/// refused with "= 7.705194491297576 is out of range: accepted
/// [7.7051944912975765, ...]" (found by the stress run: 10 of 4197 random
/// materials at the boundary). Fixed by serde_json's `float_roundtrip`.
#[test]
fn coherence_at_its_minimum_is_accepted() {
    for period in [
        5.136796327531718f64,
        80.8279949594302,
        2.407082761573215,
        18.728596843188758,
        1.2912793794843427,
        1.727522025837695,
    ] {
        let coherence = 1.5 * period;
        let json = format!(
            r#"{{"surface":"periodic","period_um":{period},"coherence_um":{coherence},"profile":"sine","height_um":0.1}}"#
        );
        if let Err(e) = Brdf::from_json(&json) {
            panic!("{json}: {e}");
        }
    }
}
