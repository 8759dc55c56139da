//! The Gaussian eval programs' parameters (`Op::Param`: sigma_um and the
//! correlation lengths), with the shared harness (testing::params): a
//! program run with a parameter changed by 0.5% and 2% gives what the
//! changed material gives (its own program and its native path), the
//! program's f64 derivative with respect to each parameter (what a
//! renderer's AD sees) is the native path's, and the program is smooth
//! along a fine sweep of a parameter (no linear interpolation).

use crate::material::program::ProgramKind;
use crate::program::ParamId::{self, *};
use crate::testing::params::{changed, check, lanes, smooth, Case, Tolerances, TOLERANCES};

const CASES: [Case; 6] = [
    Case {
        name: "constant 0.9",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_um":$corr_um,"fresnel":$fresnel}"#,
        params: &[(SigmaUm, 0.1), (CorrUm, 2.0), (Fresnel, 0.9)],
        lanes,
    },
    Case {
        name: "aluminium",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_um":$corr_um,"fresnel":"aluminium"}"#,
        params: &[(SigmaUm, 0.1), (CorrUm, 2.0)],
        lanes,
    },
    Case {
        name: "rough gold",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_um":$corr_um,"fresnel":"gold"}"#,
        params: &[(SigmaUm, 0.5), (CorrUm, 5.0)],
        lanes,
    },
    Case {
        name: "complex index",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_um":$corr_um,"fresnel":{"eta":$eta,"k":$k}}"#,
        params: &[(SigmaUm, 0.3), (CorrUm, 3.0), (Eta, 1.5), (K, 0.0)],
        lanes,
    },
    Case {
        name: "brushed aluminium",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_x_um":$corr_x_um,"corr_y_um":$corr_y_um,"fresnel":"aluminium"}"#,
        params: &[(SigmaUm, 0.15), (CorrXUm, 1.0), (CorrYUm, 15.0)],
        lanes,
    },
    Case {
        name: "brushed 0.9",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_x_um":$corr_x_um,"corr_y_um":$corr_y_um,"fresnel":$fresnel}"#,
        params: &[
            (SigmaUm, 0.15),
            (CorrXUm, 1.0),
            (CorrYUm, 15.0),
            (Fresnel, 0.9),
        ],
        lanes,
    },
];

/// The RGB program of an isotropic metal reads the folded table: its
/// channels follow the cosine the table's point had at the build's
/// parameters to first order only, so a change of 2% is held to 1.5e-3
/// (measured up to 1.1e-3 at sigma +- 2% on the harness's pairs, rough
/// gold: second order in the change; 0.5% stays within 1e-4, and the
/// derivative is exact).
const FOLDED: Tolerances = Tolerances {
    changed_large: 1.5e-3,
    ..TOLERANCES
};

/// The surface's own parameters (the Fresnel term's: optics/param_tests.rs).
fn surface_ids(case: &Case) -> Vec<ParamId> {
    case.params
        .iter()
        .map(|&(id, _)| id)
        .filter(|id| matches!(id, SigmaUm | CorrUm | CorrXUm | CorrYUm))
        .collect()
}

#[test]
fn gaussian_parameters_follow_the_changed_material() {
    let mut failures = Vec::new();
    for case in CASES {
        let ids = surface_ids(&case);
        // An isotropic surface with a measured metal's Fresnel term
        let isotropic_metal = case.template.contains("\"corr_um\"")
            && !case.template.contains("$fresnel")
            && !case.template.contains("$eta");
        failures.extend(check(
            &case,
            &[ProgramKind::EvalSpectral],
            &ids,
            TOLERANCES,
            3000,
        ));
        let rgb_tol = if isotropic_metal { FOLDED } else { TOLERANCES };
        failures.extend(check(&case, &[ProgramKind::EvalRgb], &ids, rgb_tol, 3000));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The smoothness criterion tells a cubic B-spline from linear
/// interpolation at the RGB table's row spacing (D_U / 2 in ln sigma).
#[test]
fn smoothness_criterion_detects_kinks() {
    let g = |x: f64| (3.0 * x).exp() * (20.0 * x).sin();
    let xs: Vec<f64> = (0..801).map(|i| -0.05 + i as f64 * 1.25e-4).collect();
    let exact: Vec<f64> = xs.iter().map(|&x| g(x)).collect();
    let node = 0.075;
    let linear: Vec<f64> = xs
        .iter()
        .map(|&x| {
            let i = (x / node).floor();
            let t = x / node - i;
            g(i * node) * (1.0 - t) + g((i + 1.0) * node) * t
        })
        .collect();
    let scale = exact.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(smooth(&exact, scale));
    assert!(!smooth(&linear, scale));
}

/// Materials with a sigma texture (`sigma_um_max` 0.6: the renderer gives
/// sigma per point through the programs' parameter).
const TEXTURED: [Case; 3] = [
    Case {
        name: "textured 0.9",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"sigma_um_max":0.6,"corr_um":$corr_um,"fresnel":$fresnel}"#,
        params: &[(SigmaUm, 0.1), (CorrUm, 2.0), (Fresnel, 0.9)],
        lanes,
    },
    Case {
        name: "textured gold",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"sigma_um_max":0.6,"corr_um":$corr_um,"fresnel":"gold"}"#,
        params: &[(SigmaUm, 0.1), (CorrUm, 2.0)],
        lanes,
    },
    Case {
        name: "textured brushed",
        template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"sigma_um_max":0.6,"corr_x_um":$corr_x_um,"corr_y_um":$corr_y_um,"fresnel":"aluminium"}"#,
        params: &[(SigmaUm, 0.1), (CorrXUm, 1.0), (CorrYUm, 15.0)],
        lanes,
    },
];

/// With a sigma texture, every reflectance program built at sigma 0.1 gives,
/// at any sigma from 0.005 to the maximum 0.6, what the material of that
/// sigma gives natively: within 1e-4 (spectral) and the RGB rule's
/// documented 3.5e-4 (RGB) of f's largest channel.
#[test]
fn sigma_texture_programs_serve_every_sigma_up_to_the_max() {
    let ls = lanes(1500, 5);
    let mut failures = Vec::new();
    for case in TEXTURED {
        for kind in [
            ProgramKind::EvalSpectral,
            ProgramKind::EvalRgb,
            ProgramKind::CoherentSpectral,
            ProgramKind::CoherentRgb,
        ] {
            let tol = if kind.spectral() { 1e-4 } else { 3.5e-4 };
            for factor in [0.05, 0.3, 1.7, 5.99] {
                let (vs_native, vs_program, checked) = changed(&case, kind, SigmaUm, factor, &ls);
                println!(
                    "{:>16} {kind:?} sigma {:.3}: {checked} checked, max rel vs native {vs_native:.2e}, vs that material's program {vs_program:.2e}",
                    case.name,
                    0.1 * factor
                );
                if !(vs_native <= tol && checked >= 50) {
                    failures.push(format!(
                        "{} {kind:?} x{factor}: {vs_native:.2e} ({checked})",
                        case.name
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// With a sigma texture, the sampling programs follow the point's sigma
/// (above all the coherent lobe's share): built at sigma 0.1, run at 0.01
/// (mostly coherent) and 0.6 (rough), their samples fit their pdf.
#[test]
fn sigma_texture_sampling_passes_chi_square() {
    use crate::testing::chi2::chi2_fit;
    use crate::testing::programs::ProgramSampler;
    let b = TEXTURED[1].brdf(TEXTURED[1].params);
    let mut failures = Vec::new();
    let mut seed = 500;
    for sigma in [0.01, 0.6] {
        for cos in [1.0f64, 0.5, 0.1] {
            let wi = glam::DVec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
            for mode in [None, Some(550.0)] {
                seed += 1;
                let sampler = ProgramSampler::new(&b, wi, mode).with_param(SigmaUm, sigma);
                let fit = chi2_fit(&sampler, seed, 40_000);
                println!(
                    "chi2 sigma {sigma} cos {cos} {mode:?}: p = {:.4} (dof {}), integral {:.5} + coherent {:.5}",
                    fit.p_value, fit.dof, fit.integral, fit.coherent
                );
                let again = || chi2_fit(&sampler, seed + 7_777_777, 160_000).p_value;
                if fit.integral + fit.coherent > 1.0 + 2e-3
                    || !(fit.p_value > 0.01 || again() > 0.01)
                {
                    failures.push(format!("sigma {sigma} cos {cos} {mode:?}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
