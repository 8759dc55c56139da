//! The periodic spectral kernel's parameters (`Op::Param`): period_um,
//! coherence_um, and the profile's height_um (rect and sine) and width_um
//! (rect), checked with the shared harness (testing::params) at lanes on
//! the flanks of the order peaks: a change of 0.5% and 2% against the
//! changed material, the f64 derivative against native differences, and a
//! smoothness sweep. The RGB program reads them too: its orders are planned
//! for periods up to 6% longer and coherence lengths within 6%, and its
//! smoothed weight is read C1 in mu (which the period moves) and in t (which
//! the coherence length moves).

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

/// The RGB program: the period, the coherence length, the profile's height
/// and a rect's width; against the native RGB path within the rule's error,
/// as optics/param_tests.rs holds gratings. Derivatives down to 1e-8 of the
/// peak within 5%: on lanes there whose colour the gamut map moves (a
/// channel clamped at 0, the others carrying its luminance), the map
/// magnifies the tables' error in the clamped channel; the largest errors,
/// 3.8% (period) and 2.9% (coherence), are there (2026-12-03), and above
/// 1e-7 of the peak they are at most 1.2%. (The materials are built with
/// `"gradients": true`, as for a renderer that differentiates them.)
const PERIODIC_RGB: Tolerances = Tolerances {
    vs_native: 5e-3,
    derivative_floor: 1e-8,
    derivative_rel: 0.05,
    ..TOLERANCES
};

#[test]
fn periodic_rgb_parameters_follow_the_changed_material() {
    let mut failures = Vec::new();
    for (case, ids) in CASES {
        failures.extend(check(
            &case,
            &[ProgramKind::EvalRgb],
            ids,
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

/// A sine grating with a height texture (`height_um_max` 0.6: the renderer
/// gives the height per point through the programs' parameter).
const TEXTURED_SINE: Case = Case {
    name: "textured sine gold",
    template: r#"{"surface":"periodic","period_um":$period_um,"coherence_um":$coherence_um,"profile":"sine","height_um":$height_um,"height_um_max":0.6,"fresnel":"gold"}"#,
    params: &[(PeriodUm, 1.2), (CoherenceUm, 6.0), (HeightUm, 0.3)],
    lanes: lanes_sine,
};

/// With a height texture the spectral and RGB programs, built at height
/// 0.3 for every height up to 0.6, give the material of the point's height
/// (0.03 to 0.6), and in RGB the height is differentiable and smooth.
#[test]
fn sine_height_texture_programs_serve_every_height_up_to_the_max() {
    use crate::testing::params::changed;
    let ls = lanes_sine(1500, 9);
    let mut failures = Vec::new();
    for kind in [ProgramKind::EvalSpectral, ProgramKind::EvalRgb] {
        let tol = if kind.spectral() {
            1e-4
        } else {
            PERIODIC_RGB.vs_native
        };
        for factor in [0.1, 0.5, 1.5, 2.0] {
            let (vs_native, vs_program, checked) =
                changed(&TEXTURED_SINE, kind, HeightUm, factor, &ls);
            println!(
                "{kind:?} height {:.3}: {checked} checked, max rel vs native {vs_native:.2e}, vs that material's program {vs_program:.2e}",
                0.3 * factor
            );
            if !(vs_native <= tol && checked >= 50) {
                failures.push(format!("{kind:?} x{factor}: {vs_native:.2e} ({checked})"));
            }
        }
    }
    failures.extend(check(
        &TEXTURED_SINE,
        &[ProgramKind::EvalRgb],
        &[HeightUm],
        PERIODIC_RGB,
        2000,
    ));
    assert!(failures.is_empty(), "{failures:#?}");
}

/// With a height texture the sampling programs read the point's height
/// (the orders' weights follow it): their samples fit their pdf at heights
/// 0.06 and 0.6, normal and oblique incidence.
#[test]
fn sine_height_texture_sampling_passes_chi_square() {
    use crate::testing::chi2::chi2_fit;
    use crate::testing::programs::ProgramSampler;
    let b = TEXTURED_SINE.brdf(TEXTURED_SINE.params);
    let mut failures = Vec::new();
    let mut seed = 900;
    // Each height at both incidences, RGB at one and 550 nm at the other.
    for (height, cos, mode) in [
        (0.06, 1.0f64, None),
        (0.06, 0.5, Some(550.0)),
        (0.6, 1.0, Some(550.0)),
        (0.6, 0.5, None),
    ] {
        let wi = glam::DVec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
        seed += 1;
        let sampler = ProgramSampler::new(&b, wi, mode).with_param(HeightUm, height);
        let fit = chi2_fit(&sampler, seed, 40_000);
        println!(
            "chi2 height {height} cos {cos} {mode:?}: p = {:.4} (dof {}), integral {:.5}",
            fit.p_value, fit.dof, fit.integral
        );
        let again = || chi2_fit(&sampler, seed + 7_777_777, 160_000).p_value;
        if fit.integral > 1.0 + 2e-3 || !(fit.p_value > 0.01 || again() > 0.01) {
            failures.push(format!("height {height} cos {cos} {mode:?}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
