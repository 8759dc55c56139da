//! The Fresnel term's parameters in every model's programs: the constant
//! reflectance (ParamId::Fresnel) and the complex index (ParamId::Eta,
//! ParamId::K) are `Op::Param`s of `Fresnel::program`, which the material's
//! eval programs (spectral: F at the half vector; RGB: the rule's flat
//! Fresnel factor) and the Gaussian coherent programs call. Checked with
//! the shared harness (testing::params): a change of 0.5% and 2% against
//! the changed material, the f64 derivative against native differences, a
//! smoothness sweep. Measured metals (tables by name) read no parameter.

use crate::material::program::ProgramKind;
use crate::program::ParamId::{self, *};
use crate::testing::params::{check, grating_lanes, lanes, Case, Lane, TOLERANCES};
use crate::testing::programs::exported;

const EVAL: [ProgramKind; 2] = [ProgramKind::EvalSpectral, ProgramKind::EvalRgb];
const ALL: [ProgramKind; 4] = [
    ProgramKind::EvalSpectral,
    ProgramKind::EvalRgb,
    ProgramKind::CoherentSpectral,
    ProgramKind::CoherentRgb,
];

fn cd_lanes(n: usize, seed: u64) -> Vec<Lane> {
    grating_lanes(2.5, 50.0, n, seed)
}

fn sine_lanes(n: usize, seed: u64) -> Vec<Lane> {
    grating_lanes(1.2, 20.0, n, seed)
}

/// (case, kinds, the Fresnel parameters checked)
fn cases() -> Vec<(Case, &'static [ProgramKind], &'static [ParamId])> {
    vec![
        (
            Case {
                name: "gaussian 0.8",
                template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_um":$corr_um,"fresnel":$fresnel}"#,
                params: &[(SigmaUm, 0.1), (CorrUm, 2.0), (Fresnel, 0.8)],
                lanes,
            },
            &ALL,
            &[Fresnel],
        ),
        (
            Case {
                name: "gaussian conductor",
                template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_um":$corr_um,"fresnel":{"eta":$eta,"k":$k}}"#,
                params: &[(SigmaUm, 0.3), (CorrUm, 3.0), (Eta, 0.6), (K, 3.2)],
                lanes,
            },
            &ALL,
            &[Eta, K],
        ),
        (
            Case {
                name: "brushed dielectric",
                template: r#"{"surface":"gaussian","sigma_um":$sigma_um,"corr_x_um":$corr_x_um,"corr_y_um":$corr_y_um,"fresnel":{"eta":$eta,"k":$k}}"#,
                params: &[
                    (SigmaUm, 0.15),
                    (CorrXUm, 1.0),
                    (CorrYUm, 15.0),
                    (Eta, 1.5),
                    (K, 0.0),
                ],
                lanes,
            },
            &ALL,
            &[Eta],
        ),
        (
            Case {
                name: "fractal 0.9",
                template: r#"{"surface":"fractal","hurst":0.7,"sigma_um":$sigma_um,"lag_um":$lag_um,"fresnel":$fresnel}"#,
                params: &[(SigmaUm, 0.05), (LagUm, 1.0), (Fresnel, 0.9)],
                lanes,
            },
            &EVAL,
            &[Fresnel],
        ),
        (
            Case {
                name: "fractal conductor",
                template: r#"{"surface":"fractal","hurst":0.35,"sigma_um":$sigma_um,"lag_um":$lag_um,"fresnel":{"eta":$eta,"k":$k}}"#,
                params: &[(SigmaUm, 0.1), (LagUm, 5.0), (Eta, 0.3), (K, 2.5)],
                lanes,
            },
            &EVAL,
            &[Eta, K],
        ),
        (
            Case {
                name: "cd 0.8",
                template: r#"{"surface":"cd","period_um":$period_um,"coherence_um":$coherence_um,"height_um":$height_um,"width_um":$width_um,"fresnel":$fresnel}"#,
                params: &[
                    (PeriodUm, 2.5),
                    (CoherenceUm, 50.0),
                    (HeightUm, 0.15),
                    (WidthUm, 0.5),
                    (Fresnel, 0.8),
                ],
                lanes: cd_lanes,
            },
            &EVAL,
            &[Fresnel],
        ),
        (
            Case {
                name: "sine grating conductor",
                template: r#"{"surface":"periodic","period_um":$period_um,"profile":"sine","height_um":$height_um,"coherence_um":$coherence_um,"fresnel":{"eta":$eta,"k":$k}}"#,
                params: &[
                    (PeriodUm, 1.2),
                    (HeightUm, 0.12),
                    (CoherenceUm, 20.0),
                    (Eta, 0.3),
                    (K, 2.5),
                ],
                lanes: sine_lanes,
            },
            &EVAL,
            &[Eta, K],
        ),
    ]
}

#[test]
fn fresnel_parameters_follow_the_changed_material() {
    let mut failures = Vec::new();
    for (case, kinds, ids) in cases() {
        let mut tol = TOLERANCES;
        if case.template.contains("periodic") || case.template.contains("cd") {
            // The grating's RGB program integrates its orders itself,
            // within the RGB rule's error (periodic/program_tests.rs).
            tol.vs_native = 5e-3;
            tol.derivative_floor = 1e-8;
        }
        failures.extend(check(&case, kinds, ids, tol, 2000));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A measured metal's Fresnel term is a table: its programs read no
/// Fresnel parameter (they stay non-differentiable).
#[test]
fn measured_metals_read_no_fresnel_parameter() {
    let b = crate::Brdf::from_json(r#"{"surface":"cd","fresnel":"gold"}"#).unwrap();
    for kind in EVAL {
        let p = exported(&b, kind).unwrap();
        for id in [Fresnel, Eta, K] {
            assert!(p.param_slot(id).is_none(), "{kind:?} reads {id:?}");
        }
    }
}
