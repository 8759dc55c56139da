//! The periodic spectral kernel's parameters (`Op::Param`): period_um,
//! coherence_um, and the profile's height_um (rect and sine) and width_um
//! (rect), checked with the shared harness (testing::params) at lanes on
//! the flanks of the order peaks: a change of 0.5% and 2% against the
//! changed material, the f64 derivative against native differences, and a
//! smoothness sweep. The RGB programs integrate each order against tables
//! built for the period and coherence, and keep them as constants.

use crate::material::program::ProgramKind;
use crate::program::ParamId::{self, *};
use crate::testing::params::{check, grating_lanes, Case, Lane, Tolerances, TOLERANCES};

/// Derivatives wherever f is above 1e-10 of its peak: a grating's peaks are
/// many orders of magnitude above its flanks, where d ln f / d ln p (a peak
/// moving with the period) is large.
const PERIODIC: Tolerances = Tolerances {
    derivative_floor: 1e-10,
    ..TOLERANCES
};

fn lanes_rect(n: usize, seed: u64) -> Vec<Lane> {
    grating_lanes(1.6, 8.0, n, seed)
}

fn lanes_cd(n: usize, seed: u64) -> Vec<Lane> {
    grating_lanes(2.5, 10.0, n, seed)
}

fn lanes_sine(n: usize, seed: u64) -> Vec<Lane> {
    grating_lanes(1.2, 6.0, n, seed)
}

const CASES: [(Case, &[ParamId]); 3] = [
    (
        Case {
            name: "rect grating 0.9",
            template: r#"{"surface":"periodic","period_um":$period_um,"coherence_um":$coherence_um,"profile":"rect","height_um":$height_um,"width_um":$width_um,"fresnel":$fresnel}"#,
            params: &[
                (PeriodUm, 1.6),
                (CoherenceUm, 8.0),
                (HeightUm, 0.15),
                (WidthUm, 0.5),
                (Fresnel, 0.9),
            ],
            lanes: lanes_rect,
        },
        &[PeriodUm, CoherenceUm, HeightUm, WidthUm],
    ),
    (
        Case {
            name: "cd aluminium",
            template: r#"{"surface":"cd","period_um":$period_um,"coherence_um":$coherence_um,"height_um":$height_um,"width_um":$width_um}"#,
            params: &[
                (PeriodUm, 2.5),
                (CoherenceUm, 10.0),
                (HeightUm, 0.15),
                (WidthUm, 0.5),
            ],
            lanes: lanes_cd,
        },
        &[PeriodUm, CoherenceUm, HeightUm, WidthUm],
    ),
    (
        Case {
            name: "sine gold",
            template: r#"{"surface":"periodic","period_um":$period_um,"coherence_um":$coherence_um,"profile":"sine","height_um":$height_um,"fresnel":"gold"}"#,
            params: &[(PeriodUm, 1.2), (CoherenceUm, 6.0), (HeightUm, 0.3)],
            lanes: lanes_sine,
        },
        &[PeriodUm, CoherenceUm, HeightUm],
    ),
];

/// The RGB program: the rect profile's height and width (the period, the
/// coherence length and a sine profile's height stay constants there);
/// against the native RGB path within the rule's error, as
/// optics/param_tests.rs holds gratings.
const PERIODIC_RGB: Tolerances = Tolerances {
    vs_native: 5e-3,
    derivative_floor: 1e-8,
    ..TOLERANCES
};

#[test]
fn periodic_rgb_profile_parameters_follow_the_changed_material() {
    let mut failures = Vec::new();
    for (case, ids) in CASES {
        let profile: Vec<ParamId> = ids
            .iter()
            .copied()
            .filter(|id| matches!(id, HeightUm | WidthUm) && !case.name.starts_with("sine"))
            .collect();
        failures.extend(check(
            &case,
            &[ProgramKind::EvalRgb],
            &profile,
            PERIODIC_RGB,
            2000,
        ));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn periodic_parameters_follow_the_changed_material() {
    let mut failures = Vec::new();
    for (case, ids) in CASES {
        failures.extend(check(
            &case,
            &[ProgramKind::EvalSpectral],
            ids,
            PERIODIC,
            2000,
        ));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
