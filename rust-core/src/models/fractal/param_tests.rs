//! The fractal eval programs' parameters (`Op::Param`): sigma_um and
//! lag_um, which K depends on through ln a's constant only (hurst selects
//! the profile's table and stays a constant). Checked with the shared
//! harness (testing::params): a change of 0.5% and 2% against the changed
//! material, the f64 derivative against native differences, a smoothness
//! sweep (ln Phi is a cubic Hermite with exact derivatives inside the
//! table, the series outside: C1).

use crate::material::program::ProgramKind;
use crate::program::ParamId::*;
use crate::testing::params::{check, lanes, Case, TOLERANCES};

const EVAL: [ProgramKind; 2] = [ProgramKind::EvalSpectral, ProgramKind::EvalRgb];

const CASES: [Case; 4] = [
    Case {
        name: "fractal H 0.7",
        template: r#"{"surface":"fractal","hurst":0.7,"sigma_um":$sigma_um,"lag_um":$lag_um,"fresnel":$fresnel}"#,
        params: &[(SigmaUm, 0.05), (LagUm, 1.0), (Fresnel, 0.9)],
        lanes,
    },
    Case {
        name: "fractal H 0.35 gold",
        template: r#"{"surface":"fractal","hurst":0.35,"sigma_um":$sigma_um,"lag_um":$lag_um,"fresnel":"gold"}"#,
        params: &[(SigmaUm, 0.1), (LagUm, 5.0)],
        lanes,
    },
    Case {
        name: "fractal H 1 (Gaussian)",
        template: r#"{"surface":"fractal","hurst":1.0,"sigma_um":$sigma_um,"lag_um":$lag_um,"fresnel":$fresnel}"#,
        params: &[(SigmaUm, 0.05), (LagUm, 1.0), (Fresnel, 0.9)],
        lanes,
    },
    Case {
        name: "fractal H 0.9 aluminium",
        template: r#"{"surface":"fractal","hurst":0.9,"sigma_um":$sigma_um,"lag_um":$lag_um,"fresnel":"aluminium"}"#,
        params: &[(SigmaUm, 0.02), (LagUm, 5.0)],
        lanes,
    },
];

#[test]
fn fractal_parameters_follow_the_changed_material() {
    let mut failures = Vec::new();
    for case in CASES {
        failures.extend(check(&case, &EVAL, &[SigmaUm, LagUm], TOLERANCES, 2000));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
